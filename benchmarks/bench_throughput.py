"""Throughput of BRDF evaluation, pdf and sampling: analytic models and tabulated BRDFs.

For every analytic model exported by ``gonio.brdf.models`` (constructed with its defaults; models
merged later are picked up automatically) it times jitted ``f``, ``pdf`` and ``sample`` at a batch
of 1e6 float32 queries (directions uniform over the upper hemisphere). For a MERL-resolution
(90 x 90 x 180, RGB) table of Lambert + Torrance-Sparrow (GGX, alpha 0.2, Smith, Schlick 0.04) it
times the lookup ``f`` and sampling by inversion, alias and rejection (the default majorant
proposal, also called under ``jit``, and the cosine proposal; with acceptance rates) and
reports the one-off build time of the lazily built sampling structures for every outgoing bucket
met.

Compilation and the lazy builds are warm-up and excluded; each figure is the median of
``--repeats`` runs. Queries are random (cache-unfriendly for table lookups; a renderer's coherent
queries run faster).

Targets (issue 2): analytic f >= 20 M/s, table lookup >= 20 M/s. Rejection is the exact
reference sampler, not a fast path (its 10 M/s target was withdrawn).

Writes benchmarks/results/throughput.csv and throughput.png and prints a Markdown table.
Run: PYTHONPATH=src python benchmarks/bench_throughput.py [--batch N] [--repeats K] [--quick]
"""

from __future__ import annotations

import argparse
import csv
import inspect
import math
import os
import platform
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import jax
import numpy as np

from gonio.brdf import models
from gonio.brdf.tabulated import TabulatedBRDF

RESULTS = Path(__file__).resolve().parent / "results"
TARGETS = {"f": 20e6, "lookup": 20e6, "table-sample": 10e6}


def upper_directions(n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` directions uniform over the upper hemisphere, float32 ``(n, 3)``."""
    z = rng.uniform(1e-3, 1.0, n)
    phi = rng.uniform(0, 2 * math.pi, n)
    r = np.sqrt(1 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], -1).astype(np.float32)


def median_time(fn: Callable[[], object], repeats: int) -> float:
    jax.block_until_ready(fn())  # warm-up: compilation, lazy builds
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def analytic_models() -> list[tuple[str, models.BRDFModel]]:
    """Every concrete model class in gonio.brdf.models, built with its defaults."""
    out = []
    for name in sorted(models.__all__):
        cls = getattr(models, name)
        if not (inspect.isclass(cls) and issubclass(cls, models.BRDFModel)):
            continue
        if cls in (models.BRDFModel, models.Sum):
            continue
        try:
            out.append((name, cls()))
        except Exception as e:  # a model without defaults is reported, not fatal
            print(f"skipping {name}: cannot build with defaults ({e})")
    return out


def benchmark_table() -> tuple[TabulatedBRDF, models.BRDFModel | None]:
    """The table and its specular lobe (the model's Torrance-Sparrow term, or None)."""
    try:
        spec = models.TorranceSparrow(
            alpha=0.2, distribution="ggx", shadowing="smith", fresnel=models.Schlick(0.04)
        )
        model = models.Lambert([0.55, 0.30, 0.12]) + spec
    except (AttributeError, TypeError):
        spec, model = None, models.Lambert([0.55, 0.30, 0.12])
    return TabulatedBRDF.merl_like(model), spec


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--batch", type=int, default=1_000_000, help="queries per call (default 1e6)")
    ap.add_argument("--repeats", type=int, default=5, help="timed runs per figure (median)")
    ap.add_argument(
        "--rejection-batch",
        type=int,
        default=100_000,
        help="queries per call of rejection sampling with the cosine proposal (default "
        "1e5: its low acceptance makes 1e6 slow); the majorant proposal uses --batch",
    )
    ap.add_argument("--quick", action="store_true", help="batch 1e5, 2 repeats (smoke test)")
    args = ap.parse_args()
    n, repeats = (100_000, 2) if args.quick else (args.batch, args.repeats)
    nr = min(n, args.rejection_batch)
    rng = np.random.default_rng(0)
    wi = jax.device_put(upper_directions(n, rng))
    wo = jax.device_put(upper_directions(n, rng))
    u = jax.device_put(rng.random((n, 2)).astype(np.float32))
    rows: list[dict] = []

    def record(kind: str, name: str, op: str, seconds: float, extra: str = "", batch=None) -> None:
        batch = batch or n
        rate = batch / seconds
        target = TARGETS.get("f" if op == "f" and kind == "model" else kind, float("nan"))
        if op.startswith("rejection"):  # the exact reference sampler: no throughput target
            target = float("nan")
        rows.append(
            {
                "kind": kind,
                "name": name,
                "op": op,
                "batch": batch,
                "seconds": f"{seconds:.4f}",
                "rate_M_per_s": f"{rate / 1e6:.3g}",
                "target_M_per_s": "" if math.isnan(target) else f"{target / 1e6:.0f}",
                "note": extra,
            }
        )
        print(f"{kind:12s} {name:20s} {op:14s} {rate / 1e6:8.3f} M/s  {extra}", flush=True)

    for name, m in analytic_models():
        f = jax.jit(lambda a, b, m=m: m.f(a, b))
        p = jax.jit(lambda a, b, m=m: m.pdf(a, b))
        s = jax.jit(lambda w, uu, m=m: m.sample(w, uu))
        record("model", name, "f", median_time(lambda f=f: f(wi, wo), repeats))
        record("model", name, "pdf", median_time(lambda p=p: p(wi, wo), repeats))
        record("model", name, "sample", median_time(lambda s=s: s(wo, u), repeats))

    t0 = time.perf_counter()
    table, _ = benchmark_table()
    print(f"tabulated the model on MERL's grid in {time.perf_counter() - t0:.1f} s")
    lookup = jax.jit(lambda a, b: table.f(a, b))
    record("lookup", "MERL 90x90x180 RGB", "f", median_time(lambda: lookup(wi, wo), repeats))
    nb = table.sampling_res[0]
    # (label, method, proposal, called under jit): rejection runs one traced loop either way;
    # "rejection-jit" times it inside the caller's jit
    variants = [
        ("inversion", "inversion", "majorant", True),
        ("alias", "alias", "majorant", True),
        ("rejection", "rejection", "majorant", False),
        ("rejection-jit", "rejection", "majorant", True),
        ("rejection-cosine", "rejection", "cosine", False),
    ]
    for label, method, proposal, under_jit in variants:
        t0 = time.perf_counter()
        table.pdf(wo[:1], wo[:1], method=method, proposal=proposal)  # time one lazy build
        one = time.perf_counter() - t0
        batch = n if method != "rejection" or proposal == "majorant" else nr

        def sample(w, uu, m=method, p=proposal):
            return table.sample(w, uu, method=m, proposal=p)

        call = jax.jit(sample) if under_jit else sample
        fn = lambda call=call, w=wo[:batch], uu=u[:batch]: call(w, uu)  # noqa: E731
        t0 = time.perf_counter()
        jax.block_until_ready(fn())  # builds the remaining buckets
        build = time.perf_counter() - t0
        slow = method == "rejection" and proposal != "majorant"
        sec = median_time(fn, max(1, repeats // 2) if slow else repeats)
        note = f"lazy build: first bucket {one:.2f} s, all {nb} buckets + compile {build:.1f} s"
        if under_jit and method == "rejection":
            note = "called under jit; " + note
        elif method == "rejection":
            st = table._sampler().stats
            acc = st["rejection_samples"] / st["rejection_proposals"]
            note = f"acceptance {acc:.3f}; " + note
        record("table-sample", "MERL 90x90x180 RGB", label, sec, note, batch=batch)

    RESULTS.mkdir(parents=True, exist_ok=True)
    write_csv(RESULTS / "throughput.csv", rows)
    plot(RESULTS / "throughput.png", rows, n)
    print_markdown(rows, n)


def write_csv(path: Path, rows: list[dict]) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
    with os.fdopen(fd, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    os.chmod(tmp, 0o644)  # mkstemp creates 0600
    os.replace(tmp, path)


def plot(path: Path, rows: list[dict], n: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = [f"{r['name']} {r['op']}" for r in rows]
    rates = [float(r["rate_M_per_s"]) for r in rows]
    colors = {"model": "tab:blue", "lookup": "tab:orange", "table-sample": "tab:green"}
    fig, ax = plt.subplots(figsize=(8, 0.28 * len(rows) + 1.5))
    y = np.arange(len(rows))
    ax.barh(y, rates, color=[colors[r["kind"]] for r in rows])
    for target in (20, 10):
        ax.axvline(target, color="gray", ls="--", lw=0.8)
        ax.text(target, -0.9, f"target {target} M/s", fontsize=7, color="gray")
    ax.set_yticks(y, labels, fontsize=7)
    ax.invert_yaxis()
    ax.set_xscale("log")
    ax.set_xlabel(f"million queries per second (batch {n:.0e}, float32, jitted)")
    ax.set_title(
        f"gonio BRDF throughput on {platform.machine()}, {os.cpu_count()} CPUs", fontsize=9
    )
    fig.tight_layout()
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".png")
    os.close(fd)
    fig.savefig(tmp, dpi=120)
    plt.close(fig)
    os.chmod(tmp, 0o644)
    os.replace(tmp, path)


def print_markdown(rows: list[dict], n: int) -> None:
    print("\n| what | operation | batch | M queries/s (float32, jitted) | target M/s | note |")
    print("|---|---|---:|---:|---:|---|")
    for r in rows:
        target = f"{r['target_M_per_s']}" if r["target_M_per_s"] else ""
        print(
            f"| {r['name']} | {r['op']} | {r['batch']:.0e} | {r['rate_M_per_s']} | {target} "
            f"| {r['note']} |"
        )


def write_tables() -> None:
    """Rewrite this benchmark's table in benchmarks/README.md from its CSV."""
    import _tables

    columns = [
        ("kind", "kind"),
        ("name", "name"),
        ("op", "op"),
        ("M/s", "rate_M_per_s"),
        ("target M/s", "target_M_per_s"),
        ("note", "note"),
    ]
    _tables.write("throughput", _tables.markdown(_tables.read("throughput.csv"), columns))


if __name__ == "__main__":
    main()
    write_tables()
