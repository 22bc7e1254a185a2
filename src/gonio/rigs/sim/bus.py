"""A chain of emulated X-series servos answering Dynamixel Protocol 2.0 on a pseudo-terminal.

The emulator owns the pty master; the driver opens the slave path (``emulator.port``) with
``dynamixel_sdk.PortHandler`` like any USB serial adapter. A background thread decodes instruction
packets byte-exactly (:mod:`gonio.rigs.protocol`), applies them to per-servo control tables and
answers with status packets. Motion follows the trapezoidal profile set by Profile Velocity and
Profile Acceleration; ``time_scale`` makes simulated time run faster than wall time so tests are
quick. Faults can be injected: dropped instructions, garbled replies, CRC errors, overload with
torque shutdown, any hardware error bit (:meth:`ServoChainEmulator.hardware_error`), a joint
blocked short of its goal (:meth:`ServoChainEmulator.block`), a servo that stops answering.
Every Goal Position write that reaches a servo is recorded in
:attr:`ServoChainEmulator.goal_log` (and optionally appended to a JSON-lines file) so tests can
prove that no goal beyond the limits was ever sent.
A file log that cannot be
written (a full disk) stops, whole up to its last line, and says so in
:attr:`ServoChainEmulator.file_log_error`; the bus never stops answering for it.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import random
import select
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from gonio.errors import ParameterError
from gonio.io.storage import append_whole
from gonio.io.strict_json import dumps_json
from gonio.rigs import control_table as ct
from gonio.rigs import protocol as p
from gonio.rigs.sim.pty_device import PtyDevice


@dataclass(frozen=True)
class ServoSpec:
    """One emulated servo: bus id, model name (see :data:`control_table.MODELS`), firmware."""

    id: int
    model: str = "XM430-W350"
    firmware: int = 52
    initial_position: int = ct.CENTER_TICK


@dataclass
class FaultConfig:
    """Probabilities (per packet) and switches of injected faults.

    Attributes
    ----------
    drop : float
        Probability that an instruction packet is lost (no servo acts on it or answers).
    garble : float
        Probability that a status packet is corrupted on the way back (one byte flipped).
    crc : float
        Probability that an instruction arrives with a bad CRC (the servo answers ``ERR_CRC``
        and does not act).
    overload : float
        Probability that a move ends in an overload: the servo sets Hardware Error Status bit 5,
        switches torque off and stops where it is.
    seed : int
        Seed of the fault generator.
    block_servo : int
        Id of a servo whose joint meets an obstacle (0: none): after ``block_after`` moves, its
        next move stops half-way, torque on, short of its goal (:meth:`ServoChainEmulator.block`).
    block_after : int
        Moves the blocked servo makes normally before it meets the obstacle.
    """

    drop: float = 0.0
    garble: float = 0.0
    crc: float = 0.0
    overload: float = 0.0
    seed: int = 0
    block_servo: int = 0
    block_after: int = 0


def parse_faults(spec: str):
    """'drop=0.02,crc=0.01,seed=3' -> FaultConfig; ParameterError on bad input."""
    kw: dict = {}
    ints = ("seed", "block_servo", "block_after")
    keys = ("drop", "garble", "crc", "overload", *ints)
    for part in filter(None, (s.strip() for s in spec.split(","))):
        key, sep, val = part.partition("=")
        if not sep or key not in keys:
            raise ParameterError(f"--sim-faults: bad item {part!r} (keys: {', '.join(keys)})")
        try:
            kw[key] = int(val) if key in ints else float(val)
        except ValueError:
            raise ParameterError(f"--sim-faults: {key} needs a number, got {val!r}") from None
        if key in ints and not 0 <= kw[key] <= 2**63 - 1:
            raise ParameterError(f"--sim-faults: {key} must be >= 0")
        if key not in ints and not 0.0 <= kw[key] <= 1.0:
            raise ParameterError(f"--sim-faults: {key} must be a probability in [0, 1]")
    return FaultConfig(**kw)


@dataclass(frozen=True)
class GoalRecord:
    """A Goal Position write as received by a servo (raw ticks, wall time, accepted or not)."""

    time: float
    id: int
    ticks: int
    accepted: bool


@dataclass(frozen=True)
class PacketRecord:
    """An instruction packet as the bus carried it (wall time, id, instruction, parameters).

    Recorded before any fault is injected, so the log is what the driver *sent*.
    """

    time: float
    id: int
    instruction: int
    params: bytes

    def writes(self, reg: tuple[int, int]) -> list[tuple[int, int]]:
        """``(servo id, value)`` of every write of register ``reg`` this packet carries
        (Write and Sync Write instructions whose data covers the register)."""
        a, n = reg
        prm = self.params
        if self.instruction == p.WRITE and len(prm) >= 2:
            addr = p.from_le(prm[0:2])
            data = prm[2:]
            if addr <= a and a + n <= addr + len(data):
                return [(self.id, p.from_le(data[a - addr : a - addr + n], signed=n == 4))]
            return []
        if self.instruction == p.SYNC_WRITE and len(prm) >= 4:
            addr, size = p.from_le(prm[0:2]), p.from_le(prm[2:4])
            if not (addr <= a and a + n <= addr + size):
                return []
            out, i = [], 4
            while i + 1 + size <= len(prm):
                d = prm[i + 1 + a - addr : i + 1 + a - addr + n]
                out.append((prm[i], p.from_le(d, signed=n == 4)))
                i += 1 + size
            return out
        return []


@dataclass
class _Servo:
    spec: ServoSpec
    table: bytearray
    clock: object
    settle_ticks: int
    seed: int
    move_start: float = 0.0
    move_from: float = 0.0
    move_to: float = 0.0
    move_v: float = 1.0
    move_a: float = 0.0
    move_T: float = 0.0
    ring_amp: float = 0.0
    ring_T: float = 0.0
    frozen_at: float | None = None
    dead_until: float = 0.0
    #: hardware error bits that latch half-way through the current move
    pending_bits: int = 0
    #: hardware error bits to latch half-way through the next move
    next_move_bits: int = 0
    ring_time: float = 0.12
    #: an obstacle the joint cannot pass (ticks), once met; None: free
    obstacle: float | None = None
    #: moves left before the joint meets an obstacle half-way through its move (None: never)
    block_in: int | None = None

    # --- register helpers -------------------------------------------------------------------
    def get(self, reg: tuple[int, int], signed: bool = False) -> int:
        a, n = reg
        return p.from_le(self.table[a : a + n], signed=signed)

    def set(self, reg: tuple[int, int], value: int) -> None:
        a, n = reg
        self.table[a : a + n] = int(value & ((1 << (8 * n)) - 1)).to_bytes(n, "little")

    # --- motion -------------------------------------------------------------------------------
    def settle_error(self, goal: int) -> int:
        """Where the servo comes to rest relative to ``goal`` (ticks).

        Deterministic per (seed, servo, goal): the same goal always ends at the same tick, so a
        resumed run reads back exactly what an uninterrupted one would.
        """
        h = hashlib.blake2s(f"{self.seed}:{self.spec.id}:{goal}".encode(), digest_size=2).digest()
        return (int.from_bytes(h, "little") % (2 * self.settle_ticks + 1)) - self.settle_ticks

    def position(self, now: float) -> float:
        if self.frozen_at is not None:
            return self.frozen_at
        t = now - self.move_start
        pos = self.move_from + ct.trapezoid_position(
            self.move_to - self.move_from, self.move_v, self.move_a, t
        )
        tr = t - self.move_T
        if 0.0 <= tr < self.ring_T:
            # ringing after the profile: a damped oscillation about the final position that
            # ends exactly at ring_T (so the settled position does not depend on timing)
            x = tr / self.ring_T
            pos += self.ring_amp * (1.0 - x) ** 2 * math.cos(3.0 * math.pi * x)
        return pos

    def profile_ongoing(self, now: float) -> bool:
        return self.frozen_at is None and now - self.move_start < self.move_T

    def moving(self, now: float) -> bool:
        return self.frozen_at is None and now - self.move_start < self.move_T + self.ring_T

    def stop(self, now: float) -> None:
        self.frozen_at = self.position(now)

    def latch(self, bits: int, now: float) -> None:
        """Latch hardware error ``bits``; a bit of the Shutdown register also stops the servo
        and switches its torque off."""
        self.set(ct.HARDWARE_ERROR_STATUS, self.get(ct.HARDWARE_ERROR_STATUS) | bits)
        if bits & self.get(ct.SHUTDOWN):
            self.stop(now)
            self.set(ct.TORQUE_ENABLE, 0)

    def start_move(self, goal: int, now: float, overload: bool) -> None:
        here = self.position(now)
        err = self.settle_error(goal)
        v_raw = self.get(ct.PROFILE_VELOCITY) or self.get(ct.VELOCITY_LIMIT) or 200
        a_raw = self.get(ct.PROFILE_ACCELERATION)
        tick_per_deg = ct.TICKS_PER_REV / 360.0
        self.move_v = ct.velocity_raw_to_deg_s(v_raw) * tick_per_deg
        self.move_a = ct.acceleration_raw_to_deg_s2(a_raw) * tick_per_deg if a_raw else 0.0
        self.move_from = here
        self.move_to = float(goal + err)
        if self.block_in is not None and abs(self.move_to - here) > 20:
            if self.block_in == 0:
                self.obstacle = here + 0.5 * (self.move_to - here)
                self.block_in = None
            else:
                self.block_in -= 1
        ob = self.obstacle
        if ob is not None and min(here, self.move_to) < ob < max(here, self.move_to):
            self.move_to = ob  # stalls against the obstacle, torque on, short of its goal
        self.move_start = now
        self.move_T = ct.trapezoid_time(self.move_to - here, self.move_v, self.move_a)
        # overshoot grows with the cruise speed reached; moves of a few ticks do not ring
        dist = abs(self.move_to - here)
        if dist > 8 and self.move_to != ob:
            v_peak = min(self.move_v, math.sqrt(dist * self.move_a) if self.move_a else self.move_v)
            self.ring_amp = math.copysign(min(6.0, 1.0 + v_peak / 400.0), self.move_to - here)
            self.ring_T = self.ring_time
        else:
            self.ring_amp, self.ring_T = 0.0, 0.0
        self.frozen_at = None
        self.pending_bits = (ct.HW_OVERLOAD if overload else 0) | self.next_move_bits
        self.next_move_bits = 0

    def refresh(self, now: float) -> None:
        """Update the dynamic registers (and latch a pending hardware error) at time ``now``."""
        if self.pending_bits and now - self.move_start >= 0.5 * self.move_T:
            self.latch(self.pending_bits, now)
            self.pending_bits = 0
        pos = self.position(now)
        self.set(ct.PRESENT_POSITION, round(pos))
        mv = self.moving(now)
        self.set(ct.MOVING, 1 if mv else 0)
        # Moving Status: bit 0 in position, bit 1 profile ongoing, bits 4-5 trapezoidal profile
        in_pos = abs(pos - self.get(ct.GOAL_POSITION, signed=True)) <= 3
        status = (0x01 if in_pos and not mv else 0) | (0x02 if self.profile_ongoing(now) else 0)
        self.set(ct.MOVING_STATUS, status | 0x30)
        self.set(ct.PRESENT_VELOCITY, round(self.move_v / (ct.TICKS_PER_REV / 360.0)) if mv else 0)
        self.set(ct.REALTIME_TICK, int(now * 1000) % 32768)


def _default_table(spec: ServoSpec) -> bytearray:
    t = bytearray(ct.TABLE_SIZE)
    s = _Servo(spec, t, None, 0, 0)
    s.set(ct.MODEL_NUMBER, ct.MODELS[spec.model])
    s.set(ct.FIRMWARE_VERSION, spec.firmware)
    s.set(ct.ID, spec.id)
    s.set(ct.BAUD_RATE, 3)  # 1 Mbps
    s.set(ct.RETURN_DELAY_TIME, 250)
    s.set(ct.OPERATING_MODE, ct.MODE_POSITION)
    s.set(ct.MOVING_THRESHOLD, 10)
    s.set(ct.TEMPERATURE_LIMIT, 80)
    s.set(ct.VELOCITY_LIMIT, 200)
    s.set(ct.MAX_POSITION_LIMIT, 4095)
    s.set(ct.MIN_POSITION_LIMIT, 0)
    s.set(ct.SHUTDOWN, ct.HW_OVERLOAD | ct.HW_ELECTRICAL_SHOCK | ct.HW_OVERHEATING)
    s.set(ct.STATUS_RETURN_LEVEL, 2)
    s.set(ct.PRESENT_INPUT_VOLTAGE, 120)
    s.set(ct.PRESENT_TEMPERATURE, 31)
    s.set(ct.GOAL_POSITION, spec.initial_position)
    s.set(ct.PRESENT_POSITION, spec.initial_position)
    return t


class ServoChainEmulator(PtyDevice):
    """Emulated Dynamixel X-series chain on a pseudo-terminal.

    Parameters
    ----------
    servos : sequence of ServoSpec
        The servos on the bus (distinct ids).
    faults : FaultConfig, optional
        Injected faults; none by default.
    time_scale : float
        Simulated seconds per wall-clock second (``> 0``); 1 is real time.
    settle_ticks : int
        Maximum settling error in encoder ticks (0.088 deg each); the error for a goal is
        deterministic per (seed, servo, goal).
    seed : int
        Seed of the settling errors.
    goal_log_path : path, optional
        JSON-lines file to which every received Goal Position write is appended (flushed).
    packet_log_path : path, optional
        JSON-lines file to which every decoded instruction packet is appended (flushed):
        ``{"t", "id", "inst", "params" (hex)}``; :func:`read_packet_log` reads it back.

    Use as a context manager, or call :meth:`start` / :meth:`stop`. :attr:`port` is the path the
    driver opens.
    """

    thread_name = "dxl-emulator"

    def __init__(
        self,
        servos,
        faults: FaultConfig | None = None,
        time_scale: float = 1.0,
        settle_ticks: int = 2,
        seed: int = 0,
        goal_log_path: str | os.PathLike | None = None,
        packet_log_path: str | os.PathLike | None = None,
    ) -> None:
        if time_scale <= 0:
            raise ValueError("time_scale must be > 0")
        super().__init__()
        self.faults = faults or FaultConfig()
        self.time_scale = float(time_scale)
        self._t0 = time.monotonic()
        self._servos: dict[int, _Servo] = {}
        for spec in servos:
            if spec.id in self._servos:
                raise ValueError(f"duplicate servo id {spec.id}")
            if spec.model not in ct.MODELS:
                raise ValueError(f"unknown servo model {spec.model!r}")
            servo = _Servo(spec, _default_table(spec), self.now, settle_ticks, seed)
            # powered on where the last session left it: at rest after a move to
            # initial_position (e.g. parked), Goal Position = Present Position
            rest = spec.initial_position + servo.settle_error(spec.initial_position)
            servo.frozen_at = float(rest)
            servo.set(ct.PRESENT_POSITION, rest)
            servo.set(ct.GOAL_POSITION, rest)
            self._servos[spec.id] = servo
        self._rng = random.Random(self.faults.seed)
        if self.faults.block_servo:
            if self.faults.block_servo not in self._servos:
                raise ValueError(f"block_servo: no servo {self.faults.block_servo} on the bus")
            self._servos[self.faults.block_servo].block_in = int(self.faults.block_after)
        self._lock = threading.Lock()
        self.goal_log: list[GoalRecord] = []
        #: every decoded instruction packet, in order (see :class:`PacketRecord`)
        self.packet_log: list[PacketRecord] = []
        self._packet_log_path = Path(packet_log_path) if packet_log_path else None
        self.packets_in = 0
        self.crc_errors_seen = 0
        self._goal_log_path = Path(goal_log_path) if goal_log_path else None
        #: the first failed write of a file log (goal or packet log), which then stopped
        self.file_log_error: OSError | None = None

    # --- lifecycle ---------------------------------------------------------------------------
    def now(self) -> float:
        """Simulated time in seconds since the emulator was created."""
        return (time.monotonic() - self._t0) * self.time_scale

    # --- fault and state control (thread-safe) -----------------------------------------------
    def kill(self, servo_id: int, duration_s: float = float("inf")) -> None:
        """Make a servo stop answering for ``duration_s`` wall-clock seconds (default: forever)."""
        with self._lock:
            self._servos[servo_id].dead_until = time.monotonic() + duration_s

    def revive(self, servo_id: int) -> None:
        with self._lock:
            self._servos[servo_id].dead_until = 0.0

    def overload(self, servo_id: int) -> None:
        """Trip an overload now: Hardware Error Status bit 5, torque off, motion stops."""
        self.hardware_error(servo_id, ct.HW_OVERLOAD)

    def hardware_error(self, servo_id: int, bits: int, next_move: bool = False) -> None:
        """Latch hardware error ``bits`` (Hardware Error Status) now, or half-way through the
        servo's next move (``next_move``), as the servo would.

        Every status packet then carries the alert bit. A bit in the servo's Shutdown register
        (overload, overheating, electrical shock by default) also switches torque off and stops
        the motion; the others leave the servo moving. Torque-on is refused until a reboot.
        """
        with self._lock:
            s = self._servos[servo_id]
            if next_move:
                s.next_move_bits |= bits
                return
            now = self.now()
            s.latch(bits, now)
            s.refresh(now)

    def block(self, servo_id: int, after_moves: int = 0) -> None:
        """Put an obstacle in a joint's way: after ``after_moves`` moves, its next move stops
        half-way, torque on, short of its goal, and no later move passes that point until
        :meth:`unblock` (a reboot does not move an obstacle)."""
        with self._lock:
            self._servos[servo_id].block_in = int(after_moves)

    def unblock(self, servo_id: int) -> None:
        with self._lock:
            s = self._servos[servo_id]
            s.obstacle, s.block_in = None, None

    def register(self, servo_id: int, reg: tuple[int, int], signed: bool = False) -> int:
        """Current value of a register of one servo (refreshed to now)."""
        with self._lock:
            s = self._servos[servo_id]
            s.refresh(self.now())
            return s.get(reg, signed=signed)

    def ids(self) -> list[int]:
        return sorted(self._servos)

    # --- serving -----------------------------------------------------------------------------
    def _serve(self) -> None:
        dec = p.StreamDecoder()
        last_rx = time.monotonic()
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([self._master], [], [], 0.02)
            except (OSError, ValueError):
                return
            if not ready:
                # A real servo drops a half-received packet after its receive timeout.
                if time.monotonic() - last_rx > 0.05:
                    dec.reset()
                continue
            try:
                data = os.read(self._master, 4096)
            except OSError:
                # EIO while no process holds the slave side; keep serving.
                time.sleep(0.005)
                continue
            last_rx = time.monotonic()
            dec.feed(data)
            for pkt in dec.packets():
                replies = self._handle(pkt)
                for reply in replies:
                    try:
                        os.write(self._master, reply)
                    except OSError:
                        pass

    def _chance(self, prob: float) -> bool:
        return prob > 0 and self._rng.random() < prob

    def _reply(self, servo: _Servo, error: int, params: bytes = b"") -> bytes:
        if servo.get(ct.HARDWARE_ERROR_STATUS):
            error |= p.ERR_ALERT
        raw = bytearray(p.status_packet(servo.spec.id, error, params))
        if self._chance(self.faults.garble):
            i = self._rng.randrange(7, len(raw))
            raw[i] ^= 1 << self._rng.randrange(8)
        return bytes(raw)

    def _alive(self, servo: _Servo) -> bool:
        return time.monotonic() >= servo.dead_until

    def _handle(self, pkt) -> list[bytes]:
        with self._lock:
            self.packets_in += 1
            now = self.now()
            if isinstance(pkt, p.CRCMismatch):
                self.crc_errors_seen += 1
                s = self._servos.get(pkt.id)
                if s is None or not self._alive(s):
                    return []
                return [self._reply(s, p.ERR_CRC)]
            self._log_packet(pkt)
            if self._chance(self.faults.drop):
                return []
            if self._chance(self.faults.crc):
                # the packet arrives corrupted: addressed servos answer "CRC error"; a broadcast
                # (sync read/write) is ignored, since a servo cannot tell it was meant for it
                self.crc_errors_seen += 1
                s = self._servos.get(pkt.id)
                if s is None or not self._alive(s):
                    return []
                return [self._reply(s, p.ERR_CRC)]
            for s in self._servos.values():
                s.refresh(now)
            if pkt.instruction == p.SYNC_WRITE:
                self._sync_write(pkt, now)
                return []
            if pkt.instruction == p.SYNC_READ:
                return self._sync_read(pkt)
            if pkt.id == p.BROADCAST_ID:
                if pkt.instruction == p.PING:
                    return [
                        self._reply(s, 0, self._ping_params(s))
                        for _, s in sorted(self._servos.items())
                        if self._alive(s)
                    ]
                return []
            s = self._servos.get(pkt.id)
            if s is None or not self._alive(s):
                return []
            return [self._unicast(s, pkt, now)]

    @staticmethod
    def _ping_params(s: _Servo) -> bytes:
        return p.u16(s.get(ct.MODEL_NUMBER)) + bytes([s.get(ct.FIRMWARE_VERSION)])

    def _unicast(self, s: _Servo, pkt, now: float) -> bytes:
        inst = pkt.instruction
        if inst == p.PING:
            return self._reply(s, 0, self._ping_params(s))
        if inst == p.READ:
            if len(pkt.params) != 4:
                return self._reply(s, p.ERR_DATA_LENGTH)
            addr = p.from_le(pkt.params[0:2])
            n = p.from_le(pkt.params[2:4])
            if addr + n > ct.TABLE_SIZE:
                return self._reply(s, p.ERR_ACCESS)
            return self._reply(s, 0, bytes(s.table[addr : addr + n]))
        if inst == p.WRITE:
            if len(pkt.params) < 3:
                return self._reply(s, p.ERR_DATA_LENGTH)
            addr = p.from_le(pkt.params[0:2])
            err = self._write(s, addr, bytes(pkt.params[2:]), now)
            return self._reply(s, err)
        if inst == p.REBOOT:
            self._reboot(s, now)
            return self._reply(s, 0)
        return self._reply(s, p.ERR_INSTRUCTION)

    def _sync_write(self, pkt, now: float) -> None:
        prm = pkt.params
        if len(prm) < 4:
            return
        addr = p.from_le(prm[0:2])
        n = p.from_le(prm[2:4])
        i = 4
        while i + 1 + n <= len(prm):
            s = self._servos.get(prm[i])
            if s is not None and self._alive(s):
                self._write(s, addr, bytes(prm[i + 1 : i + 1 + n]), now)
            i += 1 + n

    def _sync_read(self, pkt) -> list[bytes]:
        prm = pkt.params
        if len(prm) < 5:
            return []
        addr = p.from_le(prm[0:2])
        n = p.from_le(prm[2:4])
        out = []
        for sid in prm[4:]:
            s = self._servos.get(sid)
            if s is None or not self._alive(s):
                # The chain stalls at a silent servo: later ones wait for its reply.
                break
            if addr + n > ct.TABLE_SIZE:
                out.append(self._reply(s, p.ERR_ACCESS))
            else:
                out.append(self._reply(s, 0, bytes(s.table[addr : addr + n])))
        return out

    def _write(self, s: _Servo, addr: int, data: bytes, now: float) -> int:
        end = addr + len(data)
        if end > ct.TABLE_SIZE:
            return p.ERR_ACCESS
        torque = s.get(ct.TORQUE_ENABLE)
        goal_a = ct.GOAL_POSITION[0]
        if addr < ct.EEPROM_END and torque:
            return p.ERR_ACCESS
        if addr <= goal_a < end:
            if end < goal_a + 4:
                return p.ERR_DATA_LENGTH
            goal = p.from_le(data[goal_a - addr : goal_a - addr + 4], signed=True)
            mode = s.get(ct.OPERATING_MODE)
            lo, hi = ct.POSITION_RANGE.get(mode, ct.POSITION_RANGE[ct.MODE_POSITION])
            if mode == ct.MODE_POSITION:
                lo = max(lo, s.get(ct.MIN_POSITION_LIMIT, signed=True))
                hi = min(hi, s.get(ct.MAX_POSITION_LIMIT, signed=True))
            ok = lo <= goal <= hi
            self._log_goal(s.spec.id, goal, ok)
            if not ok:
                return p.ERR_DATA_LIMIT
        if addr <= ct.HARDWARE_ERROR_STATUS[0] < end or addr <= ct.MODEL_NUMBER[0] + 1 < end:
            return p.ERR_ACCESS  # read-only registers
        if (
            addr <= ct.TORQUE_ENABLE[0] < end
            and data[ct.TORQUE_ENABLE[0] - addr]
            and s.get(ct.HARDWARE_ERROR_STATUS)
        ):
            return p.ERR_RESULT_FAIL  # torque cannot be enabled until the error is cleared
        s.table[addr:end] = data
        if addr <= ct.TORQUE_ENABLE[0] < end:
            if data[ct.TORQUE_ENABLE[0] - addr]:
                # Torque on: hold the present position (the e-Manual: Goal := Present).
                s.set(ct.GOAL_POSITION, round(s.position(now)))
                s.frozen_at = s.position(now)
            else:
                s.stop(now)
        if addr <= goal_a < end and s.get(ct.TORQUE_ENABLE):
            s.start_move(
                s.get(ct.GOAL_POSITION, signed=True), now, self._chance(self.faults.overload)
            )
        s.refresh(now)
        return 0

    def _reboot(self, s: _Servo, now: float) -> None:
        pos = round(s.position(now))
        eeprom = bytes(s.table[: ct.EEPROM_END])
        fresh = _default_table(s.spec)
        fresh[: ct.EEPROM_END] = eeprom
        s.table[:] = fresh
        s.frozen_at = float(pos)
        s.pending_bits = 0
        s.set(ct.GOAL_POSITION, pos)
        s.refresh(now)

    def _log_packet(self, pkt) -> None:
        rec = PacketRecord(time.time(), pkt.id, pkt.instruction, bytes(pkt.params))
        self.packet_log.append(rec)
        if self._packet_log_path is not None:
            d = {"t": rec.time, "id": rec.id, "inst": rec.instruction, "params": rec.params.hex()}
            self._packet_log_path = self._append(self._packet_log_path, d)

    def writes(self, reg: tuple[int, int]) -> list[tuple[int, int]]:
        """``(servo id, value)`` of every write of ``reg`` sent on the bus so far, in order."""
        with self._lock:
            return [w for rec in self.packet_log for w in rec.writes(reg)]

    def _log_goal(self, servo_id: int, ticks: int, accepted: bool) -> None:
        rec = GoalRecord(time.time(), servo_id, ticks, accepted)
        self.goal_log.append(rec)
        if self._goal_log_path is not None:
            d = {"t": rec.time, "id": servo_id, "ticks": ticks, "ok": accepted}
            self._goal_log_path = self._append(self._goal_log_path, d)

    def _append(self, path: Path, record: dict) -> Path | None:
        """Append ``record`` as one line to a file log; returns the path, or None once a write
        failed (a full disk): that file log stops there, cut back to its last whole line, and
        :attr:`file_log_error` keeps the failure, while the bus goes on answering and the
        in-memory logs stay complete."""
        try:
            fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_CLOEXEC, 0o666)
            try:
                append_whole(fd, (dumps_json(record) + "\n").encode())
            finally:
                os.close(fd)
        except OSError as exc:
            self.file_log_error = self.file_log_error or OSError(exc.errno, exc.strerror, str(path))
            return None
        return path


def read_packet_log(path: str | os.PathLike) -> list[PacketRecord]:
    """The :class:`PacketRecord` list of a JSON-lines packet log (``packet_log_path``)."""
    out = []
    for line in Path(path).read_text(encoding="utf-8").splitlines():
        if line.strip():
            d = json.loads(line)
            out.append(PacketRecord(d["t"], d["id"], d["inst"], bytes.fromhex(d["params"])))
    return out
