"""Same-run A/B of the XLA-CPU workarounds left in the table lookup and sampling kernels.

Each workaround stays only where switching it off costs more than 10 % (issue 19). The script
alternates child processes running the working tree as it is ("base") and with one workaround
switched off by patching the module-level helper before anything is traced:

``materialize-lookup``
    :func:`gonio.brdf._xla.materialize` (store an intermediate by dividing it by a runtime 1.0)
    replaced by the identity in :mod:`gonio.brdf.lookup` and :mod:`gonio.brdf.tabulated`.
``materialize-cdf``
    the same in :mod:`gonio.brdf.sampling.distributions` (the CDF binary search of inversion).
``atan2``
    the float32 polynomial :func:`gonio.brdf.lookup.atan2` replaced by ``jnp.arctan2``.
``materialize-direction``
    the same identity in :mod:`gonio.brdf.sampling.table_buckets` (the direction built in a
    sampled cell).
``cos-sin-series``
    the cell azimuth's Taylor series replaced by ``jnp.cos``/``jnp.sin``.

Every child times, on the same 1e6 random float32 queries as ``bench_throughput.py`` (its
MERL-resolution table), the jitted lookup ``f`` and sampling by inversion and alias, each the
median of ``--calls`` calls after warm-up, in millions per second; variants run in ABBA order over
``--rounds`` rounds. Writes benchmarks/results/xla_ab.csv and prints a Markdown table of the
ratio of medians (variant / base; below 1 means the workaround helps).
Run: nice python benchmarks/ab_xla.py [--rounds R] [--calls K]
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
RESULTS = HERE / "results"
OPS = ("lookup", "inversion", "alias")
VARIANTS = (
    "base",
    "materialize-lookup",
    "materialize-cdf",
    "atan2",
    "materialize-direction",
    "cos-sin-series",
)


def _switch_off(variant: str) -> None:
    import jax.numpy as jnp

    from gonio.brdf import lookup, sampling, table_buckets, tabulated

    def identity(arrays, like):
        return list(arrays)

    if variant == "materialize-lookup":
        lookup.materialize = identity
        tabulated.materialize = identity
    elif variant == "materialize-cdf":
        sampling.materialize = identity
    elif variant == "atan2":
        lookup.atan2 = jnp.arctan2
        table_buckets.atan2 = jnp.arctan2
    elif variant == "materialize-direction":
        table_buckets.materialize = identity
    elif variant == "cos-sin-series":

        def cos_sin(n_p, col, rx, dtype):
            phi = (col.astype(dtype) + rx) * (2 * jnp.pi / n_p)
            return jnp.cos(phi), jnp.sin(phi)

        table_buckets._cos_sin_in_column = cos_sin


def child(variant: str, batch: int, calls: int) -> dict[str, float]:
    """Throughput (M/s) of each operation with ``variant`` switched off."""
    import jax
    import numpy as np

    sys.path.insert(0, str(HERE))
    from bench_throughput import benchmark_table, median_time, upper_directions

    _switch_off(variant)
    table, _ = benchmark_table()
    rng = np.random.default_rng(0)
    wo = jax.device_put(upper_directions(batch, rng))
    u = jax.device_put(rng.random((batch, 2)).astype(np.float32))
    wi = jax.device_put(upper_directions(batch, rng))
    lookup = jax.jit(lambda a, b: table.f(a, b))
    fns = {
        "lookup": lambda: lookup(wi, wo),
        "inversion": lambda: table.sample(wo, u, method="inversion"),
        "alias": lambda: table.sample(wo, u, method="alias"),
    }
    rates = {}
    for op in OPS:
        jax.block_until_ready(fns[op]())  # compile and build the sampling structures
        rates[op] = batch / median_time(fns[op], calls) / 1e6
    return rates


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=2, help="ABBA alternations of the variants")
    ap.add_argument("--calls", type=int, default=5, help="timed calls per figure (median)")
    ap.add_argument("--batch", type=float, default=1e6, help="queries per call (default 1e6)")
    ap.add_argument("--only", nargs="*", help="variants to run (default: all)")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args()
    batch = int(args.batch)
    if args.child:
        print(json.dumps(child(args.child, batch, args.calls)))
        return
    variants = ("base", *args.only) if args.only else VARIANTS
    rows = []
    env = dict(
        os.environ,
        PYTHONPATH=os.pathsep.join([str(ROOT / "src"), os.environ.get("PYTHONPATH", "")]),
    )
    for r in range(args.rounds):
        for variant in variants if r % 2 == 0 else variants[::-1]:
            cmd = [sys.executable, __file__, "--child", variant, "--batch", str(batch)]
            out = subprocess.run(
                [*cmd, "--calls", str(args.calls)], env=env, capture_output=True, text=True
            )
            if out.returncode != 0:
                raise SystemExit(f"{variant} failed: {out.stderr.strip().splitlines()[-1]}")
            rates = json.loads(out.stdout.strip().splitlines()[-1])
            print(
                f"round {r + 1} {variant}: " + ", ".join(f"{k} {v:.2f}" for k, v in rates.items())
            )
            rows += [
                {"round": r + 1, "variant": variant, "op": op, "rate_M_per_s": f"{v:.3f}"}
                for op, v in rates.items()
            ]
    RESULTS.mkdir(exist_ok=True)
    with open(RESULTS / "xla_ab.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=["round", "variant", "op", "rate_M_per_s"])
        w.writeheader()
        w.writerows(rows)

    def med(variant: str, op: str) -> float:
        return statistics.median(
            float(x["rate_M_per_s"]) for x in rows if x["variant"] == variant and x["op"] == op
        )

    print(f"\n| switched off (batch {batch:.0e}) | " + " | ".join(OPS) + " |")
    print("|---" + "|---:" * len(OPS) + "|")
    print("| none (M/s) | " + " | ".join(f"{med('base', op):.2f}" for op in OPS) + " |")
    for v in variants[1:]:
        print(
            f"| {v} (ratio) | "
            + " | ".join(f"{med(v, op) / med('base', op):.2f}" for op in OPS)
            + " |"
        )


if __name__ == "__main__":
    main()
