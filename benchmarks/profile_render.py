"""Where a small render's time goes: the host's share and the pixel-tile size.

The scene of ``bench_equal_time.py`` (a 128² sphere under the studio environment alone, 16 spp)
rendered by ``render_sphere`` in one warm process:

- host share: ``cProfile`` over ``--renders`` warm Lambert renders, split into the time spent
  waiting for the kernels (``jax.block_until_ready``), tracing the primary rays
  (``intersect_sphere``, NumPy), copying to the device (``jax.device_put``) and the rest;
- tile size: the same renders of a Lambertian and a GGX conductor (alpha 0.2) with
  ``tile_samples`` of 2^17 (the default: 8192 pixels x 16 samples per kernel call, so the
  image's 12 868 sphere pixels are padded to 16 384) down to 2^14 (1024 pixels, 13 calls),
  alternated over ``--rounds`` rounds; median wall and CPU seconds;
- stages: each of a tile's three kernels (light sampling, the material, shading) timed alone
  (one tile in flight, waiting for each call), median wall seconds per call over ``--renders``
  renders, for both materials and an RGL tensor file (``--rgl``, skipped when missing).

Writes results/render_profile.csv and render_profile.png and prints a Markdown table.
Run: PYTHONPATH=src python benchmarks/profile_render.py [--rounds K] [--renders N]
"""

from __future__ import annotations

import argparse
import cProfile
import csv
import os
import pstats
import tempfile
import time
from pathlib import Path

import numpy as np

from bench_equal_time import GOLD_ETA, GOLD_K

RESULTS = Path(__file__).resolve().parent / "results"
RGL_FILE = Path(__file__).resolve().parents[1].parent / "shared/data/rgl/paper_white_rgb.bsdf"
TILE_SAMPLES = (1 << 17, 1 << 16, 1 << 15, 1 << 14)


def host_share(render, n: int) -> dict[str, float]:
    """Seconds per render: total and the parts named in the module docstring."""
    prof = cProfile.Profile()
    prof.enable()
    for seed in range(n):
        render(seed)
    prof.disable()
    stats = pstats.Stats(prof).stats  # {(file, line, name): (cc, nc, tottime, cumtime, callers)}

    def cum(name: str, file_part: str) -> float:
        return sum(v[3] for k, v in stats.items() if k[2] == name and file_part in k[0]) / n

    total = cum("render_sphere", "integrator")
    parts = {
        "waiting for kernels": cum("block_until_ready", "jax"),
        "primary rays (intersect_sphere)": cum("intersect_sphere", "scene"),
        "device_put": cum("device_put", "jax"),
    }
    parts["rest of the host"] = total - sum(parts.values())
    return {"total": total, **parts}


def stage_times(render, n: int) -> dict[str, float]:
    """Median seconds per call of each render stage, one tile at a time."""
    import jax

    from gonio.render import integrator

    names = {"light": "_light_stage_jit", "material": "_model_stage", "shading": "_shade_stage"}
    saved = {k: getattr(integrator, v) for k, v in names.items()}
    in_flight = integrator.IN_FLIGHT
    times: dict[str, list[float]] = {k: [] for k in names}

    def timed(key, fn):
        def call(*a, **kw):
            t0 = time.perf_counter()
            out = jax.block_until_ready(fn(*a, **kw))
            times[key].append(time.perf_counter() - t0)
            return out

        return call

    try:
        integrator.IN_FLIGHT = 1
        for key, attr in names.items():
            setattr(integrator, attr, timed(key, saved[key]))
        render(0)  # compiles the wrapped calls' shapes
        for v in times.values():
            v.clear()
        for seed in range(n):
            render(seed + 1)
    finally:
        integrator.IN_FLIGHT = in_flight
        for key, attr in names.items():
            setattr(integrator, attr, saved[key])
    return {k: float(np.median(v)) for k, v in times.items() if v}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=7, help="alternated rounds (default 7)")
    ap.add_argument("--renders", type=int, default=20, help="renders profiled (default 20)")
    ap.add_argument("--rgl", type=Path, default=RGL_FILE, help="RGL tensor file for the stages")
    args = ap.parse_args()

    from gonio.brdf import models
    from gonio.render import Environment, render_sphere
    from gonio.render.lights import studio_environment
    from gonio.render.output import write_exr

    env_file = write_exr(Path(tempfile.mkdtemp()) / "env.exr", studio_environment())
    env = [Environment(str(env_file))]
    gold = models.Conductor(eta=GOLD_ETA, k=GOLD_K)
    materials = {
        "Lambert": models.Lambert([0.5, 0.5, 0.5]),
        "GGX alpha 0.2": models.TorranceSparrow(
            alpha=0.2, distribution="ggx", shadowing="smith", fresnel=gold
        ),
    }
    rows: list[dict] = []
    load0 = os.getloadavg()[0]

    def render(model, seed: int, tile_samples: int = TILE_SAMPLES[0]):
        return render_sphere(model, env, resolution=128, spp=16, seed=seed,
                             tile_samples=tile_samples)  # fmt: skip

    for name, model in materials.items():
        for ts in TILE_SAMPLES:
            render(model, 0, ts)  # compile every tile shape first
        times: dict[int, list[tuple[float, float]]] = {ts: [] for ts in TILE_SAMPLES}
        for r in range(args.rounds):
            for ts in TILE_SAMPLES if r % 2 == 0 else TILE_SAMPLES[::-1]:
                t0, c0 = time.perf_counter(), time.process_time()
                render(model, r + 1, ts)
                times[ts].append((time.perf_counter() - t0, time.process_time() - c0))
        for ts, got in times.items():
            med = np.median(np.array(got), axis=0)
            rows.append({"what": f"tile of {ts // 16} pixels", "material": name,
                         "tile_samples": ts, "wall_s": med[0], "cpu_s": med[1]})  # fmt: skip
    lam = materials["Lambert"]  # compiled above
    for part, sec in host_share(lambda s: render(lam, s), args.renders).items():
        rows.append({"what": f"host share, Lambert: {part}", "material": "Lambert",
                     "tile_samples": TILE_SAMPLES[0], "wall_s": sec, "cpu_s": ""})  # fmt: skip
    stage_materials = dict(materials)
    if args.rgl is not None and args.rgl.is_file():
        from gonio.io.rgl_measured import load_rgl

        stage_materials[f"RGL {args.rgl.stem}"] = load_rgl(args.rgl)
    for name, model in stage_materials.items():
        for stage, sec in stage_times(lambda s, m=model: render(m, s), args.renders).items():
            rows.append({"what": f"stage per tile: {stage}", "material": name,
                         "tile_samples": TILE_SAMPLES[0], "wall_s": sec, "cpu_s": ""})  # fmt: skip
    for r in rows:
        r["load_avg_1min"] = f"{load0:.1f} -> {os.getloadavg()[0]:.1f}"

    RESULTS.mkdir(exist_ok=True)
    with open(RESULTS / "render_profile.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print("| what | material | wall (ms) | CPU (ms) |\n|---|---|---:|---:|")
    for r in rows:
        cpu = f"{1e3 * r['cpu_s']:.1f}" if r["cpu_s"] != "" else ""
        print(f"| {r['what']} | {r['material']} | {1e3 * r['wall_s']:.1f} | {cpu} |")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3))
    for name in materials:
        sel = [r for r in rows if r["material"] == name and r["what"].startswith("tile")]
        ax.plot([r["tile_samples"] // 16 for r in sel], [1e3 * r["wall_s"] for r in sel], "o-",
                label=f"{name}, wall")  # fmt: skip
        ax.plot([r["tile_samples"] // 16 for r in sel], [1e3 * r["cpu_s"] for r in sel], "s--",
                label=f"{name}, CPU")  # fmt: skip
    ax.set_xscale("log", base=2)
    ax.set_xlabel("pixels per kernel call (16 samples each)")
    ax.set_ylabel("ms per 128² render, 16 spp")
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=7)
    ax.set_title(f"render time against tile size, load {load0:.1f}", fontsize=9)
    fig.tight_layout()
    fig.savefig(RESULTS / "render_profile.png", dpi=110)


if __name__ == "__main__":
    main()
