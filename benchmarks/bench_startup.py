"""Start-up time of light commands: ``gonio --help``, ``info``, ``plan``, ``rig list``.

Each command runs ``--repeat`` times (default 5) as a fresh ``python -m gonio`` process; the
median wall time is reported together with the median CPU time of the process (user + system,
which the machine's load changes much less than the wall time: on an idle machine the wall
time is close to it) and whether the process imported jax, scipy and matplotlib (from
``python -X importtime``). Target (issue 21): under a second on an idle machine.
The machine's load at the time is printed with the table: on a loaded 2-core machine every
number grows several-fold. Writes ``benchmarks/results/startup.csv`` and ``startup.png``.
"""

from __future__ import annotations

import argparse
import csv
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"
HEAVY = ("jax", "scipy", "matplotlib")


def commands(table: Path) -> list[tuple[str, list[str]]]:
    return [
        ("--help", ["--help"]),
        ("info (native table)", ["info", str(table)]),
        ("plan --plan iso-tiny", ["plan", "--rig", "sim", "--plan", "iso-tiny"]),
        ("rig list", ["rig", "list"]),
    ]


def _table(tmp: Path) -> Path:
    """A small native table to describe (written with h5py-free gonio.io)."""
    import numpy as np

    from gonio import io
    from gonio.brdf.measured import MeasuredSamples

    rng = np.random.default_rng(0)
    w = rng.normal(size=(50, 3))
    w[:, 2] = np.abs(w[:, 2]) + 0.1
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    path = tmp / "t.brdf.h5"
    io.save(MeasuredSamples(w, w[::-1], np.full((50, 3), 0.1)), path)
    return path


def imported(args: list[str]) -> dict[str, bool]:
    out = subprocess.run([sys.executable, "-X", "importtime", "-m", "gonio", *args],
                         capture_output=True, text=True)  # fmt: skip
    names = {line.rsplit("|", 1)[-1].strip() for line in out.stderr.splitlines() if "|" in line}
    return {h: h in names for h in HEAVY}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        table = _table(Path(tmp))
        for label, cmd in commands(table):
            times, cpu = [], []
            for _ in range(args.repeat):
                r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
                t0 = time.perf_counter()
                subprocess.run([sys.executable, "-m", "gonio", *cmd], capture_output=True,
                               check=True)  # fmt: skip
                times.append(time.perf_counter() - t0)
                r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
                cpu.append(r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)
            rows.append({"command": label, "median_s": statistics.median(times),
                         "min_s": min(times), "cpu_median_s": statistics.median(cpu),
                         **imported(cmd)})  # fmt: skip
    RESULTS.mkdir(exist_ok=True)
    with open(RESULTS / "startup.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 2.8), constrained_layout=True)
    ax.barh([r["command"] for r in rows], [r["median_s"] for r in rows])
    ax.axvline(1.0, color="k", ls="--", label="1 s target (idle machine)")
    ax.set_xlabel("wall time, median (s)")
    ax.set_title(f"gonio start-up (load average {os.getloadavg()[0]:.1f})")
    ax.legend()
    fig.savefig(RESULTS / "startup.png", dpi=110)
    print(f"load average {os.getloadavg()[0]:.1f}")
    print("| command | median (s) | min (s) | CPU median (s) | imports jax | scipy | matplotlib |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| `gonio {r['command']}` | {r['median_s']:.2f} | {r['min_s']:.2f} | "
              f"{r['cpu_median_s']:.2f} | "
              f"{'yes' if r['jax'] else 'no'} | {'yes' if r['scipy'] else 'no'} | "
              f"{'yes' if r['matplotlib'] else 'no'} |")  # fmt: skip
    return 0


def write_tables() -> None:
    """Rewrite this benchmark's table in benchmarks/README.md from its CSV."""
    import _tables

    columns = [
        ("command", lambda r: f"gonio {r['command']}"),
        ("median (s)", "median_s"),
        ("min (s)", "min_s"),
        ("CPU, median (s)", "cpu_median_s"),
        ("imports jax", "jax"),
        ("imports scipy", "scipy"),
        ("imports matplotlib", "matplotlib"),
    ]
    _tables.write("startup", _tables.markdown(_tables.read("startup.csv"), columns))


if __name__ == "__main__":
    _rc = main()
    if not _rc:
        write_tables()
    sys.exit(_rc)
