"""Parameter uncertainty: Laplace approximation and MCMC (emcee) whose likelihood is the loss.

Laplace
    The loss is ``L(u) = sum r^2``. Near the optimum ``u*`` the log-likelihood is quadratic with
    covariance ``Cov_u = s^2 H^-1``, ``H = J^T J`` (Gauss–Newton, default) or half the exact
    Hessian of ``L`` (``method="hessian"``). The residual scale ``s^2`` is 1 for a ``wls`` fit
    with measured sigma whose reduced chi-square is at most 1, and otherwise the reduced
    ``L / (M - P)`` (M residuals, P parameters): the noise level estimated from the residuals
    (reported as ``diagnostics["residual_scale_sq"]``; for data without sigma this is the only
    noise estimate there is).

    Model discrepancy (``covariance``): residual scaling treats the misfit as independent noise,
    so on a table of 10^6 cells the intervals shrink like 1/sqrt(M) although the misfit is one
    smooth, correlated error. ``covariance="cluster"`` uses instead the cluster-robust sandwich
    ``Cov_u = H^-1 B H^-1``, ``B = G/(G-1) sum_g (J_g^T r_g)(J_g^T r_g)^T`` (Liang & Zeger 1986)
    over ``G`` clusters of neighbouring samples: cells in the same block of
    ``(theta_h, theta_d, phi_d)`` (8 x 8 x 4 blocks, theta_h on MERL's sqrt scale) share a
    cluster, so a misfit shared by a whole region counts as one piece of evidence, not as
    thousands. Default (``"auto"``): ``"residual"`` for a ``wls`` fit with measured sigma whose
    reduced chi-square is at most 2 (the model reaches the noise), ``"cluster"`` otherwise (data
    without sigma, other losses, or misfit beyond the noise); the choice is recorded in
    ``diagnostics["covariance"]``. ``tests/fit/test_published_families.py`` (``-m slow``) checks
    the default intervals' coverage of the best-in-family parameters with a deliberately wrong
    model on simulated data.
    Intervals are symmetric in ``u`` and mapped through the (monotone) reparameterization, so
    they respect physical bounds (a log-scale roughness gets a multiplicative interval).
    Standard deviations and correlations in physical units use the delta method.

MCMC
    emcee's ensemble sampler (differential-evolution moves) on ``u``, with a vectorized
    (``jit`` + ``vmap``) log-probability whose likelihood is the **fitted loss** ``L`` itself,
    so that the optimizer's optimum is the posterior's mode and lies inside its own intervals:

    * with a measured sigma and a ``wls`` fit that reaches the noise (chi2/dof <= 1):
      ``ln p(y | u) = -L(u) / 2``, the chi-square likelihood;
    * otherwise the residual variance is unknown and integrated out (prior ``1/s``):
      ``ln p(y | u) = -(M / 2) ln L(u)``, ``M`` the effective number of values (Kish's
      ``C (sum w)^2 / sum w^2`` for weighted cells).

    Large data sets are subsampled (at most ``max_samples`` samples, fixed seed): neighbouring
    cells of a table share the same model error, so their residuals are not independent and
    the subsample's ``M`` is the more honest count. The subsample's loss is corrected to first
    order at the optimum ``u*``, ``L~(u) = L_sub(u) - (g_sub - g_all) . (u - u*)`` (``g`` the
    gradients at ``u*``, ``g_all`` scaled to the subsample), so that its gradient at ``u*`` is
    the whole data's: zero at an interior optimum, and the mode does not move with the draw of
    the subsample. Priors: uniform in the physical value for "linear"/"logit" parameters,
    uniform in the logarithm for "log" ones, inside the search box. The walkers start drawn from
    that prior over the whole box (not in a ball at the optimum); the burn-in runs in blocks of
    100 steps, moving walkers stranded far below the best known point onto copies of good
    walkers (onto the optimum when none is good; counted in ``n_reseeded``), until the ensemble
    sits in the optimum's typical set (median ``ln p* - ln p`` below the number of parameters),
    then the main run of ``n_steps``. Diagnostics: integrated autocorrelation time
    (``get_autocorr_time(tol=0)``; a warning when the chain is shorter than 50 times it), mean
    acceptance fraction, split-R-hat over walker half-chains. Intervals are the marginals'
    highest-posterior-density intervals (:func:`hpd_interval`); a parameter at its bound gets a
    one-sided interval from the bound.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from statistics import NormalDist
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from gonio.errors import FitError
from gonio.fit.bounds import at_bounds, unconstrained
from gonio.fit.objective import Problem

Array = jnp.ndarray

Z68 = NormalDist().inv_cdf(0.84)  # (statistics, not scipy.stats: a far lighter import)
Z95 = NormalDist().inv_cdf(0.975)


@dataclass
class Uncertainty:
    """Uncertainty of the fitted parameters (physical units), per flat parameter name.

    Attributes
    ----------
    method : ``"laplace"`` or ``"mcmc"``.
    names : flat parameter names (``"lambert.albedo[R]"``).
    center : (P,) the optimum (Laplace) or the posterior median (MCMC).
    std : (P,) standard deviation.
    interval68, interval95 : (P, 2) lower and upper bounds.
    correlation : (P, P) correlation matrix.
    diagnostics : method-specific numbers (residual scale, autocorrelation times, ...).
    warnings : human-readable caveats (non-identifiable parameters, short chains).
    samples : (S, P) posterior samples in physical units (MCMC), or draws of the Laplace
        Gaussian taken in the fitted coordinates and mapped to physical units (so that they
        respect the parameter bounds exactly as the intervals do).
    unconstrained : names whose 95 % interval spans the search box
        (:func:`gonio.fit.bounds.unconstrained`): not reported as intervals.
    """

    method: str
    names: list[str]
    center: np.ndarray
    std: np.ndarray
    interval68: np.ndarray
    interval95: np.ndarray
    correlation: np.ndarray
    diagnostics: dict[str, Any] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    samples: np.ndarray | None = None
    unconstrained: list[str] = field(default_factory=list)


def residual_scale(problem: Problem, cost: float) -> tuple[float, float]:
    """``(s^2, reduced)``: the variance factor of :func:`laplace` and ``L / (M - P)``."""
    dof = max(problem.n_residuals - problem.n_params, 1)
    reduced = cost / dof
    if problem.loss.statistical and problem.data.sigma is not None:
        return max(1.0, reduced), reduced
    return reduced, reduced


COVARIANCES = ("auto", "residual", "cluster")


def cluster_ids(data: Any, n_theta: int = 8, n_phi: int = 4) -> np.ndarray:
    """Cluster index ``(N,)`` of each sample: its block of ``(theta_h, theta_d, phi_d)``
    (``n_theta x n_theta x n_phi`` blocks; theta_h on MERL's sqrt scale, phi_d folded to
    [0, pi))."""
    th, td, pd = data.half_diff()
    i = np.minimum((np.sqrt(np.clip(th / (np.pi / 2), 0, 1)) * n_theta).astype(int), n_theta - 1)
    j = np.minimum((np.clip(td / (np.pi / 2), 0, 1) * n_theta).astype(int), n_theta - 1)
    k = np.minimum((np.clip(pd / np.pi, 0, 1) * n_phi).astype(int), n_phi - 1)
    return (i * n_theta + j) * n_phi + k


def choose_covariance(problem: Problem, cost: float, covariance: str = "auto") -> str:
    """``"residual"`` or ``"cluster"`` for ``covariance`` (see the module docstring)."""
    if covariance not in COVARIANCES:
        raise FitError(f"unknown covariance {covariance!r}; valid: {', '.join(COVARIANCES)}")
    if covariance != "auto":
        return covariance
    dof = max(problem.n_residuals - problem.n_params, 1)
    noise_level = problem.loss.statistical and problem.data.sigma is not None
    return "residual" if noise_level and cost / dof <= 2.0 else "cluster"


def laplace(
    problem: Problem, u: np.ndarray, method: str = "gauss-newton", covariance: str = "auto"
) -> Uncertainty:
    """Laplace approximation at the optimum ``u`` (P,); see the module docstring."""
    layout = problem.layout
    names = layout.flat_names(problem.data.channel_names)
    cost, _, a = problem.normal(u)
    if method == "hessian":
        a = 0.5 * problem.hessian(u)
    elif method != "gauss-newton":
        raise FitError(f"unknown Laplace method {method!r}; valid: gauss-newton, hessian")
    s2, reduced = residual_scale(problem, cost)
    kind = choose_covariance(problem, cost, covariance)
    meat = None
    n_clusters = 0
    if kind == "cluster":
        ids = cluster_ids(problem.data)
        uniq, ids = np.unique(ids, return_inverse=True)
        n_clusters = len(uniq)
        scores = problem.cluster_scores(u, ids, n_clusters)  # (G, P): J_g^T r_g
        meat = scores.T @ scores * (n_clusters / max(n_clusters - 1, 1))
    notes: list[str] = []
    lo_box, hi_box = layout.box()
    # Parameters on the edge of the box: the quadratic model does not hold there.
    on_edge = np.array([n in set(layout.on_bounds(u)) for n in layout.flat_names()])
    a = 0.5 * (a + a.T)
    scale = np.sqrt(np.clip(np.diag(a), 1e-300, None))
    a_s = a / np.outer(scale, scale)
    w, v = np.linalg.eigh(a_s)
    ok = w > 1e-10 * max(w.max(), 1e-300)
    if not ok.all():
        notes.append(
            f"{int((~ok).sum())} direction(s) in parameter space are not constrained by the data; "
            "their intervals span the search box"
        )
    inv = (v[:, ok] / w[ok]) @ v[:, ok].T
    if meat is None:
        cov_u = s2 * inv / np.outer(scale, scale)
        root = v[:, ok] / np.sqrt(w[ok]) * np.sqrt(s2) / scale[:, None]
    else:
        h_inv = inv / np.outer(scale, scale)
        cov_u = h_inv @ meat @ h_inv
        cov_u = 0.5 * (cov_u + cov_u.T)
        ew, ev = np.linalg.eigh(cov_u)
        root = ev * np.sqrt(np.clip(ew, 0.0, None))
    sd_u = np.sqrt(np.clip(np.diag(cov_u), 0.0, None))
    # unconstrained directions: the parameters that load on them are unknown
    weak = np.zeros(len(u), dtype=bool)
    if not ok.all():
        weak = np.abs(v[:, ~ok]).max(axis=1) > 0.1
    sd_u = np.where(weak, np.inf, sd_u)

    def to_theta(x: np.ndarray) -> np.ndarray:
        return np.asarray(layout.theta(jnp.asarray(np.clip(x, lo_box, hi_box))))

    center = to_theta(u)
    i68 = np.stack([to_theta(u - Z68 * sd_u), to_theta(u + Z68 * sd_u)], -1)
    i95 = np.stack([to_theta(u - Z95 * sd_u), to_theta(u + Z95 * sd_u)], -1)
    jac = np.asarray(layout.dtheta_du(jnp.asarray(u)))
    cov_t = cov_u * np.outer(jac, jac)
    std = np.where(weak, np.inf, np.sqrt(np.clip(np.diag(cov_t), 0.0, None)))
    corr = _correlation(cov_t)
    zero = np.isfinite(sd_u) & (sd_u <= 1e-12 * np.maximum(np.abs(u), 1.0))
    if zero.any():
        notes.append(
            "zero-width interval (the data carry no information on its spread): "
            + ", ".join(n for n, z in zip(names, zero, strict=True) if z)
        )
    if on_edge.any():
        notes.append(
            "on the search-box edge (Laplace interval one-sided there): "
            + ", ".join(n for n, e in zip(names, on_edge, strict=True) if e)
        )
    loose = unconstrained(u - Z95 * sd_u, u + Z95 * sd_u, (lo_box, hi_box), names)
    return Uncertainty(
        unconstrained=loose,
        samples=_laplace_draws(layout, u, root, weak, (lo_box, hi_box)),
        method="laplace",
        names=names,
        center=center,
        std=std,
        interval68=i68,
        interval95=i95,
        correlation=corr,
        diagnostics={
            "hessian": method,
            "covariance": kind,
            "n_clusters": int(n_clusters),
            "residual_scale_sq": float(s2),
            "reduced_loss": float(reduced),
            "condition_number": float(w.max() / max(w.min(), 1e-300)),
        },
        warnings=notes,
    )


def _laplace_draws(
    layout: Any,
    u: np.ndarray,
    root: np.ndarray,
    weak: np.ndarray,
    box: tuple[np.ndarray, np.ndarray],
    n: int = 4000,
    seed: int = 0,
) -> np.ndarray:
    """(n, P) draws of the Laplace approximation in physical units.

    The Gaussian lives in the fitted coordinates: ``u + root @ z`` with ``z ~ N(0, I)`` and
    ``root @ root.T`` the covariance of ``u`` (from its eigendecomposition, so no numerically
    indefinite matrix is ever factorized). Draws are clipped to the search box and mapped through
    the parameter transforms, like the intervals; a Gaussian in physical units (the delta-method
    covariance) would put mass beyond a bound that a parameter sits on. Parameters the data do
    not constrain are drawn uniformly over the box.
    """
    lo, hi = box
    rng = np.random.default_rng(seed)
    x = u + rng.standard_normal((n, root.shape[1])) @ root.T
    if weak.any():
        x[:, weak] = rng.uniform(lo[weak], hi[weak], (n, int(weak.sum())))
    x = np.clip(x, lo, hi)
    return np.asarray(jax.vmap(layout.theta)(jnp.asarray(x)))


def _correlation(cov: np.ndarray) -> np.ndarray:
    d = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        c = cov / np.outer(d, d)
    c = np.where(np.isfinite(c), c, 0.0)
    np.fill_diagonal(c, 1.0)
    return np.clip(c, -1.0, 1.0)


# -- MCMC ----------------------------------------------------------------------------------------
#: Steps per block of the burn-in; the burn-in ends when the walkers reached the optimum's mode
#: (:func:`_burnt_in`), after at most ``max(4 n_steps, 2000)`` steps.
_BURN_BLOCK = 100


def _mcmc_loss_fn(problem: Problem, u_opt: np.ndarray, g_corr: np.ndarray) -> Any:
    """``L~(u, arrays, tmpl)``: the fitted loss on the problem's data minus ``g_corr . (u - u*)``
    (see :func:`mcmc`)."""
    fns = problem.fns
    loss = problem.loss
    u0, g0 = jnp.asarray(u_opt), jnp.asarray(g_corr)

    def value(u: Array, arrays: Any, tmpl: Any) -> Array:
        model = fns.to_model(u, tmpl)

        def chunk(c: dict[str, Any]) -> Array:
            r = loss.residual(model.f(c["wi"], c["wo"]), c["k"]) * c["mask"]
            return jnp.sum(r * r)

        return jnp.sum(jax.vmap(chunk)(arrays)) - jnp.dot(g0, u - u0)

    return value


def _prior_draws(layout: Any, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, P) points of ``u`` drawn from the prior over the search box: uniform in the physical
    value for "linear" and "logit" parameters, uniform in ``u`` (the logarithm) for "log" ones."""
    lo, hi = layout.box()
    out = np.empty((n, layout.size))
    for e in layout.entries:
        sl = slice(e.offset, e.offset + e.size)
        if e.scale == "logit":  # uniform theta -> u = logit(t), inside the box
            t = rng.uniform(0.0, 1.0, (n, e.size))
            out[:, sl] = np.log(t) - np.log1p(-t)
        else:
            out[:, sl] = rng.uniform(lo[sl], hi[sl], (n, e.size))
    margin = 1e-9 * (hi - lo)
    return np.clip(out, lo + margin, hi - margin)


def _burnt_in(lp: np.ndarray, lp_opt: float, ndim: int) -> bool:
    """Whether an ensemble with log-probabilities ``lp`` sits in the typical set of a posterior
    whose mode has ``lp_opt``: near a Gaussian mode ``lp_opt - lp`` is chi-square(ndim) / 2
    (median about ndim / 2); accepted below ndim for the median, 5 ndim for the worst walker."""
    gap = lp_opt - lp
    return bool(np.median(gap) < max(ndim, 1) and np.max(gap) < 5 * max(ndim, 1) + 10)


def mcmc(
    problem: Problem,
    u: np.ndarray,
    n_walkers: int | None = None,
    n_steps: int = 2000,
    burn: int | None = None,
    max_samples: int = 3000,
    seed: int = 0,
    init: Uncertainty | None = None,
) -> Uncertainty:
    """Posterior sampling with emcee whose likelihood is the fitted loss; see the module
    docstring.

    Parameters
    ----------
    problem : the fit problem (layout, loss, data).
    u : (P,) the optimizer's optimum: the likelihood is centred on it (module docstring); the
        walkers do not start there but over the prior box.
    n_walkers : ensemble size (default ``max(32, 2 P + 2)``, even).
    n_steps : steps per walker of the main run, after the burn-in.
    burn : steps of the main run discarded (default ``min(3 tau, n_steps / 2)``).
    max_samples : subsample size of the data for the likelihood.
    seed : seeds the subsample, the initial ensemble and emcee's generator.
    init : unused (kept for callers of the earlier signature).
    """
    import emcee

    layout = problem.layout
    data = problem.data.random_subset(max_samples, seed)
    sub = problem if data is problem.data else problem.with_data(data)
    p = ndim = layout.size
    n_walkers = n_walkers or max(32, 2 * ndim + 2)
    n_walkers += n_walkers % 2
    lo, hi = layout.box()
    u = np.asarray(u, dtype=np.float64)

    # the subsample's loss, corrected to first order so that its gradient at u* is the whole
    # data's (zero at an interior optimum): the likelihood's mode is the optimizer's optimum
    g_corr = np.zeros(p)
    if sub is not problem:
        ratio = 1.0 if "scale" in problem.loss.needs else data.n / problem.data.n
        g_corr = sub.value_and_grad(u)[1] - ratio * problem.value_and_grad(u)[1]
    value = _mcmc_loss_fn(sub, u, g_corr)
    loss_opt = float(sub.cost(u))
    w = data.weights
    m_eff = data.channels * float(w.sum() ** 2 / np.sum(w * w))  # Kish's effective size
    dof = max(m_eff - p, 1.0)
    chi_square = problem.loss.statistical and data.sigma is not None and loss_opt / dof <= 1.0
    log_mask = np.zeros(p, dtype=bool)
    for e in layout.entries:
        log_mask[e.offset : e.offset + e.size] = e.scale == "log"
    log_mask_j = jnp.asarray(log_mask)
    tmpl = layout.template
    lo_j, hi_j = jnp.asarray(lo), jnp.asarray(hi)

    def logp(x: Array, arrays: Any) -> Array:
        inside = jnp.all((x >= lo_j) & (x <= hi_j))
        xc = jnp.clip(x, lo_j, hi_j)
        lt = jnp.maximum(value(xc, arrays, tmpl), 1e-300)
        # chi-square with measured sigma; otherwise the residual variance is unknown and
        # integrated out (prior 1/s): L^(-M/2)
        ll = -0.5 * lt if chi_square else -0.5 * m_eff * jnp.log(lt)
        log_jac = jnp.log(jnp.maximum(layout.dtheta_du(xc), 1e-300))
        out = ll + jnp.sum(jnp.where(log_mask_j, 0.0, log_jac))
        return jnp.where(inside & jnp.isfinite(out), out, -jnp.inf)

    batched = jax.jit(jax.vmap(logp, in_axes=(0, None)))

    def log_prob(xs: np.ndarray) -> np.ndarray:
        return np.asarray(batched(jnp.asarray(xs), sub.arrays))

    rng = np.random.default_rng(seed)
    lp_opt = float(log_prob(u[None])[0])
    walkers = _prior_draws(layout, n_walkers, rng)
    # differential-evolution proposals: about half the autocorrelation time of the default
    # stretch move on these posteriors (measured: tau 33 vs 72 steps, Lambert + Phong)
    moves = [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]
    sampler = emcee.EnsembleSampler(n_walkers, ndim, log_prob, vectorize=True, moves=moves)
    rstate = np.random.RandomState(int(seed) % (2**31)).get_state()
    state = emcee.State(walkers, random_state=rstate)
    # burn-in from the prior box, in blocks; walkers stranded far below the best known point (a
    # local mode, a needle lobe, a box edge) are moved onto copies of good walkers between
    # blocks, or onto the optimum when no walker is good
    max_burn = max(4 * n_steps, 2000)
    n_burn = n_reseeded = 0
    reached = False
    while n_burn < max_burn:
        state = sampler.run_mcmc(state, _BURN_BLOCK, progress=False)
        n_burn += _BURN_BLOCK
        lp = state.log_prob
        ref = max(lp_opt, float(lp.max()))
        if n_burn >= 2 * _BURN_BLOCK and _burnt_in(lp, ref, ndim):
            reached = True
            break
        good = np.flatnonzero(lp > ref - 5.0 * ndim - 10.0)
        bad = np.setdiff1d(np.arange(n_walkers), good)
        if bad.size:
            coords = state.coords.copy()
            jitter = 1e-4 * (hi - lo) * rng.standard_normal((bad.size, ndim))
            source = coords[rng.choice(good, bad.size)] if good.size else u
            coords[bad] = np.clip(source + jitter, lo, hi)
            n_reseeded += int(bad.size)
            state = emcee.State(coords, random_state=state.random_state)
        sampler.reset()
    sampler.reset()
    sampler.run_mcmc(state, n_steps, progress=False)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tau = np.asarray(sampler.get_autocorr_time(tol=0), dtype=np.float64)
    notes: list[str] = []
    if not reached:
        notes.append(
            f"burn-in of {n_burn} steps from the prior box did not settle at the optimum's "
            "mode; treat the intervals as approximate"
        )
    tau_max = float(np.nanmax(tau)) if np.isfinite(tau).any() else float("nan")
    if not np.isfinite(tau_max) or n_steps < 50 * tau_max:
        notes.append(
            f"chain of {n_steps} steps is shorter than 50 autocorrelation times "
            f"(max tau = {tau_max:.1f}); treat the intervals as approximate"
        )
    if burn is None:
        burn = int(min(3 * tau_max if np.isfinite(tau_max) else n_steps // 3, n_steps // 2))
    chain = sampler.get_chain(discard=burn)  # (steps, walkers, ndim)
    flat = chain.reshape(-1, ndim)
    theta = np.asarray(jax.vmap(layout.theta)(jnp.asarray(flat)))
    acc = float(np.mean(sampler.acceptance_fraction))
    if not 0.1 <= acc <= 0.8:
        notes.append(f"mean acceptance fraction {acc:.2f} outside [0.1, 0.8]")
    rhat = _split_rhat(chain)
    if np.nanmax(rhat) > 1.1:
        notes.append(f"split R-hat up to {np.nanmax(rhat):.2f} (> 1.1): not converged")
    names = layout.flat_names(problem.data.channel_names)
    # highest-posterior-density intervals of each marginal: an equal-tailed interval of a
    # posterior piled up against a bound (an albedo of 1e-4) leaves out its most probable values
    q = np.empty((5, p))
    q[2] = np.median(theta, axis=0)
    q[0], q[4] = hpd_interval(theta, 0.95)
    q[1], q[3] = hpd_interval(theta, 0.68)
    # a parameter at its bound: the interval is one-sided, from the bound
    best = np.asarray(layout.theta(jnp.asarray(u)))
    side = at_bounds(layout, u, problem.data.channel_names)
    one_sided = []
    for k, n in enumerate(names):
        if side.get(n) == "lower":
            q[0, k], q[1, k] = best[k], best[k]
            q[3, k], q[4, k] = np.percentile(theta[:, k], [68, 95])
        elif side.get(n) == "upper":
            q[0, k], q[1, k] = np.percentile(theta[:, k], [5, 32])
            q[3, k], q[4, k] = best[k], best[k]
        else:
            continue
        one_sided.append(n)
    if one_sided:
        notes.append("one-sided intervals from the bound: " + ", ".join(one_sided))
    lp = sampler.get_log_prob(discard=burn).reshape(-1)
    mode = theta[int(np.argmax(lp))]
    outside = [n for n, b, a, c in zip(names, best, q[0], q[4], strict=True) if not a <= b <= c]
    if outside:
        notes.append("the loss optimum lies outside the MCMC 95% interval: " + ", ".join(outside))
    uq = np.percentile(flat, [2.5, 97.5], axis=0)
    diag: dict[str, Any] = {
        "likelihood": "chi-square" if chi_square else "loss, residual variance marginalized",
        "n_walkers": int(n_walkers),
        "n_steps": int(n_steps),
        "n_burn": int(n_burn),
        "burn": int(burn),
        "burnt_in": bool(reached),
        "n_reseeded": int(n_reseeded),
        "autocorr_time": dict(zip(names, tau.tolist(), strict=True)),
        "acceptance_fraction": acc,
        "split_rhat": dict(zip(names, rhat.tolist(), strict=True)),
        "n_samples_likelihood": int(data.n),
        "effective_values": float(m_eff),
        "residual_scale_sq": float(loss_opt / dof),
        "mode": dict(zip(names, mode.tolist(), strict=True)),
        "optimum_outside": outside,
    }
    return Uncertainty(
        method="mcmc",
        names=names,
        center=q[2],
        std=theta.std(axis=0),
        interval68=np.stack([q[1], q[3]], -1),
        interval95=np.stack([q[0], q[4]], -1),
        correlation=_correlation(np.cov(theta, rowvar=False).reshape(p, p)),
        diagnostics=diag,
        warnings=notes,
        samples=theta,
        unconstrained=unconstrained(uq[0], uq[1], (lo, hi), names),
    )


def hpd_interval(samples: np.ndarray, mass: float) -> tuple[np.ndarray, np.ndarray]:
    """The shortest interval holding ``mass`` of each column's samples: ``(lo, hi)``, (P,) each,
    for samples (S, P)."""
    x = np.sort(np.asarray(samples, dtype=float), axis=0)
    n = x.shape[0]
    k = min(max(int(np.ceil(mass * n)), 1), n)
    width = x[k - 1 :] - x[: n - k + 1]  # (n - k + 1, P)
    i = np.argmin(width, axis=0)
    cols = np.arange(x.shape[1])
    return x[i, cols], x[i + k - 1, cols]


def _split_rhat(chain: np.ndarray) -> np.ndarray:
    """Gelman–Rubin R-hat over the 2W half-chains of a (steps, walkers, ndim) chain."""
    n = chain.shape[0] // 2
    if n < 2:
        return np.full(chain.shape[-1], np.nan)
    halves = np.concatenate([chain[:n], chain[n : 2 * n]], axis=1)  # (n, 2W, ndim)
    means = halves.mean(axis=0)
    var_within = halves.var(axis=0, ddof=1).mean(axis=0)
    var_between = n * means.var(axis=0, ddof=1)
    var_hat = (n - 1) / n * var_within + var_between / n
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.sqrt(var_hat / var_within)
