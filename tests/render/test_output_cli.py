import json

import numpy as np
import pytest

from gonio.brdf import models
from gonio.cli import main
from gonio.errors import FormatError, ParameterError
from gonio.render import Directional, render_sphere
from gonio.render.cli import load_fitted, parse_light
from gonio.render.compare import compare_images, comparison_figure, image_errors
from gonio.render.output import read_exr, tonemap, write_exr, write_png


@pytest.mark.parametrize("c", [1, 3, 5])
def test_exr_roundtrip_is_exact(tmp_path, c):
    img = np.random.default_rng(0).random((7, 9, c)).astype(np.float32) * 100
    path = write_exr(tmp_path / "x.exr", img)
    np.testing.assert_array_equal(read_exr(path), img)
    assert [p.name for p in tmp_path.iterdir()] == ["x.exr"]  # no temporary left behind


def test_read_exr_rejects_garbage(tmp_path):
    p = tmp_path / "bad.exr"
    p.write_bytes(b"not an exr at all")
    with pytest.raises(FormatError):
        read_exr(p)


def test_tonemap_is_monotone_and_in_range():
    ramp = np.linspace(0, 50, 200, dtype=np.float32)[None, :, None].repeat(3, -1)
    out = tonemap(ramp, exposure=1.0)
    assert out.min() >= 0 and out.max() <= 1
    assert np.all(np.diff(out[0, :, 0]) >= 0)
    # sRGB of Reinhard(0.5) = 0.5 * (1 + 0.5/16) / 1.5.
    y = 0.5 * (1 + 0.5 / 16) / 1.5
    expect = 1.055 * y ** (1 / 2.4) - 0.055
    assert tonemap(np.full((1, 1, 3), 0.5, np.float32), 1.0)[0, 0, 0] == pytest.approx(expect)


def test_png_written(tmp_path):
    from PIL import Image

    img = render_sphere(models.Lambert(0.5), Directional((0, 0, 1)), resolution=16)
    p = write_png(tmp_path / "a.png", img)
    with Image.open(p) as im:
        assert im.size == (16, 16) and im.mode == "RGB"


def test_errors_detect_a_difference():
    rng = np.random.default_rng(1)
    ref = rng.random((16, 16, 3)).astype(np.float32) + 0.5
    same = image_errors(ref, ref)
    assert same.rmse == 0 and same.rel_mse == 0
    assert same.ssim is None or same.ssim == pytest.approx(1.0)
    off = image_errors(ref * 1.1, ref)
    assert off.rmse == pytest.approx(0.1 * np.sqrt(np.mean(ref.astype(np.float64) ** 2)), rel=1e-5)
    assert off.rel_mse > 0.005
    with pytest.raises(ParameterError):
        image_errors(ref[:8], ref)


def test_comparison_figure(tmp_path):
    a = render_sphere(models.Lambert([0.5, 0.4, 0.3]), Directional((0, 0, 1)), resolution=24)
    b = render_sphere(models.Lambert([0.4, 0.4, 0.3]), Directional((0, 0, 1)), resolution=24)
    exp, comps = compare_images(a, [("fit", b), ("same", a)])
    assert comps[0].errors.rmse > 0 and comps[1].errors.rmse == 0
    p = comparison_figure(tmp_path / "c.png", a, comps, exp, title="t")
    assert p.stat().st_size > 1000


def test_parse_light_degrees():
    light = parse_light("dir:60,90,2")
    np.testing.assert_allclose(light.direction, [0, np.sin(np.pi / 3), 0.5], atol=1e-6)
    np.testing.assert_allclose(light.irradiance, [2.0])
    for bad in ["dir:95,0", "point:1,2", "dir:a,b", "dir:1"]:
        with pytest.raises(ParameterError):
            parse_light(bad)


def _fit_file(tmp_path, model, name="fit.json"):
    """A file shaped like gonio.fit's result JSON: "model" names the preset, "model_spec" is
    the model's to_dict()."""
    p = tmp_path / name
    p.write_text(json.dumps({"model": "lambert", "model_spec": model.to_dict(), "loss": "wls"}))
    return p


def load_fit_model(path):
    return load_fitted(path)[0]


def test_load_fit_model(tmp_path):
    m = models.Lambert([0.2, 0.3, 0.4])
    got = load_fit_model(_fit_file(tmp_path, m))
    np.testing.assert_allclose(np.asarray(got.albedo), [0.2, 0.3, 0.4])
    bare = tmp_path / "bare.json"
    bare.write_text(json.dumps(m.to_dict()))
    np.testing.assert_allclose(np.asarray(load_fit_model(bare).albedo), [0.2, 0.3, 0.4])
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(FormatError):
        load_fit_model(bad)
    bad.write_text(json.dumps({"model": {"type": "NoSuchModel"}}))
    with pytest.raises(FormatError):
        load_fit_model(bad)


def test_cli_renders_fits_and_reports_json(tmp_path, capsys):
    f1 = _fit_file(tmp_path, models.Lambert([0.5, 0.4, 0.3]), "a.json")
    out = tmp_path / "out.png"
    rc = main(
        [
            "render",
            "--fitted",
            str(f1),
            "--light",
            "dir:20,30",
            "--resolution",
            "16",
            "--out",
            str(out),
            "--json",
        ]
    )
    assert rc == 0
    report = json.loads(capsys.readouterr().out)
    assert out.exists() and (tmp_path / "out-a.exr").exists()
    img = read_exr(report["images"]["a"])
    assert img.shape == (16, 16, 3) and img.max() > 0


@pytest.mark.parametrize(
    "argv",
    [
        ["render"],
        ["render", "--fitted", "missing.json"],
        ["render", "--measured", "missing.binary"],
        ["render", "--fitted", "{f}", "--light", "dir:100,0"],
        ["render", "--fitted", "{f}", "--spp", "0"],
        ["render", "--fitted", "{f}", "--env", "nothere.exr"],
    ],
)
def test_cli_bad_input_is_one_line(tmp_path, capsys, argv):
    f = _fit_file(tmp_path, models.Lambert(0.5))
    argv = [a.replace("{f}", str(f)) for a in argv]
    rc = main([*argv, "--out", str(tmp_path / "o.png")])
    err = capsys.readouterr().err
    assert rc != 0 and err.startswith("gonio: ") and err.count("\n") == 1
    assert not (tmp_path / "o.png").exists()


def test_cli_measured_table_against_fits(tmp_path, capsys):
    """End to end: a table on disk, two fit files; the right fit has the smaller error."""
    tabulated = pytest.importorskip("gonio.brdf.tabulated")
    from gonio import io

    truth = models.Lambert([0.1, 0.08, 0.05]) + models.Phong(rho_d=0.0, rho_s=0.5, n=30.0)
    axes = tabulated.default_axes("half_diff_iso", 32, 32, 32)
    table = tabulated.TabulatedBRDF.from_model(truth, axes=axes)
    tpath = tmp_path / "measured.brdf.h5"
    io.save(table, tpath)
    good = _fit_file(tmp_path, truth, "good.json")
    wrong = models.Lambert([0.1, 0.08, 0.05]) + models.Phong(rho_d=0.0, rho_s=0.5, n=5.0)
    bad = _fit_file(tmp_path, wrong, "bad.json")
    out = tmp_path / "cmp.png"
    rc = main(
        [
            "render",
            "--measured",
            str(tpath),
            "--fitted",
            str(good),
            "--fitted",
            str(bad),
            "--light",
            "dir:25,60",
            "--resolution",
            "24",
            "--out",
            str(out),
            "--json",
        ]
    )
    assert rc == 0
    report = json.loads(capsys.readouterr().out)
    errs = report["errors"]
    assert errs["good"]["rmse"] < 0.5 * errs["bad"]["rmse"]
    assert out.stat().st_size > 1000
    assert {"measured", "good", "bad"} <= set(report["images"])


def test_comparison_figure_names_its_reference_and_states_the_clipping(tmp_path):
    rng = np.random.default_rng(2)
    ref = rng.random((16, 16, 3)).astype(np.float32) + 0.5
    exp, comps = compare_images(ref, [("fit", ref * 1.2)])
    p = comparison_figure(tmp_path / "c.svg", ref, comps, exp, reference_label="ground truth")
    svg = p.read_text()
    assert "ground truth" in svg and ">measured<" not in svg
    assert "clipped at" in svg and "99.5th percentile" in svg
