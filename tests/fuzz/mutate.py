"""Seeded mutations of corpus files: every case is a pure function of ``(master seed, index)``.

:func:`make_case` picks a corpus kind (uniformly, so that every reader gets its share), a file of
that kind, and a mutation; it returns the mutated bytes and a one-line description. Mutation
families:

New classes (issue #45): consistent reshaping (a MERL grid with a matching payload, a neural
network widened or deepened in its description and weights, an RGL file with three azimuths or
thousands of wavelengths), scaled fields (a MERL channel negated or scaled, an RGL field or a few
of its cells scaled, a text column scaled), integers overflowing Python's 4,300-digit limit.

* bytes (every format): truncation, bit flips, zeroed ranges, duplicated ranges (the 1 KB
  duplication of the issue among them), inserted and deleted ranges, 32/64-bit words set to
  huge, negative or zero values;
* binary headers (MERL dimensions, RGL field shapes, offsets, ranks and dtypes, EXR
  data windows) set huge, negative, zero or inconsistent; payload floats set to NaN, Inf,
  1e38, 1e308 or negative values;
* HDF5 structure (native files, through h5py): attributes deleted, retyped or set to NaN / huge
  / negative values; datasets replaced by NaN, Inf, 1e38 or negative values, by another shape or
  dtype, by external storage (``/dev/zero``), a virtual dataset, unallocated chunks declaring a
  huge grid, or a highly compressible chunk; a deeply nested or huge metadata attribute;
* text (Cornell, ALTA): numbers replaced by NaN, Inf, 1e308, negative or huge values or garbage,
  lines dropped, duplicated or swapped, non-UTF-8 bytes inserted;
* TOML and JSON trees (rig, plan, fit result): a leaf replaced by a wrong type, NaN, Inf, 1e308,
  a negative or huge integer, a key deleted or nulled, unknown keys, deep nesting; non-UTF-8.
"""

from __future__ import annotations

import io as _io
import json
import math
import re
import struct
import tempfile
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tests.fuzz.corpus import Seed
from tests.fuzz.nbrdf import m_nbrdf

Rng = np.random.Generator


def _pick(rng: Rng, seq: Any) -> Any:
    """One element of ``seq`` (by index: ``rng.choice`` would turn big ints into floats)."""
    seq = list(seq)
    return seq[int(rng.integers(0, len(seq)))]


#: Numbers that readers must refuse or handle: non-finite, absurd, negative, integer limits.
BAD_FLOATS = (math.nan, math.inf, -math.inf, 1e308, -1e308, 1e38, -1.0, -1e-3, 0.0, 1e-320)
BAD_INTS = (0, -1, -(2**31), 2**31 - 1, 2**32 - 1, 2**62, 2**63 - 1, 2**64 - 1, 10**30)
BAD_TEXT_NUMBERS = (
    "nan", "NaN", "inf", "-inf", "Infinity", "1e308", "-1e308", "1e38", "-1", "-0.5", "1e999",
    "99999999999999999999", "0", "-0", "0x10", "1,5", "", "abc", "1e-400",
)  # fmt: skip


@dataclass(frozen=True)
class Case:
    """One fuzz case: where it came from and what was done to it (enough to replay it)."""

    master: int
    index: int
    seed: Seed
    mutation: str
    data: bytes

    @property
    def case_id(self) -> str:
        return f"{self.master}:{self.index}"

    def describe(self) -> str:
        return (
            f"case {self.case_id} ({self.seed.kind}) source {self.seed.path} "
            f"mutation: {self.mutation}"
        )


# ---------------------------------------------------------------------------------- bytes
def _pos(rng: Rng, n: int, header_bias: float = 0.5) -> int:
    """An offset, biased toward the first 2 KB (headers live there)."""
    if n <= 1:
        return 0
    if rng.random() < header_bias:
        return int(rng.integers(0, min(n, 2048)))
    return int(rng.integers(0, n))


def m_truncate(d: bytes, rng: Rng) -> tuple[bytes, str]:
    at = _pos(rng, len(d), 0.3)
    return d[:at], f"truncated to {at} of {len(d)} bytes"


def m_flip(d: bytes, rng: Rng) -> tuple[bytes, str]:
    b = bytearray(d)
    k = int(rng.integers(1, 9))
    where = [_pos(rng, len(b)) for _ in range(k)]
    for w in where:
        b[w] ^= 1 << int(rng.integers(0, 8))
    return bytes(b), f"flipped one bit at offsets {where}"


def m_zero(d: bytes, rng: Rng) -> tuple[bytes, str]:
    at = _pos(rng, len(d))
    n = int(_pick(rng, [1, 4, 8, 64, 512, 4096]))
    b = bytearray(d)
    b[at : at + n] = bytes(len(b[at : at + n]))
    return bytes(b), f"zeroed {n} bytes at {at}"


def m_duplicate(d: bytes, rng: Rng) -> tuple[bytes, str]:
    n = int(_pick(rng, [16, 256, 1024, 4096]))
    at = 1103 if rng.random() < 0.15 else _pos(rng, len(d))
    return d[: at + n] + d[at : at + n] + d[at + n :], f"duplicated {n} bytes at {at}"


def m_insert(d: bytes, rng: Rng) -> tuple[bytes, str]:
    at = _pos(rng, len(d))
    n = int(_pick(rng, [1, 7, 64, 1000]))
    junk = rng.integers(0, 256, n, dtype=np.uint8).tobytes()
    return d[:at] + junk + d[at:], f"inserted {n} random bytes at {at}"


def m_delete(d: bytes, rng: Rng) -> tuple[bytes, str]:
    at = _pos(rng, len(d))
    n = int(_pick(rng, [1, 8, 100, 1000]))
    return d[:at] + d[at + n :], f"deleted {n} bytes at {at}"


def m_word(d: bytes, rng: Rng) -> tuple[bytes, str]:
    if len(d) < 8:
        return m_truncate(d, rng)
    at = _pos(rng, len(d) - 8, 0.8)
    v = int(_pick(rng, BAD_INTS))
    fmt = str(_pick(rng, ["<I", "<i", "<Q", "<q"]))
    lim = {"<I": (0, 2**32 - 1), "<i": (-(2**31), 2**31 - 1)}.get(fmt, (-(2**63), 2**64 - 1))
    if fmt == "<q":
        lim = (-(2**63), 2**63 - 1)
    if fmt == "<Q":
        lim = (0, 2**64 - 1)
    v = min(max(v, lim[0]), lim[1])
    b = bytearray(d)
    struct.pack_into(fmt, b, at, v)
    return bytes(b), f"{fmt} word at {at} set to {v}"


BYTE_MUTATIONS: list[Callable[[bytes, Rng], tuple[bytes, str]]] = [
    m_truncate, m_flip, m_zero, m_duplicate, m_insert, m_delete, m_word,
]  # fmt: skip


def _bad_float(rng: Rng) -> float:
    return float(_pick(rng, BAD_FLOATS))


def _float_payload(d: bytes, rng: Rng, start: int, end: int, dtype: str) -> tuple[bytes, str]:
    """Set some floats of a payload region (aligned to ``start``) to bad values."""
    arr = np.frombuffer(bytearray(d), dtype=np.uint8).copy()
    size = np.dtype(dtype).itemsize
    n = (end - start) // size
    if n <= 0:
        return m_flip(d, rng)
    view = arr[start : start + n * size].view(dtype)
    v = _bad_float(rng)
    how = str(_pick(rng, ["one", "some", "all", "negate"]))
    if how == "one":
        view[int(rng.integers(0, n))] = v
    elif how == "some":
        view[rng.integers(0, n, size=max(1, n // 100))] = v
    elif how == "all":
        view[:] = v
    else:
        view[:] = -np.abs(view)
    return arr.tobytes(), f"payload {dtype} [{start}:{end}] {how} set to {v}"


# ---------------------------------------------------------------------------------- MERL
#: MERL grids whose payload is resized to match (a consistent file): beyond the bounds of a
#: measured grid (the 1 x 1 x 65536 of issue #45), at them, and small.
MERL_SHAPES = ((1, 1, 65536), (1, 1, 720), (361, 2, 2), (2, 3, 5), (360, 360, 46))


def _merl_reshaped(d: bytes, rng: Rng) -> tuple[bytes, str]:
    """A MERL file with another grid and a payload of the matching size (from the file's own
    values, repeated); the largest is written as a header only (its payload would be 143 MB)."""
    dims = MERL_SHAPES[int(rng.integers(len(MERL_SHAPES)))]
    n = int(np.prod(dims))
    if n > 1 << 20:
        return struct.pack("<3i", *dims), f"MERL grid set to {dims} (header only)"
    vals = np.frombuffer(d, "<f8", offset=12)
    vals = np.resize(vals[: len(vals) // 3 * 3].reshape(3, -1), (3, n))
    return struct.pack("<3i", *dims) + vals.astype("<f8").tobytes(), f"MERL grid set to {dims}"


def _merl_channel(d: bytes, rng: Rng) -> tuple[bytes, str]:
    """One colour channel negated or scaled (negative values mark unmeasured cells)."""
    raw = np.frombuffer(d, "<f8", offset=12).copy()
    if raw.size < 3:
        return m_flip(d, rng)
    raw = raw[: raw.size // 3 * 3].reshape(3, -1)
    c = int(rng.integers(3))
    f = float(_pick(rng, [-1.0, 1e30, 1e-30, -1e-3]))
    raw[c] *= f
    return d[:12] + raw.astype("<f8").tobytes(), f"MERL channel {c} scaled by {f}"


def m_merl(d: bytes, rng: Rng) -> tuple[bytes, str]:
    r = rng.random()
    if r < 0.15:
        return _merl_reshaped(d, rng)
    if r < 0.3:
        return _merl_channel(d, rng)
    if rng.random() < 0.5:
        b = bytearray(d)
        i = int(rng.integers(0, 3))
        v = int(_pick(rng, [0, -1, -90, 1, 2**31 - 1, 1 << 16, 1 << 17, 90, 180, 6]))
        struct.pack_into("<i", b, 4 * i, v)
        return bytes(b), f"MERL dimension {i} set to {v}"
    return _float_payload(d, rng, 12, len(d), "<f8")


# ---------------------------------------------------------------------------------- RGL
def _rgl_fields(d: bytes) -> list[dict[str, int]]:
    """Byte positions of each field's header entries in a ``tensor_file``."""
    out = []
    (n,) = struct.unpack_from("<I", d, 14)
    pos = 18
    for _ in range(n):
        (ln,) = struct.unpack_from("<H", d, pos)
        name_at = pos + 2
        pos += 2 + ln
        ndim, code, offset = struct.unpack_from("<HBQ", d, pos)
        out.append(
            {"name_at": name_at, "name_len": ln, "ndim_at": pos, "code_at": pos + 2,
             "offset_at": pos + 3, "shape_at": pos + 11, "ndim": ndim, "code": code,
             "offset": offset}
        )  # fmt: skip
        pos += 11 + 8 * ndim
    return out


#: Factors a whole RGL field or a few of its cells is scaled by (issue #45: a scaled ``theta_i``,
#: a denormal ``sigma``, an NDF large in a few cells, a sign flip).
RGL_SCALES = (1e-30, 1e-38, 1e-45, 1e9, 1e30, -1.0)
#: Wavelength counts of a rewritten spectral file: beyond the reader's bound, at it, typical.
RGL_WAVELENGTHS = (2000, 129, 128, 40)


def _rgl_scaled(f: dict[str, np.ndarray], rng: Rng) -> str:
    names = [n for n, a in f.items() if a.dtype.kind == "f"]
    name = str(_pick(rng, names))
    factor = np.float32(_pick(rng, RGL_SCALES))
    a = f[name].copy()
    if rng.random() < 0.5 or a.shape[-1] < 10:
        f[name] = a * factor
        return f"RGL field {name!r} scaled by {factor:g}"
    at = int(rng.integers(0, a.shape[-1] - 9))
    a[..., at : at + 10] *= factor
    f[name] = a
    return f"RGL field {name!r} columns {at}:{at + 10} scaled by {factor:g}"


def _rgl_azimuths(f: dict[str, np.ndarray], rng: Rng) -> str:
    """``phi_i`` of 3 entries (an anisotropic-looking file) with every table repeated to match,
    over a span that is or is not a whole fold of 2 pi."""
    span = float(_pick(rng, [2.0, math.pi, 2 * math.pi, 1e-30]))
    f["phi_i"] = np.array([0.0, span / 2, span], np.float32)
    for name in ("vndf", "luminance", "rgb", "spectra"):
        if name in f:
            f[name] = np.ascontiguousarray(np.repeat(f[name][:1], 3, axis=0))
    return f"RGL phi_i set to 3 entries over {span:g} rad"


def _rgl_wavelengths(f: dict[str, np.ndarray], rng: Rng) -> str:
    """A spectral file of many wavelengths (flat spectra of the first channel, 4 x 4 grid)."""
    n = int(_pick(rng, RGL_WAVELENGTHS))
    colour = f.pop("spectra") if "spectra" in f else f.pop("rgb")
    f["spectra"] = np.ascontiguousarray(np.repeat(colour[:, :, :1, :4, :4], n, axis=2))
    f["luminance"] = np.ascontiguousarray(f["luminance"][:, :, :4, :4])
    f["wavelengths"] = np.linspace(360.0, 1000.0, n).astype(np.float32)
    return f"RGL spectral with {n} wavelengths"


def _rgl_rewritten(d: bytes, rng: Rng) -> tuple[bytes, str]:
    """A consistent file whose fields are edited: one scaled, azimuths added, wavelengths."""
    from gonio.errors import GonioError
    from gonio.io.rgl import parse_tensor_file, tensor_file_bytes

    try:
        f = parse_tensor_file(d)
    except GonioError:
        return m_flip(d, rng)
    edit = _pick(rng, [_rgl_scaled, _rgl_scaled, _rgl_azimuths, _rgl_wavelengths])
    desc = edit(f, rng)
    return tensor_file_bytes(f), desc


def m_rgl(d: bytes, rng: Rng) -> tuple[bytes, str]:
    if rng.random() < 0.3:
        return _rgl_rewritten(d, rng)
    try:
        fields = _rgl_fields(d)
    except struct.error:
        return m_flip(d, rng)
    f = fields[int(rng.integers(0, len(fields)))]
    name = d[f["name_at"] : f["name_at"] + f["name_len"]].decode("ascii", "replace")
    b = bytearray(d)
    what = str(_pick(rng, ["shape", "shape", "offset", "ndim", "code", "payload", "count"]))
    if what == "shape" and f["ndim"]:
        k = int(rng.integers(0, f["ndim"]))
        v = int(_pick(rng, [0, 1, 2**63, 2**32, 2**64 - 1, 1 << 20, 3]))
        struct.pack_into("<Q", b, f["shape_at"] + 8 * k, v)
        return bytes(b), f"RGL field {name!r} shape[{k}] set to {v}"
    if what == "offset":
        v = int(_pick(rng, [0, len(d), len(d) - 4, 2**63, 2**64 - 1, f["offset"] + 1]))
        struct.pack_into("<Q", b, f["offset_at"], v)
        return bytes(b), f"RGL field {name!r} offset set to {v}"
    if what == "ndim":
        v = int(_pick(rng, [0, 1, 2, 5, 16, 17, 65535]))
        struct.pack_into("<H", b, f["ndim_at"], v)
        return bytes(b), f"RGL field {name!r} ndim set to {v}"
    if what == "code":
        v = int(_pick(rng, [0, 1, 6, 8, 9, 11, 12, 255]))
        b[f["code_at"]] = v
        return bytes(b), f"RGL field {name!r} dtype code set to {v}"
    if what == "count":
        v = int(_pick(rng, [0, 1, 100, 4097, 2**32 - 1]))
        struct.pack_into("<I", b, 14, v)
        return bytes(b), f"RGL field count set to {v}"
    # payload of a float field
    floats = [g for g in fields if g["code"] in (9, 10, 11)]
    if not floats:
        return m_flip(d, rng)
    g = floats[int(rng.integers(0, len(floats)))]
    gname = d[g["name_at"] : g["name_at"] + g["name_len"]].decode("ascii", "replace")
    shape = struct.unpack_from(f"<{g['ndim']}Q", d, g["shape_at"])
    dtype = {9: "<f2", 10: "<f4", 11: "<f8"}[g["code"]]
    nbytes = int(np.prod(shape, dtype=np.int64)) * np.dtype(dtype).itemsize
    out, desc = _float_payload(d, rng, g["offset"], g["offset"] + nbytes, dtype)
    return out, f"RGL field {gname!r}: {desc}"


# ---------------------------------------------------------------------------------- EXR
def m_exr(d: bytes, rng: Rng) -> tuple[bytes, str]:
    names = [b"dataWindow", b"displayWindow", b"chunkCount", b"channels", b"compression"]
    name = names[int(rng.integers(0, len(names)))]
    at = d.find(name + b"\x00")
    if at < 0:
        return m_flip(d, rng)
    tname_end = d.index(b"\x00", at + len(name) + 1)
    size_at = tname_end + 1
    b = bytearray(d)
    if rng.random() < 0.3:
        v = int(_pick(rng, [0, -1, 2**31 - 1, 1 << 20]))
        struct.pack_into("<i", b, size_at, v)
        return bytes(b), f"EXR attribute {name.decode()} size field set to {v}"
    k = int(rng.integers(0, 4))
    v = int(_pick(rng, [-1, 0, 2**31 - 1, -(2**31), 1 << 16, 1 << 24]))
    struct.pack_into("<i", b, size_at + 4 + 4 * k, v)
    return bytes(b), f"EXR attribute {name.decode()} int {k} set to {v}"


# ---------------------------------------------------------------------------------- HDF5
def _h5_mutation(path: Path, rng: Rng) -> str:
    """Change ``path`` (an HDF5 copy) in place through h5py; returns the description."""
    import h5py

    with h5py.File(path, "r+") as h5:
        groups = [h5]
        h5.visititems(lambda n, o: groups.append(o) if isinstance(o, h5py.Group) else None)
        datasets: list[Any] = []
        h5.visititems(lambda n, o: datasets.append(o) if isinstance(o, h5py.Dataset) else None)
        objs = [o for o in groups + datasets if len(o.attrs)]
        op = str(
            _pick(rng,
                ["attr", "attr", "attr", "data", "data", "data", "shape", "dtype", "delete",
                 "external", "virtual", "unallocated", "bomb", "metadata", "mask0", "horizon"]
            )
        )  # fmt: skip
        if op == "attr" and objs:
            o = objs[int(rng.integers(0, len(objs)))]
            keys = list(o.attrs)
            k = keys[int(rng.integers(0, len(keys)))]
            how = str(_pick(rng, ["delete", "float", "int", "str", "array", "bytes"]))
            if how == "delete":
                del o.attrs[k]
                return f"HDF5 attribute {o.name}@{k} deleted"
            if how == "float":
                v: Any = _bad_float(rng)
            elif how == "int":
                v = np.int64(min(int(_pick(rng, BAD_INTS)), 2**63 - 1))
            elif how == "str":
                v = str(_pick(rng, ["", "x", "nan", "gridded", "scattered", "{", "1e308"]))
            elif how == "array":
                v = np.full(int(_pick(rng, [0, 2, 1000])), 1.0)
            else:
                v = np.void(b"\xff\xfe\x00")
            o.attrs[k] = v
            return f"HDF5 attribute {o.name}@{k} set to {how} {v!r}"[:200]
        if not datasets:
            return "no dataset to mutate"
        ds = datasets[int(rng.integers(0, len(datasets)))]
        name, parent = ds.name, ds.parent
        attrs = dict(ds.attrs)

        def replace(data: Any = None, **kw: Any) -> None:
            del parent[name.rsplit("/", 1)[-1]]
            new = parent.create_dataset(name.rsplit("/", 1)[-1], data=data, **kw)
            for k, v in attrs.items():
                new.attrs[k] = v

        if op == "data":
            # integer datasets (mask, counts) become float64 ones: a wrong dtype as well
            arr = np.asarray(ds[()])
            arr = arr.astype(ds.dtype if ds.dtype.kind == "f" else np.float64).reshape(-1)
            v = _bad_float(rng)
            if arr.size:
                share = int(_pick(rng, [1, 50]))  # every cell, or one in 50
                arr[rng.integers(0, arr.size, size=max(1, arr.size // share))] = v
            replace(arr.reshape(ds.shape))
            return f"HDF5 dataset {name} values set to {v} at some cells"
        if op == "shape":
            shape = tuple(int(s) for s in ds.shape)
            new = list(shape) or [1]
            k = int(rng.integers(0, len(new)))
            new[k] = int(_pick(rng, [0, 1, new[k] + 1, new[k] * 2]))
            replace(np.zeros(new, dtype=ds.dtype))
            return f"HDF5 dataset {name} reshaped {shape} -> {tuple(new)}"
        if op == "dtype":
            dt = str(_pick(rng, ["i1", "u8", "f2", "f8", "S4", "c16", "bool"]))
            replace(np.zeros(ds.shape, dtype=dt))
            return f"HDF5 dataset {name} retyped to {dt}"
        if op == "delete":
            del parent[name.rsplit("/", 1)[-1]]
            return f"HDF5 dataset {name} deleted"
        if op == "external":
            shape, dt = ds.shape, ds.dtype
            del parent[name.rsplit("/", 1)[-1]]
            nbytes = int(np.prod(shape, dtype=np.int64)) * dt.itemsize
            new = parent.create_dataset(
                name.rsplit("/", 1)[-1], shape=shape, dtype=dt,
                external=[("/dev/zero", 0, max(nbytes, 1))],
            )  # fmt: skip
            for k, v in attrs.items():
                new.attrs[k] = v
            return f"HDF5 dataset {name} moved to external storage /dev/zero"
        if op == "virtual":
            shape, dt = ds.shape, ds.dtype
            src = parent.create_dataset(name.rsplit("/", 1)[-1] + "_src", data=ds[()])
            layout = h5py.VirtualLayout(shape=shape, dtype=dt)
            layout[...] = h5py.VirtualSource(src)
            del parent[name.rsplit("/", 1)[-1]]
            new = parent.create_virtual_dataset(name.rsplit("/", 1)[-1], layout)
            for k, v in attrs.items():
                new.attrs[k] = v
            return f"HDF5 dataset {name} replaced by a virtual dataset"
        if op in ("unallocated", "bomb"):
            # a large declared grid: axes sizes changed to match, values never written
            # (fill value) or one highly compressible chunk
            if "axes" not in h5 or "values" not in h5:
                return _h5_scattered_huge(h5, rng)
            n = int(_pick(rng, [64, 256, 512]))
            order = [x.decode() if isinstance(x, bytes) else str(x)
                     for x in np.atleast_1d(h5["axes"].attrs["order"])]  # fmt: skip
            for ax in order:
                h5["axes"][ax].attrs["size"] = np.int64(n)
            grid = (n,) * len(order)
            n_ch = h5["values"].shape[-1]
            vattrs = dict(h5["values"].attrs)
            for key in ("values", "mask", "sigma", "counts"):
                if key in h5:
                    del h5[key]
            vdt = np.float32 if vattrs.get("encoding", "float32") == "float32" else np.uint16
            if op == "unallocated":
                v = h5.create_dataset("values", shape=(*grid, n_ch), dtype=vdt,
                                      chunks=(1, *grid[1:], 1))  # fmt: skip
                h5.create_dataset("mask", shape=grid, dtype=np.uint8, fillvalue=1,
                                  chunks=(1, *grid[1:]))  # fmt: skip
            else:
                v = h5.create_dataset("values", shape=(*grid, n_ch), dtype=vdt,
                                      chunks=(1, *grid[1:], 1), compression="gzip",
                                      compression_opts=9, fillvalue=0)  # fmt: skip
                v[0, ..., 0] = 1
                m = h5.create_dataset("mask", shape=grid, dtype=np.uint8,
                                      chunks=(1, *grid[1:]), compression="gzip")  # fmt: skip
                m[...] = 1
            for k, val in vattrs.items():
                v.attrs[k] = val
            return f"HDF5 gridded axes set to {n}^{len(order)} with {op} /values"
        if op == "metadata":
            depth = int(_pick(rng, [50, 600, 5000]))
            how = str(_pick(rng, ["deep", "huge", "notjson"]))
            if how == "deep":
                h5.attrs["metadata"] = "[" * depth + "]" * depth
                return f"HDF5 metadata attribute nested {depth} deep"
            if how == "huge":
                h5.attrs["metadata"] = json.dumps({"notes": "x" * (1 << 20)})
                return "HDF5 metadata attribute of 1 MB"
            h5.attrs["metadata"] = b"\xff\xfe{"
            return "HDF5 metadata attribute not UTF-8"
        if op == "mask0" and "mask" in h5:
            replace_m = h5["mask"]
            replace_m[...] = 0
            return "HDF5 /mask all zero (no valid cell)"
        if op == "horizon" and "wi" in h5:
            w = np.asarray(h5["wi"][()])
            w[: max(1, len(w) // 3), 2] *= -1
            h5["wi"][...] = w
            return "HDF5 /wi: a third of the directions below the horizon"
        if "axes" in h5:
            order = list(h5["axes"])
            ax = order[int(rng.integers(0, len(order)))]
            k = str(_pick(rng, ["lo", "hi"]))
            v = float(_pick(rng, [100.0, -100.0, 7.0, -0.5, 1e308]))
            h5["axes"][ax].attrs[k] = v
            return f"HDF5 axis {ax}@{k} set to {v}"
        return "HDF5 unchanged (no applicable mutation)"


def _h5_scattered_huge(h5: Any, rng: Rng) -> str:
    n = int(_pick(rng, [10**6, 10**8]))
    for key in ("wi", "wo", "values", "sigma", "weights"):
        if key not in h5:
            continue
        ds = h5[key]
        shape, dt, attrs = ds.shape, ds.dtype, dict(ds.attrs)
        del h5[key]
        new = h5.create_dataset(key, shape=(n, *shape[1:]), dtype=dt,
                                chunks=(min(n, 1 << 16), *shape[1:]))  # fmt: skip
        for k, v in attrs.items():
            new.attrs[k] = v
    return f"HDF5 scattered datasets declare {n} unallocated samples"


def m_hdf5(d: bytes, rng: Rng) -> tuple[bytes, str]:
    if rng.random() < 0.15:
        # a range of the metadata region (object headers, global heaps) duplicated in place
        n = int(_pick(rng, [256, 1024]))
        at = int(rng.integers(512, min(len(d), 4096)))
        return d[: at + n] + d[at : at + n] + d[at + n :], f"duplicated {n} bytes at {at}"
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "x.h5"
        p.write_bytes(d)
        try:
            desc = _h5_mutation(p, rng)
        except Exception as exc:  # the mutation itself failed: fall back to bytes
            out, desc = m_flip(d, rng)
            return out, f"{desc} (HDF5 mutation failed: {type(exc).__name__})"
        return p.read_bytes(), desc


# ---------------------------------------------------------------------------------- text
def _scale_column(lines: list[str], rng: Rng) -> tuple[bytes, str]:
    """One column of the data rows (angles, values) scaled: degrees for radians, a sign flip,
    a huge or tiny factor."""
    rows = [i for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#")]
    width = max((len(lines[i].split()) for i in rows), default=0)
    if width < 2:
        return "\n".join(lines).encode(), "no data column to scale"
    col = int(rng.integers(width))
    f = float(_pick(rng, [180 / math.pi, -1.0, 1e30, 1e-30, 4.0]))
    for i in rows:
        toks = lines[i].split()
        if col < len(toks):
            try:
                toks[col] = repr(float(toks[col]) * f)
            except ValueError:
                continue
            lines[i] = " ".join(toks)
    return "\n".join(lines).encode(), f"data column {col + 1} scaled by {f:.6g}"


#: Channel counts a widened text file declares, within and beyond the 128 a table may hold.
WIDTHS = (2, 31, 128, 129, 1000, 5000)


def _widen_cornell(lines: list[str], k: int) -> tuple[bytes, str]:
    """A Cornell file re-declared with ``k`` wavelengths, consistently: the wavelength list and
    every record's spectrum resampled to ``k`` values (one record a line)."""
    body = [ln for ln in lines if not ln.lstrip().startswith("#")]
    nums = np.array([float(t) for ln in body for t in ln.split()])
    n = int(nums[0])
    wl, rest = nums[1 : 1 + n], nums[1 + n :]
    rows = rest[: len(rest) // (4 + n) * (4 + n)].reshape(-1, 4 + n)
    new_wl = np.linspace(wl[0], wl[-1] + k, k)
    spectra = [np.interp(np.linspace(0, n - 1, k), np.arange(n), r[4:]) for r in rows]
    out = [ln for ln in lines if ln.lstrip().startswith("#")] + [str(k)]
    out.append(" ".join(f"{w:.4f}" for w in new_wl))
    out += [
        " ".join(f"{x:.6g}" for x in (*r[:4], *sp)) for r, sp in zip(rows, spectra, strict=True)
    ]
    return "\n".join(out).encode(), f"Cornell widened from {n} to {k} wavelengths"


def _widen_alta(lines: list[str], k: int) -> tuple[bytes, str]:
    """An ALTA file re-declared with ``k`` outputs, consistently: ``#DIM`` and every row's
    outputs (and their ``#VS`` columns) repeated to ``k``."""
    dim = next(i for i, ln in enumerate(lines) if ln.strip().upper().startswith("#DIM"))
    n_in, n_out = (int(t) for t in lines[dim].split()[1:3])
    vs = next((int(ln.split()[1]) for ln in lines if ln.strip().upper().startswith("#VS")), 0)
    out = list(lines)
    out[dim] = f"#DIM {n_in} {k}"
    for i, ln in enumerate(lines):
        toks = ln.split()
        if ln.lstrip().startswith("#") or len(toks) != n_in + n_out * (1 + vs):
            continue
        vals, extra = toks[n_in : n_in + n_out], toks[n_in + n_out :]
        wide = [vals[j % n_out] for j in range(k)]
        wide_extra = [extra[j % len(extra)] for j in range(k * vs)] if extra else []
        out[i] = " ".join(toks[:n_in] + wide + wide_extra)
    return "\n".join(out).encode(), f"ALTA widened from {n_out} to {k} outputs"


def _widen(lines: list[str], rng: Rng) -> tuple[bytes, str]:
    """The channel count of a Cornell or ALTA file changed consistently (:data:`WIDTHS`)."""
    k = int(_pick(rng, WIDTHS))
    try:
        if any(ln.strip().upper().startswith("#DIM") for ln in lines):
            return _widen_alta(lines, k)
        return _widen_cornell(lines, k)
    except (ValueError, IndexError, StopIteration):
        return "\n".join(lines).encode(), "not widened (unparsed layout)"


def m_text(d: bytes, rng: Rng) -> tuple[bytes, str]:
    text = d.decode("utf-8", "replace")
    lines = text.split("\n")
    op = str(_pick(rng, ["number", "number", "number", "drop", "dup", "swap", "utf8", "header",
                         "scale", "widen"]))  # fmt: skip
    if op == "scale":
        return _scale_column(lines, rng)
    if op == "widen":
        return _widen(lines, rng)
    if op in ("number", "header"):
        header = op == "header"
        cand = [
            (i, j)
            for i, ln in enumerate(lines)
            if ln.lstrip().startswith("#") == header
            for j in range(len(ln.split()))
        ]
        if not cand:
            return m_flip(d, rng)
        # half of the time one of the first tokens (counts and header fields live there)
        top = min(len(cand), 64) if rng.random() < 0.5 else len(cand)
        i, j = cand[int(rng.integers(0, top))]
        toks = lines[i].split()
        new = str(_pick(rng, BAD_TEXT_NUMBERS))
        old = toks[j]
        toks[j] = new
        lines[i] = " ".join(toks)
        return "\n".join(lines).encode(), f"line {i + 1} token {j + 1} {old!r} -> {new!r}"
    if op == "drop":
        i = int(rng.integers(0, len(lines)))
        del lines[i]
        return "\n".join(lines).encode(), f"line {i + 1} dropped"
    if op == "dup":
        i = int(rng.integers(0, len(lines)))
        lines.insert(i, lines[i])
        return "\n".join(lines).encode(), f"line {i + 1} duplicated"
    if op == "swap":
        i, j = (int(x) for x in rng.integers(0, len(lines), 2))
        lines[i], lines[j] = lines[j], lines[i]
        return "\n".join(lines).encode(), f"lines {i + 1} and {j + 1} swapped"
    at = _pos(rng, len(d))
    choices = (b"\xff", b"\xc3", b"\xed\xa0\x80", b"\x80\x80", b"\x00")
    bad = choices[int(rng.integers(0, len(choices)))]
    return d[:at] + bad + d[at:], f"non-UTF-8 bytes {bad!r} inserted at {at}"


# ---------------------------------------------------------------------------------- trees
def _paths(tree: Any, prefix: tuple = ()) -> list[tuple]:
    out = [prefix]
    if isinstance(tree, dict):
        for k, v in tree.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(tree, list):
        for i, v in enumerate(tree):
            out += _paths(v, (*prefix, i))
    return out


def _get(tree: Any, path: tuple) -> Any:
    for k in path:
        tree = tree[k]
    return tree


def _deep(depth: int, kind: str) -> Any:
    v: Any = 1
    for _ in range(depth):
        v = [v] if kind == "list" else {"a": v}
    return v


def _tree_mutation(tree: Any, rng: Rng, for_toml: bool) -> str:
    paths = [p for p in _paths(tree) if p]
    if not paths:
        return "empty tree"
    path = paths[int(rng.integers(0, len(paths)))]
    parent, key = _get(tree, path[:-1]), path[-1]
    where = "/".join(map(str, path))
    op = str(_pick(rng, ["value", "value", "value", "type", "delete", "null", "unknown", "deep"]))
    if op == "delete" or (op == "null" and for_toml):
        if isinstance(parent, list):
            parent.pop(key)
        else:
            del parent[key]
        return f"{where} deleted"
    if op == "null":
        parent[key] = None
        return f"{where} set to null"
    if op == "unknown":
        target = parent if isinstance(parent, dict) else tree
        target["fuzz_unknown_key"] = 1
        return f"unknown key added next to {where}"
    if op == "deep":
        depth = int(_pick(rng, [20, 120, 600, 3000]))
        parent[key] = _deep(depth, str(_pick(rng, ["list", "dict"])))
        return f"{where} replaced by a structure nested {depth} deep"
    if op == "type":
        v = _pick(rng, ["str", "list", "table", "bool", "bigint"])
        new: Any = {"str": "fuzz", "list": [1, "a"], "table": {"x": 1}, "bool": True,
                    "bigint": 10**30}[str(v)]  # fmt: skip
        parent[key] = new
        return f"{where} replaced by {v} {new!r}"
    old = parent[key]
    if isinstance(old, bool) or not isinstance(old, int | float):
        new = _bad_float(rng) if rng.random() < 0.7 else int(_pick(rng, BAD_INTS))
    elif isinstance(old, int):
        new = int(_pick(rng, BAD_INTS)) if rng.random() < 0.6 else _bad_float(rng)
    else:
        new = _bad_float(rng) if rng.random() < 0.8 else -abs(old) - 1.0
    if for_toml and isinstance(new, int) and not (-(2**63) <= new < 2**63):
        new = 2**63 - 1
    parent[key] = new
    return f"{where}: {old!r} -> {new!r}"[:200]


def _overflow_integer(d: bytes, rng: Rng) -> tuple[bytes, str]:
    """One integer of the text given thousands of digits (beyond Python's 4,300-digit int()
    limit, which tomllib hits)."""
    text = d.decode("utf-8", "replace")
    found = [m for m in re.finditer(r"(?<=[=\[,\s])-?\d+(?=\s*[,\]\n])", text)]
    if not found:
        return m_flip(d, rng)
    m = found[int(rng.integers(len(found)))]
    n = int(_pick(rng, [4301, 5000, 20000]))
    return (text[: m.start()] + "9" * n + text[m.end() :]).encode(), (
        f"integer {m.group()} at {m.start()} given {n} digits"
    )


def m_toml(d: bytes, rng: Rng) -> tuple[bytes, str]:
    import tomli_w

    if rng.random() < 0.1:
        return _overflow_integer(d, rng)
    try:
        tree = tomllib.loads(d.decode())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError):
        return m_flip(d, rng)
    desc = _tree_mutation(tree, rng, for_toml=True)
    try:
        out = tomli_w.dumps(tree)
    except (TypeError, ValueError, RecursionError):
        # tomli_w cannot write some values (deep nesting): write them by hand
        out = tomli_w.dumps({k: v for k, v in tree.items() if not isinstance(v, list | dict)})
        out += "fuzz_deep = " + "[" * 600 + "1" + "]" * 600 + "\n"
        desc += " (written as a 600-deep array)"
    return out.encode(), f"TOML {desc}"


def m_json(d: bytes, rng: Rng) -> tuple[bytes, str]:
    try:
        tree = json.loads(d)
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError):
        return m_flip(d, rng)
    desc = _tree_mutation(tree, rng, for_toml=False)
    buf = _io.StringIO()
    try:
        json.dump(tree, buf, allow_nan=True)
        out = buf.getvalue()
    except RecursionError:
        out = "[" * 5000 + "]" * 5000
        desc += " (whole file replaced by 5000 nested arrays)"
    return out.encode(), f"JSON {desc}"


# ---------------------------------------------------------------------------------- cases
STRUCTURED: dict[str, Callable[[bytes, Rng], tuple[bytes, str]]] = {
    "native": m_hdf5,
    "merl": m_merl,
    "rgl": m_rgl,
    "nbrdf": m_nbrdf,
    "cornell": m_text,
    "alta": m_text,
    "exr": m_exr,
    "exr_slices": m_exr,
    "rig": m_toml,
    "plan": m_toml,
    "fit": m_json,
    "prior": m_hdf5,
}
TEXT_KINDS = ("cornell", "alta", "rig", "plan", "fit")
#: Native files get three shares of the cases (HDF5 has by far the most structure to corrupt),
#: RGL two (a reader and an evaluator with its own warps).
KIND_WEIGHTS = {"native": 3, "rgl": 2}


def make_case(master: int, index: int, seeds: list[Seed]) -> Case:
    """The case ``index`` of the run seeded ``master`` over the corpus ``seeds``: a kind drawn
    with :data:`KIND_WEIGHTS`, a file of that kind, a mutation (sometimes two)."""
    rng = np.random.default_rng([master, index])
    kinds = [k for k in sorted({s.kind for s in seeds}) for _ in range(KIND_WEIGHTS.get(k, 1))]
    kind = kinds[int(rng.integers(0, len(kinds)))]
    pool = [s for s in seeds if s.kind == kind]
    seed = pool[int(rng.integers(0, len(pool)))]
    data = seed.path.read_bytes()
    r = rng.random()
    if r < 0.6:
        mutate = STRUCTURED[kind]
    elif kind in TEXT_KINDS and r < 0.75:
        mutate = m_text
    else:
        mutate = BYTE_MUTATIONS[int(rng.integers(0, len(BYTE_MUTATIONS)))]
    out, desc = mutate(data, rng)
    if rng.random() < 0.1:  # a second mutation on top, sometimes
        out, desc2 = BYTE_MUTATIONS[int(rng.integers(0, len(BYTE_MUTATIONS)))](out, rng)
        desc = f"{desc}; then {desc2}"
    return Case(master, index, seed, desc, out)
