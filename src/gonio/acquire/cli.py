"""``gonio plan`` (dry run of an acquisition plan) and ``gonio acquire`` (run or resume one)."""

from __future__ import annotations

import argparse
import math

import numpy as np

from gonio.errors import ParameterError
from gonio.io.strict_json import dumps_json

_PLAN_HELP = (
    "built-in plan name ({names}) or path to a plan TOML file. Plan files: kind = 'grid4d' |"
    " 'isotropic' | 'halfdiff' | 'adaptive'; angle keys in degrees as a list or"
    " {{start, stop, step}} (inclusive): grid4d needs theta_i_deg, phi_i_deg, theta_o_deg,"
    " phi_o_deg; isotropic and adaptive need theta_i_deg, theta_o_deg, dphi_deg (isotropic may"
    " add reciprocal = true to also measure every pair swapped, a reciprocity check; adaptive"
    " adds"
    " [refine] window_deg, step_deg, peak_ratio); halfdiff needs theta_h_deg, theta_d_deg,"
    " phi_d_deg; 'list' gives configurations = [[theta_i, phi_i, theta_o, phi_o], ...] (deg)"
    " and optionally isotropic = true; 'optimal' (count = N) and 'guided' (batch, first,"
    " target, budget_configurations, budget_s in rig seconds; model and target_width for an"
    " analytic fit after each batch) choose their configurations"
    " with a material prior (prior = PATH, relative to the plan file) among the"
    " configurations the rig reaches on a candidate grid (theta_deg, dphi_deg); a run of"
    " either writes what it chose to RUN/plan_chosen.toml, a 'list' plan"
)


def _plan_help() -> str:
    from gonio.acquire.plans import builtin_plans

    return _PLAN_HELP.format(names=", ".join(builtin_plans()))


def register(sub) -> None:
    p = sub.add_parser(
        "plan",
        help="dry-run an acquisition plan: count, predicted motion and time, refused poses",
        description=(
            "Plan an acquisition without touching hardware: inverse kinematics for every target,"
            " refusals (joint limits, keep-out sectors, light/camera too close, grazing angles)"
            " with their reasons, travel-time ordering (nearest neighbour, then 2-opt; above"
            " 1,000 poses on neighbour lists with Or-opt too; a move costs its"
            " slowest joint under the trapezoidal profile; motion times are rig time in seconds)."
            "\n\nThe total is a wall-clock estimate: the motion (divided by the time scale on a"
            " simulated rig), plus per move the bus traffic and settling beyond the profile, plus"
            " per configuration the capture and the bookkeeping. Those last costs are not in the"
            " rig file: --timing-from RUN takes them from a previous run of the rig (medians of"
            " RUN/log.jsonl); without it they are figures measured for the simulated cameras"
            " (virtual camera 'sim': 2.99 s per configuration, 0.043 s per move, on a busy 2-core"
            " machine; 'sim-sample': 1 ms), and for a real camera only the exposure time is"
            " counted, which the output says."
            "\n\nThe rig file is checked as 'gonio acquire' checks it, except that a"
            " [sim.sample] model description is checked by 'gonio acquire' only (before any"
            " motion): building the model loads the model code (JAX), which a dry run does not."
            " The text output wraps to the terminal's width (COLUMNS when set, 80 when piped)."
            "\n\nAn 'optimal' or 'guided' plan chooses its batches from the measurements: the"
            " dry run plans its first batch (chosen by the prior before any data) and says how"
            " the run goes on: the batch size and the stopping rule (target, budget)."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--rig", default="sim", help="rig name or rig TOML path (default: sim)")
    p.add_argument("--plan", required=True, help=_plan_help())
    p.add_argument(
        "--dry-run",
        action="store_true",
        default=True,
        help="only plan (always the case: 'gonio plan' never moves anything)",
    )
    p.add_argument(
        "--timing-from",
        metavar="RUN",
        help=(
            "take the per-configuration capture and bookkeeping time and the per-move overhead"
            " from a previous run of this rig (medians of RUN/log.jsonl)"
        ),
    )
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument(
        "--list-refused",
        type=int,
        default=20,
        metavar="N",
        help="show at most N refused poses in the text output (default 20; --json lists all)",
    )
    p.set_defaults(func=_plan)

    a = sub.add_parser(
        "acquire",
        help="run (or resume) an acquisition on a rig",
        description=(
            "Execute a plan on a rig: move, settle, capture, record. Every configuration is"
            " journaled in RUN/journal.sqlite; after a crash or Ctrl-C, --resume RUN continues"
            " with no lost and no duplicated sample. Ctrl-C (or SIGTERM) finishes the current"
            " configuration and parks the rig per its rig file; a second one abandons the"
            " configuration and parks. Any fault once the servos are powered parks the rig, or"
            " turns torque off when it cannot, and the one-line error says which. A start that"
            " fails leaves no RUN behind. RUN/log.jsonl is a structured"
            " log; RUN/table.brdf.h5 is written when the run completes (needs gonio.io)."
            " A full disk (or quota, file-size limit, read-only disk) stops the run parked with"
            " every committed sample kept, exit status 5: make room, then --resume RUN. One"
            " process writes a run folder and drives a serial port at a time: a second is"
            " refused naming the holder's PID, exit status 6."
        ),
    )
    a.add_argument(
        "--rig",
        help=(
            "rig name or rig TOML path (default: sim). With --resume the run continues on the rig"
            " recorded in its journal; a --rig that differs from it is refused"
        ),
    )
    a.add_argument("--plan", help=_plan_help() + " (required unless --resume)")
    a.add_argument("--out", help="new run directory (must not exist or be empty)")
    a.add_argument(
        "--resume",
        metavar="RUN",
        help="continue the run in directory RUN (its journal's rig and plan are used)",
    )
    a.add_argument(
        "--sim-faults",
        metavar="SPEC",
        help=(
            "simulated rig only: inject bus faults, e.g. 'drop=0.02,garble=0.02,crc=0.02,seed=1'"
            " (probabilities per packet); overload=P (per move) and block_servo=ID,block_after=N"
            " (that joint stopped half-way by an obstacle on its move N+1) stop the run"
        ),
    )
    a.add_argument(
        "--time-scale",
        type=float,
        help="simulated rig only: simulated seconds per wall second (default: rig file)",
    )
    a.add_argument(
        "--strict",
        action="store_true",
        help=(
            "refuse the whole plan before any motion if any pose is refused (default: skip"
            " refused poses, journal and log them with the reason)"
        ),
    )
    a.add_argument(
        "--no-exposure-planning",
        action="store_true",
        help=(
            "RAW cameras: use the rig file's fixed brackets (camera.fixed_brackets x"
            " camera.exposure_s) for every configuration instead of planning each one's"
            " exposures from the previous frame"
        ),
    )
    a.add_argument("--no-progress", action="store_true", help="no progress bar")
    a.add_argument("--json", action="store_true", help="print the run summary as JSON")
    a.set_defaults(func=_acquire, checks_interrupts=True)


def _plan(args: argparse.Namespace) -> int:
    from gonio.acquire.engine import dry_run
    from gonio.acquire.plans import load_plan
    from gonio.acquire.timing import costs_from_run, default_costs
    from gonio.rigs.config import load_rig

    if args.list_refused < 0:
        raise ParameterError(f"--list-refused must be >= 0, got {args.list_refused}")
    rig = load_rig(args.rig, check_sample_model=False)  # no model code (JAX) for a dry run
    plan, _ = load_plan(args.plan)
    costs = costs_from_run(args.timing_from) if args.timing_from else default_costs(rig)
    stages = dry_run(rig, plan)
    accepted = sum(len(s.accepted) for s in stages)
    refused = [c for s in stages for c in s.refused]
    motion = float(sum(np.sum(s.move_s) for s in stages))
    lex = float(sum(s.lexicographic_s for s in stages))
    scale = rig.sim.time_scale if rig.is_sim else 1.0
    capture = costs.capture_s
    if capture is None:  # a real camera never measured: its exposure time only
        capture = float(rig.camera.get("exposure_s", 0.0))
    per_cfg = capture + costs.book_s + costs.move_overhead_s
    total = motion / scale + accepted * per_cfg
    out = {
        "rig": rig.name,
        "plan": plan.name,
        "kind": plan.kind,
        "stages": len(stages),
        "targets": accepted + len(refused),
        "accepted": accepted,
        "refused": len(refused),
        "predicted_motion_s": round(motion, 3),
        "plan_order_motion_s": round(lex, 3),
        "predicted_total_s": round(total, 3),
        "time_scale": scale,
        "per_configuration_s": {
            "capture": round(capture, 4),
            "move_overhead": round(costs.move_overhead_s, 4),
            "bookkeeping": round(costs.book_s, 4),
        },
        "costs_source": costs.source,
        "capture_cost_known": costs.capture_s is not None,
        "refusals": [
            {
                "index": c.idx,
                "theta_i_deg": round(math.degrees(math.acos(c.wi[2])), 3),
                "phi_i_deg": round(math.degrees(math.atan2(c.wi[1], c.wi[0])) % 360, 3),
                "theta_o_deg": round(math.degrees(math.acos(c.wo[2])), 3),
                "phi_o_deg": round(math.degrees(math.atan2(c.wo[1], c.wo[0])) % 360, 3),
                "reason": c.reason,
            }
            for c in refused
        ],
    }
    if plan.n_stages > 1:
        out["note"] = "later stages depend on measurements; predicted around the mirror direction"
    if plan.dynamic:
        # what a run of it will do without data: its first batch (counted above) and its rule
        out["decides"] = plan.describe()
        out["note"] = (
            "the figures above are the first batch; later batches are chosen from the"
            " measurements (" + _rule(out["decides"]) + ")"
        )
    if args.json:
        print(dumps_json(out, indent=2))
        return 0
    _print_plan(out, plan, rig, costs, args.list_refused)
    return 0


def _rule(d: dict) -> str:
    """One phrase: how a dynamic plan goes on and when it stops."""
    if d.get("kind") == "optimal":
        return f"optimal: {d.get('count')} configurations in one batch, then stop"
    stops = []
    if d.get("target") is not None:
        stops.append(f"predicted error <= {d['target']:g}")
    if d.get("budget_configurations") is not None:
        stops.append(f"{d['budget_configurations']} configurations")
    if d.get("budget_s") is not None:
        stops.append(f"{d['budget_s']:g} rig seconds")
    if d.get("target_width") is not None:
        stops.append(f"{d['model']} parameters known to {d['target_width']:g} of their value")
    return (
        f"guided: first batch {d.get('first')}, then batches of {d.get('batch')} until "
        + " or ".join(stops)
    )


def _print_plan(out: dict, plan, rig, costs, list_refused: int) -> None:
    """The text form of ``gonio plan``, wrapped to the terminal's width (``COLUMNS`` when set,
    80 when piped): summary lines wrap at words, refused poses are a table whose reason
    column wraps (never cut)."""
    import textwrap

    from rich import box
    from rich.console import Console
    from rich.table import Table

    console = Console(markup=False, highlight=False, emoji=False)
    width = max(console.width, 40)

    def line(text: str, indent: str = "  ") -> None:
        print(textwrap.fill(text, width, initial_indent=indent, subsequent_indent=indent + "    "))

    accepted, refused, scale = out["accepted"], out["refusals"], out["time_scale"]
    motion, cfg = out["predicted_motion_s"], out["per_configuration_s"]
    line(f"plan {plan.name} ({plan.kind}) on rig {rig.name}: {out['targets']} targets", "")
    line(f"accepted {accepted}, refused {len(refused)}")
    sim = f", {motion / scale:.1f} s at time scale {scale:g}" if scale != 1.0 else ""
    line(
        f"predicted motion {motion:.1f} s rig time"
        f" (plan order: {out['plan_order_motion_s']:.1f} s){sim}"
    )
    line(
        f"total {out['predicted_total_s']:.1f} s wall = motion + {accepted} configurations"
        f" x {sum(cfg.values()):.3f} s"
    )
    line(
        f"per configuration: {cfg['capture']:.3f} s capture + {cfg['move_overhead']:.3f} s per"
        f" move + {cfg['bookkeeping']:.3f} s bookkeeping"
    )
    line(f"costs: {costs.source}")
    if "note" in out:
        line(f"note: {out['note']}")
    shown = refused[: max(list_refused, 0)]
    if shown:
        first = "" if len(shown) == len(refused) else f", the first {len(shown)}"
        line(f"refused poses (angles in deg{first}):")
        t = Table(box=box.SIMPLE_HEAD, show_edge=False, pad_edge=False, collapse_padding=True)
        for col in ("#", "theta_i", "phi_i", "theta_o", "phi_o"):
            t.add_column(col, justify="right", no_wrap=True)
        t.add_column("reason", overflow="fold")
        for r in shown:
            angles = (r[k] for k in ("theta_i_deg", "phi_i_deg", "theta_o_deg", "phi_o_deg"))
            t.add_row(str(r["index"]), *(f"{a:.1f}" for a in angles), r["reason"])
        with console.capture() as cap:
            console.print(t, width=width - 2)
        for row in cap.get().rstrip("\n").splitlines():
            print(("  " + row).rstrip())
    if len(refused) > len(shown):
        line(f"... and {len(refused) - len(shown)} more refused (--list-refused N, --json)")


def _acquire(args: argparse.Namespace) -> int:
    import functools

    from gonio.acquire.engine import acquire, open_session
    from gonio.rigs.sim.bus import parse_faults

    faults = parse_faults(args.sim_faults) if args.sim_faults else None
    if args.time_scale is not None and not 0 < args.time_scale <= 1e6:  # as sim.time_scale
        raise ParameterError(f"--time-scale must be in (0, 1e6], got {args.time_scale:g}")

    # --sim-faults and --time-scale are the simulated rig's; hardware ignores them
    devices = functools.partial(open_session, faults=faults, time_scale=args.time_scale)
    run = functools.partial(acquire, progress=not args.no_progress, open_devices=devices)
    if args.resume:
        if args.out and args.out != args.resume:
            raise ParameterError("give either --out (new run) or --resume RUN, not both")
        summary = run(args.resume, args.rig, resume=True)
    else:
        if not args.out or not args.plan:
            raise ParameterError("a new run needs --plan and --out (or --resume RUN)")
        summary = run(
            args.out,
            args.rig or "sim",
            args.plan,
            strict=args.strict,
            exposure_planning=False if args.no_exposure_planning else None,
        )
    out = {
        "run": summary.run_dir,
        "planned": summary.planned,
        "refused": summary.refused,
        "done": summary.done,
        "rejected": summary.rejected,
        "measured_now": summary.measured_now,
        "complete": summary.complete,
        "table": summary.table,
        "table_note": summary.table_note,
        "bus": summary.bus,
        "wall_s": round(summary.wall_s, 3),
    }
    if summary.batches:
        out["batches"] = summary.batches
        out["chosen_plan"] = summary.chosen_plan
    if args.json:
        print(dumps_json(out, indent=2))
    else:
        print(
            f"run {summary.run_dir}: {summary.done}/{summary.planned} samples"
            f" ({summary.measured_now} now), {summary.refused} refused,"
            f"{f' {summary.rejected} rejected,' if summary.rejected else ''}"
            f" {'complete' if summary.complete else 'incomplete'} in {summary.wall_s:.1f} s"
        )
        print(
            f"  bus: {summary.bus.get('transactions', 0)} transactions,"
            f" {summary.bus.get('retries', 0)} retries,"
            f" {summary.bus.get('resent_goals', 0)} goals re-sent"
        )
        for b in summary.batches:
            err = b["predicted_error"]
            err = "-" if err is None else f"{err:.4f}"
            then = f"stop: {b['stop']}" if b["stop"] else f"batch of {b['batch']}"
            true = b.get("true_error")
            true = "" if true is None else f" (true {true:.4f})"
            print(
                f"  decision {b['stage']}: {b['measured_before']} measured,"
                f" predicted error {err}{true}, {b['rig_s_before']:.0f} rig s; {then}"
            )
        if summary.chosen_plan:
            print(f"  chosen configurations: {summary.chosen_plan}")
        if summary.table:
            print(f"  table: {summary.table}")
        elif summary.table_note:
            print(f"  {summary.table_note}")
    return 0
