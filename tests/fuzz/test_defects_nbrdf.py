"""Defects the fuzzer found in the neural-BRDF reader, one constructed input each: a typed
one-line error naming the archive, never a raw exception, a memory blow-up or a silent load."""

from __future__ import annotations

import io as _io
import json
import re
import zipfile

import h5py
import numpy as np
import pytest

from gonio.errors import FormatError
from tests.fuzz.nbrdf import PREFIX, _network, description, weights_h5

pytest.importorskip("gonio.io.nbrdf")


def _archive(tmp, desc=None, h5=None, method=zipfile.ZIP_DEFLATED, name="t.zip"):
    ks, bs = _network([4], 1)
    p = tmp / name
    with zipfile.ZipFile(p, "w", method) as zf:
        zf.writestr(f"{PREFIX}n.json", desc if desc is not None else json.dumps(description([4])))
        zf.writestr(f"{PREFIX}n.h5", h5 if h5 is not None else weights_h5(ks, bs))
    return p


def _refused(p, match):
    from gonio.io.nbrdf import read_nbrdf

    with pytest.raises(FormatError, match=match) as info:
        read_nbrdf(f"{p}::n")
    assert str(p) in str(info.value) and "\n" not in str(info.value)


def test_corrupt_deflate_data_and_unknown_method_are_refused(tmp_path):
    p = _archive(tmp_path)
    d = bytearray(p.read_bytes())
    with zipfile.ZipFile(p) as zf:
        info = zf.getinfo(f"{PREFIX}n.json")
    at = info.header_offset + 30 + len(info.filename) + 5
    d[at] ^= 0xFF  # zlib.error: invalid deflate data
    p.write_bytes(bytes(d))
    _refused(p, "cannot read its members|not a Keras")
    q = _archive(tmp_path, name="m.zip")
    d = bytearray(q.read_bytes())
    for sig, off in ((b"PK\x03\x04", 8), (b"PK\x01\x02", 10)):
        at = d.find(sig)
        while at >= 0:
            d[at + off : at + off + 2] = (99).to_bytes(2, "little")  # NotImplementedError
            at = d.find(sig, at + 4)
    q.write_bytes(bytes(d))
    with pytest.raises(FormatError, match=r"not a readable zip|cannot read"):
        from gonio.io.nbrdf import read_nbrdf

        read_nbrdf(f"{q}::n")


def test_highly_compressible_member_is_refused_before_it_is_inflated(tmp_path):
    p = _archive(tmp_path, desc=json.dumps(description([4])).encode() + b" " * (32 << 20))
    assert p.stat().st_size < 1 << 20
    _refused(p, "declares .* bytes")


@pytest.mark.parametrize(
    "desc, match",
    [
        (b"[" * 100_000, "nested deeper"),
        (json.dumps([1, 2]), "not a Keras model"),
        (
            json.dumps({"class_name": "Sequential", "config": {"layers": [{"config": 1}]}}),
            "config is not an object",
        ),
    ],
)
def test_hostile_descriptions_are_refused(tmp_path, desc, match):
    _refused(_archive(tmp_path, desc=desc), match)


def test_huge_declared_kernel_is_refused_before_it_is_read(tmp_path):
    ks, bs = _network([4], 1)
    buf = _io.BytesIO(weights_h5(ks, bs))
    with h5py.File(buf, "r+") as h5:
        del h5["dense_1/dense_1/kernel:0"]
        h5["dense_1/dense_1"].create_dataset(
            "kernel:0", shape=(1 << 40, 3), dtype="f4", chunks=(1, 3)
        )
    # refused by the HDF5 guard's declared-size check (before the reader's shape check)
    _refused(_archive(tmp_path, h5=buf.getvalue()), r"datasets declare 12582912 MiB in total")


def test_finite_weights_whose_output_overflows_are_refused(tmp_path):
    ks, bs = _network([4], 1)
    ks[0] = ks[0].copy()
    ks[0][2, :] = 900.0  # within the weight bound, but exp of the output overflows float32
    _refused(_archive(tmp_path, h5=weights_h5(ks, bs)), "network output")


@pytest.mark.parametrize("w", [-1e20, 3e38])
def test_absurd_weights_are_refused(tmp_path, w):
    """Fuzz cases 2023:2225 and 2023:4526: a layer's weights set to -1e20 passed the probe grid
    and gave non-finite f at other directions."""
    ks, bs = _network([4], 1)
    ks[1] = ks[1].copy()
    ks[1][0, 0] = w
    _refused(_archive(tmp_path, h5=weights_h5(ks, bs)), "weights beyond 1000")


# ------------------------------------------------------------- issue #45: size and HDF5 guard
def _gonio_info(p, timeout: float = 120):
    from tests import console_script

    return console_script.run("info", f"{p}::n", timeout=timeout)


def _one_line_refusal(proc, p, match: str) -> None:
    assert proc.returncode != 0 and "Traceback" not in proc.stderr, proc.stderr[-800:]
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gonio: ") and str(p) in lines[0], lines
    assert re.search(match, lines[0]), lines[0]


def _wide(tmp, units, name="w.zip"):
    ks, bs = _network(units, 1)
    ks = [k * 0.05 for k in ks]  # keeps the output in range: only the size is wrong
    return _archive(tmp, desc=json.dumps(description(units)), h5=weights_h5(ks, bs), name=name)


@pytest.mark.parametrize(
    "units, match",
    [
        ([4096], r"layer 0 has impossible units 4096 \(at most 256\)"),  # was: XLA out of memory
        ([512, 512], r"impossible units 512"),  # was: 4.6 GiB resident
        ([200, 200], r"6 -> 200 -> 200 -> 3 needs 41800 multiply-adds"),
        ([4] * 9, r"10 Dense layers \(at most 8\)"),
    ],
)
def test_network_too_big_to_tabulate_is_refused_from_its_description(tmp_path, units, match):
    """``gonio info ARCHIVE.zip::NAME`` tabulates the network on MERL's grid (1.1 M valid
    cells): its width, depth and multiply-adds are bounded on the description, before a
    weight is read."""
    p = _wide(tmp_path, units)
    proc = _gonio_info(p)
    _one_line_refusal(proc, p, match)


def test_tabulation_runs_in_bounded_chunks_and_matches_the_plain_forward_pass():
    """A network at the bounds' edge (6 -> 64 -> 64 -> 64 -> 3, 8,768 multiply-adds) evaluated
    on more rows than one chunk: chunked and padded, the same numbers as the NumPy pass."""
    from gonio.io.nbrdf import CHUNK_ROWS, NBRDF

    ks, bs = _network([64, 64, 64], 3)
    net = NBRDF("n", tuple(k * 0.2 for k in ks), tuple(bs))
    x = np.random.default_rng(0).random((2 * CHUNK_ROWS + 17, 6)).astype(np.float32)
    np.testing.assert_allclose(net._forward_many(x), net.forward(x), rtol=1e-5, atol=1e-6)


def test_global_heap_object_of_size_zero_in_the_weights_is_refused_not_looped_on(tmp_path):
    """A weights file whose ``weight_names`` are variable-length strings (a global heap, as
    Keras writes) with the object holding them set to index 0 and size 0: libhdf5 loops
    forever decoding it; the native reader's heap walk (gonio.io._hdf5_guard) now runs on the
    NBRDF path too. Through the console script, killed if it hangs."""
    ks, bs = _network([4], 1)
    buf = _io.BytesIO(weights_h5(ks, bs))
    with h5py.File(buf, "r+") as h5:
        for i in (1, 2):
            h5[f"dense_{i}"].attrs["weight_names"] = [f"dense_{i}/kernel:0", f"dense_{i}/bias:0"]
    d = bytearray(buf.getvalue())
    # the heap object holding the name: a header (index, refcount, reserved, size 16), then it
    at = d.find(b"GCOL\x01")
    obj = d.find(b"\x10" + bytes(7) + b"dense_1/kernel:0", at) - 8
    assert at > 0 and obj > at and d[obj : obj + 2] != b"\0\0"
    d[obj : obj + 16] = bytes(16)  # index 0, size 0
    p = _archive(tmp_path, h5=bytes(d))
    _one_line_refusal(_gonio_info(p), p, "corrupt global heap collection")


def test_network_output_is_checked_where_it_is_evaluated_not_only_where_it_is_tabulated():
    """``NBRDF.f`` at any directions (a renderer's, between the nodes a read checks): an output
    beyond 1e10 sr^-1 is the one-line error of the tabulation, not a number returned."""
    from gonio.io.nbrdf import NBRDF

    ks, bs = _network([4], 1)
    net = NBRDF("n", tuple(ks), tuple(bs), {"archive": "t.zip"})
    wi = np.array([[0.0, 0.6, 0.8], [0.0, 0.0, 1.0]])
    assert np.all(np.isfinite(net.f(wi, wi[::-1])))
    ks[0] = ks[0].copy()
    ks[0][2, :] = 900.0  # cos(theta_h) * 900 through the layers: exp overflows
    net = NBRDF("n", tuple(ks), tuple(bs), {"archive": "t.zip"})
    with pytest.raises(FormatError, match=r"^t.zip: n: network output: .*(NaN/Inf|beyond)"):
        net.f(wi, wi[::-1])
