"""Does the MCMC posterior agree with the optimizer? Every RGL, Cornell and ALTA file of the
shared data and six NBRDF materials, fitted with ``--uncertainty mcmc``.

For each file the default loss is fitted (``low-e1`` without sigma) with one model
(``lambert+ts`` by default, the case of issue #40), then sampled by
:func:`gonio.fit.uncertainty.mcmc` (walkers drawn over the prior box, burn-in until the ensemble
reaches the optimum's typical set, ``--steps`` steps). Recorded per file: how many of the fitted
parameters lie inside their own 95 % interval (the optimum, not the posterior median), whether
the burn-in settled, the walkers re-seeded during it, the longest autocorrelation time, the
acceptance fraction, split R-hat and the wall time. Per parameter: the estimate, the interval
and whether it holds the estimate.

Writes ``benchmarks/results/mcmc_agreement.csv`` (one row per file) and
``mcmc_agreement_params.csv`` (one row per parameter), and the ``mcmc_agreement`` table of
``benchmarks/README.md``.

    PYTHONPATH=src python benchmarks/bench_mcmc_agreement.py [--steps 2000] [--only NAME ...]
"""

from __future__ import annotations

import argparse
import csv
import os
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
DATA = HERE.parent.parent / "shared" / "data"
#: NBRDF materials (MERL tables): metals, metallic paints, a fabric, a diffuse and a plastic.
NBRDF = (
    "chrome-steel",
    "gold-metallic-paint2",
    "blue-metallic-paint2",
    "red-fabric2",
    "white-diffuse-bball",
    "red-specular-plastic",
)


def files(data: Path = DATA) -> list[str]:
    """Every RGL and ALTA file of the shared data, the NBRDF members, then the Cornell files
    (spectral: 33 parameters, the longest runs)."""
    out = []
    for sub, ext in (("rgl", ".bsdf"), ("alta", ".alta"), ("alta", ".dat")):
        out += sorted(str(p) for p in (data / sub).glob(f"*{ext}"))
    out += [f"{data / 'nbrdf' / 'merl_nbrdf.zip'}::{name}" for name in NBRDF]
    return out + sorted(str(p) for p in (data / "cornell").glob("*.brdf"))


def run_one(path: str, model: str, steps: int, seed: int) -> tuple[dict, list[dict]]:
    import gonio.fit as gf

    t0 = time.perf_counter()
    r = gf.fit(path, model=model, uncertainty="mcmc", mcmc_steps=steps, seed=seed)
    wall = time.perf_counter() - t0
    unc = r.uncertainty
    d = unc.diagnostics
    layout_best = dict(zip(r.flat_names, _flat_values(r), strict=True))
    params = []
    inside = 0
    for i, n in enumerate(unc.names):
        lo, hi = (float(v) for v in unc.interval95[i])
        best = layout_best[n]
        ok = lo <= best <= hi
        inside += ok
        params.append({"file": _label(path), "parameter": n, "estimate": best, "lo95": lo,
                       "hi95": hi, "median": float(unc.center[i]), "inside": int(ok),
                       "unconstrained": int(n in unc.unconstrained)})  # fmt: skip
    tau = [v for v in d["autocorr_time"].values() if np.isfinite(v)]
    row = {
        "file": _label(path),
        "format": _format(path),
        "model": model,
        "channels": len(r.data["channels"]),
        "n_params": r.n_params,
        "inside": inside,
        "likelihood": d["likelihood"],
        "burnt_in": int(d["burnt_in"]),
        "n_burn": d["n_burn"],
        "n_reseeded": d["n_reseeded"],
        "steps": steps,
        "max_tau": max(tau) if tau else float("nan"),
        "acceptance": d["acceptance_fraction"],
        "max_rhat": max(v for v in d["split_rhat"].values()),
        "unconstrained": len(unc.unconstrained),
        "wall_s": wall,
        "load1": os.getloadavg()[0],
    }
    return row, params


def _flat_values(r) -> list[float]:
    out = []
    for n in r.flat_names:
        key, _, ch = n.partition("[")
        v = np.ravel(np.asarray(r.params[key], dtype=float))
        if ch:
            names = r.data["channels"]
            out.append(float(v[names.index(ch[:-1])] if v.size > 1 else v[0]))
        else:
            out.append(float(v[0]))
    return out


def _label(path: str) -> str:
    return Path(path.split("::")[-1]).name


def _format(path: str) -> str:
    if "::" in path:
        return "NBRDF"
    return {".bsdf": "RGL", ".brdf": "Cornell"}.get(Path(path).suffix, "ALTA")


def _write_csv(rows: list[dict], path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", default="lambert+ts")
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", nargs="*", help="substrings of the files to run")
    args = ap.parse_args()
    rows, params = [], []
    for path in files():
        if args.only and not any(s in path for s in args.only):
            continue
        row, ps = run_one(path, args.model, args.steps, args.seed)
        print(f"{row['file']}: {row['inside']}/{row['n_params']} inside, burnt in "
              f"{row['burnt_in']}, tau {row['max_tau']:.1f}, {row['wall_s']:.0f} s",
              flush=True)  # fmt: skip
        rows.append(row)
        params += ps
        _write_csv(rows, RESULTS / "mcmc_agreement.csv")
        _write_csv(params, RESULTS / "mcmc_agreement_params.csv")


def write_tables() -> None:
    """Rewrite this benchmark's table in benchmarks/README.md from its CSV."""
    import _tables

    columns = [
        ("file", "file"),
        ("format", "format"),
        ("channels", "channels"),
        ("optimum inside its 95 % interval", lambda r: f"{r['inside']}/{r['n_params']}"),
        ("burn-in settled", lambda r: "yes" if r["burnt_in"] == "1" else "no"),
        ("burn-in steps", "n_burn"),
        ("walkers re-seeded", "n_reseeded"),
        ("max tau", "max_tau"),
        ("acceptance", "acceptance"),
        ("max split R-hat", "max_rhat"),
        ("unconstrained", "unconstrained"),
        ("wall (s)", "wall_s"),
        ("load", "load1"),
    ]
    _tables.write("mcmc_agreement", _tables.markdown(_tables.read("mcmc_agreement.csv"), columns))


if __name__ == "__main__":
    main()
    write_tables()
