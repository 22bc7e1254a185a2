"""Spectral -> CIE 1931 XYZ -> linear sRGB, under a stated illuminant.

Data
----
``_TABLE`` holds, every 5 nm from 360 to 830 nm, the CIE 1931 2-degree standard observer colour-
matching functions x̄, ȳ, z̄ and the relative spectral power of CIE standard illuminant D65. Both
are public CIE standard data (CIE 15:2004 / ISO 11664-1 for the observer, CIE S 014-2 /
ISO 11664-2 for D65); the numbers were transcribed from the copy distributed with the
colour-science Python package, which reproduces the CIE tables.

Convention
----------
A spectral BRDF ``f(λ)`` (1/sr) is seen under illuminant ``S(λ)`` and converted as a reflectance:
``X = Σ f x̄ S Δλ / Σ ȳ S Δλ`` (likewise Y, Z), so that a spectrally flat BRDF ``f(λ) = c`` gets
``Y = c``. With illuminant D65 (sRGB's white point) a flat spectrum maps to linear sRGB ≈ (c, c, c).
Illuminant "E" (equal energy) is also accepted; its white maps to a slightly pink sRGB, since no
chromatic adaptation is applied. Linear sRGB uses the IEC 61966-2-1 XYZ -> RGB matrix (Rec. 709
primaries, D65 white), no transfer curve.
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np

from gonio.errors import ParameterError

# (wavelength nm, xbar, ybar, zbar, D65 relative power)
_TABLE = np.array(
    [
        (360, 1.299000e-04, 3.917000e-06, 6.061000e-04, 46.6383),
        (365, 2.321000e-04, 6.965000e-06, 1.086000e-03, 49.3637),
        (370, 4.149000e-04, 1.239000e-05, 1.946000e-03, 52.0891),
        (375, 7.416000e-04, 2.202000e-05, 3.486000e-03, 51.0323),
        (380, 1.368000e-03, 3.900000e-05, 6.450001e-03, 49.9755),
        (385, 2.236000e-03, 6.400000e-05, 1.054999e-02, 52.3118),
        (390, 4.243000e-03, 1.200000e-04, 2.005001e-02, 54.6482),
        (395, 7.650000e-03, 2.170000e-04, 3.621000e-02, 68.7015),
        (400, 1.431000e-02, 3.960000e-04, 6.785001e-02, 82.7549),
        (405, 2.319000e-02, 6.400000e-04, 1.102000e-01, 87.1204),
        (410, 4.351000e-02, 1.210000e-03, 2.074000e-01, 91.4860),
        (415, 7.763000e-02, 2.180000e-03, 3.713000e-01, 92.4589),
        (420, 1.343800e-01, 4.000000e-03, 6.456000e-01, 93.4318),
        (425, 2.147700e-01, 7.300000e-03, 1.039050e00, 90.0570),
        (430, 2.839000e-01, 1.160000e-02, 1.385600e00, 86.6823),
        (435, 3.285000e-01, 1.684000e-02, 1.622960e00, 95.7736),
        (440, 3.482800e-01, 2.300000e-02, 1.747060e00, 104.8650),
        (445, 3.480600e-01, 2.980000e-02, 1.782600e00, 110.9360),
        (450, 3.362000e-01, 3.800000e-02, 1.772110e00, 117.0080),
        (455, 3.187000e-01, 4.800000e-02, 1.744100e00, 117.4100),
        (460, 2.908000e-01, 6.000000e-02, 1.669200e00, 117.8120),
        (465, 2.511000e-01, 7.390000e-02, 1.528100e00, 116.3360),
        (470, 1.953600e-01, 9.098000e-02, 1.287640e00, 114.8610),
        (475, 1.421000e-01, 1.126000e-01, 1.041900e00, 115.3920),
        (480, 9.564000e-02, 1.390200e-01, 8.129501e-01, 115.9230),
        (485, 5.795001e-02, 1.693000e-01, 6.162000e-01, 112.3670),
        (490, 3.201000e-02, 2.080200e-01, 4.651800e-01, 108.8110),
        (495, 1.470000e-02, 2.586000e-01, 3.533000e-01, 109.0820),
        (500, 4.900000e-03, 3.230000e-01, 2.720000e-01, 109.3540),
        (505, 2.400000e-03, 4.073000e-01, 2.123000e-01, 108.5780),
        (510, 9.300000e-03, 5.030000e-01, 1.582000e-01, 107.8020),
        (515, 2.910000e-02, 6.082000e-01, 1.117000e-01, 106.2960),
        (520, 6.327000e-02, 7.100000e-01, 7.824999e-02, 104.7900),
        (525, 1.096000e-01, 7.932000e-01, 5.725001e-02, 106.2390),
        (530, 1.655000e-01, 8.620000e-01, 4.216000e-02, 107.6890),
        (535, 2.257499e-01, 9.148501e-01, 2.984000e-02, 106.0470),
        (540, 2.904000e-01, 9.540000e-01, 2.030000e-02, 104.4050),
        (545, 3.597000e-01, 9.803000e-01, 1.340000e-02, 104.2250),
        (550, 4.334499e-01, 9.949501e-01, 8.749999e-03, 104.0460),
        (555, 5.120501e-01, 1.000000e00, 5.749999e-03, 102.0230),
        (560, 5.945000e-01, 9.950000e-01, 3.900000e-03, 100.0000),
        (565, 6.784000e-01, 9.786000e-01, 2.749999e-03, 98.1671),
        (570, 7.621000e-01, 9.520000e-01, 2.100000e-03, 96.3342),
        (575, 8.425000e-01, 9.154000e-01, 1.800000e-03, 96.0611),
        (580, 9.163000e-01, 8.700000e-01, 1.650001e-03, 95.7880),
        (585, 9.786000e-01, 8.163000e-01, 1.400000e-03, 92.2368),
        (590, 1.026300e00, 7.570000e-01, 1.100000e-03, 88.6856),
        (595, 1.056700e00, 6.949000e-01, 1.000000e-03, 89.3459),
        (600, 1.062200e00, 6.310000e-01, 8.000000e-04, 90.0062),
        (605, 1.045600e00, 5.668000e-01, 6.000000e-04, 89.8026),
        (610, 1.002600e00, 5.030000e-01, 3.400000e-04, 89.5991),
        (615, 9.384000e-01, 4.412000e-01, 2.400000e-04, 88.6489),
        (620, 8.544499e-01, 3.810000e-01, 1.900000e-04, 87.6987),
        (625, 7.514000e-01, 3.210000e-01, 1.000000e-04, 85.4936),
        (630, 6.424000e-01, 2.650000e-01, 4.999999e-05, 83.2886),
        (635, 5.419000e-01, 2.170000e-01, 3.000000e-05, 83.4939),
        (640, 4.479000e-01, 1.750000e-01, 2.000000e-05, 83.6992),
        (645, 3.608000e-01, 1.382000e-01, 1.000000e-05, 81.8630),
        (650, 2.835000e-01, 1.070000e-01, -1.905824e-21, 80.0268),
        (655, 2.187000e-01, 8.160000e-02, 0.000000e00, 80.1207),
        (660, 1.649000e-01, 6.100000e-02, 0.000000e00, 80.2146),
        (665, 1.212000e-01, 4.458000e-02, 0.000000e00, 81.2462),
        (670, 8.740000e-02, 3.200000e-02, 0.000000e00, 82.2778),
        (675, 6.360000e-02, 2.320000e-02, 0.000000e00, 80.2810),
        (680, 4.677000e-02, 1.700000e-02, 0.000000e00, 78.2842),
        (685, 3.290000e-02, 1.192000e-02, 0.000000e00, 74.0027),
        (690, 2.270000e-02, 8.210000e-03, 0.000000e00, 69.7213),
        (695, 1.584000e-02, 5.723000e-03, 0.000000e00, 70.6652),
        (700, 1.135916e-02, 4.102000e-03, 0.000000e00, 71.6091),
        (705, 8.110916e-03, 2.929000e-03, 0.000000e00, 72.9790),
        (710, 5.790346e-03, 2.091000e-03, 0.000000e00, 74.3490),
        (715, 4.109457e-03, 1.484000e-03, 0.000000e00, 67.9765),
        (720, 2.899327e-03, 1.047000e-03, 0.000000e00, 61.6040),
        (725, 2.049190e-03, 7.400000e-04, 0.000000e00, 65.7448),
        (730, 1.439971e-03, 5.200000e-04, 0.000000e00, 69.8856),
        (735, 9.999493e-04, 3.611000e-04, 0.000000e00, 72.4863),
        (740, 6.900786e-04, 2.492000e-04, 0.000000e00, 75.0870),
        (745, 4.760213e-04, 1.719000e-04, 0.000000e00, 69.3398),
        (750, 3.323011e-04, 1.200000e-04, 0.000000e00, 63.5927),
        (755, 2.348261e-04, 8.480000e-05, 0.000000e00, 55.0054),
        (760, 1.661505e-04, 6.000000e-05, 0.000000e00, 46.4182),
        (765, 1.174130e-04, 4.240000e-05, 0.000000e00, 56.6118),
        (770, 8.307527e-05, 3.000000e-05, 0.000000e00, 66.8054),
        (775, 5.870652e-05, 2.120000e-05, 0.000000e00, 65.0941),
        (780, 4.150994e-05, 1.499000e-05, 0.000000e00, 63.3828),
        (785, 2.935326e-05, 1.060000e-05, 0.000000e00, 63.3828),
        (790, 2.067383e-05, 7.465700e-06, 0.000000e00, 63.3828),
        (795, 1.455977e-05, 5.257800e-06, 0.000000e00, 63.3828),
        (800, 1.025398e-05, 3.702900e-06, 0.000000e00, 63.3828),
        (805, 7.221456e-06, 2.607800e-06, 0.000000e00, 63.3828),
        (810, 5.085868e-06, 1.836600e-06, 0.000000e00, 63.3828),
        (815, 3.581652e-06, 1.293400e-06, 0.000000e00, 63.3828),
        (820, 2.522525e-06, 9.109300e-07, 0.000000e00, 63.3828),
        (825, 1.776509e-06, 6.415300e-07, 0.000000e00, 63.3828),
        (830, 1.251141e-06, 4.518100e-07, 0.000000e00, 63.3828),
    ],
    dtype=np.float64,
)

#: Wavelengths of the tabulated data (nm), 360..830 every 5 nm.
WAVELENGTHS_NM = _TABLE[:, 0].copy()
#: CIE 1931 2-degree colour-matching functions, shape (95, 3): x̄, ȳ, z̄.
CMF_XYZ = _TABLE[:, 1:4].copy()
#: CIE standard illuminant D65, relative spectral power (100 at 560 nm), shape (95,).
D65 = _TABLE[:, 4].copy()

#: XYZ -> linear sRGB (IEC 61966-2-1), rows R, G, B.
XYZ_TO_LINEAR_SRGB = np.array(
    [
        [3.2406, -1.5372, -0.4986],
        [-0.9689, 1.8758, 0.0415],
        [0.0557, -0.2040, 1.0570],
    ]
)

ILLUMINANTS = ("D65", "E")


def illuminant_spd(name: str, wavelengths_nm: np.ndarray) -> np.ndarray:
    """Relative spectral power of illuminant ``name`` ("D65" or "E") at ``wavelengths_nm``."""
    wl = np.asarray(wavelengths_nm, dtype=np.float64)
    if name == "D65":
        return np.interp(wl, WAVELENGTHS_NM, D65)
    if name == "E":
        return np.ones_like(wl)
    raise ParameterError(f"unknown illuminant {name!r}; choose one of {', '.join(ILLUMINANTS)}")


def cmf(wavelengths_nm: np.ndarray) -> np.ndarray:
    """CIE 1931 2-degree x̄, ȳ, z̄ linearly interpolated at ``wavelengths_nm``; shape (n, 3).

    Outside 360..830 nm the functions are 0.
    """
    wl = np.asarray(wavelengths_nm, dtype=np.float64)
    return np.stack(
        [np.interp(wl, WAVELENGTHS_NM, CMF_XYZ[:, k], left=0.0, right=0.0) for k in range(3)],
        axis=-1,
    )


def _bin_widths(wl: np.ndarray) -> np.ndarray:
    """Trapezoid-like weights for possibly irregular sample wavelengths (nm)."""
    if wl.size == 1:
        return np.ones(1)
    edges = np.concatenate([[wl[0]], 0.5 * (wl[1:] + wl[:-1]), [wl[-1]]])
    return np.diff(edges)


def spectral_weights(wavelengths_nm: np.ndarray, illuminant: str = "D65") -> np.ndarray:
    """Matrix ``W`` (n, 3) such that ``XYZ = values @ W`` for spectra sampled at the wavelengths.

    The wavelengths must be strictly increasing and overlap the visible range. The normalization
    makes a flat spectrum of value c have Y = c (see the module docstring).
    """
    wl = np.asarray(wavelengths_nm, dtype=np.float64).ravel()
    if wl.size == 0 or not np.all(np.isfinite(wl)) or np.any(np.diff(wl) <= 0):
        raise ParameterError("wavelengths must be finite and strictly increasing")
    s = illuminant_spd(illuminant, wl)
    w = cmf(wl) * (s * _bin_widths(wl))[:, None]
    norm = w[:, 1].sum()
    if norm <= 0:
        raise ParameterError(
            f"wavelengths {wl[0]:g}..{wl[-1]:g} nm do not overlap the visible range"
        )
    return w / norm


def spectrum_to_xyz(
    values: np.ndarray, wavelengths_nm: np.ndarray, illuminant: str = "D65"
) -> np.ndarray:
    """Convert spectra ``(..., n)`` sampled at ``wavelengths_nm`` (n,) to XYZ ``(..., 3)``."""
    values = np.asarray(values, dtype=np.float64)
    return values @ spectral_weights(wavelengths_nm, illuminant)


def xyz_to_linear_srgb(xyz: np.ndarray) -> np.ndarray:
    """XYZ ``(..., 3)`` -> linear sRGB ``(..., 3)`` (may be negative for out-of-gamut colours)."""
    return np.asarray(xyz, dtype=np.float64) @ XYZ_TO_LINEAR_SRGB.T


def spectrum_to_linear_srgb(
    values: np.ndarray, wavelengths_nm: np.ndarray, illuminant: str = "D65"
) -> np.ndarray:
    """Spectra ``(..., n)`` -> linear sRGB ``(..., 3)`` via CIE 1931 XYZ under ``illuminant``."""
    return xyz_to_linear_srgb(spectrum_to_xyz(values, wavelengths_nm, illuminant))


def spectral_to_rgb_matrix(wavelengths_nm: Any, illuminant: str = "D65") -> np.ndarray:
    """``M`` (n, 3) with ``linear sRGB = spectrum @ M``: CIE 1931 XYZ under ``illuminant``
    (:func:`spectral_weights`), then :data:`XYZ_TO_LINEAR_SRGB`; a flat spectrum of value c
    gives Y = c (RGB (c, c, c) under D65). The one spectral -> RGB conversion of gonio's
    renderer, exporter and RGL reader."""
    wl = np.asarray(wavelengths_nm, dtype=np.float64)
    return spectral_weights(wl, illuminant) @ XYZ_TO_LINEAR_SRGB.T


_NM = re.compile(r"^\s*(\d+(?:\.\d+)?)\s*nm\s*$")


def wavelengths_from_names(names: Any) -> np.ndarray | None:
    """Wavelengths (nm) of channel names like ``"450nm"`` (``"450 nm"``, ``"532.5nm"``), or
    None unless there are at least two, every name reads so and they strictly increase."""
    try:
        items = list(names)
    except TypeError:
        return None
    wl = []
    for n in items:
        m = _NM.match(str(n))
        if m is None:
            return None
        wl.append(float(m.group(1)))
    if len(wl) < 2 or np.any(np.diff(wl) <= 0):
        return None
    return np.asarray(wl)
