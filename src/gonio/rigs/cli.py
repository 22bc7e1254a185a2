"""``gonio rig``: inspect rigs (``check`` pings every servo, ``schema`` prints the rig schema)."""

from __future__ import annotations

import argparse
import sys

from gonio.errors import DeviceError
from gonio.io.strict_json import dumps_json


def register(sub) -> None:
    p = sub.add_parser(
        "rig",
        help="inspect a rig: check its servos, print the rig-file schema, run its bus emulator",
        description="Inspect a rig described by a rig file (TOML; data-schema/rig.schema.json).",
    )
    rs = p.add_subparsers(dest="rig_command", metavar="SUBCOMMAND")
    c = rs.add_parser(
        "check",
        help="ping every servo; report models, firmware, hardware errors and limits",
        description=(
            "Open the rig's bus, ping every joint's servo and report its model (checked against the"
            " rig file), firmware, latched hardware error (register 70, Hardware Error Status, and"
            " the alert bit of its status packets), torque, present angle and software limits."
            " Moves and writes nothing. Exit status 3 if a servo is missing, of the wrong model or"
            " has a latched hardware error (the line says what to do next)."
        ),
    )
    c.add_argument(
        "--rig",
        default="sim",
        help="shipped rig name (sim, xm430_4axis) or path to a rig TOML file (default: sim)",
    )
    c.add_argument("--json", action="store_true", help="print the report as JSON")
    c.set_defaults(func=_check)
    r = rs.add_parser(
        "reboot",
        help="reboot servos to clear their latched hardware errors (moves nothing)",
        description=(
            "Reboot the servos whose hardware error is latched (Hardware Error Status != 0 or the"
            " alert bit set), or those of --joint, to clear it. gonio never reboots a servo by"
            " itself: clear the cause first (the safety policy in docs/guide/rig.md says what each"
            " error asks for). A rebooted servo comes back with torque off and moves nothing; the"
            " next 'gonio acquire' (or --resume) powers it again. Exit status 3 if an error"
            " persists after the reboot."
        ),
    )
    r.add_argument("--rig", default="sim", help="rig name or rig TOML path (default: sim)")
    r.add_argument(
        "--joint",
        action="append",
        metavar="NAME",
        help="reboot this joint's servo even without a latched error (repeatable)",
    )
    r.set_defaults(func=_reboot)
    s = rs.add_parser("schema", help="print the JSON schema of rig files")
    s.set_defaults(func=_schema)
    e = rs.add_parser(
        "emulate",
        help="run the servo-bus emulator of a rig in the foreground on a pseudo-terminal",
        description=(
            "Start the Dynamixel Protocol 2.0 emulator with the servos of a rig file (ids, models,"
            " park pose) on a pseudo-terminal and print its port path ('port: /dev/pts/N'). Point"
            " a copy of the rig file's bus.port at that path to drive it exactly like hardware"
            " (gonio rig check, gonio acquire). Runs until Ctrl-C or SIGTERM."
        ),
    )
    e.add_argument("--rig", default="sim", help="rig name or rig TOML path (default: sim)")
    e.add_argument(
        "--sim-faults",
        metavar="SPEC",
        help=(
            "inject faults, e.g. 'drop=0.02,garble=0.02,crc=0.02,seed=1', 'overload=0.01',"
            " 'block_servo=2,block_after=3'"
        ),
    )
    e.add_argument(
        "--time-scale",
        type=float,
        help="simulated seconds per wall second (default: the rig file's [sim] time_scale)",
    )
    e.add_argument(
        "--goal-log", metavar="FILE", help="append every received Goal Position (JSON lines)"
    )
    e.add_argument(
        "--packet-log",
        metavar="FILE",
        help="append every instruction packet received, before any injected fault (JSON lines)",
    )
    e.set_defaults(func=_emulate)
    lst = rs.add_parser("list", help="list the rigs shipped with gonio")
    lst.set_defaults(func=_list)
    p.set_defaults(func=lambda a: (p.print_help(), 0)[1])


def _check(args: argparse.Namespace) -> int:
    from gonio.rigs.config import load_rig
    from gonio.rigs.session import open_rig

    rig = load_rig(args.rig)
    with open_rig(rig, initialize=False, devices=("servos",)) as ses:
        infos = ses.chain.check()
    from gonio.rigs.control_table import hardware_error_text

    bad = [i for i in infos if not i.ok]
    if args.json:
        out = {
            "rig": rig.name,
            "port": rig.bus.port,
            "ok": not bad,
            "servos": [
                {
                    "joint": i.joint,
                    "id": i.id,
                    "model": i.model,
                    "model_number": i.model_number,
                    "expected_model": i.expected_model,
                    "firmware": i.firmware,
                    "hardware_error": i.hardware_error,
                    "hardware_error_text": hardware_error_text(i.hardware_error),
                    "alert": i.alert,
                    "torque": i.torque,
                    "position_deg": round(i.position_deg, 4),
                    "limits_deg": [i.min_deg, i.max_deg],
                }
                for i in infos
            ],
        }
        print(dumps_json(out, indent=2))
    else:
        from rich.console import Console
        from rich.table import Table

        t = Table(title=f"rig {rig.name} on {rig.bus.port}")
        for col in ("joint", "id", "model", "fw", "hw error", "torque", "angle (deg)", "limits"):
            t.add_column(col)
        for i in infos:
            model = (
                i.model
                if i.model == i.expected_model
                else f"{i.model} (expected {i.expected_model})"
            )
            t.add_row(
                i.joint,
                str(i.id),
                model,
                str(i.firmware),
                hardware_error_text(i.hardware_error) + (" (alert)" if i.alert else ""),
                "on" if i.torque else "off",
                f"{i.position_deg:.2f}",
                f"[{i.min_deg}, {i.max_deg}]",
            )
        Console(file=sys.stdout).print(t)
    if bad:
        raise DeviceError(
            "servo check failed: "
            + ", ".join(
                f"{i.joint} (id {i.id})"
                + (f": {hardware_error_text(i.hardware_error)}" if i.hardware_error else "")
                for i in bad
            )
            + _latched_next(bad)
        )
    return 0


def _latched_next(bad) -> str:
    """The policy table's next step for the latched errors among ``bad`` ServoInfos."""
    from gonio.rigs.faults import bit_policies

    bits = 0
    for i in bad:
        bits |= i.hardware_error
    steps = dict.fromkeys(p.next_step for p in bit_policies(bits))
    return f"; next: {' '.join(steps)}" if steps else ""


def _reboot(args: argparse.Namespace) -> int:
    from gonio.rigs.config import load_rig
    from gonio.rigs.control_table import hardware_error_text
    from gonio.rigs.session import open_rig

    rig = load_rig(args.rig)
    names = set(args.joint or ())
    unknown = sorted(names - {j.name for j in rig.joints})
    if unknown:
        from gonio.errors import ParameterError

        raise ParameterError(f"--joint {unknown[0]}: no such joint in rig {rig.name}")
    with open_rig(rig, initialize=False, devices=("servos",)) as ses:
        done = ses.chain.reboot(names or None)
    if not done:
        print(f"rig {rig.name}: no servo has a latched hardware error; nothing rebooted")
    for name, bits in done.items():
        j = rig.joint(name)
        print(f"rebooted servo {j.id} ({name}): {hardware_error_text(bits)} cleared, torque off")
    return 0


def _emulate(args: argparse.Namespace) -> int:
    import signal
    import threading

    from gonio.errors import ParameterError
    from gonio.rigs.config import load_rig
    from gonio.rigs.session import make_emulator
    from gonio.rigs.sim.bus import parse_faults

    rig = load_rig(args.rig)
    if args.time_scale is not None and not args.time_scale > 0:
        raise ParameterError("--time-scale must be > 0")
    faults = parse_faults(args.sim_faults) if args.sim_faults else None
    emu = make_emulator(rig, faults, args.goal_log, args.time_scale, args.packet_log)
    done = threading.Event()
    old = {s: signal.signal(s, lambda *_: done.set()) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with emu:
            print(f"port: {emu.port}", flush=True)
            ids = ", ".join(f"{j.name}={j.id} ({j.model})" for j in rig.joints)
            print(f"servos: {ids}", flush=True)
            while not done.wait(0.2):
                pass
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    return 0


def _schema(args: argparse.Namespace) -> int:
    from gonio.rigs.config import schema_json

    sys.stdout.write(schema_json())
    return 0


def _list(args: argparse.Namespace) -> int:
    from gonio.rigs.config import shipped_rigs

    print("\n".join(shipped_rigs()))
    return 0
