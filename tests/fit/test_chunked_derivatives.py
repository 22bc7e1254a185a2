"""The gradient and Hessian programs, sums of per-chunk derivatives in one scan
(gonio.fit.objective.chunk_sum), equal JAX's derivatives of the whole-scan cost."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gonio.fit.data import from_arrays
from gonio.fit.losses import get_loss
from gonio.fit.objective import Problem, chunk_sum
from gonio.fit.params import Layout
from gonio.fit.presets import build


def _problem(loss: str) -> Problem:
    rng = np.random.default_rng(11)
    n = 700
    wi, wo = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]) + 0.2, np.abs(wo[:, 2]) + 0.2
    data = from_arrays(wi, wo, rng.random((n, 3)) * 2.0 + 0.05, weights=rng.random(n) + 0.5)
    tmpl, fixed, tied = build("lambert+cook-torrance")
    # chunks of 256 rows: three chunks, the last one padded
    return Problem(Layout(tmpl, 3, fixed=fixed, tied=tied), get_loss(loss), data, chunk=256)


def _whole_scan_cost(pb: Problem):
    """``sum r^2`` as one plain scan over the chunks (built here, independent of chunk_sum)."""

    def cost(u, arrays, tmpl):
        def step(acc, c):
            r = pb.fns.chunk_res(u, c, tmpl)
            return acc + jnp.dot(r, r), None

        return jax.lax.scan(step, jnp.zeros((), u.dtype), arrays)[0]

    return cost


@pytest.mark.parametrize("loss", ["ngan", "wls", "low-e2"])
def test_gradient_and_hessian_equal_those_of_the_whole_scan(loss):
    pb = _problem(loss)
    assert pb.n_chunks == 3 and pb.n_chunks * pb.chunk_rows > pb.data.n
    whole = _whole_scan_cost(pb)
    # jitted once (the template static): eagerly, every call traces and compiles the scan again
    ref_vg = jax.jit(jax.value_and_grad(whole), static_argnums=2)
    ref_h = jax.jit(jax.hessian(whole), static_argnums=2)
    for u in pb.layout.random_starts(3, 4):
        args = (jnp.asarray(u), pb.arrays, pb.layout.template)
        want_v, want_g = ref_vg(*args)
        want_h = np.asarray(ref_h(*args))
        v, g = pb.value_and_grad(u)
        v2, g2 = pb.value_and_grad_scored(u)
        h = pb.hessian(u)
        scale = np.abs(want_g).max()
        np.testing.assert_allclose(v, float(want_v), rtol=1e-13)
        np.testing.assert_allclose(v2, float(want_v), rtol=1e-13)
        np.testing.assert_allclose(g, want_g, rtol=1e-12, atol=1e-13 * scale)
        np.testing.assert_allclose(g2, want_g, rtol=1e-12, atol=1e-13 * scale)
        assert h.shape == (pb.n_params, pb.n_params)
        np.testing.assert_allclose(h, want_h, rtol=1e-11, atol=1e-12 * np.abs(want_h).max())


def test_chunk_sum_sums_every_chunk_of_a_pytree():
    xs = {"a": jnp.arange(12.0).reshape(4, 3), "b": (jnp.ones((4, 2, 2)), None)}

    def fn(c):
        return c["a"].sum(), {"m": c["b"][0] * c["a"][0]}

    total, rest = jax.jit(lambda x: chunk_sum(fn, x))(xs)
    assert float(total) == 66.0
    np.testing.assert_array_equal(np.asarray(rest["m"]), np.full((2, 2), 0.0 + 3 + 6 + 9))
