"""The native ``*.brdf.h5`` format: gridded or scattered BRDF data in HDF5 (via h5py).

The complete byte-level description for readers without gonio is ``data-schema/FORMAT.md``; the
JSON Schema of the header (:func:`read_header`) is ``data-schema/table-metadata.schema.json``,
generated from :func:`gonio.io.native_schema.table_metadata_schema`.

Summary of version 1
--------------------
Root attributes ``format`` = "gonio-brdf", ``format_version`` = 1, ``kind`` ("gridded" |
"scattered"), ``units`` = "1/sr", ``software``, ``created_utc``, ``metadata`` (a JSON object
with the provenance). Group ``/channels``. Gridded files: group ``/axes`` and datasets
``/values`` (n1, ..., nk, C), ``/mask`` (n1, ..., nk) uint8, optional ``/sigma`` and ``/counts``;
``/mask`` attribute ``invalid_values`` says what ``/values`` holds at invalid nodes: ``"zero"``
(also when absent) or ``"extrapolated"`` (a filled table's extrapolation, kept as written).
Scattered files: ``/wi`` and ``/wo`` (N, 3) float64, ``/values`` (N, C), optional ``/sigma``,
``/weights``. Values are float32 compressed losslessly (shuffle + deflate), chunked with one
channel per chunk and a few rows of the first axis per chunk; or, opt-in, log-quantized with a
guaranteed relative error bound (encoding "log-quantized-delta", see :func:`encode_lossy`).
Every array dataset carries a fletcher32 checksum per chunk (files written before it load too).
Reading is bounded (:mod:`gonio.io._hdf5_guard`): only this layout is accepted.
"""

from __future__ import annotations

import io
import json
import math
import os
import time
from typing import Any

import numpy as np

from gonio import __version__
from gonio.errors import GonioError, ParameterError
from gonio.io._common import PathLike, atomic_output, check_input_file, fail
from gonio.io._hdf5_guard import (
    ReadBudgetExceeded,
    check_attribute,
    check_global_heaps,
    check_group_datasets,
    open_bounded,
)
from gonio.io._sanity import check_axis_range, check_channel_count, check_table_arrays
from gonio.io.lossy import LossyEncoding, decode_lossy, encode_lossy, lossy_stats
from gonio.io.strict_json import dumps_json

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
#: What ``/values`` holds at invalid nodes (``/mask`` attribute ``invalid_values``).
INVALID_VALUES = ("zero", "extrapolated")
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
_HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"


# --------------------------------------------------------------------------------------------
# writing
# --------------------------------------------------------------------------------------------
def _jsonable(obj: Any) -> Any:
    """Turn metadata into plain JSON types (NumPy scalars and arrays included; a NaN or infinite
    number stays a float, which :func:`~gonio.io.strict_json.dumps_json` writes as null)."""
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
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


def _write_channels(h5: Any, channels: Any, path: PathLike) -> None:
    check_channel_count(path, len(channels.names))  # the reader's bound
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
    h5.attrs["metadata"] = dumps_json(_jsonable(meta or {}), sort_keys=True)


def _check_finite(path: PathLike, name: str, arr: np.ndarray, valid: np.ndarray | None) -> None:
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

    from gonio.brdf.measured import MeasuredSamples
    from gonio.brdf.tabulated import TabulatedBRDF

    gridded = isinstance(obj, TabulatedBRDF)
    if not gridded and not isinstance(obj, MeasuredSamples):
        raise ParameterError(f"cannot save a {type(obj).__name__} as {SUFFIX}")
    if lossy is not None and not gridded:
        raise ParameterError("lossy encoding applies to gridded tables only")
    report: dict = {}
    # built in memory: HDF5 never meets a full disk (its clean-up crashes after a failed close)
    image = io.BytesIO()
    with h5py.File(image, "w", libver=("v108", "v108")) as h5:
        meta = dict(obj.meta or {})
        _common_attrs(h5, "gridded" if gridded else "scattered", meta)
        _write_channels(h5, obj.channels, path)
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
            extra_gridded = isinstance(extra, TabulatedBRDF)
            _common_attrs(g, "gridded" if extra_gridded else "scattered", extra.meta)
            _write_channels(g, extra.channels, path)
            if extra_gridded:
                _write_gridded(g, extra, path, None, level, None)
            else:
                _write_scattered(g, extra, path, level)
    with atomic_output(path, suffix=".h5.tmp") as tmp:
        tmp.write_bytes(image.getbuffer())
    return report


def _write_gridded(
    h5: Any, t: Any, path: PathLike, lossy: float | None, level: int, hook: Any
) -> dict:
    values = np.asarray(t.values, dtype=np.float32)
    grid_shape = tuple(a.size for a in t.axes)
    mask = np.ones(grid_shape, bool) if t.mask is None else np.asarray(t.mask, dtype=bool)
    # a filled table's extrapolation at invalid nodes is data too (TabulatedBRDF.filled)
    filled = bool(getattr(t, "filled", False)) and not bool(mask.all())
    kept = np.ones_like(mask) if filled else mask
    _check_finite(path, "values", values, kept)
    h5.attrs["parameterization"] = str(t.parameterization)
    h5.attrs["interpolation"] = str(getattr(t, "interpolation", "linear"))
    axes = h5.create_group("axes")
    axes.attrs["order"] = np.array([a.name for a in t.axes], dtype=object)
    for i, a in enumerate(t.axes):
        check_axis_range(path, a.name, a.lo, a.hi)  # the reader's check of each axis
        g = axes.create_group(a.name)
        g.attrs["index"] = np.int64(i)
        g.attrs["size"] = np.int64(a.size)
        g.attrs["lo"] = float(a.lo)
        g.attrs["hi"] = float(a.hi)
        g.attrs["warp"] = str(a.warp)
        g.attrs["periodic"] = np.int8(bool(a.periodic))
        g.attrs["node_offset"] = float(a.node_offset)
        g.create_dataset("nodes", data=np.asarray(a.nodes(), dtype=np.float64))
    clean = np.where(kept[..., None] & np.isfinite(values), values, np.float32(0))
    sigma = None
    if t.sigma is not None:
        sigma = np.where(mask[..., None], np.asarray(t.sigma, dtype=np.float32), np.float32(0))
    report: dict = {}
    if lossy is None:
        check_table_arrays(path, {"values": clean, "mask": mask, "sigma": sigma}, filled)
        ds = _dataset(h5, "values", clean, True, level)
        ds.attrs["encoding"] = "float32"
    else:
        codes, enc = encode_lossy(clean, kept, lossy)
        decoded = decode_lossy(codes, enc)
        # what the reader will decode is what must pass its checks
        check_table_arrays(path, {"values": decoded, "mask": mask, "sigma": sigma}, filled)
        achieved = lossy_stats(clean, decoded, mask, enc.floor)
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
    ds = _dataset(h5, "mask", mask.astype(np.uint8), False, level)
    ds.attrs["invalid_values"] = INVALID_VALUES[1] if filled else INVALID_VALUES[0]
    if sigma is not None:
        ds = _dataset(h5, "sigma", sigma, True, level)
        ds.attrs["units"] = UNITS
    if t.counts is not None:
        _dataset(h5, "counts", np.asarray(t.counts).astype(np.uint32), False, level)
    return report


def _write_scattered(h5: Any, s: Any, path: PathLike, level: int) -> None:
    values = np.asarray(s.values, dtype=np.float32)
    _check_finite(path, "values", values, None)
    arrays = {
        "values": values,
        "wi": np.asarray(s.wi, np.float64),
        "wo": np.asarray(s.wo, np.float64),
    }
    for name, arr, dtype in (("sigma", s.sigma, np.float32), ("weights", s.weights, np.float64)):
        arrays[name] = None if arr is None else np.asarray(arr, dtype)
    check_table_arrays(path, arrays)
    _dataset(h5, "wi", arrays["wi"], False, level)
    _dataset(h5, "wo", arrays["wo"], False, level)
    ds = _dataset(h5, "values", values, True, level)
    ds.attrs["encoding"] = "float32"
    ds.attrs["units"] = UNITS
    if arrays["sigma"] is not None:
        ds = _dataset(h5, "sigma", arrays["sigma"], True, level)
        ds.attrs["units"] = UNITS
    if arrays["weights"] is not None:
        _dataset(h5, "weights", arrays["weights"], False, level)


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
    check_channel_count(path, len(names))
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
        invalid = INVALID_VALUES[0]  # files written before the attribute hold zeros there
        if "invalid_values" in h5["mask"].attrs:
            invalid = _attr_str(h5["mask"], "invalid_values", path)
            if invalid not in INVALID_VALUES:
                raise fail(path, f"unknown /mask invalid_values {invalid!r}")
        header["grid"] = {
            "parameterization": param,
            "interpolation": interp,
            "axes": axes,
            "invalid_values": invalid,
        }
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
    check_table_arrays(path, out, header["kind"] == "gridded" and
                 header["grid"]["invalid_values"] == "extrapolated")  # fmt: skip
    return out


def _build(header: dict, arrays: dict) -> Any:
    from gonio.brdf.measured import MeasuredSamples
    from gonio.brdf.tabulated import Axis, Channels, TabulatedBRDF

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
            filled=g["invalid_values"] == "extrapolated",
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
