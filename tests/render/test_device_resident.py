"""The render path runs on the device without host round trips or recompiles.

Once a scene's kernels are compiled and a table's sampling structures are built, a second render
with another spp, image size or light count must neither compile anything (counted over all of
JAX, not per function) nor move data implicitly between host and device (under
``jax.transfer_guard("disallow")``, where an ``np.asarray`` of a device array, a ``float()`` of
one, or a NumPy argument to a jitted call raises). The renderer's explicit uploads of tile
geometry (``device_put``) and its one ``device_get`` per render are allowed.
"""

from __future__ import annotations

import contextlib
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gonio.brdf import frames, models
from gonio.brdf.tabulated import Axis, TabulatedBRDF
from gonio.render import Directional, Environment, SphereLight, render_sphere

# an XLA compilation, or one read back from the persistent cache (tests/conftest.py turns it on)
_COMPILE_EVENTS = (
    "/jax/core/compile/backend_compile_duration",
    "/jax/compilation_cache/cache_retrieval_time_sec",
)


@contextlib.contextmanager
def compiles():
    """Counts XLA compilations inside the block: ``with compiles() as n: ...; n[0]``."""
    n = [0]

    def listener(event, duration, **kw):
        if event in _COMPILE_EVENTS:
            n[0] += 1

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        yield n
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)


def _table() -> TabulatedBRDF:
    model = models.Lambert([0.1, 0.08, 0.05]) + models.TorranceSparrow(
        alpha=0.25,
        distribution="ggx",
        fresnel=models.Conductor(eta=[0.2, 0.9, 1.1], k=[3.9, 2.4, 1.9]),
    )
    half = math.pi / 2
    axes = (
        Axis("theta_h", 24, 0.0, half, "sqrt"),
        Axis("theta_d", 16, 0.0, half),
        Axis("phi_d", 16, 0.0, math.pi, periodic=True),
    )
    return TabulatedBRDF.from_model(model, axes=axes, sampling_res=(16, 32, 64))


@pytest.fixture(scope="module")
def table() -> TabulatedBRDF:
    return _table()


def test_guard_catches_an_implicit_transfer():
    """The test's own premise: the guard raises on an implicit copy to the host."""
    x = jax.device_put(np.ones(3, np.float32))
    with jax.transfer_guard("disallow"), pytest.raises(Exception, match=r"[Dd]isallow"):
        np.asarray(x * 2)


METHODS = ["inversion", "alias", pytest.param("rejection", marks=pytest.mark.slow)]


@pytest.mark.parametrize("sampler", METHODS)
def test_table_render_has_no_host_round_trip_or_recompile(table, sampler):
    env = Environment(np.full((8, 16, 3), 0.5, np.float32))
    lights = [env, SphereLight((2.0, 2.0, 3.0), 0.5, [4.0, 3.0, 2.0])]
    dim = SphereLight((2.0, 2.0, 3.0), 0.5, 0.0)  # no light: the environment's image alone
    # every outgoing bucket built beforehand: the renders below only read the structures
    wo = frames.spherical_to_direction(np.linspace(0, 1.5707, 2000), 0.3)
    table.sampling_state(sampler, np.asarray(wo, np.float32))
    built = table.sampling_cache_size(sampler)
    render_sphere(table, lights, resolution=16, spp=16, sampler=sampler)
    with compiles() as n, jax.transfer_guard("disallow"):
        render_sphere(table, lights + lights[1:], resolution=18, spp=5, sampler=sampler)
        img = render_sphere(table, [env, dim], resolution=16, spp=33, sampler=sampler, seed=1)
    assert n[0] == 0
    assert table.sampling_cache_size(sampler) == built
    # a constant environment of 0.5 on the table: L = 0.5 * albedo, within noise
    hit = img[..., 0] > 0
    albedo = np.asarray(table.directional_albedo(jnp.array([0.0, 0.0, 1.0])))
    assert abs(img[hit].mean(axis=0)[1] / (0.5 * albedo[1]) - 1) < 0.15


def test_table_delta_lights_on_the_device(table):
    """Tables under delta lights: one jitted kernel for any light count (no host evaluation),
    exact and additive."""
    lights = [Directional.from_angles(0.2 * k, 0.9 * k, 1.0 + k) for k in range(4)]
    render_sphere(table, lights[:1], resolution=12)
    with compiles() as n, jax.transfer_guard("disallow"):
        both = render_sphere(table, lights[:2], resolution=14)
        render_sphere(table, lights, resolution=12)
    assert n[0] == 0
    singles = [render_sphere(table, [lt], resolution=14) for lt in lights[:2]]
    np.testing.assert_allclose(both, singles[0] + singles[1], rtol=1e-5, atol=1e-7)


def test_grey_and_coloured_lights_share_kernels():
    """A grey light next to coloured ones of its kind is the same kernel shape (broadcast), and
    the same light: the image of a grey light equals that of its value repeated per channel."""
    mat = models.Lambert([0.5, 0.4, 0.3])
    rgb = [
        SphereLight((3.0, 0.0, 2.0), 0.5, [5.0, 4.0, 3.0]),
        Directional((0, 0.6, 0.8), [1, 2, 3]),
    ]
    grey = [SphereLight((-3.0, 0.0, 2.0), 0.5, 4.0), Directional((0.6, 0, 0.8), 2.0)]
    render_sphere(mat, rgb, resolution=12, spp=16)
    with compiles() as n:
        mixed = render_sphere(mat, [rgb[0], grey[0], rgb[1], grey[1]], resolution=12, spp=16)
    assert n[0] == 0
    assert np.all(np.isfinite(mixed)) and mixed.max() > 0
    spelled = [SphereLight((-3.0, 0.0, 2.0), 0.5, [4.0] * 3), Directional((0.6, 0, 0.8), [2.0] * 3)]
    np.testing.assert_array_equal(
        render_sphere(mat, grey, resolution=12, spp=16),
        render_sphere(mat, spelled, resolution=12, spp=16),
    )


@pytest.mark.parametrize("method", METHODS)
def test_traced_table_sampling_from_a_state(table, method):
    """``sampling_state`` + ``state=``: one jitted call with the structures as arguments, the
    same samples as the eager call, and no host transfer inside."""
    rng = np.random.default_rng(4)
    wo = np.asarray(frames.spherical_to_direction(rng.uniform(0, 1.4, 400), 0.7), np.float32)
    u = rng.random((400, 2)).astype(np.float32)
    state = table.sampling_state(method, wo)
    fn = jax.jit(lambda st, w, uu: table.sample(w, uu, method=method, state=st))
    pdf_fn = jax.jit(lambda st, wi, w: table.pdf(wi, w, method=method, state=st))
    wo_d, u_d = jax.device_put(wo), jax.device_put(u)
    fn(state, wo_d, u_d)
    with jax.transfer_guard("disallow"):
        s = fn(state, wo_d, u_d)
        p = pdf_fn(state, s.wi, wo_d)
    eager = table.sample(wo, u, method=method)
    s, p = jax.device_get((s, p))
    np.testing.assert_allclose(s.wi, np.asarray(eager.wi), rtol=2e-5, atol=2e-6)
    ok = s.pdf > 0
    assert ok.mean() > 0.99
    np.testing.assert_allclose(s.pdf, np.asarray(eager.pdf), rtol=2e-4)
    np.testing.assert_allclose(p[ok], s.pdf[ok], rtol=1e-5)
