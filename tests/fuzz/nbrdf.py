"""Neural-BRDF archives for the fuzzer: seed archives and zip-level mutations.

A seed is a zip with the member layout of ``merl_nbrdf.zip`` (``merl_nbrdf/NAME.json``, the Keras
``Sequential`` description, and ``merl_nbrdf/NAME.h5``, its weights: one group per ``Dense``
layer holding ``LAYER/LAYER/kernel:0`` ``(in, out)`` and ``bias:0``, named by the group's
``weight_names`` attribute). Generated seeds hold one or two tiny networks; the real archive, when
present, gives a one-material archive (its members copied byte for byte), so that a case reads
kilobytes, not the whole archive.

The mutations (:func:`m_nbrdf`) act on the archive's members: removal, a corrupt or hostile JSON
description, wrong weight shapes, NaN/Inf or huge weights, huge declared dataset shapes, a highly
compressible member (a zip bomb in miniature), an unsupported compression method,
truncation or byte flips of one compressed member, and a network widened or deepened
consistently (description and weights) within and beyond the reader's bounds.
"""

from __future__ import annotations

import io
import itertools
import json
import struct
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from tests.conftest import SHARED_DATA

PREFIX = "merl_nbrdf/"
#: Materials the check reads by name in every archive, whether or not the zip still lists them
#: (a removed member must give "lacks its .json or .h5 file", not a silent skip).
NAMES = ("fuzz-a", "fuzz-b", "gold-paint")
REAL_ARCHIVE = "nbrdf/merl_nbrdf.zip"
REAL_NAME = "gold-paint"


def _layer(name: str, units: int, activation: str, first: bool) -> dict[str, Any]:
    cfg: dict[str, Any] = {"name": name, "trainable": True, "units": units,
                           "activation": activation, "use_bias": True}  # fmt: skip
    if first:
        cfg["batch_input_shape"] = [None, 6]
    return {"class_name": "Dense", "config": cfg}


def description(units: list[int]) -> dict[str, Any]:
    """The Keras description of a ReLU MLP 6 -> units... -> 3, with the final Lambda layer."""
    sizes = [*units, 3]
    layers = [
        _layer(f"dense_{i + 1}", n, "linear" if i == len(sizes) - 1 else "relu", i == 0)
        for i, n in enumerate(sizes)
    ]
    layers.append({"class_name": "Lambda", "config": {"name": "lambda_1", "function": "(not run)"}})
    return {"class_name": "Sequential", "config": {"name": "sequential_1", "layers": layers}}


def weights_h5(kernels: list[np.ndarray], biases: list[np.ndarray]) -> bytes:
    """A Keras weights file (in memory) for the given per-layer kernels and biases."""
    import h5py

    buf = io.BytesIO()
    with h5py.File(buf, "w") as h5:
        names = [f"dense_{i + 1}" for i in range(len(kernels))]
        h5.attrs["layer_names"] = np.array([n.encode() for n in [*names, "lambda_1"]])
        h5.attrs["backend"] = b"tensorflow"
        for n, k, b in zip(names, kernels, biases, strict=True):
            g = h5.create_group(n)
            g.attrs["weight_names"] = np.array([f"{n}/kernel:0".encode(), f"{n}/bias:0".encode()])
            g.create_dataset(f"{n}/kernel:0", data=k)
            g.create_dataset(f"{n}/bias:0", data=b)
        h5.create_group("lambda_1").attrs["weight_names"] = np.array([], dtype=np.float64)
    return buf.getvalue()


def _network(units: list[int], seed: int) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Small random weights whose output is log1p of a plausible BRDF (0.35-2 1/sr): ReLU
    activations are >= 0 and the last layer's kernel and bias are positive and small."""
    rng = np.random.default_rng(seed)
    sizes = [6, *units, 3]
    ks = [(rng.normal(0, 0.3, (a, b))).astype(np.float32) for a, b in itertools.pairwise(sizes)]
    ks[-1] = rng.uniform(0.0, 0.1, ks[-1].shape).astype(np.float32)
    bs = [rng.uniform(0.0, 0.1, b).astype(np.float32) for b in sizes[1:]]
    bs[-1] = np.full(3, 0.3, np.float32)
    return ks, bs


def _write_zip(path: Path, members: dict[str, bytes]) -> None:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in members.items():
            info = zipfile.ZipInfo(name, date_time=(2021, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            zf.writestr(info, data)


def seed_archives(out: Path, real: bool = True) -> list[tuple[str, Path]]:
    """``[(seed name, path)]``: two generated archives, and a one-material real one if present."""
    seeds = []
    p = out / "tiny_nbrdf.zip"
    ks, bs = _network([4], 1)
    _write_zip(p, {f"{PREFIX}fuzz-a.json": json.dumps(description([4])).encode(),
                   f"{PREFIX}fuzz-a.h5": weights_h5(ks, bs)})  # fmt: skip
    seeds.append(("generated-one", p))
    p = out / "two_nbrdf.zip"
    members = {}
    for name, units, s in (("fuzz-a", [5, 5], 2), ("fuzz-b", [8], 3)):
        ks, bs = _network(units, s)
        members[f"{PREFIX}{name}.json"] = json.dumps(description(units)).encode()
        members[f"{PREFIX}{name}.h5"] = weights_h5(ks, bs)
    _write_zip(p, members)
    seeds.append(("generated-two", p))
    src = SHARED_DATA / REAL_ARCHIVE
    if real and src.is_file():
        p = out / "merl_nbrdf_one.zip"
        with zipfile.ZipFile(src) as zf:
            members = {f"{PREFIX}{REAL_NAME}.{ext}": zf.read(f"{PREFIX}{REAL_NAME}.{ext}")
                       for ext in ("json", "h5")}  # fmt: skip
        _write_zip(p, members)
        seeds.append((f"real-{REAL_NAME}", p))
    return seeds


# ---------------------------------------------------------------------------------- mutations
def _weights_of(data: bytes) -> tuple[list[np.ndarray], list[np.ndarray]]:
    import h5py

    ks, bs = [], []
    with h5py.File(io.BytesIO(data), "r") as h5:
        for n in sorted(k for k in h5 if k.startswith("dense_")):
            ks.append(np.asarray(h5[n][n]["kernel:0"]))
            bs.append(np.asarray(h5[n][n]["bias:0"]))
    return ks, bs


def _huge_shape_h5(data: bytes, rng: Any) -> tuple[bytes, str]:
    """One kernel replaced by a chunked dataset declaring a huge shape (nothing stored)."""
    import h5py

    ks, bs = _weights_of(data)
    buf = io.BytesIO(weights_h5(ks, bs))
    i = int(rng.integers(0, len(ks)))
    shape = tuple(int(x) for x in [(1 << 14, 1 << 15), (6, 1 << 31), (1 << 40, 3)][rng.integers(3)])
    with h5py.File(buf, "r+") as h5:
        n = f"dense_{i + 1}"
        del h5[n][n]["kernel:0"]
        h5[n][n].create_dataset("kernel:0", shape=shape, dtype="f4", chunks=(1, 3))
    return buf.getvalue(), f"layer {i + 1} kernel declared with shape {shape}"


def _members(d: bytes) -> dict[str, bytes]:
    with zipfile.ZipFile(io.BytesIO(d)) as zf:
        return {n: zf.read(n) for n in zf.namelist()}


def _zip(members: dict[str, bytes], method: int = zipfile.ZIP_DEFLATED) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for name, data in members.items():
            info = zipfile.ZipInfo(name, date_time=(2021, 1, 1, 0, 0, 0))
            info.compress_type = method
            zf.writestr(info, data)
    return buf.getvalue()


def _json_mutation(desc: dict[str, Any], rng: Any) -> tuple[Any, str]:
    layers = desc["config"]["layers"]
    i = int(rng.integers(0, len(layers) - 1))
    what = str(["units", "activation", "class", "config", "layers", "top", "deep", "nan"][
        rng.integers(8)])  # fmt: skip
    if what == "units":
        v = [0, -1, 10**9, 1 << 40, 2.5, "21", None, True][int(rng.integers(8))]
        layers[i]["config"]["units"] = v
        return desc, f"layer {i} units set to {v!r}"
    if what == "activation":
        v = ["tanh", None, 3, "softmax"][int(rng.integers(4))]
        layers[i]["config"]["activation"] = v
        return desc, f"layer {i} activation set to {v!r}"
    if what == "class":
        v = ["Conv2D", None, 7, "Lambda"][int(rng.integers(4))]
        layers[i]["class_name"] = v
        return desc, f"layer {i} class_name set to {v!r}"
    if what == "config":
        v = [None, [], "x", 1][int(rng.integers(4))]
        layers[i]["config"] = v
        return desc, f"layer {i} config set to {v!r}"
    if what == "layers":
        v = [None, {}, [], "x", [1, 2]][int(rng.integers(5))]
        desc["config"]["layers"] = v
        return desc, f"layers set to {v!r}"
    if what == "top":
        v = [[], "x", None, 3, {"config": {}}][int(rng.integers(5))]
        return v, f"whole description replaced by {v!r}"
    if what == "deep":
        v: Any = 0
        for _ in range(100_000):
            v = [v]
        return v, "whole description replaced by 100,000 nested lists"
    layers[i]["config"]["units"] = float("nan")
    return desc, f"layer {i} units set to NaN"


#: Hidden layers a widened network gets: within the reader's bounds (the first two) and
#: beyond them in width, depth or multiply-adds (issue #45: 4096 wide ran XLA out of memory,
#: 512 wide took 4.6 GiB).
WIDENED = ([64, 64], [24] * 7, [4096], [512, 512], [200, 200], [4] * 9)


def _widen(members: dict[str, bytes], json_name: str, rng: Any) -> tuple[bytes, str]:
    """Replace one material's description and weights by a consistent wider or deeper one
    (small weights, so that only the size can be wrong)."""
    units = list(WIDENED[int(rng.integers(len(WIDENED)))])
    ks, bs = _network(units, int(rng.integers(1 << 16)))
    members[json_name] = json.dumps(description(units)).encode()
    members[json_name[: -len(".json")] + ".h5"] = weights_h5([k * 0.05 for k in ks], bs)
    return _zip(members), f"nbrdf {json_name}: network widened to hidden layers {units}"


def m_nbrdf(d: bytes, rng: Any) -> tuple[bytes, str]:
    """One zip-level mutation of a neural-BRDF archive (see the module docstring)."""
    members = _members(d)
    names = sorted(members)
    what = str(["remove", "json", "json", "shape", "nan", "huge_weights", "huge_shape", "bomb",
                "method", "member_bytes", "raw_json", "widen"][rng.integers(12)])  # fmt: skip
    jsons = [n for n in names if n.endswith(".json")]
    h5s = [n for n in names if n.endswith(".h5")]
    if what == "widen" and jsons:
        return _widen(members, jsons[int(rng.integers(len(jsons)))], rng)
    if what == "remove":
        n = names[int(rng.integers(len(names)))]
        del members[n]
        return _zip(members), f"nbrdf member {n} removed"
    if what in ("json", "raw_json") and jsons:
        n = jsons[int(rng.integers(len(jsons)))]
        if what == "raw_json":
            v = [b"", b"{", b"\xff\xfe\x00", b"null", b"[" * 100_000, b'{"class_name": "Seq'][
                int(rng.integers(6))]  # fmt: skip
            members[n] = v
            return _zip(members), f"nbrdf {n} replaced by {v[:20]!r} ({len(v)} bytes)"
        new, desc = _json_mutation(json.loads(members[n]), rng)
        try:
            members[n] = json.dumps(new).encode()
        except RecursionError:  # the deep list: write it by hand
            members[n] = b"[" * 100_000 + b"0" + b"]" * 100_000
        return _zip(members), f"nbrdf {n}: {desc}"
    if what in ("shape", "nan", "huge_weights") and h5s:
        n = h5s[int(rng.integers(len(h5s)))]
        ks, bs = _weights_of(members[n])
        i = int(rng.integers(len(ks)))
        if what == "shape":
            k = ks[i]
            ks[i] = [k.T.copy(), k[:-1], np.zeros((k.shape[0], k.shape[1], 2), k.dtype)][
                int(rng.integers(3))]  # fmt: skip
            desc = f"layer {i + 1} kernel reshaped {k.shape} -> {ks[i].shape}"
        else:
            v = {"nan": [np.nan, np.inf, -np.inf], "huge_weights": [1e30, 3e38, -1e20]}[what][
                int(rng.integers(3))]  # fmt: skip
            ks[i] = ks[i].copy()
            ks[i].reshape(-1)[int(rng.integers(ks[i].size))] = v
            bs[i] = bs[i] + (v if rng.random() < 0.3 else 0)
            desc = f"layer {i + 1} weights given {v}"
        members[n] = weights_h5(ks, [b.astype(np.float32) for b in bs])
        return _zip(members), f"nbrdf {n}: {desc}"
    if what == "huge_shape" and h5s:
        n = h5s[int(rng.integers(len(h5s)))]
        members[n], desc = _huge_shape_h5(members[n], rng)
        return _zip(members), f"nbrdf {n}: {desc}"
    if what == "bomb":
        n = names[int(rng.integers(len(names)))]
        size = int([1 << 25, 1 << 26][int(rng.integers(2))])
        members[n] = members[n] + b"\0" * size  # deflates ~1000:1
        return _zip(members), f"nbrdf {n} padded with {size} zero bytes (highly compressible)"
    if what == "method":
        # the compression method field of every local and central header set to an unknown code
        b = bytearray(d)
        v = int([99, 14, 12, 1][int(rng.integers(4))])
        for sig, off in ((b"PK\x03\x04", 8), (b"PK\x01\x02", 10)):
            at = b.find(sig)
            while at >= 0:
                struct.pack_into("<H", b, at + off, v)
                at = b.find(sig, at + 4)
        return bytes(b), f"nbrdf compression method set to {v}"
    # bytes inside one member's compressed data (headers intact: the reader must notice)
    with zipfile.ZipFile(io.BytesIO(d)) as zf:
        infos = zf.infolist()
    info = infos[int(rng.integers(len(infos)))]
    start = info.header_offset + 30 + len(info.filename.encode()) + len(info.extra)
    b = bytearray(d)
    if info.compress_size == 0:
        return bytes(b[: len(b) // 2]), "nbrdf archive truncated to half"
    at = start + int(rng.integers(info.compress_size))
    b[at] ^= 1 << int(rng.integers(8))
    return bytes(b), f"nbrdf member {info.filename}: bit flipped in its compressed data at {at}"
