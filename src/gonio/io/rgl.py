"""RGL-EPFL ``tensor_file`` measured BSDFs (Dupuy & Jakob 2018): container parsing and evaluation.

Container (little-endian): 12 bytes ``tensor_file\\0``; uint8 major (1) and minor version; uint32
field count; per field: uint16 name length, name, uint16 ndim, uint8 dtype code, uint64 absolute
data offset, uint64 shape[ndim]; data in C order.

Evaluation follows the published reader (the ``measured`` BSDF plugin of Mitsuba 2/3, which is the
reference implementation accompanying the paper), re-implemented here in NumPy:

1. the half vector ``wm = normalize(wi + wo)`` and ``wi`` are turned into unit coordinates
   ``u(theta) = sqrt(2 theta / pi)``, ``u(phi) = (phi + pi) / (2 pi)`` (for isotropic data the
   half vector's azimuth is taken relative to ``phi_i`` and wrapped to [0, 1));
2. the ``vndf`` warp — a continuous marginal/conditional 2-D distribution over a bilinear grid,
   linearly interpolated in the parameters ``(phi_i, theta_i)`` — is *inverted* at ``u(wm)``;
3. the colour table (``rgb`` or ``spectra``) is bilinearly interpolated at the resulting point,
   conditioned on ``(phi_i, theta_i, channel)``;
4. if ``jacobian`` is set the value is multiplied by ``ndf(u(wm)) / (4 sigma(u(wi)))``.

The result is ``F = f_r * cos(theta_o)`` in the file's own order (:meth:`RGLBSDF.f_cos`; the
file's "incident" direction is the one the tables are conditioned on). gonio's :meth:`RGLBSDF.f`
follows Mitsuba's rendering convention, where that direction is the viewer's (``si.wi`` points to
the camera): ``f(wi, wo) = F(wo, wi) / cos(theta_i)``, see :mod:`gonio.io.rgl_measured`, whose
JAX :class:`~gonio.io.rgl_measured.RGLMeasured` is what :func:`gonio.io.load` returns. This
NumPy evaluator is its independent reference and the source of :meth:`RGLBSDF.to_table`.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from gonio._bounded import MAX_BRDF
from gonio.io._common import PathLike, fail, read_bytes

if TYPE_CHECKING:
    from collections.abc import Callable

    from gonio.brdf.tabulated import TabulatedBRDF

MAGIC = b"tensor_file\x00"
SUPPORTED_MAJOR = 1
_DTYPES = {
    1: "u1",
    2: "i1",
    3: "<u2",
    4: "<i2",
    5: "<u4",
    6: "<i4",
    7: "<u8",
    8: "<i8",
    9: "<f2",
    10: "<f4",
    11: "<f8",
}
_MAX_FIELDS = 4096
#: Default horizon cut of :meth:`RGLBSDF.to_table`: cos(89 degrees).
HORIZON_MIN_COS = math.cos(math.radians(89.0))
_MAX_NDIM = 16
#: The colour table may dip below 0 (colours outside the sRGB gamut, noise in dark cells: the
#: database's files reach -1.4 % of their peak); below this fraction of its largest magnitude
#: it cannot come from a measurement and the file is refused.
COLOUR_NEGATIVE_TOLERANCE = 0.1


def parse_tensor_file(data: bytes, path: PathLike = "<bytes>") -> dict[str, np.ndarray]:
    """Parse a ``tensor_file`` container into ``{name: array}`` (arrays are copies, native order).

    Raises
    ------
    FormatError
        Wrong magic, unknown major version, truncated header or data, bad dtype codes, fields
        pointing outside the file.
    """
    if len(data) < 18:
        raise fail(path, f"truncated tensor_file: {len(data)} bytes")
    if data[:12] != MAGIC:
        raise fail(path, "not a tensor_file (wrong magic)")
    major, minor = data[12], data[13]
    if major != SUPPORTED_MAJOR:
        raise fail(path, f"unsupported tensor_file version {major}.{minor} (reader knows 1.x)")
    (n_fields,) = struct.unpack_from("<I", data, 14)
    if n_fields > _MAX_FIELDS:
        raise fail(path, f"impossible tensor_file field count {n_fields}")
    pos = 18
    fields: dict[str, np.ndarray] = {}
    try:
        for _ in range(n_fields):
            (name_len,) = struct.unpack_from("<H", data, pos)
            pos += 2
            raw_name = data[pos : pos + name_len]
            if len(raw_name) != name_len:
                raise fail(path, "truncated tensor_file header (field name)")
            try:
                name = raw_name.decode("ascii")
            except UnicodeDecodeError:
                raise fail(path, "tensor_file field name is not ASCII") from None
            pos += name_len
            ndim, code, offset = struct.unpack_from("<HBQ", data, pos)
            pos += 11
            if ndim > _MAX_NDIM:
                raise fail(path, f"field {name!r}: impossible rank {ndim}")
            if code not in _DTYPES:
                raise fail(path, f"field {name!r}: unknown dtype code {code}")
            shape = struct.unpack_from(f"<{ndim}Q", data, pos)
            pos += 8 * ndim
            if any(n >= 1 << 40 for n in shape):  # even beside a 0, NumPy cannot shape these
                raise fail(path, f"field {name!r}: impossible shape {'x'.join(map(str, shape))}")
            dtype = np.dtype(_DTYPES[code])
            count = 1
            for s in shape:
                count *= int(s)
            nbytes = count * dtype.itemsize
            if offset + nbytes > len(data):
                raise fail(
                    path,
                    f"field {name!r} ({'x'.join(map(str, shape))} {dtype.name}) runs past the "
                    f"end of the file (truncated?)",
                )
            if name in fields:
                raise fail(path, f"duplicate field {name!r}")
            arr = np.frombuffer(data, dtype=dtype, count=count, offset=offset).reshape(shape)
            fields[name] = arr.astype(dtype.newbyteorder("="), copy=True)
    except struct.error:
        raise fail(path, "truncated tensor_file header") from None
    return fields


def tensor_file_bytes(fields: dict[str, np.ndarray]) -> bytes:
    """Encode ``{name: array}`` as a ``tensor_file`` 1.0 container (inverse of the parser).

    Used to build test fixtures and to re-export edited RGL data; dtypes must be among the
    container's eleven codes.
    """
    codes = {np.dtype(v): k for k, v in _DTYPES.items()}
    header = bytearray(MAGIC + bytes([1, 0]) + struct.pack("<I", len(fields)))
    arrays = []
    for name, arr in fields.items():
        a = np.ascontiguousarray(arr)
        dt = a.dtype.newbyteorder("<") if a.dtype.itemsize > 1 else a.dtype
        if dt not in codes:
            raise ValueError(f"field {name!r}: dtype {a.dtype} has no tensor_file code")
        arrays.append((name.encode("ascii"), a.astype(dt), codes[dt]))
    size = len(header) + sum(2 + len(n) + 2 + 1 + 8 + 8 * a.ndim for n, a, _ in arrays)
    offset = size
    blobs = []
    for name, a, code in arrays:
        header += struct.pack("<H", len(name)) + name
        header += struct.pack("<HBQ", a.ndim, code, offset)
        header += struct.pack(f"<{a.ndim}Q", *a.shape)
        blobs.append(a.tobytes())
        offset += a.nbytes
    return bytes(header) + b"".join(blobs)


def _find_interval(values: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Largest ``i`` in ``[0, n-2]`` with ``values[i] < x`` (clamped), like find_interval."""
    idx = np.searchsorted(values, x, side="left") - 1
    return np.clip(idx, 0, max(len(values) - 2, 0))


class _Marginal2D:
    """NumPy port of a continuous ``Marginal2D`` warp over a bilinear grid with parameters.

    ``data`` has shape ``(*param_res, H, W)``; positions are ``(x, y)`` in [0, 1]² with x along W.
    With ``build_cdf`` the slices are normalized and CDFs built (for :meth:`invert`); without,
    :meth:`eval` is a plain multilinear interpolation of the raw data.
    """

    def __init__(self, data: np.ndarray, params: list[np.ndarray], build_cdf: bool) -> None:
        data = np.asarray(data, dtype=np.float64)
        self.param_values = [np.asarray(p, dtype=np.float64) for p in params]
        self.param_res = data.shape[:-2]
        self.h, self.w = data.shape[-2:]
        if self.h < 2 or self.w < 2:
            raise ValueError("grid resolution must be at least 2 x 2")
        slices = data.reshape(-1, self.h, self.w)
        # strides in slices; dimensions of size 1 get stride 0 (as in the reference)
        self.strides: list[int] = [0] * len(self.param_res)
        n = 1
        for i in range(len(self.param_res) - 1, -1, -1):
            self.strides[i] = n if self.param_res[i] > 1 else 0
            n *= self.param_res[i]
        if build_cdf:
            cond = np.zeros_like(slices)
            cond[:, :, 1:] = np.cumsum(0.5 * (slices[:, :, :-1] + slices[:, :, 1:]), axis=2)
            marg = np.zeros((slices.shape[0], self.h))
            row_tot = cond[:, :, -1]
            marg[:, 1:] = np.cumsum(0.5 * (row_tot[:, :-1] + row_tot[:, 1:]), axis=1)
            norm = 1.0 / marg[:, -1]
            self.data = slices * norm[:, None, None]
            self.cond = cond * norm[:, None, None]
            self.marg = marg * norm[:, None]
        else:
            self.data = slices
            self.cond = self.marg = None

    def _corners(self, params: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """Slice indices ``(N, 2^D)`` and weights ``(N, 2^D)`` of the parameter interpolation."""
        n = np.broadcast(*params).shape if params else ()
        idx = np.zeros((*n, 1), dtype=np.int64)
        wts = np.ones((*n, 1))
        for dim, p in enumerate(params):
            vals = self.param_values[dim]
            p = np.broadcast_to(np.asarray(p, dtype=np.float64), n)
            if len(vals) == 1:
                i0 = np.zeros(n, dtype=np.int64)
                w1 = np.zeros(n)
            else:
                i0 = _find_interval(vals, p)
                p0, p1 = vals[i0], vals[i0 + 1]
                w1 = np.clip((p - p0) / (p1 - p0), 0.0, 1.0)
            base = idx + (self.strides[dim] * i0)[..., None]
            idx = np.concatenate([base, base + self.strides[dim]], axis=-1)
            wts = np.concatenate([wts * (1.0 - w1)[..., None], wts * w1[..., None]], axis=-1)
        return idx, wts

    @staticmethod
    def _gather(arr: np.ndarray, idx: np.ndarray, wts: np.ndarray, *rest: np.ndarray) -> np.ndarray:
        """Parameter-interpolated ``arr[slice, *rest]``."""
        vals = arr[(idx, *(r[..., None] for r in rest))]
        return np.sum(vals * wts, axis=-1)

    def _patch(self, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        x = np.clip(pos[..., 0], 0.0, 1.0) * (self.w - 1)
        y = np.clip(pos[..., 1], 0.0, 1.0) * (self.h - 1)
        px = np.minimum(x.astype(np.int64), self.w - 2)
        py = np.minimum(y.astype(np.int64), self.h - 2)
        return px, py, x - px, y - py

    def eval(self, pos: np.ndarray, params: list[np.ndarray]) -> np.ndarray:
        """Bilinear (and parameter-linear) interpolation at ``pos`` ``(..., 2)``."""
        idx, wts = self._corners(params)
        px, py, fx, fy = self._patch(pos)
        g = self._gather
        v00 = g(self.data, idx, wts, py, px)
        v10 = g(self.data, idx, wts, py, px + 1)
        v01 = g(self.data, idx, wts, py + 1, px)
        v11 = g(self.data, idx, wts, py + 1, px + 1)
        scale = 1.0 if self.cond is None else (self.w - 1) * (self.h - 1)
        return ((1 - fy) * ((1 - fx) * v00 + fx * v10) + fy * ((1 - fx) * v01 + fx * v11)) * scale

    def invert(self, pos: np.ndarray, params: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """Inverse of the continuous warp: sample-space point ``(..., 2)`` and density."""
        assert self.cond is not None and self.marg is not None
        idx, wts = self._corners(params)
        px, py, x, y = self._patch(pos)
        g = self._gather
        v00 = g(self.data, idx, wts, py, px)
        v10 = g(self.data, idx, wts, py, px + 1)
        v01 = g(self.data, idx, wts, py + 1, px)
        v11 = g(self.data, idx, wts, py + 1, px + 1)
        c0 = (1 - y) * v00 + y * v01
        c1 = (1 - y) * v10 + y * v11
        pdf = (1 - x) * c0 + x * c1
        sx = x * (c0 + 0.5 * x * (c1 - c0))
        sx = sx + (1 - y) * g(self.cond, idx, wts, py, px) + y * g(self.cond, idx, wts, py + 1, px)
        last = np.full_like(px, self.w - 1)
        r0 = g(self.cond, idx, wts, py, last)
        r1 = g(self.cond, idx, wts, py + 1, last)
        sx = sx / ((1 - y) * r0 + y * r1)
        sy = y * (r0 + 0.5 * y * (r1 - r0)) + g(self.marg, idx, wts, py)
        return np.stack([sx, sy], axis=-1), pdf * (self.w - 1) * (self.h - 1)


def _elevation(d: np.ndarray) -> np.ndarray:
    """Polar angle of unit vectors, computed stably near the pole (as the reference reader)."""
    dist = np.sqrt(d[..., 0] ** 2 + d[..., 1] ** 2 + (d[..., 2] - 1.0) ** 2)
    return 2.0 * np.arcsin(np.clip(0.5 * dist, -1.0, 1.0))


def _theta2u(theta: np.ndarray) -> np.ndarray:
    return np.sqrt(theta * (2.0 / math.pi))


def _phi2u(phi: np.ndarray) -> np.ndarray:
    return (phi + math.pi) / (2.0 * math.pi)


@dataclass
class RGLBSDF:
    """An RGL-EPFL measured BSDF, evaluable at arbitrary direction pairs.

    Attributes
    ----------
    fields : dict of str to ndarray
        The raw container fields.
    wavelengths : ndarray
        Channel coordinates of the colour table: (0, 1, 2) for RGB files, nm for spectral files.
    channels : Channels
        gonio channel description (RGB/sRGB or spectral).
    description : str
        The file's free-text description.
    """

    fields: dict[str, np.ndarray]
    path: str = "<memory>"
    description: str = ""
    isotropic: bool = True
    jacobian: bool = True
    reduction: int = 0
    spectral: bool = False
    wavelengths: np.ndarray = field(default_factory=lambda: np.arange(3.0))
    _ndf: _Marginal2D | None = None
    _sigma: _Marginal2D | None = None
    _vndf: _Marginal2D | None = None
    _colour: _Marginal2D | None = None

    @classmethod
    def from_fields(cls, fields: dict[str, np.ndarray], path: PathLike = "<memory>") -> RGLBSDF:
        """Validate the fields of a BSDF tensor file and build the interpolants."""

        def need(name: str, ndim: int, kind: str = "f4") -> np.ndarray:
            if name not in fields:
                raise fail(path, f"tensor_file has no {name!r} field (not an RGL BSDF?)")
            arr = fields[name]
            if arr.ndim != ndim or arr.dtype != np.dtype(kind):
                raise fail(
                    path,
                    f"field {name!r} has shape {arr.shape} {arr.dtype}, expected {ndim}-D {kind}",
                )
            if arr.dtype.kind == "f" and not np.all(np.abs(arr) <= MAX_BRDF):  # False for NaN
                raise fail(path, f"field {name!r} contains NaN, Inf or values beyond {MAX_BRDF:g}")
            if arr.size == 0:
                raise fail(path, f"field {name!r} is empty")
            return arr

        theta_i = need("theta_i", 1)
        phi_i = need("phi_i", 1)
        ndf = need("ndf", 2)
        sigma = need("sigma", 2)
        vndf = need("vndf", 4)
        luminance = need("luminance", 4)
        description = need("description", 1, "u1")
        jac = need("jacobian", 1, "u1")
        spectral = "wavelengths" in fields
        if spectral:
            colour_name = "spectra"
            colour = need("spectra", 5)
            wavelengths = need("wavelengths", 1).astype(np.float64)
        else:
            colour_name = "rgb"
            colour = need("rgb", 5)
            wavelengths = np.arange(3.0)
        np_, nt = len(phi_i), len(theta_i)
        for name, arr in (("vndf", vndf), ("luminance", luminance), (colour_name, colour)):
            if arr.shape[:2] != (np_, nt):
                raise fail(
                    path,
                    f"field {name!r} has shape {arr.shape}, expected leading axes "
                    f"({np_}, {nt}) from the lengths of 'phi_i' and 'theta_i'",
                )
        if colour.shape[2] != len(wavelengths):
            raise fail(
                path,
                f"field {colour_name!r} has {colour.shape[2]} channels, expected "
                f"{len(wavelengths)}",
            )
        if luminance.shape[2:] != colour.shape[3:]:
            raise fail(
                path,
                f"field 'luminance' grid {luminance.shape[2:]} differs from the "
                f"{colour_name!r} grid {colour.shape[3:]}",
            )
        for name, grid in (
            ("ndf", ndf.shape),
            ("sigma", sigma.shape),
            ("vndf", vndf.shape[2:]),
            ("luminance", luminance.shape[2:]),
            (colour_name, colour.shape[3:]),
        ):
            if min(grid) < 2:
                raise fail(path, f"field {name!r} grid {grid} must be at least 2 x 2")
        if jac.shape != (1,):
            raise fail(path, "field 'jacobian' must hold one byte")
        for name, arr in (("theta_i", theta_i), ("phi_i", phi_i)):
            if len(arr) > 1 and np.any(np.diff(arr) <= 0):
                raise fail(path, f"field {name!r} values are not strictly increasing")
        if spectral and len(wavelengths) > 1 and np.any(np.diff(wavelengths) <= 0):
            raise fail(path, "field 'wavelengths' values are not strictly increasing")
        for name, arr in (("vndf", vndf), ("ndf", ndf), ("luminance", luminance)):
            if np.any(arr < 0):
                raise fail(path, f"field {name!r} has negative values (min {float(arr.min()):g})")
        if np.any(sigma <= 0):
            raise fail(path, "field 'sigma' has non-positive values (projected areas are > 0)")
        top = float(np.max(np.abs(colour))) if colour.size else 0.0
        if colour.size and float(np.min(colour)) < -COLOUR_NEGATIVE_TOLERANCE * top:
            raise fail(
                path,
                f"field {colour_name!r} is clearly negative (min {float(np.min(colour)):g}, "
                f"below -{COLOUR_NEGATIVE_TOLERANCE:g} x its peak {top:g})",
            )
        for name, arr in (("vndf", vndf), ("luminance", luminance)):
            sums = arr.reshape(np_ * nt, -1).sum(axis=1)
            if np.any(sums <= 0):
                raise fail(path, f"field {name!r} has an identically zero slice")
        isotropic = np_ <= 2
        reduction = 0
        if not isotropic:
            reduction = round(2 * math.pi / float(phi_i[-1] - phi_i[0]))
        self = cls(
            fields=fields,
            path=str(path),
            description=bytes(description).decode("utf-8", errors="replace"),
            isotropic=isotropic,
            jacobian=bool(jac[0]),
            reduction=reduction,
            spectral=spectral,
            wavelengths=wavelengths,
        )
        params = [phi_i.astype(np.float64), theta_i.astype(np.float64)]
        self._ndf = _Marginal2D(ndf, [], build_cdf=False)
        self._sigma = _Marginal2D(sigma, [], build_cdf=False)
        self._vndf = _Marginal2D(vndf, params, build_cdf=True)
        self._colour = _Marginal2D(colour, [*params, wavelengths], build_cdf=False)
        return self

    @property
    def n_channels(self) -> int:
        """Number of colour channels (3 for RGB files, the number of wavelengths otherwise)."""
        return len(self.wavelengths)

    @property
    def channels(self) -> Any:
        """gonio :class:`Channels` of this BSDF."""
        from gonio.brdf.tabulated import Channels

        if self.spectral:
            return Channels.spectral(self.wavelengths)
        return Channels.rgb()

    def f_cos(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """The tabulated quantity ``F(wi, wo) = f_r * cos(theta_o)``, shape ``(..., C)``, in the
        file's own argument order: ``wi`` is the direction the tables are conditioned on (the
        file's "incident" direction, Mitsuba's ``si.wi``), ``wo`` the warped one. Zero where
        either direction is at or below the horizon. (:meth:`f` swaps them: see there.)
        """
        assert self._vndf is not None and self._colour is not None
        wi = np.asarray(wi, dtype=np.float64)
        wo = np.asarray(wo, dtype=np.float64)
        wi, wo = np.broadcast_arrays(wi, wo)
        active = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        wi = wi.copy()
        wo = wo.copy()
        if self.reduction >= 2:
            # fold by the measured symmetry: mirror both vectors so that wi sits in the
            # tabulated wedge (mulsign_neg: make the component's sign opposite to the reference)
            sy = wi[..., 1].copy()
            sx = wi[..., 0].copy() if self.reduction == 4 else sy
            for w in (wi, wo):
                w[..., 0] = -np.abs(w[..., 0]) * np.where(sx >= 0, 1.0, -1.0)
                w[..., 1] = -np.abs(w[..., 1]) * np.where(sy >= 0, 1.0, -1.0)
        m = wi + wo
        norm = np.linalg.norm(m, axis=-1, keepdims=True)
        m = m / np.where(norm > 0, norm, 1.0)
        theta_i = _elevation(wi)
        phi_i = np.arctan2(wi[..., 1], wi[..., 0])
        theta_m = _elevation(m)
        phi_m = np.arctan2(m[..., 1], m[..., 0])
        u_wi = np.stack([_theta2u(theta_i), _phi2u(phi_i)], axis=-1)
        u_m1 = _phi2u(phi_m - phi_i if self.isotropic else phi_m)
        u_m = np.stack([_theta2u(theta_m), u_m1 - np.floor(u_m1)], axis=-1)
        params = [phi_i, theta_i]
        sample, _ = self._vndf.invert(u_m, params)
        out = np.empty((*phi_i.shape, self.n_channels))
        for c, lam in enumerate(self.wavelengths):
            out[..., c] = self._colour.eval(sample, [phi_i, theta_i, np.full_like(phi_i, lam)])
        if self.jacobian:
            assert self._ndf is not None and self._sigma is not None
            jac = self._ndf.eval(u_m, []) / (4.0 * self._sigma.eval(u_wi, []))
            out *= jac[..., None]
        return np.where(active[..., None], out, 0.0)

    def f(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """BRDF ``f_r(wi, wo)`` in 1/sr, shape ``(..., C)``: ``f_cos(wo, wi) / cos(theta_i)``.

        gonio's ``wi`` (toward the light) is the file's free direction and ``wo`` (toward the
        viewer) the one its tables are conditioned on, as Mitsuba renders the file (``si.wi``
        toward the camera); see :mod:`gonio.io.rgl_measured`. Within about a degree of the
        horizon this grows like ``1 / cos(theta_i)`` because the tabulated ``f_cos`` does not
        vanish there (see :meth:`to_table`'s ``min_cos``).
        """
        wi = np.asarray(wi, dtype=np.float64)
        cos_i = wi[..., 2]
        val = self.f_cos(wo, wi)
        return np.where((cos_i > 0)[..., None], val / np.where(cos_i > 0, cos_i, 1.0)[..., None], 0)

    def to_table(
        self,
        axes: tuple[Any, ...] | None = None,
        chunk: int = 1 << 16,
        progress: Callable[[int, int], None] | None = None,
        min_cos: float = HORIZON_MIN_COS,
        reciprocal: bool = False,
    ) -> TabulatedBRDF:
        """Tabulate ``f_r`` on a half/diff grid as a gonio :class:`TabulatedBRDF`.

        Parameters
        ----------
        axes : tuple of Axis, optional
            ``(theta_h, theta_d, phi_d)`` for isotropic data (default: MERL's 90x90x180 grid) or
            ``(theta_h, phi_h, theta_d, phi_d)`` for anisotropic data.
        chunk : int
            Cells evaluated per batch.
        progress : callable(done, total), optional
            Called after each batch (for progress bars).
        min_cos : float
            Cells whose ``wi`` or ``wo`` has ``cos(theta) < min_cos`` are marked invalid. The
            tabulated ``f_r cos(theta_o)`` does not vanish at the horizon (it is a bilinear
            interpolant), so ``f_r`` diverges like ``1 / cos(theta_o)`` in the last degree;
            the default ``cos(89 deg)`` keeps that artifact out of the table.
        reciprocal : bool
            Store the reciprocal part ``(f(wi, wo) + f(wo, wi)) / 2`` of the measurement. A
            measured table is not exactly reciprocal (the acrylic felt differs by ~5 % between
            ``phi_d`` and ``phi_d + pi``), but an isotropic half/diff table folds ``phi_d`` by
            reciprocity: taken from one half only, its periodic wrap joins ``f(phi_d -> pi)`` to
            ``f(0)``, a one-cell ramp (a slope discontinuity) on the plane of incidence, where
            in-plane geometries sit. The average makes the folded table continuous there.
            Ignored for anisotropic axes (``phi_d`` over ``2 pi`` is not folded).
        """
        from gonio.brdf.tabulated import Axis, TabulatedBRDF
        from gonio.io._geometry import half_diff_to_directions
        from gonio.io.merl import merl_axes

        if axes is None:
            if self.isotropic:
                axes = merl_axes()
            else:
                th, td, pd = merl_axes((45, 45, 90))
                axes = (
                    th,
                    Axis("phi_h", 90, 0.0, 2 * math.pi, "linear", True, 0.0),
                    td,
                    Axis("phi_d", 180, 0.0, 2 * math.pi, "linear", True, 0.0),
                )
        nodes = [np.asarray(a.nodes(), dtype=np.float64) for a in axes]
        grid = np.meshgrid(*nodes, indexing="ij")
        if len(axes) == 3:
            th, td, pd = grid
            ph = np.zeros_like(th)
            param = "half_diff_iso"
        elif len(axes) == 4:
            th, ph, td, pd = grid
            param = "half_diff_aniso"
        else:
            raise ValueError("axes must be (theta_h, theta_d, phi_d) or 4 half/diff axes")
        shape = th.shape
        symmetrize = reciprocal and param == "half_diff_iso"
        flat = [a.ravel() for a in (th, ph, td, pd)]
        total = flat[0].size
        values = np.zeros((total, self.n_channels), dtype=np.float32)
        valid = np.zeros(total, dtype=bool)
        for start in range(0, total, chunk):
            sl = slice(start, min(start + chunk, total))
            wi, wo = half_diff_to_directions(*(a[sl] for a in flat))
            ok = (wi[..., 2] >= min_cos) & (wo[..., 2] >= min_cos)
            val = self.f(wi, wo)
            if symmetrize:  # phi_d + pi is the swapped pair; ok is symmetric in (wi, wo)
                val = 0.5 * (val + self.f(wo, wi))
            values[sl] = np.where(ok[:, None], val, 0.0)
            valid[sl] = ok
            if progress is not None:
                progress(sl.stop, total)
        return TabulatedBRDF(
            values=values.reshape(*shape, self.n_channels),
            axes=tuple(axes),
            parameterization=param,
            mask=valid.reshape(shape),
            sigma=None,
            counts=None,
            channels=self.channels,
            meta={
                "source": {
                    "horizon_min_cos": float(min_cos),
                    "format": "rgl-tensor",
                    "file": self.path,
                    "description": self.description,
                }
            },
            interpolation="linear",
        )


def read_rgl(path: PathLike) -> RGLBSDF:
    """Read an RGL ``.bsdf`` tensor file as an evaluable :class:`RGLBSDF`."""
    return RGLBSDF.from_fields(parse_tensor_file(read_bytes(path), path), path)
