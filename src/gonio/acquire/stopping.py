"""Bringing a rig to rest on every way out of a run: park when it can, torque off when it cannot.

Used by the run engine once the servos are powered: after the last configuration, after a
SIGINT or SIGTERM, after a :class:`~gonio.errors.DeviceError` (a dead servo, a lost serial
port, too many faults) and after any other exception. The outcome is one short phrase
(``"rig parked"``, ``"rig not parked (...), torque off"``, ...) that the engine attaches to the
exception it re-raises (the command line prints it on the same line as the error), writes to
``RUN/log.jsonl`` and records in the journal's metadata (``last_stop``).

A servo fault (:class:`gonio.rigs.faults.JointFault`: a hardware error, a stall) is handled as
its row of the policy table :data:`gonio.rigs.faults.POLICY` says: the faulted joints get torque
off first, then the others park (the faulted ones held where they are, the whole pose checked);
a lost bus is not parked. :func:`record_fault` journals the fault as an event.
"""

from __future__ import annotations

import time

from gonio.interrupts import StopFlag
from gonio.io.strict_json import dumps_json
from gonio.rigs.dynamixel import BusLost
from gonio.rigs.faults import EVERY, FAULTED, NONE, JointFault, policy


def _short(exc: BaseException) -> str:
    if isinstance(exc, BusLost):
        return "servo bus lost"
    text = str(exc) or type(exc).__name__
    return text if len(text) <= 160 else text[:157] + "..."


def bring_to_rest(chain, flag: StopFlag, cause: BaseException | None = None) -> tuple[bool, str]:
    """Park ``chain`` (a :class:`gonio.rigs.dynamixel.ServoChain`), else switch torque off.

    ``cause`` is what stopped the run: a :class:`~gonio.rigs.faults.JointFault` is handled as
    its policy row says (faulted joints torque off, the others parked), a lost bus is not
    parked. Signals are only recorded meanwhile (no exception can land half-way through a bus
    transaction); a further signal abandons the park at the move's next poll, and torque goes
    off instead. Returns ``(parked, phrase)``; never raises.
    """
    if isinstance(cause, BusLost):
        why = "servo bus lost"
    else:
        parked, why = _park(chain, flag, cause)
        if parked:
            return True, why
    return _all_torque_off(chain, flag, why)


def _park(chain, flag: StopFlag, cause) -> tuple[bool, str]:
    """Park, holding the faulted joints of ``cause`` with torque off; (parked, phrase)."""
    hold: tuple[str, ...] = ()
    if isinstance(cause, JointFault) and cause.policy.torque_off == FAULTED:
        hold = cause.joints
    if isinstance(cause, JointFault) and (
        cause.policy.park == NONE or cause.policy.torque_off == EVERY
    ):
        return False, "rig not parked (policy)"
    n0 = flag.count
    chain.should_abort = lambda: flag.count > n0
    try:
        with flag.shielded():
            if hold:
                silent = chain.torque_off(hold)
                if silent:
                    raise RuntimeError(f"servo {', '.join(map(str, silent))} did not confirm")
            chain.park(hold=hold)
        if hold:
            names = ", ".join(hold)
            return True, f"{names} torque off, the other joints parked"
        return True, "rig parked"
    except BaseException as exc:
        return False, _short(exc)
    finally:
        chain.should_abort = lambda: False


def _all_torque_off(chain, flag: StopFlag, why: str) -> tuple[bool, str]:
    try:
        with flag.shielded():
            silent = chain.torque_off()
    except BaseException as exc:
        return (
            False,
            f"rig not parked ({why}) and torque off failed ({_short(exc)}): torque state unknown",
        )
    if silent:
        ids = ", ".join(map(str, silent))
        return False, f"rig not parked ({why}), torque off sent (servo {ids} did not confirm)"
    return False, f"rig not parked ({why}), torque off"


def record_fault(journal, log, exc: BaseException, phrase: str) -> None:
    """Journal (an ``events`` row) and log (event ``fault``) a servo fault, what was done about
    it and what the user does next (:class:`gonio.rigs.faults.JointFault`); never raises."""
    if not isinstance(exc, (JointFault, BusLost)):
        return
    if isinstance(exc, JointFault):
        entry = {**exc.event(), "message": str(exc), "next": exc.next_step}
    else:
        entry = {"fault": "bus lost", "message": str(exc), "next": policy("bus lost").next_step}
    entry["rig"] = phrase
    try:
        log("fault", **entry)
    except Exception:
        pass
    try:
        journal.event(entry["fault"], entry)
    except Exception:
        pass


def record_stop(journal, log, reason: str, parked: bool, phrase: str) -> None:
    """Journal (meta ``last_stop``) and log (event ``stopped``) how a run ended; never raises."""
    entry = {"reason": reason, "parked": parked, "rig": phrase, "t": time.time()}
    try:
        log("stopped", **entry)
    except Exception:
        pass
    try:
        journal.set_meta({"last_stop": dumps_json(entry)})
    except Exception:
        pass
