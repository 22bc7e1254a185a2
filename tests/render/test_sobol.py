"""The renderer's Sobol' points: SciPy's sequence, digitally shifted per pixel."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from gonio.render import sobol


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


def test_padded_pairs_are_each_the_shifted_net_in_a_random_order():
    pts = sobol.sobol_ints(64, 2)
    sh = sobol.shifts(np.random.default_rng(8), 3000, 6)
    u = np.asarray(sobol.padded_unit(pts, sh))  # (3000, 64, 6)
    assert u.shape == (3000, 64, 6) and u.min() >= 0.0 and u.max() < 1.0
    for k in range(3):
        pair = u[:50, :, 2 * k : 2 * k + 2]
        cell = np.floor(pair[..., 0] * 8).astype(int) * 8 + np.floor(pair[..., 1] * 8)
        assert all(np.unique(c).size == 64 for c in cell)
    # undoing the shift of pair 1 gives the net's point i XOR r for sample i, with r from the
    # shift's low bits: a per-pixel permutation (not the first pair's order)
    top = np.uint32(0xFFFFFF00)
    raw = (u[..., 2] * 2.0**24).astype(np.uint32) << np.uint32(8)
    unshifted = raw ^ (sh[:, None, 2] & top)
    r = sh[:, 2] & np.uint32(63)
    idx = np.arange(64, dtype=np.uint32)[None, :] ^ r[:, None]
    np.testing.assert_array_equal(unshifted, pts[idx, 0] & top)
    assert np.unique(r).size == 64
    # every sample of a later pair is uniform over pixels: chi-square, 16 bins, 15 degrees of
    # freedom, significance 1e-3 (critical 37.7)
    counts = np.bincount(np.floor(u[:, 9, 5] * 16).astype(int), minlength=16)
    assert ((counts - 187.5) ** 2 / 187.5).sum() < 37.7


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
