"""ALTA text data files (``#DIM``, ``#PARAM_IN``, ``#PARAM_OUT``, optional ``#VS``).

Header lines start with ``#``; the data rows hold ``n_in`` inputs, then ``n_out`` outputs, then
(with ``#VS k``) ``k`` extra numbers per output: ``k = 1`` a symmetric half-width, ``k = 2`` a
lower and an upper bound (kept as ``sigma`` = half the interval). Inputs are converted to
directions the way ALTA's ``params::to_cartesian`` does, with ALTA's light vector ``L`` as gonio's
``wi`` and view vector ``V`` as ``wo``:

* ``COS_TH``: cos(theta_h) with theta_d = 0 (so ``wi = wo`` = the half vector);
* ``RUSIN_TH_TD``, ``RUSIN_TH_TD_PD``, ``RUSIN_TH_PH_TD_PD``: Rusinkiewicz angles (radians);
* ``ISOTROPIC_TL_TV_PROJ_DPHI``: ``[theta_l, theta_v cos(dphi), theta_v sin(dphi)]``;
* ``ISOTROPIC_TV_TL_DPHI``: ``[theta_v, theta_l, dphi]``;
* ``SPHERICAL_TL_PL_TV_PV``: four spherical angles; ``CARTESIAN``: ``[V, L]`` unit vectors.

Outputs: ``INV_STERADIAN`` (f_r, 1/sr), ``INV_STERADIAN_COSINE_FACTOR`` (f_r * cos(theta_v),
divided out here; samples with cos(theta_v) <= 1e-6 are dropped), ``RGB_COLOR`` (f_r per RGB
channel), ``XYZ_COLOR`` (converted to linear sRGB). A file without ``#PARAM_OUT`` is read as
``INV_STERADIAN_COSINE_FACTOR`` — the convention of ALTA's measured gonioreflectometer data — unless
``param_out`` says otherwise; the assumption is recorded in the metadata.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from gonio.io._common import PathLike, fail, read_text
from gonio.io._geometry import half_diff_to_directions, spherical
from gonio.io._sanity import check_brdf_values, check_channel_count
from gonio.io._text import NumberBlocks, check_line_count, numbered_lines, rows_to_array

PARAM_IN_DIMS = {
    "COS_TH": 1,
    "RUSIN_TH_TD": 2,
    "RUSIN_TH_TD_PD": 3,
    "ISOTROPIC_TL_TV_PROJ_DPHI": 3,
    "ISOTROPIC_TV_TL_DPHI": 3,
    "RUSIN_TH_PH_TD_PD": 4,
    "SPHERICAL_TL_PL_TV_PV": 4,
    "CARTESIAN": 6,
}
PARAM_OUTS = ("INV_STERADIAN", "INV_STERADIAN_COSINE_FACTOR", "RGB_COLOR", "XYZ_COLOR")
DEFAULT_MISSING_PARAM_OUT = "INV_STERADIAN_COSINE_FACTOR"
_MIN_COS = 1e-6


def parse_alta_text(text: str, path: PathLike = "<text>") -> dict[str, Any]:
    """Parse ALTA data text: header dict and the data as ``(N, columns)`` float64."""
    header: dict[str, Any] = {"comments": []}
    check_line_count(path, text)
    rows = NumberBlocks(path, "data row")
    for lineno, line in numbered_lines(text):
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            key, _, rest = s[1:].partition(" ")
            key, rest = key.strip().upper(), rest.strip()
            if key == "DIM":
                parts = rest.split()
                try:
                    dims = [int(p) for p in parts]
                except ValueError:
                    raise fail(path, f"line {lineno}: bad #DIM {rest!r}") from None
                if len(dims) != 2 or not (1 <= dims[0] <= 6 and 1 <= dims[1]):
                    raise fail(path, f"line {lineno}: impossible #DIM {rest!r}")
                check_channel_count(path, dims[1], f"outputs (channels) on #DIM (line {lineno})")
                header["dim"] = dims
            elif key == "PARAM_IN":
                header["param_in"] = rest.split()[0].upper() if rest else ""
            elif key == "PARAM_OUT":
                header["param_out"] = rest.split()[0].upper() if rest else ""
            elif key == "VS":
                try:
                    header["vs"] = int(rest.split()[0])
                except (ValueError, IndexError):
                    raise fail(path, f"line {lineno}: bad #VS {rest!r}") from None
                if header["vs"] not in (0, 1, 2):
                    raise fail(path, f"line {lineno}: unsupported #VS {header['vs']}")
            elif key in ("FUNC", "NB_FUNC", "ALTA"):
                raise fail(path, "ALTA function/fit file, not a data file")
            else:
                header["comments"].append(s[1:].strip())
            continue
        if "dim" not in header:
            raise fail(path, f"line {lineno}: data before the #DIM header (not an ALTA file?)")
        rows.add(lineno, s)
    if "dim" not in header:
        raise fail(path, "no #DIM header (not an ALTA data file)")
    n_in, n_out = header["dim"]
    width = n_in + n_out * (1 + header.get("vs", 0))
    header["data"] = rows_to_array(path, rows, width, "data")
    return header


def _directions(param_in: str, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(wi, wo)`` = (ALTA light L, ALTA view V) for inputs ``x`` (N, n_in)."""

    def half(th, ph, td, pd):
        return half_diff_to_directions(th, ph, td, pd)

    z = np.zeros(len(x))
    if param_in == "COS_TH":
        th = np.arccos(np.clip(x[:, 0], -1.0, 1.0))
        return half(th, z, z, z)
    if param_in == "RUSIN_TH_TD":
        return half(x[:, 0], z, x[:, 1], z + 0.5 * math.pi)
    if param_in == "RUSIN_TH_TD_PD":
        return half(x[:, 0], z, x[:, 1], x[:, 2])
    if param_in == "RUSIN_TH_PH_TD_PD":
        return half(x[:, 0], x[:, 1], x[:, 2], x[:, 3])
    if param_in == "ISOTROPIC_TL_TV_PROJ_DPHI":
        theta_v = np.hypot(x[:, 1], x[:, 2])
        phi_v = np.arctan2(x[:, 2], x[:, 1])
        return spherical(x[:, 0], z), spherical(theta_v, phi_v)
    if param_in == "ISOTROPIC_TV_TL_DPHI":
        return spherical(x[:, 1], x[:, 2]), spherical(x[:, 0], z)
    if param_in == "SPHERICAL_TL_PL_TV_PV":
        return spherical(x[:, 0], x[:, 1]), spherical(x[:, 2], x[:, 3])
    if param_in == "CARTESIAN":
        v, l_ = x[:, 0:3], x[:, 3:6]
        norm = np.linalg.norm
        return l_ / norm(l_, axis=1, keepdims=True), v / norm(v, axis=1, keepdims=True)
    raise AssertionError(param_in)


_ELEVATION = (0.0, math.pi / 2, "a Rusinkiewicz elevation in radians, [0, pi/2]")
_POLAR = (0.0, math.pi, "a polar angle in radians, [0, pi]")
_AZIMUTH = (-2 * math.pi, 2 * math.pi, "an azimuth in radians, [-2 pi, 2 pi]")
_UNIT = (0.99, 1.01, "a unit vector (length 1 within 1 %)")
#: Input columns with a bounded domain: (first column, last column + 1, (low, high, what)),
#: the column's value or, with ``norm``, the length of the columns as a vector. Polar angles
#: beyond pi/2 are directions below the horizon (dropped and counted, as ALTA's files have
#: them); any angle beyond its domain is refused, which the direction formulas would
#: otherwise wrap or clamp silently.
_BOUNDED_INPUTS: dict[str, list[tuple[int, int, tuple[float, float, str], bool]]] = {
    "COS_TH": [(0, 1, (-1.0, 1.0, "a cosine, in [-1, 1]"), False)],
    "RUSIN_TH_TD": [(0, 2, _ELEVATION, False)],
    "RUSIN_TH_TD_PD": [(0, 2, _ELEVATION, False), (2, 3, _AZIMUTH, False)],
    "RUSIN_TH_PH_TD_PD": [
        (0, 1, _ELEVATION, False),
        (2, 3, _ELEVATION, False),
        (1, 2, _AZIMUTH, False),
        (3, 4, _AZIMUTH, False),
    ],
    "ISOTROPIC_TL_TV_PROJ_DPHI": [
        (0, 1, _POLAR, False),
        (1, 3, (0.0, math.pi, "a projected polar angle in radians, length in [0, pi]"), True),
    ],
    "ISOTROPIC_TV_TL_DPHI": [(0, 2, _POLAR, False), (2, 3, _AZIMUTH, False)],
    "SPHERICAL_TL_PL_TV_PV": [
        (0, 1, _POLAR, False),
        (2, 3, _POLAR, False),
        (1, 2, _AZIMUTH, False),
        (3, 4, _AZIMUTH, False),
    ],
    "CARTESIAN": [(0, 3, _UNIT, True), (3, 6, _UNIT, True)],
}


def _check_inputs(path: PathLike, param_in: str, x: np.ndarray) -> None:
    """Refuse input coordinates outside their domain (beyond 1e-6 of rounding), which the
    direction formulas would otherwise clamp or wrap silently; names the first bad row."""
    for a, b, (lo, hi, what), norm in _BOUNDED_INPUTS.get(param_in, ()):
        cols = x[:, a:b]
        v = np.linalg.norm(cols, axis=1, keepdims=True) if norm else cols
        bad = np.flatnonzero(np.any((v < lo - 1e-6) | (v > hi + 1e-6), axis=1))
        if bad.size:
            row = int(bad[0])
            raise fail(
                path,
                f"data row {row + 1}: {param_in} input {cols[row].tolist()} is not {what} "
                f"({bad.size} row(s) out of range)",
            )


def read_alta(
    path: PathLike,
    param_out: str | None = None,
    color: str = "keep",
) -> Any:
    """Read an ALTA data file as :class:`MeasuredSamples` (f_r in 1/sr, cosine divided out).

    Parameters
    ----------
    param_out : str, optional
        Output parametrization to assume when the file has no ``#PARAM_OUT`` line
        (default :data:`DEFAULT_MISSING_PARAM_OUT`); a file's own header always wins.
    color : {"keep", "rgb"}
        ``"rgb"`` replicates a single output into three equal RGB channels.
    """
    from gonio.brdf.measured import MeasuredSamples
    from gonio.brdf.tabulated import Channels
    from gonio.errors import ParameterError
    from gonio.io import spectral

    h = parse_alta_text(read_text(path), path)
    n_in, n_out = h["dim"]
    pin = h.get("param_in")
    if pin is None:
        raise fail(path, "no #PARAM_IN header")
    if pin not in PARAM_IN_DIMS:
        raise fail(path, f"unsupported #PARAM_IN {pin} (known: {', '.join(PARAM_IN_DIMS)})")
    if PARAM_IN_DIMS[pin] != n_in:
        raise fail(path, f"#PARAM_IN {pin} has {PARAM_IN_DIMS[pin]} inputs but #DIM says {n_in}")
    assumed = "param_out" not in h
    pout = h.get("param_out") or (param_out or DEFAULT_MISSING_PARAM_OUT)
    if pout not in PARAM_OUTS:
        raise fail(path, f"unsupported #PARAM_OUT {pout} (known: {', '.join(PARAM_OUTS)})")
    if pout in ("RGB_COLOR", "XYZ_COLOR") and n_out != 3:
        raise fail(path, f"#PARAM_OUT {pout} needs 3 outputs, #DIM says {n_out}")
    data = h["data"]
    x = data[:, :n_in]
    values = data[:, n_in : n_in + n_out].copy()
    vs = h.get("vs", 0)
    sigma = None
    if vs == 1:
        sigma = np.abs(data[:, n_in + n_out : n_in + 2 * n_out])
    elif vs == 2:
        lo_hi = data[:, n_in + n_out :].reshape(-1, n_out, 2)
        sigma = 0.5 * np.abs(lo_hi[..., 1] - lo_hi[..., 0])
    _check_inputs(path, pin, x)
    wi, wo = _directions(pin, x)
    keep = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    if pout == "INV_STERADIAN_COSINE_FACTOR":
        keep &= wo[:, 2] > _MIN_COS
        cos_v = np.where(keep, wo[:, 2], 1.0)[:, None]
        values = values / cos_v
        if sigma is not None:
            sigma = sigma / cos_v
    if pout == "XYZ_COLOR":
        values = spectral.xyz_to_linear_srgb(values)
        sigma = None  # per-channel intervals do not map through the colour matrix
    if not np.any(keep):
        raise fail(path, "no sample lies above the horizon")
    # every output parametrization is f_r (times a cosine): finite, >= 0, not absurd
    check_brdf_values(path, "sample values", values[keep])
    if sigma is not None:
        check_brdf_values(path, "#VS uncertainties", sigma[keep])
    source: dict[str, Any] = {
        "format": "alta",
        "file": str(path),
        "param_in": pin,
        "param_out": pout,
        "dropped_at_or_below_horizon": int(np.count_nonzero(~keep)),
        "description": " ".join(h["comments"]),
    }
    if assumed:
        source["param_out_assumed"] = True
    if color not in ("keep", "rgb"):
        raise ParameterError(f"color must be 'keep' or 'rgb', got {color!r}")
    if n_out == 3:
        channels = Channels.rgb()
    elif n_out == 1 and color == "rgb":
        values = np.repeat(values, 3, axis=1)
        sigma = None if sigma is None else np.repeat(sigma, 3, axis=1)
        channels = Channels.rgb()
    elif n_out == 1:
        channels = Channels.mono()
    else:
        raise fail(path, f"{n_out} outputs: only 1 (mono) or 3 (RGB) are supported")
    return MeasuredSamples(
        wi=wi[keep],
        wo=wo[keep],
        values=values[keep],
        sigma=None if sigma is None else sigma[keep],
        channels=channels,
        weights=None,
        meta={"source": source},
    )
