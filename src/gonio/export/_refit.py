"""Refitting a target renderer's family to the fit's own data with :func:`gonio.fit.fit`.

When a target cannot express the fitted model exactly, the exporter fits the target's family
(a gonio model the target can express exactly, e.g. Lambert + GGX/Smith/Schlick for Blender) to
the data of the original fit, under the original fit's metric and polar-angle cutoff:

* the measurement file recorded in the fit JSON (``data.path``), when it is still readable;
* otherwise the fitted model itself, evaluated without noise on a dense, deterministic
  half/difference-angle grid (:func:`model_samples`), so the refit approximates the model.

The result reports both losses: the original fit's loss as recorded in its JSON, the original
model's loss on the refit data (equal to the recorded one when the measurement is used; 0 for a
sampled model, whose data it is), and the refit's loss on the same data under the same metric.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from gonio.brdf.models import BRDFModel
from gonio.export._source import FitSource, rgb_matrix
from gonio.fit.data import FitData, from_arrays, prepare

#: Grid of :func:`model_samples`: theta_h, phi_h, theta_d, phi_d node counts.
GRID = (24, 3, 16, 12)
#: A refit uses at most this many measured cells, one per stratum along theta_h
#: (:meth:`~gonio.fit.data.FitData.stratified_subset`, as the default fit's training cells): the
#: target families have at most 8 parameters, and a MERL table's 9e5 cells would cost minutes.
MAX_CELLS = 8192
#: Measured refit data by (path, theta_max_deg), read once per process.
_MEASURED: dict[tuple[str, float], FitData] = {}


@dataclass(frozen=True)
class RefitData:
    """Samples to refit on, and where they came from (``kind``: ``"measurement"`` or
    ``"sampled model"``)."""

    data: FitData
    kind: str
    path: str | None


def model_samples(model: BRDFModel, theta_max_deg: float, grid: tuple[int, ...] = GRID) -> tuple:
    """Noise-free samples of ``model`` on a half/difference grid: ``(wi, wo, f)``.

    ``theta_h`` nodes are spaced quadratically (dense near the specular peak, as MERL's grid),
    ``phi_h`` (anisotropic models), ``theta_d`` and ``phi_d`` uniformly at cell centres; pairs
    with a direction beyond ``theta_max_deg`` or below the horizon are dropped by the fit.
    """
    from gonio.brdf.frames import half_diff_to_directions

    nh, nph, nd, npd = grid
    th = (((np.arange(nh) + 0.5) / nh) ** 2) * (math.pi / 2)
    ph = (np.arange(nph) + 0.5) / nph * math.pi
    td = (np.arange(nd) + 0.5) / nd * (math.pi / 2)
    pd = (np.arange(npd) + 0.5) / npd * math.pi
    mesh = np.meshgrid(th, ph, td, pd, indexing="ij")
    wi, wo = half_diff_to_directions(*(m.reshape(-1) for m in mesh))
    wi, wo = np.asarray(wi, np.float64), np.asarray(wo, np.float64)
    cmax = math.cos(math.radians(theta_max_deg))
    keep = (wi[:, 2] >= cmax) & (wo[:, 2] >= cmax)
    wi, wo = wi[keep], wo[keep]
    return wi, wo, np.asarray(model.f(wi, wo), np.float64)


def to_rgb(fd: FitData, wavelengths_nm: np.ndarray) -> FitData:
    """Spectral samples converted to linear sRGB (values exactly; sigma propagated as
    independent errors: ``sigma_rgb = sqrt(sigma^2 @ T^2)``)."""
    t = rgb_matrix(wavelengths_nm)
    sigma = None if fd.sigma is None else np.sqrt((fd.sigma**2) @ (t**2))
    return FitData(fd.wi, fd.wo, fd.values @ t, sigma, fd.weights, ("R", "G", "B"), dict(fd.source))


def refit_data(src: FitSource, measurement: bool = True) -> RefitData:
    """The data a refit of ``src`` uses (see the module docstring); ``measurement=False``
    skips the recorded file and samples the model."""
    from gonio.errors import GonioError
    from gonio.export._price import measurement_path

    desc = src.record["data"]
    theta = float(desc.get("theta_max_deg") or 80.0)
    path = measurement_path(desc.get("path"), src.path) if measurement else None
    fd = None
    if path:
        try:
            if (path, theta) not in _MEASURED:
                _MEASURED[(path, theta)] = prepare(path, theta).stratified_subset(MAX_CELLS)
            fd = _MEASURED[(path, theta)]
        except GonioError:
            fd = None
        if fd is not None and fd.channels != len(src.channels):
            fd = None
    kind = "measurement"
    if fd is None:
        wi, wo, f = model_samples(src.model, theta)
        fd = from_arrays(wi, wo, f, theta_max_deg=theta, name="sampled model")
        fd = FitData(fd.wi, fd.wo, fd.values, None, fd.weights, tuple(src.channels), fd.source)
        kind, path = "sampled model", None
    if src.spectral:
        fd = to_rgb(fd, src.wavelengths_nm)  # type: ignore[arg-type]
    return RefitData(fd, kind, None if path is None else str(path))


#: Losses a refit is tried under when the refit under the fit's own metric looks worse than the
#: fit (HDR-FLIP against the measurement, :mod:`._price`); the candidate that looks closest to
#: the measurement is exported. The fit's metric can favour a lobe that matches the sampled
#: cells but not the look (a single GGX lobe in place of a chrome's two narrow lobes); the
#: cube-root loss weights the dim tails more.
EXTRA_LOSSES = ("cube-root",)


def refit(
    src: FitSource,
    template: BRDFModel,
    fixed: dict[str, Any],
    family: str,
    data: RefitData | None = None,
    loss: str | None = None,
) -> dict[str, Any]:
    """Fit ``template`` (a gonio model the target expresses exactly) to the fit's data.

    ``loss`` is the loss the refit minimizes (default: the fit's metric). Returns a JSON-ready
    dictionary: ``family``, ``data`` (kind, path, n_samples), ``metric`` (the fit's),
    ``original_loss`` (as recorded), ``original_loss_on_refit_data`` and ``refit_loss`` (the
    fit's and the refit's loss under ``metric`` on the same data), ``refit_metric`` (the loss
    minimized) and ``on_refit_metric`` (``{"fit", "export"}`` under it), ``params`` and
    ``model_spec`` of the refitted model (``"model"`` key: the model itself, not JSON, removed
    before writing).
    """
    from gonio.fit import fit
    from gonio.fit.losses import evaluate
    from gonio.io.fit_result import to_jsonable

    rd = data or refit_data(src)
    metric = str(src.record.get("metric") or "wls")
    minimized = loss or metric
    theta = float(rd.data.source.get("theta_max_deg") or 80.0)
    res = fit(rd.data, model=template, loss=minimized, fixed=fixed, theta_max_deg=theta)
    f0 = np.asarray(src.model.f(rd.data.wi, rd.data.wo), np.float64)
    if src.spectral:  # the data were converted to RGB: so is the model's prediction
        f0 = f0 @ rgb_matrix(src.wavelengths_nm)  # type: ignore[arg-type]
    f1 = np.asarray(res.model.f(rd.data.wi, rd.data.wo), np.float64)
    return {
        "family": family,
        "data": {"kind": rd.kind, "path": rd.path, "n_samples": rd.data.n},
        "metric": metric,
        "original_loss": src.record.get("loss"),
        "original_loss_on_refit_data": evaluate(metric, f0, rd.data),
        "refit_loss": float(res.loss) if minimized == metric else evaluate(metric, f1, rd.data),
        "refit_metric": minimized,
        "on_refit_metric": {
            "fit": evaluate(minimized, f0, rd.data),
            "export": evaluate(minimized, f1, rd.data),
        },
        "params": to_jsonable(res.params),
        "model_spec": res.model.to_dict(),
        "model": res.model,
    }
