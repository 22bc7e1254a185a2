"""A material as the sphere shader's 3-D texture: an isotropic half/diff table in float16.

Encoding
--------
The sphere of ``gonio view`` looks a material up in an isotropic table over gonio's
Rusinkiewicz axes ``(theta_h, theta_d, phi_d)`` (:mod:`gonio.brdf.tabulated`), node for node
the table gonio itself evaluates, with the same axes (warp, node offset, periodicity, phi_d
folding) and the same rule (:mod:`gonio.brdf.lookup`: multilinear or nearest in warped index
coordinates over the valid nodes, weights renormalized over them, 0 where none is valid).

* values: IEEE float16 (little endian) of ``values * 2**k``, with the power of two ``k`` chosen
  so that the largest magnitude is at most 2**15; the shader multiplies by ``2**-k``. float16
  keeps 11 significant bits, so every value of magnitude at least ``2**-14 / 2**k`` is within
  2**-11 = 0.049 % of the table (:func:`encoding_error` measures it per table);
* the mask: one byte per node (1 valid, 0 not), shipped only when some node is invalid;
* both gzip-compressed and base64-encoded in the page; the browser inflates them with its own
  ``DecompressionStream``.

Resampling
----------
* Isotropic tables (MERL, native gridded, NBRDF members, scattered data made renderable by
  :func:`gonio.render.measured.renderable`) are shipped as they are: no resampling.
* Analytic models (fits) are tabulated on MERL's 90 x 90 x 180 grid
  (:meth:`TabulatedBRDF.merl_like`), isotropic or not.
* Anisotropic tables, RGL files and anisotropic models are averaged over ``phi_h`` (the
  rotation of the half vector about the normal) onto that grid: the sphere shows the material's
  isotropic part. :func:`resampling_error` states what that costs at random direction pairs.
"""

from __future__ import annotations

import base64
import gzip
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from gonio.errors import ParameterError

#: phi_h rotations averaged when an anisotropic material is resampled onto an isotropic grid.
PHI_H_SAMPLES = 16


@dataclass(frozen=True)
class SphereTable:
    """What the shader needs of one material (see the module docstring).

    Attributes
    ----------
    label : the material's name on the page.
    axes : the table's three axes ``(theta_h, theta_d, phi_d)`` as dictionaries
        (:meth:`gonio.brdf.grid.Axis.to_dict`).
    shape : ``(n_theta_h, n_theta_d, n_phi_d)``.
    channels : 1 (grey) or 3 (linear sRGB).
    fold : phi_d folding: 0 none, 1 reciprocity, 2 reciprocity and mirror.
    nearest : nearest-node lookup instead of multilinear.
    scale_log2 : ``k``: the stored float16 values are ``values * 2**k``.
    values_b64 : base64 of the gzip of the float16 values ``(n_th, n_td, n_pd, C)``, C order.
    mask_b64 : base64 of the gzip of the uint8 mask ``(n_th, n_td, n_pd)``, or None (all valid).
    encoding_error : max relative error of the float16 values (nodes with ``|f| > 0``).
    resampling : one line saying how the table was made from the input.
    resampling_error : relative RMSE of the resampled table against the input at random
        direction pairs, or None when the input is shipped as it is.
    """

    label: str
    axes: tuple[dict[str, Any], ...]
    shape: tuple[int, int, int]
    channels: int
    fold: int
    nearest: bool
    scale_log2: int
    values_b64: str
    mask_b64: str | None
    encoding_error: float
    resampling: str
    resampling_error: float | None

    def to_json(self) -> dict[str, Any]:
        """The JSON object the page's sphere script reads."""
        return {
            "label": self.label,
            "axes": list(self.axes),
            "shape": list(self.shape),
            "channels": self.channels,
            "fold": self.fold,
            "nearest": self.nearest,
            "scale": 2.0 ** (-self.scale_log2),
            "values": self.values_b64,
            "mask": self.mask_b64,
            "encoding_error": self.encoding_error,
            "resampling": self.resampling,
            "resampling_error": self.resampling_error,
        }


def fold_of(phi_d_axis: Any) -> int:
    """phi_d folding of an isotropic table whose phi_d axis is ``phi_d_axis``, by the rule of
    :class:`gonio.brdf.tabulated.TabulatedBRDF`: its span at most pi/2 -> 2, at most pi -> 1."""
    span = phi_d_axis.hi - phi_d_axis.lo
    if span <= math.pi / 2 + 1e-9:
        return 2
    return 1 if span <= math.pi + 1e-6 else 0


def float16_scale(values: np.ndarray) -> int:
    """``k`` such that ``max |values| * 2**k`` is in (2**14, 2**15] (0 for an all-zero table)."""
    peak = float(np.max(np.abs(values))) if values.size else 0.0
    if not (peak > 0 and math.isfinite(peak)):
        return 0
    return math.floor(15 - math.log2(peak))


def encoding_error(values: np.ndarray, encoded: np.ndarray, scale_log2: int) -> float:
    """Max relative error ``|decoded - values| / |values|`` over the nonzero ``values``."""
    v = np.asarray(values, np.float64)
    d = encoded.astype(np.float64) * 2.0 ** (-scale_log2)
    nz = v != 0
    if not nz.any():
        return 0.0
    return float(np.max(np.abs(d[nz] - v[nz]) / np.abs(v[nz])))


def pack(data: np.ndarray | bytes) -> str:
    """base64 of the gzip of ``data`` (an array's bytes in C order, or bytes), as the page
    ships its binary data."""
    raw = data if isinstance(data, bytes) else np.ascontiguousarray(data).tobytes()
    return base64.b64encode(gzip.compress(raw, 6, mtime=0)).decode()


def _iso_axes_ok(table: Any) -> bool:
    names = tuple(a.name for a in table.axes)
    return table.parameterization == "half_diff_iso" and names == ("theta_h", "theta_d", "phi_d")


#: Pairs per compiled evaluation (inputs are padded to a multiple: one program per material).
CHUNK = 1 << 16


class Compiled:
    """``material.f`` compiled once for chunks of :data:`CHUNK` pairs (inputs are padded), so
    that the many evaluations of a page reuse one program per material."""

    def __init__(self, material: Any) -> None:
        import jax

        self.material = material
        self._f = jax.jit(lambda wi, wo: material.f(wi, wo))

    def f(self, wi: Any, wo: Any) -> np.ndarray:
        wi = np.asarray(wi, np.float64).reshape(-1, 3)
        wo = np.asarray(wo, np.float64).reshape(-1, 3)
        n = wi.shape[0]
        out = []
        for a in range(0, max(n, 1), CHUNK):
            b = min(a + CHUNK, n)
            pi = np.zeros((CHUNK, 3))
            po = np.zeros((CHUNK, 3))
            pi[:, 2] = po[:, 2] = 1.0
            pi[: b - a], po[: b - a] = wi[a:b], wo[a:b]
            out.append(np.asarray(self._f(pi, po), np.float64)[: b - a])
        return np.concatenate(out, 0)


def compiled(material: Any) -> Compiled:
    """``material`` wrapped in :class:`Compiled` (once)."""
    return material if isinstance(material, Compiled) else Compiled(material)


class _PhiHAverage:
    """``f`` of a material averaged over rotations of the direction pair about the normal."""

    def __init__(self, material: Any, n: int = PHI_H_SAMPLES) -> None:
        self.material = material
        self.n = n

    def f(self, wi: Any, wo: Any) -> np.ndarray:
        wi = np.asarray(wi, np.float64)
        wo = np.asarray(wo, np.float64)
        total = None
        for k in range(self.n):
            a = 2 * math.pi * k / self.n
            c, s = math.cos(a), math.sin(a)
            rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            v = np.asarray(self.material.f(wi @ rot.T, wo @ rot.T), np.float64)
            total = v if total is None else total + v
        return total / self.n


def _cosine_pairs(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` pairs of directions, each cosine-distributed over the upper hemisphere."""
    rng = np.random.default_rng(seed)

    def dirs() -> np.ndarray:
        u = rng.random((n, 2))
        r, phi = np.sqrt(u[:, 0]), 2 * math.pi * u[:, 1]
        return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - u[:, 0])], -1)

    return dirs(), dirs()


def is_isotropic(material: Any, n: int = 512, rtol: float = 1e-4) -> bool:
    """Whether ``f`` is unchanged (within ``rtol`` of its largest value) when a direction pair
    is rotated about the normal, at ``n`` seeded random pairs and three rotations."""
    wi, wo = _cosine_pairs(n, 1)
    ref = np.asarray(material.f(wi, wo), np.float64)
    tol = rtol * max(float(np.max(np.abs(ref))), 1e-30)
    for a in (0.7, 2.1, 4.0):
        c, s = math.cos(a), math.sin(a)
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        got = np.asarray(material.f(wi @ rot.T, wo @ rot.T), np.float64)
        if not np.all(np.abs(got - ref) <= tol):
            return False
    return True


def resampling_error(material: Any, table: Any, n: int = 4096, seed: int = 0) -> float:
    """Relative RMSE of ``table`` against ``material`` at ``n`` random direction pairs, both
    cosine-distributed over the upper hemisphere (seeded): ``||t - m|| / ||m||`` over all
    channels."""
    wi, wo = _cosine_pairs(n, seed)
    ref = np.asarray(material.f(wi, wo), np.float64)
    got = np.asarray(table.f(wi, wo), np.float64)
    den = float(np.sqrt(np.mean(ref**2)))
    return float(np.sqrt(np.mean((got - ref) ** 2)) / den) if den > 0 else 0.0


def sphere_table(label: str, material: Any) -> SphereTable:
    """The shader's table of ``material`` (an isotropic or anisotropic table, an RGL file, an
    analytic model; spectral data already made RGB), as the module docstring describes.

    Raises
    ------
    ParameterError
        the material has a channel count other than 1 or 3.
    """
    from gonio.brdf.tabulated import TabulatedBRDF

    if isinstance(material, Compiled):
        material = material.material
    if isinstance(material, TabulatedBRDF) and _iso_axes_ok(material):
        table, how, err = material, "the table itself (no resampling)", None
    else:
        fast = compiled(material)
        iso = is_isotropic(fast)
        source = fast if iso else _PhiHAverage(fast)
        table = TabulatedBRDF.merl_like(source, chunk=CHUNK)
        if isinstance(material, TabulatedBRDF) or hasattr(material, "to_table"):
            how = "resampled onto MERL's 90x90x180 half/diff grid"
        else:
            how = "the model tabulated on MERL's 90x90x180 half/diff grid"
        if not iso:
            how += f", averaged over {PHI_H_SAMPLES} rotations about the normal (isotropic part)"
        err = resampling_error(fast, table)
    values = np.asarray(table.values, np.float32)
    c = values.shape[-1]
    if c not in (1, 3):
        raise ParameterError(f"{label}: the sphere shows 1 or 3 channels, the data has {c}")
    mask = np.asarray(table.mask, bool) if table.mask is not None else None
    values = np.where(mask[..., None], values, 0.0) if mask is not None else values
    values = np.nan_to_num(values, nan=0.0, posinf=0.0, neginf=0.0)
    k = float16_scale(values)
    enc = (values.astype(np.float64) * 2.0**k).astype("<f2")
    return SphereTable(
        label=label,
        axes=tuple(a.to_dict() for a in table.axes),
        shape=tuple(int(s) for s in values.shape[:3]),
        channels=c,
        fold=fold_of(table.axes[2]),
        nearest=table.interpolation == "nearest",
        scale_log2=k,
        values_b64=pack(enc),
        mask_b64=None if mask is None or mask.all() else pack(mask.astype(np.uint8)),
        encoding_error=encoding_error(values, enc, k),
        resampling=how,
        resampling_error=err,
    )


def environment_map() -> dict[str, Any]:
    """The spheres' environment for the page: gonio's studio lat-long map
    (:func:`gonio.render.lights.studio_environment`, the default light of ``gonio render``),
    ``(H, W, 3)`` linear RGB radiance in float32, gzip + base64, rows from straight up (+y)
    down, the centre column facing -z (:func:`gonio.render.lights.latlong_to_direction`)."""
    from gonio.render.lights import studio_environment

    img = np.ascontiguousarray(studio_environment(), dtype="<f4")
    h, w = img.shape[:2]
    return {
        "shape": [h, w],
        "radiance": pack(img),
        "description": (
            f"gonio's studio environment ({h}x{w} lat-long map, the default light of gonio render)"
        ),
    }
