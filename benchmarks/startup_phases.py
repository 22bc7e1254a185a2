"""Where a fresh process's time to its first image goes: a diagnostic split by in-process timers.

Each round starts a fresh Python process that times (wall and CPU seconds) ``import jax``,
gonio's render imports, building the studio environment (in memory, no file read), the first
128² Lambert render of it at 16 spp (tracing, lowering and compiling or loading from the
persistent compilation cache) and the same render again (the compiled kernels' own cost). The
first round fills the compilation cache (``--cache DIR``, default a fresh temporary folder,
passed as ``XDG_CACHE_HOME``); the rounds after it are what a second process sees.
``bench_first_image.py`` times the whole command (``gonio render``) against Mitsuba; this script
says which part of it is which.

Writes benchmarks/results/OUT.csv (default ``startup_phases``; one row per round, with the
``ml_dtypes`` version the interpreter imports) and prints a Markdown table.
Run: PYTHONPATH=src python benchmarks/startup_phases.py [--rounds 4]
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

RESULTS = Path(__file__).resolve().parent / "results"
PHASES = ("import_jax", "import_gonio", "environment", "first_render", "second_render")

CHILD = r"""
import json, time
t0, c0 = time.perf_counter(), time.process_time()
marks = {}
def mark(name):
    marks[name] = (time.perf_counter() - t0, time.process_time() - c0)
import jax
mark("import_jax")
from gonio import compile_cache
compile_cache.enable()
from gonio.brdf.models import Lambert
from gonio.render import Environment, render_sphere
from gonio.render.lights import studio_environment
mark("import_gonio")
env, model = [Environment(studio_environment())], Lambert(albedo=0.5)
mark("environment")
render_sphere(model, env, resolution=128, spp=16)
mark("first_render")
render_sphere(model, env, resolution=128, spp=16, seed=1)
mark("second_render")
import importlib.metadata
marks["ml_dtypes"] = importlib.metadata.version("ml_dtypes")
print(json.dumps(marks))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=4, help="processes (the first fills the cache)")
    ap.add_argument("--cache", type=Path, help="XDG_CACHE_HOME for the children (default: new)")
    ap.add_argument("--out", default="startup_phases", help="CSV name under benchmarks/results")
    args = ap.parse_args()
    cache = args.cache or Path(tempfile.mkdtemp(prefix="gonio-phases-"))
    env = {**os.environ, "XDG_CACHE_HOME": str(cache)}
    rows = []
    for r in range(args.rounds):
        load = os.getloadavg()[0]
        out = subprocess.run(
            [sys.executable, "-c", CHILD], env=env, check=True, capture_output=True, text=True
        ).stdout
        marks = json.loads(out.strip().splitlines()[-1])
        row: dict[str, object] = {"round": r, "cache": "empty" if r == 0 else "warm"}
        prev = (0.0, 0.0)
        for name in PHASES:
            wall, cpu = marks[name]
            row[f"{name}_wall_s"] = round(wall - prev[0], 3)
            row[f"{name}_cpu_s"] = round(cpu - prev[1], 3)
            prev = (wall, cpu)
        row["ml_dtypes"] = marks["ml_dtypes"]
        row["load_avg_1min"] = round(load, 1)
        rows.append(row)
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / f"{args.out}.csv"
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print("| round | cache | " + " | ".join(f"{p} CPU s (wall)" for p in PHASES) + " | load |")
    print("|---|---|" + "---:|" * (len(PHASES) + 1))
    for row in rows:
        cells = " | ".join(f"{row[f'{p}_cpu_s']} ({row[f'{p}_wall_s']})" for p in PHASES)
        print(f"| {row['round']} | {row['cache']} | {cells} | {row['load_avg_1min']} |")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
