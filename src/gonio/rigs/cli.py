"""``gonio rig``: inspect rigs (``check`` pings every servo, ``schema`` prints the rig schema)."""

from __future__ import annotations

import argparse
import json
import sys

from gonio.errors import DeviceError


def register(sub) -> None:
    p = sub.add_parser(
        "rig",
        help="inspect a rig: check its servos, print the rig-file schema",
        description="Inspect a rig described by a rig file (TOML; data-schema/rig.schema.json).",
    )
    rs = p.add_subparsers(dest="rig_command", metavar="SUBCOMMAND")
    c = rs.add_parser(
        "check",
        help="ping every servo; report models, firmware, hardware errors and limits",
        description=(
            "Open the rig's bus, ping every joint's servo and report its model (checked against the"
            " rig file), firmware, Hardware Error Status, torque, present angle and software"
            " limits. Moves nothing. Exit status 3 if a servo is missing, of the wrong model or in"
            " a hardware-error state."
        ),
    )
    c.add_argument(
        "--rig",
        default="sim",
        help="shipped rig name (sim, xm430_4axis) or path to a rig TOML file (default: sim)",
    )
    c.add_argument("--json", action="store_true", help="print the report as JSON")
    c.set_defaults(func=_check)
    s = rs.add_parser("schema", help="print the JSON schema of rig files")
    s.set_defaults(func=_schema)
    lst = rs.add_parser("list", help="list the rigs shipped with gonio")
    lst.set_defaults(func=_list)
    p.set_defaults(func=lambda a: (p.print_help(), 0)[1])


def _check(args: argparse.Namespace) -> int:
    from gonio.rigs.config import load_rig
    from gonio.rigs.session import open_rig

    rig = load_rig(args.rig)
    with open_rig(rig, initialize=False) as ses:
        infos = ses.chain.check()
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
                    "torque": i.torque,
                    "position_deg": round(i.position_deg, 4),
                    "limits_deg": [i.min_deg, i.max_deg],
                }
                for i in infos
            ],
        }
        print(json.dumps(out, indent=2))
    else:
        from rich.console import Console
        from rich.table import Table

        from gonio.rigs.control_table import hardware_error_text

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
                hardware_error_text(i.hardware_error),
                "on" if i.torque else "off",
                f"{i.position_deg:.2f}",
                f"[{i.min_deg}, {i.max_deg}]",
            )
        Console(file=sys.stdout).print(t)
    if bad:
        raise DeviceError("servo check failed: " + ", ".join(f"{i.joint} (id {i.id})" for i in bad))
    return 0


def _schema(args: argparse.Namespace) -> int:
    from gonio.rigs.config import schema_json

    sys.stdout.write(schema_json())
    return 0


def _list(args: argparse.Namespace) -> int:
    from gonio.rigs.config import shipped_rigs

    print("\n".join(shipped_rigs()))
    return 0
