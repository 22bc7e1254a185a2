"""Dynamixel Protocol 2.0 wire format: CRC-16, byte stuffing, instruction and status packets.

This module is the byte-level vocabulary shared by the bus emulator (:mod:`gonio.rigs.sim.bus`)
and the tests. The driver itself (:mod:`gonio.rigs.dynamixel`) never builds packets: it goes
through ``dynamixel_sdk``, exactly as on hardware.

Packet layout (all multi-byte fields little-endian)::

    FF FF FD 00 | ID | LEN_L LEN_H | INST | PARAMS ... | CRC_L CRC_H

``LEN`` counts the instruction byte, the (stuffed) parameters and the two CRC bytes. A status
packet has ``INST = 0x55`` followed by an error byte. The CRC is CRC-16 with polynomial 0x8005
(no reflection, initial value 0) over everything from the first header byte to the last
parameter byte, computed *after* byte stuffing. Stuffing inserts an extra ``FD`` after every
``FF FF FD`` inside the instruction/parameter field so that the header never appears there.
"""

from __future__ import annotations

from dataclasses import dataclass

HEADER = b"\xff\xff\xfd\x00"
BROADCAST_ID = 0xFE

# Instructions.
PING = 0x01
READ = 0x02
WRITE = 0x03
REG_WRITE = 0x04
ACTION = 0x05
FACTORY_RESET = 0x06
REBOOT = 0x08
CLEAR = 0x10
STATUS = 0x55
SYNC_READ = 0x82
SYNC_WRITE = 0x83
BULK_READ = 0x92
BULK_WRITE = 0x93

# Error numbers carried in the low 7 bits of a status packet's error byte.
ERR_RESULT_FAIL = 1
ERR_INSTRUCTION = 2
ERR_CRC = 3
ERR_DATA_RANGE = 4
ERR_DATA_LENGTH = 5
ERR_DATA_LIMIT = 6
ERR_ACCESS = 7
#: Set in every status packet while the Hardware Error Status register is non-zero.
ERR_ALERT = 0x80


def _crc_table() -> tuple[int, ...]:
    # Generated from the polynomial rather than pasted: a 256-entry literal is easy to mistype
    # and this is the whole of the algorithm (MSB-first CRC-16, poly 0x8005).
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return tuple(table)


_CRC_TABLE = _crc_table()


def crc16(data: bytes | bytearray, crc: int = 0) -> int:
    """CRC-16 of Dynamixel Protocol 2.0 (poly 0x8005, init 0, MSB first) over ``data``."""
    for b in data:
        crc = ((crc << 8) ^ _CRC_TABLE[((crc >> 8) ^ b) & 0xFF]) & 0xFFFF
    return crc


def stuff(body: bytes) -> bytes:
    """Insert ``FD`` after every ``FF FF FD`` in ``body`` (instruction + parameters)."""
    out = bytearray()
    for b in body:
        out.append(b)
        if b == 0xFD and len(out) >= 3 and out[-3] == 0xFF and out[-2] == 0xFF:
            out.append(0xFD)
    return bytes(out)


def unstuff(body: bytes) -> bytes:
    """Remove the ``FD`` inserted by :func:`stuff` (``FF FF FD FD`` -> ``FF FF FD``)."""
    out = bytearray()
    i = 0
    while i < len(body):
        b = body[i]
        out.append(b)
        if (
            b == 0xFD
            and len(out) >= 3
            and out[-3] == 0xFF
            and out[-2] == 0xFF
            and i + 1 < len(body)
            and body[i + 1] == 0xFD
        ):
            i += 1  # skip the stuffing byte
        i += 1
    return bytes(out)


def encode(packet_id: int, instruction: int, params: bytes = b"") -> bytes:
    """Build a complete packet (header, id, length, stuffed body, CRC)."""
    if not 0 <= packet_id <= 0xFE:
        raise ValueError(f"packet id {packet_id} out of range 0..254")
    body = stuff(bytes([instruction]) + bytes(params))
    length = len(body) + 2
    head = HEADER + bytes([packet_id, length & 0xFF, length >> 8])
    crc = crc16(head + body)
    return head + body + bytes([crc & 0xFF, crc >> 8])


def instruction_packet(packet_id: int, instruction: int, params: bytes = b"") -> bytes:
    """An instruction packet (alias of :func:`encode`, named for readability at call sites)."""
    return encode(packet_id, instruction, params)


def status_packet(packet_id: int, error: int = 0, params: bytes = b"") -> bytes:
    """A status packet: instruction 0x55, then the error byte, then the parameters."""
    return encode(packet_id, STATUS, bytes([error]) + bytes(params))


@dataclass(frozen=True)
class Packet:
    """A decoded packet: ``params`` is unstuffed and, for status packets, excludes the error."""

    id: int
    instruction: int
    params: bytes
    error: int = 0

    @property
    def is_status(self) -> bool:
        return self.instruction == STATUS


class CRCMismatch(ValueError):
    """A complete packet arrived whose CRC does not match (the receiver answers ERR_CRC)."""

    def __init__(self, packet_id: int, instruction: int) -> None:
        super().__init__(f"CRC mismatch in packet for id {packet_id}")
        self.id = packet_id
        self.instruction = instruction


class StreamDecoder:
    """Incremental decoder of a byte stream into packets.

    Feed arbitrary chunks with :meth:`feed`; :meth:`packets` yields each complete packet in
    order, or a :class:`CRCMismatch` instance in its place. Bytes before a header are skipped, as
    a servo does on a shared bus.
    """

    #: Longest packet accepted; anything longer is treated as line noise.
    MAX_LENGTH = 1024

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> None:
        self._buf.extend(data)

    def reset(self) -> None:
        self._buf.clear()

    def packets(self):
        """Yield :class:`Packet` or :class:`CRCMismatch` for each complete packet buffered."""
        buf = self._buf
        while True:
            start = buf.find(HEADER[:3])
            if start < 0:
                # keep a possible partial header at the end
                keep = 2 if buf.endswith(b"\xff\xff") else (1 if buf.endswith(b"\xff") else 0)
                del buf[: len(buf) - keep]
                return
            if start:
                del buf[:start]
            if len(buf) < 7:
                return
            if buf[3] != 0x00:  # "FF FF FD FD" is stuffed data, not a header
                del buf[:1]
                continue
            length = buf[5] | (buf[6] << 8)
            if length < 3 or length > self.MAX_LENGTH:
                del buf[:1]
                continue
            total = 7 + length
            if len(buf) < total:
                return
            raw = bytes(buf[:total])
            del buf[:total]
            crc = raw[-2] | (raw[-1] << 8)
            if crc16(raw[:-2]) != crc:
                yield CRCMismatch(raw[4], raw[7])
                continue
            body = unstuff(raw[7:-2])
            inst = body[0]
            if inst == STATUS:
                if len(body) < 2:
                    continue
                yield Packet(raw[4], inst, body[2:], body[1])
            else:
                yield Packet(raw[4], inst, body[1:])


def decode(raw: bytes) -> Packet:
    """Decode exactly one complete packet; raise ``ValueError`` if it is not one."""
    dec = StreamDecoder()
    dec.feed(raw)
    out = list(dec.packets())
    if len(out) != 1:
        raise ValueError(f"expected one packet, found {len(out)}")
    if isinstance(out[0], CRCMismatch):
        raise out[0]
    return out[0]


def u16(v: int) -> bytes:
    return int(v & 0xFFFF).to_bytes(2, "little")


def u32(v: int) -> bytes:
    return int(v & 0xFFFFFFFF).to_bytes(4, "little")


def from_le(data: bytes, signed: bool = False) -> int:
    return int.from_bytes(bytes(data), "little", signed=signed)
