"""Kernel and render throughput on whatever JAX device is present (GPU when there is one).

Runs on JAX's default device — CPU here, CUDA or ROCm wherever ``jax[cuda]`` finds a GPU — so
that the same script gives the device figures as soon as such a machine is available:

- analytic kernels: ``f``, ``pdf`` and ``sample`` of the ``bench_mitsuba.py`` models (Lambert,
  Torrance-Sparrow Beckmann/GGX with Smith and conductor or dielectric Fresnel; RGB) at
  ``--batch`` float32 queries;
- renders: ``render_sphere`` of a Lambertian and a GGX conductor sphere under the studio
  environment (``--res``², ``--spp``), and under two directional lights; the figure is the
  second call (the first compiles), in million samples per second (pixels hit x spp; one
  sample per pixel and light for delta lights).

Known host round trips that bound the render figures on a GPU (not on a CPU): the renderer
uploads every tile's geometry from NumPy (its sample points once per render; tile sums stay on
the device and come back in one transfer at the end, ``integrator._render_area``, which waits
without a copy on the call dispatched a few calls earlier); tabulated BRDFs sampled by their own
methods run outside ``jit`` and build per-bucket structures on the host. Analytic
models, as here, are traced into the render kernels.

Writes benchmarks/results/gpu_<platform>.csv and .png and prints a Markdown table.
Run: PYTHONPATH=src python benchmarks/bench_gpu.py [--quick]
"""

from __future__ import annotations

import argparse
import csv
import os
import statistics
import sys
import time
from pathlib import Path

import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_mitsuba import pairs, upper
from gonio.brdf import models
from gonio.render import Directional, Environment, RenderStats, render_sphere

RESULTS = Path(__file__).resolve().parent / "results"


def timed(fn, repeats: int) -> float:
    jax.block_until_ready(fn())
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--batch", type=int, default=1_000_000)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--res", type=int, default=256)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--quick", action="store_true", help="batch 1e5, 2 repeats, 64² at 16 spp")
    args = ap.parse_args()
    if args.quick:
        args.batch, args.repeats, args.res, args.spp = 100_000, 2, 64, 16
    dev = jax.devices()[0]
    platform = dev.platform
    print(f"device: {dev.device_kind} ({platform}), {jax.device_count()} device(s)", flush=True)

    rng = np.random.default_rng(0)
    n = args.batch
    wi, wo = (jax.device_put(upper(n, rng)) for _ in range(2))
    u = jax.device_put(rng.random((n, 2)).astype(np.float32))
    rows = []
    for label, model, _ in pairs():
        name = label.split(" /")[0]
        ops = {
            "f": (jax.jit(lambda a, b, m=model: m.f(a, b)), (wi, wo)),
            "pdf": (jax.jit(lambda a, b, m=model: m.pdf(a, b)), (wi, wo)),
            "sample": (jax.jit(lambda a, b, m=model: m.sample(a, b)), (wo, u)),
        }
        for op, (fn, a) in ops.items():
            sec = timed(lambda fn=fn, a=a: fn(*a), args.repeats)
            rows.append(("kernel", name, op, n, sec, n / sec / 1e6))
            print(f"kernel {name:40s} {op:7s} {n / sec / 1e6:9.2f} M/s", flush=True)

    gold = models.Conductor(eta=[0.143, 0.374, 1.442], k=[3.983, 2.385, 1.603])
    materials = {
        "Lambert": models.Lambert([0.5, 0.4, 0.3]),
        "TS GGX Smith conductor": models.TorranceSparrow(
            alpha=0.2, distribution="ggx", shadowing="smith", fresnel=gold
        ),
    }
    scenes = {
        "studio environment": ([Environment("studio")], args.spp),
        "2 directional lights": (
            [Directional.from_angles(0.5, 0.3, 1.0), Directional.from_angles(1.0, 2.0, 0.5)],
            1,
        ),
    }
    for mname, mat in materials.items():
        for sname, (lights, spp) in scenes.items():
            stats = RenderStats()

            def go(mat=mat, lights=lights, spp=spp, stats=stats):
                return render_sphere(mat, lights, resolution=args.res, spp=spp, stats=stats)

            go()  # compile
            t0 = time.perf_counter()
            go()
            sec = time.perf_counter() - t0
            samples = stats.pixels * spp * (len(lights) if spp == 1 else 1)
            rows.append(("render", f"{mname}, {sname}", f"{args.res}² {spp} spp", samples, sec,
                         samples / sec / 1e6))  # fmt: skip
            print(f"render {mname}, {sname}: {sec:.3f} s, {samples / sec / 1e6:.2f} M samples/s")

    load = os.getloadavg()[0]
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / f"gpu_{platform}.csv"
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["kind", "what", "op", "count", "seconds", "M_per_s", "device", "load_avg"])
        for r in rows:
            w.writerow([*r[:4], f"{r[4]:.4f}", f"{r[5]:.3g}", dev.device_kind, f"{load:.1f}"])

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 0.28 * len(rows) + 1.4))
    y = np.arange(len(rows))
    ax.barh(y, [r[5] for r in rows], color=["C0" if r[0] == "kernel" else "C2" for r in rows])
    ax.set_yticks(y, [f"{r[1]}: {r[2]}" for r in rows], fontsize=7)
    ax.invert_yaxis()
    ax.set_xscale("log")
    ax.set_xlabel("million queries (kernels) or samples (renders) per second")
    ax.set_title(f"{dev.device_kind} ({platform}), load average {load:.1f}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path.with_suffix(".png"), dpi=120)

    print(f"\n{dev.device_kind} ({platform}), load average {load:.1f}\n")
    print("| kind | what | op | M/s |")
    print("|---|---|---|---:|")
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]} | {r[5]:.3g} |")


if __name__ == "__main__":
    main()
