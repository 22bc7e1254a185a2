"""Dynamixel X-series servo driver over the real ``dynamixel_sdk`` (Protocol 2.0).

Two layers:

* :class:`~gonio.rigs.dxl_bus.DynamixelBus` (in :mod:`gonio.rigs.dxl_bus`, re-exported here) —
  transactions (ping, read, write, sync write, sync read, reboot) through
  ``dynamixel_sdk.PortHandler`` / ``PacketHandler(2.0)``, each retried with exponential backoff
  after a timeout, a corrupt reply or a CRC error reported by the servo.
* :class:`ServoChain` — joints from a rig file: identify models, configure operating mode and
  motion profile, check software limits **before** sending anything, sync-write all goals at
  once, poll (sync read) until every joint has settled, and return the positions actually
  reached as read back from the servos. Every goal passes :class:`gonio.rigs.guard.GoalGuard`
  at the last moment before its packet is written.

A hardware error (the alert bit of a status packet, then register 70) raises
:class:`~gonio.rigs.faults.HardwareFault`, a joint that does not reach its goal in time
:class:`~gonio.rigs.faults.MotionTimeout`, a latched error found when the rig is initialized
:class:`~gonio.rigs.faults.LatchedAtOpen`; what happens then is the policy table of
:mod:`gonio.rigs.faults`. Nothing here reboots a servo except :meth:`ServoChain.reboot`, which
only ``gonio rig reboot`` calls.

Angles at this interface are joint angles in **degrees** keyed by joint name (the rig file's
unit); the kinematics layer converts to radians.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass

import numpy as np

from gonio.errors import DeviceError, Interrupted, PlanError
from gonio.rigs import control_table as ct
from gonio.rigs.config import JointConfig, RigConfig
from gonio.rigs.dxl_bus import BusLost, BusStats, DynamixelBus
from gonio.rigs.faults import HardwareFault, LatchedAtOpen, MotionTimeout
from gonio.rigs.guard import GoalGuard

__all__ = [
    "BusLost",
    "BusStats",
    "DynamixelBus",
    "HardwareFault",
    "LatchedAtOpen",
    "MotionTimeout",
    "MoveResult",
    "ServoChain",
    "ServoInfo",
]

log = logging.getLogger("gonio.rigs.dynamixel")


@dataclass(frozen=True)
class ServoInfo:
    """What ``rig check`` reports for one joint."""

    joint: str
    id: int
    model_number: int
    model: str
    firmware: int
    hardware_error: int
    torque: bool
    position_deg: float
    min_deg: float
    max_deg: float
    expected_model: str
    #: the alert bit (0x80) of the servo's status packets: a hardware error is latched
    alert: bool = False

    @property
    def ok(self) -> bool:
        return self.model == self.expected_model and self.hardware_error == 0 and not self.alert


@dataclass(frozen=True)
class MoveResult:
    """Outcome of one move: joint angles read back (deg) and timings (s)."""

    reached_deg: dict[str, float]
    motion_s: float
    settle_s: float
    polls: int
    #: reboots during the move: always 0 (a hardware error stops the run; gonio.rigs.faults)
    recoveries: int
    #: the profile time predicted for the move (rig time; both phases of a two-phase move)
    predicted_s: float = 0.0


class ServoChain:
    """The joints of a rig on one Dynamixel bus.

    Parameters
    ----------
    rig : RigConfig
        Validated rig file.
    port : str, optional
        Overrides ``rig.bus.port`` (the simulated rig passes the emulator's pty path).
    """

    def __init__(self, rig: RigConfig, port: str | None = None) -> None:
        self.rig = rig
        self.joints: tuple[JointConfig, ...] = rig.joints
        self.bus = DynamixelBus.from_config(rig.bus, port)
        self.guard = GoalGuard(rig)
        self.bus.goal_guard = self.guard.check
        self.ids = [j.id for j in self.joints]
        #: polled while a move settles; True aborts it (:class:`gonio.errors.Interrupted`)
        self.should_abort: Callable[[], bool] = lambda: False
        self._by_id = {j.id: j for j in self.joints}
        self.last_goal_ticks: dict[int, int] = {}
        #: moves split in two because the arms would have come too close on the way
        self.two_phase_moves = 0

    # --- setup --------------------------------------------------------------------------------
    def open(self) -> None:
        self.bus.open()

    def close(self) -> None:
        self.bus.close()

    def __enter__(self) -> ServoChain:
        self.open()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def check(self) -> list[ServoInfo]:
        """Ping every servo and read model, firmware, hardware error (register 70 and the
        alert bit of its status packets), torque and position. Moves and writes nothing."""
        out = []
        for j in self.joints:
            model = self.bus.ping(j.id)
            fw = self.bus.read(j.id, ct.FIRMWARE_VERSION)
            hw = self.bus.read(j.id, ct.HARDWARE_ERROR_STATUS)
            alert = j.id in self.bus.alerts
            tq = self.bus.read(j.id, ct.TORQUE_ENABLE)
            pos = self.bus.read(j.id, ct.PRESENT_POSITION, signed=True)
            out.append(
                ServoInfo(
                    j.name,
                    j.id,
                    model,
                    ct.MODEL_NAMES.get(model, f"unknown ({model})"),
                    fw,
                    hw,
                    bool(tq),
                    j.from_ticks(pos),
                    j.min_deg,
                    j.max_deg,
                    j.model,
                    alert,
                )
            )
        return out

    def _configure(self, j: JointConfig) -> None:
        mode = ct.OPERATING_MODES[j.operating_mode]
        self.bus.write(j.id, ct.TORQUE_ENABLE, 0)
        if self.bus.read(j.id, ct.OPERATING_MODE) != mode:
            self.bus.write(j.id, ct.OPERATING_MODE, mode)
        v = ct.deg_s_to_velocity_raw(j.profile_velocity_deg_s * j.gear_ratio)
        a = ct.deg_s2_to_acceleration_raw(j.profile_acceleration_deg_s2 * j.gear_ratio)
        self.bus.write(j.id, ct.PROFILE_ACCELERATION, a)
        self.bus.write(j.id, ct.PROFILE_VELOCITY, v)
        self.bus.write(j.id, ct.TORQUE_ENABLE, 1)

    def initialize(self) -> None:
        """Identify every servo, refuse latched hardware errors, set mode/profile, torque on.

        Every servo is identified and its Hardware Error Status read before any is written to:
        a wrong model anywhere in the chain refuses the rig with no torque on, and so does a
        latched hardware error (:class:`~gonio.rigs.faults.LatchedAtOpen`, after torque off on
        every servo; nothing is rebooted: the user clears it with ``gonio rig reboot``). If
        configuring fails part-way, torque is switched off again on every servo.
        """
        for j in self.joints:
            model = self.bus.ping(j.id)
            if model != ct.MODELS[j.model]:
                name = ct.MODEL_NAMES.get(model, f"model number {model}")
                raise DeviceError(
                    f"joint {j.name}: servo {j.id} is {name}, rig file says {j.model}"
                )
        latched = {}
        for j in self.joints:
            bits = self.bus.read(j.id, ct.HARDWARE_ERROR_STATUS)
            if bits or j.id in self.bus.alerts:
                latched[j.name] = bits
        if latched:
            exc = LatchedAtOpen(latched, self._ids_of(latched))
            try:
                silent = self.torque_off()
            except Exception:
                exc.add_note("torque off failed")
            else:
                exc.add_note("nothing moved, torque off" + _unconfirmed(silent))
            exc.add_note(f"next: {exc.next_step}")
            raise exc
        try:
            for j in self.joints:
                self._configure(j)
        except BaseException as exc:
            try:
                self.torque_off()
            except Exception:
                pass
            else:
                exc.add_note("torque off")
            raise

    def _ids_of(self, names) -> dict[str, int]:
        return {n: self.rig.joint(n).id for n in names}

    def reboot(self, names=None) -> dict[str, int]:
        """Reboot servos to clear their latched hardware errors: those of ``names`` (joint
        names), or by default every servo whose Hardware Error Status is not 0 or whose status
        packets carry the alert bit. Only ``gonio rig reboot`` calls this.

        A rebooted servo comes back with torque off and its RAM registers at their defaults; it
        moves nothing. Returns ``{joint: bits it had}``; DeviceError when an error persists.
        """
        out = {}
        for j in self.joints:
            bits = self.bus.read(j.id, ct.HARDWARE_ERROR_STATUS)
            if (names is None and (bits or j.id in self.bus.alerts)) or (
                names is not None and j.name in names
            ):
                out[j.name] = bits
                self._reboot(j, bits)
        return out

    def _reboot(self, j: JointConfig, bits: int) -> None:
        log.warning("rebooting servo %d (%s): %s", j.id, j.name, ct.hardware_error_text(bits))
        self.bus.reboot(j.id)
        deadline = time.monotonic() + 2.0
        while True:
            try:
                self.bus.ping(j.id)
                break
            except DeviceError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.05)  # a real servo takes a few hundred ms to boot
        if self.bus.read(j.id, ct.HARDWARE_ERROR_STATUS):
            raise DeviceError(f"joint {j.name}: hardware error persists after reboot")

    # --- limits -------------------------------------------------------------------------------
    def check_limits(self, targets_deg: Mapping[str, float]) -> dict[int, int]:
        """Validate a full pose against the software limits; return goal ticks per servo id.

        Raises PlanError (nothing is sent) if a joint is unknown, missing, or out of limits.
        """
        names = {j.name for j in self.joints}
        unknown = set(targets_deg) - names
        if unknown:
            raise PlanError(f"unknown joint(s) {sorted(unknown)}")
        goals: dict[int, int] = {}
        for j in self.joints:
            if j.name not in targets_deg:
                raise PlanError(f"pose gives no angle for joint {j.name}")
            a = float(targets_deg[j.name])
            if not (j.min_deg - 1e-9 <= a <= j.max_deg + 1e-9) or a != a:
                raise PlanError(
                    f"joint {j.name}: {a:.3f} deg outside its limits [{j.min_deg}, {j.max_deg}]"
                )
            for k in self.rig.safety.keepout:
                if k.joint != j.name:
                    continue
                park = self.rig.park_deg.get(j.name, j.zero_offset_deg)
                side = (a < k.min_deg and park < k.min_deg) or (a > k.max_deg and park > k.max_deg)
                if not side:  # also refuses NaN
                    raise PlanError(
                        f"joint {j.name}: {a:.3f} deg in or across the keep-out sector"
                        f" [{k.min_deg}, {k.max_deg}] ({k.reason})"
                    )
            t = j.to_ticks(a)
            lo, hi = ct.POSITION_RANGE[ct.OPERATING_MODES[j.operating_mode]]
            if not lo <= t <= hi:
                raise PlanError(f"joint {j.name}: tick {t} outside the servo range {lo}..{hi}")
            goals[j.id] = t
        return goals

    # --- motion -------------------------------------------------------------------------------
    def read_positions(self) -> dict[str, float]:
        """Present joint angles (deg), one sync read."""
        a, n = ct.PRESENT_POSITION
        data = self.bus.sync_read(a, n, self.ids)
        return {
            self._by_id[i].name: self._by_id[i].from_ticks(int.from_bytes(d, "little", signed=True))
            for i, d in data.items()
        }

    def predicted_time(
        self, start_deg: Mapping[str, float], goal_deg: Mapping[str, float]
    ) -> float:
        """Predicted rest-to-rest time (s): the slowest joint under its trapezoidal profile."""
        return max(
            float(j.move_time(goal_deg[j.name] - start_deg.get(j.name, goal_deg[j.name])))
            for j in self.joints
        )

    def move(
        self,
        targets_deg: Mapping[str, float],
        timeout_s: float | None = None,
        poll_s: float | None = None,
        hold: Collection[str] = (),
    ) -> MoveResult:
        """Move every joint at once and wait until all have settled.

        Limits are checked first (PlanError, nothing sent). Goals go out in one Sync Write;
        a Sync Read block (Goal .. Present Position) is polled: a goal that did not arrive is
        re-sent, the alert bit raises :class:`~gonio.rigs.faults.HardwareFault`, a joint still
        short of its goal after the predicted time plus ``bus.motion_timeout_s`` raises
        :class:`~gonio.rigs.faults.MotionTimeout`, and the move ends when every joint has
        stopped within its settle tolerance. Returns the angles read back.

        ``hold`` names joints that are sent nothing and not polled (a faulted joint with torque
        off while the others park): their target must be their present angle, and the whole
        pose, theirs included, passes the safety checks.
        """
        goals = self.check_limits(targets_deg)
        self._predicted_s = 0.0
        moving = [j.id for j in self.joints if j.name not in hold]
        res = self._move_once(goals, timeout_s, poll_s, moving=moving)
        return MoveResult(res[0], res[1], res[2], res[3], 0, self._predicted_s)

    def park_pose(self, hold: Collection[str] = ()) -> dict[str, float]:
        """The rig file's park pose; joints it does not name, and joints in ``hold``, keep
        their present angle."""
        present = self.read_positions()
        park = {n: a for n, a in self.rig.park_deg.items() if n not in hold}
        return {j.name: park.get(j.name, present[j.name]) for j in self.joints}

    def park(self, hold: Collection[str] = ()) -> MoveResult:
        """Move to the park pose; the joints in ``hold`` stay where they are (see :meth:`move`)."""
        return self.move(self.park_pose(hold), hold=hold)

    def torque_off(self, joints: Collection[str] | None = None) -> list[int]:
        """Torque off on every servo (or those of ``joints``): one Sync Write, then a write
        each servo acknowledges.

        Returns the ids of servos that did not acknowledge; raises DeviceError only when the
        bus itself is gone.
        """
        ids = self.ids if joints is None else [j.id for j in self.joints if j.name in joints]
        self.bus.sync_write(ct.TORQUE_ENABLE, dict.fromkeys(ids, 0))
        silent = []
        for sid in ids:
            try:
                self.bus.write(sid, ct.TORQUE_ENABLE, 0)
            except BusLost:
                raise
            except DeviceError:
                silent.append(sid)
        return silent

    def bus_stats(self) -> dict[str, int]:
        """Counters of this bus session (transactions, retries, timeouts, re-sent goals, ...)."""
        return dict(vars(self.bus.stats))

    def arm_transit_hold(
        self, start_deg: Mapping[str, float], goal_deg: Mapping[str, float]
    ) -> str | None:
        """If moving the light and camera arms together would bring them closer than the safety
        margin on the way (or across each other), the arm to hold still while the other moves
        first; None when the simultaneous move is safe.

        Both arms follow their trapezoidal profiles from the same start time; the predicted
        separation is sampled along the move. Holding one arm makes the separation change
        monotonically, so a two-phase move is safe whenever both end poses are.
        """
        lay = self.rig.layout
        jl, jc = self.rig.joint(lay.light), self.rig.joint(lay.camera)
        l0, l1 = start_deg[jl.name], goal_deg[jl.name]
        c0, c1 = start_deg[jc.name], goal_deg[jc.name]
        if l0 == l1 or c0 == c1:
            return None
        t_end = max(float(jl.move_time(l1 - l0)), float(jc.move_time(c1 - c0)))
        ts = np.linspace(0.0, t_end, 65)

        def path(j, a0, a1):
            return np.array(
                [
                    a0
                    + ct.trapezoid_position(
                        a1 - a0, j.profile_velocity_deg_s, j.profile_acceleration_deg_s2, t
                    )
                    for t in ts
                ]
            )

        order = 1.0 if l0 - c0 >= 0 else -1.0
        d = order * (path(jl, l0, l1) - path(jc, c0, c1))
        floor = min(self.rig.safety.min_light_camera_deg, order * (l0 - c0), order * (l1 - c1))
        if float(np.min(d)) >= floor - 1e-6:
            return None
        # move first the arm whose move alone keeps the arms apart
        if order * (l1 - c0) >= floor:
            return jc.name
        return jl.name

    def _move_once(self, goals: dict[int, int], timeout_s, poll_s, split: bool = True, moving=None):
        a, n = ct.POLL_BLOCK
        t0 = time.monotonic()
        ids = self.ids if moving is None else list(moving)
        start = self.bus.sync_read(a, n, self.ids)
        start_deg = {
            self._by_id[i].name: self._by_id[i].from_ticks(_field(d, ct.PRESENT_POSITION))
            for i, d in start.items()
        }
        goal_deg = {self._by_id[i].name: self._by_id[i].from_ticks(t) for i, t in goals.items()}
        hold = self.arm_transit_hold(start_deg, goal_deg) if split else None
        if hold is not None:
            j = self.rig.joint(hold)
            first = dict(goals)
            # the held arm keeps its last (checked) goal; it rests within tolerance of it
            first[j.id] = self.last_goal_ticks.get(j.id, _field(start[j.id], ct.PRESENT_POSITION))
            log.info("two-phase move: %s waits for the other arm", hold)
            self.two_phase_moves += 1
            self._move_once(first, None, poll_s, split=False, moving=ids)
            reached, _, settle, polls = self._move_once(
                goals, timeout_s, poll_s, split=False, moving=ids
            )
            t_end = time.monotonic()
            return reached, t_end - t0 - settle, settle, polls
        predicted = self.predicted_time(start_deg, goal_deg)
        self._predicted_s = getattr(self, "_predicted_s", 0.0) + predicted
        if timeout_s is None:
            timeout_s = predicted + self.rig.bus.motion_timeout_s
        if poll_s is None:
            poll_s = self.rig.bus.poll_interval_ms / 1000.0
        self.guard.check(goals, start_deg)  # the whole pose; the bus checks each goal again
        send = {sid: goals[sid] for sid in ids}
        self.bus.sync_write(ct.GOAL_POSITION, send)
        self.last_goal_ticks.update(send)
        t_sent = time.monotonic()
        t_stopped: float | None = None
        polls = 0
        deadline = t_sent + timeout_s
        while True:
            if self.should_abort():
                raise Interrupted("move abandoned on a second interrupt")
            data = self.bus.sync_read(a, n, ids)
            polls += 1
            if self.bus.alerts & set(ids):
                faults = {}
                for sid in sorted(self.bus.alerts & set(ids)):
                    bits = self.bus.read(sid, ct.HARDWARE_ERROR_STATUS)
                    faults[self._by_id[sid].name] = bits
                if any(faults.values()):
                    bad = {k: v for k, v in faults.items() if v}
                    raise HardwareFault(bad, self._ids_of(bad))
            lost = {
                sid: goals[sid]
                for sid, d in data.items()
                if _field(d, ct.GOAL_POSITION) != goals[sid]
            }
            if lost:
                # the Sync Write (no reply by design) was lost or corrupted for these servos
                self.bus.stats.resent_goals += 1
                self.bus.sync_write(ct.GOAL_POSITION, lost)
            else:
                moving = any(_field(d, ct.MOVING) for d in data.values())
                profile = any(_field(d, ct.MOVING_STATUS) & 0x02 for d in data.values())
                if not profile and t_stopped is None:
                    # motion = until every profile has ended; settle = from then until settled
                    t_stopped = time.monotonic()
                settled = not moving and all(
                    abs(_field(d, ct.PRESENT_POSITION) - goals[sid])
                    <= self._by_id[sid].tolerance_ticks
                    for sid, d in data.items()
                )
                if settled:
                    t_end = time.monotonic()
                    reached = {
                        self._by_id[sid].name: self._by_id[sid].from_ticks(
                            _field(d, ct.PRESENT_POSITION)
                        )
                        for sid, d in data.items()
                    }
                    t_stop = t_stopped if t_stopped is not None else t_end
                    return reached, t_stop - t0, t_end - t_stop, polls
                if profile:
                    t_stopped = None
            if time.monotonic() > deadline:
                far = [
                    sid
                    for sid, d in data.items()
                    if abs(_field(d, ct.PRESENT_POSITION) - goals[sid])
                    > self._by_id[sid].tolerance_ticks
                ]
                text = [
                    f"servo {sid} ({self._by_id[sid].name}) stopped at"
                    f" {self._by_id[sid].from_ticks(_field(data[sid], ct.PRESENT_POSITION)):.2f}"
                    f" deg, goal {self._by_id[sid].from_ticks(goals[sid]):.2f} deg"
                    for sid in far
                ]
                stuck = [self._by_id[sid].name for sid in (far or ids)]
                raise MotionTimeout(
                    f"move did not settle within {timeout_s:.2f} s:"
                    f" {', '.join(text) or 'still moving'}",
                    stuck,
                )
            if poll_s:
                time.sleep(poll_s)


def _unconfirmed(silent: list[int]) -> str:
    return f" sent (servo {', '.join(map(str, silent))} did not confirm)" if silent else ""


def _field(block: bytes, reg: tuple[int, int]) -> int:
    off = reg[0] - ct.POLL_BLOCK[0]
    return int.from_bytes(block[off : off + reg[1]], "little", signed=reg[1] == 4)
