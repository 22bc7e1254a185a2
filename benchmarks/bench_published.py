"""gonio's fits against the published fits (Ngan et al. 2005) on MERL-resolution neural tables.

For every material of ``../shared/data/nbrdf/merl_nbrdf.zip`` that has a published fit in
``../shared/data/fits/ngan_*.fit``, the network is tabulated on MERL's 90 x 90 x 180 grid
(``gonio.io.load("merl_nbrdf.zip::NAME")``) and, per family (Cook-Torrance, Ward, Blinn-Phong
with the half vector), both the published fit (``gonio.brdf.ngan.to_family``) and gonio's fit of
the same preset are scored by the same code (``gonio.fit.score``) on the same cells: theta_i,
theta_o <= 80 deg, each cell weighted by its exact solid-angle measure, in two metrics:

``ngan``    Ngan's cosine-weighted L2; gonio's fit for this column minimizes ``--loss ngan``.
``low-e2``  Löw et al.'s log metric E2; gonio's fit for this column minimizes ``--loss low-e2``.

gonio's fits use the default settings of ``gonio.fit.fit`` (8 starts, LM) from the preset's
default start: the published parameters are not used as a start. For Blinn-Phong the CSV also
scores bbm's mirror-direction reading of the published numbers (``published_bbm``).

Run from the repository root::

    PYTHONPATH=src python benchmarks/bench_published.py            # every material
    PYTHONPATH=src python benchmarks/bench_published.py --quick    # 8 materials
    PYTHONPATH=src python benchmarks/bench_published.py --materials gold-paint,pvc
    PYTHONPATH=src python benchmarks/bench_published.py --speed gold-paint   # timings only

Writes ``results/published.csv`` (one row per material, family and metric), ``published.png``
(gonio against published, per family and metric) and prints the summary table (wins, median
ratio gonio / published) that benchmarks/README.md shows.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
SHARED = next(
    (p / "shared" / "data" for p in ROOT.parents if (p / "shared" / "data").is_dir()),
    ROOT.parent / "shared" / "data",
)
ARCHIVE = SHARED / "nbrdf" / "merl_nbrdf.zip"
FAMILIES = {  # published file -> gonio preset
    "cooktorrance": "lambert+cook-torrance",
    "ward": "lambert+ward",
    "blinnphong": "lambert+ngan-blinn-phong",
}
METRICS = ("ngan", "low-e2")
QUICK = ("gold-paint", "blue-acrylic", "chrome-steel", "white-fabric", "pvc", "nylon",
         "black-oxidized-steel", "yellow-paint")  # fmt: skip


def _published() -> dict[str, dict[str, Any]]:
    from gonio.brdf import ngan

    return {
        fam: ngan.parse_ngan_fits((SHARED / "fits" / f"ngan_{fam}.fit").read_text())
        for fam in FAMILIES
    }


def run_material(name: str) -> list[dict[str, Any]]:
    """Every row of one material (runs in a worker process)."""
    from gonio import fit as gf
    from gonio import io
    from gonio.brdf import ngan
    from gonio.errors import GonioError, ParameterError
    from gonio.fit.data import prepare
    from gonio.fit.score import score

    t0 = time.perf_counter()
    data = prepare(io.load(f"{ARCHIVE}::{name}"))
    t_table = time.perf_counter() - t0
    rows = []
    published = _published()
    for fam, preset in FAMILIES.items():
        entry = published[fam].get(name)
        if entry is None:
            continue
        _, pub_model = ngan.to_family(entry)
        pub = score(pub_model, data)
        bbm = None
        if fam == "blinnphong":
            try:
                bbm = score(ngan.to_family(entry, "bbm")[1], data)
            except ParameterError:  # bbm's Phong exponent range ends at 1e5 (5 materials)
                bbm = None
        for metric in METRICS:
            t1 = time.perf_counter()
            try:
                res = gf.fit(data, model=preset, loss=metric)
            except GonioError as exc:  # recorded as a loss for gonio, the run goes on
                print(f"{name} {preset} {metric}: {exc}", flush=True)
                rows.append({"material": name, "family": preset, "metric": metric,
                             "loss": metric, "published": pub[metric], "gonio": float("nan"),
                             "ratio": float("nan"), "win": False, "error": str(exc)})  # fmt: skip
                continue
            wall = time.perf_counter() - t1
            ours = score(res.model, data)
            rows.append(
                {
                    "material": name,
                    "family": preset,
                    "metric": metric,
                    "loss": metric,
                    "published": pub[metric],
                    "gonio": ours[metric],
                    "ratio": ours[metric] / pub[metric],
                    "win": bool(ours[metric] <= pub[metric] * (1 + 1e-9)),
                    "published_bbm": None if bbm is None else bbm[metric],
                    "converged": bool(res.optimizer["converged"]),
                    "on_bounds": " ".join(res.optimizer["on_bounds"]),
                    "fit_s": round(wall, 3),
                    "table_s": round(t_table, 3),
                    "n_cells": data.n,
                }
            )
    print(f"{name}: {len(rows)} rows, {time.perf_counter() - t0:.1f} s", flush=True)
    return rows


def summary(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per family and metric: wins, count and the median ratio gonio / published."""
    out = []
    for preset in FAMILIES.values():
        for metric in METRICS:
            sel = [r for r in rows if r["family"] == preset and r["metric"] == metric]
            if not sel:
                continue
            ratios = np.array([r["ratio"] for r in sel])
            out.append(
                {
                    "family": preset,
                    "metric": metric,
                    "wins": sum(r["win"] for r in sel),
                    "materials": len(sel),
                    "median_ratio": float(np.median(ratios)),
                    "worst_ratio": float(ratios.max()),
                    "worst_material": sel[int(np.argmax(ratios))]["material"],
                    "median_fit_s": float(np.median([r["fit_s"] for r in sel])),
                }
            )
    return out


def _plot(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 3, figsize=(13, 8.5), squeeze=False)
    for j, preset in enumerate(FAMILIES.values()):
        for i, metric in enumerate(METRICS):
            ax = axes[i][j]
            sel = [r for r in rows if r["family"] == preset and r["metric"] == metric]
            if not sel:
                ax.set_visible(False)
                continue
            p = np.array([r["published"] for r in sel])
            g = np.array([r["gonio"] for r in sel])
            win = np.array([r["win"] for r in sel])
            ax.loglog(p[win], g[win], "o", ms=4, color="tab:blue", label="gonio better")
            ax.loglog(p[~win], g[~win], "o", ms=4, color="tab:red", label="published better")
            lim = [min(p.min(), g.min()) * 0.8, max(p.max(), g.max()) * 1.25]
            ax.plot(lim, lim, "k-", lw=0.8)
            ax.set_xlim(lim)
            ax.set_ylim(lim)
            ax.set_xlabel(f"published fit, {metric}" + (" (1/sr)" if metric == "ngan" else ""))
            ax.set_ylabel(f"gonio fit (loss {metric})")
            ax.set_title(f"{preset}: {int(win.sum())}/{len(sel)} won", fontsize=10)
            ax.legend(fontsize=8, loc="upper left")
    fig.suptitle("Scores on neural MERL tables (theta <= 80 deg, cell solid-angle weights)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _write_csv(rows: list[dict[str, Any]], path: Path) -> None:
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)


def speed(name: str, preset: str = "lambert+cook-torrance", loss: str = "ngan") -> list[dict]:
    """Wall times of one fit of a MERL-resolution table, cold (a fresh ``gonio fit`` process) and
    warm (in process, second call), and the check that the multi-start on a 4000-cell subsample
    keeps the optimum of a multi-start on every cell."""
    import subprocess
    import sys
    import tempfile

    from gonio import fit as gf
    from gonio import io
    from gonio.fit.data import prepare

    rows = []
    with tempfile.TemporaryDirectory() as out:
        cmd = [sys.executable, "-m", "gonio", "fit", f"{ARCHIVE}::{name}", "-m", preset,
               "--loss", loss, "--no-plots", "-o", out]  # fmt: skip
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True)
        rows.append({"what": "cold gonio fit process (import, table, fit, JSON)",
                     "seconds": time.perf_counter() - t0})  # fmt: skip
    t0 = time.perf_counter()
    data = prepare(io.load(f"{ARCHIVE}::{name}"))
    rows.append(
        {"what": "tabulate the network + prepare cells", "seconds": time.perf_counter() - t0}
    )
    costs = {}
    for label, sub in (("first fit (compiles)", 4000), ("warm fit", 4000),
                       ("warm fit, multi-start on every cell", data.n)):  # fmt: skip
        t0 = time.perf_counter()
        r = gf.fit(data, preset, loss=loss, subsample=sub)
        rows.append({"what": label, "seconds": time.perf_counter() - t0, "loss": r.loss,
                     "polish_s": r.optimizer["timings"]["polish"],
                     "starts_s": r.optimizer["timings"]["starts"], "n_cells": data.n})  # fmt: skip
        costs[label] = r.loss
    rel = abs(costs["warm fit"] - costs["warm fit, multi-start on every cell"]) / costs["warm fit"]
    rows.append({"what": "relative loss difference, subsample vs every cell", "seconds": rel})
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help=f"only {len(QUICK)} materials")
    ap.add_argument("--materials", help="comma-separated material names")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    ap.add_argument("--out", default="published", help="result file stem (default published)")
    ap.add_argument("--speed", metavar="MATERIAL", help="only the timing section on MATERIAL")
    ap.add_argument("--combine", metavar="STEM,STEM",
                    help="fit nothing: merge results/STEM.csv of earlier runs (on disjoint "
                    "materials) into results/OUT.csv, .png and _summary.csv")  # fmt: skip
    args = ap.parse_args()
    if args.combine:
        rows = []
        for stem in args.combine.split(","):
            with open(RESULTS / f"{stem}.csv", newline="") as fh:
                for r in csv.DictReader(fh):
                    for k in ("published", "gonio", "ratio", "fit_s"):
                        r[k] = float(r[k])
                    r["win"] = r["win"] == "True"
                    rows.append(r)
        _report(rows, args.out, f"combined from {args.combine}")
        return
    if not ARCHIVE.exists():
        print(f"no {ARCHIVE}: skipped")
        return
    if args.speed:
        load = os.getloadavg()[0]
        rows = speed(args.speed)
        RESULTS.mkdir(parents=True, exist_ok=True)
        _write_csv(rows, RESULTS / f"{args.out}_speed.csv")
        print(f"{args.speed}, {os.cpu_count()} CPUs, load {load:.1f} at start")
        for r in rows:
            print(f"  {r['what']}: {r['seconds']:.4g}")
        return
    from gonio.io.nbrdf import list_materials

    published = _published()
    names = [n for n in list_materials(ARCHIVE) if any(n in published[f] for f in FAMILIES)]
    if args.materials:
        names = [n for n in args.materials.split(",") if n in names]
    elif args.quick:
        names = [n for n in QUICK if n in names]
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    RESULTS.mkdir(parents=True, exist_ok=True)
    partial = RESULTS / f"{args.out}_partial.jsonl"  # rows so far, if the run is cut short
    partial.unlink(missing_ok=True)
    rows = []
    with ProcessPoolExecutor(max(args.jobs, 1)) as pool:
        for rs in pool.map(run_material, names):
            rows += rs
            with open(partial, "a") as fh:
                fh.writelines(json.dumps(r) + "\n" for r in rs)
    wall = time.perf_counter() - t0
    _report(rows, args.out, f"{len(names)} materials, {args.jobs} jobs, {wall:.0f} s wall "
            f"({os.cpu_count()} CPUs, load {load:.1f} at start)")  # fmt: skip


def _report(rows: list[dict[str, Any]], out: str, note: str) -> None:
    RESULTS.mkdir(parents=True, exist_ok=True)
    _write_csv(rows, RESULTS / f"{out}.csv")
    _plot(rows, RESULTS / f"{out}.png")
    summ = summary(rows)
    _write_csv(summ, RESULTS / f"{out}_summary.csv")
    n = len({r["material"] for r in rows})
    print(f"\n{n} materials; {note}\n")
    print("| family | metric (= loss) | gonio wins | median gonio/published | worst (material) |")
    print("|---|---|---|---|---|")
    for s in summ:
        worst = f"{s['worst_ratio']:.3f} ({s['worst_material']})"
        print(f"| {s['family']} | {s['metric']} | {s['wins']}/{s['materials']} | "
              f"{s['median_ratio']:.3f} | {worst} |")  # fmt: skip


if __name__ == "__main__":
    main()
