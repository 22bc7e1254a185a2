"""Servo faults and what gonio does about each: the policy table, in one place.

A Dynamixel X-series servo latches a hardware error in its Hardware Error Status register
(address 70) and sets the alert bit (0x80) of every status packet it sends until it is rebooted;
a servo whose error is in its Shutdown register (overload, overheating and electrical shock by
default) switches its own torque off, and a servo with a latched error refuses torque-on until
it is rebooted. :data:`POLICY` says, for each hardware error bit, for a joint that stops short of
its goal (a stall, found by the motion timeout), for a latch found when the rig is opened and for
a lost serial bus: which joints are parked, which get torque off, whether the run stops, and
what the user does next. The run engine (:mod:`gonio.acquire.stopping`) and the command line
read it; the safety page of the guide (``docs/guide/rig.md``) shows :func:`policy_markdown`,
and a test keeps the two equal.

gonio never reboots a servo on its own: a reboot clears the latch and would let the next move
drive an arm into whatever it met (a cable, a hand, the sample holder). ``gonio rig reboot``
is the one way to clear a latch, run by the user once the cause is cleared.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from gonio.errors import DeviceError
from gonio.rigs import control_table as ct

#: what ``park`` and ``torque_off`` of a :class:`FaultPolicy` may say
OTHERS, FAULTED, EVERY, NONE = "the other joints", "the faulted joint", "every joint", "none"

_NEXT_REBOOT = "then `gonio rig reboot`, `gonio rig check` and `gonio acquire --resume RUN`"


@dataclass(frozen=True)
class FaultPolicy:
    """One row of the policy table.

    Attributes
    ----------
    key : the fault: a hardware error name (:data:`gonio.rigs.control_table.HW_ERROR_NAMES`),
        ``"stall"``, ``"latch at open"`` or ``"bus lost"``.
    bit : its Hardware Error Status bit; None for the faults that are not one.
    park : which joints move to the park pose (:data:`OTHERS`, :data:`EVERY` or :data:`NONE`).
    torque_off : which joints get torque off (:data:`FAULTED`, :data:`EVERY` or :data:`NONE`).
    stops_run : whether the run stops (it does for every fault).
    next_step : what the user does next.
    """

    key: str
    bit: int | None
    park: str
    torque_off: str
    stops_run: bool
    next_step: str


#: The policy table: every hardware error bit, a stall, a latch found at open, a lost bus.
POLICY: tuple[FaultPolicy, ...] = (
    FaultPolicy(
        "input voltage",
        ct.HW_INPUT_VOLTAGE,
        OTHERS,
        FAULTED,
        True,
        "Measure the supply at the servo under load (XM430: 10.0-14.8 V) and fix the supply or"
        f" its wiring; {_NEXT_REBOOT}.",
    ),
    FaultPolicy(
        "overheating",
        ct.HW_OVERHEATING,
        OTHERS,
        FAULTED,
        True,
        "Let the servo cool below its Temperature Limit and lower its load (a slower profile, a"
        f" lighter arm, a free bearing); {_NEXT_REBOOT}.",
    ),
    FaultPolicy(
        "motor encoder",
        ct.HW_MOTOR_ENCODER,
        OTHERS,
        FAULTED,
        True,
        "The servo cannot trust its position: power-cycle it; if the error returns, replace the"
        f" servo; {_NEXT_REBOOT}.",
    ),
    FaultPolicy(
        "electrical shock",
        ct.HW_ELECTRICAL_SHOCK,
        OTHERS,
        FAULTED,
        True,
        "Power off and inspect the servo's motor, cable and connectors; a servo that latches it"
        f" again is faulty; {_NEXT_REBOOT}.",
    ),
    FaultPolicy(
        "overload",
        ct.HW_OVERLOAD,
        OTHERS,
        FAULTED,
        True,
        "The joint met a load it should not (a cable, a hand, the sample holder): with torque off,"
        " find and remove it and check that the joint turns freely by hand; "
        f"{_NEXT_REBOOT}.",
    ),
    FaultPolicy(
        "stall",
        None,
        OTHERS,
        FAULTED,
        True,
        "The joint stopped short of its goal within the motion timeout: with torque off, find what"
        " blocks it (a cable, the holder, an arm) and clear it; then `gonio rig check` and"
        " `gonio acquire --resume RUN`.",
    ),
    FaultPolicy(
        "latch at open",
        None,
        NONE,
        EVERY,
        True,
        "Nothing moved and no torque is on: `gonio rig check` names the error; clear its cause"
        " (the row of that error), then `gonio rig reboot` and start or resume the run again.",
    ),
    FaultPolicy(
        "bus lost",
        None,
        NONE,
        EVERY,
        True,
        "The servos keep their last goal with torque on if the torque-off did not reach them:"
        " switch the servo supply off, reconnect the adapter, then `gonio rig check` and"
        " `gonio acquire --resume RUN`.",
    ),
)

_BY_KEY = {p.key: p for p in POLICY}


def policy(key: str) -> FaultPolicy:
    """The row of fault ``key`` (KeyError for an unknown one)."""
    return _BY_KEY[key]


def bit_policies(bits: int) -> list[FaultPolicy]:
    """The rows of every hardware error bit set in ``bits`` (Hardware Error Status)."""
    return [p for p in POLICY if p.bit is not None and bits & p.bit]


def policy_markdown() -> str:
    """The policy table as the Markdown table the guide's safety page shows."""
    lines = [
        "| fault | parked | torque off | run stops | what to do next |",
        "|---|---|---|---|---|",
    ]
    for p in POLICY:
        name = p.key if p.bit is None else f"{p.key} (bit {p.bit.bit_length() - 1})"
        stops = "yes" if p.stops_run else "no"
        lines.append(f"| {name} | {p.park} | {p.torque_off} | {stops} | {p.next_step} |")
    return "\n".join(lines)


# --- the faults ------------------------------------------------------------------------------


class JointFault(DeviceError):
    """A fault of named joints; :attr:`policy` is its row of :data:`POLICY`.

    Attributes
    ----------
    joints : the joints at fault, in the rig file's order.
    """

    key = "stall"

    def __init__(self, message: str, joints: Iterable[str]) -> None:
        super().__init__(message)
        self.joints = tuple(joints)

    @property
    def policy(self) -> FaultPolicy:
        return policy(self.key)

    @property
    def next_step(self) -> str:
        return self.policy.next_step

    def event(self) -> dict:
        """The fault as a journal event: its kind, joints and (for hardware errors) bits."""
        return {"fault": self.key, "joints": list(self.joints)}


class HardwareFault(JointFault):
    """Servos report a latched hardware error (Hardware Error Status != 0).

    Parameters
    ----------
    faults : joint name -> Hardware Error Status bits.
    ids : joint name -> servo id (named in the message when given).
    """

    key = "hardware error"

    def __init__(
        self, faults: Mapping[str, int], ids: Mapping[str, int] | None = None, when: str = ""
    ) -> None:
        self.faults = dict(faults)
        ids = ids or {}
        text = "; ".join(
            (f"servo {ids[j]} ({j})" if j in ids else j) + f": {ct.hardware_error_text(b)}"
            for j, b in self.faults.items()
        )
        super().__init__(f"servo hardware error{when} ({text})", self.faults)

    @property
    def bits(self) -> int:
        out = 0
        for b in self.faults.values():
            out |= b
        return out

    @property
    def policy(self) -> FaultPolicy:
        rows = bit_policies(self.bits)
        return rows[0] if rows else policy("overload")

    @property
    def next_step(self) -> str:
        rows = bit_policies(self.bits) or [policy("overload")]
        return " ".join(dict.fromkeys(p.next_step for p in rows))

    def event(self) -> dict:
        return {
            "fault": self.key,
            "joints": list(self.joints),
            "bits": dict(self.faults),
            "errors": {j: ct.hardware_error_text(b) for j, b in self.faults.items()},
        }


class LatchedAtOpen(HardwareFault):
    """Servos came up with a latched hardware error: the rig is not opened (no torque on)."""

    key = "latch at open"

    def __init__(self, faults: Mapping[str, int], ids: Mapping[str, int] | None = None) -> None:
        super().__init__(faults, ids, " latched before the rig was opened")

    @property
    def policy(self) -> FaultPolicy:
        return policy("latch at open")

    @property
    def next_step(self) -> str:
        return policy("latch at open").next_step


class MotionTimeout(JointFault):
    """Joints did not reach their goals within the motion timeout (a stall: a blocked joint)."""

    key = "stall"
