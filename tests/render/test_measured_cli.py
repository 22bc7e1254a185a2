"""Rendering every kind of file gonio reads, through the ``gonio`` command line.

Each command must exit 0 with no traceback, and write an image that shows the material (not
black, the right colour where that is known); a refused one exits non-zero with one line on
stderr. The commands run in-process (:func:`gonio.cli.main`: the render kernels compile once for
the module); a render of a run's table and a refusal go through the real ``python -m gonio``.
"""

import json
from pathlib import Path

import numpy as np
import pytest

from gonio.brdf import models
from gonio.render.output import read_exr
from tests.conftest import shared_file
from tests.render.helpers import gonio_cli as gonio

FAST = ["--resolution", "24", "--spp", "2"]


@pytest.fixture(scope="module")
def run_table(tmp_path_factory):
    """The table ``gonio acquire`` writes, from the fast simulated rig."""
    run = tmp_path_factory.mktemp("acq") / "run"
    out = gonio(
        "acquire", "--rig", "sim_sample", "--plan", "iso-tiny", "--out", run, "--no-progress"
    )
    assert out.returncode == 0, out.stderr
    return run / "table.brdf.h5"


def _sphere(exr):
    img = read_exr(exr)
    lit = img.sum(-1) > 0
    return img, lit


@pytest.mark.parametrize("light", [[], ["--light", "dir:20,0"]])
def test_render_a_runs_table(tmp_path, run_table, light):
    # without a light: through the real entry point, python -m gonio
    out = gonio(
        "render",
        "--measured",
        run_table,
        *light,
        *FAST,
        "--out",
        tmp_path / "m.png",
        real=not light,
    )
    assert out.returncode == 0, out.stderr
    assert "scattered samples tabulated" in out.stderr
    img, lit = _sphere(tmp_path / "m-measured.exr")
    assert lit.mean() > 0.3  # the sphere covers pi/4 of the frame: most of it is lit
    assert np.isfinite(img).all()


# pink-felt-1d.alta is COS_TH only (theta_d = 0): its samples lie on a line, which Qhull cannot
# tetrahedralize (render, plot and grid --method interp stopped on a QhullError)
@pytest.mark.parametrize("name", ["retro-gray-tape.dat", "pink-felt-1d.alta"])
def test_render_alta_files(tmp_path, name):
    path = shared_file("alta", name)
    out = gonio("render", "--measured", path, *FAST, "--out", tmp_path / "a.png")
    assert out.returncode == 0, out.stderr
    _, lit = _sphere(tmp_path / "a-measured.exr")
    assert lit.mean() > 0.3


def test_a_one_dimensional_alta_file_is_interpolated_along_its_slice():
    from gonio import io
    from gonio.brdf.gridding import half_diff_iso
    from gonio.render.measured import renderable

    samples = io.load(shared_file("alta", "pink-felt-1d.alta"))
    table, _ = renderable(samples)
    th, _, _ = half_diff_iso(samples.wi, samples.wo)
    order = np.argsort(th)
    th_n = table.axes[0].nodes()
    keep = th_n <= th.max()
    vals = np.asarray(samples.values)[order]
    want = np.exp([np.interp(th_n[keep], th[order], np.log(vals[:, c])) for c in range(3)]).T
    # the theta_d = 0 row is the file's slice, log-linear between its samples; the other
    # theta_d rows repeat it (the file says nothing about them)
    np.testing.assert_allclose(np.asarray(table.values)[keep, 0, 0], want, rtol=1e-5)
    np.testing.assert_allclose(np.asarray(table.values)[keep, 7, 5], want, rtol=1e-5)


def test_render_cornell_spectral_in_colour(tmp_path):
    path = shared_file("cornell", "garnet_red.brdf")
    out = gonio("render", "--measured", path, *FAST, "--out", tmp_path / "c.png")
    assert out.returncode == 0, out.stderr
    assert "linear sRGB under D65" in out.stderr
    img, lit = _sphere(tmp_path / "c-measured.exr")
    r, g, b = img[lit].mean(0)
    assert r > 1.5 * g and r > 1.5 * b  # garnet red paint


def _spectral_fit(path, albedo, wl):
    model = models.Lambert(albedo=albedo)
    doc = {
        "model": "lambert",
        "model_spec": model.to_dict(),
        "data": {"n_samples": 1, "channels": [f"{w:g}nm" for w in wl]},
    }
    path.write_text(json.dumps(doc))
    return path


def test_spectral_fit_renders_in_colour(tmp_path):
    from gonio.io.spectral import spectrum_to_linear_srgb

    wl = np.arange(400, 701, 10.0)
    albedo = np.where(wl > 600, 0.8, 0.1)  # a red spectrum
    fit = _spectral_fit(tmp_path / "lambert.json", albedo, wl)
    out = gonio("render", "--fitted", fit, "--light", "dir:0,0", *FAST, "--out", tmp_path / "s.png")
    assert out.returncode == 0, out.stderr
    img = read_exr(tmp_path / "s-lambert.exr")
    assert img.shape[-1] == 3
    # Head-on light, E = 1: the centre pixel's radiance is albedo / pi * cos(0) in sRGB.
    expect = np.maximum(spectrum_to_linear_srgb(albedo, wl, "D65"), 0) / np.pi
    centre = img[12, 12]
    np.testing.assert_allclose(centre, expect, rtol=0.02, atol=1e-4)
    assert centre[0] > 3 * centre[1]


def test_flat_spectrum_renders_grey(tmp_path):
    wl = np.arange(400, 701, 10.0)
    fit = _spectral_fit(tmp_path / "grey.json", np.full(wl.size, 0.5), wl)
    out = gonio("render", "--fitted", fit, "--light", "dir:0,0", *FAST, "--out", tmp_path / "g.png")
    assert out.returncode == 0, out.stderr
    c = read_exr(tmp_path / "g-grey.exr")[12, 12]
    np.testing.assert_allclose(c, 0.5 / np.pi, rtol=0.01)


def test_same_named_fits_render_as_two_images_with_a_warning(tmp_path):
    for sub, a in (("a", 0.2), ("b", 0.7)):
        (tmp_path / sub).mkdir()
        (tmp_path / sub / "lambert.json").write_text(
            json.dumps({"model_spec": models.Lambert(albedo=a).to_dict()})
        )
    out = gonio(
        "render",
        "--fitted",
        tmp_path / "a" / "lambert.json",
        "--fitted",
        tmp_path / "b" / "lambert.json",
        "--light",
        "dir:0,0",
        *FAST,
        "--out",
        tmp_path / "f.png",
    )
    assert out.returncode == 0, out.stderr
    assert "several --fitted files are named lambert.json" in out.stderr
    ia, ib = read_exr(tmp_path / "f-a-lambert.exr"), read_exr(tmp_path / "f-b-lambert.exr")
    assert ib[12, 12, 0] > 3 * ia[12, 12, 0]


def test_grid_command_bins_and_interpolates(tmp_path, run_table):
    from gonio import io

    out = gonio("grid", run_table, tmp_path / "g.brdf.h5", "--res", "8,8,6")
    assert out.returncode == 0, out.stderr
    t = io.load(tmp_path / "g.brdf.h5")
    assert t.shape == (8, 8, 6) and t.sigma is not None and t.counts is not None
    assert 0 < t.mask.mean() < 1
    s = io.load(run_table)
    assert int(t.counts.sum()) == len(s)
    out = gonio("grid", run_table, tmp_path / "i.brdf.h5", "--res", "10", "--method", "interp")
    assert out.returncode == 0, out.stderr
    ti = io.load(tmp_path / "i.brdf.h5")
    assert ti.shape == (10, 10, 10) and ti.mask.mean() > t.mask.mean()
    # Existing output, gridded input, bad resolution: one line each, nothing written.
    for args in (
        (run_table, tmp_path / "g.brdf.h5"),
        (tmp_path / "g.brdf.h5", tmp_path / "x.brdf.h5"),
        (run_table, tmp_path / "y.brdf.h5", "--res", "0,4"),
    ):
        bad = gonio("grid", *args)
        assert bad.returncode != 0 and len(bad.stderr.strip().splitlines()) == 1, bad.stderr
    assert not (tmp_path / "x.brdf.h5").exists() and not (tmp_path / "y.brdf.h5").exists()
    # The binned table renders (its holes filled by interpolation).
    out = gonio("render", "--measured", tmp_path / "g.brdf.h5", *FAST, "--out", tmp_path / "r.png")
    assert out.returncode == 0, out.stderr
    assert "filled by log-linear Delaunay interpolation" in out.stderr
    assert Path(tmp_path / "r.png").is_file()


@pytest.mark.parametrize(
    "doc, why",
    [
        (
            {"schema": "gonio/fit-result", "version": 2, "model_spec": {"type": "Lambert"}},
            "unsupported fit file",
        ),
        (
            {"model_spec": {"type": "Lambert", "params": {}, "static": {}, "children": {}}},
            "lacks parameter(s) albedo",
        ),
    ],
)
def test_fit_file_of_unknown_version_or_missing_parameter_is_refused(tmp_path, doc, why):
    fit = tmp_path / "f.json"
    fit.write_text(json.dumps(doc))
    real = why == "unsupported fit file"  # one refusal through python -m gonio
    out = gonio("render", "--fitted", fit, *FAST, "--out", tmp_path / "x.png", real=real)
    assert out.returncode == 2 and why in out.stderr, out.stderr
    assert len(out.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "x.png").exists()


def test_render_output_checks(tmp_path):
    fit = _spectral_fit(tmp_path / "l.json", np.full(31, 0.5), np.arange(400, 701, 10.0))
    bad = gonio("render", "--fitted", fit, *FAST, "--out", tmp_path / "a.jpg")
    assert bad.returncode == 2 and "unsupported figure format" in bad.stderr
    assert not list(tmp_path.glob("a*"))
    ok = gonio("render", "--fitted", fit, "--light", "dir:0,0", *FAST, "--out", f"{tmp_path}/d/")
    assert ok.returncode == 0, ok.stderr
    assert (tmp_path / "d" / "compare.png").read_bytes()[:4] == b"\x89PNG"
    assert not (tmp_path / "d").is_file()


def test_negative_seed_is_refused(tmp_path):
    from gonio.errors import ParameterError
    from gonio.render import render_sphere

    fit = _spectral_fit(tmp_path / "l.json", np.full(31, 0.5), np.arange(400, 701, 10.0))
    bad = gonio("render", "--fitted", fit, *FAST, "--seed", "-1", "--out", tmp_path / "a.png")
    assert bad.returncode == 2 and "--seed must be >= 0" in bad.stderr, bad.stderr
    assert not list(tmp_path.glob("a*"))
    with pytest.raises(ParameterError, match="seed"):
        render_sphere(models.Lambert(), resolution=8, spp=1, seed=-1)


def test_brdf_slice_exr_is_not_an_environment(tmp_path, run_table):
    assert gonio("grid", run_table, tmp_path / "g.brdf.h5", "--res", "6").returncode == 0
    assert gonio("convert", tmp_path / "g.brdf.h5", tmp_path / "s.exr", "--quiet").returncode == 0
    fit = _spectral_fit(tmp_path / "l.json", np.full(31, 0.5), np.arange(400, 701, 10.0))
    out = gonio("render", "--fitted", fit, "--env", tmp_path / "s.exr", *FAST, "--out",
                tmp_path / "e.png")  # fmt: skip
    assert out.returncode == 2 and "not a lat-long environment map" in out.stderr
    assert not (tmp_path / "e.png").exists()


def test_spp_beyond_the_limit_is_refused(tmp_path):
    fit = _spectral_fit(tmp_path / "l.json", np.full(31, 0.5), np.arange(400, 701, 10.0))
    bad = gonio("render", "--fitted", fit, "--spp", "100000000", "--out", tmp_path / "a.png")
    assert bad.returncode == 2 and "--spp must be in [1, 65536]" in bad.stderr, bad.stderr
    assert not list(tmp_path.glob("a*"))
