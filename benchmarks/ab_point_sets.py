"""Which 2-D point set gives the least error when BRDF-sampling the environment: a diagnostic.

A standalone Lambert estimate with the renderer's geometry, warp and environment lookup, and
nothing else: per pixel of a ``--res``² sphere, the mean of the studio environment's radiance
over ``--spp`` directions ``frame * square_to_cosine_hemisphere(u)`` (times the albedo 0.5),
i.e. what ``render_sphere(Lambert, sampler="brdf", mis=False)`` computes, with ``u`` drawn from
each point set in turn, a fresh randomization per pixel:

- ``sobol-xor``: the Sobol' (0, m, 2)-net, digitally shifted (XOR) per pixel;
- ``sobol-owen``: the same net fully Owen-scrambled per pixel (a random flip per node of each
  coordinate's binary tree, uniform below the net's resolution);
- ``jitter``: one uniform point in each cell of a k x k grid;
- ``cmj``: correlated multi-jittered points (Kensler 2013: one permutation of the sub-columns
  for all columns and one of the sub-rows for all rows, then jitter), the pattern of Mitsuba
  3's ``multijitter`` sampler;
- ``lattice``: the renderer's rank-1 lattice sequence (``gonio.brdf.sampling.points.padded_unit``,
  pair 0), rotated per pixel;
- ``random``: independent uniform points.

Relative MSE (``bench_equal_time.rel_mse``, pixels within 0.9 of the radius) against a
reference of 8192 random directions per pixel, mean over ``--seeds`` seeds. Error only.
Writes benchmarks/results/point_sets.csv and prints a Markdown table.
Run: PYTHONPATH=src python benchmarks/ab_point_sets.py [--spp 16 64]
"""

from __future__ import annotations

import argparse
import csv
import math
import os
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from bench_equal_time import disk_mask, rel_mse

RESULTS = Path(__file__).resolve().parent / "results"


def sobol_xor(rng: np.random.Generator, n_pix: int, spp: int) -> np.ndarray:
    from gonio.brdf.sampling import points

    pts = points.sobol_ints(spp, 2)
    return np.asarray(points.to_unit(jnp.asarray(pts), jnp.asarray(points.shifts(rng, n_pix, 2))))


def sobol_owen(rng: np.random.Generator, n_pix: int, spp: int) -> np.ndarray:
    from gonio.brdf.sampling import points

    m = int(math.log2(spp))
    top = (points.sobol_ints(spp, 2) >> np.uint32(32 - m)).astype(np.int64)  # (spp, 2), m bits
    out = np.empty((n_pix, spp, 2))
    for d in range(2):
        x = top[:, d]
        y = np.zeros((n_pix, spp), np.int64)
        for level in range(m):
            node = (1 << level) - 1 + (x >> (m - level))  # the node above bit `level`
            flips = rng.integers(0, 2, size=(n_pix, (1 << m) - 1))
            bit = ((x >> (m - 1 - level)) & 1)[None, :] ^ flips[:, node]
            y = (y << 1) | bit
        out[..., d] = (y + rng.random((n_pix, spp))) / spp
    return out


def jitter(rng: np.random.Generator, n_pix: int, spp: int) -> np.ndarray:
    k = math.isqrt(spp)
    i = np.arange(spp)
    cell = np.stack([i % k, i // k], -1)
    return (cell[None] + rng.random((n_pix, spp, 2))) / k


def cmj(rng: np.random.Generator, n_pix: int, spp: int) -> np.ndarray:
    k = math.isqrt(spp)
    s = np.arange(spp)
    col, row = s % k, s // k
    px = rng.permuted(np.broadcast_to(np.arange(k), (n_pix, k)), axis=1)
    py = rng.permuted(np.broadcast_to(np.arange(k), (n_pix, k)), axis=1)
    jx, jy = rng.random((n_pix, spp)), rng.random((n_pix, spp))
    x = (col[None] + (py[:, row] + jx) / k) / k
    y = (row[None] + (px[:, col] + jy) / k) / k
    return np.stack([x, y], -1)


def lattice(rng: np.random.Generator, n_pix: int, spp: int) -> np.ndarray:
    from gonio.brdf.sampling import points

    pts = jnp.asarray(points.sobol_ints(spp, 1))
    return np.asarray(points.padded_unit(pts, jnp.asarray(points.shifts(rng, n_pix, 2))))


def random(rng: np.random.Generator, n_pix: int, spp: int) -> np.ndarray:
    return rng.random((n_pix, spp, 2))


POINT_SETS = {
    "sobol-xor": sobol_xor,
    "sobol-owen": sobol_owen,
    "jitter": jitter,
    "cmj": cmj,
    "lattice": lattice,
    "random": random,
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, nargs="+", default=[16, 64], help="squares of 2^k")
    ap.add_argument("--seeds", type=int, default=4)
    args = ap.parse_args()
    for spp in args.spp:
        if spp < 4 or spp & (spp - 1) or math.isqrt(spp) ** 2 != spp:
            raise SystemExit(f"ab_point_sets: --spp must be a power of 4, got {spp}")

    from gonio.brdf.sampling import warps
    from gonio.render import Environment
    from gonio.render.lights import studio_environment
    from gonio.render.scene import intersect_sphere

    env = Environment(studio_environment())
    hits = intersect_sphere(args.res)
    n_pix = hits.count
    frame = jnp.asarray(hits.frame)
    mask = disk_mask(args.res)

    @jax.jit
    def estimate(u: jnp.ndarray) -> jnp.ndarray:  # u (P, S, 2) -> (P, 3)
        wi = warps.square_to_cosine_hemisphere(u)
        w = jnp.sum(frame[:, None, :, :] * wi[:, :, :, None], axis=-2)
        return 0.5 * jnp.mean(env.radiance(None, w), axis=1)

    ref_rng = np.random.default_rng(1000)
    ref = hits.scatter(
        np.mean(
            [np.asarray(estimate(jnp.asarray(ref_rng.random((n_pix, 256, 2)), jnp.float32)))
             for _ in range(32)],
            axis=0,
        ).astype(np.float64)
    )  # fmt: skip
    load = os.getloadavg()[0]
    rows = []
    for spp in args.spp:
        for name, make in POINT_SETS.items():
            errs = []
            for seed in range(1, args.seeds + 1):
                u = jnp.asarray(make(np.random.default_rng([seed, 7]), n_pix, spp), jnp.float32)
                img = hits.scatter(np.asarray(estimate(u), np.float64))
                errs.append(rel_mse(img, ref, mask))
            rows.append(
                {
                    "point_set": name,
                    "spp": spp,
                    "rel_mse": f"{np.mean(errs):.4g}",
                    "res": args.res,
                    "seeds": args.seeds,
                    "load_avg_1min": f"{load:.1f}",
                }
            )
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / "point_sets.csv"
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    names = list(POINT_SETS)
    print("| spp | " + " | ".join(names) + " |")
    print("|---:|" + "---:|" * len(names))
    for spp in args.spp:
        vals = {r["point_set"]: r["rel_mse"] for r in rows if r["spp"] == spp}
        print(f"| {spp} | " + " | ".join(vals[n] for n in names) + " |")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
