"""Wall time of ``gonio demo`` per stage, default and ``--quick``, and what each run recovered.

Runs the demo exactly as ``make demo`` does (the material found by ``--material auto``: the
first RGL-EPFL file in ../shared/data, else the built-in paint) and the quick demo on the
built-in material (known truth), each into a temporary folder, and records the stage timings
from the run's own summary, the number of configurations and, for the built-in material, the
largest ``|fit - truth| / std`` of the true model's parameters and whether it is within the
family-wise 1 % limit (:class:`gonio.demo.pipeline.TruthCheck`).

Writes benchmarks/results/demo_timings.csv and demo_timings.png.
Run: PYTHONPATH=src python benchmarks/bench_demo.py [--quick-only] [--replot]
"""

from __future__ import annotations

import argparse
import csv
import os
import tempfile
from pathlib import Path

from gonio.demo import DemoSettings, find_material, run_demo

RESULTS = Path(__file__).resolve().parent / "results"
STAGES = ("acquire", "fit", "render", "total")


def run(label: str, material_choice: str, settings: DemoSettings, tmp: Path) -> dict:
    material = find_material(material_choice)
    s = run_demo(tmp / label, material, settings, progress=False)
    truth = s.models[-1].truth_check
    row = {
        "run": label,
        "material": material.name,
        "plan": settings.plan,
        "configurations": s.acquisition["measured"],
        "render": f"{settings.resolution}px {settings.spp}spp",
        "truth_max_abs_z": "" if truth is None else round(truth.max_z, 2),
        "truth_consistent": "" if truth is None else truth.consistent,
        "cpus": os.cpu_count(),
    }
    row.update({f"{k}_s": round(s.timings_s[k], 1) for k in STAGES})
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick-only", action="store_true", help="skip the full demo")
    ap.add_argument(
        "--replot", action="store_true", help="only redraw the PNG from the existing CSV"
    )
    args = ap.parse_args()
    if args.replot:
        with open(RESULTS / "demo_timings.csv", newline="") as fh:
            plot(list(csv.DictReader(fh)), RESULTS / "demo_timings.png")
        return
    rows = []
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        rows.append(run("quick (builtin)", "builtin", DemoSettings.quick(), tmp))
        if not args.quick_only:
            rows.append(run("default (make demo)", "auto", DemoSettings(), tmp))
    RESULTS.mkdir(exist_ok=True)
    with open(RESULTS / "demo_timings.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    plot(rows, RESULTS / "demo_timings.png")
    print("| run | material | configurations | acquire | fit | render | total (s) |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for r in rows:
        print(
            f"| {r['run']} | {r['material']} | {r['configurations']} | {r['acquire_s']} |"
            f" {r['fit_s']} | {r['render_s']} | {r['total_s']} |"
        )


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colors = dict(zip(STAGES[:-1], ("tab:blue", "tab:orange", "tab:green"), strict=True))
    fig, ax = plt.subplots(figsize=(7, 1.2 + 0.6 * len(rows)))
    for i, r in enumerate(rows):
        left = 0.0
        for stage in STAGES[:-1]:
            v = float(r[f"{stage}_s"])
            ax.barh(i, v, left=left, color=colors[stage], label=stage if i == 0 else None)
            left += v
    ax.set_yticks(range(len(rows)), [r["run"] for r in rows])
    ax.axvline(600, color="k", ls="--", lw=1, label="10 min")
    ax.set_xlabel("wall time (s)")
    ax.legend(ncol=5, fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def write_tables() -> None:
    """Rewrite this benchmark's table in benchmarks/README.md from its CSV."""
    import _tables

    columns = [
        ("run", "run"),
        ("material", "material"),
        ("plan", "plan"),
        ("configurations", "configurations"),
        ("render", "render"),
        ("max \\|fit - truth\\|/std", "truth_max_abs_z"),
        ("acquire (s)", "acquire_s"),
        ("fit (s)", "fit_s"),
        ("render (s)", "render_s"),
        ("total (s)", "total_s"),
    ]
    _tables.write("demo", _tables.markdown(_tables.read("demo_timings.csv"), columns))


if __name__ == "__main__":
    main()
    write_tables()
