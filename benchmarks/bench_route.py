"""Route planning at scale: the full-matrix ordering against the neighbour-list one.

For n = 500 ... 10,000 poses of the sim rig's four joints (uniform random in +-120 deg, and the
first n nodes of a regular 4-D grid), each ordering (:func:`gonio.acquire.ordering.order_poses`
with ``lists=False`` / ``lists=True``, default 10 s improvement budget) runs in its own child
process, which reports:

* the route's travel time (rig s, sum of the slowest joint's move times from the zero pose);
* wall and CPU time (s) of the ordering;
* peak memory: traced by :mod:`tracemalloc` during the ordering (MB), and the child's peak
  resident set (MB, imports included).

The matrix ordering runs up to ``--matrix-max`` poses (default 5,000: its cost matrix is
8 n^2 bytes, and its 2-opt pass O(n^2)).

Writes ``results/route.csv`` and ``results/route.png``. Run:
``PYTHONPATH=src nice -n 10 python benchmarks/bench_route.py [--quick]``.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
OUT = HERE / "results"
SIZES = (500, 1000, 2000, 5000, 10_000)
FIELDS = (
    "poses",
    "n",
    "method",
    "travel_s",
    "travel_vs_matrix",
    "wall_s",
    "cpu_s",
    "traced_peak_mb",
    "maxrss_mb",
)


def poses(kind: str, n: int):
    """(n, 4) joint angles (deg): ``random`` uniform in +-120, or ``grid`` nodes in order."""
    import numpy as np

    if kind == "random":
        return np.random.default_rng(0).uniform(-120, 120, size=(n, 4))
    m = int(np.ceil(n**0.25))
    g = np.linspace(-120, 120, m)
    return np.stack(np.meshgrid(g, g, g, g, indexing="ij"), -1).reshape(-1, 4)[:n]


def one(kind: str, n: int, method: str) -> dict:
    """Order ``n`` poses of ``kind`` with ``method`` in this process; the measurements."""
    import resource
    import time
    import tracemalloc

    import numpy as np
    import scipy.spatial  # noqa: F401  before timing: the ordering is timed, not an import

    from gonio.acquire.ordering import order_poses, path_time
    from gonio.rigs.config import load_rig

    joints = list(load_rig("sim", check_sample_model=False).joints)
    p = poses(kind, n)
    start = np.zeros(4)
    tracemalloc.start()
    wall, cpu = time.perf_counter(), time.process_time()
    order = order_poses(start, p, joints, lists=method == "lists")
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert sorted(order.tolist()) == list(range(n))
    return {
        "travel_s": path_time(start, p, order, joints),
        "wall_s": wall,
        "cpu_s": cpu,
        "traced_peak_mb": peak / 1e6,
        "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def child(kind: str, n: int, method: str) -> dict:
    """:func:`one` in a fresh interpreter (its own peak memory)."""
    env = dict(os.environ, PYTHONPATH=str(HERE.parent / "src"))
    out = subprocess.run(
        [sys.executable, __file__, "--one", kind, str(n), method],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(out.stdout)


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="n = 500 and 1,000 only")
    ap.add_argument("--matrix-max", type=int, default=5000)
    ap.add_argument("--one", nargs=3, metavar=("KIND", "N", "METHOD"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        kind, n, method = args.one
        json.dump(one(kind, int(n), method), sys.stdout)
        return []
    rows = []
    for kind in ("random", "grid"):
        for n in SIZES[:2] if args.quick else SIZES:
            matrix = None
            for method in ("matrix", "lists"):
                if method == "matrix" and n > args.matrix_max:
                    continue
                r = child(kind, n, method)
                matrix = r["travel_s"] if method == "matrix" else matrix
                r["travel_vs_matrix"] = r["travel_s"] / matrix if matrix else float("nan")
                rows.append({"poses": kind, "n": n, "method": method, **r})
                print(
                    f"{kind:6s} n={n:6d} {method:6s} travel {r['travel_s']:9.1f} s"
                    f"  wall {r['wall_s']:6.2f} s  cpu {r['cpu_s']:6.2f} s"
                    f"  traced {r['traced_peak_mb']:7.1f} MB  rss {r['maxrss_mb']:7.1f} MB",
                    flush=True,
                )
    OUT.mkdir(exist_ok=True)
    with open(OUT / "route.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, FIELDS)
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    plot(rows)
    return rows


def plot(rows: list[dict]) -> None:
    """``results/route.png``: travel time per move, wall time and traced peak memory against n."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    panels = (
        ("travel_per_move_s", "travel time per move (rig s)"),
        ("wall_s", "ordering wall time (s)"),
        ("traced_peak_mb", "traced peak memory (MB)"),
    )
    for ax, (field, label) in zip(axes, panels, strict=True):
        for kind, marker in (("random", "o"), ("grid", "s")):
            for method, style in (("matrix", "--"), ("lists", "-")):
                sel = [
                    {**r, "travel_per_move_s": r["travel_s"] / r["n"]}
                    for r in rows
                    if r["poses"] == kind and r["method"] == method
                ]
                if sel:
                    ax.plot(
                        [r["n"] for r in sel],
                        [r[field] for r in sel],
                        style,
                        marker=marker,
                        label=f"{method}, {kind}",
                    )
        ax.set_xscale("log")
        ax.set_yscale("linear" if field == "travel_per_move_s" else "log")
        ax.set_xlabel("poses")
        ax.set_ylabel(label)
    axes[2].axhline(500, color="grey", lw=0.8)
    axes[0].legend(fontsize=8)
    fig.suptitle("route planning on the sim rig: full cost matrix against neighbour lists")
    fig.tight_layout()
    fig.savefig(OUT / "route.png", dpi=120)
    plt.close(fig)


def write_tables() -> None:
    """Rewrite this benchmark's table in benchmarks/README.md from its CSV."""
    import _tables

    columns = [
        ("poses", "poses"),
        ("n", "n"),
        ("method", "method"),
        ("travel (s)", "travel_s"),
        ("travel / matrix", "travel_vs_matrix"),
        ("wall (s)", "wall_s"),
        ("CPU (s)", "cpu_s"),
        ("traced peak (MB)", "traced_peak_mb"),
        ("peak RSS (MB)", "maxrss_mb"),
    ]
    _tables.write("route", _tables.markdown(_tables.read("route.csv"), columns))


if __name__ == "__main__":
    if main():  # not in a child's --one run
        write_tables()
