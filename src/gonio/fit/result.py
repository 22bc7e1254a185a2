"""Fit results: the :class:`FitResult` record, its JSON form and JSON Schema, and loading back.

A result file holds one fitted model: ``model`` (the name it was fitted under), ``params``
``{key: value}`` (per-channel values as lists), ``intervals`` ``{key: [lo95, hi95]}`` (each bound
shaped like the value), ``loss`` and ``metric``, a description of the ``data``, optimizer and
uncertainty diagnostics, and ``model_spec``: the model's own ``to_dict()`` so that
:func:`load_model` returns a usable gonio model. :data:`SCHEMA` is the JSON Schema, generated
from this module (``python -m gonio.fit.result`` rewrites data-schema/fit-result.schema.json).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gonio._bounded import read_json
from gonio.brdf.models import BRDFModel, Node
from gonio.errors import FormatError
from gonio.fit._spec_check import check_model_spec
from gonio.fit.uncertainty import Uncertainty
from gonio.io.atomic import atomic_output

SCHEMA_ID = "gonio/fit-result"
SCHEMA_VERSION = 1

_num = {"type": ["number", "null"]}
# A parameter value: a number, one per channel or lobe (C,) / (L,), or per lobe and channel (L, C).
_vector = {"type": "array", "items": _num, "minItems": 1}
_value = {"oneOf": [_num, _vector, {"type": "array", "items": _vector, "minItems": 1}]}
_pair = {"type": "array", "items": _value, "minItems": 2, "maxItems": 2}

#: JSON Schema (draft 2020-12) of a fit-result file.
SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "$id": "https://gonio.invalid/schemas/fit-result.schema.json",
    "title": "gonio fit result",
    "description": (
        "One analytic BRDF model fitted to measured data by gonio.fit. Values are physical "
        "(BRDF in 1/sr, angles in radians, albedos dimensionless); non-finite numbers are null."
    ),
    "type": "object",
    "required": [
        "schema",
        "version",
        "model",
        "model_spec",
        "params",
        "intervals",
        "loss",
        "metric",
        "data",
    ],
    "properties": {
        "schema": {"const": SCHEMA_ID},
        "version": {"const": SCHEMA_VERSION},
        "model": {"type": "string", "description": "name the model was fitted under"},
        "model_type": {"type": "string"},
        "model_spec": {
            "type": "object",
            "required": ["type"],
            "description": "the model's to_dict(); gonio.fit.load_model rebuilds it",
        },
        "params": {
            "type": "object",
            "additionalProperties": _value,
            "description": "fitted value per parameter key (lists for per-channel values)",
        },
        "fixed": {"type": "array", "items": {"type": "string"}},
        "tied": {"type": "object", "additionalProperties": {"type": "string"}},
        "intervals": {
            "type": "object",
            "additionalProperties": _pair,
            "description": "95% interval [lo, hi] per fitted parameter key (null bounds: "
            "unknown); fixed parameters have none (see fixed)",
        },
        "intervals68": {"type": "object", "additionalProperties": _pair},
        "std": {"type": "object", "additionalProperties": _value},
        "correlation": {
            "type": ["object", "null"],
            "required": ["names", "matrix"],
            "properties": {
                "names": {"type": "array", "items": {"type": "string"}},
                "matrix": {"type": "array", "items": {"type": "array", "items": _num}},
            },
        },
        "loss": _num,
        "metric": {"type": "string"},
        "metrics": {"type": "object", "additionalProperties": _num},
        "chi2": _num,
        "dof": {"type": "integer"},
        "reduced_chi2": _num,
        "aic": _num,
        "bic": _num,
        "n_params": {"type": "integer", "minimum": 0},
        "channel": {"type": ["string", "null"]},
        "data": {
            "type": "object",
            "required": ["n_samples", "channels"],
            "properties": {
                "n_samples": {"type": "integer", "minimum": 0},
                "channels": {"type": "array", "items": {"type": "string"}},
            },
        },
        "optimizer": {"type": "object"},
        "uncertainty": {"type": ["object", "null"]},
        "warnings": {"type": "array", "items": {"type": "string"}},
        "wall_s": _num,
        "gonio_version": {"type": "string"},
    },
}


def to_jsonable(x: Any) -> Any:
    """NumPy -> JSON: arrays to lists, non-finite floats to None (nested dicts and lists)."""
    if isinstance(x, dict):
        return {str(k): to_jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [to_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return to_jsonable(x.tolist())
    if isinstance(x, (np.floating, float)):
        v = float(x)
        return v if math.isfinite(v) else None
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


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
    chi2, dof, reduced_chi2 : wls chi-square (with the data's sigma, or 1 when absent).
    aic, bic : information criteria from the fitted metric (see :mod:`gonio.fit.compare`).
    data : description of the data (:meth:`FitData.describe`).
    optimizer : method, status, iterations, timings, parameters on bounds.
    warnings : caveats worth reading.
    channel : channel name when fitted per channel, else None.
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
    chi2: float
    dof: int
    reduced_chi2: float
    aic: float
    bic: float
    data: dict[str, Any]
    optimizer: dict[str, Any]
    warnings: list[str] = field(default_factory=list)
    channel: str | None = None
    wall_s: float = 0.0
    u: np.ndarray | None = None

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
        not given a zero-width interval that would read as a measured certainty."""
        out: dict[str, list[Any]] = {}
        if self.uncertainty is None:
            return out
        arr = self.uncertainty.interval95 if level == 95 else self.uncertainty.interval68
        for key, v in self._by_key(arr).items():
            out[key] = [v[..., 0], v[..., 1]]
        for target, source in self.tied.items():
            if source in out:
                out[target] = out[source]
        return out

    def to_json(self) -> dict[str, Any]:
        """The JSON-ready dictionary (validates against :data:`SCHEMA`)."""
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
            "wall_s": self.wall_s,
            "gonio_version": __version__,
        }
        return to_jsonable(d)

    def save(self, path: str | Path) -> Path:
        """Write the JSON atomically (temporary file, then rename); returns the path."""
        return write_json(self.to_json(), path)


def write_json(obj: Any, path: str | Path) -> Path:
    """Write ``obj`` as indented JSON atomically."""
    path = Path(path)
    with atomic_output(path, make_parents=True) as tmp, open(tmp, "w") as fh:
        json.dump(obj, fh, indent=2, allow_nan=False)
        fh.write("\n")
    return path


def read_result(path: str | Path) -> dict[str, Any]:
    """Read and validate a fit-result JSON file; FormatError naming the problem otherwise."""
    import jsonschema

    path = Path(path)
    obj = read_json(path)  # size, UTF-8, nesting depth and finite numbers, see gonio._bounded
    try:
        jsonschema.validate(obj, SCHEMA)
    except jsonschema.ValidationError as exc:
        where = "/".join(str(p) for p in exc.absolute_path) or "top level"
        raise FormatError(f"{path}: not a fit result ({where}: {exc.message[:120]})") from None
    return obj


def load_model(path: str | Path) -> BRDFModel:
    """The fitted model stored in a fit-result JSON file, ready to evaluate or render."""
    from gonio.errors import ParameterError

    obj = read_result(path)
    check_model_spec(obj["model_spec"], str(path))  # no missing, null or mistyped parameter
    try:
        model = Node.from_dict(obj["model_spec"])
    except (ParameterError, TypeError, KeyError, ValueError) as exc:
        raise FormatError(f"{path}: model_spec cannot be rebuilt ({exc})") from None
    if not isinstance(model, BRDFModel):
        raise FormatError(f"{path}: model_spec describes a {type(model).__name__}, not a BRDF")
    return model


def schema_path() -> Path:
    """Where the generated schema lives in a source checkout."""
    return Path(__file__).resolve().parents[3] / "data-schema" / "fit-result.schema.json"


def schema_text() -> str:
    """The schema as written to data-schema/fit-result.schema.json."""
    return json.dumps(SCHEMA, indent=2) + "\n"


if __name__ == "__main__":  # pragma: no cover - regenerates the published schema
    p = schema_path()
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(schema_text())
    print(p)
