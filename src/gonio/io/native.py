"""The native ``*.brdf.h5`` format: gridded or scattered BRDF data in HDF5 (via h5py).

The complete byte-level description for readers without gonio is ``data-schema/FORMAT.md``; the
JSON Schema of the header (:func:`read_header`) is ``data-schema/table-metadata.schema.json``,
generated from :func:`table_metadata_schema`.

Summary of version 1
--------------------
Root attributes ``format`` = "gonio-brdf", ``format_version`` = 1, ``kind`` ("gridded" |
"scattered"), ``units`` = "1/sr", ``software``, ``created_utc``, ``metadata`` (a JSON object
with the provenance). Group ``/channels``. Gridded files: group ``/axes`` and datasets
``/values`` (n1, ..., nk, C), ``/mask`` (n1, ..., nk) uint8, optional ``/sigma`` and ``/counts``.
Scattered files: ``/wi`` and ``/wo`` (N, 3) float64, ``/values`` (N, C), optional ``/sigma``,
``/weights``. Values are float32 compressed losslessly (shuffle + deflate), chunked with one
channel per chunk and a few rows of the first axis per chunk; or, opt-in, log-quantized with a
guaranteed relative error bound (encoding "log-quantized-delta", see :func:`encode_lossy`).
Every array dataset carries a fletcher32 checksum per chunk (files written before it load too).
Reading is bounded (:mod:`gonio.io._hdf5_guard`): only this layout is accepted.
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from gonio import __version__
from gonio.io._common import PathLike, atomic_output, check_input_file, fail
from gonio.io._hdf5_guard import (
    ReadBudgetExceeded,
    check_attribute,
    check_global_heaps,
    check_group_datasets,
    open_bounded,
)
from gonio.io._sanity import check_axis_range, check_brdf_values, check_directions
from gonio.io.schemas import register_schema

FORMAT_NAME = "gonio-brdf"
FORMAT_VERSION = 1
SUFFIX = ".brdf.h5"
UNITS = "1/sr"
KINDS = ("gridded", "scattered")
PARAMETERIZATIONS = ("half_diff_iso", "half_diff_aniso")
INTERPOLATIONS = ("linear", "nearest")
WARPS = ("linear", "sqrt")
CHANNEL_KINDS = ("rgb", "spectral", "mono")
ENCODINGS = ("float32", "log-quantized-delta")
#: Recommended provenance keys in the ``metadata`` attribute (others are allowed).
PROVENANCE_FIELDS: dict[str, tuple[list[str], str]] = {
    "rig": (["object", "string"], "rig that measured the data: name, rig file and its hash"),
    "plan": (["object", "string"], "acquisition plan: name or the plan's parameters"),
    "calibration": (["object", "string"], "calibration used: white reference, camera response"),
    "software_version": (["string"], "version of the software that produced the values"),
    "created_utc": (["string"], "ISO 8601 UTC time the data were produced"),
    "source": (["object"], "for imported data: original format, file and description"),
    "operator": (["string"], "who ran the measurement"),
    "notes": (["string"], "free text"),
}
#: Target uncompressed bytes per chunk (a few rows of the first axis, one channel).
CHUNK_BYTES = 1 << 18
DEFAULT_GZIP_LEVEL = 4
#: Datasets up to this size are stored as one uncompressed chunk (with a fletcher32 checksum).
SMALL_BYTES = 1 << 14
#: In lossy mode, values below ``LOSSY_FLOOR_RATIO * max`` are stored as 0.
LOSSY_FLOOR_RATIO = 1e-7
_HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"


# --------------------------------------------------------------------------------------------
# lossy encoding
# --------------------------------------------------------------------------------------------
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
    from gonio.errors import ParameterError

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


def _lossy_stats(values: np.ndarray, decoded: np.ndarray, valid: np.ndarray, floor: float) -> dict:
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


# --------------------------------------------------------------------------------------------
# writing
# --------------------------------------------------------------------------------------------
def _jsonable(obj: Any) -> Any:
    """Turn metadata into plain JSON types (NumPy scalars and arrays included)."""
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return str(obj)
    if obj is None or isinstance(obj, bool | int | float | str):
        return obj
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    return str(obj)


def _chunks(shape: tuple[int, ...], itemsize: int, channel_last: bool) -> tuple[int, ...]:
    """Chunk shape: a few rows of axis 0, whole other axes, one channel (if ``channel_last``)."""
    inner = list(shape[1:])
    if channel_last:
        inner[-1] = 1
    row_bytes = max(1, int(np.prod(inner, dtype=np.int64)) * itemsize)
    rows = int(max(1, min(shape[0], CHUNK_BYTES // row_bytes)))
    return (rows, *inner)


def _dataset(h5: Any, name: str, data: np.ndarray, channel_last: bool, level: int) -> Any:
    data = np.ascontiguousarray(data)
    if data.ndim == 0 or data.size == 0:
        return h5.create_dataset(name, data=data)  # HDF5 cannot chunk these
    if data.nbytes <= SMALL_BYTES:
        # one uncompressed chunk: compression costs more than it saves on small arrays, but the
        # fletcher32 checksum still catches a flipped bit
        return h5.create_dataset(name, data=data, chunks=data.shape, fletcher32=True)
    return h5.create_dataset(
        name,
        data=data,
        chunks=_chunks(data.shape, data.dtype.itemsize, channel_last),
        shuffle=True,
        compression="gzip",
        compression_opts=level,
        fletcher32=True,  # a checksum per chunk: payload corruption is an error, not data
    )


def _write_channels(h5: Any, channels: Any) -> None:
    g = h5.create_group("channels")
    g.attrs["kind"] = str(channels.kind)
    g.attrs["names"] = np.array([str(n) for n in channels.names], dtype=object)
    g.attrs["primaries"] = str(channels.primaries or "")
    g.attrs["white_point"] = str(channels.white_point or "")
    if channels.wavelengths_nm is not None:
        g.create_dataset("wavelengths_nm", data=np.asarray(channels.wavelengths_nm, np.float64))


def _common_attrs(h5: Any, kind: str, meta: dict) -> None:
    h5.attrs["format"] = FORMAT_NAME
    h5.attrs["format_version"] = np.int64(FORMAT_VERSION)
    h5.attrs["kind"] = kind
    h5.attrs["units"] = UNITS
    h5.attrs["software"] = f"gonio {__version__}"
    h5.attrs["created_utc"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    h5.attrs["metadata"] = json.dumps(_jsonable(meta or {}), sort_keys=True)


def _check_finite(path: PathLike, name: str, arr: np.ndarray, valid: np.ndarray | None) -> None:
    from gonio.errors import ParameterError

    bad = ~np.isfinite(arr)
    if valid is not None:
        bad &= np.broadcast_to(
            valid.reshape(valid.shape + (1,) * (arr.ndim - valid.ndim)), arr.shape
        )
    if np.any(bad):
        raise ParameterError(
            f"{os.fspath(path)}: {int(bad.sum())} non-finite {name} at valid cells"
        )


def write_native(
    obj: Any,
    path: PathLike,
    *,
    lossy: float | None = None,
    level: int = DEFAULT_GZIP_LEVEL,
    _hook: Any = None,
    groups: dict[str, Any] | None = None,
) -> dict:
    """Write a :class:`TabulatedBRDF` or :class:`MeasuredSamples` as ``*.brdf.h5``, atomically.

    Parameters
    ----------
    obj : TabulatedBRDF or MeasuredSamples
    path : path-like
        Destination; written through a temporary file in the same folder and renamed.
    lossy : float, optional
        Guaranteed relative error of stored values (e.g. 0.005 for 0.5 %); gridded tables only.
        Default: lossless float32.
    level : int
        Deflate level 0..9.
    _hook : callable(stage), optional
        Test hook called with "attrs" and "values" while the file is being written (the tests
        raise from it to prove that a crash leaves no file behind).
    groups : dict, optional
        More tables stored in the same file, each in a group ``/<name>`` laid out exactly like a
        file root (attributes, ``channels``, ``values``...), e.g. a run's scattered samples at the
        root and the gridded table resampled from them in ``/gridded``. Read them with
        ``read_native(path, group=name)``; readers that ignore groups see the root object.

    Returns
    -------
    dict
        ``{"encoding": ..., "achieved": {...}}`` for lossy writes (empty dict otherwise).
    """
    import h5py

    from gonio.errors import ParameterError

    gridded = hasattr(obj, "axes")
    if not gridded and not hasattr(obj, "wi"):
        raise ParameterError(f"cannot save a {type(obj).__name__} as {SUFFIX}")
    if lossy is not None and not gridded:
        raise ParameterError("lossy encoding applies to gridded tables only")
    report: dict = {}
    with (
        atomic_output(path, suffix=".h5.tmp") as tmp,
        h5py.File(tmp, "w", libver=("v108", "v108")) as h5,
    ):
        meta = dict(getattr(obj, "meta", None) or {})
        _common_attrs(h5, "gridded" if gridded else "scattered", meta)
        _write_channels(h5, obj.channels)
        if _hook is not None:
            _hook("attrs")
        if gridded:
            report = _write_gridded(h5, obj, path, lossy, level, _hook)
        else:
            _write_scattered(h5, obj, path, level)
        for name, extra in (groups or {}).items():
            if name in h5 or not name.isidentifier():
                raise ParameterError(f"bad or reserved group name {name!r}")
            g = h5.create_group(name)
            _common_attrs(g, "gridded" if hasattr(extra, "axes") else "scattered", extra.meta)
            _write_channels(g, extra.channels)
            if hasattr(extra, "axes"):
                _write_gridded(g, extra, path, None, level, None)
            else:
                _write_scattered(g, extra, path, level)
    return report


def _write_gridded(
    h5: Any, t: Any, path: PathLike, lossy: float | None, level: int, hook: Any
) -> dict:
    values = np.asarray(t.values, dtype=np.float32)
    grid_shape = tuple(a.size for a in t.axes)
    mask = np.ones(grid_shape, bool) if t.mask is None else np.asarray(t.mask, dtype=bool)
    _check_finite(path, "values", values, mask)
    h5.attrs["parameterization"] = str(t.parameterization)
    h5.attrs["interpolation"] = str(getattr(t, "interpolation", "linear"))
    axes = h5.create_group("axes")
    axes.attrs["order"] = np.array([a.name for a in t.axes], dtype=object)
    for i, a in enumerate(t.axes):
        g = axes.create_group(a.name)
        g.attrs["index"] = np.int64(i)
        g.attrs["size"] = np.int64(a.size)
        g.attrs["lo"] = float(a.lo)
        g.attrs["hi"] = float(a.hi)
        g.attrs["warp"] = str(a.warp)
        g.attrs["periodic"] = np.int8(bool(a.periodic))
        g.attrs["node_offset"] = float(a.node_offset)
        g.create_dataset("nodes", data=np.asarray(a.nodes(), dtype=np.float64))
    clean = np.where(mask[..., None] & np.isfinite(values), values, np.float32(0))
    report: dict = {}
    if lossy is None:
        ds = _dataset(h5, "values", clean, True, level)
        ds.attrs["encoding"] = "float32"
    else:
        codes, enc = encode_lossy(clean, mask, lossy)
        decoded = decode_lossy(codes, enc)
        achieved = _lossy_stats(clean, decoded, mask, enc.floor)
        ds = _dataset(h5, "values", codes, True, max(level, 6))
        ds.attrs["encoding"] = "log-quantized-delta"
        for k in ("log_offset", "log_step", "floor", "bound_relative"):
            ds.attrs[k] = float(getattr(enc, k))
        ds.attrs["delta_axis"] = np.int64(enc.delta_axis)
        ds.attrs["requested_precision"] = float(lossy)
        for k, v in achieved.items():
            ds.attrs[f"achieved_{k}"] = v
        report = {"encoding": enc.__dict__ | {"requested_precision": lossy}, "achieved": achieved}
    ds.attrs["units"] = UNITS
    if hook is not None:
        hook("values")
    _dataset(h5, "mask", mask.astype(np.uint8), False, level)
    if t.sigma is not None:
        sigma = np.asarray(t.sigma, dtype=np.float32)
        ds = _dataset(h5, "sigma", np.where(mask[..., None], sigma, np.float32(0)), True, level)
        ds.attrs["units"] = UNITS
    if t.counts is not None:
        _dataset(h5, "counts", np.asarray(t.counts).astype(np.uint32), False, level)
    return report


def _write_scattered(h5: Any, s: Any, path: PathLike, level: int) -> None:
    values = np.asarray(s.values, dtype=np.float32)
    _check_finite(path, "values", values, None)
    _dataset(h5, "wi", np.asarray(s.wi, dtype=np.float64), False, level)
    _dataset(h5, "wo", np.asarray(s.wo, dtype=np.float64), False, level)
    ds = _dataset(h5, "values", values, True, level)
    ds.attrs["encoding"] = "float32"
    ds.attrs["units"] = UNITS
    if getattr(s, "sigma", None) is not None:
        ds = _dataset(h5, "sigma", np.asarray(s.sigma, dtype=np.float32), True, level)
        ds.attrs["units"] = UNITS
    if getattr(s, "weights", None) is not None:
        _dataset(h5, "weights", np.asarray(s.weights, dtype=np.float64), False, level)


# --------------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------------
def is_native(data_head: bytes) -> bool:
    """True if the bytes start with the HDF5 signature."""
    return data_head.startswith(_HDF5_MAGIC)


def _attr_str(obj: Any, name: str, path: PathLike) -> str:
    if name not in obj.attrs:
        raise fail(path, f"missing attribute {name!r} on {obj.name}")
    check_attribute(obj, name, path)
    v = obj.attrs[name]
    if isinstance(v, bytes):
        v = v.decode("utf-8")
    if isinstance(v, np.ndarray) and v.shape == ():
        v = v.item()
    if not isinstance(v, str):
        raise fail(path, f"attribute {name!r} on {obj.name} is not a string")
    return v


def _attr_num(obj: Any, name: str, path: PathLike, kind: type = float) -> Any:
    if name not in obj.attrs:
        raise fail(path, f"missing attribute {name!r} on {obj.name}")
    check_attribute(obj, name, path)
    v = np.asarray(obj.attrs[name])
    if v.shape != () or v.dtype.kind not in "iuf":
        raise fail(path, f"attribute {name!r} on {obj.name} is not a number")
    out = kind(v.item())
    if isinstance(out, float) and not math.isfinite(out):
        raise fail(path, f"attribute {name!r} on {obj.name} is not finite")
    return out


class _Guard:
    """Turn any exception raised while parsing an untrusted HDF5 file into a FormatError.

    h5py reports corrupt structures through many exception types (OSError, KeyError,
    RuntimeError, ValueError, ...); all of them mean the same thing to the caller.
    """

    def __init__(self, path: PathLike) -> None:
        self.path = path

    def __enter__(self) -> None:
        return None

    def __exit__(self, etype: Any, exc: BaseException | None, tb: Any) -> bool:
        from gonio.errors import GonioError

        if exc is None or isinstance(exc, GonioError) or not isinstance(exc, Exception):
            return False
        if isinstance(exc, ReadBudgetExceeded):
            raise fail(self.path, f"corrupt {FORMAT_NAME} file: HDF5 structures loop ({exc})")
        raise fail(self.path, f"corrupt {FORMAT_NAME} file ({etype.__name__}: {exc})") from None


def _open(path: PathLike) -> Any:
    with _Guard(path):
        return _open_unguarded(path)


def _open_unguarded(path: PathLike) -> Any:
    p = check_input_file(path)
    with open(p, "rb") as fh:
        head = fh.read(8)
    if not is_native(head):
        raise fail(p, "not an HDF5 file (wrong magic)")
    try:
        h5 = open_bounded(p)
    except ReadBudgetExceeded:
        raise
    except OSError as exc:
        raise fail(p, f"corrupt or truncated HDF5 file ({exc})") from None
    try:
        # the layout first: attributes live in global heaps, which must be checked before
        # libhdf5 decodes one (a corrupt one makes it loop forever), skipping raw data
        raw = check_group_datasets(h5, p, p.stat().st_size)
        check_global_heaps(p, raw)
        fmt = _attr_str(h5, "format", p) if "format" in h5.attrs else None
        if fmt != FORMAT_NAME:
            raise fail(p, f"HDF5 file is not a {FORMAT_NAME} table (format attribute {fmt!r})")
        version = _attr_num(h5, "format_version", p, int)
        if version != FORMAT_VERSION:
            raise fail(
                p, f"unsupported format_version {version} (this gonio reads {FORMAT_VERSION})"
            )
    except BaseException:
        h5.close()
        raise
    return h5


def _read_channels(h5: Any, path: PathLike) -> dict:
    if "channels" not in h5:
        raise fail(path, "missing group /channels")
    g = h5["channels"]
    kind = _attr_str(g, "kind", path)
    if kind not in CHANNEL_KINDS:
        raise fail(path, f"unknown channel kind {kind!r}")
    names = [
        n.decode() if isinstance(n, bytes) else str(n) for n in np.atleast_1d(g.attrs["names"])
    ]
    wl = np.asarray(g["wavelengths_nm"][()], dtype=np.float64) if "wavelengths_nm" in g else None
    if kind == "spectral" and (wl is None or len(wl) != len(names)):
        raise fail(path, "spectral channels need one wavelength per channel")
    return {
        "kind": kind,
        "names": names,
        "primaries": _attr_str(g, "primaries", path) or None,
        "white_point": _attr_str(g, "white_point", path) or None,
        "wavelengths_nm": None if wl is None else wl.tolist(),
    }


def _read_axes(h5: Any, path: PathLike) -> list[dict]:
    if "axes" not in h5:
        raise fail(path, "missing group /axes")
    g = h5["axes"]
    order = [
        n.decode() if isinstance(n, bytes) else str(n) for n in np.atleast_1d(g.attrs["order"])
    ]
    axes = []
    for i, name in enumerate(order):
        if name not in g:
            raise fail(path, f"missing axis group /axes/{name}")
        a = g[name]
        ax = {
            "name": name,
            "size": _attr_num(a, "size", path, int),
            "lo": _attr_num(a, "lo", path),
            "hi": _attr_num(a, "hi", path),
            "warp": _attr_str(a, "warp", path),
            "periodic": bool(_attr_num(a, "periodic", path, int)),
            "node_offset": _attr_num(a, "node_offset", path),
        }
        if _attr_num(a, "index", path, int) != i:
            raise fail(path, f"axis {name!r} index does not match /axes order")
        if not (1 <= ax["size"] <= 1 << 20):
            raise fail(path, f"axis {name!r}: impossible size {ax['size']}")
        if ax["warp"] not in WARPS:
            raise fail(path, f"axis {name!r}: unknown warp {ax['warp']!r}")
        if not ax["hi"] > ax["lo"]:
            raise fail(path, f"axis {name!r}: empty range [{ax['lo']}, {ax['hi']}]")
        check_axis_range(path, name, ax["lo"], ax["hi"])
        if not 0.0 <= ax["node_offset"] < 1.0:
            raise fail(path, f"axis {name!r}: node_offset {ax['node_offset']} outside [0, 1)")
        axes.append(ax)
    return axes


def _encoding(ds: Any, path: PathLike) -> tuple[str, LossyEncoding | None]:
    enc = _attr_str(ds, "encoding", path)
    if enc not in ENCODINGS:
        raise fail(path, f"unknown value encoding {enc!r}")
    if enc == "float32":
        if ds.dtype != np.float32:
            raise fail(path, f"values have dtype {ds.dtype}, encoding says float32")
        return enc, None
    if ds.dtype not in (np.uint16, np.uint32):
        raise fail(path, f"lossy values have dtype {ds.dtype}, expected uint16/uint32")
    lossy = LossyEncoding(
        log_offset=_attr_num(ds, "log_offset", path),
        log_step=_attr_num(ds, "log_step", path),
        floor=_attr_num(ds, "floor", path),
        delta_axis=_attr_num(ds, "delta_axis", path, int),
        bound_relative=_attr_num(ds, "bound_relative", path),
    )
    if not (lossy.log_step > 0 and 0 <= lossy.delta_axis < ds.ndim - 1):
        raise fail(path, "invalid lossy encoding parameters")
    return enc, lossy


def read_header(path: PathLike) -> dict:
    """The file's header as a JSON-compatible dict (validates against table-metadata schema)."""
    h5 = _open(path)
    try:
        with _Guard(path):
            return _header(h5, path)
    finally:
        h5.close()


def _header(h5: Any, path: PathLike) -> dict:
    kind = _attr_str(h5, "kind", path)
    if kind not in KINDS:
        raise fail(path, f"unknown kind {kind!r}")
    units = _attr_str(h5, "units", path)
    if units != UNITS:
        raise fail(path, f"unsupported units {units!r} (expected {UNITS})")
    try:
        meta = json.loads(_attr_str(h5, "metadata", path))
    except json.JSONDecodeError as exc:
        raise fail(path, f"metadata attribute is not valid JSON ({exc.msg})") from None
    if not isinstance(meta, dict):
        raise fail(path, "metadata attribute is not a JSON object")
    if "values" not in h5:
        raise fail(path, "missing dataset /values")
    ds = h5["values"]
    enc, lossy = _encoding(ds, path)
    header: dict = {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "kind": kind,
        "units": units,
        "software": _attr_str(h5, "software", path),
        "created_utc": _attr_str(h5, "created_utc", path),
        "channels": _read_channels(h5, path),
    }
    n_ch = len(header["channels"]["names"])
    if kind == "gridded":
        axes = _read_axes(h5, path)
        param = _attr_str(h5, "parameterization", path)
        if param not in PARAMETERIZATIONS:
            raise fail(path, f"unknown parameterization {param!r}")
        interp = _attr_str(h5, "interpolation", path)
        if interp not in INTERPOLATIONS:
            raise fail(path, f"unknown interpolation {interp!r}")
        grid = tuple(a["size"] for a in axes)
        if ds.shape != (*grid, n_ch):
            raise fail(path, f"/values has shape {ds.shape}, axes and channels say {(*grid, n_ch)}")
        for name in ("mask", "counts"):
            if name in h5 and h5[name].shape != grid:
                raise fail(path, f"/{name} has shape {h5[name].shape}, expected {grid}")
        if "mask" not in h5:
            raise fail(path, "missing dataset /mask")
        header["grid"] = {"parameterization": param, "interpolation": interp, "axes": axes}
    else:
        n = ds.shape[0] if ds.ndim == 2 else -1
        if ds.ndim != 2 or ds.shape[1] != n_ch:
            raise fail(path, f"/values has shape {ds.shape}, expected (N, {n_ch})")
        for name in ("wi", "wo"):
            if name not in h5 or h5[name].shape != (n, 3):
                raise fail(path, f"/{name} missing or not of shape ({n}, 3)")
        if "weights" in h5 and h5["weights"].shape != (n,):
            raise fail(path, f"/weights has shape {h5['weights'].shape}, expected ({n},)")
        header["samples"] = {"count": int(n)}
    if "sigma" in h5 and h5["sigma"].shape != ds.shape:
        raise fail(path, f"/sigma has shape {h5['sigma'].shape}, expected {ds.shape}")
    header["datasets"] = sorted(k for k in h5 if isinstance(h5[k], type(ds)))
    encoding: dict = {"values": enc}
    if lossy is not None:
        encoding.update({k: getattr(lossy, k) for k in lossy.__dataclass_fields__})
        for key in ("median_relative", "p99_relative", "max_relative"):
            if f"achieved_{key}" in ds.attrs:
                encoding.setdefault("achieved", {})[key] = _attr_num(ds, f"achieved_{key}", path)
        if "requested_precision" in ds.attrs:
            encoding["requested_precision"] = _attr_num(ds, "requested_precision", path)
    header["encoding"] = encoding
    header["metadata"] = meta
    return header


def _values(ds: Any, lossy: LossyEncoding | None, sel: tuple = ()) -> np.ndarray:
    raw = ds[sel] if sel else ds[()]
    if lossy is None:
        return np.asarray(raw, dtype=np.float32)
    return decode_lossy(raw, lossy)


def read_values(
    path: PathLike,
    *,
    rows: slice | None = None,
    channel: int | None = None,
) -> np.ndarray:
    """Partial read of a gridded file's values: rows of the first axis and/or one channel.

    Only the chunks holding the selection are read and decompressed (chunks span a few rows of
    the first axis and one channel). Returns float32 of shape ``(rows, n2, ..., nk, C')``.
    """
    h5 = _open(path)
    try:
        with _Guard(path):
            header = _header(h5, path)
            if header["kind"] != "gridded":
                raise fail(path, "partial reads by rows apply to gridded files")
            ds = h5["values"]
            _, lossy = _encoding(ds, path)
            sel = (rows if rows is not None else slice(None),) + (slice(None),) * (ds.ndim - 2)
            sel += (slice(None) if channel is None else slice(channel, channel + 1),)
            return _values(ds, lossy, sel)
    finally:
        h5.close()


def read_native(path: PathLike, group: str | None = None) -> Any:
    """Read a ``*.brdf.h5`` file as :class:`TabulatedBRDF` (gridded) or :class:`MeasuredSamples`.

    ``group`` reads a table stored in a group of the file (see ``write_native(groups=...)``)
    instead of the root one.
    """
    from gonio.errors import GonioError

    h5 = _open(path)
    try:
        with _Guard(path):
            root = h5
            if group is not None:
                if group not in h5 or not isinstance(h5[group], type(h5["channels"])):
                    raise fail(path, f"no table group /{group}")
                root = h5[group]
            header = _header(root, path)
            arrays = _read_arrays(root, header, path)
    finally:
        h5.close()
    try:
        return _build(header, arrays)
    except GonioError as exc:
        raise fail(path, str(exc)) from None


def _read_arrays(h5: Any, header: dict, path: PathLike) -> dict:
    ds = h5["values"]
    _, lossy = _encoding(ds, path)
    out: dict = {"values": _values(ds, lossy)}
    for name in ("sigma", "weights", "wi", "wo"):
        if name in h5:
            out[name] = np.asarray(h5[name][()])
    if header["kind"] == "gridded":
        out["mask"] = np.asarray(h5["mask"][()]) != 0
        if "counts" in h5:
            out["counts"] = np.asarray(h5["counts"][()])
        valid = np.broadcast_to(out["mask"][..., None], out["values"].shape)
    else:
        valid = np.ones(out["values"].shape, dtype=bool)
    # a BRDF in 1/sr (and its standard deviation) is finite, >= 0 and below MAX_BRDF
    for name in ("values", "sigma"):
        if name in out:
            check_brdf_values(path, f"/{name}", out[name], valid[..., 0])
    for name in ("wi", "wo"):
        if name in out:
            check_directions(path, f"/{name}", out[name])
    if "weights" in out:
        w = out["weights"]
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise fail(path, "/weights: NaN/Inf or negative weights")
    return out


def _build(header: dict, arrays: dict) -> Any:
    from gonio.brdf.tabulated import Axis, Channels, MeasuredSamples, TabulatedBRDF

    ch = header["channels"]
    channels = Channels(
        kind=ch["kind"],
        names=tuple(ch["names"]),
        wavelengths_nm=None if ch["wavelengths_nm"] is None else np.asarray(ch["wavelengths_nm"]),
        primaries=ch["primaries"],
        white_point=ch["white_point"],
    )
    meta = dict(header["metadata"])
    if header["kind"] == "gridded":
        g = header["grid"]
        axes = tuple(
            Axis(a["name"], a["size"], a["lo"], a["hi"], a["warp"], a["periodic"], a["node_offset"])
            for a in g["axes"]
        )
        return TabulatedBRDF(
            values=arrays["values"],
            axes=axes,
            parameterization=g["parameterization"],
            mask=arrays["mask"],
            sigma=arrays.get("sigma"),
            counts=arrays.get("counts"),
            channels=channels,
            meta=meta,
            interpolation=g["interpolation"],
        )
    return MeasuredSamples(
        wi=arrays["wi"],
        wo=arrays["wo"],
        values=arrays["values"],
        sigma=arrays.get("sigma"),
        channels=channels,
        weights=arrays.get("weights"),
        meta=meta,
    )


# --------------------------------------------------------------------------------------------
# schema
# --------------------------------------------------------------------------------------------
@register_schema("table-metadata.schema.json")
def table_metadata_schema() -> dict:
    """JSON Schema of :func:`read_header`'s result (the header of a ``*.brdf.h5`` file)."""
    num = {"type": "number"}
    axis = {
        "type": "object",
        "description": "A grid axis. Node i sits at x_i = (i + node_offset) / size; angle = "
        "lo + (hi - lo) * x (warp 'linear') or lo + (hi - lo) * x**2 (warp 'sqrt'), radians.",
        "required": ["name", "size", "lo", "hi", "warp", "periodic", "node_offset"],
        "additionalProperties": False,
        "properties": {
            "name": {"type": "string", "description": "theta_h, phi_h, theta_d or phi_d"},
            "size": {"type": "integer", "minimum": 1},
            "lo": {**num, "description": "radians"},
            "hi": {**num, "description": "radians"},
            "warp": {"enum": list(WARPS)},
            "periodic": {"type": "boolean"},
            "node_offset": num,
        },
    }
    provenance = {
        name: {"type": types if len(types) > 1 else types[0], "description": doc}
        for name, (types, doc) in PROVENANCE_FIELDS.items()
    }
    return {
        "$id": "https://gonio.invalid/schemas/table-metadata.schema.json",
        "title": "gonio tabulated BRDF header",
        "description": f"Header of a {SUFFIX} file (format {FORMAT_NAME} version "
        f"{FORMAT_VERSION}) as returned by gonio.io.native.read_header and 'gonio info --json'.",
        "type": "object",
        "required": [
            "format",
            "format_version",
            "kind",
            "units",
            "software",
            "created_utc",
            "channels",
            "datasets",
            "encoding",
            "metadata",
        ],
        "properties": {
            "format": {"const": FORMAT_NAME},
            "format_version": {"const": FORMAT_VERSION},
            "kind": {"enum": list(KINDS)},
            "units": {"const": UNITS},
            "software": {"type": "string"},
            "created_utc": {"type": "string", "description": "ISO 8601, UTC"},
            "channels": {
                "type": "object",
                "required": ["kind", "names", "primaries", "white_point", "wavelengths_nm"],
                "additionalProperties": False,
                "properties": {
                    "kind": {"enum": list(CHANNEL_KINDS)},
                    "names": {"type": "array", "items": {"type": "string"}, "minItems": 1},
                    "primaries": {"type": ["string", "null"], "description": "e.g. sRGB"},
                    "white_point": {"type": ["string", "null"], "description": "e.g. D65"},
                    "wavelengths_nm": {"type": ["array", "null"], "items": num},
                },
            },
            "grid": {
                "type": "object",
                "required": ["parameterization", "interpolation", "axes"],
                "additionalProperties": False,
                "properties": {
                    "parameterization": {"enum": list(PARAMETERIZATIONS)},
                    "interpolation": {"enum": list(INTERPOLATIONS)},
                    "axes": {"type": "array", "items": axis, "minItems": 1},
                },
            },
            "samples": {
                "type": "object",
                "required": ["count"],
                "properties": {"count": {"type": "integer", "minimum": 0}},
            },
            "datasets": {"type": "array", "items": {"type": "string"}},
            "encoding": {
                "type": "object",
                "required": ["values"],
                "properties": {
                    "values": {"enum": list(ENCODINGS)},
                    "log_offset": num,
                    "log_step": {**num, "exclusiveMinimum": 0},
                    "floor": num,
                    "delta_axis": {"type": "integer", "minimum": 0},
                    "bound_relative": {**num, "description": "guaranteed max relative error"},
                    "requested_precision": num,
                    "achieved": {
                        "type": "object",
                        "properties": {
                            "median_relative": num,
                            "p99_relative": num,
                            "max_relative": num,
                        },
                    },
                },
            },
            "metadata": {
                "type": "object",
                "description": "Provenance. Recommended keys are listed; others are allowed.",
                "properties": provenance,
                "additionalProperties": True,
            },
        },
        "oneOf": [
            {"properties": {"kind": {"const": "gridded"}}, "required": ["grid"]},
            {"properties": {"kind": {"const": "scattered"}}, "required": ["samples"]},
        ],
    }
