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
``no-dot``
    :func:`gonio.brdf.models._base.channels_last` as a plain transpose (``moveaxis``), which
    XLA fuses with the channels-first Fresnel into one loop over the ``(n, C)`` output, as the
    channels-last code did.

A second table (``--layout``, ``kernels_layout.csv``) times the layout alone on one cheap
per-lane value ``v = x / y`` scaled by 3 channel constants, at ``--batch`` lanes: the
``(n, 3)`` output the public API returns, computed in place (a loop with the channel axis
innermost) or as ``(3, n)`` moved by the identity product, against the ``(3, n)`` and three
``(n,)`` arrays (Mitsuba's structure-of-arrays layout) that need no move.

Each figure is the best of ``--calls`` calls at ``--batch`` float32 queries (the order of the
variants rotating from call to call), in M/s; the table
gives each variant's throughput over the base (below 1: the workaround helps). Writes
benchmarks/results/kernels_ab.csv. Run: python benchmarks/ab_kernels.py [--calls K] [--only TEXT]
[--layout]
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_mitsuba import pairs, upper  # noqa: E402
from gonio.brdf.models import BRDFModel, TorranceSparrow, _base  # noqa: E402
from gonio.brdf.models import torrance_sparrow as _ts  # noqa: E402

VARIANTS = ("base", "no-barrier", "mixture", "generic-weight", "no-dot")
OPS = ("f", "pdf", "sample")


def _patched(variant: str) -> list[tuple[object, str, object]]:
    """(owner, attribute, replacement) triples that switch ``variant`` off."""
    if variant == "no-barrier":
        return [(jax.lax, "optimization_barrier", lambda x: x)]
    if variant == "mixture":
        return [(TorranceSparrow, "_diffuse_free", lambda self: False)]
    if variant == "generic-weight":
        return [(TorranceSparrow, "_finish", BRDFModel._finish)]
    if variant == "no-dot":

        def move(x):
            return jnp.moveaxis(x, 0, -1)

        return [(_base, "channels_last", move), (_ts, "channels_last", move)]
    return []


def layout(args) -> None:
    """Time the output layouts alone (module docstring) and write kernels_layout.csv."""
    n = args.batch
    x = jax.device_put(np.random.default_rng(1).random(n).astype(np.float32))
    y = x + 1.0
    a = jnp.array([0.5, 0.4, 0.3], jnp.float32)

    def cf(x, y):
        return jnp.where((x > 0.1)[None], a[:, None] * (x / y)[None], 0.0)

    fns = {
        "(n, 3) in place": lambda x, y: jnp.where(
            (x > 0.1)[:, None], a[None, :] * (x / y)[:, None], 0.0
        ),
        "(3, n) moved by the identity": lambda x, y: _base.channels_last(cf(x, y)),
        "(3, n)": cf,
        "3 x (n,)": lambda x, y: tuple(jnp.where(x > 0.1, a[i] * (x / y), 0.0) for i in range(3)),
        "1 x (n,)": lambda x, y: jnp.where(x > 0.1, x / y, 0.0),
    }
    fns = {k: jax.jit(f) for k, f in fns.items()}
    best = dict.fromkeys(fns, float("inf"))
    for f in fns.values():
        jax.block_until_ready(f(x, y))
    order = list(fns.items())
    for i in range(args.calls):
        for k, f in order[i % len(order) :] + order[: i % len(order)]:
            t0 = time.perf_counter()
            jax.block_until_ready(f(x, y))
            best[k] = min(best[k], time.perf_counter() - t0)
    print("| output layout | ms per call | M lanes/s |")
    print("|---|---:|---:|")
    rows = []
    for k, t in best.items():
        print(f"| {k} | {t * 1e3:.2f} | {n / t / 1e6:.0f} |")
        rows.append({"layout": k, "batch": n, "ms_per_call": f"{t * 1e3:.3f}",
                     "load_avg_1min": f"{os.getloadavg()[0]:.1f}"})  # fmt: skip
    with open(HERE / "results" / "kernels_layout.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


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
    ap.add_argument("--layout", action="store_true", help="the layout table only")
    ap.add_argument("--only", default="", help="pairs whose label contains this text")
    args = ap.parse_args()
    (HERE / "results").mkdir(exist_ok=True)
    if args.layout:
        layout(args)
        return
    rng = np.random.default_rng(0)
    n = args.batch
    wi, wo = jax.device_put(upper(n, rng)), jax.device_put(upper(n, rng))
    u = jax.device_put(rng.random((n, 2)).astype(np.float32))
    rows = []
    print("| model | op | base M/s | " + " | ".join(VARIANTS[1:]) + " |")
    print("|---|---|---:" + "|---:" * (len(VARIANTS) - 1) + "|")
    for label, model, _ in pairs():
        if args.only not in label:
            continue
        for op in OPS:
            a = (wo, u) if op == "sample" else (wi, wo)
            fns = {v: build(v, model, op, a) for v in VARIANTS}
            best = dict.fromkeys(VARIANTS, float("inf"))
            order = list(fns.items())
            for i in range(args.calls):
                # the order rotates from call to call: the variant timed last read up to 1.7x
                # faster than the same code timed first (no-dot on the dielectric pair)
                for v, fn in order[i % len(order) :] + order[: i % len(order)]:
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
    with open(HERE / "results" / "kernels_ab.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


if __name__ == "__main__":
    main()
