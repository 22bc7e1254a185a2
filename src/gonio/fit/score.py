"""Scores of any model (fitted or published) on a measured table, by the literature's metrics.

Both scores are computed on the data's own samples, as :func:`gonio.fit.data.prepare` gives
them: for a table, its valid cells with both polar angles at most ``theta_max`` (80 degrees by
default), each weighted by its exact measure in direction-pair space
(:meth:`~gonio.brdf.tabulated.TabulatedBRDF.cell_measure`, sr^2), so that a sum over cells is a
quadrature of the integral over the hemisphere pair. The formulas are the losses of
:mod:`gonio.fit.losses` (the same code a fit minimizes):

``ngan``   Ngan, Durand & Matusik 2005: ``sqrt(sum w ((f - y) cos_i)^2 / (C W))`` (sr^-1).
``low-e2`` Löw, Kronander, Ynnerman & Unger 2012, log metric: ``sqrt(sum w (ln(1 + f) -
           ln(1 + y))^2 / (C W))``.

A published fit (any file of ``../shared/data/fits/``: Ngan et al.'s, Löw et al.'s, Bagher et
al.'s) is scored through :func:`gonio.brdf.published.to_model`; Ngan's Cook-Torrance, Ward and
Blinn-Phong fits through :func:`gonio.brdf.ngan.to_family`, so that they are evaluated by the
same model code as gonio's fit of the same family.

The appearance score (:mod:`gonio.appearance`) is computed beside them by
:func:`appearance_reference` (the measurement's own sphere images, once) and
:func:`appearance_score` (a model's images against them).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from gonio.brdf.models import BRDFModel
from gonio.errors import FitError, FormatError, GonioError
from gonio.fit.data import DEFAULT_THETA_MAX_DEG, FitData, prepare
from gonio.fit.losses import evaluate_many
from gonio.fit.programs import model_f

#: The metrics reported by :func:`score` (keys of :data:`gonio.fit.losses.LOSSES`).
SCORES = ("ngan", "low-e2")


def _eval(model: Any, wi: Any, wo: Any) -> Any:
    return model.f(wi, wo)


def model_values(model: Any, data: FitData, chunk: int = 1 << 18) -> np.ndarray:
    """``model.f`` at the data's direction pairs, ``(N, C)`` float64.

    A gonio model (a JAX pytree) is evaluated by one jitted function in chunks of ``chunk``
    pairs, the last one padded to full size, so that every model of the same structure reuses
    one compiled program whatever the data size (evaluating op by op, un-jitted, dispatches
    every operation separately and is slow on a MERL table). Anything else with ``f(wi, wo)``
    is called chunk by chunk as it is.
    """
    fn = model_f if isinstance(model, BRDFModel) else _eval
    out = []
    for s in range(0, data.n, chunk):
        wi, wo = data.wi[s : s + chunk], data.wo[s : s + chunk]
        m = wi.shape[0]
        if fn is not _eval and m < chunk:
            up = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (chunk - m, 3))
            wi, wo = np.concatenate([wi, up]), np.concatenate([wo, up])
        f = np.asarray(fn(model, wi, wo), dtype=np.float64)
        f = f[:m] if f.ndim and f.shape[0] == wi.shape[0] else f
        out.append(np.broadcast_to(f, (m, data.channels)))
    return np.concatenate(out)


def score(model: Any, data: Any, theta_max_deg: float = DEFAULT_THETA_MAX_DEG) -> dict[str, float]:
    """``{"ngan": ..., "low-e2": ...}`` of ``model`` (anything with ``f(wi, wo)``) on ``data``
    (a table, samples, FitData or a path)."""
    fd = data if isinstance(data, FitData) else prepare(data, theta_max_deg)
    f = model_values(model, fd)
    if not np.all(np.isfinite(f)):
        raise FitError("the model is not finite on the data")
    return evaluate_many(SCORES, f, fd)


def load_scored_model(spec: str, material: str | None) -> tuple[str, BRDFModel]:
    """``(label, model)`` for a model file named on the command line.

    ``FIT.json`` (a gonio fit result), a published fit file ``FILE.fit`` (the fit of
    ``material``: the data's name) or ``FILE.fit::MATERIAL``. The label of a published fit is
    ``published PRESET`` for Ngan's three preset families, else ``published FILE-STEM``.
    """
    from gonio.brdf import ngan, published
    from gonio.io.fit_result import load_model

    path, _, mat = spec.partition("::")
    if path.endswith(".json"):
        return Path(path).stem, load_model(path)
    if not path.endswith(".fit"):
        raise FitError(f"{spec}: expected a fit result (.json) or a published fit file (.fit)")
    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise FormatError(f"{path}: cannot read ({exc.strerror})") from None
    fits = ngan.parse_ngan_fits(text)
    mat = mat or material or ""
    if mat not in fits:
        raise FitError(f"{path}: no published fit for material {mat!r} ({len(fits)} materials)")
    fit = fits[mat]
    model = published.to_model(fit)
    preset = ngan.FAMILY_PRESETS.get(fit.model)
    return f"published {preset or Path(path).stem}", model


def appearance_reference(path: str | Path) -> tuple[Any, str | None]:
    """``(reference, None)``: the measurement's sphere images (:class:`gonio.appearance.
    Reference` at the default resolution and samples), or ``(None, why)`` where the file cannot
    be rendered (e.g. a spectral measurement: the score compares 1- or 3-channel images)."""
    from gonio import appearance, io

    try:
        return appearance.Reference.of(io.load(path)), None
    except GonioError as exc:
        return None, str(exc)


def appearance_score(reference: Any, model: Any) -> dict[str, float]:
    """The appearance score of ``model`` against ``reference`` (:func:`gonio.appearance.score`
    keys)."""
    from gonio import appearance

    return appearance.score(reference, model)


def score_results(path: str | Path, results: list[Any]) -> str | None:
    """Set the appearance score (``.appearance``) of every whole-colour result of ``results``
    (per-channel fits have none: the score compares whole-colour images) against the sphere
    images of the measurement at ``path``; returns why it was skipped, or None."""
    ref, why = appearance_reference(path)
    if ref is None:
        return why
    for r in results:
        if r.channel is None:
            r.appearance = appearance_score(ref, r.model)
    return None
