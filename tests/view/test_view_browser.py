"""``gonio view``'s page in headless Chromium: no console errors, the WebGL2 sphere equal to
gonio's exact render (delta light: f E cos per pixel, :mod:`gonio.render.delta`) within 1 %
relative RMSE for a table and a fit, at two light directions; under the studio environment the
progressive estimate equal to gonio's within its own measured noise (a Lambertian table against
an exact quadrature here; in ``-m slow`` a glossy table and a fit against ``render_sphere``);
the point / environment / both toggle; and the coverage plot holding exactly a run's samples.
One browser and one page for the module; every format in ``-m slow``."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from tests.view import browser

SIZE = 48  # sphere readback size (pixels); the reference is rendered at the same size
LIGHTS = ((0.3, 0.2, 0.93), (-0.6, 0.3, 0.74))


def _grid_table(model, n_th, n_td, n_pd):
    """``model`` tabulated on a small MERL-like half/diff grid (sqrt theta_h, periodic phi_d)."""
    from gonio.brdf.grid import Axis
    from gonio.brdf.tabulated import TabulatedBRDF

    half = math.pi / 2
    axes = (
        Axis("theta_h", n_th, 0.0, half, "sqrt"),
        Axis("theta_d", n_td, 0.0, half),
        Axis("phi_d", n_pd, 0.0, math.pi, "linear", True),
    )
    return TabulatedBRDF.from_model(model, axes=axes)


def _small_table():
    from gonio.brdf import models

    m = models.Lambert(albedo=[0.4, 0.3, 0.2]) + models.TorranceSparrow(
        alpha=0.25, distribution="ggx", rho_d=0.0
    )
    return _grid_table(m, 24, 10, 12)


def _nearest_masked_table():
    """The small table with nearest lookup and a seeded fifth of its nodes masked out (the
    lookup rule of MERL files, which mark unmeasured nodes)."""
    from gonio.brdf.tabulated import TabulatedBRDF

    t = _small_table()
    mask = np.random.default_rng(3).random(np.shape(t.values)[:3]) > 0.2
    values = np.where(mask[..., None], np.asarray(t.values), 0.0)
    return TabulatedBRDF(values, t.axes, mask=mask, interpolation="nearest")


LAMBERT_ALBEDO = (0.5, 0.4, 0.3)


def _lambert_table():
    from gonio.brdf import models

    return _grid_table(models.Lambert(albedo=list(LAMBERT_ALBEDO)), 6, 4, 4)


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
        io.save(_lambert_table(), d / "lambert.brdf.h5")
        io.save(_nearest_masked_table(), d / "nearest.brdf.h5")
        names = ("table.brdf.h5", "fit.json", "run.brdf.h5", "lambert.brdf.h5", "nearest.brdf.h5")
        sources = [from_path(d / name) for name in names]
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


@pytest.mark.parametrize("k", [0, 1, 4], ids=["table", "fit", "nearest-masked"])
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


def _webgl_env(driver, k, size, frames, seed):
    px = driver.execute_script(
        "return gonioView.readEnv(arguments[0], arguments[1], arguments[2], arguments[3])",
        k, size, frames, seed,
    )  # fmt: skip
    return np.asarray(px, np.float64).reshape(size, size, 4)[..., :3]


def _lambert_under_studio(size):
    """``albedo / pi * E(n)`` per pixel (rows top first): the irradiance of the studio map
    (:func:`gonio.render.lights.studio_environment`, piecewise constant per texel) by the
    midpoint rule on each texel split 4 x 4 (float64); 0 off the sphere."""
    from gonio.render.lights import studio_environment

    env = studio_environment().astype(np.float64)
    k = 4
    h, w = env.shape[0] * k, env.shape[1] * k
    theta = np.pi * (np.arange(h) + 0.5) / h
    phi = 2 * np.pi * ((np.arange(w) + 0.5) / w - 0.5)
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    d = np.stack(np.broadcast_arrays(st * np.sin(phi), ct, -st * np.cos(phi)), -1).reshape(-1, 3)
    weight = np.repeat(np.repeat(env, k, 0), k, 1) * (st * (np.pi / h) * (2 * np.pi / w))[..., None]
    weight = weight.reshape(-1, 3)
    c = (np.arange(size) + 0.5) / size * 2 - 1
    x, y = np.meshgrid(c, -c)
    inside = x * x + y * y < 1
    n = np.stack([x[inside], y[inside], np.sqrt(1 - x[inside] ** 2 - y[inside] ** 2)], -1)
    out = np.zeros((size, size, 3))
    out[inside] = np.stack([np.maximum(d @ v, 0) @ weight for v in n])
    return out * np.asarray(LAMBERT_ALBEDO) / np.pi


ENV_SIZE, ENV_FRAMES = 16, 192  # frames: one sample per pixel each, 64 cycles of three


def test_environment_converges_to_gonio_studio_render(session):
    """Two fixed sample sequences (seeds 1 and 2, 192 samples per pixel each) measure the
    estimate's own noise: ``noise = rmse(A - B) / sqrt(2) / rms(ref)`` per image. Their mean must
    be within ``0.5 % + 2 noise / sqrt(2)`` relative RMSE of the exact value (0.5 % for the
    quadrature and float16; an unbiased mean's expected error is ``noise / sqrt(2)``), its image
    mean within 1 % of the exact one (a bias test the noise cannot hide), and the noise itself
    below 5 %."""
    driver = session[0]
    ref = _lambert_under_studio(ENV_SIZE)
    a, b = (_webgl_env(driver, 3, ENV_SIZE, ENV_FRAMES, seed) for seed in (1, 2))
    _assert_converges(a, b, ref)


def _assert_converges(a, b, ref):
    """The rule of test_environment_converges_to_gonio_studio_render."""
    noise = _rel_rmse(a, b) / math.sqrt(2)
    assert noise < 0.05, noise
    mean = (a + b) / 2
    assert _rel_rmse(mean, ref) < 0.005 + 2 * noise / math.sqrt(2), (_rel_rmse(mean, ref), noise)
    assert abs(mean.sum() / ref.sum() - 1) < 0.01, mean.sum() / ref.sum()


@pytest.mark.slow
@pytest.mark.parametrize("k", [0, 1], ids=["table", "fit"])
def test_environment_equals_render_sphere(session, k):
    """A glossy table and a fit under the studio: the same rule against ``render_sphere`` with
    ``Environment("studio")`` at 1024 samples per pixel (its own noise about 0.2 %, inside the
    0.5 % allowance)."""
    from gonio.render import render_sphere
    from gonio.render.lights import Environment

    driver, _, sources, _, _ = session
    size, frames = 48, 192
    a, b = (_webgl_env(driver, k, size, frames, seed) for seed in (1, 2))
    material = sources[k].material.material
    ref = render_sphere(material, lights=[Environment("studio")], resolution=size, spp=1024)
    _assert_converges(a, b, np.broadcast_to(np.asarray(ref, np.float64), a.shape))


def test_light_mode_toggle(session):
    """The radio buttons switch the spheres between point light, environment and both: the
    linear image of both is the sum of the other two (same light, same environment samples)."""
    from selenium.webdriver.common.by import By

    driver = session[0]
    driver.execute_script("gonioView.hold(true); gonioView.setLight([0.3, 0.2, 0.93])")
    seen = {}
    try:
        for mode in ("environment", "both", "point"):
            driver.find_element(By.CSS_SELECTOR, f"input[name=light-mode][value={mode}]").click()
            assert driver.execute_script("return gonioView.state.mode") == mode
            px = driver.execute_script("return gonioView.readView(3, 16, 6, 1)")
            seen[mode] = np.asarray(px, np.float64).reshape(16, 16, 4)[..., :3]
    finally:
        driver.execute_script("gonioView.hold(false)")
    assert seen["environment"].max() > 0 and seen["point"].max() > 0
    np.testing.assert_allclose(
        seen["both"], seen["environment"] + seen["point"], rtol=1e-5, atol=1e-7
    )


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
