"""Rig benchmarks: plan ordering, bus round-trip latency, per-configuration time split.

Writes CSV + PNG into benchmarks/results/:

* ``rig_ordering.csv/.png`` — predicted motion time (rig time, s) per plan and stage: the plan's
  own (lexicographic) order, a lexicographic sort of the directions (theta_i, phi_i, theta_o,
  phi_o), and the travel-time-optimized order (nearest neighbour + 2-opt + pose choice), with a
  lower bound valid for every order (each target entered once by its cheapest move), hence the
  best ratio any ordering could reach.
* ``rig_latency.csv/.png`` — round-trip latency over the pseudo-terminal through dynamixel-sdk:
  ping of one servo, and the 20-byte Sync Read of 4 servos the driver polls while settling.
* ``rig_time_split.csv/.png`` — wall time per configuration of a simulated run, split into
  motion, settle, capture and bookkeeping (journal commit + log), from the run's log.jsonl.

Run: ``PYTHONPATH=src python benchmarks/bench_rig.py [--quick]``.
"""

from __future__ import annotations

import argparse
import csv
import json
import tempfile
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from gonio.acquire.engine import acquire, plan_stage
from gonio.acquire.ordering import cost_matrix, move_times
from gonio.acquire.plans import load_plan
from gonio.rigs import control_table as ct
from gonio.rigs.config import load_rig
from gonio.rigs.kinematics import Kinematics, spherical

OUT = Path(__file__).resolve().parent / "results"


def bench_ordering(rig, plans):
    kin = Kinematics(rig)
    names = [kin.joint_names[r] for r in kin.ROLES]
    joints = [rig.joint(n) for n in names]
    rows = []
    for name in plans:
        plan, _ = load_plan(name)
        start = {n: rig.park_deg.get(n, 0.0) for n in names}
        idx = 0
        for s in range(plan.n_stages):
            t0 = time.perf_counter()
            sp = plan_stage(rig, plan, s, [], start, idx)
            t_plan = time.perf_counter() - t0
            acc = sp.accepted
            st = np.array([start[n] for n in names])
            # lexicographic sort of the targets' directions, each at its reference-nearest pose
            near = kin.joints_deg_to_pose(start)
            keyed = []
            for c in acc:
                pose, _ = kin.inverse(c.wi, c.wo, c.isotropic, near)
                ti, pi = spherical(np.array(c.wi))
                to, po = spherical(np.array(c.wo))
                key = tuple(np.round(np.degrees([ti, pi, to, po]), 6))
                keyed.append((key, np.degrees(pose.as_tuple())))
            keyed.sort(key=lambda kv: kv[0])
            lex_poses = np.array([p for _, p in keyed])
            lex = float(np.sum(move_times(st, lex_poses, np.arange(len(lex_poses)), joints)))
            opt = float(np.sum(sp.move_s))
            # lower bound of any order: every target is entered once, at best by its cheapest
            # incoming move (from the start or another target, over all equivalent poses)
            cands = []
            for c in acc:
                poses = [
                    p
                    for p in kin.candidates(c.wi, c.wo, c.isotropic, near.rot if c.isotropic else 0)
                    if kin.refusal(p) is None
                ]
                cands.append(np.degrees(np.array([p.as_tuple() for p in poses])))
            allp = np.vstack([st[None], *cands])
            owner = np.concatenate([[-1], *[np.full(len(c), i) for i, c in enumerate(cands)]])
            d = cost_matrix(allp, joints)
            d[owner[:, None] == owner[None, :]] = np.inf
            d[:, 0] = np.inf
            bound = 0.0
            for i in range(len(cands)):
                cols = np.nonzero(owner == i)[0]
                bound += float(np.min(d[:, cols]))
            rows.append(
                {
                    "plan": name,
                    "stage": s,
                    "configs": len(acc),
                    "plan_order_s": round(sp.lexicographic_s, 3),
                    "lexicographic_s": round(lex, 3),
                    "optimized_s": round(opt, 3),
                    "lower_bound_s": round(bound, 3),
                    "ratio_vs_lexicographic": round(lex / opt, 3) if opt else float("nan"),
                    "ratio_vs_plan_order": round(sp.lexicographic_s / opt, 3)
                    if opt
                    else float("nan"),
                    "best_possible_ratio": round(lex / bound, 3) if bound else float("nan"),
                    "planning_s": round(t_plan, 3),
                }
            )
            idx += len(sp.configs)
            if acc:
                start = dict(acc[-1].joints_deg)
    return rows


def bench_latency(rig, n):
    import dynamixel_sdk as sdk

    from gonio.rigs.session import make_emulator

    emu = make_emulator(rig, time_scale=1.0)
    port_name = emu.start()
    try:
        port = sdk.PortHandler(port_name)
        port.openPort()
        port.setBaudRate(rig.bus.baudrate)
        ph = sdk.PacketHandler(2.0)
        ids = [j.id for j in rig.joints]
        out = {"ping_1": [], "sync_read_4x20": []}
        failed = {"ping_1": 0, "sync_read_4x20": 0}
        a, m = ct.POLL_BLOCK
        for _ in range(n):
            t0 = time.perf_counter()
            _, res, _ = ph.ping(port, ids[0])
            t1 = time.perf_counter()
            if res == sdk.COMM_SUCCESS:
                out["ping_1"].append((t1 - t0) * 1e3)
            else:  # a reply missed the SDK's timeout (a loaded host): counted, not timed
                failed["ping_1"] += 1
            t0 = time.perf_counter()
            res = ph.syncReadTx(port, a, m, ids, len(ids), False)
            for sid in ids:
                if res != sdk.COMM_SUCCESS:
                    break
                _, res, _ = ph.readRx(port, sid, m)
            t1 = time.perf_counter()
            if res == sdk.COMM_SUCCESS:
                out["sync_read_4x20"].append((t1 - t0) * 1e3)
            else:
                failed["sync_read_4x20"] += 1
                port.is_using = False
        port.closePort()
    finally:
        emu.stop()
    return out, failed


def bench_time_split(plan):
    with tempfile.TemporaryDirectory() as d:
        run = Path(d) / "run"
        t0 = time.perf_counter()
        acquire(run, "sim_sample", plan, progress=False, write_table=False)
        wall = time.perf_counter() - t0
        events = [json.loads(x) for x in (run / "log.jsonl").read_text().splitlines()]
    rows = [e for e in events if e["event"] == "sample"]
    predicted = sum(e["predicted_motion_s"] for e in events if e["event"] == "stage_planned")
    return rows, wall, predicted


def markdown(rows: list[dict]) -> str:
    """A Markdown table of dict rows (same keys)."""
    keys = list(rows[0])
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    lines += ["| " + " | ".join(str(r[k]) for k in keys) + " |" for r in rows]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer latency samples, smaller plans")
    args = ap.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    rig = load_rig("sim")

    plans = ["iso-small", "grid4d-small", "halfdiff-small", "adaptive-small"]
    if not args.quick:
        plans.append("adaptive")
    rows = bench_ordering(rig, plans)
    with open(OUT / "rig_ordering.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    fig, ax = plt.subplots(figsize=(8, 4))
    labels = [f"{r['plan']}\nstage {r['stage']}" for r in rows]
    x = np.arange(len(rows))
    for k, (key, lab) in enumerate(
        [
            ("lexicographic_s", "lexicographic"),
            ("plan_order_s", "plan order"),
            ("optimized_s", "NN+2-opt"),
        ]
    ):
        ax.bar(x + (k - 1) * 0.27, [r[key] for r in rows], 0.27, label=lab)
    ax.set_xticks(x, labels, fontsize=7)
    ax.set_ylabel("predicted motion time (s, rig time)")
    ax.legend()
    ax.set_title("plan ordering on the sim rig")
    fig.tight_layout()
    fig.savefig(OUT / "rig_ordering.png", dpi=120)
    plt.close(fig)
    print("\n### Plan ordering (predicted motion time, rig seconds)\n")
    print(markdown(rows))

    lat, failed = bench_latency(rig, 300 if args.quick else 2000)
    lat_rows = []
    for k, v in lat.items():
        v = np.array(v)
        p50, p90, p99 = (round(float(np.percentile(v, q)), 3) for q in (50, 90, 99))
        lat_rows.append(
            {
                "transaction": k,
                "n": len(v),
                "timeouts": failed[k],
                "p50_ms": p50,
                "p90_ms": p90,
                "p99_ms": p99,
                "max_ms": round(float(v.max()), 3),
            }
        )
    with open(OUT / "rig_latency.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(lat_rows[0]))
        w.writeheader()
        w.writerows(lat_rows)
    print("\n### Bus round trip over the pty (dynamixel-sdk -> emulator)\n")
    print(markdown(lat_rows))
    fig, ax = plt.subplots(figsize=(6, 3.5))
    for k, v in lat.items():
        ax.hist(v, bins=60, alpha=0.6, label=k)
    ax.set_xlabel("round trip (ms) over the pty via dynamixel-sdk")
    ax.set_yscale("log")
    ax.legend()
    fig.tight_layout()
    fig.savefig(OUT / "rig_latency.png", dpi=120)
    plt.close(fig)

    split_plan = "iso-small" if args.quick else "adaptive-small"
    rows, wall, predicted = bench_time_split(split_plan)
    keys = ["t_motion", "t_settle", "t_capture", "t_book"]
    mean = {k: float(np.mean([r[k] for r in rows])) for k in keys}
    split = {
        "plan": split_plan,
        "configs": len(rows),
        "time_scale": rig.sim.time_scale,
        "wall_s": round(wall, 3),
        **{f"{k[2:]}_ms": round(mean[k] * 1e3, 3) for k in keys},
        # motion and settle run time_scale times faster than on hardware (polling overhead is
        # scaled up too); capture and bookkeeping are real wall time. The profile prediction is
        # what the same moves take on hardware.
        "motion_x_scale_ms": round(mean["t_motion"] * 1e3 * rig.sim.time_scale, 1),
        "settle_x_scale_ms": round(mean["t_settle"] * 1e3 * rig.sim.time_scale, 1),
        "predicted_motion_rig_ms": round(predicted / len(rows) * 1e3, 1),
    }
    with open(OUT / "rig_time_split.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(split))
        w.writeheader()
        w.writerow(split)
    print("\n### Wall time per configuration in a simulated run (mean)\n")
    print(markdown([split]))
    fig, ax = plt.subplots(figsize=(5, 3.5))
    bottom = 0.0
    for k in keys:
        ax.bar([0], [mean[k] * 1e3], bottom=bottom, label=k[2:])
        bottom += mean[k] * 1e3
    ax.set_xticks([0], [f"{split_plan}\n(time scale {rig.sim.time_scale:g})"])
    ax.set_ylabel("wall time per configuration (ms)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(OUT / "rig_time_split.png", dpi=120)
    plt.close(fig)


def write_tables() -> None:
    """Rewrite this benchmark's tables in benchmarks/README.md from its CSVs."""
    import _tables

    latency = [
        ("transaction", "transaction"),
        ("n", "n"),
        ("timeouts", "timeouts"),
        ("p50 (ms)", "p50_ms"),
        ("p90 (ms)", "p90_ms"),
        ("p99 (ms)", "p99_ms"),
        ("max (ms)", "max_ms"),
    ]
    _tables.write("rig_latency", _tables.markdown(_tables.read("rig_latency.csv"), latency))
    ordering = [
        ("plan", "plan"),
        ("stage", "stage"),
        ("configurations", "configs"),
        ("plan order (s)", "plan_order_s"),
        ("lexicographic (s)", "lexicographic_s"),
        ("optimized (s)", "optimized_s"),
        ("lower bound (s)", "lower_bound_s"),
        ("lexicographic / optimized", "ratio_vs_lexicographic"),
        ("planning (s)", "planning_s"),
    ]
    _tables.write("rig_ordering", _tables.markdown(_tables.read("rig_ordering.csv"), ordering))
    split = [
        ("plan", "plan"),
        ("configurations", "configs"),
        ("time scale", "time_scale"),
        ("wall (s)", "wall_s"),
        ("motion (ms)", "motion_ms"),
        ("settle (ms)", "settle_ms"),
        ("capture (ms)", "capture_ms"),
        ("bookkeeping (ms)", "book_ms"),
    ]
    _tables.write("rig_time_split", _tables.markdown(_tables.read("rig_time_split.csv"), split))


if __name__ == "__main__":
    main()
    write_tables()
