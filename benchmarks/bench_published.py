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
    PYTHONPATH=src python benchmarks/bench_published.py --speed gold-paint,pvc,white-fabric

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
    try:
        data = prepare(io.load(f"{ARCHIVE}::{name}"))
    except GonioError as exc:  # a network the reader refuses (non-finite or nowhere positive)
        print(f"{name}: not scored: {exc}", flush=True)
        return [{"material": name, "error": str(exc)}]
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
            ratios = np.array([float(r["ratio"]) for r in sel])  # NaN: the fit failed
            ratios = np.where(np.isfinite(ratios), ratios, np.inf)
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


def _cold_cli(
    name: str, preset: str, loss: str, cache: str, refine: int | None = None, src: str | None = None
) -> tuple[float, float]:
    """Wall and CPU seconds (user + system, every thread) of one fresh ``gonio fit`` process on
    ``ARCHIVE::name`` (JSON only, no plots); ``src``: another source tree on ``PYTHONPATH``
    (e.g. an earlier commit's ``src``, for a same-run baseline)."""
    import resource
    import subprocess
    import sys
    import tempfile

    with tempfile.TemporaryDirectory() as out:
        cmd = [sys.executable, "-m", "gonio", "fit", f"{ARCHIVE}::{name}", "-m", preset,
               "--loss", loss, "--no-plots", "-o", out]  # fmt: skip
        if refine is not None:
            cmd += ["--refine", str(refine)]
        env = {**os.environ, "GONIO_COMPILE_CACHE": cache}
        if src is not None:
            env["PYTHONPATH"] = src
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True, env=env)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        return wall, cpu


_WARM_CHILD = """
import json, os, sys, time
from gonio import fit as gf, io
from gonio.fit.data import prepare
data = prepare(io.load(sys.argv[1]))
gf.fit(data, sys.argv[2], loss=sys.argv[3])
out = []
for _ in range(int(sys.argv[4])):
    t0, c0 = time.perf_counter(), time.process_time()
    r = gf.fit(data, sys.argv[2], loss=sys.argv[3])
    out.append([time.perf_counter() - t0, time.process_time() - c0, r.loss])
print(json.dumps(out))
"""


def _warm_proc(name: str, preset: str, loss: str, src: str, n: int) -> list[list[float]]:
    """``[wall, CPU, loss]`` of ``n`` warm fits (after one that compiles) in one fresh process
    running the source tree ``src``."""
    import subprocess
    import sys

    cmd = [sys.executable, "-c", _WARM_CHILD, f"{ARCHIVE}::{name}", preset, loss, str(n)]
    env = {**os.environ, "PYTHONPATH": src}
    done = subprocess.run(cmd, check=True, capture_output=True, text=True, env=env)
    return json.loads(done.stdout.strip().splitlines()[-1])


def batch(names: list[str], jobs: int = 1) -> list[dict[str, Any]]:
    """Wall and CPU seconds of one ``gonio fit`` batch process over ``names`` (archive members)
    with the three families (default loss, no plots), per material, the materials fitted and
    failed (from the batch's ``batch.jsonl``) and the 1-minute load average at the start, the
    end and sampled every 10 s in between (mean, max)."""
    import resource
    import subprocess
    import sys
    import tempfile
    import threading

    loads: list[float] = []
    stop = threading.Event()

    def sample() -> None:
        while not stop.wait(10.0):
            loads.append(os.getloadavg()[0])

    with tempfile.TemporaryDirectory() as out:
        cmd = [sys.executable, "-m", "gonio", "fit", *[f"{ARCHIVE}::{n}" for n in names]]
        for preset in FAMILIES.values():
            cmd += ["-m", preset]
        cmd += ["--no-plots", "-j", str(jobs), "-o", out]
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        load0 = os.getloadavg()[0]
        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()
        t0 = time.perf_counter()
        done = subprocess.run(cmd, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        stop.set()
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        journal = Path(out) / "batch.jsonl"
        records = (
            [json.loads(x) for x in journal.read_text().splitlines()] if journal.exists() else []
        )
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    ok = [r["material"] for r in records if r.get("status") == "ok"]
    failed = [f"{r['material']}: {r.get('error', '?')}" for r in records if r.get("status") != "ok"]
    n = len(names)
    row = {"materials": n, "families": len(FAMILIES), "jobs": jobs, "wall_s": wall,
           "cpu_s": cpu, "wall_per_material_s": wall / n, "cpu_per_material_s": cpu / n,
           "fitted": len(ok), "failed": len(failed), "returncode": done.returncode,
           "load1_start": load0, "load1_end": os.getloadavg()[0],
           "load1_mean": float(np.mean(loads)) if loads else load0,
           "load1_max": float(np.max(loads)) if loads else load0,
           "failures": " | ".join(failed), "names": " ".join(names)}  # fmt: skip
    print(row, flush=True)
    return [row]


def speed(
    names: list[str], repeats: int = 3, baseline: str | None = None, every_cell: bool = False
) -> list[dict]:
    """Timings of single fits of MERL-resolution tables and the check that the staged fit keeps
    the optimum. Every timing row also has its CPU seconds (``cpu_s``: user + system of every
    thread), which a loaded machine inflates far less than the wall time.

    - cold: a fresh ``gonio fit`` process (imports, tabulating the network, fit, JSON), with an
      empty persistent compilation cache and again with the cache it filled; with ``baseline``
      (another source tree, e.g. the previous commit's ``src``), ``repeats`` cold processes of
      each, alternated, with an empty cache each and then with a filled one, and the ratio of
      the medians;
    - warm against ``baseline``: ``repeats`` alternated pairs of fresh processes, one per
      code, each timing 3 warm fits after one that compiles, and the ratio of the medians;
    - warm: in process, the default staged fit (multi-start on 2048 random cells, refinement on
      a stratified 65,536-cell subset, polish on every cell with the subset's curvature) against
      the earlier path (``refine=0``: every polish step on every cell), alternated ``repeats``
      times on the first material so that both see the same machine load; the ratio of the
      medians is the gain independent of the load;
    - optimum: per material and family (loss ``ngan``, same seed), the final loss of the default
      fit against the ``refine=0`` path and, with ``every_cell``, on the first material against
      a fit whose multi-start and polish both run on every cell (``subsample`` = all cells,
      ``refine=0``; minutes per fit).
    """
    import tempfile

    from gonio import fit as gf
    from gonio import io
    from gonio.fit.data import prepare

    preset, loss = "lambert+cook-torrance", "ngan"
    rows: list[dict[str, Any]] = []

    def row(what: str, seconds: float, **kw: Any) -> None:
        rows.append({"what": what, "seconds": seconds, "load1": os.getloadavg()[0], **kw})
        print(f"  {what}: {seconds:.4g} {kw if kw else ''}", flush=True)

    def cold(what: str, timing: tuple[float, float]) -> None:
        row(what, timing[0], cpu_s=round(timing[1], 3))

    if baseline is not None:
        # empty caches, the two codes alternated: the first fit a new user runs
        empty: dict[str, list[tuple[float, float]]] = {"current": [], "baseline": []}
        for _ in range(repeats):
            for k, src in (("current", None), ("baseline", baseline)):
                with tempfile.TemporaryDirectory() as fresh:
                    empty[k].append(_cold_cli(names[0], preset, loss, fresh, src=src))
                cold(f"cold gonio fit, empty compile cache, {k} code", empty[k][-1])
        for k, v in empty.items():
            cold(f"cold gonio fit median, empty compile cache, {k} code",
                 tuple(np.median(np.array(v), axis=0)))  # fmt: skip
    with tempfile.TemporaryDirectory() as cache:
        cold("cold gonio fit, empty compile cache", _cold_cli(names[0], preset, loss, cache))
        cold("cold gonio fit, compile cache filled", _cold_cli(names[0], preset, loss, cache))
        cold("cold gonio fit --refine 0, cache filled",
             _cold_cli(names[0], preset, loss, cache, refine=0))  # fmt: skip
        if baseline is not None:
            with tempfile.TemporaryDirectory() as base_cache:
                _cold_cli(names[0], preset, loss, base_cache, src=baseline)  # fills its cache
                runs: dict[str, list[tuple[float, float]]] = {"current": [], "baseline": []}
                for _ in range(repeats):
                    runs["current"].append(_cold_cli(names[0], preset, loss, cache))
                    runs["baseline"].append(
                        _cold_cli(names[0], preset, loss, base_cache, src=baseline)
                    )
                    for k in runs:
                        cold(f"cold gonio fit, cache filled, {k} code", runs[k][-1])
                med = {k: np.median(np.array(v), axis=0) for k, v in runs.items()}
                for k in runs:
                    cold(f"cold gonio fit median, {k} code", tuple(med[k]))
                row("cold speed-up, same run (baseline / current), wall",
                    med["baseline"][0] / med["current"][0])  # fmt: skip
                row("cold speed-up, same run (baseline / current), CPU",
                    med["baseline"][1] / med["current"][1])  # fmt: skip
    if baseline is not None:
        # warm fits, each code in its own process, alternated: the gain independent of the load
        warm: dict[str, list[list[float]]] = {"current": [], "baseline": []}
        for _ in range(repeats):
            for k, src in (("current", str(ROOT / "src")), ("baseline", baseline)):
                got = _warm_proc(names[0], preset, loss, src, 3)
                warm[k] += got
                for w, c, lo in got:
                    row(f"warm fit in a fresh process, {k} code", w, cpu_s=round(c, 3), loss=lo)
        for k in warm:
            med = np.median(np.array(warm[k]), axis=0)
            row(f"warm fit median, {k} code", med[0], cpu_s=round(med[1], 3), loss=med[2])
        wmed = {k: np.median(np.array(v)[:, :2], axis=0) for k, v in warm.items()}
        row("warm speed-up, same run (baseline / current), wall",
            wmed["baseline"][0] / wmed["current"][0])  # fmt: skip
        row("warm speed-up, same run (baseline / current), CPU",
            wmed["baseline"][1] / wmed["current"][1])  # fmt: skip
        lo_new, lo_old = warm["current"][0][2], warm["baseline"][0][2]
        row("warm optimum: (current - baseline) / baseline, final loss", (lo_new - lo_old) / lo_old)
    t0, c0 = time.perf_counter(), time.process_time()
    tables = {n: prepare(io.load(f"{ARCHIVE}::{n}")) for n in names}
    row("tabulate the networks + prepare cells", (time.perf_counter() - t0) / len(names),
        cpu_s=round((time.process_time() - c0) / len(names), 3))  # fmt: skip
    data = tables[names[0]]
    for label, refine in (("first fit, staged (compiles)", 65536),
                          ("first fit, refine=0 (compiles)", 0)):  # fmt: skip
        t0 = time.perf_counter()
        gf.fit(data, preset, loss=loss, refine=refine)
        row(label, time.perf_counter() - t0)
    times: dict[int, list[float]] = {65536: [], 0: []}
    for _ in range(repeats):
        for refine in times:
            t0, c0 = time.perf_counter(), time.process_time()
            r = gf.fit(data, preset, loss=loss, refine=refine)
            times[refine].append(time.perf_counter() - t0)
            row(f"warm fit, refine={refine}", times[refine][-1], loss=r.loss,
                cpu_s=round(time.process_time() - c0, 3),
                **{f"{k}_s": v for k, v in r.optimizer["timings"].items()})  # fmt: skip
    new, old = float(np.median(times[65536])), float(np.median(times[0]))
    row("warm fit median, staged (default)", new)
    row("warm fit median, refine=0", old)
    row("warm speed-up, same run (refine=0 / staged)", old / new)
    for name in names[1:2]:
        t0 = time.perf_counter()
        gf.fit(tables[name], preset, loss=loss)
        row(
            f"first fit of a second material ({name}): compiled code reused",
            time.perf_counter() - t0,
        )
    for name in names:
        for fam in FAMILIES.values():
            t0 = time.perf_counter()
            staged = gf.fit(tables[name], fam, loss=loss)
            t1 = time.perf_counter()
            plain = gf.fit(tables[name], fam, loss=loss, refine=0)
            t2 = time.perf_counter()
            row(f"optimum {name} {fam}: (staged - refine=0) / refine=0",
                (staged.loss - plain.loss) / plain.loss, staged_loss=staged.loss,
                ref_loss=plain.loss, staged_s=t1 - t0, ref_s=t2 - t1)  # fmt: skip
            if name != names[0] or not every_cell:
                continue
            full = gf.fit(tables[name], fam, loss=loss, subsample=tables[name].n, refine=0)
            row(f"optimum {name} {fam}: (staged - every cell) / every cell",
                (staged.loss - full.loss) / full.loss, staged_loss=staged.loss,
                ref_loss=full.loss, staged_s=t1 - t0, ref_s=time.perf_counter() - t2)  # fmt: skip
    return rows


def compare_runs(new: str, old: str) -> list[dict[str, Any]]:
    """Per shared (material, family, metric) row of two benchmark runs: gonio's score in each,
    ``(new - old) / old`` and both win flags; writes ``results/NEW_vs_OLD.csv`` and prints the
    largest increase and decrease and the number of wins lost."""

    def load(stem: str) -> dict[tuple[str, str, str], dict[str, str]]:
        with open(RESULTS / f"{stem}.csv", newline="") as fh:
            return {(r["material"], r["family"], r["metric"]): r for r in csv.DictReader(fh)}

    a, b = load(new), load(old)
    rows = []
    for key in sorted(set(a) & set(b)):
        g_new, g_old = float(a[key]["gonio"]), float(b[key]["gonio"])
        win_new, win_old = a[key]["win"] == "True", b[key]["win"] == "True"
        rows.append({"material": key[0], "family": key[1], "metric": key[2], "gonio_new": g_new,
                     "gonio_old": g_old, "rel_change": (g_new - g_old) / g_old,
                     "win_new": win_new, "win_old": win_old})  # fmt: skip
    _write_csv(rows, RESULTS / f"{new}_vs_{old}.csv")
    rel = np.array([r["rel_change"] for r in rows])
    lost = sum(r["win_old"] and not r["win_new"] for r in rows)
    print(f"{len(rows)} shared rows ({len({r['material'] for r in rows})} materials): wins "
          f"{sum(r['win_new'] for r in rows)} (new) / {sum(r['win_old'] for r in rows)} (old), "
          f"{lost} lost; largest increase {rel.max():+.2e}, largest decrease {rel.min():+.2e}, "
          f"median |change| {np.median(np.abs(rel)):.1e}; "
          f"{int(np.sum(np.abs(rel) > 1e-6))} rows changed by more than 1e-6")  # fmt: skip
    for r in sorted(rows, key=lambda r: -abs(r["rel_change"]))[:6]:
        print(f"  {r['rel_change']:+.3e} {r['material']} {r['family']} {r['metric']}")
    return rows


def _plot_speed(rows: list[dict[str, Any]], path: Path) -> None:
    """Bar chart of the speed section's timings (seconds) and the optimum check."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    skip = ("optimum", "warm speed-up", "warm optimum", "warm fit, refine", "warm fit in a",
            "cold speed-up")  # fmt: skip
    timed = [r for r in rows if not str(r["what"]).startswith(skip)]
    opt = [r for r in rows if str(r["what"]).startswith("optimum")]
    fig, axes = plt.subplots(1, 2, figsize=(14, 5), gridspec_kw={"width_ratios": [3, 2]})
    ax = axes[0]
    y = np.arange(len(timed))
    ax.barh(y, [float(r["seconds"]) for r in timed], color="tab:blue")
    ax.set_yticks(y, [f"{r['what']} (load {float(r['load1']):.0f})" for r in timed], fontsize=7)
    ax.invert_yaxis()
    ax.set_xlabel("seconds (2-core machine, shared; 1-min load average in brackets)")
    ax.set_title("single fit of a MERL-resolution table, lambert+cook-torrance, loss ngan",
                 fontsize=9)  # fmt: skip
    ax = axes[1]
    if opt:
        rel = [abs(float(r["seconds"])) for r in opt]
        y = np.arange(len(opt))
        ax.barh(y, np.maximum(rel, 1e-16), color="tab:green")
        ax.set_xscale("log")
        labels = [str(r["what"]).split(":")[0].removeprefix("optimum ")
                  + (" vs every-cell starts" if "every cell" in str(r["what"]) else " vs refine=0")
                  for r in opt]  # fmt: skip
        ax.set_yticks(y, labels, fontsize=7)
        ax.invert_yaxis()
        ax.set_xlabel("|staged - reference| / reference, final loss")
        ax.set_title("the staged fit keeps the optimum (loss ngan)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help=f"only {len(QUICK)} materials")
    ap.add_argument("--materials", help="comma-separated material names")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    ap.add_argument("--out", default="published", help="result file stem (default published)")
    ap.add_argument("--speed", metavar="MATERIAL,...",
                    help="only the timing and optimum checks, on these materials (the first "
                    "one timed)")  # fmt: skip
    ap.add_argument("--batch", metavar="MATERIAL,...",
                    help="only time one `gonio fit` batch process over these materials ('all': "
                    "every network of the archive), three families "
                    "(results/OUT_batch.csv)")  # fmt: skip
    ap.add_argument("--baseline", metavar="SRC",
                    help="with --speed: also time cold processes of this source tree (e.g. an "
                    "earlier commit's src), alternated with the current code")  # fmt: skip
    ap.add_argument(
        "--rounds",
        type=int,
        default=3,
        help="with --speed: alternated rounds per timing (default 3)",
    )
    ap.add_argument("--every-cell", action="store_true",
                    help="with --speed: also fit every family with starts and polish on every "
                    "cell (minutes per fit) for the optimum check")  # fmt: skip
    ap.add_argument(
        "--resume",
        action="store_true",
        help="keep the materials of results/OUT_partial.jsonl (an interrupted run)",
    )
    ap.add_argument("--plot-speed", action="store_true",
                    help="fit nothing: plot results/OUT_speed.csv into OUT_speed.png")  # fmt: skip
    ap.add_argument("--combine", metavar="STEM,STEM",
                    help="fit nothing: merge results/STEM.csv of earlier runs (STEM_partial: the "
                    "streamed rows of a stopped run; a material in several takes the rows of "
                    "the first stem listed) into results/OUT.csv, .png, _summary.csv")  # fmt: skip
    ap.add_argument("--compare-runs", metavar="NEW,OLD",
                    help="fit nothing: gonio's scores of results/NEW.csv against OLD.csv on their "
                    "shared (material, family, metric) rows: relative change, wins kept "
                    "(results/NEW_vs_OLD.csv)")  # fmt: skip
    args = ap.parse_args()
    if args.compare_runs:
        compare_runs(*args.compare_runs.split(","))
        return
    if args.combine:
        rows = []
        for stem in args.combine.split(","):
            if not (RESULTS / f"{stem}.csv").exists() and stem.endswith("_partial"):
                # the rows streamed by a run that was stopped before its report
                lines = (RESULTS / f"{stem}.jsonl").read_text().splitlines()
                got = [r for r in map(json.loads, lines) if "family" in r]
            else:
                with open(RESULTS / f"{stem}.csv", newline="") as fh:
                    got = list(csv.DictReader(fh))
                for r in got:
                    for k in ("published", "gonio", "ratio", "fit_s"):
                        r[k] = float(r[k])
                    r["win"] = r["win"] == "True"
            # a material already taken from an earlier-listed stem keeps those rows
            seen = {r["material"] for r in rows}
            rows += [dict(r, run=stem) for r in got if r["material"] not in seen]
        _report(rows, args.out, f"combined from {args.combine}")
        return
    if not ARCHIVE.exists():
        print(f"no {ARCHIVE}: skipped")
        return
    if args.speed:
        load = os.getloadavg()
        print(f"{args.speed}: {os.cpu_count()} CPUs, load average {load[0]:.1f} {load[1]:.1f} "
              f"{load[2]:.1f} at start", flush=True)  # fmt: skip
        rows = speed(args.speed.split(","), args.rounds, args.baseline, args.every_cell)
        RESULTS.mkdir(parents=True, exist_ok=True)
        _write_csv(rows, RESULTS / f"{args.out}_speed.csv")
        _plot_speed(rows, RESULTS / f"{args.out}_speed.png")
        return
    if args.batch:
        RESULTS.mkdir(parents=True, exist_ok=True)
        if args.batch == "all":
            from gonio.io.nbrdf import list_materials

            names = list_materials(ARCHIVE)
        else:
            names = args.batch.split(",")
        _write_csv(batch(names, args.jobs), RESULTS / f"{args.out}_batch.csv")
        return
    if args.plot_speed:
        with open(RESULTS / f"{args.out}_speed.csv", newline="") as fh:
            _plot_speed(list(csv.DictReader(fh)), RESULTS / f"{args.out}_speed.png")
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
    rows = []
    if args.resume and partial.exists():
        rows = [json.loads(line) for line in partial.read_text().splitlines() if line]
        done = {r["material"] for r in rows}
        names = [n for n in names if n not in done]
    else:
        partial.unlink(missing_ok=True)
    with ProcessPoolExecutor(max(args.jobs, 1)) as pool:
        for rs in pool.map(run_material, names):
            rows += rs
            with open(partial, "a") as fh:
                fh.writelines(json.dumps(r) + "\n" for r in rs)
    skipped = sorted({r["material"] for r in rows if "family" not in r})
    if skipped:
        print(f"not scored (table refused by the reader): {', '.join(skipped)}")
    rows = [r for r in rows if "family" in r]
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


def write_tables() -> None:
    """Rewrite this benchmark's tables in benchmarks/README.md from its CSVs."""
    import _tables

    summary = [
        ("family", "family"),
        ("metric (= gonio's loss)", "metric"),
        ("gonio at least as good", lambda r: f"{r['wins']}/{r['materials']}"),
        ("median gonio / published", "median_ratio"),
        ("worst ratio", "worst_ratio"),
        ("worst material", "worst_material"),
        ("median fit (s)", "median_fit_s"),
    ]
    rows = _tables.read("published_summary.csv")
    _tables.write("published", _tables.markdown(rows, summary))
    keep = ("median", "speed-up", "optimum", "first fit", "tabulate")
    speed = [
        r
        for r in _tables.read("published_speed.csv")
        if any(k in r["what"] for k in keep) and "baseline" not in r["what"]
    ]
    columns = [
        ("what", "what"),
        ("wall (s) or ratio", "seconds"),
        ("CPU (s)", "cpu_s"),
        ("load", "load1"),
    ]
    _tables.write("published_speed", _tables.markdown(speed, columns))
    batch = [
        ("materials", "materials"),
        ("families", "families"),
        ("jobs", "jobs"),
        ("wall (s)", "wall_s"),
        ("CPU (s)", "cpu_s"),
        ("CPU per material (s)", "cpu_per_material_s"),
        ("fitted", "fitted"),
        ("failed", "failed"),
        ("load at start", "load1_start"),
        ("load, mean", "load1_mean"),
    ]
    _tables.write("published_batch", _tables.markdown(_tables.read("published_batch.csv"), batch))


if __name__ == "__main__":
    main()
    write_tables()
