"""``gonio view``'s page in headless Chromium: no console errors, the WebGL2 sphere equal to
gonio's exact render (delta light: f E cos per pixel, :mod:`gonio.render.delta`) within 1 %
relative RMSE for a table and a fit, at two light directions, and the coverage plot holding
exactly a run's samples. One browser and one page for the module; every format in ``-m slow``."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from tests.view import browser

SIZE = 48  # sphere readback size (pixels); the reference is rendered at the same size
LIGHTS = ((0.3, 0.2, 0.93), (-0.6, 0.3, 0.74))


def _small_table():
    from gonio.brdf import models
    from gonio.brdf.grid import Axis
    from gonio.brdf.tabulated import TabulatedBRDF

    half = math.pi / 2
    axes = (
        Axis("theta_h", 24, 0.0, half, "sqrt"),
        Axis("theta_d", 10, 0.0, half),
        Axis("phi_d", 12, 0.0, math.pi, "linear", True),
    )
    m = models.Lambert(albedo=[0.4, 0.3, 0.2]) + models.TorranceSparrow(
        alpha=0.25, distribution="ggx", rho_d=0.0
    )
    return TabulatedBRDF.from_model(m, axes=axes)


def _fit_file(path):
    from gonio.brdf import models
    from gonio.io import fit_result

    m = models.Lambert(albedo=[0.2, 0.3, 0.35]) + models.TorranceSparrow(
        alpha=0.2, distribution="ggx", rho_d=0.0
    )
    record = {
        "schema": fit_result.SCHEMA_ID,
        "version": fit_result.SCHEMA_VERSION,
        "model": "lambert+ts",
        "model_spec": m.to_dict(),
        "params": {k: np.asarray(v).tolist() for k, v in m.params().items()},
        "intervals": {},
        "loss": 0.125,
        "metric": "wls",
        "data": {"n_samples": 40, "channels": ["R", "G", "B"], "name": "m"},
    }
    return fit_result.write_json(fit_result.to_jsonable(record), path)


def _run_file(path, n=37):
    from gonio import io
    from gonio.brdf.measured import MeasuredSamples

    rng = np.random.default_rng(4)
    ti, to = rng.uniform(0.1, 1.3, n), rng.uniform(0.1, 1.3, n)
    po = rng.uniform(0, 2 * math.pi, n)
    wi = np.stack([np.sin(ti), np.zeros(n), np.cos(ti)], -1)
    wo = np.stack([np.sin(to) * np.cos(po), np.sin(to) * np.sin(po), np.cos(to)], -1)
    v = 0.1 + 0.3 * np.cos(ti)[:, None] * np.ones((1, 3))
    io.save(MeasuredSamples(wi, wo, v, 0.01 * v), path)
    return n


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """(driver, page path, sources, run sample count) for one page of a table, a fit and a run."""
    from gonio import io
    from gonio.view.page import write_page
    from gonio.view.sources import from_path

    d = tmp_path_factory.mktemp("view")
    driver = browser.start(d / "profile")
    try:
        io.save(_small_table(), d / "table.brdf.h5")
        _fit_file(d / "fit.json")
        n = _run_file(d / "run.brdf.h5")
        sources = [from_path(d / name) for name in ("table.brdf.h5", "fit.json", "run.brdf.h5")]
        page = write_page(sources, d / "view.html")
        errors = browser.open_page(driver, page)
        yield driver, page, sources, n, errors
    finally:
        driver.quit()


def _webgl(driver, k, light):
    px = driver.execute_script(
        "return gonioView.readLinear(arguments[0], arguments[1], arguments[2])", k, light, SIZE
    )
    return np.asarray(px, np.float64).reshape(SIZE, SIZE, 4)[..., :3]


def _exact(material, light):
    from gonio.render import Directional, render_sphere

    img = render_sphere(material, lights=[Directional(light)], resolution=SIZE)
    return np.broadcast_to(np.asarray(img, np.float64), (SIZE, SIZE, 3))


def _rel_rmse(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b**2)))


def test_page_opens_without_console_errors(session):
    driver, _, _, _, errors = session
    assert not errors, errors
    assert driver.execute_script("return gonioView.webgl2") is True
    assert driver.title.startswith("gonio view")


@pytest.mark.parametrize("k", [0, 1], ids=["table", "fit"])
def test_sphere_equals_gonio_render_and_follows_the_light(session, k):
    driver, _, sources, _, _ = session
    material = sources[k].material.material  # what gonio renders (the adapted table / model)
    images = []
    for light in LIGHTS:
        got = _webgl(driver, k, list(light))
        ref = _exact(material, np.asarray(light) / np.linalg.norm(light))
        assert _rel_rmse(got, ref) < 0.01, (light, _rel_rmse(got, ref))
        images.append(got)
    # the light moved: the image changed as gonio's render changes
    assert _rel_rmse(images[1], images[0]) > 0.1


def test_coverage_plot_holds_every_sample_of_the_run(session):
    driver, _, _, n, _ = session
    shown = driver.execute_script(
        "const d = document.getElementById('coverage-2').data;"
        "return [d[0].x.length, d[1].x.length];"
    )
    assert shown == [n, n]


def test_fit_panel_and_log_polar(session):
    driver, page, _, _, _ = session
    text = page.read_text(encoding="utf-8")
    assert "lambert+ts" in text and "0.125" in text
    radial = driver.execute_script(
        "return document.getElementById('polar').layout.polar.radialaxis.type"
    )
    assert radial == "log"
    data = json.loads(text.split('id="gonio-data">', 1)[1].split("</script>", 1)[0])
    assert data["figures"]["map-0"]["layout"]["xaxis"]["title"]["text"].startswith("θh")


def _every_format(d):
    """One input per format gonio view reads: label -> path."""
    from gonio import io
    from gonio.brdf import models
    from gonio.brdf.tabulated import TabulatedBRDF
    from tests.conftest import shared_file

    merl = d / "m.binary"
    io.save(TabulatedBRDF.merl_like(models.Lambert(albedo=[0.3, 0.4, 0.5])), merl)
    io.save(_small_table(), d / "table.brdf.h5")
    _run_file(d / "run.brdf.h5")
    _fit_file(d / "fit.json")
    zip_path = shared_file("nbrdf", "merl_nbrdf.zip")
    return {
        "merl": merl,
        "native-gridded": d / "table.brdf.h5",
        "native-run": d / "run.brdf.h5",
        "fit": d / "fit.json",
        "rgl": shared_file("rgl", "paper_white_rgb.bsdf"),
        "cornell": shared_file("cornell", "acryl_blue.brdf"),
        "alta": shared_file("alta", "pink-felt-1d.alta"),
        "nbrdf": f"{zip_path}::blue-acrylic",
    }


@pytest.mark.slow
def test_every_format_opens_without_console_errors(session, tmp_path):
    from gonio.view.page import write_page
    from gonio.view.sources import from_path

    driver = session[0]
    for name, path in _every_format(tmp_path).items():
        page = write_page([from_path(path)], tmp_path / f"{name}.html")
        errors = browser.open_page(driver, page)
        assert not errors, (name, errors)
        assert driver.execute_script("return gonioView.webgl2") is True, name
