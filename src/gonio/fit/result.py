"""Fit results: the :class:`FitResult` record and its JSON form.

The file format (schema, reader, validation, writer) is :mod:`gonio.io.fit_result`, which every
command that reads a fit uses; :meth:`FitResult.to_json` produces a record of that format and
:meth:`FitResult.save` writes it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gonio.brdf.models import BRDFModel
from gonio.fit.uncertainty import Uncertainty
from gonio.io.fit_result import SCHEMA_ID, SCHEMA_VERSION, to_jsonable, write_result


@dataclass
class FitResult:
    """One fitted model with its diagnostics (see the module docstring for the JSON form).

    Attributes
    ----------
    name : the model name used to fit (``"lambert+ward"``) or the class name.
    model : the fitted model.
    params : value per parameter key, fixed ones included.
    fixed : keys held fixed.
    tied : ``{target: source}`` keys that equal another (their intervals are the source's).
    flat_names : names of the fitted scalar parameters (``"lambert.albedo[R]"``).
    uncertainty : Laplace or MCMC result, or None.
    metric, loss : the loss fitted and its reported value.
    metrics : the fitted model's value under every metric.
    chi2, dof, reduced_chi2 : wls chi-square with the data's sigma; None (``null`` in the JSON)
        when the data carry no measured sigma.
    aic, bic : information criteria from the fitted metric (see :mod:`gonio.fit.compare`);
        None without a measured sigma.
    data : description of the data (:meth:`FitData.describe`).
    optimizer : method, status, iterations, timings, parameters on bounds.
    warnings : caveats worth reading.
    at_bound : ``{flat name: "lower" | "upper"}`` of the values at their search bound
        (:func:`gonio.fit.bounds.at_bounds`).
    channel : channel name when fitted per channel, else None.
    appearance : the appearance score against the data's own sphere images
        (:func:`gonio.appearance.score` keys: HDR-FLIP and relative L1 per image and their
        means), or None where it was not computed (``gonio fit --score`` computes it).
    """

    name: str
    model: BRDFModel
    params: dict[str, Any]
    fixed: list[str]
    tied: dict[str, str]
    flat_names: list[str]
    uncertainty: Uncertainty | None
    metric: str
    loss: float
    metrics: dict[str, float]
    chi2: float | None
    dof: int
    reduced_chi2: float | None
    aic: float | None
    bic: float | None
    data: dict[str, Any]
    optimizer: dict[str, Any]
    warnings: list[str] = field(default_factory=list)
    at_bound: dict[str, str] = field(default_factory=dict)
    channel: str | None = None
    wall_s: float = 0.0
    u: np.ndarray | None = None
    appearance: dict[str, float] | None = None

    @property
    def n_params(self) -> int:
        return len(self.flat_names)

    # -- intervals by key -----------------------------------------------------------------------
    def _by_key(self, arr: np.ndarray | None) -> dict[str, Any]:
        """Regroup a flat (P, ...) array by parameter key; fixed keys get their value."""
        out: dict[str, Any] = {}
        if arr is None:
            return out
        groups: dict[str, list[Any]] = {}
        for name, v in zip(self.flat_names, arr, strict=True):
            key = name.split("[", 1)[0]
            groups.setdefault(key, []).append(v)
        for key, vals in groups.items():
            shape = np.shape(self.params[key])
            tail = np.shape(vals[0])  # per flat value: a scalar, or e.g. (lo, hi)
            out[key] = np.asarray(vals).reshape(*shape, *tail) if shape else np.asarray(vals[0])
        return out

    def standard_deviations(self) -> dict[str, Any]:
        """``{key: std}`` of the free parameters, shaped like ``params[key]`` (empty without
        uncertainty)."""
        return self._by_key(None if self.uncertainty is None else self.uncertainty.std)

    def intervals(self, level: int = 95) -> dict[str, list[Any]]:
        """``{key: [lo, hi]}`` at 95 (or 68) percent of the fitted parameters (and of those tied
        to them). Fixed parameters have none: they are listed in ``fixed`` (shown as "fixed"),
        not given a zero-width interval that would read as a measured certainty. Parameters the
        data do not constrain (``uncertainty.unconstrained``) get NaN bounds: an interval that
        spans the search box is no interval."""
        out: dict[str, list[Any]] = {}
        if self.uncertainty is None:
            return out
        arr = self.uncertainty.interval95 if level == 95 else self.uncertainty.interval68
        loose = set(self.uncertainty.unconstrained)
        if loose:  # never reported as an interval: null bounds (JSON), listed as unconstrained
            arr = np.array(arr, dtype=float)
            arr[[n in loose for n in self.flat_names]] = np.nan
        for key, v in self._by_key(arr).items():
            out[key] = [v[..., 0], v[..., 1]]
        for target, source in self.tied.items():
            if source in out:
                out[target] = out[source]
        return out

    def to_json(self) -> dict[str, Any]:
        """The JSON-ready dictionary (validates against :data:`gonio.io.fit_result.SCHEMA`)."""
        from gonio import __version__

        unc = self.uncertainty
        d: dict[str, Any] = {
            "schema": SCHEMA_ID,
            "version": SCHEMA_VERSION,
            "model": self.name,
            "model_type": type(self.model).__name__,
            "model_spec": self.model.to_dict(),
            "params": self.params,
            "fixed": self.fixed,
            "tied": self.tied,
            "intervals": self.intervals(95),
            "intervals68": self.intervals(68),
            "std": self.standard_deviations(),
            "correlation": None if unc is None else {"names": unc.names, "matrix": unc.correlation},
            "loss": self.loss,
            "metric": self.metric,
            "metrics": self.metrics,
            "appearance": self.appearance,
            "chi2": self.chi2,
            "dof": int(self.dof),
            "reduced_chi2": self.reduced_chi2,
            "aic": self.aic,
            "bic": self.bic,
            "n_params": self.n_params,
            "channel": self.channel,
            "data": self.data,
            "optimizer": self.optimizer,
            "uncertainty": None
            if unc is None
            else {
                "method": unc.method,
                "median": self._by_key(unc.center),
                "diagnostics": unc.diagnostics,
                "warnings": unc.warnings,
            },
            "warnings": self.warnings,
            "at_bound": self.at_bound,
            "unconstrained": [] if unc is None else list(unc.unconstrained),
            "wall_s": self.wall_s,
            "gonio_version": __version__,
        }
        return to_jsonable(d)

    def save(self, path: str | Path) -> Path:
        """Write the JSON atomically (temporary file, then rename); returns the path."""
        return write_result(self.to_json(), path)
