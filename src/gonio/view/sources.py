"""What ``gonio view`` shows: each input (a file, a fit, an object) read once, through gonio's
one loader (:func:`gonio.io.load`) and its one fit-result reader
(:func:`gonio.io.fit_result.load_fit`), into a :class:`Source`."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gonio.errors import ParameterError


@dataclass
class Source:
    """One input of the page.

    Attributes
    ----------
    label : its name on the page.
    material : what the sphere and the curves evaluate (``f(wi, wo)``, 1 or 3 channels):
        measured data made renderable (:func:`gonio.render.measured.renderable`) or a model.
    measured : whether it is a measurement (else a fit or a model).
    samples : a scattered input's own rows ``(wi, wo, values, sigma)`` (``(N, 3)``, ``(N, 3)``,
        ``(N, C)`` in 1/sr, ``(N, C)`` or None), drawn as points and as its coverage.
    table : a gridded input's own table (its mask is drawn as its coverage), or None.
    record : a fit's record (the fit-result JSON), or None.
    notes : one-line notes on what was done to show it.
    """

    label: str
    material: Any
    measured: bool
    samples: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None] | None = None
    table: Any = None
    record: dict[str, Any] | None = None
    notes: list[str] = field(default_factory=list)


def _run_table(p: Path) -> Path:
    """A run folder stands for its ``table.brdf.h5``."""
    if p.is_dir():
        t = p / "table.brdf.h5"
        if not t.is_file():
            raise ParameterError(f"{p}: a folder without table.brdf.h5 (not a gonio run)")
        return t
    return p


def _is_fit(p: Path) -> bool:
    return p.suffix.lower() == ".json"


def from_object(obj: Any, label: str, notes: list[str] | None = None) -> Source:
    """A :class:`Source` of anything :func:`gonio.io.load` returns, or a model with ``f``."""
    from gonio.brdf.measured import MeasuredSamples
    from gonio.brdf.tabulated import TabulatedBRDF
    from gonio.render.measured import renderable, rgb_samples

    if not callable(getattr(obj, "f", None)):
        raise ParameterError(f"{label}: not a BRDF (no f(wi, wo))")
    measured = isinstance(obj, MeasuredSamples | TabulatedBRDF) or hasattr(obj, "to_table")
    from gonio.view.encode import compiled

    material, more = renderable(obj) if measured else (obj, [])
    material = compiled(material)
    c = material.f(np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, 1.0]])).shape[-1]
    if c not in (1, 3):
        raise ParameterError(f"{label}: gonio view shows 1 or 3 channels, the data has {c}")
    samples = table = None
    if isinstance(obj, MeasuredSamples):
        rows = rgb_samples(obj, "D65") if obj.channel_info.kind == "spectral" else obj
        samples = (rows.wi, rows.wo, rows.values, rows.sigma)
    elif isinstance(obj, TabulatedBRDF):
        table = obj
    return Source(label, material, measured, samples, table, None, [*(notes or []), *more])


def from_path(path: str | os.PathLike[str]) -> Source:
    """Read one input: a fit JSON, a run folder, or any file :func:`gonio.io.load` reads
    (``ARCHIVE.zip::NAME`` included).

    Raises
    ------
    GonioError
        the input cannot be read (one line naming it).
    """
    text = os.fspath(path)
    if "::" in text:
        from gonio import io

        return from_object(io.load(text, color="rgb"), text.rsplit("::", 1)[1])
    p = _run_table(Path(text))
    if not p.exists():
        raise ParameterError(f"file not found: {p}")
    if _is_fit(p):
        from gonio.io.fit_result import load_fit
        from gonio.render.cli import load_fitted

        record, _ = load_fit(p, descriptions=True)
        model, notes = load_fitted(p)
        src = from_object(model, p.name.removesuffix(".json"), notes)
        src.record = record
        return src
    from gonio import io

    label = p.parent.name if p.name == "table.brdf.h5" else p.name
    # spectral data (Cornell, spectral RGL files) as linear sRGB under D65, as gonio render shows it
    return from_object(io.load(p, color="rgb"), label)


def unique_labels(sources: list[Source]) -> None:
    """Number repeated labels (``name``, ``name (2)``, ...) in place."""
    seen: dict[str, int] = {}
    for s in sources:
        k = seen.get(s.label, 0) + 1
        seen[s.label] = k
        if k > 1:
            s.label = f"{s.label} ({k})"
