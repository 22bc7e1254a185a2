"""Soak: a long acquisition on the simulated rig with a faulty bus, measured as it runs.

One ``gonio.acquire.engine.acquire`` run of ``--n`` configurations (default 10,000: an isotropic
plan of 10 incident x 10 outgoing polar angles x n/100 azimuth differences, every pose
reachable) on the fast direct-reading rig ``sim_sample``, time-compressed (the emulator's
``time_scale``, default 1000 simulated seconds per wall second: a move's profile and settling
take a thousandth of their rig time, every packet still crosses the pseudo-terminal through
dynamixel-sdk), with packet faults on the bus: a fraction ``--faults`` (default 5 %) of the
packets is lost or damaged, split evenly between dropped instructions, instructions arriving
with a CRC error (corrupted) and garbled status packets. No hardware fault is injected (those
stop the run: docs/guide/rig.md).

Every ``--window`` configurations the run's own process records its resident memory (VmRSS),
the journal's size on disk (``journal.sqlite`` with its WAL), ``log.jsonl``'s size, the
configurations per minute of the window, the process's CPU time per configuration, the host's
load average and the bus counters. The emulator's in-memory lists
of every packet and goal it received (test instruments, absent on a real rig) are emptied at
each window; everything else is the code path of a real run. The run table is not written
(``write_table=False``): the soak measures the loop.

At the end the journal is checked: every planned configuration has exactly one sample, and
``log.jsonl`` names each sample once (lost and duplicated samples are counted).

Writes ``results/soak.csv`` (one row per window), ``results/soak_summary.csv`` and
``results/soak.png``, and the README's ``soak`` table. Run:
``PYTHONPATH=src nice -n 10 python benchmarks/bench_soak.py [--n 10000]``.
"""

from __future__ import annotations

import argparse
import csv
import json
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
OUT = HERE / "results"
WINDOW_FIELDS = (
    "configs",
    "wall_s",
    "configs_per_min",
    "cpu_ms_per_config",
    "host_load",
    "rss_mb",
    "journal_mb",
    "log_mb",
    "retries",
    "timeouts",
    "corrupt",
    "crc_errors",
    "stops",
)


def plan_text(n: int) -> str:
    """An isotropic plan of ``n`` configurations (a multiple of 100), every pose reachable on
    the sim rig: theta_i 3..39 deg, theta_o 48..79.5 deg, n/100 azimuth differences."""
    k = n // 100
    if k < 1 or n % 100:
        raise SystemExit("--n must be a positive multiple of 100")
    step = 180.0 / k
    return (
        'kind = "isotropic"\n'
        "theta_i_deg = { start = 3, stop = 39, step = 4 }\n"
        "theta_o_deg = { start = 48, stop = 79.5, step = 3.5 }\n"
        f"dphi_deg = {{ start = 0, stop = {180.0 - step:.6f}, step = {step:.6f} }}\n"
    )


def rss_mb() -> float:
    """This process's resident set (VmRSS), MB."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def _size_mb(*paths: Path) -> float:
    return sum(p.stat().st_size for p in paths if p.exists()) / 1e6


def soak(
    n: int,
    time_scale: float,
    fault_p: float,
    window: int,
    seed: int,
    run: Path,
    retries: int = 6,
    max_stops: int = 20,
    minutes: float | None = None,
):
    """Run the soak into ``run`` (the rig's ``bus.retries`` set to ``retries``; a run stopped by
    a bus fault is resumed up to ``max_stops`` times; after ``minutes`` of wall time the run is
    stopped as Ctrl-C stops it, and the summary covers what was measured); (window rows,
    summary dict)."""
    import os
    import signal

    from gonio.acquire.engine import acquire
    from gonio.acquire.journal import Journal
    from gonio.errors import DeviceError
    from gonio.rigs.config import load_rig, parse_rig
    from gonio.rigs.session import open_rig
    from gonio.rigs.sim import FaultConfig

    plan = run.parent / "soak_plan.toml"
    plan.write_text(plan_text(n))
    base = load_rig("sim_sample")
    rig = parse_rig(base.text.replace("retries = 6", f"retries = {retries}"), base.source)
    each = fault_p / 3.0
    faults = FaultConfig(drop=each, garble=each, crc=each, seed=seed)
    rows: list[dict] = []
    keys = ("transactions", "retries", "timeouts", "corrupt", "crc_errors")
    state = {
        "t": time.perf_counter(),
        "cpu": time.process_time(),
        "n": 0,
        "done": 0,
        "last": {},
        "before": {},
    }
    t0 = time.perf_counter()

    def bus_total(st: dict) -> dict:
        """Bus counters summed over the sessions (each resume opens a new bus)."""
        if st.get("transactions", 0) < state["last"].get("transactions", 0):
            state["before"] = {k: state["before"].get(k, 0) + state["last"][k] for k in keys}
        state["last"] = {k: st.get(k, 0) for k in keys}
        return {k: state["before"].get(k, 0) + state["last"][k] for k in keys}

    def hook(_: int, ses) -> None:
        state["done"] += 1
        done = state["done"]
        if minutes is not None and time.perf_counter() - t0 > 60.0 * minutes:
            if not state.get("deadline"):
                state["deadline"] = True
                os.kill(os.getpid(), signal.SIGINT)  # finish this configuration, park, stop
        if done % window:
            return
        now, cpu = time.perf_counter(), time.process_time()
        emu = ses.emulator
        emu.goal_log.clear()  # test instruments of the emulator, not part of a run
        emu.packet_log.clear()
        st = bus_total(ses.chain.bus_stats())
        rows.append(
            {
                "configs": done,
                "wall_s": round(now - t0, 3),
                "configs_per_min": round((done - state["n"]) * 60.0 / (now - state["t"]), 1),
                # this process's CPU time (driver, emulator thread, journal): the run's own
                # cost, less sensitive than the rate to the host's other load
                "cpu_ms_per_config": round((cpu - state["cpu"]) * 1e3 / (done - state["n"]), 2),
                "host_load": round(os.getloadavg()[0], 1),
                "rss_mb": round(rss_mb(), 2),
                "journal_mb": round(
                    _size_mb(run / "journal.sqlite", run / "journal.sqlite-wal"), 3
                ),
                "log_mb": round(_size_mb(run / "log.jsonl"), 3),
                **{k: st[k] for k in keys[1:]},
                "stops": len(stops),
            }
        )
        state["t"], state["cpu"], state["n"] = now, cpu, done
        r = rows[-1]
        print(
            f"{done:6d} configs  {r['wall_s']:8.1f} s  {r['configs_per_min']:7.1f}/min"
            f"  CPU {r['cpu_ms_per_config']:6.2f} ms  load {r['host_load']:5.1f}"
            f"  RSS {r['rss_mb']:7.1f} MB  journal {r['journal_mb']:7.2f} MB",
            flush=True,
        )

    stops: list[str] = []  # a run stopped by the bus is resumed, as a user would
    while True:
        try:
            summary = acquire(
                run,
                None if stops else rig,
                None if stops else plan,
                resume=bool(stops),
                progress=False,
                write_table=False,
                on_sample=hook,
                open_devices=lambda r, d: open_rig(
                    r, faults=faults, log_dir=d, time_scale=time_scale
                ),
            )
            break
        except KeyboardInterrupt:
            if not state.get("deadline"):
                raise
            summary = None
            break
        except DeviceError as exc:
            stops.append(str(exc))
            print(f"stopped after {state['done']} configurations: {exc}; resuming", flush=True)
            if len(stops) > max_stops:
                raise
    wall = time.perf_counter() - t0
    # lost and duplicated samples, from the journal and the run's log
    j = Journal(run)
    planned = {c.idx for c in j.configs() if c.status == "planned"}
    sampled = [s.idx for s in j.samples()]
    done_total = j.counts()["done"]
    j.close()
    logged = [
        json.loads(x)["idx"]
        for x in (run / "log.jsonl").read_text().splitlines()
        if json.loads(x)["event"] == "sample"
    ]
    if not rows:
        raise SystemExit(f"no window of {window} configurations completed")
    warm = max(1, len(rows) // 10)  # the first tenth of the run is warm-up
    rss_warm = rows[warm - 1]["rss_mb"]
    after = rows[warm:]
    cpm = [r["configs_per_min"] for r in after]
    q = max(1, len(cpm) // 4)
    out = {
        "configs": n,
        "done": done_total,
        "stopped_at_deadline": bool(state.get("deadline")),
        "time_scale": time_scale,
        "fault_p": fault_p,
        "wall_s": round(wall, 1),
        "configs_per_min": round(done_total * 60.0 / wall, 1),
        "cpm_first_quarter": round(sum(cpm[:q]) / q, 1),
        "cpm_last_quarter": round(sum(cpm[-q:]) / q, 1),
        "cpu_ms_first_quarter": round(sum(r["cpu_ms_per_config"] for r in after[:q]) / q, 2),
        "cpu_ms_last_quarter": round(sum(r["cpu_ms_per_config"] for r in after[-q:]) / q, 2),
        "host_load_mean": round(sum(r["host_load"] for r in rows) / len(rows), 1),
        "rss_warm_mb": rss_warm,
        "rss_max_mb": max(r["rss_mb"] for r in after) if after else rss_warm,
        "rss_growth_pct": round(
            100.0 * (max(r["rss_mb"] for r in after) - rss_warm) / rss_warm if after else 0.0, 2
        ),
        "journal_mb": round(_size_mb(run / "journal.sqlite", run / "journal.sqlite-wal"), 3),
        "journal_bytes_per_config": round(
            1e6 * _size_mb(run / "journal.sqlite", run / "journal.sqlite-wal") / max(1, n)
        ),
        # lost: planned and logged as measured but not in the journal, or (run complete)
        # planned and never measured
        "lost": len((set(logged) if summary is None else planned) - set(sampled)),
        "duplicated": (len(sampled) - len(set(sampled))) + (len(logged) - len(set(logged))),
        "bus_retries_setting": retries,
        "stops": len(stops),
        "first_stop": stops[0] if stops else "",
        **{k: rows[-1][k] for k in ("retries", "timeouts", "corrupt", "crc_errors")},
    }
    return rows, out


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = [r["configs"] for r in rows]
    fig, axes = plt.subplots(4, 1, figsize=(7, 9), sharex=True)
    for ax, key, label in zip(
        axes,
        ("rss_mb", "journal_mb", "configs_per_min", "cpu_ms_per_config"),
        (
            "resident memory (MB)",
            "journal on disk (MB)",
            "configurations / min",
            "CPU per configuration (ms)",
        ),
        strict=True,
    ):
        ax.plot(x, [r[key] for r in rows], marker=".", lw=1)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].set_ylim(bottom=0)
    axes[2].set_ylim(bottom=0)
    axes[3].set_ylim(bottom=0)
    axes[-1].set_xlabel("configurations measured")
    axes[0].set_title("soak: sim_sample rig, packet faults on the bus")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10_000, help="configurations (multiple of 100)")
    ap.add_argument("--time-scale", type=float, default=1000.0, help="simulated s per wall s")
    ap.add_argument(
        "--faults",
        type=float,
        default=0.05,
        help="fraction of packets dropped, corrupted or garbled (a third each)",
    )
    ap.add_argument("--window", type=int, default=250, help="configurations per recorded row")
    ap.add_argument("--seed", type=int, default=1, help="fault seed")
    ap.add_argument("--retries", type=int, default=6, help="the rig's bus.retries (sim_sample: 6)")
    ap.add_argument("--max-stops", type=int, default=20, help="bus stops resumed, at most")
    ap.add_argument("--minutes", type=float, help="stop (as Ctrl-C does) after this wall time")
    ap.add_argument("--run", type=Path, help="run directory to keep (default: a temporary one)")
    args = ap.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        run = args.run or Path(tmp) / "run"
        run.parent.mkdir(parents=True, exist_ok=True)
        rows, summary = soak(
            args.n,
            args.time_scale,
            args.faults,
            args.window,
            args.seed,
            run,
            args.retries,
            args.max_stops,
            args.minutes,
        )
    with open(OUT / "soak.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=WINDOW_FIELDS)
        w.writeheader()
        w.writerows(rows)
    with open(OUT / "soak_summary.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(summary))
        w.writeheader()
        w.writerow(summary)
    plot(rows, OUT / "soak.png")
    print(json.dumps(summary, indent=1))


def write_tables() -> None:
    """Rewrite this benchmark's table in benchmarks/README.md from its CSV."""
    import _tables

    columns = [
        ("configurations", "done"),
        ("time scale", "time_scale"),
        ("faulty packets", "fault_p"),
        ("wall (s)", "wall_s"),
        ("configs / min", "configs_per_min"),
        (
            "first / last quarter (per min)",
            lambda r: f"{r['cpm_first_quarter']} / {r['cpm_last_quarter']}",
        ),
        (
            "CPU per config, first / last quarter (ms)",
            lambda r: f"{r['cpu_ms_first_quarter']} / {r['cpu_ms_last_quarter']}",
        ),
        ("host load (mean)", "host_load_mean"),
        ("RSS after warm-up (MB)", "rss_warm_mb"),
        ("RSS growth (%)", "rss_growth_pct"),
        ("journal (MB)", "journal_mb"),
        ("journal (B / config)", "journal_bytes_per_config"),
        ("bus.retries", "bus_retries_setting"),
        ("stops (resumed)", "stops"),
        ("lost", "lost"),
        ("duplicated", "duplicated"),
        ("retries", "retries"),
        ("timeouts", "timeouts"),
    ]
    _tables.write("soak", _tables.markdown(_tables.read("soak_summary.csv"), columns))


if __name__ == "__main__":
    main()
    write_tables()
