"""Pixel tiles of the sampled-light kernels: equal tiles against powers of 4, same run.

The scene of ``bench_equal_time.py`` (the unit sphere under the studio environment alone, 16
spp) at several resolutions, rendered by ``render_sphere`` in one warm process with the pixels
cut into tiles by each rule:

- ``equal``: :func:`gonio.render.tiling.sample_tile` (the renderer's rule): the fewest tiles of
  at most 8192 pixels, of equal size rounded up to a multiple of 512;
- ``powers of 4``: :func:`gonio.render.tiling.pixel_tile` (the rule before, still the delta
  lights'): 256 times a power of 4, at most 8192, every tile that size.

Padding pixels cost what real ones do, so the figure of merit is the wall time of a warm render;
the padded fraction of each rule is in the CSV. The rules alternate within each round (order
flipped every round); per round the fastest of ``--repeats`` renders; the table gives medians
over ``--rounds`` rounds and the ratio equal / powers of 4 (< 1: the equal tiles are faster).
The images are the same bit for bit (``max_abs_image_diff``: the tiles only group the pixels
differently; every pixel keeps its own samples).

Writes results/tiles.csv and tiles.png and prints a Markdown table.
Run: PYTHONPATH=src python benchmarks/bench_tiles.py [--rounds K] [--res 64 128 256 512]
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from bench_equal_time import GOLD_ETA, GOLD_K

RESULTS = Path(__file__).resolve().parent / "results"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--res", type=int, nargs="+", default=[64, 128, 256, 512])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--repeats", type=int, default=5, help="renders per rule and round (fastest)")
    args = ap.parse_args()

    from gonio.brdf import models
    from gonio.render import Environment, integrator, render_sphere, tiling
    from gonio.render.lights import studio_environment
    from gonio.render.output import write_exr
    from gonio.render.scene import intersect_sphere

    env = [Environment(str(write_exr(Path(tempfile.mkdtemp()) / "env.exr", studio_environment())))]
    materials = {
        "Lambert": models.Lambert([0.5, 0.5, 0.5]),
        "GGX alpha 0.2": models.TorranceSparrow(
            alpha=0.2,
            distribution="ggx",
            shadowing="smith",
            fresnel=models.Conductor(eta=GOLD_ETA, k=GOLD_K),
        ),
    }
    rules = {"equal": tiling.sample_tile, "powers of 4": tiling.pixel_tile}
    cap = integrator.DEFAULT_TILE_SAMPLES // integrator.SAMPLE_BATCH
    load0 = os.getloadavg()[0]
    rows = []
    try:
        for res in args.res:
            n = intersect_sphere(res, None).count
            for name, model in materials.items():
                times: dict[str, list[float]] = {k: [] for k in rules}
                images = {}
                for rule, fn in rules.items():  # compile each rule's tile shape
                    integrator.sample_tile = fn
                    images[rule] = render_sphere(model, env, resolution=res, spp=16, seed=1)
                for r in range(args.rounds):
                    for rule in list(rules) if r % 2 == 0 else list(rules)[::-1]:
                        integrator.sample_tile = rules[rule]
                        best = math.inf
                        for k in range(args.repeats):
                            t0 = time.perf_counter()
                            render_sphere(model, env, resolution=res, spp=16, seed=2 + k)
                            best = min(best, time.perf_counter() - t0)
                        times[rule].append(best)
                diff = float(np.max(np.abs(images["equal"] - images["powers of 4"])))
                for rule, fn in rules.items():
                    tile = fn(n, cap)
                    padded = tile * math.ceil(n / tile)
                    rows.append({
                        "res": res, "pixels": n, "material": name, "rule": rule,
                        "tile_pixels": tile, "padded_fraction": round(1 - n / padded, 4),
                        "wall_s": statistics.median(times[rule]),
                        "ratio_equal_over_powers": statistics.median(
                            a / b for a, b in zip(times["equal"], times["powers of 4"],
                                                  strict=True)),
                        "max_abs_image_diff": diff,
                    })  # fmt: skip
    finally:
        integrator.sample_tile = tiling.sample_tile
    for r in rows:
        r["load_avg_1min"] = f"{load0:.1f} -> {os.getloadavg()[0]:.1f}"

    RESULTS.mkdir(exist_ok=True)
    with open(RESULTS / "tiles.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print("| resolution | material | tile, equal / powers of 4 | padded, equal / powers of 4 "
          "| wall ms, equal / powers of 4 | ratio |\n|---|---|---|---|---|---:|")  # fmt: skip
    for eq, p4 in zip(rows[::2], rows[1::2], strict=True):
        print(f"| {eq['res']}² | {eq['material']} | {eq['tile_pixels']} / {p4['tile_pixels']} "
              f"| {100 * eq['padded_fraction']:.0f} % / {100 * p4['padded_fraction']:.0f} % "
              f"| {1e3 * eq['wall_s']:.1f} / {1e3 * p4['wall_s']:.1f} "
              f"| {eq['ratio_equal_over_powers']:.2f} |")  # fmt: skip

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3))
    for name in materials:
        sel = [r for r in rows if r["material"] == name and r["rule"] == "equal"]
        ax.plot([r["res"] for r in sel], [r["ratio_equal_over_powers"] for r in sel], "o-",
                label=name)  # fmt: skip
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_xscale("log", base=2)
    ax.set_xlabel("image resolution (pixels per side), 16 spp")
    ax.set_ylabel("render time, equal / powers of 4")
    ax.legend(fontsize=7)
    ax.set_title(f"equal pixel tiles against powers of 4, load {load0:.1f}", fontsize=9)
    fig.tight_layout()
    fig.savefig(RESULTS / "tiles.png", dpi=110)


if __name__ == "__main__":
    main()
