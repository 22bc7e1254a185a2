"""The opt-in lossy value encoding of native ``*.brdf.h5`` files: log-quantized values stored as
zigzag-coded differences along one grid axis, with a guaranteed relative error bound
(encoding ``"log-quantized-delta"``, see ``data-schema/FORMAT.md``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gonio.errors import ParameterError

#: In lossy mode, values below ``LOSSY_FLOOR_RATIO * max`` are stored as 0.
LOSSY_FLOOR_RATIO = 1e-7


@dataclass(frozen=True)
class LossyEncoding:
    """Parameters of the log-quantized delta encoding (all stored as ``/values`` attributes).

    A value ``v >= floor`` gets code ``q = round((ln v - log_offset) / log_step) + 1``; values
    below ``floor`` (and invalid cells) get ``q = 0``. Codes are stored as differences along grid
    axis ``delta_axis`` (``d[..., 0] = q[..., 0]``, ``d[..., k] = q[..., k] - q[..., k-1]``),
    zigzag-mapped to unsigned integers (``z = 2 d`` for ``d >= 0``, ``z = -2 d - 1`` for ``d < 0``)
    so that small differences of either sign have small codes (this compresses far better).
    Decoding: ``d = (z >> 1) XOR -(z AND 1)``; ``q = cumsum(d, delta_axis)``;
    ``v = exp(log_offset + (q - 1) * log_step)`` where ``q > 0``, else 0.
    The relative error of a decoded value ``>= floor`` is at most
    ``bound_relative = exp(log_step / 2) - 1``.
    """

    log_offset: float
    log_step: float
    floor: float
    delta_axis: int
    bound_relative: float


def lossy_step(precision: float) -> float:
    """Log-domain step whose rounding error is at most ``precision`` (relative)."""
    return 2.0 * math.log1p(precision)


def encode_lossy(
    values: np.ndarray, valid: np.ndarray, precision: float
) -> tuple[np.ndarray, LossyEncoding]:
    """Quantize ``values`` (n1..nk, C) to delta-coded integer codes, relative bound ``precision``.

    Returns the code array (uint16 when the zigzag codes fit, else uint32) and the parameters.
    """
    if not (0.0 < precision < 0.5):
        raise ParameterError(f"lossy precision must be in (0, 0.5), got {precision}")
    v = np.asarray(values, dtype=np.float64)
    ok = np.broadcast_to(valid[..., None], v.shape) & (v > 0)
    vmax = float(v[ok].max()) if np.any(ok) else 1.0
    floor = vmax * LOSSY_FLOOR_RATIO
    ok &= v >= floor
    step = lossy_step(precision)
    offset = math.log(floor)
    q = np.zeros(v.shape, dtype=np.int64)
    q[ok] = np.rint((np.log(v[ok]) - offset) / step).astype(np.int64) + 1
    delta_axis = v.ndim - 2  # last grid axis: smooth direction (phi_d), rows stay independent
    d = np.diff(q, axis=delta_axis, prepend=0)
    z = np.where(d >= 0, 2 * d, -2 * d - 1)
    dtype = np.uint16 if z.max(initial=0) <= np.iinfo(np.uint16).max else np.uint32
    enc = LossyEncoding(offset, step, floor, delta_axis, math.expm1(step / 2))
    return z.astype(dtype), enc


def decode_lossy(
    codes: np.ndarray, enc: LossyEncoding, delta_axis: int | None = None
) -> np.ndarray:
    """Inverse of :func:`encode_lossy` (float32 result). ``codes`` may be a partial read as long
    as it holds whole rows along ``delta_axis`` (pass the axis index within ``codes``)."""
    axis = enc.delta_axis if delta_axis is None else delta_axis
    z = np.asarray(codes, dtype=np.int64)
    q = np.cumsum((z >> 1) ^ -(z & 1), axis=axis)
    out = np.exp(enc.log_offset + (q - 1) * enc.log_step)
    return np.where(q > 0, out, 0.0).astype(np.float32)


def lossy_stats(values: np.ndarray, decoded: np.ndarray, valid: np.ndarray, floor: float) -> dict:
    """Relative errors (median, 99th percentile, maximum) of ``decoded`` against ``values`` at
    valid cells whose value is at least ``floor``."""
    v = np.asarray(values, dtype=np.float64)
    sel = np.broadcast_to(valid[..., None], v.shape) & (v >= floor)
    if not np.any(sel):
        return {"median_relative": 0.0, "p99_relative": 0.0, "max_relative": 0.0}
    rel = np.abs(decoded[sel].astype(np.float64) - v[sel]) / v[sel]
    return {
        "median_relative": float(np.median(rel)),
        "p99_relative": float(np.percentile(rel, 99)),
        "max_relative": float(rel.max()),
    }


__all__ = [
    "LOSSY_FLOOR_RATIO",
    "LossyEncoding",
    "decode_lossy",
    "encode_lossy",
    "lossy_stats",
    "lossy_step",
]
