"""Prior-based reconstruction from a few optimal configurations (issue #42, items 1-3).

Cross-validation over the NBRDF materials of ``../shared/data/nbrdf/merl_nbrdf.zip`` (MERL-grid
tables evaluated from the neural fits), with the one split of ``benchmarks/_nbrdf_split.py`` as
two folds: a prior built from the tuning half scores held-out materials, a prior built from the
held-out half scores tuning materials. No material is ever scored with a prior that contains it.

For each fold the prior is built with ``gonio.prior.build_prior`` (rank by leave-one-out), the
configurations are chosen once by ``prior.choose`` among a subgrid of the prior's valid nodes
(every third θh node, every second θd and φd node: about 4° apart) with both polar angles at
most 80 degrees (the choice depends on the posterior covariance only, which for
noiseless samples does not depend on the material; the greedy order makes the first n of 40 the
choice of n). Each scored material is then

* sampled without noise (its own table's ``f``) at the first n = 5, 10, 20, 40 configurations
  and reconstructed (``prior.reconstruct``),
* projected onto the prior with every cell known (the reference: what the basis can do at best),
* and compared with every published fit of the material (``../shared/data/fits/``, loaded as
  ``bench_appearance.py`` does; their scores are taken from ``results/appearance.csv`` where it
  has the material: the same score against the same reference images),

all scored against the material's own table by the appearance score (``gonio.appearance``: exact
point-light sphere renders at 0, 30 and 60 degrees plus the studio, HDR-FLIP and relative L1),
and, for the reconstructions, by the mean absolute difference in the mapped space over the
prior's valid cells (with the prior's own predicted error beside it).

Writes ``results/prior.csv`` (one row per material and estimator), ``results/prior_summary.csv``,
``results/prior_build.csv``, ``results/prior.png`` and the ``prior`` table of
``benchmarks/README.md``.

Usage: ``python benchmarks/bench_prior.py [--materials N] [--folds held-out,tuning]``
(``--materials``: per fold, default 10).
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
SHARED = ROOT.parent / "shared" / "data"
ARCHIVE = SHARED / "nbrdf" / "merl_nbrdf.zip"
RESULTS = HERE / "results"
COUNTS = (5, 10, 20, 40)
#: Largest polar angle of a chosen configuration, degrees.
THETA_MAX_DEG = 80.0


def build(names: list[str], cache: Path) -> tuple[object, dict]:
    """The prior of ``names`` (read from ``cache`` when there), and its build figures (the
    build's wall time and peak memory as the prior's metadata recorded them)."""
    from gonio import io
    from gonio.prior import Prior, build_prior

    key = hashlib.sha256("\n".join(names).encode()).hexdigest()[:12]
    path = cache / f"prior-{key}.prior.h5"
    if path.exists():
        prior = Prior.read(path)
    else:
        tables = (io.load(f"{ARCHIVE}::{n}") for n in names)
        prior = build_prior(tables, names, progress=lambda s: print(f"  {s}", flush=True))
        prior.write(path)
    wall = prior.meta["build"]["seconds"]
    return prior, {
        "materials": len(names),
        "rank": prior.rank,
        "valid_cells": prior.n_valid,
        "file_mib": path.stat().st_size / 2**20,
        "build_s": wall,
        "peak_rss_mib": prior.meta["build"]["peak_rss_mib"],
        "loo_rms_at_rank": prior.meta["rank_selection"]["loo_rms_at_rank"],
    }


def candidates(prior) -> tuple[np.ndarray, np.ndarray]:
    """Every third θh node and every second θd and φd node of the prior's grid (4°: MERL's
    θh nodes 0, 3, 6, ...; θd and φd 0.5°, 4.5°, ...), valid, with both polar angles at most
    :data:`THETA_MAX_DEG`."""
    from gonio.prior import space

    wi, wo = space.grid_directions(prior.axes)
    sub = np.zeros(prior.mask.shape, bool)
    sub[::3, ::2, ::2] = True
    c = math.cos(math.radians(THETA_MAX_DEG))
    keep = (sub & prior.mask).reshape(-1) & (wi[:, 2] >= c) & (wo[:, 2] >= c)
    return wi[keep], wo[keep]


def published_scores(name: str, ref) -> list[dict]:
    """``{"estimator": "published FAMILY", **score}`` of every published fit of ``name``: from
    ``results/appearance.csv`` when it holds them (the same score of the same model against the
    same reference images: ``bench_appearance.py`` renders the same table with the same seed
    and resolution), else scored here (``bench_appearance.published_fits``)."""
    from gonio import appearance

    sys.path.insert(0, str(HERE))
    import bench_appearance

    path = RESULTS / "appearance.csv"
    if path.exists():
        with open(path, newline="") as fh:
            rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
        got = [
            r
            for r in rows
            if r["material"] == name and r["kind"] == "published" and not r.get("note")
        ]
        if got:
            keys = [k for k in appearance.KEYS if k in got[0]]
            return [
                {
                    "estimator": r["model"],
                    "published_from": "appearance.csv",
                    **{k: float(r[k]) for k in keys},
                }
                for r in got
            ]
    fits = bench_appearance.published_fits(name)[0]
    return [
        {"estimator": f"published {fam}", **appearance.score(ref, model)}
        for fam, model in fits.items()
    ]


def run_material(prior, name: str, split: str, wi: np.ndarray, wo: np.ndarray) -> list[dict]:
    """Rows of ``prior.csv`` for one held-out material."""
    from gonio import appearance, io
    from gonio.prior import space
    from gonio.prior.posterior import to_table

    truth = io.load(f"{ARCHIVE}::{name}")
    ref = appearance.Reference.of(truth)
    cwi, cwo = prior.cell_directions()
    m_true = space.to_mapped(
        np.asarray(truth.f(cwi, cwo), np.float64), space.cos_product(cwi, cwo), prior.epsilon
    )
    base = {"material": name, "split": split}
    rows = []
    for n in COUNTS:
        t0 = time.perf_counter()
        vals = np.asarray(truth.f(wi[:n], wo[:n]), np.float64)
        r = prior.reconstruct(wi[:n], wo[:n], vals)
        wall = time.perf_counter() - t0
        rows.append(
            {
                **base,
                "estimator": f"reconstruction n={n}",
                "n": n,
                "mapped_mae": float(np.abs(r.mapped - m_true).mean()),
                "predicted_mae": r.predicted_error,
                "reconstruct_s": wall,
                **appearance.score(ref, r.table),
            }
        )
    K = prior.rank
    B = prior.basis.reshape(-1, K).astype(np.float64)
    c = B.T @ (m_true - prior.mean).reshape(-1)
    proj = prior.mean + (B @ c).reshape(prior.mean.shape)
    rows.append(
        {
            **base,
            "estimator": "projection (all cells)",
            "n": prior.n_valid,
            "mapped_mae": float(np.abs(proj - m_true).mean()),
            **appearance.score(ref, to_table(prior, proj, None, {})),
        }
    )
    rows += [{**base, **r} for r in published_scores(name, ref)]
    return rows


def summarize(rows: list[dict]) -> list[dict]:
    """Per estimator: materials, medians, and how often it is at least as good as the best
    published fit of the material (HDR-FLIP; relative L1)."""
    mats = sorted({r["material"] for r in rows})
    best = {}
    for m in mats:
        p = [r for r in rows if r["material"] == m and r["estimator"].startswith("published")]
        if p:
            best[m] = (min(float(r["hdr_flip"]) for r in p), min(float(r["rel_l1"]) for r in p))
    out = []
    ests = [f"reconstruction n={n}" for n in COUNTS] + ["projection (all cells)"]
    for e in [*ests, "best published"]:
        if e == "best published":
            sel = [{"material": m, "hdr_flip": b[0], "rel_l1": b[1]} for m, b in best.items()]
        else:
            sel = [r for r in rows if r["estimator"] == e and r["material"] in best]
        if not sel:
            continue
        flip = [float(r["hdr_flip"]) for r in sel]
        l1 = [float(r["rel_l1"]) for r in sel]
        mae = [float(r["mapped_mae"]) for r in sel if r.get("mapped_mae") not in (None, "")]
        pred = [float(r["predicted_mae"]) for r in sel if r.get("predicted_mae") not in (None, "")]
        out.append(
            {
                "estimator": e,
                "materials": len(sel),
                "flip_at_least_as_good": ""
                if e == "best published"
                else sum(float(r["hdr_flip"]) <= best[r["material"]][0] for r in sel),
                "l1_at_least_as_good": ""
                if e == "best published"
                else sum(float(r["rel_l1"]) <= best[r["material"]][1] for r in sel),
                "median_hdr_flip": float(np.median(flip)),
                "median_rel_l1": float(np.median(l1)),
                "median_mapped_mae": float(np.median(mae)) if mae else "",
                "median_predicted_mae": float(np.median(pred)) if pred else "",
            }
        )
    return out


def _plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    mats = sorted({r["material"] for r in rows})
    fig, axes = plt.subplots(1, 2, figsize=(9.5, 4.2))
    for m in mats:
        rs = {r["estimator"]: r for r in rows if r["material"] == m}
        pub = [float(r["hdr_flip"]) for e, r in rs.items() if e.startswith("published")]
        rec = [rs.get(f"reconstruction n={n}") for n in COUNTS]
        axes[0].plot(COUNTS, [float(r["hdr_flip"]) for r in rec], "-o", ms=3, lw=0.8)
        if pub:
            axes[0].plot([COUNTS[-1] * 1.25], [min(pub)], "k_", ms=8)
        axes[1].plot(COUNTS, [float(r["mapped_mae"]) for r in rec], "-o", ms=3, lw=0.8)
        axes[1].plot(COUNTS, [float(r["predicted_mae"]) for r in rec], ":", lw=0.8, c="grey")
    axes[0].set_xscale("log")
    axes[0].set_xlabel("optimal configurations n")
    axes[0].set_ylabel("HDR-FLIP (mean of 4 images)")
    axes[0].set_title("reconstruction (lines); best published fit (black ticks)", fontsize=8)
    axes[1].set_xscale("log")
    axes[1].set_xlabel("optimal configurations n")
    axes[1].set_ylabel("mean |error|, mapped space")
    axes[1].set_title("measured (lines) and predicted (grey dotted)", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write_tables() -> None:
    """Rewrite this benchmark's table in benchmarks/README.md from its CSVs."""
    import _tables

    text = _tables.markdown(
        _tables.read("prior_summary.csv"),
        [
            ("estimator", "estimator"),
            ("materials", "materials"),
            ("HDR-FLIP <= best published", "flip_at_least_as_good"),
            ("rel. L1 <= best published", "l1_at_least_as_good"),
            ("median HDR-FLIP", "median_hdr_flip"),
            ("median rel. L1", "median_rel_l1"),
            ("median mapped |error|", "median_mapped_mae"),
            ("median predicted", "median_predicted_mae"),
        ],
    )
    build_rows = _tables.read("prior_build.csv") if (RESULTS / "prior_build.csv").exists() else []
    if build_rows:
        text += "\n\n" + _tables.markdown(
            build_rows,
            [
                ("prior of", "fold"),
                ("materials", "materials"),
                ("rank", "rank"),
                ("valid cells", "valid_cells"),
                ("file MiB", "file_mib"),
                ("build s", "build_s"),
                ("peak RSS MiB", "peak_rss_mib"),
                ("LOO RMS at rank", "loo_rms_at_rank"),
                ("choose 40 s", "choose_s"),
                ("load", "load1"),
            ],
        )
    _tables.write("prior", text)


def _merge(_tables, comment: str) -> None:
    """``prior.csv`` and ``prior_reverse.csv`` as one (a material scored by both: the first's
    rows), then the summary, plot and README table."""
    rows = _tables.read("prior.csv") if (RESULTS / "prior.csv").exists() else []
    done = {r["material"] for r in rows}
    if (RESULTS / "prior_reverse.csv").exists():
        rows += [r for r in _tables.read("prior_reverse.csv") if r["material"] not in done]
        (RESULTS / "prior_reverse.csv").unlink()
    _tables.write_csv(rows, "prior.csv", comment)
    _tables.write_csv(summarize(rows), "prior_summary.csv", comment)
    _plot(rows, RESULTS / "prior.png")
    write_tables()


def main() -> None:
    import os

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--materials", type=int, default=10, help="materials scored per fold")
    ap.add_argument(
        "--folds",
        default="held-out",
        help="which halves are scored: held-out "
        "(prior of the tuning half), tuning, or both comma-separated",
    )
    ap.add_argument("--cache", default=None, help="folder keeping the built priors")
    ap.add_argument(
        "--resume",
        action="store_true",
        help="keep the materials already in results/prior.csv and score only the others",
    )
    ap.add_argument(
        "--reverse",
        action="store_true",
        help="score the materials last first, "
        "into results/prior_reverse.csv (a second process beside a first one)",
    )
    ap.add_argument(
        "--merge",
        action="store_true",
        help="score nothing: merge "
        "results/prior_reverse.csv into results/prior.csv and write the outputs",
    )
    args = ap.parse_args()
    sys.path.insert(0, str(HERE))
    import _nbrdf_split
    import _tables

    tuning, held = _nbrdf_split.split(ARCHIVE)
    halves = {"held-out": (tuning, held), "tuning": (held, tuning)}
    folds = [f.strip() for f in args.folds.split(",") if f.strip()]
    tmp = tempfile.TemporaryDirectory(prefix="bench-prior-")
    cache = Path(args.cache) if args.cache else Path(tmp.name)
    cache.mkdir(parents=True, exist_ok=True)
    rows: list[dict] = []
    out_csv = "prior_reverse.csv" if args.reverse else "prior.csv"
    if args.merge:
        _merge(_tables, comment=f"gonio.prior reconstruction; split seed {_nbrdf_split.SEED}")
        return
    if args.resume and (RESULTS / out_csv).exists():
        rows = _tables.read(out_csv)  # materials already scored are not scored again
    builds: list[dict] = []
    comment = f"gonio.prior reconstruction; split seed {_nbrdf_split.SEED}, two folds"
    for fold in folds:
        train, scored = halves[fold]
        print(
            f"prior of the {'tuning' if fold == 'held-out' else 'held-out'} half "
            f"({len(train)} materials)",
            flush=True,
        )
        prior, figures = build(train, cache)
        t0 = time.perf_counter()
        wi, wo = candidates(prior)
        idx = prior.choose(wi, wo, max(COUNTS))
        figures.update(
            fold=f"{len(train)} materials, scores {fold}",
            choose_s=time.perf_counter() - t0,
            candidates=len(wi),
            load1=os.getloadavg()[0],
        )
        builds.append(figures)
        _tables.write_csv(builds, "prior_build.csv", comment)
        todo = scored[: args.materials]
        for k, name in enumerate(todo[::-1] if args.reverse else todo):
            if any(r["material"] == name and r["split"] == fold for r in rows):
                continue
            t0 = time.perf_counter()
            r = run_material(prior, name, fold, wi[idx], wo[idx])
            rows += r
            rec = next(x for x in r if x["estimator"] == "reconstruction n=20")
            pub = [x["hdr_flip"] for x in r if x["estimator"].startswith("published")]
            print(
                f"[{k + 1}/{args.materials}] {name}: n=20 flip {rec['hdr_flip']:.3f} "
                f"(best published {min(pub) if pub else math.nan:.3f}), mapped MAE "
                f"{rec['mapped_mae']:.3f}; {time.perf_counter() - t0:.0f} s",
                flush=True,
            )
            _tables.write_csv(rows, out_csv, comment)
            if not args.reverse:
                _tables.write_csv(summarize(rows), "prior_summary.csv", comment)
                _plot(rows, RESULTS / "prior.png")
                write_tables()
    tmp.cleanup()


if __name__ == "__main__":
    main()
