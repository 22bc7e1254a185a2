"""The renderer's sample points: SciPy's Sobol' sequence, digitally shifted per pixel, and the
rank-1 lattice sequence built on its first dimension, rotated per pixel."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from gonio.brdf.sampling import points as sobol


@pytest.mark.parametrize("dims", [1, 2, 4, 8])
def test_points_are_scipys_unscrambled_sobol_sequence(dims):
    qmc = pytest.importorskip("scipy.stats").qmc
    for n in (1, 7, 64, 300):
        ref = qmc.Sobol(d=dims, scramble=False, bits=32).random(n) if n > 1 else np.zeros((1, dims))
        expect = (ref * 2.0**32).astype(np.uint64).astype(np.uint32)
        np.testing.assert_array_equal(sobol.sobol_ints(n, dims), expect)


def test_digital_shift_keeps_the_net_stratified_and_is_uniform():
    pts = sobol.sobol_ints(64, 4)
    rng = np.random.default_rng(5)
    sh = sobol.shifts(rng, 2000, 4)
    u = np.asarray(sobol.to_unit(pts, sh))  # (2000, 64, 4)
    assert u.dtype == np.float32 and u.min() >= 0.0 and u.max() < 1.0
    # every shifted copy of the first two dimensions is still a (0, 6, 2)-net: one point in
    # each of the 8 x 8 (and 64 x 1, 1 x 64) elementary boxes
    for bx, by in ((8, 8), (64, 1), (1, 64), (4, 16)):
        cell = np.floor(u[..., 0] * bx).astype(int) * by + np.floor(u[..., 1] * by).astype(int)
        assert all(np.unique(c).size == 64 for c in cell[:50])
    # and each point is uniform over the shifts: chi-square on 16 bins of one coordinate of
    # point 5 over the 2000 pixels, 15 degrees of freedom, significance 1e-3 (critical 37.7)
    counts = np.bincount(np.floor(u[:, 5, 2] * 16).astype(int), minlength=16)
    chi2 = ((counts - 125.0) ** 2 / 125.0).sum()
    assert chi2 < 37.7


def test_padded_pairs_are_each_the_rotated_lattice_in_a_random_order():
    pts = sobol.sobol_ints(64, 1)
    sh = sobol.shifts(np.random.default_rng(8), 3000, 6)
    u = np.asarray(sobol.padded_unit(pts, sh))  # (3000, 64, 6)
    assert u.dtype == np.float32 and u.shape == (3000, 64, 6)
    assert u.min() >= 0.0 and u.max() < 1.0
    r = pts[:, 0].astype(np.uint64)
    g = np.uint64(sobol.LATTICE_GENERATOR)
    lattice = np.stack([r, (r * g) % np.uint64(1 << 32)], -1)  # (64, 2), 32-bit fixed point
    raw = (u.astype(np.float64) * 2.0**24).astype(np.uint64)  # the top 24 bits of each number
    for k in range(3):
        # pair 0 in the points' order, later pairs in the order i XOR r, r from the low 6 bits of
        # the pair's first shift word (a per-pixel permutation)
        r_k = (sh[:, 2 * k] & np.uint32(63)) if k else np.zeros(3000, np.uint32)
        idx = np.arange(64, dtype=np.uint32)[None, :] ^ r_k[:, None]
        for c in range(2):
            # undoing the rotation: (point + shift) >> 8 is (point >> 8) + (shift >> 8) plus the
            # carry of the low 8 bits, modulo 2^24
            off = (sh[:, None, 2 * k + c].astype(np.uint64) >> np.uint64(8)) % np.uint64(1 << 24)
            diff = (raw[..., 2 * k + c] - off - (lattice[idx, c] >> np.uint64(8))) % (1 << 24)
            assert set(np.unique(diff)) <= {0, 1}
        if k:
            assert np.unique(r_k).size == 64
    # every sample of a pair is uniform over pixels: chi-square, 16 bins, 15 degrees of
    # freedom, significance 1e-3 (critical 37.7)
    for col in (0, 1, 5):
        counts = np.bincount(np.floor(u[:, 9, col] * 16).astype(int), minlength=16)
        assert ((counts - 187.5) ** 2 / 187.5).sum() < 37.7


def test_samples_first_layout_holds_the_same_numbers():
    # the renderer's (S, P, d) layout is the (P, S, d) one transposed, bit for bit, for a
    # power-of-2 batch (permuted pairs) and another size (mask 0)
    for n in (16, 24):
        pts = sobol.sobol_ints(n, 1)
        sh = sobol.shifts(np.random.default_rng(3), 50, 6)
        a = np.asarray(sobol.padded_unit(pts, sh))
        b = np.asarray(sobol.padded_unit(pts, sh, samples_first=True))
        assert b.shape == (n, 50, 6)
        np.testing.assert_array_equal(b, a.transpose(1, 0, 2))


def _zaremba(g: int, n: int) -> int:
    """Zaremba index of the Korobov lattice {(j / n, frac(j g / n))}: min over the nonzero
    dual vectors (h1 + g h2 = 0 mod n) of max(1, |h1|) max(1, |h2|)."""
    h2 = np.arange(1, n)
    h1 = (-g * h2) % n
    return int(min(n, (np.maximum(1, np.minimum(h1, n - h1)) * h2).min()))


def test_lattice_sequence_is_a_korobov_lattice_at_every_power_of_two():
    n_max = 2048
    r = sobol.sobol_ints(n_max, 1)[:, 0].astype(np.uint64)
    g = sobol.LATTICE_GENERATOR
    second = (r * np.uint64(g)) % np.uint64(1 << 32)
    for m in range(4, 12):
        n = 1 << m
        # the first 2^m points are {(j / n, frac(j g / n))}, exactly
        j = (r[:n] >> np.uint64(32 - m)).astype(np.int64)
        assert np.array_equal(np.sort(j), np.arange(n))
        assert np.all(r[:n] == j.astype(np.uint64) << np.uint64(32 - m))
        expect = ((j * g) % n).astype(np.uint64) << np.uint64(32 - m)
        np.testing.assert_array_equal(second[:n], expect)
    # each aligned block of 16 (one kernel call's samples) is the first block shifted mod 1
    first = {(int(a), int(b)) for a, b in zip(r[:16], second[:16], strict=True)}
    for start in range(16, n_max, 16):
        blk_r, blk_s = r[start : start + 16], second[start : start + 16]
        c = blk_r.min()  # the block's copy of the point (0, 0)
        cs = (c * np.uint64(g)) % np.uint64(1 << 32)
        moved = {
            ((int(a) - int(c)) % (1 << 32), (int(b) - int(cs)) % (1 << 32))
            for a, b in zip(blk_r, blk_s, strict=True)
        }
        assert moved == first


def test_lattice_generator_maximizes_the_worst_zaremba_index():
    """The generator's claim in gonio.brdf.sampling.points: among the odd numbers below 2^14 none
    has a larger minimum of Zaremba index / N over N = 2^4 ... 2^11, and that minimum is 0.113."""

    def worst(g: int) -> float:
        return min(_zaremba(g % (1 << m), 1 << m) / (1 << m) for m in range(4, 12))

    mine = worst(sobol.LATTICE_GENERATOR)
    assert mine == pytest.approx(0.1128, abs=1e-4)
    # g and 2^m - g give mirrored lattices; checking the odd g below 2^14 covers every class
    assert all(worst(g) <= mine for g in range(1, 1 << 14, 2))


def test_render_path_does_not_import_scipy_stats_or_matplotlib():
    code = (
        "import sys, gonio.render.integrator, gonio.render.cli, gonio.render.output;"
        "print(sorted(m for m in ('scipy.stats', 'matplotlib') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


@pytest.mark.slow  # a fresh process compiling the render kernels: 15-40 s on a loaded machine
def test_cli_render_imports_neither_fit_nor_scipy_stats_nor_rich(tmp_path):
    """What a second process pays for before its first image: `gonio render` of a fit, output
    piped (no progress bar), imports neither the fitting package, scipy.stats, matplotlib nor
    rich."""
    from gonio.brdf.models import Lambert

    fit = tmp_path / "lambert.json"
    fit.write_text(json.dumps(Lambert(albedo=0.5).to_dict()))
    code = (
        "import sys; from gonio.cli import main;"
        f"rc = main(['render', '--fitted', {str(fit)!r}, '--resolution', '8', '--spp', '1',"
        f" '--no-images', '--no-compile-cache', '--out', {str(tmp_path / 'g.png')!r}]);"
        "print(rc, sorted(m for m in ('gonio.fit', 'scipy.stats', 'matplotlib', 'rich')"
        " if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == "0 []"
    assert (tmp_path / "g.png").is_file()
