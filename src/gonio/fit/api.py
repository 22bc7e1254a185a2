"""``gonio.fit.fit``: fit one model (or several) to measured data, with optional uncertainty."""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from gonio.brdf.models import BRDFModel
from gonio.errors import FitError, ParameterError
from gonio.fit import presets
from gonio.fit.bounds import at_bounds
from gonio.fit.data import DEFAULT_THETA_MAX_DEG, FitData, prepare
from gonio.fit.losses import LOSSES, evaluate_many, get_loss
from gonio.fit.objective import Problem
from gonio.fit.optimize import optimize
from gonio.fit.params import Layout
from gonio.fit.result import FitResult
from gonio.fit.uncertainty import laplace, mcmc

UNCERTAINTY_METHODS = (None, "laplace", "mcmc")
#: Data at least this large (values) is scored after the fit by one compiled pass
#: (:meth:`~gonio.fit.objective.Problem.scores`), smaller data by NumPy.
_SCORE_PASS_MIN_VALUES = 1 << 18


def information_criteria(
    cost: float, n_res: int, n_par: int, statistical: bool
) -> tuple[float, float]:
    """``(AIC, BIC)`` of a least-squares fit with loss ``cost`` = sum of squared residuals.

    With standardized residuals (``statistical``: a chi-square), ``-2 ln L = chi2 + const`` and
    ``AIC = chi2 + 2P``, ``BIC = chi2 + P ln M``. Otherwise the residual variance is estimated
    (``cost / M``): ``AIC = M ln(cost / M) + 2P``, ``BIC = M ln(cost / M) + P ln M``. Only
    differences between models fitted to the same data under the same metric are meaningful.
    """
    m = max(n_res, 1)
    if statistical:
        base = cost
    else:
        base = m * math.log(max(cost, 1e-300) / m)
    return base + 2 * n_par, base + n_par * math.log(m)


#: Lobe-shape parameters and the bound at which the lobe becomes a needle between the cells.
_NEEDLE_AT = {"alpha": "lower", "alpha_x": "lower", "alpha_y": "lower", "n": "upper",
              "nu": "upper", "nv": "upper", "B": "upper"}  # fmt: skip


def _degenerate(layout: Layout, u: np.ndarray) -> list[str]:
    """Lobe-shape parameters (roughness, exponents) on the search bound where the lobe becomes
    a needle (roughness at its lower bound, an exponent at its upper bound)."""
    lo, hi = layout.box()
    out = []
    for e in layout.entries:
        side = _NEEDLE_AT.get(e.key.rpartition(".")[2])
        if side is None:
            continue
        sl = slice(e.offset, e.offset + e.size)
        tol = 1e-4 * (hi[sl] - lo[sl])
        hit = u[sl] <= lo[sl] + tol if side == "lower" else u[sl] >= hi[sl] - tol
        if np.any(hit):
            out.append(e.key)
    return out


def _resolve_model(
    model: str | BRDFModel,
) -> tuple[str, BRDFModel, dict[str, Any], dict[str, str]]:
    if isinstance(model, BRDFModel):
        return type(model).__name__.lower(), model, {}, {}
    if isinstance(model, str):
        return (model, *presets.build(model))
    raise FitError(f"model must be a name or a gonio model, got {type(model).__name__}")


#: Loss used when ``loss="auto"`` and the data has no sigma (see :class:`FitOptions`).
AUTO_LOSS_WITHOUT_SIGMA = "low-e1"


@dataclass(frozen=True)
class FitOptions:
    """Every setting of :func:`fit` other than the data and the model, in one documented object.

    ``fit(data, model, options=FitOptions(loss="ngan", n_starts=16))``; keyword arguments of
    :func:`fit` with the same names override the object's fields.

    Attributes
    ----------
    loss : ``"auto"`` (default), ``"wls"``, ``"ngan"``, ``"low-e1"``, ``"low-e2"`` or
        ``"cube-root"`` (see :mod:`gonio.fit.losses`). ``"auto"`` is ``wls`` (chi-square) when the
        data has sigma, and otherwise :data:`AUTO_LOSS_WITHOUT_SIGMA` (``low-e1``, Löw et al.'s
        log metric): without sigma the errors of published tables are closer to relative than
        to absolute, and ``wls`` with sigma = 1 lets the specular peak's absolute errors decide
        the whole fit (diffuse albedos end on their bounds). The logarithm ``ln(1 + f cos_i)``
        weighs errors relatively above about 1 sr^-1 and absolutely (cosine-weighted) below.
    uncertainty : None, ``"laplace"`` or ``"mcmc"`` (see :mod:`gonio.fit.uncertainty`).
    theta_max_deg : polar-angle cutoff for both directions, degrees (applied also to data that
        was already prepared with another cutoff).
    fixed : parameter keys held at given values (``{"ward.rho_d": 0.0}``).
    tie : apply the named model's ties (isotropic Ward: ``alpha_y = alpha_x``); False fits
        every parameter of the preset separately.
    grey_fresnel : fit a Schlick ``f0`` (keys ending in ``fresnel.f0``) as one value for every
        channel. None (default): True for spectral data (more than 3 channels), where 31 free
        reflectances at normal incidence are not identifiable, False otherwise.
    channels : ``"shared"`` (lobe shapes shared, per-channel albedos) or ``"separate"`` (each
        channel fitted on its own; returns one result per channel).
    optimizer : local method ``"lm"``, ``"lbfgs"`` or ``"slsqp"``.
    global_method : None, ``"crs2"``, ``"mlsl"`` or ``"direct"`` before the local stage.
    n_starts, seed, subsample, refine, max_iter : multi-start settings (see
        :func:`~.optimize.optimize`): the starts run on ``subsample`` random samples, the best
        one is refined on a stratified subset of ``refine`` samples (data of more than twice as
        many samples only; 0 turns it off), then polished on every sample.
    laplace_method : ``"gauss-newton"`` or ``"hessian"``.
    covariance : Laplace covariance: ``"auto"`` (default), ``"residual"`` (residual-scaled
        inverse Hessian) or ``"cluster"`` (cluster-robust sandwich, which includes the model's
        discrepancy); ``"auto"`` is ``"residual"`` only for a ``wls`` fit with measured sigma
        that reaches the noise (chi2/dof <= 2). See :mod:`gonio.fit.uncertainty`.
    mcmc_steps, mcmc_samples : chain length per walker and data subsample size for MCMC.
    name : material name for the record.
    progress : called with a short text before each stage (for progress displays).
    """

    loss: str = "auto"
    uncertainty: str | None = None
    theta_max_deg: float = DEFAULT_THETA_MAX_DEG
    fixed: Mapping[str, Any] | None = None
    tie: bool = True
    grey_fresnel: bool | None = None
    channels: str = "shared"
    optimizer: str = "lm"
    global_method: str | None = None
    n_starts: int = 8
    seed: int = 0
    subsample: int = 2048
    refine: int = 65536
    max_iter: int = 200
    laplace_method: str = "gauss-newton"
    covariance: str = "auto"
    mcmc_steps: int = 2000
    mcmc_samples: int = 3000
    name: str | None = None
    progress: Callable[[str], None] | None = None

    def resolved_loss(self, has_sigma: bool) -> str:
        """The loss actually used on data with (or without) sigma."""
        if self.loss != "auto":
            return self.loss
        return "wls" if has_sigma else AUTO_LOSS_WITHOUT_SIGMA


_OPTION_NAMES = frozenset(f.name for f in dataclasses.fields(FitOptions))


def fit(
    data: Any,
    model: str | BRDFModel | Sequence[str | BRDFModel] = "lambert+ward",
    loss: str | None = None,
    uncertainty: str | None = None,
    *,
    options: FitOptions | None = None,
    **overrides: Any,
) -> FitResult | list[FitResult]:
    """Fit an analytic BRDF model to measured data.

    Parameters
    ----------
    data : a TabulatedBRDF, MeasuredSamples, :class:`~gonio.fit.data.FitData` or a file path.
    model : a model name (see :func:`gonio.fit.presets.available`, e.g. ``"lambert+ward"``;
        :data:`gonio.fit.presets.FAMILIES` lists the literature's families), a gonio model used
        as template (its values are the starting point), or a list of either (then a list of
        results, one per model, is returned).
    loss, uncertainty : as in :class:`FitOptions` (positional for convenience).
    options : a :class:`FitOptions`; default ``FitOptions()``.
    **overrides : any :class:`FitOptions` field by name (``n_starts=16``), overriding
        ``options``.

    Returns
    -------
    FitResult, or a list of them (several models, or ``channels="separate"``).

    Raises
    ------
    FitError
        When the data cannot be fitted (no valid samples, fewer values than parameters, all
        values zero, unknown names or options).
    """
    unknown = sorted(set(overrides) - _OPTION_NAMES)
    if unknown:
        raise FitError(f"unknown fit option(s) {', '.join(unknown)}; valid: "
                       f"{', '.join(sorted(_OPTION_NAMES))}")  # fmt: skip
    if loss is not None:
        overrides["loss"] = loss
    if uncertainty is not None:
        overrides["uncertainty"] = uncertainty
    opts = dataclasses.replace(options or FitOptions(), **overrides)
    if opts.uncertainty not in UNCERTAINTY_METHODS:
        raise FitError(f"unknown uncertainty method {opts.uncertainty!r}; valid: laplace, mcmc")
    if opts.channels not in ("shared", "separate"):
        raise FitError(f"channels must be 'shared' or 'separate', got {opts.channels!r}")
    if opts.loss != "auto":
        get_loss(opts.loss)
    theta_max_deg, name = opts.theta_max_deg, opts.name
    if isinstance(data, FitData) and data.source.get("theta_max_deg") == float(theta_max_deg):
        fd = data  # already validated with this cutoff
        if name is not None:
            fd = dataclasses.replace(fd, source={**fd.source, "name": name})
    else:
        fd = prepare(data, theta_max_deg, name=name)
    if not np.any(fd.values > 0):
        raise FitError(f"all {fd.values.size} measured values are <= 0: nothing to fit")
    many = not isinstance(model, (str, BRDFModel))
    model_list = list(model) if many else [model]  # type: ignore[arg-type]
    if not model_list:
        raise FitError("no model given")
    results: list[FitResult] = []
    for m in model_list:
        if opts.channels == "separate" and fd.channels > 1:
            for c in range(fd.channels):
                results.append(_fit_one(fd.channel(c), m, opts, channel=fd.channel_names[c]))
        else:
            results.append(_fit_one(fd, m, opts))
    return results if (many or len(results) > 1) else results[0]


def _fit_one(
    fd: FitData,
    model: str | BRDFModel,
    opts: FitOptions,
    channel: str | None = None,
) -> FitResult:
    loss = opts.resolved_loss(fd.sigma is not None)
    fixed, tie, progress = opts.fixed, opts.tie, opts.progress
    optimizer, global_method, seed = opts.optimizer, opts.global_method, opts.seed
    n_starts, subsample, max_iter = opts.n_starts, opts.subsample, opts.max_iter
    uncertainty, laplace_method = opts.uncertainty, opts.laplace_method
    mcmc_steps, mcmc_samples = opts.mcmc_steps, opts.mcmc_samples
    t0 = time.perf_counter()
    say = progress or (lambda s: None)
    name, tmpl, preset_fixed, preset_tied = _resolve_model(model)
    all_fixed = {**preset_fixed, **dict(fixed or {})}
    tied = {t: s for t, s in (preset_tied if tie else {}).items() if t not in all_fixed}
    try:
        grey = opts.grey_fresnel if opts.grey_fresnel is not None else fd.channels > 3
        shared = [k for k in tmpl.param_specs() if grey and k.endswith("fresnel.f0")]
        layout = Layout(tmpl, fd.channels, fixed=all_fixed, tied=tied, shared=shared)
    except ParameterError as exc:
        raise FitError(f"{name}: {exc}") from None
    n_res = fd.n * fd.channels
    if n_res <= layout.size:
        raise FitError(
            f"{name}: only {n_res} measured values for {layout.size} parameters; "
            "need more samples than parameters"
        )
    lo = get_loss(loss)
    problem = Problem(layout, lo, fd)
    say(f"{name}: optimizing {layout.size} parameters on {fd.n} samples")
    opt = optimize(
        problem,
        method=optimizer,
        global_method=global_method,
        n_starts=n_starts,
        seed=seed,
        subsample=subsample,
        max_iter=max_iter,
        refine=opts.refine,
    )
    spikes = _degenerate(layout, opt.u)
    restarted = None
    if spikes:
        # A lobe shape on its lower bound (roughness -> 0, a needle between the cells): not an
        # optimum worth reporting. Restart from twice as many other points once.
        say(f"{name}: degenerate optimum ({', '.join(spikes)} on a bound); restarting")
        again = optimize(problem, method=optimizer, global_method=global_method,
                         n_starts=max(2 * n_starts, 16), seed=seed + 1, subsample=subsample,
                         max_iter=max_iter, refine=opts.refine)  # fmt: skip
        restarted = not _degenerate(layout, again.u)
        if restarted:
            opt = again
    fitted = layout.model(opt.u)
    if fd.values.size >= _SCORE_PASS_MIN_VALUES:
        # one compiled pass: no model values on the host (a MERL table: 2.7e6 of them)
        metrics, n_bad = problem.scores(opt.u, tuple(LOSSES))
    else:  # NumPy: no compilation per data size
        f = problem.predict(opt.u)
        n_bad = int(np.count_nonzero(~np.isfinite(f)))
        metrics = evaluate_many(LOSSES, f, fd) if not n_bad else {}
    if n_bad:
        raise FitError(f"{name}: the fitted model is not finite on the data")
    dof = max(n_res - layout.size, 1)
    # chi-square, AIC and BIC only where the data carry a measured sigma: without one the
    # "chi-square" is a sum of squares in sr^-2 and the criteria assume independent residuals
    # of a common variance that a table's smooth, correlated model error is not
    chi2 = metrics["wls"] if fd.sigma is not None else None
    aic = bic = None
    if fd.sigma is not None:
        aic, bic = information_criteria(opt.cost, n_res, layout.size, lo.statistical)
    at_bound = at_bounds(layout, opt.u, fd.channel_names)
    warnings_: list[str] = []
    if at_bound:
        shown = [f"{n} ({side})" for n, side in at_bound.items()]
        warnings_.append("parameters at their search bound: " + ", ".join(shown))
    if restarted is False:
        opt.converged = False
        opt.message = "degenerate optimum: " + ", ".join(_degenerate(layout, opt.u))
        opt.message += " on the bound of a needle lobe, also after a restart"
        warnings_.append(opt.message + "; not a usable fit")
    elif restarted:
        warnings_.append(f"restarted after a degenerate optimum ({', '.join(spikes)} on bound)")
    if not opt.converged and restarted is not False:
        warnings_.append(f"optimizer did not converge: {opt.message}")
    unc = None
    if uncertainty == "laplace":
        say(f"{name}: Laplace approximation")
        unc = laplace(problem, opt.u, method=laplace_method, covariance=opts.covariance)
    elif uncertainty == "mcmc":
        say(f"{name}: MCMC (burn-in from the prior box, then {mcmc_steps} steps)")
        unc = mcmc(problem, opt.u, n_steps=mcmc_steps, max_samples=mcmc_samples, seed=seed)
    if unc is not None:
        warnings_ += unc.warnings
    params = {
        k: float(np.asarray(v).reshape(-1)[0]) if np.size(v) == 1 else np.asarray(v).tolist()
        for k, v in fitted.params().items()
    }
    return FitResult(
        name=name,
        model=fitted,
        params=params,
        fixed=sorted(all_fixed),
        tied=dict(layout.tied),
        flat_names=layout.flat_names(fd.channel_names),
        uncertainty=unc,
        metric=lo.name,
        loss=lo.value(opt.cost),
        metrics=metrics,
        chi2=chi2,
        dof=dof,
        reduced_chi2=None if chi2 is None else chi2 / dof,
        aic=aic,
        bic=bic,
        data=fd.describe(),
        optimizer={
            "method": opt.method,
            "global_method": opt.global_method,
            "converged": opt.converged,
            "message": opt.message,
            "n_iter": opt.n_iter,
            "on_bounds": opt.on_bounds,
            "start_costs": opt.starts,
            "timings": opt.timings,
            "n_starts": n_starts,
            "seed": seed,
            "subsample": subsample,
            "refine": opts.refine,
        },
        warnings=warnings_,
        at_bound=at_bound,
        channel=channel,
        wall_s=time.perf_counter() - t0,
        u=opt.u,
    )
