"""Rendering tabulated BRDFs: accuracy against the tabulated model, every table sampler, skips."""

import numpy as np
import pytest

from gonio.brdf import models
from gonio.errors import ParameterError
from gonio.render import Camera, Directional, Environment, RenderStats, SphereLight, render_sphere
from tests.render.helpers import block_means, ortho_normals, seed_stack, z_scores

tabulated = pytest.importorskip("gonio.brdf.tabulated")
needs_samplers = pytest.mark.skipif(
    not hasattr(tabulated.TabulatedBRDF, "sample"), reason="table samplers not available yet"
)


def _glossy():
    ts, conductor = getattr(models, "TorranceSparrow", None), getattr(models, "Conductor", None)
    if ts is None or conductor is None:
        return models.Lambert([0.1, 0.08, 0.05]) + models.Phong(rho_d=0.0, rho_s=0.5, n=40.0)
    return models.Lambert([0.1, 0.08, 0.05]) + ts(
        alpha=0.2,
        distribution="beckmann",
        fresnel=conductor(eta=[0.2, 0.9, 1.1], k=[3.9, 2.4, 1.9]),
    )


@pytest.fixture(scope="module")
def glossy_pair():
    model = _glossy()
    return model, tabulated.TabulatedBRDF.merl_like(model)


def _rel_rmse(a, b, mask):
    d = (a - b)[mask].astype(np.float64)
    return np.sqrt(np.mean(d**2)) / np.sqrt(np.mean(b[mask].astype(np.float64) ** 2))


def test_dense_table_renders_like_its_model(glossy_pair):
    """MERL-density table of a glossy model within 1% relative RMSE of the model's rendering.

    Directional light: both renders are exact (no noise), so the difference is the table's
    interpolation error alone. Studio with cosine sampling + MIS: the sample directions do not
    depend on the material, so both renders use the same directions and noise cancels too.
    """
    model, table = glossy_pair
    n = 32
    _, hit = ortho_normals(n)
    light = Directional((0.3, 0.4, 0.87), 2.0)
    a = render_sphere(table, light, resolution=n)
    b = render_sphere(model, light, resolution=n)
    assert _rel_rmse(a, b, hit) < 0.01
    env = Environment("studio")
    a = render_sphere(table, env, resolution=n, spp=16, sampler="cosine")
    b = render_sphere(model, env, resolution=n, spp=16, sampler="cosine")
    assert _rel_rmse(a, b, hit) < 0.01


@needs_samplers
@pytest.mark.slow
def test_table_samplers_converge_to_the_same_image(glossy_pair):
    """Inversion, alias, rejection (majorant proposal) and analytic-lobe sampling of
    a table, with and without MIS, against cosine+MIS: 4x4 block means over 16 seeds (48
    without MIS), |z| < 6 (Student t; < 1% false alarms over all comparisons).

    Without MIS, BRDF sampling alone finds the studio's small bright panels rarely: a block's
    mean over seeds is then heavy-tailed, and over 16 seeds that none of them hit is likely
    enough (a few percent per block) to make the spread, and so the z test, meaningless. 48
    seeds make that rare; the means themselves agree (e.g. 0.0224 +- 0.0037 against 0.0262
    for the block where 16 seeds of majorant rejection saw no hit)."""
    model, table = glossy_pair
    lights = [Environment("studio"), SphereLight((-2, 2, 3), 0.5, 5.0)]
    kw = dict(resolution=16, spp=16)
    ref = block_means(seed_stack(table, lights, 16, sampler="cosine", **kw), 4)
    cases = [
        ("inversion", {}), ("alias", {}), ("rejection", {}), ("brdf", {"proposal": model}),
    ]  # fmt: skip
    for sampler, extra in cases:
        for mis in (True, False):
            k = 16 if mis else 48
            other = block_means(seed_stack(table, lights, k, sampler=sampler, mis=mis, **extra,
                                           **kw), 4)  # fmt: skip
            z = z_scores(other, ref)
            assert np.max(np.abs(z)) < 6, (sampler, extra, mis, np.max(np.abs(z)))


_QUICK_STACK = dict(resolution=16, spp=16)


@pytest.fixture(scope="module")
def cosine_means(glossy_pair):
    """Per-seed sphere means of the cosine-sampled table (4 seeds): the reference of every
    sampler in the quick test, rendered once."""
    _, table = glossy_pair
    stack = seed_stack(table, Environment("studio"), 4, sampler="cosine", **_QUICK_STACK)
    return stack.mean(axis=(1, 2))


@needs_samplers
@pytest.mark.parametrize("sampler", ["inversion", "alias", "rejection"])
def test_table_sampler_matches_model_image_on_average(glossy_pair, cosine_means, sampler):
    """Quick version of the slow test: the mean over the sphere of 4 seeds agrees with the
    cosine-sampled image of the same table within 5 standard errors."""
    _, table = glossy_pair
    env = Environment("studio")
    a = seed_stack(table, env, 4, sampler=sampler, **_QUICK_STACK).mean(axis=(1, 2))
    z = z_scores(a, cosine_means)
    assert np.max(np.abs(z)) < 5


def test_rejection_refuses_an_analytic_proposal(glossy_pair):
    """Rejection proposes from the table's own rigorous majorant: proposal= is for the
    analytic-lobe strategy (sampler="brdf") only, and any other sampler refuses it."""
    model, table = glossy_pair
    for sampler in ("rejection", "inversion"):
        with pytest.raises(ParameterError, match="sampler='brdf' only"):
            render_sphere(table, Environment(1.0), resolution=4, spp=1, sampler=sampler,
                          proposal=model)  # fmt: skip


@needs_samplers
def test_sampling_structures_only_for_outgoing_directions_in_view(glossy_pair):
    _, table0 = glossy_pair
    table = table0.replace()  # fresh lazy caches
    if not hasattr(table, "sampling_cache_size"):
        pytest.skip("table does not report its sampling caches")
    st = RenderStats()
    # Delta lights never need BRDF sampling: nothing is built.
    render_sphere(table, Directional((0, 0, 1)), resolution=16, stats=st)
    assert table.sampling_cache_size("inversion") == 0
    # A narrow perspective view of the sphere's centre sees theta_o up to ~20 degrees only.
    render_sphere(table, Environment("studio"), resolution=16, spp=4,
                  camera=Camera.perspective(distance=4.0, fov_deg=5.0))  # fmt: skip
    narrow = table.sampling_cache_size("inversion")
    assert narrow > 0
    render_sphere(table, Environment("studio"), resolution=16, spp=4)
    assert table.sampling_cache_size("inversion") > narrow


def test_table_channel_selection(glossy_pair):
    _, table = glossy_pair
    light = [Directional((0.3, 0.4, 0.87), 2.0)]
    full = render_sphere(table, light, resolution=16)
    one = render_sphere(table, light, resolution=16, channels=[1])
    assert one.shape == (16, 16, 1)
    np.testing.assert_allclose(one[..., 0], full[..., 1], rtol=1e-5, atol=1e-7)


def test_any_material_takes_an_analytic_proposal():
    """Lobe sampling is a generic wrapper (gonio.brdf.sampled.LobeSampled), not a table
    branch: a Lambert sphere sampled by another Lambert lobe under a uniform environment,
    without MIS, has weight f cos / pdf = albedo on every sample, so every pixel is exact."""
    _, hit = ortho_normals(8)
    img = render_sphere(models.Lambert(0.3), Environment(1.0), resolution=8, spp=4,
                        sampler="brdf", proposal=models.Lambert(0.7), mis=False)  # fmt: skip
    np.testing.assert_allclose(img[hit][..., 0], 0.3, rtol=1e-5)
    mirror = models.Lambert(0.3) + models.SpecularReflection()
    with pytest.raises(ParameterError, match="delta"):
        render_sphere(mirror, Environment(1.0), resolution=4, spp=1, sampler="brdf",
                      proposal=models.Lambert(0.7))  # fmt: skip
