"""Fitting benchmarks: interval coverage, speed on a MERL-size table, optimizers, real files.

Run from the repository root (each section can be run alone; results go to
benchmarks/results/fit_*.csv and .png)::

    PYTHONPATH=src python benchmarks/bench_fit.py                  # every section
    PYTHONPATH=src python benchmarks/bench_fit.py coverage --trials 200
    PYTHONPATH=src python benchmarks/bench_fit.py speed optimizers real ngan

Sections
--------
coverage    Simulated data from known parameters with realistic noise (sigma = 0.002 + 5% of f,
            known), fitted with Laplace intervals (and optionally MCMC, ``--mcmc-trials``); the
            fraction of trials whose 95% (68%) interval holds the truth, per parameter.
speed       Lambert + Torrance-Sparrow (Beckmann, V-cavity, Schlick) tabulated on MERL's full
            90 x 90 x 180 grid with 2% multiplicative noise: wall time to the optimum (after JIT,
            second run), Laplace, MCMC, per material.
optimizers  Loss against wall time for each optimizer from the same start (LM, L-BFGS, SLSQP,
            CRS2, MLSL, DIRECT) on a 20 000-sample subsample of the same table.
real        Every file in ../shared/data that gonio.io reads, fitted with every model; loss per
            model and whether it converged without manual restarts.
ngan        Ngan et al. (2005) published parameters next to ours on the same metric, where a
            measurement of the same material is available.

Timings depend on the machine and on what else runs on it; the CSVs record the CPU count and
the load average at the start of each section.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

import gonio.fit as gf
import gonio.fit.losses  # noqa: F401  (gf.losses)
from gonio.brdf import models
from gonio.fit import presets
from gonio.fit.data import from_arrays
from gonio.fit.lm import levenberg_marquardt
from gonio.fit.losses import get_loss
from gonio.fit.objective import Problem
from gonio.fit.optimize import run_nlopt
from gonio.fit.params import Layout

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
# ../shared/data next to the checkout (a worktree may sit one level deeper)
SHARED = next(
    (p / "shared" / "data" for p in ROOT.parents if (p / "shared" / "data").is_dir()),
    ROOT.parent / "shared" / "data",
)


def _machine() -> str:
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return f"{os.cpu_count()} CPUs, load {load:.1f}"


def _write_csv(name: str, rows: list[dict[str, Any]]) -> Path:
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / name
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    print(f"wrote {path}")
    _print_markdown(rows, keys)
    return path


def _print_markdown(rows: list[dict[str, Any]], keys: list[str]) -> None:
    """The rows as a Markdown table (numbers to 4 significant digits)."""

    def fmt(v: Any) -> str:
        if isinstance(v, float):
            return f"{v:.4g}"
        return str(v).replace("|", "/")

    print("| " + " | ".join(keys) + " |")
    print("|" + "---|" * len(keys))
    for r in rows[:60]:
        print("| " + " | ".join(fmt(r.get(k, "")) for k in keys) + " |")


def _directions(n: int, rng: np.random.Generator) -> np.ndarray:
    u = rng.uniform(size=(n, 2))
    th = np.arccos(np.sqrt(u[:, 0]))
    ph = 2 * np.pi * u[:, 1]
    return np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)


def _spec_model() -> tuple[str, Any]:
    """The specular model of the benchmarks: Lambert + TS(Beckmann) when available."""
    if "lambert+ts" in presets.available():
        tmpl, _, _ = presets.build("lambert+ts")
        truth = tmpl.replace(
            **{
                "lambert.albedo": np.array([0.25, 0.15, 0.08]),
                "torrancesparrow.alpha": 0.15,
                "torrancesparrow.fresnel.f0": np.array([0.05, 0.05, 0.06]),
            }
        )
        return "lambert+ts", truth
    truth = models.Phong(rho_d=[0.25, 0.15, 0.08], rho_s=[0.3, 0.3, 0.35], n=80.0)
    return "phong", truth


# -- coverage ------------------------------------------------------------------------------------
def coverage(trials: int, mcmc_trials: int, n_samples: int) -> None:
    name, truth = _spec_model()
    print(f"coverage: {name}, {trials} trials of {n_samples} samples ({_machine()})")
    true_params = truth.params()
    hits95: dict[str, list[bool]] = {}
    hits68: dict[str, list[bool]] = {}
    widths: dict[str, list[float]] = {}
    mc95: dict[str, list[bool]] = {}
    t0 = time.perf_counter()
    for trial in range(trials):
        rng = np.random.default_rng(1000 + trial)
        wi, wo = _directions(n_samples, rng), _directions(n_samples, rng)
        f = np.asarray(truth.f(wi, wo))
        sigma = 0.002 + 0.05 * f
        y = f + sigma * rng.standard_normal(f.shape)
        data = from_arrays(wi, wo, y, sigma=sigma, name=f"trial{trial}")
        unc_kind = "mcmc" if trial < mcmc_trials else "laplace"
        res = gf.fit(data, model=name, uncertainty="laplace", n_starts=4, seed=trial)
        results = [(hits95, hits68, res)]
        if unc_kind == "mcmc":
            res_m = gf.fit(data, model=name, uncertainty="mcmc", n_starts=4, seed=trial)
            results.append((mc95, None, res_m))
        for h95, h68, r in results:
            unc = r.uncertainty
            for i, flat in enumerate(unc.names):
                key, _, ch = flat.partition("[")
                tv = np.atleast_1d(np.asarray(true_params[key]))
                t = tv[r.data["channels"].index(ch[:-1])] if ch and tv.size > 1 else tv[0]
                lo, hi = unc.interval95[i]
                h95.setdefault(flat, []).append(bool(lo <= t <= hi))
                if h68 is not None:
                    lo68, hi68 = unc.interval68[i]
                    h68.setdefault(flat, []).append(bool(lo68 <= t <= hi68))
                    widths.setdefault(flat, []).append(float(hi - lo))
        if (trial + 1) % 10 == 0:
            print(f"  {trial + 1} trials, {time.perf_counter() - t0:.0f} s")
    rows = []
    for flat in hits95:
        k = len(hits95[flat])
        c95 = float(np.mean(hits95[flat]))
        rows.append({
            "model": name,
            "parameter": flat,
            "trials": k,
            "coverage95": round(c95, 3),
            "coverage68": round(float(np.mean(hits68[flat])), 3),
            "binomial_se95": round(float(np.sqrt(0.95 * 0.05 / k)), 3),
            "mean_width95": float(np.mean(widths[flat])),
            "mcmc_trials": len(mc95.get(flat, [])),
            "mcmc_coverage95": round(float(np.mean(mc95[flat])), 3) if mc95.get(flat) else "",
            "in_90_99": 0.90 <= c95 <= 0.99,
        })  # fmt: skip
    rows.append({"model": name, "parameter": "(machine)", "trials": trials,
                 "coverage95": _machine(), "mean_width95": time.perf_counter() - t0})  # fmt: skip
    _write_csv("fit_coverage.csv", rows)
    for r in rows[:-1]:
        print(f"  {r['parameter']:<36} 95%: {r['coverage95']:.3f}  68%: {r['coverage68']:.3f}"
              f"  MCMC 95%: {r['mcmc_coverage95']}")  # fmt: skip


# -- speed ---------------------------------------------------------------------------------------
def merl_table(truth: Any, seed: int = 0) -> Any:
    """``truth`` on MERL's grid with 2% multiplicative and 1e-4 absolute Gaussian noise."""
    from gonio.brdf.tabulated import TabulatedBRDF

    t = TabulatedBRDF.merl_like(truth)
    rng = np.random.default_rng(seed)
    v = np.asarray(t.values, dtype=np.float64)
    v = v * (1 + 0.02 * rng.standard_normal(v.shape)) + 1e-4 * rng.standard_normal(v.shape)
    return t.replace(values=v.astype(np.float32))


def speed(mcmc: bool = True) -> None:
    name, truth = _spec_model()
    print(f"speed: {name} on MERL's grid ({_machine()})")
    t0 = time.perf_counter()
    table = merl_table(truth)
    t_tab = time.perf_counter() - t0
    t0 = time.perf_counter()
    data = gf.prepare(table)
    t_prep = time.perf_counter() - t0
    print(f"  {data.n} valid cells under 80 deg x {data.channels} channels "
          f"(tabulate {t_tab:.1f} s, prepare {t_prep:.1f} s)")  # fmt: skip
    rows = []
    for run in ("first (includes JIT)", "second", "third"):
        t0 = time.perf_counter()
        c0 = time.process_time()
        r = gf.fit(data, model=name, uncertainty="laplace")
        wall = time.perf_counter() - t0
        cpu = time.process_time() - c0
        tm = r.optimizer["timings"]
        rows.append({
            "model": name, "run": run, "cells": data.n, "channels": data.channels,
            "optimum_s": round(tm["total"], 3), "starts_s": round(tm["starts"], 3),
            "polish_s": round(tm["polish"], 3), "fit_call_s": round(wall, 3),
            "fit_call_cpu_s": round(cpu, 3),
            "lm_iterations": r.optimizer["n_iter"], "loss": r.loss,
            "machine": _machine(),
        })  # fmt: skip
        print(f"  {run}: optimum {tm['total']:.2f} s (starts {tm['starts']:.2f}, polish "
              f"{tm['polish']:.2f}), whole fit() with Laplace {wall:.2f} s wall, "
              f"{cpu:.2f} s CPU (all threads)")  # fmt: skip
    # Laplace alone, after JIT
    from gonio.fit.uncertainty import laplace
    from gonio.fit.uncertainty import mcmc as run_mcmc

    tmpl, fixed, tied = presets.build(name)
    lay = Layout(tmpl, data.channels, fixed=fixed, tied=tied)
    prob = Problem(lay, get_loss("wls"), data)
    u = r.u
    laplace(prob, u)
    t0, c0 = time.perf_counter(), time.process_time()
    lap = laplace(prob, u)
    t_lap = time.perf_counter() - t0
    cpu_lap = time.process_time() - c0
    print(f"  Laplace: {t_lap:.2f} s")
    row = {"model": name, "run": "laplace", "cells": data.n, "laplace_s": round(t_lap, 3),
           "laplace_cpu_s": round(cpu_lap, 3),
           "machine": _machine()}  # fmt: skip
    rows.append(row)
    if mcmc:
        t0, c0 = time.perf_counter(), time.process_time()
        m = run_mcmc(prob, u, init=lap)
        t_mc = time.perf_counter() - t0
        cpu_mc = time.process_time() - c0
        d = m.diagnostics
        print(f"  MCMC: {t_mc:.1f} s ({d['n_walkers']} walkers x {d['n_steps']} steps on "
              f"{d['n_samples_likelihood']} samples; acceptance {d['acceptance_fraction']:.2f}, "
              f"max tau {max(d['autocorr_time'].values()):.0f})")  # fmt: skip
        rows.append({"model": name, "run": "mcmc", "cells": data.n, "mcmc_s": round(t_mc, 2),
                     "mcmc_cpu_s": round(cpu_mc, 2),
                     "acceptance": d["acceptance_fraction"],
                     "max_tau": max(d["autocorr_time"].values()),
                     "max_rhat": max(d["split_rhat"].values()), "machine": _machine()})  # fmt: skip
    truth_flat = {k: np.asarray(v).tolist() for k, v in truth.params().items()}
    rows.append({"model": name, "run": "truth vs fit", "truth": str(truth_flat),
                 "fit": str(r.params)})  # fmt: skip
    _write_csv("fit_speed.csv", rows)


# -- optimizers ----------------------------------------------------------------------------------
class _Timed:
    """Wrap a problem's objective calls to record (time, best loss so far)."""

    def __init__(self, prob: Problem):
        self.prob = prob
        self.t0 = time.perf_counter()
        self.trace: list[tuple[float, float]] = []
        self.best = np.inf
        self._normal, self._vg, self._cost = prob.normal, prob.value_and_grad, prob.cost
        prob.normal = self.normal  # type: ignore[method-assign]
        prob.value_and_grad = self.vg  # type: ignore[method-assign]
        prob.cost = self.cost  # type: ignore[method-assign]

    def _rec(self, c: float) -> None:
        self.best = min(self.best, c) if np.isfinite(c) else self.best
        self.trace.append((time.perf_counter() - self.t0, self.best))

    def normal(self, u: np.ndarray) -> Any:
        out = self._normal(u)
        self._rec(out[0])
        return out

    def vg(self, u: np.ndarray) -> Any:
        out = self._vg(u)
        self._rec(out[0])
        return out

    def cost(self, u: np.ndarray) -> float:
        out = self._cost(u)
        self._rec(out)
        return out


def optimizers(n_sub: int = 20000) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    name, truth = _spec_model()
    print(f"optimizers: {name}, {n_sub} samples of the MERL-grid table ({_machine()})")
    data = gf.prepare(merl_table(truth)).random_subset(n_sub, 0)
    tmpl, fixed, tied = presets.build(name)
    lay = Layout(tmpl, data.channels, fixed=fixed, tied=tied)
    u0 = lay.initial()
    methods = ["lm", "lbfgs", "slsqp", "crs2", "mlsl", "direct"]
    traces = {}
    for m in methods:
        prob = Problem(lay, get_loss("wls"), data)
        # warm the JIT outside the timed region
        prob.normal(u0)
        prob.value_and_grad(u0)
        prob.cost(u0)
        rec = _Timed(prob)
        if m == "lm":
            lo, hi = lay.box()
            levenberg_marquardt(prob.normal, u0, lo, hi, max_iter=200)
        else:
            budget = 20000 if m in ("crs2", "mlsl", "direct") else 5000
            run_nlopt(prob, u0, m, maxeval=budget, seed=0)
        traces[m] = rec.trace
        print(f"  {m:<7} best loss {rec.best:.6g} after {rec.trace[-1][0]:.2f} s, "
              f"{len(rec.trace)} evaluations")  # fmt: skip
    best = min(min(c for _, c in tr) for tr in traces.values())
    rows = []
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for m, tr in traces.items():
        t = np.array([x[0] for x in tr])
        c = np.array([x[1] for x in tr])
        rel = (c - best) / best + 1e-16
        ax.plot(t, rel, label=m)
        for tt, cc in tr[:: max(1, len(tr) // 200)]:
            rows.append({"method": m, "time_s": round(tt, 5), "loss": cc,
                         "relative_excess": (cc - best) / best})  # fmt: skip
        rows.append({"method": m, "time_s": round(t[-1], 5), "loss": c[-1],
                     "relative_excess": (c[-1] - best) / best})  # fmt: skip
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time (s), after JIT")
    ax.set_ylabel("(loss - best) / best")
    ax.set_title(f"{name} on {data.n} samples ({_machine()})")
    ax.legend()
    RESULTS.mkdir(parents=True, exist_ok=True)
    fig.savefig(RESULTS / "fit_optimizers.png", dpi=110, bbox_inches="tight")
    print(f"wrote {RESULTS / 'fit_optimizers.png'}")
    _write_csv("fit_optimizers.csv", rows)


# -- real data -----------------------------------------------------------------------------------
def real(model_names: list[str] | None = None) -> None:
    try:
        from gonio import io as gio

        load = gio.load
    except (ImportError, AttributeError):
        print("real: gonio.io.load is not available; skipped")
        return
    names = model_names or [
        m for m in ("lambert", "oren-nayar", "phong", "ward", "torrance-sparrow", "lambert+ward",
                    "lambert+ts") if m in presets.available()
    ]  # fmt: skip
    files = sorted(
        p for sub in ("cornell", "rgl", "alta") for p in (SHARED / sub).glob("*")
        if p.suffix in (".brdf", ".bsdf", ".alta", ".dat")
    )  # fmt: skip
    print(f"real: {len(files)} files x {len(names)} models ({_machine()})")
    rows = []
    for path in files:
        try:
            data = gf.prepare(load(path), name=path.stem)
        except Exception as exc:  # report and go on: one unreadable file is a result too
            rows.append({"file": path.name, "model": "", "error": f"{type(exc).__name__}: {exc}"})
            print(f"  {path.name}: cannot prepare ({exc})")
            continue
        for m in names:
            t0 = time.perf_counter()
            try:
                r = gf.fit(data, model=m, loss="wls")
            except Exception as exc:
                rows.append({"file": path.name, "model": m, "error": str(exc)})
                print(f"  {path.name} {m}: {exc}")
                continue
            rows.append({
                "file": path.name, "model": m, "samples": data.n, "channels": data.channels,
                "converged": r.optimizer["converged"], "wls": r.metrics["wls"],
                "ngan": r.metrics["ngan"], "low_e1": r.metrics["low-e1"],
                "cube_root": r.metrics["cube-root"], "bic": r.bic,
                "on_bounds": ";".join(r.optimizer["on_bounds"]),
                "seconds": round(time.perf_counter() - t0, 2),
            })  # fmt: skip
            print(f"  {path.name:<32} {m:<22} ngan {r.metrics['ngan']:.4g} "
                  f"converged={r.optimizer['converged']} ({rows[-1]['seconds']} s)")  # fmt: skip
    _write_csv("fit_real.csv", rows)


def ngan() -> None:
    """Ngan et al.'s published parameters next to ours, where a measurement allows it.

    The fits are to MERL measurements; ../shared/data holds no MERL binary, only the ALTA
    library's 1-D slice of MERL pink-felt (RGB against cos theta_h at theta_d = 0, as gonio.io
    reads it). On that slice both parameter sets are evaluated under every metric: the published
    ones (converted by gonio.brdf.ngan under bbm's conventions) and ours, fitted to the slice
    with the ngan metric from the published model's structure. Ours is fitted to the slice and
    theirs to the whole 4-D table, so ours must be at least as good here; the comparison checks
    conventions and scale, not which fit is better overall.
    """
    rows: list[dict[str, Any]] = []
    try:
        from gonio import io as gio
        from gonio.brdf import ngan as ngan_fits

        load = gio.load
    except (ImportError, AttributeError) as exc:
        print(f"ngan: needs gonio.io and gonio.brdf.ngan ({exc}); skipped")
        _write_csv("fit_ngan.csv", [{"note": f"skipped: {exc}"}])
        return
    slice_path = SHARED / "alta" / "pink-felt-1d.alta"
    if not slice_path.exists():
        print("ngan: no pink-felt slice in ../shared/data; skipped")
        return
    data = gf.prepare(load(slice_path), name="pink-felt (1-D slice)")
    print(f"ngan: pink-felt slice, {data.n} samples x {data.channels} channels ({_machine()})")
    for fname in ("ngan_ward.fit", "ngan_blinnphong.fit", "ngan_cooktorrance.fit"):
        fits = ngan_fits.parse_ngan_fits((SHARED / "fits" / fname).read_text())
        entry = fits.get("pink-felt")
        if entry is None:
            continue
        published = ngan_fits.to_model(entry)
        f_pub = np.asarray(published.f(data.wi, data.wo))
        pub = {k: gf.losses.evaluate(k, f_pub, data) for k in gf.LOSSES}
        r = gf.fit(data, model=published, loss="ngan", n_starts=16)
        rows.append({
            "material": "pink-felt", "model": entry.model, "metric": "ngan",
            "published_ngan": pub["ngan"], "ours_ngan": r.metrics["ngan"],
            "published_low_e1": pub["low-e1"], "ours_low_e1": r.metrics["low-e1"],
            "published_cube_root": pub["cube-root"], "ours_cube_root": r.metrics["cube-root"],
            "published_params": str(entry.params), "ours_params": str(r.params),
        })  # fmt: skip
        print(f"  {entry.model:<18} ngan metric: published {pub['ngan']:.4g}, "
              f"ours {r.metrics['ngan']:.4g}")  # fmt: skip
    _write_csv("fit_ngan.csv", rows)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("sections", nargs="*", default=["coverage", "speed", "optimizers", "real",
                                                    "ngan"])  # fmt: skip
    p.add_argument("--trials", type=int, default=100)
    p.add_argument("--mcmc-trials", type=int, default=0)
    p.add_argument("--samples", type=int, default=1500)
    p.add_argument("--no-mcmc", action="store_true", help="skip MCMC in the speed section")
    a = p.parse_args(argv)
    for s in a.sections:
        if s == "coverage":
            coverage(a.trials, a.mcmc_trials, a.samples)
        elif s == "speed":
            speed(mcmc=not a.no_mcmc)
        elif s == "optimizers":
            optimizers()
        elif s == "real":
            real()
        elif s == "ngan":
            ngan()
        else:
            print(f"unknown section {s}", file=sys.stderr)
            return 2
    return 0


def write_tables() -> None:
    """Rewrite this benchmark's tables in benchmarks/README.md from its CSVs."""
    import statistics

    import _tables

    speed = [
        ("model", "model"),
        ("run", "run"),
        ("cells", "cells"),
        ("optimum (s)", "optimum_s"),
        ("fit call (s)", "fit_call_s"),
        ("fit call, CPU (s)", "fit_call_cpu_s"),
        ("Laplace (s)", "laplace_s"),
        ("MCMC (s)", "mcmc_s"),
        ("machine", "machine"),
    ]
    _tables.write("fit_speed", _tables.markdown(_tables.read("fit_speed.csv"), speed))
    coverage = [
        ("model", "model"),
        ("parameter", "parameter"),
        ("trials", "trials"),
        ("95 % coverage", "coverage95"),
        ("68 % coverage", "coverage68"),
        ("binomial s.e.", "binomial_se95"),
        ("MCMC trials", "mcmc_trials"),
        ("MCMC 95 % coverage", "mcmc_coverage95"),
    ]
    _tables.write("fit_coverage", _tables.markdown(_tables.read("fit_coverage.csv"), coverage))
    real = _tables.read("fit_real.csv")
    files = sorted({r["file"] for r in real})
    models = sorted({r["model"] for r in real})
    converged = sum(r["converged"] == "True" for r in real)
    _tables.write(
        "fit_real",
        f"{converged} of {len(real)} fits of {len(models)} models to {len(files)} files converge.",
    )
    opt = _tables.read("fit_optimizers.csv")
    methods = sorted({r["method"] for r in opt})
    summary = [
        {
            "method": m,
            "n": str(sum(r["method"] == m for r in opt)),
            "time": statistics.median(float(r["time_s"]) for r in opt if r["method"] == m),
            "excess": statistics.median(
                float(r["relative_excess"]) for r in opt if r["method"] == m
            ),
        }
        for m in methods
    ]
    columns = [
        ("optimizer", "method"),
        ("fits", "n"),
        ("median time (s)", "time"),
        ("median relative loss excess", "excess"),
    ]
    _tables.write("fit_optimizers", _tables.markdown(summary, columns))


if __name__ == "__main__":
    _rc = main()
    if not _rc:
        write_tables()
    sys.exit(_rc)
