"""Fit several models to the same data and say which one to use.

For every model the table lists the fitted loss, the fitted model's value under every metric of
:mod:`gonio.fit.losses`, chi^2/dof (with the data's sigma, or sigma = 1 when it has none), the
number of parameters, AIC and BIC (:func:`gonio.fit.api.information_criteria`, computed from the
fitted metric so that they compare models fitted under the same metric). The recommendation is
the model with the lowest BIC, except that a model with fewer parameters whose BIC is within 2
of the best is preferred (a BIC difference below 2 is not evidence; Kass & Raftery 1995).

A fit is not recommended while another is free of these flags: parameters on their search
bounds, an optimizer that did not converge (degenerate optima included), or intervals that span
the whole search box. When every model is flagged the best is named with its flags in the
reason.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from gonio.brdf.models import BRDFModel
from gonio.fit.api import fit
from gonio.fit.result import FitResult


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
    if r.optimizer.get("on_bounds"):
        out.append("parameters on their bounds")
    if not r.optimizer.get("converged"):
        out.append("not converged")
    unc = r.uncertainty
    if unc is not None and any("span the search box" in w for w in unc.warnings):
        out.append("intervals spanning the search box")
    return out


def summarize(results: Sequence[FitResult]) -> Comparison:
    """Build the comparison table and recommendation from finished fits."""
    if not results:
        raise ValueError("no results to compare")
    clean = [r for r in results if not flags(r)]
    pool = clean or list(results)
    best_bic = min(r.bic for r in results)
    pool_bic = min(r.bic for r in pool)
    rows = []
    for r in results:
        rows.append(
            {
                "model": r.name if r.channel is None else f"{r.name}[{r.channel}]",
                "n_params": r.n_params,
                "loss": r.loss,
                "metric": r.metric,
                "chi2_dof": r.reduced_chi2,
                "aic": r.aic,
                "bic": r.bic,
                "delta_bic": r.bic - best_bic,
                "metrics": r.metrics,
                "appearance": r.appearance,
                "converged": bool(r.optimizer.get("converged")),
                "flags": flags(r),
            }
        )
    best = min(pool, key=lambda r: r.bic)
    near = [r for r in pool if r.bic - pool_bic < 2.0 and r.n_params < best.n_params]
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
            "noise, so quote intervals from MCMC with the discrepancy term"
        )
    return Comparison(list(results), rows, choice.name, reason)


def compare(
    data: Any, models: Sequence[str | BRDFModel], loss: str = "wls", **kwargs: Any
) -> Comparison:
    """Fit every model in ``models`` to ``data`` (same options, see :func:`gonio.fit.fit`)."""
    res = fit(data, model=list(models), loss=loss, **kwargs)
    return summarize(res if isinstance(res, list) else [res])
