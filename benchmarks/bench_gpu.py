"""Kernel and render throughput on whatever JAX device is present (GPU when there is one).

Runs on JAX's default device — CPU here, CUDA or ROCm wherever ``jax[cuda]`` finds a GPU — so
that the same script gives the device figures as soon as such a machine is available:

- analytic kernels: ``f``, ``pdf`` and ``sample`` of the ``bench_mitsuba.py`` models (Lambert,
  Torrance-Sparrow Beckmann/GGX with Smith and conductor or dielectric Fresnel; RGB) at
  ``--batch`` float32 queries;
- renders: ``render_sphere`` of a Lambertian and a GGX conductor sphere under the studio
  environment (``--res``², ``--spp``), and under two directional lights, and of a MERL-grid
  table of a glossy model sampled by inversion and by exact rejection under the studio; the
  figure is the best of ``--repeats`` calls after the first (which compiles and builds the
  table's sampling structures), in million samples per second (pixels hit x spp; one sample
  per pixel and light for delta lights);
- recompiles: XLA compilations (counted over all of JAX; the ``count`` column) of renders
  with other spp, image sizes and light counts, after one render of each scene kind and of
  three image sizes (0 expected, except for image sizes that need a pixel tile size not
  compiled yet: :func:`gonio.render.tiling.sample_tile` has at most 17, and the row of such
  sizes counts their compilations).

Every kernel of these renders is traced, tables included (their sampling structures are built
once per render for the outgoing directions of the image and passed as kernel arguments), and
no kernel call waits on a copy to the host. What is left on the host per render: the sphere's
geometry (NumPy), uploaded per tile by ``device_put`` (asynchronous), one copy of the bucket
flags of a table and the building of new buckets, one copy of the image at the end; the driver
waits, without a copy, on the call dispatched a few calls earlier (``integrator.IN_FLIGHT``)
to bound the memory queued calls hold.

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
from gonio.brdf.tabulated import TabulatedBRDF
from gonio.render import Directional, Environment, RenderStats, SphereLight, render_sphere

RESULTS = Path(__file__).resolve().parent / "results"


def timed(fn, repeats: int) -> float:
    jax.block_until_ready(fn())
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts)


def count_compiles(fn) -> int:
    """XLA compilations during ``fn()``."""
    n = [0]

    def listener(event, duration, **kw):
        n[0] += event == "/jax/core/compile/backend_compile_duration"

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        fn()
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
    return n[0]


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
    table = TabulatedBRDF.merl_like(
        models.Lambert([0.1, 0.08, 0.05])
        + models.TorranceSparrow(alpha=0.2, distribution="beckmann", fresnel=gold)
    )
    cases = [(m, mat, s, "auto") for m, mat in materials.items() for s in scenes]
    cases += [
        ("MERL-grid table", table, "studio environment", m) for m in ("inversion", "rejection")
    ]
    for mname, mat, sname, sampler in cases:
        lights, spp = scenes[sname]
        stats = RenderStats()

        def go(mat=mat, lights=lights, spp=spp, stats=stats, sampler=sampler):
            return render_sphere(
                mat, lights, resolution=args.res, spp=spp, sampler=sampler, stats=stats
            )

        go()  # compile (and build a table's sampling structures)
        ts = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            go()
            ts.append(time.perf_counter() - t0)
        sec = min(ts)
        samples = stats.pixels * spp * (len(lights) if spp == 1 else 1)
        what = f"{mname} ({sampler}), {sname}" if sampler != "auto" else f"{mname}, {sname}"
        rows.append(("render", what, f"{args.res}² {spp} spp", samples, sec, samples / sec / 1e6))
        print(f"render {what}: {sec:.3f} s, {samples / sec / 1e6:.2f} M samples/s", flush=True)

    # Recompiles: after one render of each scene kind and of three image sizes (their pixel tiles
    # of 1536 and 8192 pixels), renders with other spp, image sizes and light counts. Image
    # sizes whose tiles were compiled reuse them; sizes that need a new tile size (120²: 2 x
    # 6144, 230²: 6 x 7168) compile it, once.
    env = scenes["studio environment"][0]
    suns = [Directional.from_angles(0.2 * k, 0.7 * k, 1.0) for k in range(1, 6)]
    balls = [SphereLight((3.0 * np.cos(a), 3.0 * np.sin(a), 2.0), 0.5, 3.0) for a in (0, 1, 2)]
    for mat, sampler in ((materials["TS GGX Smith conductor"], "auto"), (table, "inversion")):
        for r in (40, 100, 200):
            render_sphere(mat, env, resolution=r, spp=8, sampler=sampler)
        render_sphere(mat, env + balls[:1], resolution=args.res, spp=4, sampler=sampler)
        render_sphere(mat, suns[:1], resolution=args.res, spp=1)
        variants = {
            "spp (3, 17, 40)": lambda m=mat, s=sampler: [
                render_sphere(m, env, resolution=args.res, spp=k, sampler=s) for k in (3, 17, 40)
            ],
            "image sizes of compiled tiles (44, 102, 202)": lambda m=mat, s=sampler: [
                render_sphere(m, env, resolution=r, spp=8, sampler=s) for r in (44, 102, 202)
            ],
            "image sizes of two new tile sizes (120, 230)": lambda m=mat, s=sampler: [
                render_sphere(m, env, resolution=r, spp=8, sampler=s) for r in (120, 230)
            ],
            "delta light counts (2, 3, 5)": lambda m=mat: [
                render_sphere(m, suns[:k], resolution=args.res, spp=1) for k in (2, 3, 5)
            ],
            "sphere light counts (2, 3, 3) and spp": lambda m=mat, s=sampler: [
                render_sphere(m, env + balls[:k], resolution=args.res, spp=q, sampler=s)
                for k, q in ((2, 8), (3, 4), (3, 21))
            ],
        }
        name = "MERL-grid table (inversion)" if mat is table else "TS GGX Smith conductor"
        for label, fn in variants.items():
            n = count_compiles(fn)
            rows.append(("recompiles", name, f"renders with other {label}", n, None, None))
            print(f"recompiles {name}, other {label}: {n}", flush=True)

    load = os.getloadavg()[0]
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / f"gpu_{platform}.csv"
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["kind", "what", "op", "count", "seconds", "M_per_s", "device", "load_avg"])
        for r in rows:
            rate = ["", ""] if r[4] is None else [f"{r[4]:.4f}", f"{r[5]:.3g}"]
            w.writerow([*r[:4], *rate, dev.device_kind, f"{load:.1f}"])
    rows = [r for r in rows if r[0] != "recompiles"]  # counts, not rates: table only

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
    with open(path) as fh:
        for rec in csv.DictReader(fh):
            if rec["kind"] == "recompiles":
                print(f"recompiles, {rec['what']}, {rec['op']}: {rec['count']} compilations")


def write_tables() -> None:
    """Rewrite this benchmark's table in benchmarks/README.md from its CSV (this machine: CPU)."""
    import _tables

    columns = [
        ("kind", "kind"),
        ("what", "what"),
        ("op", "op"),
        ("count", "count"),
        ("seconds", "seconds"),
        ("M/s", "M_per_s"),
        ("device", "device"),
    ]
    _tables.write("gpu", _tables.markdown(_tables.read("gpu_cpu.csv"), columns))


if __name__ == "__main__":
    main()
    write_tables()
