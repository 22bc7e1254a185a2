"""Where a cold ``gonio fit`` process's time goes, phase by phase, against another source tree.

Each process (a fresh interpreter, the persistent compilation cache filled by an earlier
process of the same code, or with ``--empty-cache`` an empty one) does what ``gonio fit
ARCHIVE::NAME -m lambert+cook-torrance --loss ngan --no-plots`` does, timing each phase (wall
and CPU seconds of the process, all threads):
``import jax``, the gonio imports, reading and tabulating the network (``io.load``),
``prepare`` (the cells under 80 degrees), the first fit (tracing or loading the fit's programs,
the compilation cache, the fit itself) and writing the JSON; then a second fit of the same
data in the same process (warm: what the first one costs beyond tracing and loading). JAX's
own event timers add the tracing, lowering and compile-or-cache-load seconds.

With ``--baseline SRC`` (e.g. an earlier commit's ``src``) the processes of the two codes
alternate, each code with its own cache directory, so that both see the same machine load.

Run from the repository root::

    PYTHONPATH=src python benchmarks/fit_phases.py --rounds 3 --baseline /tmp/base/src

Writes ``results/fit_phases.csv`` (one row per process and phase, with the load average).
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
SHARED = next(
    (p / "shared" / "data" for p in ROOT.parents if (p / "shared" / "data").is_dir()),
    ROOT.parent / "shared" / "data",
)
ARCHIVE = SHARED / "nbrdf" / "merl_nbrdf.zip"

_CHILD = r"""
import json, resource, sys, time
def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime
out, last = [], [time.perf_counter(), cpu()]
def mark(name):
    t, c = time.perf_counter(), cpu()
    out.append([name, t - last[0], c - last[1]])
    last[:] = [t, c]
import jax
mark("import jax")
events = {}
def listen(event, seconds, **kw):
    events[event] = events.get(event, 0.0) + seconds
jax.monitoring.register_event_duration_secs_listener(listen)
from gonio import compile_cache
compile_cache.enable()
import gonio.io
from gonio.fit.api import fit
from gonio.fit.data import prepare
mark("gonio imports")
table = gonio.io.load(sys.argv[1])
mark("io.load (tabulate the network)")
data = prepare(table)
mark("prepare (cells under 80 deg)")
r = fit(data, "lambert+cook-torrance", loss="ngan")
mark("first fit (programs, cache, fit, scores)")
r.save(sys.argv[2])
mark("write JSON")
ev = dict(events)
fit(data, "lambert+cook-torrance", loss="ngan")
mark("second fit in the process (warm)")
for key, name in (("/jax/core/compile/jaxpr_trace_duration", "JAX: tracing"),
                  ("/jax/core/compile/jaxpr_to_mlir_module_duration", "JAX: lowering"),
                  ("/jax/core/compile/backend_compile_duration", "JAX: compile or cache load")):
    out.append([name, ev.get(key, 0.0), None])
print(json.dumps(out))
"""


def run_child(src: str, cache: str, material: str) -> list[list]:
    """Phases ``[name, wall, cpu]`` of one fresh process running the source tree ``src``."""
    env = {**os.environ, "PYTHONPATH": src, "GONIO_COMPILE_CACHE": cache}
    with tempfile.TemporaryDirectory() as tmp:
        done = subprocess.run(
            [sys.executable, "-c", _CHILD, f"{ARCHIVE}::{material}", str(Path(tmp) / "r.json")],
            check=True, capture_output=True, text=True, env=env,
        )  # fmt: skip
    phases = json.loads(done.stdout.strip().splitlines()[-1])
    upto = [p for p in phases[: [p[0] for p in phases].index("write JSON") + 1]]
    total = ["total: imports to JSON", sum(p[1] for p in upto), sum(p[2] for p in upto)]
    return [*phases, total]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--material", default="gold-paint")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--baseline", metavar="SRC", help="another source tree to alternate with")
    ap.add_argument("--out", default="fit_phases")
    ap.add_argument("--empty-cache", action="store_true",
                    help="every process starts with an empty compilation cache (a new user's "
                         "first fit) instead of one filled by an earlier process")  # fmt: skip
    args = ap.parse_args()
    codes = {"current": str(ROOT / "src")}
    if args.baseline:
        codes["baseline"] = args.baseline
    rows = []
    with tempfile.TemporaryDirectory() as caches:
        dirs = {k: str(Path(caches) / k) for k in codes}
        if not args.empty_cache:
            for k, src in codes.items():  # fill each code's cache
                run_child(src, dirs[k], args.material)
        for rnd in range(args.rounds):
            for k, src in codes.items():
                load = os.getloadavg()[0]
                cache = dirs[k] if not args.empty_cache else str(Path(caches) / f"{k}-{rnd}")
                for name, wall, cpu in run_child(src, cache, args.material):
                    rows.append({"code": k, "round": rnd, "phase": name, "wall_s": wall,
                                 "cpu_s": cpu, "load1": load})  # fmt: skip
    RESULTS.mkdir(parents=True, exist_ok=True)
    with open(RESULTS / f"{args.out}.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    loads = [r["load1"] for r in rows]
    print(f"load average {min(loads):.1f}-{max(loads):.1f}; medians over {args.rounds} rounds")
    print(f"{'phase':45s}" + "".join(f"{k + ' wall':>14s}{k + ' CPU':>14s}" for k in codes))
    phases = list(dict.fromkeys(r["phase"] for r in rows))
    for ph in phases:
        line = f"{ph:45s}"
        for k in codes:
            sel = [r for r in rows if r["code"] == k and r["phase"] == ph]
            wall = np.median([r["wall_s"] for r in sel])
            cpus = [r["cpu_s"] for r in sel if r["cpu_s"] is not None]
            line += f"{wall:14.3f}" + (f"{np.median(cpus):14.3f}" if cpus else f"{'':14s}")
        print(line)


if __name__ == "__main__":
    main()
