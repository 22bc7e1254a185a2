"""The render kernels compile once per material kind and scene kind, not per spp, image size or
number of delta, area or environment lights (each compilation costs seconds on a small CPU)."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.models import Lambert
from gonio.render import delta, integrator
from gonio.render.lights import Directional, Environment, SphereLight


def _sizes() -> tuple[int, ...]:
    return (
        integrator._light_stage_jit._cache_size(),
        integrator._model_stage._cache_size(),
        integrator._shade_stage._cache_size(),
        delta.delta_kernel_model._cache_size(),
    )


@pytest.fixture
def env() -> Environment:
    return Environment(np.full((8, 16, 1), 0.5, np.float32))


def test_spp_and_size_reuse_one_kernel(env):
    mat = Lambert(albedo=0.3)
    integrator.render_sphere(mat, [env], resolution=12, spp=3)
    before = _sizes()
    a = integrator.render_sphere(mat, [env], resolution=12, spp=5)
    b = integrator.render_sphere(mat, [env], resolution=14, spp=17)
    assert _sizes() == before
    # A constant environment of radiance 0.5 on a Lambertian sphere: L = albedo * 0.5 (the
    # padded samples carry zero weight: a wrong mask would scale the mean by spp / 16).
    for img in (a, b):
        hit = img[..., 0] > 0
        assert abs(img[hit, 0].mean() - 0.15) < 0.005


def test_delta_light_count_reuses_one_kernel():
    mat = Lambert(albedo=0.5)
    lights = [Directional.from_angles(0.3 * k, 0.7 * k, 1.0) for k in range(5)]
    integrator.render_sphere(mat, lights[:1], resolution=10, spp=1)
    before = _sizes()
    imgs = [integrator.render_sphere(mat, lights[:k], resolution=10, spp=1) for k in (2, 3, 5)]
    assert _sizes() == before
    # Delta lights are exact and additive: k lights give the sum of the single-light images.
    singles = [integrator.render_sphere(mat, [lt], resolution=10, spp=1) for lt in lights]
    np.testing.assert_allclose(imgs[2], sum(singles), rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(imgs[0], singles[0] + singles[1], rtol=1e-5, atol=1e-7)


def test_area_light_count_reuses_one_kernel():
    mat = Lambert(albedo=0.5)
    spheres = [
        SphereLight((3.0 * np.cos(a), 3.0 * np.sin(a), 2.0), 0.5, 5.0) for a in (0, 0.8, 1.6, 2.4)
    ]
    integrator.render_sphere(mat, spheres[:1], resolution=12, spp=64)
    before = _sizes()
    imgs = {k: integrator.render_sphere(mat, spheres[:k], resolution=12, spp=64) for k in (2, 4)}
    assert _sizes() == before
    # One light sample per pixel sample, the light chosen uniformly: unbiased for the sum of the
    # lights (a missing 1/count in the pdf would scale the image by count, a wrong MIS weight
    # by a few tens of per cent). Tolerance: 3 % of the mean, ~6 standard errors here.
    singles = [integrator.render_sphere(mat, [s], resolution=12, spp=256) for s in spheres]
    for k, img in imgs.items():
        ref = sum(singles[:k])
        hit = ref[..., 0] > 0
        assert abs(img[hit].mean() / ref[hit].mean() - 1.0) < 0.03, k


def test_environment_count_reuses_one_kernel():
    mat = Lambert(albedo=0.5)
    rng = np.random.default_rng(3)
    envs = [Environment(rng.random((8, 16, 3)).astype(np.float32)) for _ in range(3)]
    integrator.render_sphere(mat, envs[:1], resolution=12, spp=4)
    before = _sizes()
    two = integrator.render_sphere(mat, envs[:2], resolution=12, spp=4)
    three = integrator.render_sphere(mat, envs, resolution=12, spp=4)
    assert _sizes() == before
    # Environments of one size are merged into one light with the summed image: the very same
    # samples as a render of the sum.
    total = Environment(sum(np.asarray(e.image) for e in envs))
    np.testing.assert_array_equal(
        three, integrator.render_sphere(mat, [total], resolution=12, spp=4)
    )
    assert two.mean() < three.mean()
