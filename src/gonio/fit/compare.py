"""Fit several models to the same data and say which one to use.

Every row lists the fitted loss, the fitted model's value under every metric of
:mod:`gonio.fit.losses`, the number of parameters and its flags. What ranks the models depends on
whether the data carry a measured sigma:

*With sigma* (gonio's own runs): chi^2/dof, AIC and BIC (:func:`gonio.fit.api.information_criteria`,
computed from the fitted metric so that they compare models fitted under the same metric). The
recommendation is the model with the lowest BIC, except that a model with fewer parameters whose
BIC is within 2 of the best is preferred (a BIC difference below 2 is not evidence; Kass &
Raftery 1995).

*Without sigma* (MERL, RGL, Cornell, ALTA, NBRDF tables): no chi-square, AIC or BIC is computed
or shown, since each assumes a noise level nobody measured (on a MERL table the "BIC" differences
run to millions). Models are ranked by what is measured, the first of :data:`RANK_MEASURES` that
every fit carries (lower is better): the appearance score (the mean HDR-FLIP of ``appearance``), the
cross-validated loss on held-out cells (``metrics["cv_loss"]``), else the fitted loss itself.
A model with fewer parameters whose measure is within :data:`AS_WELL` (1 %, relative) of the best
"fits as well" and is preferred: in particular the nested family without a lobe that reached its
bound (:func:`gonio.fit.bounds.nested_family`: Lambert alone when a matte paint's Lambert + TS
ends with f0 at 6e-6).

Either way a fit is not recommended while another is free of these flags: parameters at their
search bounds, an optimizer that did not converge (degenerate optima included), or intervals that
span the whole search box (unconstrained). When every model is flagged the best is named with its
flags in the reason.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from gonio.brdf.models import BRDFModel
from gonio.fit.api import fit
from gonio.fit.bounds import nested_family
from gonio.fit.result import FitResult
from gonio.fit.table_text import percent_above

#: What ranks fits of data without sigma: the first measure every fit carries (lower is better).
RANK_MEASURES = ("appearance", "cv_loss", "loss")
#: Relative margin within which a model with fewer parameters "fits as well" as the best.
AS_WELL = 0.01


@dataclass
class Comparison:
    """Results of several fits and the recommendation.

    Attributes
    ----------
    results : one FitResult per model (in the order given).
    table : one row per model: ``model``, ``n_params``, ``loss``, ``metric``, ``chi2_dof``,
        ``aic``, ``bic``, ``delta_bic``, ``metrics`` (every metric), ``appearance`` (the
        appearance score, or None), ``converged``.
    recommended : name of the recommended model.
    reason : one sentence explaining the choice.
    """

    results: list[FitResult]
    table: list[dict[str, Any]]
    recommended: str
    reason: str

    def to_json(self) -> dict[str, Any]:
        """JSON-ready summary (without the per-model details)."""
        from gonio.io.fit_result import to_jsonable

        d = {"table": self.table, "recommended": self.recommended, "reason": self.reason}
        return to_jsonable(d)


def flags(r: FitResult) -> list[str]:
    """Why a fit should not be used as it is (empty when nothing is wrong)."""
    out = []
    if r.at_bound or r.optimizer.get("on_bounds"):
        out.append("parameters at their bounds")
    if not r.optimizer.get("converged"):
        out.append("not converged")
    unc = r.uncertainty
    if unc is not None and unc.unconstrained:
        out.append("unconstrained parameters")
    return out


def measure(r: FitResult, name: str) -> float | None:
    """The value of rank measure ``name`` (:data:`RANK_MEASURES`) for ``r``, None if absent."""
    if name == "loss":
        v = r.loss
    elif name == "appearance":  # the mean HDR-FLIP of the sphere images (gonio.appearance)
        v = (r.appearance or {}).get("hdr_flip")
    else:
        v = r.metrics.get(name)
    return None if v is None else float(v)


def rank_measure(results: Sequence[FitResult]) -> str:
    """The first of :data:`RANK_MEASURES` that every result carries."""
    for name in RANK_MEASURES:
        if all(measure(r, name) is not None for r in results):
            return name
    return "loss"


def _has_sigma(results: Sequence[FitResult]) -> bool:
    return all(r.data.get("has_sigma") and r.bic is not None for r in results)


def _label(r: FitResult) -> str:
    return r.name if r.channel is None else f"{r.name}[{r.channel}]"


def summarize(results: Sequence[FitResult]) -> Comparison:
    """Build the comparison table and recommendation from finished fits."""
    if not results:
        raise ValueError("no results to compare")
    if _has_sigma(results):
        return _summarize_bic(results)
    return _summarize_measured(results)


def _row(r: FitResult) -> dict[str, Any]:
    return {
        "model": _label(r),
        "n_params": r.n_params,
        "loss": r.loss,
        "metric": r.metric,
        "metrics": r.metrics,
        "converged": bool(r.optimizer.get("converged")),
        "flags": flags(r),
        "at_bound": dict(r.at_bound),
        "appearance": r.appearance,
    }


def _summarize_measured(results: Sequence[FitResult]) -> Comparison:
    """Data without sigma: rank by a measured quantity (see the module docstring)."""
    by = rank_measure(results)
    clean = [r for r in results if not flags(r)]
    pool = clean or list(results)
    best_all = min(measure(r, by) for r in results)  # type: ignore[type-var]
    rows = []
    for r in results:
        v = measure(r, by)
        rows.append({**_row(r), "rank_by": by,
                     "delta_rank": (v - best_all) / max(abs(best_all), 1e-300)})  # fmt: skip
    top = min(results, key=lambda r: measure(r, by))  # type: ignore[arg-type, return-value]
    ref = measure(top, by)
    limit = ref + AS_WELL * abs(ref)  # type: ignore[operator]
    what = "loss" if by == "loss" else by
    # the smallest usable family whose measure is within AS_WELL of the best of all fits
    near = [r for r in pool if measure(r, by) <= limit]  # type: ignore[operator]
    if near:
        choice = min(near, key=lambda r: (r.n_params, measure(r, by)))
    else:
        choice = min(pool, key=lambda r: measure(r, by))  # type: ignore[arg-type, return-value]
    vc = measure(choice, by)
    if choice is not top and near:
        reason = (f"{choice.name} fits as well as {top.name} ({what} {vc:.4g} vs {ref:.4g}, "
                  f"within {AS_WELL:.0%})")  # fmt: skip
        if choice.n_params < top.n_params:
            reason += f" with {choice.n_params} instead of {top.n_params} parameters"
        if top.at_bound:
            reason += f"; {top.name} has {', '.join(top.at_bound)} at a bound"
    else:
        others = sorted((measure(r, by), r.name) for r in results if r is not choice)  # type: ignore
        if others:
            rel = (others[0][0] - vc) / max(abs(vc), 1e-300)  # type: ignore[operator]
            reason = (f"{choice.name} has the lowest {what} (next: {others[0][1]}, "
                      f"{percent_above(rel)})")  # fmt: skip
        else:
            reason = f"{choice.name} is the only model fitted" if len(results) == 1 else (
                f"{choice.name} is the only model without flags")  # fmt: skip
    skipped = [f"{r.name} ({', '.join(flags(r))})" for r in results
               if clean and flags(r) and r is not choice]  # fmt: skip
    if skipped:
        reason += f"; not considered: {'; '.join(skipped)}"
    if not clean and flags(choice):
        reason += f"; but every fit is flagged ({choice.name}: {', '.join(flags(choice))})"
    reason += f"; no sigma in the data: ranked by the measured {what}, not by a chi-square"
    return Comparison(list(results), rows, choice.name, reason)


def _summarize_bic(results: Sequence[FitResult]) -> Comparison:
    """Data with a measured sigma: chi2/dof, AIC, BIC (see the module docstring)."""
    clean = [r for r in results if not flags(r)]
    pool = clean or list(results)
    best_bic = min(r.bic for r in results)  # type: ignore[type-var]
    pool_bic = min(r.bic for r in pool)  # type: ignore[type-var]
    rows = []
    for r in results:
        rows.append(
            {
                **_row(r),
                "chi2_dof": r.reduced_chi2,
                "aic": r.aic,
                "bic": r.bic,
                "delta_bic": r.bic - best_bic,  # type: ignore[operator]
            }
        )
    best = min(pool, key=lambda r: r.bic)  # type: ignore[arg-type, return-value]
    near = [r for r in pool if r.bic - pool_bic < 2.0 and r.n_params < best.n_params]  # type: ignore[operator]
    if near:
        simple = min(near, key=lambda r: (r.n_params, r.bic))
        choice = simple
        reason = (
            f"{simple.name} is within 2 BIC of {best.name} with {simple.n_params} instead of "
            f"{best.n_params} parameters; the extra parameters are not supported by the data"
        )
    else:
        choice = best
        others = sorted((r.bic - pool_bic, r.name) for r in pool if r is not best)
        if others:
            reason = f"{best.name} has the lowest BIC (next: {others[0][1]}, +{others[0][0]:.1f})"
        else:
            reason = f"{best.name} is the only model fitted" if len(results) == 1 else (
                f"{best.name} is the only model without flags")  # fmt: skip
    skipped = [f"{r.name} ({', '.join(flags(r))})" for r in results if clean and flags(r)]
    if skipped:
        reason += f"; not considered: {'; '.join(skipped)}"
    if not clean:
        reason += f"; but every fit is flagged ({best.name}: {', '.join(flags(best))})"
    if choice.reduced_chi2 > 3.0 and choice.data.get("has_sigma"):
        reason += (
            f"; chi2/dof = {choice.reduced_chi2:.3g}: model error dominates the measurement "
            "noise, so quote intervals with the residual scale (Laplace's cluster sandwich or "
            "MCMC, whose likelihood then marginalizes the residual variance)"
        )
    return Comparison(list(results), rows, choice.name, reason)


def with_nested(
    results: Sequence[FitResult], fit_model: Callable[[str], Sequence[FitResult]]
) -> list[FitResult]:
    """``results`` plus fits of the nested families (:func:`gonio.fit.bounds.nested_family`)
    that are not among them; ``fit_model(name)`` fits one more model with the same options."""
    from gonio.fit.presets import available

    out = list(results)
    names = {r.name for r in out}
    todo = []
    for r in out:
        nested = nested_family(r, available())
        if nested is not None and nested not in names and nested not in todo:
            todo.append(nested)
    for name in todo:
        out += list(fit_model(name))
    return out


def compare(
    data: Any, models: Sequence[str | BRDFModel], loss: str = "wls", **kwargs: Any
) -> Comparison:
    """Fit every model in ``models`` to ``data`` (same options, see :func:`gonio.fit.fit`)."""
    res = fit(data, model=list(models), loss=loss, **kwargs)
    res = res if isinstance(res, list) else [res]

    def one(name: str) -> list[FitResult]:
        r = fit(data, model=name, loss=loss, **kwargs)
        return r if isinstance(r, list) else [r]

    return summarize(with_nested(res, one))
