"""CPU and wall time of ``import jax, jax.numpy`` in fresh processes, per Python environment.

The floor under every gonio process that renders or fits is JAX's own import; most of it was
measured to be ``ml_dtypes`` registering its NumPy ufunc loops, and its cost depends on the
``ml_dtypes`` release. This script times the same statement in each interpreter given (e.g.
virtual environments that differ only in ``ml_dtypes``), in alternating rounds so that a drift
of the machine's speed favours none, and records each environment's NumPy, ml_dtypes and JAX
versions. CPU = the child's user + system time (``getrusage``), which waiting for a core on a
loaded machine does not inflate.

Writes benchmarks/results/OUT.csv (default ``import_jax``) and prints a Markdown table.
Run: python benchmarks/bench_import_jax.py --python ENV1/bin/python --python ENV2/bin/python
[--rounds 8]
"""

from __future__ import annotations

import argparse
import csv
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"
STATEMENT = "import jax, jax.numpy"
VERSIONS = (
    "import importlib.metadata as m; "
    "print(' '.join(m.version(p) for p in ('numpy', 'ml_dtypes', 'jax')))"
)


def _child_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--python", action="append", type=Path, help="an interpreter (repeatable)")
    ap.add_argument("--rounds", type=int, default=8)
    ap.add_argument("--out", default="import_jax", help="CSV name under benchmarks/results")
    args = ap.parse_args()
    pythons = args.python or [Path(sys.executable)]
    for py in pythons:
        if not py.is_file():
            sys.exit(f"bench_import_jax: no such interpreter: {py}")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.setdefault("JAX_PLATFORMS", "cpu")
    versions = {}
    for py in pythons:
        out = subprocess.run([str(py), "-c", VERSIONS], env=env, capture_output=True, text=True)
        if out.returncode != 0:
            sys.exit(f"bench_import_jax: {py} cannot import numpy, ml_dtypes and jax")
        versions[py] = out.stdout.split()
    load0 = os.getloadavg()[0]
    cpu: dict[Path, list[float]] = {py: [] for py in pythons}
    wall: dict[Path, list[float]] = {py: [] for py in pythons}
    for r in range(args.rounds):
        for py in pythons if r % 2 == 0 else pythons[::-1]:
            c0, t0 = _child_cpu(), time.perf_counter()
            subprocess.run([str(py), "-c", STATEMENT], env=env, check=True)
            wall[py].append(time.perf_counter() - t0)
            cpu[py].append(_child_cpu() - c0)
    load1 = os.getloadavg()[0]
    rows = []
    for py in pythons:
        numpy_v, mld_v, jax_v = versions[py]
        rows.append(
            {
                "python": str(py),
                "numpy": numpy_v,
                "ml_dtypes": mld_v,
                "jax": jax_v,
                "rounds": args.rounds,
                "cpu_median_s": f"{statistics.median(cpu[py]):.3f}",
                "cpu_min_s": f"{min(cpu[py]):.3f}",
                "cpu_max_s": f"{max(cpu[py]):.3f}",
                "wall_median_s": f"{statistics.median(wall[py]):.3f}",
                "load_avg_1min": f"{load0:.1f}-{load1:.1f}",
            }
        )
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / f"{args.out}.csv"
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print(f"`{STATEMENT}`, {args.rounds} alternating rounds, load average {load0:.1f}-{load1:.1f}")
    print("| NumPy | ml_dtypes | JAX | CPU median (range) s | wall median s |")
    print("|---|---|---|---:|---:|")
    for row in rows:
        print(
            f"| {row['numpy']} | {row['ml_dtypes']} | {row['jax']} | {row['cpu_median_s']} "
            f"({row['cpu_min_s']}–{row['cpu_max_s']}) | {row['wall_median_s']} |"
        )
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
