"""Cornell .brdf and ALTA text files: parsing real files, conversions, corruption."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gonio.errors import FormatError
from gonio.io import alta, cornell, load, spectral
from tests.conftest import shared_file
from tests.io.corrupt import assert_clean, variants


@pytest.mark.parametrize("name", ["acryl_blue.brdf", "cayman.brdf", "garnet_red.brdf"])
def test_cornell_real_files(name):
    path = shared_file("cornell", name)
    s = load(path)
    assert len(s) == 1439  # README: 1439 scattered samples each
    assert s.channels.kind == "spectral"
    np.testing.assert_allclose(s.channels.wavelengths_nm, np.arange(400, 701, 10))
    theta_i = np.degrees(np.arccos(s.wi[:, 2]))
    assert theta_i.min() == pytest.approx(10, abs=0.5) and theta_i.max() == pytest.approx(
        80, abs=0.5
    )
    np.testing.assert_allclose(s.wi[:, 1], 0, atol=1e-12)  # phi_i = 0
    # the first record, read straight from the text
    lines = [ln for ln in path.read_text().splitlines() if ln.strip() and not ln.startswith("#")]
    tokens = " ".join(lines).split()
    n_wl = int(tokens[0])
    rec = [float(x) for x in tokens[1 + n_wl : 1 + n_wl + 4 + n_wl]]
    ti, pi_, ts, ps = rec[:4]
    np.testing.assert_allclose(
        s.wi[0],
        [math.sin(ti) * math.cos(pi_), math.sin(ti) * math.sin(pi_), math.cos(ti)],
        atol=1e-12,
    )
    np.testing.assert_allclose(
        s.wo[0],
        [math.sin(ts) * math.cos(ps), math.sin(ts) * math.sin(ps), math.cos(ts)],
        atol=1e-12,
    )
    np.testing.assert_allclose(s.values[0], rec[4:])


def test_cornell_rgb_conversion_is_the_cie_path():
    path = shared_file("cornell", "acryl_blue.brdf")
    spec = cornell.read_cornell(path)
    rgb = cornell.read_cornell(path, color="rgb", illuminant="D65")
    assert rgb.channels.kind == "rgb"
    expect = spectral.spectrum_to_linear_srgb(spec.values, spec.channels.wavelengths_nm)
    np.testing.assert_allclose(rgb.values, expect, rtol=1e-12)
    mean = rgb.values.mean(axis=0)
    assert mean[2] > mean[0]  # acrylic *blue*
    red = cornell.read_cornell(shared_file("cornell", "garnet_red.brdf"), color="rgb")
    m = red.values.mean(axis=0)
    assert m[0] > m[1] and m[0] > m[2]


def test_alta_pink_felt_rgb_cos_th():
    path = shared_file("alta", "pink-felt-1d.alta")
    s = load(path)
    assert s.channels.kind == "rgb" and len(s) == 90
    # COS_TH with theta_d = 0: both directions equal the half vector, cos = first column
    first = [float(x) for x in path.read_text().splitlines()[6].split()]
    np.testing.assert_allclose(s.wi[0], s.wo[0], atol=1e-12)
    assert s.wi[0, 2] == pytest.approx(first[0])
    np.testing.assert_allclose(s.values[0], first[1:4])
    assert s.meta["source"]["param_in"] == "COS_TH"


def test_alta_retro_tape_projection_and_cosine_factor():
    path = shared_file("alta", "retro-gray-tape.dat")
    s = alta.read_alta(path)
    src = s.meta["source"]
    assert src["param_in"] == "ISOTROPIC_TL_TV_PROJ_DPHI"
    assert src["param_out"] == "INV_STERADIAN_COSINE_FACTOR" and src["param_out_assumed"]
    rows = np.array(
        [
            [float(x) for x in ln.split()]
            for ln in path.read_text().splitlines()
            if ln.strip() and not ln.startswith("#")
        ]
    )
    assert len(s) + src["dropped_at_or_below_horizon"] == len(rows) == 7405
    # independent conversion: theta_v = |(a, b)|, f = value / cos(theta_v), row order kept
    tl, a, b, v = rows.T
    tv = np.hypot(a, b)
    keep = np.cos(tv) > 1e-6
    np.testing.assert_allclose(s.values[:, 0], v[keep] / np.cos(tv[keep]), rtol=1e-9)
    np.testing.assert_allclose(s.wi[:, 0], np.sin(tl[keep]), atol=1e-12)
    np.testing.assert_allclose(s.wo[:, 2], np.cos(tv[keep]), atol=1e-12)
    sinc = np.where(tv > 0, np.sin(tv) / np.where(tv > 0, tv, 1), 1.0)  # theta_v = 0: normal
    np.testing.assert_allclose(s.wo[:, 1], (sinc * b)[keep], atol=1e-12)
    # a file that declares its output wins over the assumption
    s2 = alta.read_alta(path, param_out="INV_STERADIAN")
    assert s2.meta["source"]["param_out"] == "INV_STERADIAN"


def test_alta_bad_headers(tmp_path):
    cases = {
        "nodim": "#PARAM_IN COS_TH\n0.5 1 2 3\n",
        "baddim": "#DIM 1 x\n",
        "unknown_in": "#DIM 2 1\n#PARAM_IN WHATEVER\n0.1 0.2 0.3\n",
        "mismatch": "#DIM 2 1\n#PARAM_IN COS_TH\n0.1 0.2 0.3\n",
        "short_row": "#DIM 1 3\n#PARAM_IN COS_TH\n#PARAM_OUT RGB_COLOR\n0.5 1 2\n",
        "nan": "#DIM 1 3\n#PARAM_IN COS_TH\n#PARAM_OUT RGB_COLOR\n0.5 nan 2 3\n",
        "text": "#DIM 1 3\n#PARAM_IN COS_TH\n#PARAM_OUT RGB_COLOR\n0.5 one 2 3\n",
        "func": "#ALTA FUNC HEADER\n#FUNC nonlinear_function_lafortune\n",
        # inputs outside their domain, which the direction formulas clamped or wrapped silently
        "cos_above_1": "#DIM 1 3\n#PARAM_IN COS_TH\n#PARAM_OUT RGB_COLOR\n0.9 1 2 3\n2.5 1 2 3\n",
        "rusin_degrees": "#DIM 2 1\n#PARAM_IN RUSIN_TH_TD\n#PARAM_OUT INV_STERADIAN\n30 10 0.5\n",
    }
    for name, text in cases.items():
        p = tmp_path / f"{name}.alta"
        p.write_text(text)
        with pytest.raises(FormatError) as exc:
            alta.read_alta(p)
        assert str(p) in str(exc.value) and "\n" not in str(exc.value), name


def test_cornell_bad_files(tmp_path):
    cases = {
        "empty": "# nothing\n",
        "count": "-3\n400 500\n",
        "wl": "2\n500 400\n0 0 0 0 1 1\n",
        "partial": "2\n400 500\n0.1 0 0.2 0 1\n",
        "degrees": "1\n500\n45 0 30 180 0.5\n",
    }
    for name, text in cases.items():
        p = tmp_path / f"{name}.brdf"
        p.write_text(text)
        with pytest.raises(FormatError) as exc:
            cornell.read_cornell(p)
        assert str(p) in str(exc.value), name


@pytest.mark.parametrize(
    ("folder", "name"),
    [("cornell", "cayman.brdf"), ("alta", "pink-felt-1d.alta"), ("alta", "retro-gray-tape.dat")],
)
def test_corrupted_text_files_fail_cleanly_or_stay_sane(tmp_path, folder, name):
    src = shared_file(folder, name)
    outcomes = []
    for what, p in variants(src, tmp_path, n_flips=12):

        def sane(s, what=what):
            assert len(s) > 0, what
            assert np.all(np.isfinite(s.values)) and np.all(np.isfinite(s.wi)), what
            np.testing.assert_allclose(np.linalg.norm(s.wo, axis=1), 1, atol=1e-9)
            assert np.all(s.wi[:, 2] >= -1e-12) and np.all(s.wo[:, 2] >= -1e-12), what

        outcomes.append(assert_clean(load, p, what, sane))
        p.unlink()
    assert "error" in outcomes


def test_numpy_half_diff_matches_frames():
    from gonio.brdf import frames
    from gonio.io._geometry import half_diff_to_directions

    a = np.random.default_rng(0).uniform(0, 3, (4, 64))
    for ours, ref in zip(
        half_diff_to_directions(*a), frames.half_diff_to_directions(*a), strict=True
    ):
        np.testing.assert_allclose(ours, np.asarray(ref), atol=1e-12)
