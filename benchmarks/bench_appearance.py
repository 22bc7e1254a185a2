"""Appearance of gonio's default fit against every published fit (issue #40).

For each of the 88 complete materials of ``../shared/data/nbrdf/merl_nbrdf.zip`` (MERL-grid
tables evaluated from the neural fits), this benchmark

1. runs ``gonio fit T.binary`` with no model options (what the command does by default on the
   branch it runs on, through the CLI entry point itself, in this process, ``--no-plots``) and
   takes the model the command recommends;
2. converts every published fit of that material in ``../shared/data/fits/`` (Ngan et al.'s
   files but He, Löw et al.'s six, Bagher et al.'s: :mod:`gonio.brdf.published`);
3. scores all of them with the appearance score (:mod:`gonio.appearance`: 96 px spheres under a
   light at 0, 30 and 60 degrees from the view and under the studio; HDR-FLIP and relative L1
   per image and their means) against the table's own images.

The 88 materials are split once into a *tuning* half and a *held-out* half, the one split of
``benchmarks/_nbrdf_split.py`` (sorted names, a seeded permutation, first 44 tuning) that the
default fit was tuned on. Choices of the default fit
(families, loss, thresholds) may look at the tuning half only; the table reports both halves and
all. Materials are run in an order that alternates the halves, so that ``--materials N`` covers
both.

Also measured:

* the studio image's noise: for the first ``--noise N`` materials run, every model is scored a
  second time against images estimated with another seed; the change of each score is compared
  with the differences between the models' scores that the benchmark ranks (``noise / spread``);
* the default ``gonio fit T.binary`` (no options at all, plots included) of one MERL-grid table
  in a fresh process with an empty compilation cache, wall time per phase
  (``--timing``; with ``--no-timing`` skipped).

Writes ``results/appearance.csv`` (one row per material and model), ``appearance_noise.csv``,
``appearance_timing.csv``, ``appearance_summary.csv``, ``appearance.png`` and the
``appearance`` tables of ``benchmarks/README.md``.

Usage: ``python benchmarks/bench_appearance.py [--materials N] [--only NAME] [--noise N]
[--no-timing] [--timing-only] [--resume] [--rescore-skipped]`` (``--resume`` keeps the
materials already in ``results/appearance.csv``, so a long run can be done in pieces;
``--rescore-skipped`` scores the published fits a run skipped that convert now).
"""

from __future__ import annotations

import argparse
import contextlib
import io as _io
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
SHARED = ROOT.parent / "shared" / "data"
ARCHIVE = SHARED / "nbrdf" / "merl_nbrdf.zip"
FITS = SHARED / "fits"
RESULTS = HERE / "results"


def run_order(tuning: list[str], held: list[str]) -> list[str]:
    """The materials alternating tuning and held-out (each half in its permuted order)."""
    out: list[str] = []
    for a, b in zip(tuning, held, strict=False):
        out += [a, b]
    return out + tuning[len(held) :] + held[len(tuning) :]


def published_fits(material: str) -> tuple[dict[str, Any], dict[str, str]]:
    """``({family: model}, {family: why not})`` of every published fit of ``material``."""
    from gonio.brdf import ngan, published
    from gonio.errors import GonioError

    models, skipped = {}, {}
    for path in sorted(FITS.glob("*.fit")):
        fits = ngan.parse_ngan_fits(path.read_text())
        if material not in fits:
            continue
        try:
            models[path.stem] = published.to_model(fits[material])
        except GonioError as exc:
            skipped[path.stem] = str(exc)
    return models, skipped


def default_fit(table_path: Path, out: Path) -> tuple[str, Any, float]:
    """``(name, model, wall s)`` of what ``gonio fit T --no-plots`` recommends."""
    from gonio.cli import main
    from gonio.io.fit_result import load_model, read_result

    t0 = time.perf_counter()
    buf = _io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = main(["fit", str(table_path), "--no-plots", "-o", str(out), "--json"])
    wall = time.perf_counter() - t0
    if rc != 0:
        raise RuntimeError(f"gonio fit exited {rc}")
    summary = json.loads((out / "summary.json").read_text())
    chosen = summary["recommended"]
    for f in summary["files"]:
        p = out / Path(f).name
        if p.suffix == ".json" and read_result(p)["model"] == chosen:
            return chosen, load_model(p), wall
    raise RuntimeError(f"no result file for the recommended model {chosen!r}")


def rescore_skipped(rows: list[dict]) -> list[dict]:
    """``rows`` with every published fit that was skipped (a ``note``) but converts now scored
    against its material's images (the default fit's rows are kept as they are)."""
    from gonio import appearance, io

    out, tables = [], {}
    for r in rows:
        if r["kind"] != "published" or not r.get("note"):
            out.append(r)
            continue
        name, fam = r["material"], r["model"].split(" ", 1)[1]
        models, skipped = published_fits(name)
        if fam not in models:
            out.append({**r, "note": skipped.get(fam, r["note"])})
            continue
        if name not in tables:
            tables[name] = appearance.Reference.of(io.load(f"{ARCHIVE}::{name}"))
        s = appearance.score(tables[name], models[fam])
        out.append({**{k: v for k, v in r.items() if k != "note"}, "fit_s": "", **s, "note": ""})
        print(f"{name}: {r['model']} scored (skipped before: {r['note']})", flush=True)
    return out


def run_material(name: str, where: str, noise: bool) -> tuple[list[dict], list[dict]]:
    """Rows of ``appearance.csv`` (and of ``appearance_noise.csv`` when ``noise``)."""
    from gonio import appearance, io

    table = io.load(f"{ARCHIVE}::{name}")
    with tempfile.TemporaryDirectory(prefix="bench-appearance-") as tmp:
        path = Path(tmp) / f"{name}.binary"
        io.save(table, path)
        chosen, model, wall = default_fit(path, Path(tmp) / "fit")
    models = {f"default {chosen}": model}
    pub, skipped = published_fits(name)
    models.update({f"published {k}": v for k, v in pub.items()})
    ref = appearance.Reference.of(table)
    rows = []
    for label, m in models.items():
        s = appearance.score(ref, m)
        rows.append(
            {
                "material": name,
                "split": where,
                "model": label,
                "kind": label.split()[0],
                "fit_s": wall if label.startswith("default") else "",
                **s,
                "note": "",
            }
        )
    for fam, why in skipped.items():
        rows.append(
            {
                "material": name,
                "split": where,
                "model": f"published {fam}",
                "kind": "published",
                "note": why,
            }
        )
    noise_rows = []
    if noise:
        ref1 = appearance.Reference.of(table, seed=1)
        for r in rows:
            if r["note"]:
                continue
            s1 = appearance.score(ref1, models[r["model"]])
            noise_rows.append(
                {
                    "material": name,
                    "model": r["model"],
                    **{f"{k}_seed0": r[k] for k in ("hdr_flip_env", "rel_l1_env")},
                    **{f"{k}_seed1": s1[k] for k in ("hdr_flip_env", "rel_l1_env")},
                }
            )
    return rows, noise_rows


def timing(name: str) -> list[dict]:
    """The default ``gonio fit T.binary`` in a fresh process, empty compilation cache, then
    again on the cache it filled: wall seconds per phase (the command's own stage times from
    ``summary.json``, each family's fit from its JSON, start-up = the rest), and the process's
    CPU seconds (user + system, its threads included) with the load average at the end: on a
    shared machine the CPU time is the honest measure, the wall time depends on the load."""
    from gonio import io

    with tempfile.TemporaryDirectory(prefix="bench-appearance-t-") as tmp:
        path = Path(tmp) / f"{name}.binary"
        io.save(io.load(f"{ARCHIVE}::{name}"), path)
        env = dict(os.environ, XDG_CACHE_HOME=str(Path(tmp) / "cache"), JAX_PLATFORMS="cpu")
        env.pop("GONIO_COMPILE_CACHE", None)
        env["PYTHONPATH"] = str(ROOT / "src") + os.pathsep + env.get("PYTHONPATH", "")
        gonio = Path(sys.executable).parent / "gonio"
        rows = []
        for what in ("cold (empty cache)", "warm (same cache)"):
            out = Path(tmp) / what.split()[0]
            t0, c0 = time.perf_counter(), os.times()
            proc = subprocess.run(
                [str(gonio), "fit", str(path), "-o", str(out)],
                env=env,
                capture_output=True,
                text=True,
            )
            wall = time.perf_counter() - t0
            c1 = os.times()
            cpu = (c1.children_user - c0.children_user) + (c1.children_system - c0.children_system)
            if proc.returncode != 0:
                raise RuntimeError(proc.stderr[-2000:])
            summary = json.loads((out / "summary.json").read_text())
            stages = summary["timings_s"]

            def row(phase: str, seconds: float, run: str = what, **extra: Any) -> None:
                rows.append({"run": run, "phase": phase, "seconds": seconds, **extra})

            row("start-up (imports, arguments)", wall - sum(stages.values()))
            row("read the table", stages["read"])
            for f in summary["files"]:
                p = out / Path(f).name
                if p.suffix == ".json":
                    rec = json.loads(p.read_text())
                    row(f"fit {rec['model']} (compile + optimize + held-out loss)", rec["wall_s"])
            row("fit, all families", stages["fit"])
            row(f"plots ({summary['recommended']})", stages["plots"])
            row("write results, print tables", stages["write"])
            row("total", wall, cpu_s=cpu, load1=os.getloadavg()[0], material=name)
    return rows


def _median(xs: list[float]) -> float:
    return float(np.median(xs)) if xs else math.nan


def summarize(rows: list[dict]) -> tuple[list[dict], list[dict]]:
    """The summary per split (``tuning``, ``held-out``, ``all``) and the worst materials."""
    by_mat: dict[str, list[dict]] = {}
    for r in rows:
        if not r.get("note"):
            by_mat.setdefault(r["material"], []).append(r)
    per = []
    for mat, rs in by_mat.items():
        d = [r for r in rs if r["kind"] == "default"]
        p = [r for r in rs if r["kind"] == "published"]
        if not d or not p:
            continue
        d = d[0]
        best_flip = min(float(r["hdr_flip"]) for r in p)
        best_l1 = min(float(r["rel_l1"]) for r in p)
        per.append(
            {
                "material": mat,
                "split": d["split"],
                "default": d["model"],
                "flip": float(d["hdr_flip"]),
                "l1": float(d["rel_l1"]),
                "best_flip": best_flip,
                "best_l1": best_l1,
                "wins": float(d["hdr_flip"]) <= best_flip and float(d["rel_l1"]) <= best_l1,
                "published": p,
            }
        )
    out = []
    for where in ("tuning", "held-out", "all"):
        sel = [m for m in per if where == "all" or m["split"] == where]
        fams: dict[str, list[float]] = {}
        for m in sel:
            for r in m["published"]:
                fams.setdefault(r["model"], []).append(float(r["hdr_flip"]))
        fam_med = {f: _median(v) for f, v in fams.items() if len(v) == len(sel)}
        best_fam = min(fam_med, key=fam_med.get) if fam_med else ""
        worst = sorted(sel, key=lambda m: m["flip"] - m["best_flip"], reverse=True)[:3]
        out.append(
            {
                "split": where,
                "materials": len(sel),
                "default_wins_both": sum(m["wins"] for m in sel),
                "default_wins_flip": sum(m["flip"] <= m["best_flip"] for m in sel),
                "default_wins_l1": sum(m["l1"] <= m["best_l1"] for m in sel),
                "median_flip_default": _median([m["flip"] for m in sel]),
                "best_family": best_fam.removeprefix("published "),
                "median_flip_best_family": fam_med.get(best_fam, math.nan),
                "median_l1_default": _median([m["l1"] for m in sel]),
                "median_best_l1_published": _median([m["best_l1"] for m in sel]),
                "worst": "; ".join(
                    f"{m['material']} ({m['flip']:.3f} vs {m['best_flip']:.3f})" for m in worst
                ),
            }
        )
    return out, per


def _write_csv(rows: list[dict], name: str, comment: str = "") -> None:
    import _tables

    _tables.write_csv(rows, name, comment)


def _plot(per: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 4.2))
    for ax, key, best, title in (
        (axes[0], "flip", "best_flip", "HDR-FLIP (mean of 4 images)"),
        (axes[1], "l1", "best_l1", "relative L1 (mean of 4 images)"),
    ):
        for where, colour in (("tuning", "tab:blue"), ("held-out", "tab:orange")):
            sel = [m for m in per if m["split"] == where]
            ax.scatter([m[best] for m in sel], [m[key] for m in sel], s=14, c=colour, label=where)
        hi = max([m[key] for m in per] + [m[best] for m in per] + [1e-3])
        ax.plot([0, hi], [0, hi], "k:", lw=0.8)
        ax.set_xlabel("best published fit of the material")
        ax.set_ylabel("gonio's default fit")
        ax.set_title(title, fontsize=9)
        ax.legend(fontsize=7)
    fig.suptitle("Below the diagonal: the default looks closer to the measurement", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write_tables() -> None:
    """Rewrite this benchmark's tables in benchmarks/README.md from its CSVs."""
    import _tables

    cols = [
        ("materials", "split"),
        ("run", "materials"),
        ("default >= best published, both", "default_wins_both"),
        ("… HDR-FLIP", "default_wins_flip"),
        ("… rel. L1", "default_wins_l1"),
        ("median HDR-FLIP default", "median_flip_default"),
        ("best family (median HDR-FLIP)*", "best_family"),
        ("its median", "median_flip_best_family"),
        ("median rel. L1 default", "median_l1_default"),
        ("median best published rel. L1", "median_best_l1_published"),
        ("worst (default vs best published HDR-FLIP)", "worst"),
    ]
    text = _tables.markdown(_tables.read("appearance_summary.csv"), cols)
    noise = _tables.read("appearance_noise_summary.csv")
    if noise and "measure" in noise[0]:
        text += "\n\n" + _tables.markdown(
            noise,
            [
                ("studio image, measure", "measure"),
                ("models", "models"),
                ("median change with a second seed", "median_noise"),
                ("median difference default vs each published fit", "median_spread"),
                ("noise / spread", "ratio"),
            ],
        )
    timing_rows = (
        _tables.read("appearance_timing.csv")
        if (RESULTS / "appearance_timing.csv").exists()
        else []
    )
    if timing_rows:
        text += "\n\n" + _tables.markdown(
            timing_rows,
            [
                ("run", "run"),
                ("phase", "phase"),
                ("seconds", "seconds"),
                ("CPU s", "cpu_s"),
                ("load", "load1"),
            ],
        )
    _tables.write("appearance", text)


def _noise_summary(noise: list[dict], per: list[dict]) -> list[dict]:
    out = []
    mats = {r["material"] for r in noise}
    for key in ("hdr_flip_env", "rel_l1_env"):
        changes = [abs(r[f"{key}_seed0"] - r[f"{key}_seed1"]) for r in noise]
        spreads = []
        for m in mats:
            rs = [r for r in noise if r["material"] == m]
            d = [r[f"{key}_seed0"] for r in rs if r["model"].startswith("default")]
            p = [r[f"{key}_seed0"] for r in rs if r["model"].startswith("published")]
            spreads += [abs(d[0] - x) for x in p] if d else []
        med_n, med_s = _median(changes), _median(spreads)
        out.append(
            {
                "measure": key,
                "models": len(changes),
                "median_noise": med_n,
                "median_spread": med_s,
                "ratio": med_n / med_s if med_s else math.nan,
            }
        )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--materials", type=int, default=0, help="run the first N (0: all 88)")
    ap.add_argument("--only", action="append", default=[], help="run this material (repeatable)")
    ap.add_argument("--noise", type=int, default=2, help="materials with the seed check")
    ap.add_argument("--no-timing", action="store_true", help="skip the cold-process timing")
    ap.add_argument(
        "--timing-only", action="store_true", help="only the cold-process timing (of --only)"
    )
    ap.add_argument(
        "--rescore-skipped",
        action="store_true",
        help="score the published fits of results/appearance.csv that were skipped and convert "
        "now (no fitting)",
    )
    ap.add_argument(
        "--resume",
        action="store_true",
        help="keep the materials already in results/appearance.csv and run the others",
    )
    args = ap.parse_args()
    sys.path.insert(0, str(HERE))
    sys.path.insert(0, str(ROOT / "src"))  # this checkout's gonio, not an installed one
    import _nbrdf_split

    tuning, held = _nbrdf_split.split(ARCHIVE)
    where = {**dict.fromkeys(tuning, "tuning"), **dict.fromkeys(held, "held-out")}
    order = args.only or run_order(tuning, held)
    if args.materials:
        order = order[: args.materials]
    if args.rescore_skipped:
        _write_outputs(
            rescore_skipped(_read_rows("appearance.csv")),
            _read_rows("appearance_noise.csv"),
            f"gonio fit default vs published fits; split seed {_nbrdf_split.SEED}",
        )
        return
    if args.timing_only:
        _write_csv(timing(order[0]), "appearance_timing.csv", "gonio fit T.binary, no options")
        write_tables()
        return
    rows: list[dict] = []
    noise: list[dict] = []
    if args.resume and (RESULTS / "appearance.csv").exists():
        rows = _read_rows("appearance.csv")
        if (RESULTS / "appearance_noise.csv").exists():
            noise = _read_rows("appearance_noise.csv")
    done = {r["material"] for r in rows}
    comment = f"gonio fit default vs published fits; split seed {_nbrdf_split.SEED}"
    for k, name in enumerate(order):
        if name in done:
            continue
        t0 = time.perf_counter()
        r, n = run_material(name, where[name], k < args.noise)
        rows += r
        noise += n
        d = next(x for x in r if x["kind"] == "default")
        print(
            f"[{k + 1}/{len(order)}] {name} ({where[name]}): {d['model']} "
            f"flip {d['hdr_flip']:.3f} L1 {d['rel_l1']:.3f}; "
            f"{time.perf_counter() - t0:.0f} s",
            flush=True,
        )
        # every output after every material: an interrupted run still leaves its tables
        _write_outputs(rows, noise, comment)
    if not args.no_timing:
        _write_csv(timing(order[0]), "appearance_timing.csv", "gonio fit T.binary, no options")
        write_tables()


def _read_rows(name: str) -> list[dict]:
    """A results CSV written by this benchmark, numbers as floats (for ``--resume``)."""
    import _tables

    def value(text: str) -> Any:
        try:
            return float(text)
        except ValueError:
            return text

    return [{k: value(v) for k, v in r.items()} for r in _tables.read(name)]


def _write_outputs(rows: list[dict], noise: list[dict], comment: str) -> None:
    summary, per = summarize(rows)
    _write_csv(rows, "appearance.csv", comment)
    _write_csv(summary, "appearance_summary.csv", comment)
    _write_csv(noise, "appearance_noise.csv", comment)
    _write_csv(_noise_summary(noise, per) if noise else [], "appearance_noise_summary.csv")
    if per:
        _plot(per, RESULTS / "appearance.png")
    write_tables()


if __name__ == "__main__":
    main()
