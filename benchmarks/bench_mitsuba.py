"""Throughput of gonio's analytic BRDF kernels against Mitsuba 3's BSDFs, in one process.

Pairs (RGB, 3 channels on both sides; gonio jitted float32, Mitsuba ``llvm_ad_rgb`` by default):

- ``Lambert`` / ``diffuse``;
- Torrance-Sparrow, Beckmann, Smith, conductor Fresnel (gold-like eta, k) / ``roughconductor``
  Beckmann without visible-normal sampling;
- the same with GGX and visible-normal sampling on both sides;
- Torrance-Sparrow GGX with dielectric Fresnel (eta 1.5 per RGB channel, so that both sides
  compute 3 channels) / ``roughconductor`` with ``k = 0`` (its conductor formula is then the
  exact dielectric one).

Operations: ``f`` vs ``eval`` (Mitsuba's value includes the cosine), ``pdf`` vs ``pdf``, and
``sample`` (direction, pdf and weight) vs ``sample`` (``BSDFSample3f`` and weight), on the same
``--batch`` float32 queries (directions uniform over the upper hemisphere). The models are not
bit-identical: Mitsuba's Smith term is the separable ``G1 G1``, gonio's the height-correlated
one, so the ratio is "the same job", not "the same arithmetic".

Each round times every pair and operation on both sides, in an order that alternates between
rounds (ABBA); a figure is the fastest (``--stat min``, the default) or the median of
``--repeats`` calls after a warm-up (compilation and Dr.Jit's kernel cache excluded). On the
shared 2-core machine other processes preempt either side at random; the fastest call is the
one least disturbed, for both sides alike, while a median of a few calls varied 2-5x between
runs. The ratio is gonio's throughput over Mitsuba's in the same round; the table gives the
median ratio over rounds (>1: gonio faster). The CSV also gives the minor page faults per call
of each side (``getrusage``): XLA:CPU allocates its outputs and temporaries per call and the
first touch of fresh pages is part of its time; Dr.Jit reuses its cached allocations.

Both sides use the machine's cores: Dr.Jit's thread pool (``drjit.thread_count()``, in the
CSV) and XLA:CPU, which splits every loop over the batch into one task per core (its
``outer_dimension_partitions``); inputs are on the device before timing, and each side waits for
its result (``block_until_ready`` / ``drjit.sync_thread``) inside the timed call.

Writes benchmarks/results/mitsuba_kernels.csv and mitsuba_kernels.png and prints a Markdown
table. Run: PYTHONPATH=src python benchmarks/bench_mitsuba.py [--rounds K] [--quick]
[--stat min|median] [--csv NAME] (``--csv`` names another CSV in benchmarks/results, e.g. for a
run against an older ``src/``; the plot is then not written).
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import resource
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import jax
import numpy as np

from gonio.brdf import models

RESULTS = Path(__file__).resolve().parent / "results"

GOLD_ETA = [0.143, 0.374, 1.442]
GOLD_K = [3.983, 2.385, 1.603]


def upper(n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` directions uniform over the upper hemisphere, float32 ``(n, 3)``."""
    z = rng.uniform(1e-3, 1.0, n)
    phi = rng.uniform(0, 2 * math.pi, n)
    r = np.sqrt(1 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], -1).astype(np.float32)


def pairs() -> list[tuple[str, models.BRDFModel, dict]]:
    """(label, gonio model, Mitsuba BSDF dict)."""

    def rgb(v):
        return {"type": "rgb", "value": v}

    ts = models.TorranceSparrow
    cond = models.Conductor(eta=GOLD_ETA, k=GOLD_K)
    return [
        ("Lambert / diffuse", models.Lambert([0.5, 0.4, 0.3]),
         {"type": "diffuse", "reflectance": rgb([0.5, 0.4, 0.3])}),
        ("TS Beckmann Smith conductor / roughconductor",
         ts(alpha=0.2, distribution="beckmann", shadowing="smith", fresnel=cond),
         {"type": "roughconductor", "distribution": "beckmann", "alpha": 0.2,
          "sample_visible": False, "eta": rgb(GOLD_ETA), "k": rgb(GOLD_K)}),
        ("TS GGX Smith conductor, visible / roughconductor",
         ts(alpha=0.2, distribution="ggx", shadowing="smith", fresnel=cond, sampling="visible"),
         {"type": "roughconductor", "distribution": "ggx", "alpha": 0.2,
          "sample_visible": True, "eta": rgb(GOLD_ETA), "k": rgb(GOLD_K)}),
        ("TS GGX Smith dielectric F / roughconductor k=0",
         ts(alpha=0.2, distribution="ggx", shadowing="smith", fresnel=models.Dielectric([1.5] * 3),
            sampling="visible"),
         {"type": "roughconductor", "distribution": "ggx", "alpha": 0.2,
          "sample_visible": True, "eta": 1.5, "k": 0.0}),
    ]  # fmt: skip


def timed(fn: Callable[[], None], repeats: int, stat: str) -> tuple[float, float]:
    """(fastest or median seconds per call, minor page faults per call) after one warm-up."""
    fn()
    ts = []
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    faults = (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults) / repeats
    return (min(ts) if stat == "min" else statistics.median(ts)), faults


def gonio_ops(model, wi, wo, u) -> dict[str, Callable[[], None]]:
    f = jax.jit(lambda a, b: model.f(a, b))
    p = jax.jit(lambda a, b: model.pdf(a, b))
    s = jax.jit(lambda w, uu: model.sample(w, uu))
    return {
        "f": lambda: jax.block_until_ready(f(wi, wo)),
        "pdf": lambda: jax.block_until_ready(p(wi, wo)),
        "sample": lambda: jax.block_until_ready(s(wo, u)),
    }


def mitsuba_ops(mi, dr, desc: dict, wi, wo, u) -> dict[str, Callable[[], None]]:
    n = wi.shape[0]
    bsdf = mi.load_dict(desc)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(wo.T)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    v_wi = mi.Vector3f(wi.T)
    u1, u2 = mi.Float(u[:, 0]), mi.Point2f(u.T)
    dr.make_opaque(si, v_wi, u1, u2)
    ctx = mi.BSDFContext()

    def ev():
        dr.eval(bsdf.eval(ctx, si, v_wi))
        dr.sync_thread()

    def pdf():
        dr.eval(bsdf.pdf(ctx, si, v_wi))
        dr.sync_thread()

    def sample():
        bs, w = bsdf.sample(ctx, si, u1, u2)
        dr.eval(bs.wo, bs.pdf, w)
        dr.sync_thread()

    return {"f": ev, "pdf": pdf, "sample": sample}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--batch", type=int, default=1_000_000)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--variant", default="llvm_ad_rgb")
    ap.add_argument("--quick", action="store_true", help="3 rounds of 3 repeats")
    ap.add_argument(
        "--stat",
        choices=("min", "median"),
        default="min",
        help="figure per side and round: fastest or median call",
    )
    ap.add_argument("--csv", default="mitsuba_kernels.csv", help="CSV name in benchmarks/results")
    args = ap.parse_args()
    if "/" in args.csv or not args.csv.endswith(".csv"):
        raise SystemExit(
            f"bench_mitsuba.py: --csv must be a file name ending in .csv, got {args.csv!r}"
        )
    rounds, repeats = (3, 3) if args.quick else (args.rounds, args.repeats)

    import drjit as dr
    import mitsuba as mi

    mi.set_variant(args.variant)
    rng = np.random.default_rng(0)
    n = args.batch
    wi, wo = upper(n, rng), upper(n, rng)
    u = rng.random((n, 2)).astype(np.float32)
    jwi, jwo, ju = (jax.device_put(x) for x in (wi, wo, u))

    jobs = []
    for label, model, desc in pairs():
        g = gonio_ops(model, jwi, jwo, ju)
        m = mitsuba_ops(mi, dr, desc, wi, wo, u)
        for op in ("f", "pdf", "sample"):
            jobs.append((label, op, g[op], m[op]))
    res: dict[tuple[str, str], dict[str, list[float]]] = {
        (j[0], j[1]): {"gonio": [], "mitsuba": [], "gonio_faults": [], "mitsuba_faults": []}
        for j in jobs
    }
    for r in range(rounds):
        for label, op, g, m in jobs:
            sides = [("gonio", g), ("mitsuba", m)]
            for side, fn in sides if r % 2 == 0 else sides[::-1]:
                t, faults = timed(fn, repeats, args.stat)
                res[(label, op)][side].append(t)
                res[(label, op)][f"{side}_faults"].append(faults)
        print(f"round {r + 1}/{rounds} done", flush=True)

    load = os.getloadavg()[0]
    rows = []
    for (label, op), d in res.items():
        ratio = statistics.median(m / g for g, m in zip(d["gonio"], d["mitsuba"], strict=True))
        rows.append({
            "pair": label, "op": op, "batch": n,
            "gonio_M_per_s": f"{n / statistics.median(d['gonio']) / 1e6:.3g}",
            "mitsuba_M_per_s": f"{n / statistics.median(d['mitsuba']) / 1e6:.3g}",
            "ratio_gonio_over_mitsuba": f"{ratio:.3f}",
            "gonio_page_faults_per_call": f"{statistics.median(d['gonio_faults']):.0f}",
            "mitsuba_page_faults_per_call": f"{statistics.median(d['mitsuba_faults']):.0f}",
            "stat": args.stat, "repeats": repeats,
            "variant": args.variant, "rounds": rounds, "load_avg_1min": f"{load:.1f}",
            "drjit_threads": dr.thread_count(), "cpus": os.cpu_count(),
        })  # fmt: skip
    RESULTS.mkdir(exist_ok=True)
    with open(RESULTS / args.csv, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    if args.csv != "mitsuba_kernels.csv":
        print_table(rows, n, args, rounds, repeats, load, dr.thread_count())
        return

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 0.3 * len(rows) + 1.4))
    y = np.arange(len(rows))
    ax.barh(y, [float(r["ratio_gonio_over_mitsuba"]) for r in rows], color="tab:blue")
    ax.axvline(1.0, color="gray", ls="--", lw=0.8)
    ax.set_yticks(y, [f"{r['pair']}: {r['op']}" for r in rows], fontsize=7)
    ax.invert_yaxis()
    ax.set_xscale("log")
    ax.set_xlabel(f"gonio / Mitsuba {args.variant} throughput (same run; >1: gonio faster)")
    ax.set_title(f"batch {n:.0e} float32, {rounds} rounds, load average {load:.1f}", fontsize=9)
    fig.tight_layout()
    fig.savefig(RESULTS / "mitsuba_kernels.png", dpi=120)

    print_table(rows, n, args, rounds, repeats, load, dr.thread_count())


def print_table(rows, n, args, rounds, repeats, load, threads) -> None:
    print(
        f"\nbatch {n:.0e}, Mitsuba {args.variant} ({threads} threads), {rounds} rounds x "
        f"{repeats} calls ({args.stat}), {os.cpu_count()} CPUs, load average {load:.1f}\n"
    )
    print("| gonio model / Mitsuba BSDF | op | gonio M/s | Mitsuba M/s | gonio / Mitsuba |")
    print("|---|---|---:|---:|---:|")
    for r in rows:
        print(
            f"| {r['pair']} | {r['op']} | {r['gonio_M_per_s']} | {r['mitsuba_M_per_s']} "
            f"| {r['ratio_gonio_over_mitsuba']} |"
        )


def write_tables() -> None:
    """Rewrite this benchmark's table in benchmarks/README.md from its CSV."""
    import _tables

    columns = [
        ("gonio model / Mitsuba BSDF", "pair"),
        ("op", "op"),
        ("gonio M/s", "gonio_M_per_s"),
        ("Mitsuba M/s", "mitsuba_M_per_s"),
        ("gonio / Mitsuba", "ratio_gonio_over_mitsuba"),
        ("load", "load_avg_1min"),
    ]
    rows = _tables.read("mitsuba_kernels.csv")
    _tables.write("mitsuba_kernels", _tables.markdown(rows, columns))


if __name__ == "__main__":
    main()
    write_tables()
