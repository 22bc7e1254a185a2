"""Same-run A/B of table lookup and sampling throughput against an earlier commit.

This machine's speed drifts by 10-25 % over hours, more than most single optimizations of the
table paths, so a change is judged against the commit before it measured in the same run: the
script checks the reference commit out into a temporary git worktree and alternates child
processes running the reference code (``PYTHONPATH=<worktree>/src``) and the working tree's
code, ``--rounds`` times each, in ABBA order. Every child times, on the same 1e6 random float32
queries as ``bench_throughput.py`` (its MERL-resolution Lambert + Torrance-Sparrow table), the
jitted lookup ``f`` and sampling by inversion, alias and rejection (default majorant proposal;
called eagerly and under ``jit``), each the median of ``--calls`` calls after warm-up, in
millions per second. With ``--clock cpu`` a call is timed by the CPU time of the child process
(all threads) instead of wall time: on a machine shared with other work it counts what the call
costs rather than how long it waited for a core (the figure is then CPU-seconds per query, not a
rate anyone sees; compare ratios).

Writes benchmarks/results/table_ab.csv (or ``--csv NAME``; one row per child and operation) and
prints a Markdown table with each side's range over the rounds and the ratio of their medians.
Run: .venv/bin/python benchmarks/ab_table.py --ref COMMIT [--rounds R] [--calls K] [--clock cpu]
[--ops lookup,inversion,render-inversion,...] [--csv NAME]
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
RESULTS = HERE / "results"
OPS = ("lookup", "inversion", "alias", "rejection", "rejection-jit")
#: renders of the table (128² sphere, studio environment, 16 spp) by each sampler: rates in
#: million samples (pixels hit x spp) per second
RENDER_OPS = ("render-inversion", "render-alias", "render-rejection")


def median_cpu_time(fn, repeats: int) -> float:
    """Median process CPU time (s, all threads) of ``fn()`` after one warm-up call."""
    import jax

    jax.block_until_ready(fn())
    times = []
    for _ in range(repeats):
        c = time.process_time()
        jax.block_until_ready(fn())
        times.append(time.process_time() - c)
    return statistics.median(times)


def child(batch: int, calls: int, clock: str = "wall", ops=OPS) -> dict[str, float]:
    """Throughput (M/s) of each operation with whichever gonio is importable."""
    import jax
    import numpy as np

    sys.path.insert(0, str(HERE))
    from bench_throughput import benchmark_table, median_time, upper_directions

    table, _ = benchmark_table()
    rng = np.random.default_rng(0)
    wo = jax.device_put(upper_directions(batch, rng))
    u = jax.device_put(rng.random((batch, 2)).astype(np.float32))
    wi = jax.device_put(upper_directions(batch, rng))
    lookup = jax.jit(lambda a, b: table.f(a, b))
    sample_jit = jax.jit(lambda a, b: table.sample(a, b, method="rejection"))
    calls_of = {
        "lookup": lambda: lookup(wi, wo),
        "rejection-jit": lambda: sample_jit(wo, u),  # the sampler called under jit: no host loop
    }
    from gonio.render import Environment, RenderStats, render_sphere

    stats = RenderStats()
    env = Environment("studio")

    def render(method):
        return lambda: render_sphere(
            table, env, resolution=128, spp=16, sampler=method, stats=stats
        )

    for op in RENDER_OPS:
        calls_of[op] = render(op.split("-")[1])
    rates = {}
    for op in ops:
        fn = calls_of.get(op, lambda op=op: table.sample(wo, u, method=op))
        jax.block_until_ready(fn())  # compile and build the sampling structures
        timer = median_cpu_time if clock == "cpu" else median_time
        count = stats.pixels * 16 if op in RENDER_OPS else batch
        rates[op] = count / timer(fn, calls) / 1e6  # after one more warm-up call
    return rates


def run_child(src: Path, batch: int, calls: int, clock: str = "wall", ops=OPS) -> dict[str, float]:
    env = dict(os.environ, PYTHONPATH=str(src))
    cmd = [sys.executable, __file__, "--child", "--batch", str(batch), "--calls", str(calls)]
    cmd += ["--clock", clock, "--ops", ",".join(ops)]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    if out.returncode != 0:
        raise SystemExit(f"benchmark child for {src} failed: {out.stderr.strip().splitlines()[-1]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ref", help="commit to compare against (required unless --child)")
    ap.add_argument("--rounds", type=int, default=3, help="alternations of the two sides")
    ap.add_argument("--calls", type=int, default=9, help="timed calls per figure (median)")
    ap.add_argument(
        "--clock", choices=("wall", "cpu"), default="wall", help="time calls by wall or CPU time"
    )
    ap.add_argument("--batch", type=float, default=1e6, help="queries per call (default 1e6)")
    ap.add_argument(
        "--ops",
        default=",".join(OPS),
        help=f"comma-separated operations to time, of {', '.join(OPS + RENDER_OPS)}",
    )
    ap.add_argument("--csv", default="table_ab.csv", help="file name under benchmarks/results")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    batch = int(args.batch)
    ops = tuple(o for o in args.ops.split(",") if o)
    unknown = sorted(set(ops) - set(OPS + RENDER_OPS))
    if unknown or not ops:
        ap.error(f"unknown operation(s) {unknown}; choose from {', '.join(OPS + RENDER_OPS)}")
    if args.child:
        print(json.dumps(child(batch, args.calls, args.clock, ops)))
        return
    if not args.ref:
        ap.error("--ref COMMIT is required")
    head = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True
    ).stdout.strip()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tree = Path(tmp) / "ref"
        made = subprocess.run(
            ["git", "worktree", "add", "--detach", str(tree), args.ref],
            cwd=ROOT,
            capture_output=True,
            text=True,
        )
        if made.returncode != 0:
            raise SystemExit(f"cannot check out {args.ref!r}: {made.stderr.strip()}")
        try:
            sides = [("ref", tree / "src"), ("new", ROOT / "src")]
            for r in range(args.rounds):
                # ABBA order: with a fixed order a steady drift of the machine's speed over
                # the run would favour whichever side goes first in every round
                for side, src in sides if r % 2 == 0 else sides[::-1]:
                    rates = run_child(src, batch, args.calls, args.clock, ops)
                    print(
                        f"round {r + 1} {side}: "
                        + ", ".join(f"{k} {v:.2f}" for k, v in rates.items())
                    )
                    rows += [
                        {"round": r + 1, "side": side, "op": op, "rate_M_per_s": f"{v:.3f}"}
                        for op, v in rates.items()
                    ]
        finally:
            subprocess.run(
                ["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT, check=False
            )
    RESULTS.mkdir(exist_ok=True)
    with open(RESULTS / args.csv, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=["round", "side", "op", "rate_M_per_s"])
        w.writeheader()
        w.writerows(rows)
    print(
        f"\n| M/s ({args.clock} clock, batch {batch:.0e}) | {args.ref} | working tree ({head}+) "
        "| ratio of medians |"
    )
    print("|---|---:|---:|---:|")
    for op in ops:
        ref = [float(x["rate_M_per_s"]) for x in rows if x["op"] == op and x["side"] == "ref"]
        new = [float(x["rate_M_per_s"]) for x in rows if x["op"] == op and x["side"] == "new"]
        ratio = statistics.median(new) / statistics.median(ref)
        span = f"{min(ref):.1f}–{max(ref):.1f} | {min(new):.1f}–{max(new):.1f}"
        print(f"| {op} | {span} | {ratio:.2f} |")


if __name__ == "__main__":
    main()
