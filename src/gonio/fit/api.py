"""``gonio.fit.fit``: fit one model (or several) to measured data, with optional uncertainty."""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from gonio.brdf.models import BRDFModel
from gonio.errors import FitError, ParameterError
from gonio.fit import presets
from gonio.fit.data import DEFAULT_THETA_MAX_DEG, FitData, prepare
from gonio.fit.losses import LOSSES, evaluate, get_loss
from gonio.fit.objective import Problem
from gonio.fit.optimize import optimize
from gonio.fit.params import Layout
from gonio.fit.result import FitResult
from gonio.fit.uncertainty import laplace, mcmc

UNCERTAINTY_METHODS = (None, "laplace", "mcmc")


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


def _resolve_model(
    model: str | BRDFModel,
) -> tuple[str, BRDFModel, dict[str, Any], dict[str, str]]:
    if isinstance(model, BRDFModel):
        return type(model).__name__.lower(), model, {}, {}
    if isinstance(model, str):
        return (model, *presets.build(model))
    raise FitError(f"model must be a name or a gonio model, got {type(model).__name__}")


def fit(
    data: Any,
    model: str | BRDFModel | Sequence[str | BRDFModel] = "lambert+ward",
    loss: str = "wls",
    uncertainty: str | None = None,
    *,
    theta_max_deg: float = DEFAULT_THETA_MAX_DEG,
    fixed: Mapping[str, Any] | None = None,
    tie: bool = True,
    channels: str = "shared",
    optimizer: str = "lm",
    global_method: str | None = None,
    n_starts: int = 8,
    seed: int = 0,
    subsample: int = 4000,
    max_iter: int = 200,
    laplace_method: str = "gauss-newton",
    mcmc_steps: int = 2000,
    mcmc_samples: int = 3000,
    name: str | None = None,
    progress: Callable[[str], None] | None = None,
) -> FitResult | list[FitResult]:
    """Fit an analytic BRDF model to measured data.

    Parameters
    ----------
    data : a TabulatedBRDF, MeasuredSamples, :class:`~gonio.fit.data.FitData` or a file path.
    model : a model name (see :func:`gonio.fit.presets.available`, e.g. ``"lambert+ward"``), a
        gonio model used as template (its values are the starting point), or a list of either
        (then a list of results, one per model, is returned).
    loss : ``"wls"``, ``"ngan"``, ``"low-e1"``, ``"low-e2"`` or ``"cube-root"`` (see
        :mod:`gonio.fit.losses`).
    uncertainty : None, ``"laplace"`` or ``"mcmc"`` (see :mod:`gonio.fit.uncertainty`).
    theta_max_deg : polar-angle cutoff for both directions, degrees (applied also to data that
        was already prepared with another cutoff).
    fixed : parameter keys held at given values (``{"ward.rho_d": 0.0}``).
    tie : apply the named model's ties (isotropic Ward: ``alpha_y = alpha_x``); False fits
        every parameter of the preset separately.
    channels : ``"shared"`` (lobe shapes shared, per-channel albedos) or ``"separate"`` (each
        channel fitted on its own; returns one result per channel).
    optimizer : local method ``"lm"``, ``"lbfgs"`` or ``"slsqp"``.
    global_method : None, ``"crs2"``, ``"mlsl"`` or ``"direct"`` before the local stage.
    n_starts, seed, subsample, max_iter : multi-start settings (see :func:`~.optimize.optimize`).
    laplace_method : ``"gauss-newton"`` or ``"hessian"``.
    mcmc_steps, mcmc_samples : chain length per walker and data subsample size for MCMC.
    name : material name for the record.
    progress : called with a short text before each stage (for progress displays).

    Returns
    -------
    FitResult, or a list of them (several models, or ``channels="separate"``).

    Raises
    ------
    FitError
        When the data cannot be fitted (no valid samples, fewer values than parameters, all
        values zero, unknown names).
    """
    if uncertainty not in UNCERTAINTY_METHODS:
        raise FitError(f"unknown uncertainty method {uncertainty!r}; valid: laplace, mcmc")
    if channels not in ("shared", "separate"):
        raise FitError(f"channels must be 'shared' or 'separate', got {channels!r}")
    get_loss(loss)
    if isinstance(data, FitData) and data.source.get("theta_max_deg") == float(theta_max_deg):
        fd = data  # already validated with this cutoff
        if name is not None:
            fd = dataclasses.replace(fd, source={**fd.source, "name": name})
    else:
        fd = prepare(data, theta_max_deg, name=name)
    if not np.any(fd.values > 0):
        raise FitError(f"all {fd.values.size} measured values are <= 0: nothing to fit")
    kwargs = dict(
        tie=tie,
        loss=loss,
        uncertainty=uncertainty,
        fixed=fixed,
        optimizer=optimizer,
        global_method=global_method,
        n_starts=n_starts,
        seed=seed,
        subsample=subsample,
        max_iter=max_iter,
        laplace_method=laplace_method,
        mcmc_steps=mcmc_steps,
        mcmc_samples=mcmc_samples,
        progress=progress,
    )
    many = not isinstance(model, (str, BRDFModel))
    model_list = list(model) if many else [model]  # type: ignore[arg-type]
    if not model_list:
        raise FitError("no model given")
    results: list[FitResult] = []
    for m in model_list:
        if channels == "separate" and fd.channels > 1:
            for c in range(fd.channels):
                results.append(_fit_one(fd.channel(c), m, channel=fd.channel_names[c], **kwargs))
        else:
            results.append(_fit_one(fd, m, **kwargs))
    return results if (many or len(results) > 1) else results[0]


def _fit_one(
    fd: FitData,
    model: str | BRDFModel,
    *,
    loss: str,
    uncertainty: str | None,
    fixed: Mapping[str, Any] | None,
    tie: bool,
    optimizer: str,
    global_method: str | None,
    n_starts: int,
    seed: int,
    subsample: int,
    max_iter: int,
    laplace_method: str,
    mcmc_steps: int,
    mcmc_samples: int,
    progress: Callable[[str], None] | None,
    channel: str | None = None,
) -> FitResult:
    t0 = time.perf_counter()
    say = progress or (lambda s: None)
    name, tmpl, preset_fixed, preset_tied = _resolve_model(model)
    all_fixed = {**preset_fixed, **dict(fixed or {})}
    tied = {t: s for t, s in (preset_tied if tie else {}).items() if t not in all_fixed}
    try:
        layout = Layout(tmpl, fd.channels, fixed=all_fixed, tied=tied)
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
    )
    fitted = layout.model(opt.u)
    f = problem.predict(opt.u)
    if not np.all(np.isfinite(f)):
        raise FitError(f"{name}: the fitted model is not finite on the data")
    metrics = {k: evaluate(k, f, fd) for k in LOSSES}
    sig = 1.0 if fd.sigma is None else fd.sigma
    chi2 = float(np.sum(((f - fd.values) / sig) ** 2))
    dof = max(n_res - layout.size, 1)
    statistical = lo.statistical and fd.sigma is not None
    aic, bic = information_criteria(opt.cost, n_res, layout.size, statistical)
    warnings_: list[str] = []
    if opt.on_bounds:
        flat = layout.flat_names(fd.channel_names)
        idx = {n: i for i, n in enumerate(layout.flat_names())}
        shown = [flat[idx[n]] for n in opt.on_bounds]
        warnings_.append("parameters ended on their search bound: " + ", ".join(shown))
    if not opt.converged:
        warnings_.append(f"optimizer did not converge: {opt.message}")
    unc = None
    if uncertainty == "laplace":
        say(f"{name}: Laplace approximation")
        unc = laplace(problem, opt.u, method=laplace_method)
    elif uncertainty == "mcmc":
        say(f"{name}: Laplace approximation")
        init = laplace(problem, opt.u, method=laplace_method)
        say(f"{name}: MCMC ({mcmc_steps} steps)")
        unc = mcmc(
            problem, opt.u, n_steps=mcmc_steps, max_samples=mcmc_samples, seed=seed, init=init
        )
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
        reduced_chi2=chi2 / dof,
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
        },
        warnings=warnings_,
        channel=channel,
        wall_s=time.perf_counter() - t0,
        u=opt.u,
    )
