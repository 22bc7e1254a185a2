"""The render kernels compile once per material kind and scene kind, not per spp, image size or
number of delta lights (each compilation costs seconds on a small CPU)."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.models import Lambert
from gonio.render import integrator
from gonio.render.lights import Directional, Environment


def _sizes() -> tuple[int, ...]:
    return (
        integrator._light_stage_jit._cache_size(),
        integrator._model_stage._cache_size(),
        integrator._shade_stage._cache_size(),
        integrator._delta_kernel_model._cache_size(),
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
