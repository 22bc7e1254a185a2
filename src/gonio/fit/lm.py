"""A compiled, box-projected Levenberg–Marquardt solver for ``min_u sum r(u)^2``.

Hand-written (rather than scipy.optimize.least_squares) so that the whole iteration runs inside
one ``jax.jit``/``lax.while_loop`` with the normal equations accumulated in chunks (see
:mod:`gonio.fit.objective`): scipy would need the full M x P Jacobian in host memory at every
step, which on a MERL table is the dominant cost. The same function is ``vmap``-ed over starting
points for multi-start on a subsample.

Step: solve ``(A + lam * D) delta = -g`` with ``A = J^T J``, ``g = J^T r`` and Marquardt's
scaling ``D = diag(A)`` (floored), project ``u + delta`` onto the box, accept when the gain
ratio (actual over predicted decrease) exceeds 1e-4, and update ``lam`` with Nielsen's rule.
Stops when an accepted step lowers the cost by less than ``ftol`` relatively, when a step is
shorter than ``xtol`` relative to ``|u|``, when ``lam`` exceeds 1e14, or after ``max_iter``
Jacobian evaluations.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

Array = jnp.ndarray

RUNNING, CONVERGED_F, CONVERGED_X, STALLED, MAX_ITER = 0, 1, 2, 3, 4
STATUS_TEXT = {
    RUNNING: "running",
    CONVERGED_F: "converged (relative cost change below ftol)",
    CONVERGED_X: "converged (step below xtol)",
    STALLED: "stopped: no further decrease possible (damping limit)",
    MAX_ITER: "stopped: iteration limit reached",
}


class LMState(NamedTuple):
    u: Array
    cost: Array
    g: Array
    a: Array
    lam: Array
    nu: Array
    it: Array
    n_eval: Array
    status: Array


def make_lm(cost_fn: Any, normal_fn: Any) -> Any:
    """Build ``lm(u0, arrays, tmpl, lo, hi, max_iter, ftol, xtol) -> LMState`` (not jitted).

    ``cost_fn(u, arrays, tmpl) -> L`` and ``normal_fn(u, arrays, tmpl) -> (L, g, A)`` are the
    raw (unjitted) objective functions of :class:`~gonio.fit.objective.Compiled`.
    """

    def lm(
        u0: Array, arrays: Any, tmpl: Any, lo: Array, hi: Array, max_iter: Any, ftol: Any, xtol: Any
    ) -> LMState:
        c0, g0, a0 = normal_fn(u0, arrays, tmpl)
        dt = u0.dtype
        state = LMState(
            u0,
            c0,
            g0,
            a0,
            jnp.asarray(1e-3, dt),
            jnp.asarray(2.0, dt),
            jnp.asarray(0, jnp.int32),
            jnp.asarray(1, jnp.int32),
            jnp.asarray(RUNNING, jnp.int32),
        )

        def cond(s: LMState) -> Array:
            return (s.status == RUNNING) & (s.it < max_iter)

        def body(s: LMState) -> LMState:
            d = jnp.diag(s.a)
            d = jnp.maximum(d, 1e-12 * jnp.maximum(jnp.max(d), 1e-300))
            h = s.a + s.lam * jnp.diag(d)
            delta = jnp.linalg.solve(h, -s.g)
            delta = jnp.where(jnp.isfinite(delta), delta, 0.0)
            u_new = jnp.clip(s.u + delta, lo, hi)
            step = u_new - s.u
            c_new = cost_fn(u_new, arrays, tmpl)
            predicted = -(2.0 * jnp.dot(s.g, step) + step @ s.a @ step)
            actual = s.cost - c_new
            rho = actual / jnp.where(predicted > 0, predicted, jnp.inf)
            accept = jnp.isfinite(c_new) & (actual > 0) & (rho > 1e-4)
            small_step = jnp.linalg.norm(step) <= xtol * (jnp.linalg.norm(s.u) + xtol)
            lam_acc = s.lam * jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            lam = jnp.where(accept, lam_acc, s.lam * s.nu)
            nu = jnp.where(accept, 2.0, 2.0 * s.nu)
            c2, g2, a2 = jax.lax.cond(
                accept,
                lambda: normal_fn(u_new, arrays, tmpl),
                lambda: (s.cost, s.g, s.a),
            )
            status = jnp.where(
                accept & (actual <= ftol * s.cost),
                CONVERGED_F,
                jnp.where(small_step, CONVERGED_X, jnp.where(lam > 1e14, STALLED, RUNNING)),
            ).astype(jnp.int32)
            it = s.it + accept.astype(jnp.int32)
            status = jnp.where((status == RUNNING) & (it >= max_iter), MAX_ITER, status)
            return LMState(
                jnp.where(accept, u_new, s.u),
                c2,
                g2,
                a2,
                jnp.minimum(lam, 1e16),
                jnp.minimum(nu, 1e8),
                it,
                s.n_eval + 1,
                status.astype(jnp.int32),
            )

        out = jax.lax.while_loop(cond, body, state)
        final = jnp.where(out.status == RUNNING, MAX_ITER, out.status).astype(jnp.int32)
        return out._replace(status=final)

    return lm
