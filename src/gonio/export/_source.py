"""The fit being exported: its JSON record (read through :mod:`gonio.io.fit_result`), its model,
and the RGB form of a spectral fit.

Spectral fits (channels named ``"450nm"``, ...) are converted to linear sRGB with gonio's
documented conversion (:mod:`gonio.io.spectral`: CIE 1931 2-degree observer, illuminant D65,
normalized so that a flat spectrum of value c has Y = c, IEC 61966-2-1 matrix). The conversion is
linear, so it is exact for every parameter the BRDF is linear in (albedos, ``rho_d``, a lobe's
constant ``scale``); Schlick's ``f0`` enters affinely (``F = f0 (1 - m) + m``) and converts
exactly up to the RGB of the flat white spectrum, which is reported; indices of refraction enter
non-linearly and are never converted: such a fit is refitted on the RGB-converted data.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gonio.brdf.models import BRDFModel
from gonio.errors import ParameterError
from gonio.io.spectral import spectral_to_rgb_matrix, wavelengths_from_names


@dataclass(frozen=True)
class FitSource:
    """One fit to export.

    Attributes
    ----------
    record : the fit-result JSON (validated by :func:`gonio.io.fit_result.validate`).
    model : the fitted model as stored (channels as fitted).
    path : the JSON file it came from (None for an in-memory result).
    wavelengths_nm : the channels' wavelengths for a spectral fit, else None.
    """

    record: dict[str, Any]
    model: BRDFModel
    path: Path | None = None
    wavelengths_nm: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def name(self) -> str:
        """Material name for the exported files (the data's name, else the model's)."""
        raw = str(self.record.get("data", {}).get("name") or self.record.get("model") or "fit")
        clean = re.sub(r"[^A-Za-z0-9_]+", "_", raw).strip("_") or "fit"
        return clean if not clean[0].isdigit() else f"m_{clean}"

    @property
    def channels(self) -> list[str]:
        return list(self.record["data"]["channels"])

    @property
    def spectral(self) -> bool:
        return self.wavelengths_nm is not None


def rgb_matrix(wavelengths_nm: np.ndarray) -> np.ndarray:
    """``T`` (n, 3): linear sRGB = spectrum @ T under illuminant D65, the exporter's
    (:func:`gonio.io.spectral.spectral_to_rgb_matrix`)."""
    return spectral_to_rgb_matrix(wavelengths_nm, "D65")


def load(fit: Any) -> FitSource:
    """A :class:`FitSource` from a fit-result path, a :class:`~gonio.fit.result.FitResult` or its
    JSON dictionary.

    Raises
    ------
    FormatError
        For a file that is not a fit result, a schema version this gonio does not read, or a
        model description that cannot be rebuilt.
    """
    from gonio.fit.result import FitResult
    from gonio.io import fit_result

    path: Path | None = None
    if isinstance(fit, FitResult):
        record = fit_result.validate(fit.to_json())
    elif isinstance(fit, dict):
        record = fit_result.validate(fit)
    elif isinstance(fit, (str, Path)):
        path = Path(fit)
        record = fit_result.read_result(path)
    else:
        raise ParameterError(f"cannot export a {type(fit).__name__}: give a fit-result file")
    model = fit_result.model_of(record["model_spec"], str(path or "fit result"))
    return FitSource(record, model, path, wavelengths_from_names(record["data"]["channels"]))
