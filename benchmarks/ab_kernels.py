"""Same-run A/B of the XLA:CPU workarounds in the analytic kernels of ``bench_mitsuba.py``.

Variants, each switched off while its functions are traced (one process, so that every call of
every variant runs under the same load; calls alternate between variants):

``no-barrier``
    ``jax.lax.optimization_barrier`` replaced by the identity: the stored per-lane values of
    Torrance-Sparrow's ``f`` (``D G``, ``wi.h``), the sampled directions of ``sample`` and the
    unnormalized GGX visible normal.
``mixture``
    Torrance-Sparrow with ``rho_d = 0`` sampled through the two-lobe mixture, as if ``rho_d``
    were traced (and so with the generic sample weight too).
``generic-weight``
    Torrance-Sparrow's ``D``-free sample weight replaced by the generic ``f cos / pdf``.

Each figure is the best of ``--calls`` calls at ``--batch`` float32 queries, in M/s; the table
gives each variant's throughput over the base (below 1: the workaround helps). Writes
benchmarks/results/kernels_ab.csv. Run: nice python benchmarks/ab_kernels.py [--calls K]
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path

import jax
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_mitsuba import pairs, upper  # noqa: E402
from gonio.brdf.models import BRDFModel, TorranceSparrow  # noqa: E402

VARIANTS = ("base", "no-barrier", "mixture", "generic-weight")
OPS = ("f", "pdf", "sample")


def _patched(variant: str) -> list[tuple[object, str, object]]:
    """(owner, attribute, replacement) triples that switch ``variant`` off."""
    if variant == "no-barrier":
        return [(jax.lax, "optimization_barrier", lambda x: x)]
    if variant == "mixture":
        return [(TorranceSparrow, "_diffuse_free", lambda self: False)]
    if variant == "generic-weight":
        return [(TorranceSparrow, "_finish", BRDFModel._finish)]
    return []


def build(variant: str, model, op: str, args) -> object:
    """The jitted ``op`` of ``model``, traced and compiled with ``variant`` switched off."""
    saved = []
    for owner, name, value in _patched(variant):
        saved.append((owner, name, getattr(owner, name)))
        setattr(owner, name, value)
    try:
        fn = jax.jit(lambda a, b: getattr(model, op)(a, b))  # a fresh function: no trace cache
        jax.block_until_ready(fn(*args))
    finally:
        for owner, name, value in saved:
            setattr(owner, name, value)
    return fn


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--batch", type=int, default=1_000_000)
    ap.add_argument("--calls", type=int, default=7)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    n = args.batch
    wi, wo = jax.device_put(upper(n, rng)), jax.device_put(upper(n, rng))
    u = jax.device_put(rng.random((n, 2)).astype(np.float32))
    rows = []
    print("| model | op | base M/s | " + " | ".join(VARIANTS[1:]) + " |")
    print("|---|---|---:" + "|---:" * (len(VARIANTS) - 1) + "|")
    for label, model, _ in pairs():
        for op in OPS:
            a = (wo, u) if op == "sample" else (wi, wo)
            fns = {v: build(v, model, op, a) for v in VARIANTS}
            best = dict.fromkeys(VARIANTS, float("inf"))
            for _ in range(args.calls):
                for v, fn in fns.items():
                    t0 = time.perf_counter()
                    jax.block_until_ready(fn(*a))
                    best[v] = min(best[v], time.perf_counter() - t0)
            rate = {v: n / best[v] / 1e6 for v in VARIANTS}
            rows += [
                {"pair": label, "op": op, "variant": v, "rate_M_per_s": f"{rate[v]:.3f}"}
                for v in VARIANTS
            ]
            ratios = " | ".join(f"{rate[v] / rate['base']:.2f}" for v in VARIANTS[1:])
            print(f"| {label} | {op} | {rate['base']:.3g} | {ratios} |", flush=True)
    (HERE / "results").mkdir(exist_ok=True)
    with open(HERE / "results" / "kernels_ab.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


if __name__ == "__main__":
    main()
