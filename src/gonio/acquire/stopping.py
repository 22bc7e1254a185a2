"""Bringing a rig to rest on every way out of a run: park when it can, torque off when it cannot.

Used by the run engine once the servos are powered: after the last configuration, after a
SIGINT or SIGTERM, after a :class:`~gonio.errors.DeviceError` (a dead servo, a lost serial
port, too many faults) and after any other exception. The outcome is one short phrase
(``"rig parked"``, ``"rig not parked (...), torque off"``, ...) that the engine attaches to the
exception it re-raises (the command line prints it on the same line as the error), writes to
``RUN/log.jsonl`` and records in the journal's metadata (``last_stop``).
"""

from __future__ import annotations

import time

from gonio.interrupts import StopFlag
from gonio.io.strict_json import dumps_json
from gonio.rigs.dynamixel import BusLost


def _short(exc: BaseException) -> str:
    if isinstance(exc, BusLost):
        return "servo bus lost"
    text = str(exc) or type(exc).__name__
    return text if len(text) <= 160 else text[:157] + "..."


def bring_to_rest(chain, flag: StopFlag) -> tuple[bool, str]:
    """Park ``chain`` (a :class:`gonio.rigs.dynamixel.ServoChain`), else switch torque off.

    Signals are only recorded meanwhile (no exception can land half-way through a bus
    transaction); a further signal abandons the park at the move's next poll, and torque goes
    off instead. Returns ``(parked, phrase)``; never raises.
    """
    n0 = flag.count
    chain.should_abort = lambda: flag.count > n0
    try:
        with flag.shielded():
            chain.park()
        return True, "rig parked"
    except BaseException as exc:
        why = _short(exc)
    finally:
        chain.should_abort = lambda: False
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
