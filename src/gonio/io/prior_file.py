"""The material-prior file (``*.prior.h5``): writer, reader, and the JSON Schema of its metadata.

A prior (:mod:`gonio.prior`) is a mean and a low-rank basis of materials in a mapped space over
a half/diff grid. This module only stores and checks its arrays; what they mean is
:mod:`gonio.prior`'s business. Layout (HDF5, every dataset float32 unless said):

``/`` attributes
    ``format`` = ``"gonio-prior"``, ``format_version`` = 1 (int64), ``metadata``: strict JSON
    (no NaN/Infinity), validated against ``data-schema/prior-metadata.schema.json``.
``/mask``
    ``(n_θh, n_θd, n_φd)`` uint8, 1 for the valid cells; V of them, in C order.
``/mean``
    ``(V, C)`` the mean material in the mapped space.
``/basis``
    ``(V, C, K)``: column ``k`` is basis vector ``k``, the K columns orthonormal over all V·C
    numbers.
``/variances``
    ``(K,)`` float64 > 0: the prior variance of each coefficient.
``/residual_var``
    ``(V, C)`` >= 0: variance, per cell and channel, of what the basis leaves out.

The reader checks everything at one boundary (HDF5 structure through the bounded path of
:mod:`gonio.io._hdf5_guard`, the metadata against its schema, every shape, every number finite,
variances positive) and raises one :class:`~gonio.errors.FormatError` line naming the file.
"""

from __future__ import annotations

import io
import math
import time
from typing import Any

import numpy as np

from gonio import __version__
from gonio._bounded import MAX_CHANNELS, loads_json
from gonio.errors import FormatError, GonioError
from gonio.io._common import PathLike, check_input_file, fail
from gonio.io._hdf5_guard import (
    ReadBudgetExceeded,
    check_attribute,
    check_global_heaps,
    check_group_datasets,
    open_bounded,
)
from gonio.io.atomic import atomic_output
from gonio.io.schemas import register_schema
from gonio.io.strict_json import dumps_json

FORMAT_NAME = "gonio-prior"
FORMAT_VERSION = 1
SUFFIX = ".prior.h5"
#: Datasets of a prior file, in the order they are written.
DATASETS = ("mask", "mean", "basis", "variances", "residual_var")
#: Largest rank a file may declare.
MAX_RANK = 1024
_HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"


@register_schema("prior-metadata.schema.json")
def prior_metadata_schema() -> dict:
    """JSON Schema of a prior file's ``metadata`` attribute."""
    num = {"type": "number"}
    axis = {
        "type": "object",
        "required": ["name", "size", "lo", "hi", "warp", "periodic", "node_offset"],
        "additionalProperties": False,
        "properties": {
            "name": {"enum": ["theta_h", "theta_d", "phi_d"]},
            "size": {"type": "integer", "minimum": 1, "maximum": 4096},
            "lo": {**num, "description": "radians"},
            "hi": {**num, "description": "radians"},
            "warp": {"enum": ["linear", "sqrt"]},
            "periodic": {"type": "boolean"},
            "node_offset": {**num, "minimum": 0, "exclusiveMaximum": 1},
        },
    }
    return {
        "$id": "https://gonio.invalid/schemas/prior-metadata.schema.json",
        "title": "gonio material prior metadata",
        "description": f"The metadata attribute of a {SUFFIX} file (format {FORMAT_NAME} "
        f"version {FORMAT_VERSION}): a mean and low-rank basis of materials in a mapped space.",
        "type": "object",
        "required": [
            "format",
            "format_version",
            "software",
            "created_utc",
            "space",
            "grid",
            "channels",
            "rank",
            "n_valid",
            "materials",
            "residual",
        ],
        "properties": {
            "format": {"const": FORMAT_NAME},
            "format_version": {"const": FORMAT_VERSION},
            "software": {"type": "string"},
            "created_utc": {"type": "string", "description": "ISO 8601, UTC"},
            "space": {
                "type": "object",
                "description": "m = log(f cos(theta_i) cos(theta_o) + epsilon), f in 1/sr",
                "required": ["name", "epsilon"],
                "properties": {
                    "name": {"const": "log_cos"},
                    "epsilon": {**num, "exclusiveMinimum": 0, "description": "1/sr"},
                    "formula": {"type": "string"},
                },
            },
            "grid": {
                "type": "object",
                "required": ["parameterization", "axes"],
                "additionalProperties": False,
                "properties": {
                    "parameterization": {"const": "half_diff_iso"},
                    "axes": {"type": "array", "items": axis, "minItems": 3, "maxItems": 3},
                },
            },
            "channels": {
                "type": "object",
                "required": ["kind", "names"],
                "properties": {
                    "kind": {"enum": ["rgb", "spectral", "mono"]},
                    "names": {
                        "type": "array",
                        "items": {"type": "string"},
                        "minItems": 1,
                        "maxItems": MAX_CHANNELS,
                    },
                },
            },
            "rank": {"type": "integer", "minimum": 1, "maximum": MAX_RANK},
            "n_valid": {"type": "integer", "minimum": 1},
            "materials": {
                "type": "array",
                "items": {"type": "string"},
                "description": "names of the materials the prior was built from",
            },
            "residual": {
                "type": "object",
                "required": ["kind", "floor"],
                "properties": {
                    "kind": {"enum": ["per_cell"]},
                    "floor": {**num, "minimum": 0},
                    "estimate": {"type": "string"},
                },
            },
            "rank_selection": {"type": "object"},
            "build": {"type": "object"},
            "sources": {"type": "array"},
        },
    }


# --------------------------------------------------------------------------------------------
# writing
# --------------------------------------------------------------------------------------------
def write_prior_file(path: PathLike, arrays: dict[str, np.ndarray], metadata: dict) -> None:
    """Write a prior atomically (built in memory, then :func:`gonio.io.atomic.atomic_output`).

    ``arrays`` holds :data:`DATASETS`; ``metadata`` the JSON fields (``format``,
    ``format_version``, ``software`` and ``created_utc`` are set here). The result is checked
    as the reader checks it before anything is written.
    """
    import h5py

    meta = {
        **metadata,
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "software": f"gonio {__version__}",
        "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    text = dumps_json(meta, nonfinite="refuse", source=str(path), sort_keys=True)
    check_prior(path, arrays, loads_json(text.encode(), str(path)))
    image = io.BytesIO()
    with h5py.File(image, "w", libver=("v108", "v108")) as h5:
        h5.attrs["format"] = FORMAT_NAME
        h5.attrs["format_version"] = np.int64(FORMAT_VERSION)
        h5.attrs["metadata"] = text
        for name in DATASETS:
            data = np.ascontiguousarray(arrays[name])
            if name == "mask":
                data = data.astype(np.uint8)
            elif name != "variances":
                data = data.astype(np.float32)
            h5.create_dataset(name, data=data)
    with atomic_output(path, suffix=".h5.tmp") as tmp:
        tmp.write_bytes(image.getbuffer())


# --------------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------------
def read_prior_file(path: PathLike) -> tuple[dict, dict[str, np.ndarray]]:
    """``(metadata, arrays)`` of a prior file, checked (module docstring).

    Raises
    ------
    FormatError
        One line naming the file: not HDF5, not a prior, another version, a corrupt structure,
        metadata that break the schema, arrays of the wrong shape, non-finite or negative
        numbers where they are not allowed.
    """
    p = check_input_file(path)
    with open(p, "rb") as fh:
        if fh.read(8) != _HDF5_MAGIC:
            raise fail(p, f"not a {FORMAT_NAME} file (not HDF5)")
    try:
        h5 = open_bounded(p)
    except ReadBudgetExceeded as exc:
        raise fail(p, f"corrupt {FORMAT_NAME} file: HDF5 structures loop ({exc})") from None
    except OSError as exc:
        raise fail(p, f"corrupt or truncated HDF5 file ({exc})") from None
    try:
        meta, arrays = _read(h5, p)
    except GonioError:
        raise
    except ReadBudgetExceeded as exc:
        raise fail(p, f"corrupt {FORMAT_NAME} file: HDF5 structures loop ({exc})") from None
    except Exception as exc:  # h5py reports corruption through many exception types
        raise fail(p, f"corrupt {FORMAT_NAME} file ({type(exc).__name__}: {exc})") from None
    finally:
        h5.close()
    check_prior(p, arrays, meta)
    return meta, arrays


def _attr(h5: Any, name: str, path: PathLike) -> Any:
    if name not in h5.attrs:
        raise fail(path, f"not a {FORMAT_NAME} file (no {name!r} attribute)")
    check_attribute(h5, name, path)
    v = h5.attrs[name]
    if isinstance(v, np.ndarray) and v.shape == ():
        v = v.item()
    return v.decode("utf-8") if isinstance(v, bytes) else v


def _read(h5: Any, path: PathLike) -> tuple[dict, dict[str, np.ndarray]]:
    raw = check_group_datasets(h5, path, path.stat().st_size)
    check_global_heaps(path, raw)
    fmt = _attr(h5, "format", path)
    if fmt != FORMAT_NAME:
        raise fail(path, f"HDF5 file is not a {FORMAT_NAME} file (format attribute {fmt!r})")
    version = _attr(h5, "format_version", path)
    if not isinstance(version, int | np.integer) or int(version) != FORMAT_VERSION:
        raise fail(
            path, f"unsupported format_version {version!r} (this gonio reads {FORMAT_VERSION})"
        )
    text = _attr(h5, "metadata", path)
    if not isinstance(text, str):
        raise fail(path, "metadata attribute is not text")
    meta = loads_json(text.encode("utf-8"), str(path))
    _check_schema(meta, path)
    arrays = {}
    for name in DATASETS:
        if name not in h5 or not hasattr(h5[name], "dtype"):
            raise fail(path, f"missing dataset /{name}")
        ds = h5[name]
        if ds.dtype.kind not in "fiub":
            raise fail(path, f"/{name} is not numeric (dtype {ds.dtype})")
        arrays[name] = np.asarray(ds[()])
    return meta, arrays


def _check_schema(meta: Any, path: PathLike) -> None:
    import jsonschema

    try:
        jsonschema.validate(meta, prior_metadata_schema())
    except jsonschema.ValidationError as exc:
        where = "/".join(map(str, exc.absolute_path)) or "top level"
        problem = " ".join(exc.message.split())[:120]
        raise fail(path, f"bad prior metadata ({where}: {problem})") from None


def check_prior(path: PathLike, arrays: dict[str, np.ndarray], meta: dict) -> None:
    """Shapes and numbers of a prior's arrays against its metadata; FormatError otherwise."""
    _check_schema(meta, path)
    for name in DATASETS:
        if name not in arrays:
            raise fail(path, f"missing dataset /{name}")
    axes = meta["grid"]["axes"]
    if [a["name"] for a in axes] != ["theta_h", "theta_d", "phi_d"]:
        raise fail(path, "grid axes must be theta_h, theta_d, phi_d")
    for a in axes:
        if not (math.isfinite(a["lo"]) and math.isfinite(a["hi"]) and a["hi"] > a["lo"]):
            raise fail(path, f"axis {a['name']}: need lo < hi")
    grid = tuple(int(a["size"]) for a in axes)
    mask = np.asarray(arrays["mask"])
    if mask.shape != grid or mask.dtype.kind not in "biu" or not np.isin(mask, (0, 1)).all():
        raise fail(path, f"/mask must be 0/1 of shape {grid}, got {mask.dtype} {mask.shape}")
    n_valid, rank = int(meta["n_valid"]), int(meta["rank"])
    if int(mask.sum()) != n_valid:
        raise fail(path, f"/mask has {int(mask.sum())} valid cells, metadata says {n_valid}")
    C = len(meta["channels"]["names"])
    shapes = {
        "mean": (n_valid, C),
        "basis": (n_valid, C, rank),
        "variances": (rank,),
        "residual_var": (n_valid, C),
    }
    for name, shape in shapes.items():
        arr = np.asarray(arrays[name])
        if arr.shape != shape or arr.dtype.kind != "f":
            raise fail(path, f"/{name} must be float {shape}, got {arr.dtype} {arr.shape}")
        if not np.isfinite(arr).all():
            raise fail(path, f"/{name} holds NaN or infinite numbers")
    if not (np.asarray(arrays["variances"]) > 0).all():
        raise fail(path, "/variances must be > 0")
    if (np.asarray(arrays["residual_var"]) < 0).any():
        raise fail(path, "/residual_var must be >= 0")
    eps = float(meta["space"]["epsilon"])
    if not math.isfinite(eps):
        raise fail(path, "space epsilon must be finite")


def is_prior_file(path: PathLike) -> bool:
    """Whether ``path`` opens as HDF5 with ``format = "gonio-prior"`` (no other check)."""
    try:
        read_prior_header(path)
    except (FormatError, OSError):
        return False
    return True


def read_prior_header(path: PathLike) -> dict:
    """The checked metadata of a prior file without its arrays; FormatError otherwise."""
    p = check_input_file(path)
    with open(p, "rb") as fh:
        if fh.read(8) != _HDF5_MAGIC:
            raise fail(p, f"not a {FORMAT_NAME} file (not HDF5)")
    try:
        h5 = open_bounded(p)
    except OSError as exc:
        raise fail(p, f"corrupt or truncated HDF5 file ({exc})") from None
    try:
        raw = check_group_datasets(h5, p, p.stat().st_size)
        check_global_heaps(p, raw)
        if _attr(h5, "format", p) != FORMAT_NAME:
            raise fail(p, f"HDF5 file is not a {FORMAT_NAME} file")
        meta = loads_json(str(_attr(h5, "metadata", p)).encode("utf-8"), str(p))
    except GonioError:
        raise
    except Exception as exc:
        raise fail(p, f"corrupt {FORMAT_NAME} file ({type(exc).__name__}: {exc})") from None
    finally:
        h5.close()
    _check_schema(meta, p)
    return meta


__all__ = [
    "DATASETS",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "SUFFIX",
    "check_prior",
    "is_prior_file",
    "prior_metadata_schema",
    "read_prior_file",
    "read_prior_header",
    "write_prior_file",
]
