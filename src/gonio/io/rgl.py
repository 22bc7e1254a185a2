"""RGL-EPFL ``tensor_file`` measured BSDFs (Dupuy & Jakob 2018): the container and its fields.

Container (little-endian): 12 bytes ``tensor_file\\0``; uint8 major (1) and minor version; uint32
field count; per field: uint16 name length, name, uint16 ndim, uint8 dtype code, uint64 absolute
data offset, uint64 shape[ndim]; data in C order.

:func:`parse_tensor_file` and :func:`tensor_file_bytes` read and write the container;
:meth:`RGLFile.from_fields` checks that its fields form a BSDF (names, shapes, dtypes, finite and
non-negative where the format needs it) and reads its header values. Every reader and writer of
RGL files goes through that one check. The file is evaluated and sampled by
:class:`gonio.io.rgl_measured.RGLMeasured` (what :func:`gonio.io.load` returns), through the
continuous 2-D warps of :mod:`gonio.brdf.sampling.marginal2d`.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gonio._bounded import MAX_BRDF, MAX_CHANNELS
from gonio.io._common import PathLike, fail, read_bytes

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
#: Default horizon cut of :meth:`gonio.io.rgl_measured.RGLMeasured.to_table`: cos(89 degrees).
HORIZON_MIN_COS = math.cos(math.radians(89.0))
_MAX_NDIM = 16
#: The colour table may dip below 0 (colours outside the sRGB gamut, noise in dark cells: the
#: database's files reach -1.4 % of their peak); below this fraction of its largest magnitude
#: it cannot come from a measurement and the file is refused.
COLOUR_NEGATIVE_TOLERANCE = 0.1
#: Most wavelengths a spectral file may hold (:data:`gonio._bounded.MAX_CHANNELS`; the
#: database's spectral files hold a few dozen); checked before anything is evaluated or
#: tabulated, whose memory grows with the count.
MAX_WAVELENGTHS = MAX_CHANNELS
#: Smallest step between consecutive ``theta_i`` or ``phi_i`` values, radians (0.006 degrees:
#: finer than any goniophotometer positions; a scaled axis collapses below it).
MIN_ANGLE_STEP = 1e-4
#: Slack on the angle domains (float32 rounds pi / 2 up by 4e-8).
_ANGLE_SLACK = 1e-6
#: Largest relative distance of ``2 pi / (phi_i span)`` from its symmetry fold (an integer).
_FOLD_TOL = 0.01
#: Largest symmetry fold of an anisotropic file (a phi_i span of one degree).
MAX_REDUCTION = 360


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


@dataclass
class RGLFile:
    """The checked fields of an RGL-EPFL BSDF tensor file and the values its header implies.

    Attributes
    ----------
    fields : dict of str to ndarray
        The raw container fields.
    path : str
        Where the fields came from (for messages and provenance).
    isotropic : bool
        True when ``phi_i`` holds at most two values.
    jacobian : bool
        The file's ``jacobian`` flag: values are scaled by ``ndf / (4 sigma)``.
    reduction : int
        Symmetry fold of anisotropic files (``round(2 pi / phi_i range)``; 0 when isotropic).
    spectral : bool
        True for ``spectra`` + ``wavelengths`` files, False for ``rgb`` files.
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

    @classmethod
    def from_fields(cls, fields: dict[str, np.ndarray], path: PathLike = "<memory>") -> RGLFile:
        """Check the fields of a BSDF tensor file and read its header values.

        Raises
        ------
        FormatError
            A missing field, a wrong shape or dtype, non-finite or impossible values (one line
            naming ``path`` and the field).
        """

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
        if spectral and len(wavelengths) > MAX_WAVELENGTHS:
            raise fail(
                path,
                f"field 'wavelengths' holds {len(wavelengths)} wavelengths, more than the "
                f"{MAX_WAVELENGTHS} a spectral RGL file may have",
            )
        _check_angles(path, theta_i, phi_i)
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
        if bool(jac[0]):
            _check_jacobian_bound(path, colour_name, colour, ndf, sigma)
        isotropic = np_ <= 2
        reduction = 0
        if not isotropic:
            reduction = round(2 * math.pi / float(phi_i[-1] - phi_i[0]))
        return cls(
            fields=fields,
            path=str(path),
            description=bytes(description).decode("utf-8", errors="replace"),
            isotropic=isotropic,
            jacobian=bool(jac[0]),
            reduction=reduction,
            spectral=spectral,
            wavelengths=wavelengths,
        )

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


def _check_angles(path: PathLike, theta_i: np.ndarray, phi_i: np.ndarray) -> None:
    """``theta_i`` in [0, pi/2], ``phi_i`` in [-pi, 2 pi], both with steps of at least
    :data:`MIN_ANGLE_STEP`; an anisotropic ``phi_i`` spans ``2 pi / n`` for an integer fold
    ``n <= MAX_REDUCTION``."""
    for name, arr, lo, hi in (
        ("theta_i", theta_i, 0.0, math.pi / 2),
        ("phi_i", phi_i, -math.pi, 2 * math.pi),
    ):
        a = arr.astype(np.float64)
        if float(a.min()) < lo - _ANGLE_SLACK or float(a.max()) > hi + _ANGLE_SLACK:
            raise fail(
                path,
                f"field {name!r} spans [{float(a.min()):.6g}, {float(a.max()):.6g}] rad, "
                f"outside [{lo:.6g}, {hi:.6g}]",
            )
        if len(a) > 1 and float(np.min(np.diff(a))) < MIN_ANGLE_STEP:
            raise fail(
                path,
                f"field {name!r} values are not increasing by at least {MIN_ANGLE_STEP:g} rad "
                f"(smallest step {float(np.min(np.diff(a))):.3g})",
            )
    if len(phi_i) > 2:
        fold = 2 * math.pi / (float(phi_i[-1]) - float(phi_i[0]))
        n = round(fold)
        if not 1 <= n <= MAX_REDUCTION or abs(fold - n) > _FOLD_TOL * n:
            raise fail(
                path,
                f"field 'phi_i' spans 2 pi / {fold:.4g}: an anisotropic file's azimuths span "
                f"2 pi / n for a whole symmetry fold n <= {MAX_REDUCTION}",
            )


def _check_jacobian_bound(
    path: PathLike, colour_name: str, colour: np.ndarray, ndf: np.ndarray, sigma: np.ndarray
) -> None:
    """With the Jacobian the file's value is ``colour * ndf / (4 sigma)`` at interpolated
    points; its bound ``max|colour| max(ndf) / (4 min(sigma))`` must stay below ``MAX_BRDF``."""
    top = (
        float(np.max(np.abs(colour)))
        * float(np.max(ndf))
        / (4.0 * float(np.min(sigma.astype(np.float64))))
    )
    if not top <= MAX_BRDF:
        raise fail(
            path,
            f"fields 'ndf' and 'sigma' scale {colour_name!r} up to {top:.3g} (colour x ndf / "
            f"(4 sigma)), beyond any reflectance ({MAX_BRDF:g} 1/sr)",
        )


def read_rgl(path: PathLike) -> RGLFile:
    """Read and check an RGL ``.bsdf`` tensor file (:func:`gonio.io.rgl_measured.load_rgl`
    evaluates it)."""
    return RGLFile.from_fields(parse_tensor_file(read_bytes(path), path), path)
