"""The fit-result file format: its JSON Schema, reader, validation and writer, in one place.

A result file holds one fitted model: ``model`` (the name it was fitted under), ``params``
``{key: value}`` (per-channel values as lists), ``intervals`` ``{key: [lo95, hi95]}`` (each bound
shaped like the value), ``loss`` and ``metric``, a description of the ``data``, optimizer and
uncertainty diagnostics, and ``model_spec``: the model's own ``to_dict()`` so that
:func:`load_model` returns a usable gonio model. :data:`SCHEMA` is the JSON Schema
(``python -m gonio.io.schemas --write`` writes it to data-schema/fit-result.schema.json).

Every command that reads a fit (``gonio render``, ``export``, ``plot``, ``fit --score``, the
demo) reads it here: :func:`read_result` checks the file against :data:`SCHEMA` and the model
description field by field (:func:`check_model_spec`), so a mistyped field is one
:class:`~gonio.errors.FormatError` naming it, never a ``TypeError`` from deep inside a command.
The record class :class:`gonio.fit.FitResult` writes the files through :func:`write_result`,
which applies the reader's checks (:func:`validate`) before writing strict JSON: gonio never
writes a fit result it would refuse to read.

This module imports only :mod:`gonio.brdf` (the model registry), and that only when a model is
rebuilt, so that ``fit``, ``render`` and ``export`` may all use it.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from gonio._bounded import loads_json, read_json
from gonio.errors import FormatError
from gonio.io.schemas import default_dir, register_schema, render
from gonio.io.strict_json import write_json

SCHEMA_ID = "gonio/fit-result"
SCHEMA_VERSION = 1

_num = {"type": ["number", "null"]}
# A parameter value: a number, one per channel or lobe (C,) / (L,), or per lobe and channel (L, C).
_vector = {"type": "array", "items": _num, "minItems": 1}
_value = {"oneOf": [_num, _vector, {"type": "array", "items": _vector, "minItems": 1}]}
_pair = {"type": "array", "items": _value, "minItems": 2, "maxItems": 2}
_count = {"type": "integer", "minimum": 0}
_text = {"type": ["string", "null"]}

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
        "appearance": {
            "type": ["object", "null"],
            "additionalProperties": _num,
            "description": "appearance score against the measurement's sphere images "
            "(gonio.appearance): hdr_flip and rel_l1 (means over the images) and per image "
            "(_0, _30, _60: light angle from the view in degrees; _env: the studio), "
            "resolution_px, env_samples; null where not computed",
        },
        "chi2": _num,
        "dof": {"type": "integer"},
        "reduced_chi2": _num,
        "aic": _num,
        "bic": _num,
        "n_params": _count,
        "channel": {"type": ["string", "null"]},
        "data": {
            "type": "object",
            "required": ["n_samples", "channels"],
            "properties": {
                "n_samples": _count,
                "channels": {"type": "array", "items": {"type": "string"}},
                "kind": _text,
                "name": _text,
                "path": {**_text, "description": "the measurement file fitted (export refits it)"},
                "theta_max_deg": _num,
                "has_sigma": {"type": "boolean"},
                "n_input": _count,
                "n_used": _count,
                "n_invalid": _count,
                "n_beyond_cutoff": _count,
            },
        },
        "optimizer": {"type": "object"},
        "uncertainty": {"type": ["object", "null"]},
        "warnings": {"type": "array", "items": {"type": "string"}},
        "wall_s": _num,
        "gonio_version": {"type": "string"},
    },
}

#: A model description's optional ``data`` object: :data:`SCHEMA`'s ``data`` without its
#: required fields.
DATA_FIELDS_SCHEMA: dict[str, Any] = {
    k: v for k, v in SCHEMA["properties"]["data"].items() if k != "required"
}

_MAX_LOBES = 64
_MAX_VALUE_RANK = 3


@register_schema("fit-result.schema.json")
def fit_result_schema() -> dict[str, Any]:
    """The schema of a ``gonio fit`` result file."""
    return dict(SCHEMA)


# -- writing -----------------------------------------------------------------------------------


def to_jsonable(x: Any) -> Any:
    """NumPy -> JSON: arrays to lists, non-finite floats to None (nested dicts and lists).

    ``null`` is how the format writes a number that is not finite (an unbounded interval, a
    loss that diverged); :data:`SCHEMA` says so.
    """
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


def write_result(record: dict[str, Any], path: str | Path) -> Path:
    """Write a fit-result record (``FitResult.to_json()``) as strict JSON, atomically, after
    the checks the reader applies (:func:`validate`): a record the reader would refuse is a
    FormatError naming ``path`` and the field, and nothing is written."""
    path = Path(path)
    validate(record, str(path))
    return write_json(record, path)


# -- reading and validation --------------------------------------------------------------------


def validate(record: Any, source: str = "fit result") -> dict[str, Any]:
    """``record`` (a parsed fit-result JSON) when it is a complete, well-typed fit result.

    Checks the schema name and version first (an unsupported version is named as such), then
    :data:`SCHEMA` (every field's type), then the model description
    (:func:`check_model_spec`).

    Raises
    ------
    FormatError
        ``"<source>: ..."``, one line naming the field at fault.
    """
    if isinstance(record, dict) and record.get("schema") == SCHEMA_ID:
        v = record.get("version")
        if v != SCHEMA_VERSION:
            raise FormatError(
                f"{source}: unsupported fit file (fit-result schema version {v!r} is not "
                f"supported; this gonio reads version {SCHEMA_VERSION})"
            )
    _check(record, SCHEMA, source, "not a fit result")
    check_model_spec(record["model_spec"], source)
    return record


def _check(instance: Any, schema: dict[str, Any], source: str, what: str, at: str = "") -> None:
    """FormatError ``"<source>: <what> (<field path>: <problem>)"`` unless ``instance`` is valid
    under ``schema``; ``at`` prefixes the field path."""
    import jsonschema

    # what jsonschema.validate does, with the schema checked against its metaschema once per
    # schema rather than at every record (most of the cost of writing a small result)
    exc = jsonschema.exceptions.best_match(_validator(schema).iter_errors(instance))
    if exc is not None:
        where = "/".join([*([at] if at else []), *map(str, exc.absolute_path)]) or "top level"
        message = " ".join(exc.message.split())[:120]
        raise FormatError(f"{source}: {what} ({where}: {message})") from None


#: Validators of the module's schemas (:data:`SCHEMA`, :data:`DATA_FIELDS_SCHEMA`), by identity.
_VALIDATORS: dict[int, Any] = {}


def _validator(schema: dict[str, Any]) -> Any:
    """A jsonschema validator of ``schema`` (one of this module's schemas), checked against
    its metaschema once."""
    import jsonschema

    v = _VALIDATORS.get(id(schema))
    if v is None:
        cls = jsonschema.validators.validator_for(schema)
        cls.check_schema(schema)
        v = _VALIDATORS[id(schema)] = cls(schema)
    return v


def read_result(path: str | Path) -> dict[str, Any]:
    """Read and validate a fit-result JSON file (:func:`validate`); FormatError otherwise.

    The file is parsed within :mod:`gonio._bounded`'s limits (size, UTF-8, nesting depth,
    finite numbers, no duplicate keys).
    """
    return validate(read_json(path), str(path))


def model_of(spec: dict[str, Any], source: str = "fit result") -> Any:
    """The model a checked description (:func:`check_model_spec`) describes: a BRDF model."""
    from gonio.brdf.models import BRDFModel, Node
    from gonio.errors import ParameterError

    try:
        model = Node.from_dict(spec)
    except (ParameterError, TypeError, KeyError, ValueError) as exc:
        text = " ".join(str(exc).split())[:200]
        raise FormatError(f"{source}: model_spec cannot be rebuilt ({text})") from None
    if not isinstance(model, BRDFModel):
        raise FormatError(f"{source}: model_spec describes a {type(model).__name__}, not a BRDF")
    return model


def load_model(path: str | Path) -> Any:
    """The fitted model stored in a fit-result JSON file, ready to evaluate or render."""
    return model_of(read_result(path)["model_spec"], str(path))


def load_fit(path: str | Path, *, descriptions: bool = False) -> tuple[dict[str, Any], Any]:
    """``(record, model)`` of a fit-result file (:func:`read_result`).

    With ``descriptions``, a file without ``schema``/``version`` keys may instead hold a bare
    model description: a model's ``to_dict()``, or an object holding it under ``model_spec``
    (or ``model``), with an optional ``data`` object. The description is checked as strictly as
    a fit's, ``data`` against the schema's; ``record`` is then the document itself (a bare
    description: an empty dictionary).
    """
    return fit_from_document(read_json(path), str(path), descriptions=descriptions)


def load_fit_text(
    text: str, source: str = "fit text", *, descriptions: bool = False
) -> tuple[dict[str, Any], Any]:
    """``(record, model)`` of a fit result (or, with ``descriptions``, a model description)
    given as JSON text, read within the same limits and checks as :func:`load_fit`."""
    return fit_from_document(
        loads_json(text.encode("utf-8"), source), source, descriptions=descriptions
    )


def fit_from_document(
    doc: Any, source: str, *, descriptions: bool = False
) -> tuple[dict[str, Any], Any]:
    """``(record, model)`` of a parsed JSON document: the checks of :func:`load_fit`."""
    if not descriptions or not isinstance(doc, dict) or "schema" in doc or "version" in doc:
        record = validate(doc, source)
        return record, model_of(record["model_spec"], source)
    if "type" in doc:
        spec, doc = doc, {}
    else:
        spec = doc.get("model_spec", doc.get("model"))
    if not isinstance(spec, dict):
        raise FormatError(f"{source}: no model description (expected a 'model_spec' object)")
    check_model_spec(spec, source)
    _check(doc.get("data", {}), DATA_FIELDS_SCHEMA, source, "not a model description", "data")
    return doc, model_of(spec, source)


def _numbers(value: Any, rank: int = 0) -> bool:
    """True for a finite number or a (nested, rectangular or not) non-empty list of them."""
    if isinstance(value, bool):
        return False
    if isinstance(value, int | float):
        return math.isfinite(value)
    if isinstance(value, list) and value and rank < _MAX_VALUE_RANK:
        return all(_numbers(v, rank + 1) for v in value)
    return False


def check_model_spec(spec: Any, source: str, where: str = "model_spec") -> None:
    """Raise :class:`FormatError` ``"<source>: <where>...: <problem>"`` unless ``spec`` is a
    complete, well-typed model description.

    :meth:`Node.from_dict` trusts its input: a missing parameter silently takes the
    constructor's default (a Lambert albedo of 0.5 that was never fitted), a ``params`` that is
    not a mapping raises a bare ``TypeError``. This walks the description first and refuses,
    naming the field: unknown model types, fields of the wrong type, missing or null
    parameters, unknown parameters, and parameter values that are not finite numbers (or nested
    lists of them).
    """
    from gonio.brdf.models import registry

    def bad(problem: str) -> FormatError:
        return FormatError(f"{source}: {where}: {problem}")

    if not isinstance(spec, dict):
        raise bad("not an object")
    kind = spec.get("type")
    classes = registry()
    if not isinstance(kind, str) or kind not in classes:
        raise bad(f"unknown model type {str(kind)[:40]!r}")
    if kind == "Sum":
        lobes = spec.get("lobes")
        if not isinstance(lobes, list) or not 1 <= len(lobes) <= _MAX_LOBES:
            raise bad(f"a Sum needs 1 to {_MAX_LOBES} lobes")
        for i, lobe in enumerate(lobes):
            check_model_spec(lobe, source, f"{where}.lobes[{i}]")
        return
    cls = classes[kind]
    parts = {}
    for key in ("params", "static", "children"):
        value = spec.get(key, {})
        if not isinstance(value, dict):
            raise bad(f"{key} is not an object")
        parts[key] = value
    params, static, children = parts["params"], parts["static"], parts["children"]
    names = [p.name for p in cls.PARAMS]
    missing = [name for name in names if params.get(name) is None]
    if missing:
        raise bad(
            f"parameter {missing[0]!r} of {kind} is missing or null (the description lacks "
            f"parameter(s) {', '.join(missing)}; none is filled in with a default)"
        )
    for name in names:
        if not _numbers(params[name]):
            raise bad(f"parameter {name!r} of {kind} is not a finite number or list of numbers")
    for key, allowed in (("params", names), ("static", cls.STATIC), ("children", cls.CHILDREN)):
        unknown = sorted(set(parts[key]) - set(allowed))
        if unknown:
            raise bad(f"unknown {key} entry {unknown[0][:40]!r} for {kind}")
    for name, value in static.items():
        if value is not None and not isinstance(value, str | int | float | bool):
            raise bad(f"static option {name!r} of {kind} is not a string, number or boolean")
    for name, child in children.items():
        kids = child if isinstance(child, list) else [child]
        for i, c in enumerate(kids):
            if c is not None:
                check_model_spec(c, source, f"{where}.{name}" + (f"[{i}]" if kids is child else ""))


def schema_path() -> Path:
    """Where the generated schema lives in a source checkout."""
    return default_dir() / "fit-result.schema.json"


def schema_text() -> str:
    """The schema as written to data-schema/fit-result.schema.json (:mod:`gonio.io.schemas`)."""
    return render(fit_result_schema())
