"""Defects the fuzzer found in the neural-BRDF reader, one constructed input each: a typed
one-line error naming the archive, never a raw exception, a memory blow-up or a silent load."""

from __future__ import annotations

import io as _io
import json
import zipfile

import h5py
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
    _refused(_archive(tmp_path, h5=buf.getvalue()), r"has shape \(1099511627776, 3\)")


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
