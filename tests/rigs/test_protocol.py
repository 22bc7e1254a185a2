"""Golden packets from the ROBOTIS Protocol 2.0 e-Manual examples, and stuffing/decoder checks."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from gonio.rigs import protocol as p

# (description, bytes) pairs as printed in the e-Manual's examples.
GOLDEN = {
    "ping id1": "FF FF FD 00 01 03 00 01 19 4E",
    "ping status model 1030 fw 38": "FF FF FD 00 01 07 00 55 00 06 04 26 65 5D",
    "read present position id1": "FF FF FD 00 01 07 00 02 84 00 04 00 1D 15",
    "read status 166": "FF FF FD 00 01 08 00 55 00 A6 00 00 00 8C C0",
    "write goal 512 id1": "FF FF FD 00 01 09 00 03 74 00 00 02 00 00 CA 89",
    "empty status id1": "FF FF FD 00 01 04 00 55 00 A1 0C",
    "reboot id1": "FF FF FD 00 01 03 00 08 2F 4E",
    "sync read 132x4 ids 1 2": "FF FF FD 00 FE 09 00 82 84 00 04 00 01 02 CE FA",
    "sync write 116 ids 1=150 2=170": (
        "FF FF FD 00 FE 11 00 83 74 00 04 00 01 96 00 00 00 02 AA 00 00 00 82 87"
    ),
    "sync read status id2 2079": "FF FF FD 00 02 08 00 55 00 1F 08 00 00 BA BE",
}


def golden(name: str) -> bytes:
    return bytes.fromhex(GOLDEN[name])


def test_crc_of_ping_example():
    raw = golden("ping id1")
    assert p.crc16(raw[:-2]) == 0x4E19


@pytest.mark.parametrize(
    ("name", "built"),
    [
        ("ping id1", lambda: p.encode(1, p.PING)),
        ("ping status model 1030 fw 38", lambda: p.status_packet(1, 0, p.u16(1030) + bytes([38]))),
        ("read present position id1", lambda: p.encode(1, p.READ, p.u16(132) + p.u16(4))),
        ("read status 166", lambda: p.status_packet(1, 0, p.u32(166))),
        ("write goal 512 id1", lambda: p.encode(1, p.WRITE, p.u16(116) + p.u32(512))),
        ("empty status id1", lambda: p.status_packet(1, 0)),
        ("reboot id1", lambda: p.encode(1, p.REBOOT)),
        (
            "sync read 132x4 ids 1 2",
            lambda: p.encode(p.BROADCAST_ID, p.SYNC_READ, p.u16(132) + p.u16(4) + bytes([1, 2])),
        ),
        (
            "sync write 116 ids 1=150 2=170",
            lambda: p.encode(
                p.BROADCAST_ID,
                p.SYNC_WRITE,
                p.u16(116) + p.u16(4) + bytes([1]) + p.u32(150) + bytes([2]) + p.u32(170),
            ),
        ),
        ("sync read status id2 2079", lambda: p.status_packet(2, 0, p.u32(2079))),
    ],
)
def test_encoder_matches_manual(name, built):
    assert built() == golden(name)


def test_decode_manual_packets():
    pk = p.decode(golden("ping status model 1030 fw 38"))
    assert pk.is_status and pk.id == 1 and pk.error == 0
    assert p.from_le(pk.params[:2]) == 1030 and pk.params[2] == 38
    pk = p.decode(golden("write goal 512 id1"))
    assert pk.instruction == p.WRITE and p.from_le(pk.params[2:]) == 512


def test_bad_crc_is_reported():
    raw = bytearray(golden("ping id1"))
    raw[-1] ^= 0x01
    with pytest.raises(p.CRCMismatch):
        p.decode(bytes(raw))


def test_stuffing_inserts_fd_and_length_counts_it():
    params = bytes([0xFF, 0xFF, 0xFD, 0x01])
    raw = p.encode(1, p.WRITE, p.u16(200) + params)
    assert b"\xff\xff\xfd\xfd" in raw[7:]
    assert p.from_le(raw[5:7]) == len(raw) - 7
    assert p.decode(raw).params == p.u16(200) + params


@given(st.binary(max_size=60), st.integers(0, 252))
def test_encode_decode_roundtrip(params, pid):
    raw = p.encode(pid, p.WRITE, params)
    body = raw[7:-2]
    # after stuffing, every FF FF FD inside the body is followed by the stuffing FD
    i = body.find(b"\xff\xff\xfd")
    while i >= 0:
        assert body[i + 3 : i + 4] == b"\xfd"
        i = body.find(b"\xff\xff\xfd", i + 4)
    pk = p.decode(raw)
    assert (pk.id, pk.instruction, pk.params) == (pid, p.WRITE, params)


@given(st.binary(max_size=80))
def test_unstuff_inverts_stuff(body):
    assert p.unstuff(p.stuff(body)) == body


def test_stream_decoder_resyncs_after_noise_and_split_chunks():
    dec = p.StreamDecoder()
    stream = b"\x00\x13\xff" + golden("ping id1") + golden("reboot id1")
    for i in range(0, len(stream), 3):
        dec.feed(stream[i : i + 3])
    got = list(dec.packets())
    assert [g.instruction for g in got] == [p.PING, p.REBOOT]


@given(
    st.lists(st.tuples(st.integers(0, 252), st.binary(max_size=24)), min_size=1, max_size=6),
    st.lists(st.binary(max_size=8).filter(lambda b: b"\xff" not in b), min_size=7, max_size=7),
    st.integers(1, 9),
)
def test_stream_decoder_finds_every_packet_between_noise(packets, noise, chunk):
    stream = b""
    for (pid, params), junk in zip(packets, noise, strict=False):
        stream += junk + p.encode(pid, p.WRITE, params)
    dec = p.StreamDecoder()
    got = []
    for i in range(0, len(stream), chunk):
        dec.feed(stream[i : i + chunk])
        got.extend(dec.packets())
    assert [(g.id, g.params) for g in got] == packets
