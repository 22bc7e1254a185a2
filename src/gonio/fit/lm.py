"""Box-projected Levenberg–Marquardt for ``min_u L(u) = sum r(u)^2`` on compiled normal equations.

Hand-written (rather than scipy.optimize.least_squares) because scipy needs the full M x P
Jacobian in host memory at every step, which on a MERL table (M ~ 3e6) is the dominant cost.
Here every iteration makes exactly one call of the compiled ``normal(u) -> (L, g, A)`` (see
:mod:`gonio.fit.objective`: ``A = J^T J`` and ``g = J^T r`` accumulated in chunks with one
forward-mode Jacobian pass); the P x P algebra runs on the host. The trial point's normal
equations are computed directly, so an accepted step (the usual case near the optimum) needs no
second pass. (The loop is not a ``lax.while_loop``: inside one, XLA copies the loop-invariant
data through the loop and its branches, which costs more than the host round trip per step.)

Step: solve ``(A + lam * D) delta = -g`` with Marquardt's scaling ``D = diag(A)`` (floored)
over the free parameters, project ``u + delta`` onto the box, accept when the gain ratio (actual
over predicted decrease) exceeds 1e-4, and update ``lam`` with Nielsen's rule. A parameter on a
bound whose descent direction ``-g`` points out of the box is held there for the step (its row
and column are left out of the solve: projected Newton, Bertsekas 1982). Without that, the
solve spends the step on the held parameter and its coupling bends every other one, so that the
clipped step is poor: on a metal whose Cook-Torrance ``f0`` ends on 1 the polish on every cell
took several times the passes over the data of a fit inside the box, and the stages on
subsets stopped early on steps whose clipped gain was tiny (``benchmarks/bench_published.py``
fits such metals). Stops when an accepted step lowers the loss by less than ``ftol``
relatively or the next step is predicted to, when a step is shorter than ``xtol`` relative to
``|u|``, when ``lam`` exceeds 1e14, or after ``max_iter`` accepted steps.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

CONVERGED_F, CONVERGED_X, STALLED, MAX_ITER = 1, 2, 3, 4
STATUS_TEXT = {
    CONVERGED_F: "converged (relative cost change below ftol)",
    CONVERGED_X: "converged (step below xtol)",
    STALLED: "stopped: no further decrease possible (damping limit)",
    MAX_ITER: "stopped: iteration limit reached",
}

Normal = Callable[[np.ndarray], tuple[float, np.ndarray, np.ndarray]]


@dataclass
class LMResult:
    """``u`` (P,), ``cost`` L, accepted iterations ``it``, ``n_eval`` normal-equation calls,
    ``status`` (one of the constants above) and the loss after each call (``history``)."""

    u: np.ndarray
    cost: float
    it: int
    n_eval: int
    status: int
    history: list[float]


def _held(u: np.ndarray, g: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Parameters on a bound that the descent direction ``-g`` would push out of the box."""
    return ((u <= lo) & (g > 0)) | ((u >= hi) & (g < 0))


def _trial(
    u: np.ndarray, g: np.ndarray, a: np.ndarray, lam: float, lo: np.ndarray, hi: np.ndarray
) -> np.ndarray:
    """The trial point: a damped Newton step from ``u`` over the free parameters, clipped to
    the box (so that a parameter stepped onto a bound is exactly on it)."""
    free = ~_held(u, g, lo, hi)
    d = np.diag(a).copy()
    d = np.maximum(d, 1e-12 * max(float(d.max(initial=0.0)), 1e-300))
    h = a[np.ix_(free, free)] + lam * np.diag(d[free])
    delta = np.zeros_like(u)
    try:
        delta[free] = np.linalg.solve(h, -g[free])
    except np.linalg.LinAlgError:
        delta[free] = np.linalg.lstsq(h, -g[free], rcond=None)[0]
    delta = np.where(np.isfinite(delta), delta, 0.0)
    return np.clip(u + delta, lo, hi)


def _predicted(g: np.ndarray, a: np.ndarray, step: np.ndarray) -> float:
    """Decrease of the quadratic model ``L + 2 g.s + s.A.s`` along ``step``."""
    return float(-(2.0 * g @ step + step @ a @ step))


def _next_gain(
    u: np.ndarray, g: np.ndarray, a: np.ndarray, lam: float, lo: np.ndarray, hi: np.ndarray
) -> float:
    """Decrease of the quadratic model predicted for the next (projected) step."""
    return _predicted(g, a, _trial(u, g, a, lam, lo, hi) - u)


def levenberg_marquardt(
    normal: Normal,
    u0: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    max_iter: int = 200,
    ftol: float = 1e-10,
    xtol: float = 1e-9,
    lam0: float = 1e-3,
) -> LMResult:
    """Minimize from ``u0`` inside the box ``[lo, hi]``; see the module docstring."""
    u = np.clip(np.asarray(u0, dtype=np.float64), lo, hi)
    cost, g, a = normal(u)
    history = [cost]
    lam, nu = lam0, 2.0
    it = n_eval = 0
    n_eval = 1
    status = MAX_ITER
    if not np.isfinite(cost):
        return LMResult(u, cost, 0, n_eval, STALLED, history)
    while it < max_iter:
        u_new = _trial(u, g, a, lam, lo, hi)
        step = u_new - u
        small_step = np.linalg.norm(step) <= xtol * (np.linalg.norm(u) + xtol)
        if small_step:
            status = CONVERGED_X
            break
        c_new, g_new, a_new = normal(u_new)
        n_eval += 1
        history.append(c_new)
        predicted = _predicted(g, a, step)
        actual = cost - c_new
        rho = actual / predicted if predicted > 0 else -np.inf
        if np.isfinite(c_new) and actual > 0 and rho > 1e-4:
            lam *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            nu = 2.0
            converged = actual <= ftol * cost
            u, cost, g, a = u_new, c_new, g_new, a_new
            it += 1
            if converged or _next_gain(u, g, a, lam, lo, hi) <= ftol * cost:
                # (the second test saves a pass: the next step could not gain more than ftol)
                status = CONVERGED_F
                break
        else:
            lam *= nu
            nu *= 2.0
            if lam > 1e14:
                status = STALLED
                break
    return LMResult(u, float(cost), it, n_eval, status, history)
