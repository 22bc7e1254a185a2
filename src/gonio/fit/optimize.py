"""Optimizers: multi-start Levenberg–Marquardt, nlopt global search and nlopt local polish.

Strategy of :func:`optimize` (every step seeded, nothing to restart by hand):

1. On a random subsample of at most ``subsample`` samples (fixed seed), optionally run an nlopt
   global method (``"crs2"``: controlled random search with local mutation; ``"mlsl"``:
   multi-level single linkage with L-BFGS local searches; ``"direct"``: DIRECT-L) inside the
   box of the reparameterized space (see :mod:`gonio.fit.params`).
2. From ``n_starts`` points (the template's values, the global result, and uniform random points
   of the start box) run the chosen local method on the subsample, one start after the other
   (each LM iteration is one jitted normal-equation pass over the subsample).
3. On data larger than twice ``refine`` samples, run the local method from the best start to
   convergence on a stratified subset of ``refine`` samples (one per theta_h stratum, see
   :meth:`~gonio.fit.data.FitData.stratified_subset`): on a MERL table (about 9e5 cells) this
   does the bulk of the descent at a fourteenth of the cost. The starts' stage and this one
   stop at a relative loss change of 1e-7 (their optima differ from the full data's by more).
4. Polish the best on the full data with the local method: ``"lm"`` (Levenberg–Marquardt on the
   JAX Jacobian, the default: every loss is a sum of squares), ``"lbfgs"`` or ``"slsqp"``
   (nlopt's LD_LBFGS / LD_SLSQP with exact JAX gradients). After step 3, LM takes the loss and
   its gradient from every sample (one reverse-mode pass each) and the curvature from the
   subset's exact Hessian at its optimum (:func:`subset_hessian`), and stops at a relative
   change of 1e-8: typically two passes over the data. The passes after the first also sum
   every loss's score at their point, so that the fit's reported metrics need no pass of
   their own when the last pass is at the optimum (the usual case).
5. If the polish did not meet its tolerance, restart it from where it stopped (at most
   ``max_restarts`` times).
6. While steps 1-2 run, two background threads compile (or load from the compilation cache)
   the programs of steps 3-4 (:meth:`~gonio.fit.programs.Program.prepare`); a stage that needs
   one before it is ready waits for it.

Parameters that end on the edge of the search box are reported in ``on_bounds``.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field

import nlopt
import numpy as np

from gonio.errors import FitError
from gonio.fit.lm import CONVERGED_F, CONVERGED_X, STALLED, STATUS_TEXT, levenberg_marquardt
from gonio.fit.objective import Problem

LOCAL_METHODS = ("lm", "lbfgs", "slsqp")
GLOBAL_METHODS = ("crs2", "mlsl", "direct")

#: Relative loss change at which the intermediate stages on subsets stop (the stage after
#: them corrects the rest; their optimum differs from the full data's by more than this).
_STAGE_FTOL = 1e-7

#: Relative loss change at which the staged polish on every sample stops: it starts from the
#: subset's optimum with the subset's Hessian, typically within 1e-8 of the optimum after one
#: step, so this test usually ends it after two passes over the data (three to six with the
#: plain path's 1e-10 and Gauss–Newton curvature).
_POLISH_FTOL = 1e-8

_NLOPT_LOCAL = {"lbfgs": nlopt.LD_LBFGS, "slsqp": nlopt.LD_SLSQP}
_NLOPT_GLOBAL = {"crs2": nlopt.GN_CRS2_LM, "mlsl": nlopt.G_MLSL_LDS, "direct": nlopt.GN_DIRECT_L}


@dataclass
class OptimResult:
    """Outcome of :func:`optimize`.

    Attributes
    ----------
    u : (P,) optimum in the reparameterized space.
    cost : ``L = sum r^2`` at ``u`` on the full data.
    converged : whether the final local method met its tolerance.
    message : the final method's stopping reason.
    method, global_method : what ran.
    n_iter : iterations (LM: Jacobian evaluations; nlopt: objective evaluations) of the polish.
    on_bounds : flat parameter names ending on their box edge.
    starts : costs of the multi-start runs on the subsample (best first).
    timings : seconds per stage (``global``, ``starts``, ``polish``, ``total``).
    """

    u: np.ndarray
    cost: float
    converged: bool
    message: str
    method: str
    global_method: str | None
    n_iter: int
    on_bounds: list[str]
    starts: list[float] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)


# -- LM ------------------------------------------------------------------------------------------
def run_lm(
    problem: Problem,
    u0: np.ndarray,
    max_iter: int = 200,
    ftol: float = 1e-10,
    xtol: float = 1e-9,
    normal: Callable[[np.ndarray], tuple[float, np.ndarray, np.ndarray]] | None = None,
) -> tuple[np.ndarray, float, int, int]:
    """Levenberg–Marquardt from ``u0`` (P,) or from several starts (S, P), one after the other.

    ``normal``: the normal equations to use instead of ``problem.normal`` (e.g. the full
    data's gradient with a subset's curvature, :func:`subset_curvature`).

    Returns ``(u, cost, n_iter, status)``; with several starts, arrays over starts.
    """
    lo, hi = problem.layout.box()
    u0 = np.asarray(u0, np.float64)
    starts = u0[None] if u0.ndim == 1 else u0
    normal = problem.normal if normal is None else normal
    outs = []
    for s in starts:
        r = levenberg_marquardt(normal, s, lo, hi, max_iter, ftol, xtol)
        outs.append((r.u, r.cost, r.it, r.status))
    if u0.ndim == 1:
        return outs[0]
    return tuple(np.array([o[i] for o in outs]) for i in range(4))  # type: ignore[return-value]


def subset_curvature(
    problem: Problem, sub: Problem, hessian: np.ndarray | None = None
) -> Callable[[np.ndarray], tuple[float, np.ndarray, np.ndarray]]:
    """Normal equations ``u -> (L, g, A)`` with ``L`` and ``g = J^T r`` of ``problem`` (all the
    data: one reverse-mode pass, about a third of the cost of the forward-mode Jacobian) and
    ``A`` from ``sub`` (a subset: the curvature only sets the step, so an estimate of it
    changes the path, not the optimum, where the full gradient vanishes): ``hessian`` (P x P,
    on the scale of ``A``, i.e. half the Hessian of ``L``) when given, else ``J^T J`` of ``sub``
    at every step. The losses that normalize by the total weight (every loss but ``wls``) give
    subset sums on the scale of the full ones; ``wls`` sums are scaled by the sample ratio."""
    factor = problem.data.n / sub.data.n if problem.loss.value_kind == "chi2" else 1.0
    calls = [0]

    def normal(u: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        # from the second pass on, each may be the last: it also computes the score sums at
        # its point (kept by the problem), so the fit's score pass is not a pass of its own
        pass_ = problem.value_and_grad_scored if calls[0] else problem.value_and_grad
        calls[0] += 1
        cost, grad = pass_(u)
        a = hessian if hessian is not None else sub.normal(u)[2]
        return cost, 0.5 * grad, factor * a

    return normal


def subset_hessian(sub: Problem, u: np.ndarray) -> np.ndarray | None:
    """Half the exact Hessian of the subset's loss at ``u`` (the scale of ``J^T J``), or None
    where it is not finite and positive definite (far from an optimum).

    Why the exact Hessian and not ``J^T J``: the fits of real tables have large residuals
    (model misfit), where Gauss–Newton converges only linearly (on MERL tables about tenfold
    per pass over the data); with the subset's full Hessian one pass takes the loss from the
    subset's optimum (1e-6 to 1e-5 above the full data's) to within about 1e-8 of it."""
    h = 0.5 * sub.hessian(u)
    h = 0.5 * (h + h.T)
    if not np.all(np.isfinite(h)):
        return None
    try:
        np.linalg.cholesky(h)
    except np.linalg.LinAlgError:
        return None
    return h


# -- nlopt ---------------------------------------------------------------------------------------
class _Tracker:
    """nlopt objective with exact JAX gradients; remembers the best point (nlopt may raise)."""

    def __init__(self, problem: Problem, scale: float):
        self.problem = problem
        self.scale = scale
        self.best_u: np.ndarray | None = None
        self.best = np.inf
        self.n = 0

    def __call__(self, x: np.ndarray, grad: np.ndarray) -> float:
        self.n += 1
        if grad.size > 0:
            v, g = self.problem.value_and_grad(x)
            g = np.where(np.isfinite(g), g, 0.0)
            grad[:] = g / self.scale
        else:
            v = self.problem.cost(x)
        if not np.isfinite(v):
            return 1e300
        if v < self.best:
            self.best, self.best_u = v, np.array(x)
        return v / self.scale


def run_nlopt(
    problem: Problem,
    u0: np.ndarray,
    method: str,
    maxeval: int = 2000,
    seed: int = 0,
    ftol_rel: float = 1e-12,
    xtol_rel: float = 1e-10,
) -> tuple[np.ndarray, float, int, str]:
    """One nlopt run (local ``"lbfgs"``/``"slsqp"`` or global ``"crs2"``/``"mlsl"``/``"direct"``)
    inside the box. Returns ``(u, cost, n_evaluations, message)``."""
    p = problem.n_params
    lo, hi = problem.layout.box()
    nlopt.srand(int(seed))
    algo = _NLOPT_LOCAL.get(method, _NLOPT_GLOBAL.get(method))
    if algo is None:
        raise FitError(f"unknown optimizer {method!r}")
    opt = nlopt.opt(algo, p)
    if method == "mlsl":
        local = nlopt.opt(nlopt.LD_LBFGS, p)
        local.set_ftol_rel(1e-8)
        local.set_maxeval(200)
        opt.set_local_optimizer(local)
    opt.set_lower_bounds(lo)
    opt.set_upper_bounds(hi)
    u0 = np.clip(np.asarray(u0, dtype=np.float64), lo, hi)
    c0 = problem.cost(u0)
    tracker = _Tracker(problem, scale=c0 if np.isfinite(c0) and c0 > 0 else 1.0)
    opt.set_min_objective(tracker)
    opt.set_maxeval(int(maxeval))
    if method in _NLOPT_LOCAL:
        opt.set_ftol_rel(ftol_rel)
        opt.set_xtol_rel(xtol_rel)
    elif method != "direct":  # DIRECT stops far too early on a relative-change test
        opt.set_ftol_rel(1e-8)
    try:
        opt.optimize(u0)
        message = _nlopt_message(opt.last_optimize_result())
    except nlopt.RoundoffLimited:
        message = "roundoff limited (best point kept)"
    except (RuntimeError, ValueError) as exc:  # nlopt reports failures as exceptions
        message = f"nlopt failure: {exc}"
    if tracker.best_u is None:
        return u0, c0, tracker.n, message
    return tracker.best_u, tracker.best, tracker.n, message


def _nlopt_message(code: int) -> str:
    return {
        nlopt.SUCCESS: "success",
        nlopt.STOPVAL_REACHED: "stopval reached",
        nlopt.FTOL_REACHED: "converged (ftol)",
        nlopt.XTOL_REACHED: "converged (xtol)",
        nlopt.MAXEVAL_REACHED: "stopped: evaluation limit reached",
        nlopt.MAXTIME_REACHED: "stopped: time limit reached",
    }.get(code, f"nlopt code {code}")


# -- driver --------------------------------------------------------------------------------------
@functools.cache
def _compile_pool() -> ThreadPoolExecutor:
    """Threads that compile the later stages' programs while the first stages run (created on
    first use; XLA's compiler releases the GIL, so on 2 cores this overlaps with the starts)."""
    return ThreadPoolExecutor(2, thread_name_prefix="gonio-compile")


@contextmanager
def _compiled_ahead(problem: Problem, mid: Problem | None) -> Iterator[None]:
    """Compile (or load) the refinement's and the polish's programs in the background while
    the body runs: on an empty compilation cache that is most of a first fit's time (module
    docstring, 6.). A stage that calls one before it is ready waits for it
    (``Program.prepare``), and a failure here is raised again by that call. Leaving the body
    cancels the compilations not yet started (an interrupted fit does not wait for them)."""
    if mid is None:
        yield
        return
    jobs = [_compile_pool().submit(prob.prepare, name)
            for prob, name in ((mid, "normal"), (problem, "value_and_grad"), (mid, "hessian"),
                               (problem, "value_and_grad_scored"))]  # fmt: skip
    try:
        yield
    finally:
        for job in jobs:
            job.cancel()


def optimize(
    problem: Problem,
    method: str = "lm",
    global_method: str | None = None,
    n_starts: int = 8,
    seed: int = 0,
    subsample: int = 2048,
    max_iter: int = 200,
    max_restarts: int = 3,
    start: np.ndarray | None = None,
    refine: int = 65536,
) -> OptimResult:
    """Minimize the problem's loss; see the module docstring for the strategy.

    Parameters
    ----------
    problem : the compiled problem on the full data.
    method : local method: ``"lm"``, ``"lbfgs"`` or ``"slsqp"``.
    global_method : None, ``"crs2"``, ``"mlsl"`` or ``"direct"``.
    n_starts : number of starting points of the multi-start stage (>= 1).
    seed : seed of the subsample and the random starts.
    subsample : samples used by the global and multi-start stages (all when fewer). 2048 keeps
        the optimum of every fit of ``benchmarks/bench_published.py`` (MERL-resolution tables x
        3 families x 2 losses: final losses within 1e-9 relative of those with 4000 samples, or
        lower), and the starts cost less than with 4000.
    max_iter : iteration limit of each local run.
    max_restarts : automatic restarts of the polish when it stops before converging.
    start : optional (P,) starting point used instead of the template's values.
    refine : samples of the intermediate stage on a stratified subset (0: none).
    """
    if method not in LOCAL_METHODS:
        raise FitError(f"unknown optimizer {method!r}; valid: {', '.join(LOCAL_METHODS)}")
    if global_method is not None and global_method not in GLOBAL_METHODS:
        raise FitError(
            f"unknown global method {global_method!r}; valid: {', '.join(GLOBAL_METHODS)}"
        )
    t_start = time.perf_counter()
    layout = problem.layout
    timings: dict[str, float] = {}
    sub = problem
    if problem.data.n > subsample:
        sub = problem.with_data(problem.data.random_subset(subsample, seed))
    mid = None
    if refine and problem.data.n > 2 * refine and method == "lm":
        mid = problem.with_data(problem.data.stratified_subset(int(refine), seed))

    with _compiled_ahead(problem, mid):
        starts = layout.random_starts(max(int(n_starts), 1), seed)
        if start is not None:
            starts[0] = np.clip(start, *layout.box())
        t0 = time.perf_counter()
        if global_method is not None:
            maxeval = 200 * layout.size if global_method != "direct" else 400 * layout.size
            ug, _, _, _ = run_nlopt(sub, starts[0], global_method, maxeval=maxeval, seed=seed)
            starts = np.vstack([ug[None], starts])
        timings["global"] = time.perf_counter() - t0

        t0 = time.perf_counter()
        if len(starts) > 1 or sub is not problem:
            if method == "lm":
                # a few iterations from every start, then the two best to convergence
                us, costs, _, _ = run_lm(sub, starts, max_iter=min(12, max_iter))
                costs = np.where(np.isfinite(costs), costs, np.inf)
                top = np.argsort(costs)[:2]
                ftol = _STAGE_FTOL if sub is not problem else 1e-10
                us2, costs2, _, _ = run_lm(sub, us[top], max_iter=max_iter, ftol=ftol)
                us[top], costs[top] = us2, costs2
            else:
                runs = [run_nlopt(sub, s, method, maxeval=50 * max_iter) for s in starts]
                us = np.stack([r[0] for r in runs])
                costs = np.array([r[1] for r in runs])
            costs = np.where(np.isfinite(costs), costs, np.inf)
            order = np.argsort(costs)
            best = us[order[0]]
            start_costs = [float(costs[i]) for i in order]
        else:
            best, start_costs = starts[0], []
        timings["starts"] = time.perf_counter() - t0

        t0 = time.perf_counter()
        curvature, polish_ftol = None, 1e-10
        if mid is not None:
            best = run_lm(mid, best, max_iter=max_iter, ftol=_STAGE_FTOL)[0]
            hess = subset_hessian(mid, best)
            curvature = subset_curvature(problem, mid, hess)
            if hess is not None:  # (with J^T J, convergence is linear: keep the tight test)
                polish_ftol = _POLISH_FTOL
        timings["refine"] = time.perf_counter() - t0

        t0 = time.perf_counter()
        converged, message, n_iter, cost = False, "", 0, np.inf
        u = best
        for _ in range(max_restarts + 1):
            if method == "lm":
                u, cost_a, it, status = run_lm(problem, u, max_iter, polish_ftol, normal=curvature)
                cost = float(cost_a)
                n_iter += int(it)
                message = STATUS_TEXT[int(status)]
                converged = int(status) in (CONVERGED_F, CONVERGED_X, STALLED)
            else:
                u, cost, n, message = run_nlopt(problem, u, method, maxeval=50 * max_iter)
                n_iter += n
                converged = "converged" in message or message in ("success", "roundoff limited")
            if converged:
                break
        timings["polish"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_start
    if not np.isfinite(cost):
        raise FitError(
            f"the {method} fit produced a non-finite loss; the data may not be fittable by "
            f"this model"
        )
    return OptimResult(
        u=np.asarray(u),
        cost=float(cost),
        converged=bool(converged),
        message=message,
        method=method,
        global_method=global_method,
        n_iter=n_iter,
        on_bounds=layout.on_bounds(np.asarray(u)),
        starts=start_costs,
        timings=timings,
    )
