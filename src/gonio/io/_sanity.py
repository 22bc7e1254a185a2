"""Checks every reader applies to the numbers it loads (and writers to what they write): values
that cannot be right are errors.

A loaded table must not lie: a BRDF is finite, non-negative (where the format stores f_r or
f_r cos, as every format gonio reads except RGL does) and below :data:`gonio._bounded.MAX_BRDF`.
"Non-negative" allows what measurement and colour conversion produce: values down to
:data:`NEGATIVE_TOLERANCE` times the table's largest magnitude (dark-frame noise; a spectrum
converted to sRGB outside the gamut has slightly negative components); anything lower cannot be
noise and is refused;
a table has at least one valid cell; directions are unit vectors in the upper hemisphere; a grid
axis stays inside the domain of its angle. Each failure is a one-line :class:`FormatError`
naming the file and the field.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from gonio._bounded import MAX_BRDF, MAX_CHANNELS
from gonio.io._common import PathLike, fail

#: Largest ``hi`` of each half/diff axis, radians (phi_d may span [0, 2 pi) when anisotropic).
AXIS_DOMAIN = {
    "theta_h": math.pi / 2,
    "theta_d": math.pi / 2,
    "phi_h": 2 * math.pi,
    "phi_d": 2 * math.pi,
}
_ANGLE_TOL = 1e-6
#: Lowest value accepted as "non-negative", as a fraction of the largest |value| (see above).
NEGATIVE_TOLERANCE = 0.01
#: Largest deviation of a direction's norm from 1, and lowest z of an upper-hemisphere direction.
UNIT_TOL = 1e-3
HORIZON_TOL = 1e-6


def check_brdf_values(
    path: PathLike, what: str, values: Any, valid: Any = None, non_negative: bool = True
) -> None:
    """Refuse NaN/Inf, |v| > MAX_BRDF and (optionally) negative values at valid entries.

    With ``non_negative``, a value below ``-NEGATIVE_TOLERANCE * max|v|`` is an error.

    ``valid`` is a boolean mask over the leading axes of ``values`` (None: all valid); a mask
    with no True entry is itself an error (a table with no valid cell).
    """
    v = np.asarray(values)
    if valid is not None:
        valid = np.asarray(valid, dtype=bool)
        if not np.any(valid):
            raise fail(path, f"{what}: no valid cell")
        valid = valid.reshape(valid.shape + (1,) * (v.ndim - valid.ndim))
        v = v[np.broadcast_to(valid, v.shape)]
    elif v.size == 0:
        raise fail(path, f"{what}: no values")
    bad = ~np.isfinite(v)
    if np.any(bad):
        raise fail(path, f"{what}: {int(np.count_nonzero(bad))} NaN/Inf value(s) at valid cells")
    top = float(np.max(np.abs(v)))
    if top > MAX_BRDF:
        raise fail(path, f"{what}: value {top:.3g} is beyond any reflectance ({MAX_BRDF:g} 1/sr)")
    if non_negative:
        low = float(np.min(v))
        if low < -NEGATIVE_TOLERANCE * top:
            n = int(np.count_nonzero(v < -NEGATIVE_TOLERANCE * top))
            raise fail(path, f"{what}: {n} negative value(s) (lowest {low:.3g}) at valid cells")


def check_axis_range(path: PathLike, name: str, lo: float, hi: float) -> None:
    """A grid axis must be a known half/diff angle with ``[lo, hi]`` inside its domain."""
    top = AXIS_DOMAIN.get(name)
    if top is None:
        raise fail(path, f"unknown axis {name!r} (expected one of {', '.join(AXIS_DOMAIN)})")
    if not (-_ANGLE_TOL <= lo < hi <= top + _ANGLE_TOL):
        raise fail(path, f"axis {name!r}: range [{lo:.6g}, {hi:.6g}] rad outside [0, {top:.6g}]")


def check_directions(path: PathLike, what: str, d: Any) -> None:
    """``(N, 3)`` finite unit vectors with z >= 0 (the upper hemisphere of the local frame)."""
    d = np.asarray(d, dtype=np.float64)
    if d.ndim != 2 or d.shape[1] != 3:
        raise fail(path, f"{what} has shape {d.shape}, expected (N, 3)")
    if not np.all(np.isfinite(d)):
        raise fail(path, f"{what}: NaN/Inf directions")
    norm = np.linalg.norm(d, axis=1)
    if d.size and np.max(np.abs(norm - 1)) > UNIT_TOL:
        raise fail(path, f"{what}: not unit vectors (a norm is {float(np.max(norm)):.4g})")
    if d.size and np.min(d[:, 2]) < -HORIZON_TOL:
        n = int(np.count_nonzero(d[:, 2] < -HORIZON_TOL))
        raise fail(path, f"{what}: {n} direction(s) below the horizon")


def check_table_arrays(path: PathLike, arrays: dict, extrapolated: bool = False) -> None:
    """The checks of a native table's stored numbers, the same when it is read and before it is
    written (:mod:`gonio.io.native`: the writer never writes what the reader refuses).

    ``arrays``: ``values`` as stored (float32, lossy codes decoded) and, where present (absent
    or None otherwise), ``mask`` (gridded), ``sigma``, ``wi``, ``wo``, ``weights``. A BRDF in
    1/sr (and its standard deviation) is finite, not clearly negative and below ``MAX_BRDF``
    at valid cells (every cell when ``extrapolated``: a filled table's extrapolation is data
    too); directions are unit vectors above the horizon; weights are finite and >= 0.
    FormatError naming ``path``.
    """
    arrays = {k: v for k, v in arrays.items() if v is not None}
    values = arrays["values"]
    if "mask" in arrays:
        valid = np.broadcast_to(np.asarray(arrays["mask"], bool)[..., None], values.shape)
        if extrapolated:
            check_brdf_values(path, "/values", values)
    else:
        valid = np.ones(values.shape, dtype=bool)
    for name in ("values", "sigma"):
        if name in arrays:
            check_brdf_values(path, f"/{name}", arrays[name], valid[..., 0])
    for name in ("wi", "wo"):
        if name in arrays:
            check_directions(path, f"/{name}", arrays[name])
    if "weights" in arrays:
        w = arrays["weights"]
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise fail(path, "/weights: NaN/Inf or negative weights")


def check_channel_count(path: PathLike, n: int, what: str = "channels") -> None:
    """At most :data:`gonio._bounded.MAX_CHANNELS` channels (wavelengths) in one table, checked
    on the declared count before anything is allocated (and by writers before writing)."""
    if n > MAX_CHANNELS:
        raise fail(path, f"{n} {what}, more than the {MAX_CHANNELS} a table may hold")
