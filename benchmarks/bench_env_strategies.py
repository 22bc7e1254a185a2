"""Error per sampling strategy under the environment alone, gonio against Mitsuba 3's ``direct``.

The scene of ``bench_equal_time.py`` (unit sphere seen orthographically, the studio environment
only, Lambert albedo 0.5 or a GGX gold conductor at alpha 0.2) at ``--res``² pixels. Each
strategy is scored against its renderer's own converged image (``--ref-spp``) by relative MSE
over the pixels inside 0.9 of the radius, averaged over ``--seeds`` seeds:

- ``mis``: environment and BRDF samples with MIS (gonio's default; Mitsuba's ``direct`` with one
  emitter and one BSDF sample), at ``--spp`` and at 4 x ``--spp``;
- ``mis-independent``: Mitsuba with its unstratified ``independent`` sampler (how much the
  stratification is worth);
- ``light``: environment samples alone (gonio ``sampler="light"``; Mitsuba ``bsdf_samples=0``);
- ``brdf``: BRDF samples alone, no MIS (gonio ``sampler="brdf", mis=False``;
  Mitsuba ``emitter_samples=0``), at ``--spp`` and at 4 x ``--spp``;
- ``brdf-independent``: the same in Mitsuba with the ``independent`` sampler (its error with no
  stratification, the cost of random points).

Error only, no timing (``bench_equal_time.py`` times the renders). To compare gonio's code with
an older revision, run this script with ``PYTHONPATH`` at that revision's ``src/`` and
``--out`` another name.

Writes benchmarks/results/OUT.csv (default ``env_strategies``) and prints a Markdown table.
Run: PYTHONPATH=src python benchmarks/bench_env_strategies.py [--res 64 --spp 16 --seeds 4]
"""

from __future__ import annotations

import argparse
import csv
import os
import tempfile
from pathlib import Path

import numpy as np

from bench_equal_time import GOLD_ETA, GOLD_K, disk_mask, rel_mse

RESULTS = Path(__file__).resolve().parent / "results"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--ref-spp", type=int, default=2048)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--variant", default="llvm_ad_rgb")
    ap.add_argument("--out", default="env_strategies", help="CSV name under benchmarks/results")
    args = ap.parse_args()

    import mitsuba as mi

    import gonio
    from gonio.brdf import models
    from gonio.render import Environment, render_sphere
    from gonio.render.lights import studio_environment
    from gonio.render.output import write_exr

    mi.set_variant(args.variant)
    res = args.res
    tmp = Path(tempfile.mkdtemp())
    env_file = write_exr(tmp / "env.exr", studio_environment())
    env = [Environment(str(env_file))]
    mask = disk_mask(res)
    gold = models.Conductor(eta=GOLD_ETA, k=GOLD_K)
    rgb = {"type": "rgb"}
    cases = {
        "lambert": (
            models.Lambert([0.5] * 3),
            {"type": "diffuse", "reflectance": {**rgb, "value": 0.5}},
        ),
        "ggx-0.2": (
            models.TorranceSparrow(alpha=0.2, distribution="ggx", shadowing="smith", fresnel=gold),
            {
                "type": "roughconductor",
                "distribution": "ggx",
                "alpha": 0.2,
                "eta": {**rgb, "value": GOLD_ETA},
                "k": {**rgb, "value": GOLD_K},
            },
        ),
    }

    def scene(bsdf: dict, emitter: int, brdf: int, sampler: str = "multijitter"):
        view = mi.ScalarTransform4f.look_at(origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0])
        return mi.load_dict(
            {
                "type": "scene",
                "integrator": {"type": "direct", "emitter_samples": emitter, "bsdf_samples": brdf},
                "sensor": {
                    "type": "orthographic",
                    "to_world": view,
                    "film": {
                        "type": "hdrfilm",
                        "width": res,
                        "height": res,
                        "rfilter": {"type": "box"},
                    },
                    "sampler": {"type": sampler},
                },
                "sphere": {"type": "sphere", "bsdf": bsdf},
                "env": {
                    "type": "envmap",
                    "filename": str(env_file),
                    "to_world": mi.ScalarTransform4f.rotate([0, 1, 0], 180.0),
                },
            }
        )

    def mitsuba_mse(sc, ref: np.ndarray, spp: int) -> float:
        seeds = range(1, args.seeds + 1)
        return float(
            np.mean(
                [
                    rel_mse(np.asarray(mi.render(sc, spp=spp, seed=s))[..., :3], ref, mask)
                    for s in seeds
                ]
            )
        )

    def gonio_mse(model, ref: np.ndarray, spp: int, **kw) -> float:
        seeds = range(1, args.seeds + 1)
        imgs = (render_sphere(model, env, resolution=res, spp=spp, seed=s, **kw) for s in seeds)
        return float(np.mean([rel_mse(img, ref, mask) for img in imgs]))

    load = os.getloadavg()[0]
    rows = []
    for name, (model, bsdf) in cases.items():
        gref = render_sphere(model, env, resolution=res, spp=args.ref_spp, seed=1000)
        mref = np.asarray(mi.render(scene(bsdf, 1, 1), spp=args.ref_spp, seed=1000))[..., :3]
        mis = scene(bsdf, 1, 1)
        n = args.spp
        strategies = [
            ("mis", n, gonio_mse(model, gref, n), mitsuba_mse(mis, mref, n)),
            ("mis", 4 * n, gonio_mse(model, gref, 4 * n), mitsuba_mse(mis, mref, 4 * n)),
            ("mis-independent", n, None, mitsuba_mse(scene(bsdf, 1, 1, "independent"), mref, n)),
            (
                "light",
                n,
                gonio_mse(model, gref, n, sampler="light"),
                mitsuba_mse(scene(bsdf, 1, 0), mref, n),
            ),
            (
                "brdf",
                n,
                gonio_mse(model, gref, n, sampler="brdf", mis=False),
                mitsuba_mse(scene(bsdf, 0, 1), mref, n),
            ),
            (
                "brdf",
                4 * n,
                gonio_mse(model, gref, 4 * n, sampler="brdf", mis=False),
                mitsuba_mse(scene(bsdf, 0, 1), mref, 4 * n),
            ),
            ("brdf-independent", n, None, mitsuba_mse(scene(bsdf, 0, 1, "independent"), mref, n)),
        ]
        for strategy, spp, g, m in strategies:
            rows.append(
                {
                    "material": name,
                    "strategy": strategy,
                    "spp": spp,
                    "gonio_rel_mse": "" if g is None else f"{g:.6g}",
                    "mitsuba_rel_mse": f"{m:.6g}",
                    "res": res,
                    "seeds": args.seeds,
                    "ref_spp": args.ref_spp,
                    "gonio_version": gonio.__version__,
                    "gonio_src": str(Path(gonio.__file__).resolve().parents[1]),
                    "load_avg_1min": f"{load:.1f}",
                }
            )
    RESULTS.mkdir(exist_ok=True)
    out = RESULTS / f"{args.out}.csv"
    with out.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print("| material | strategy | spp | gonio rel. MSE | Mitsuba rel. MSE |")
    print("|---|---|---:|---:|---:|")
    for r in rows:
        print(
            f"| {r['material']} | {r['strategy']} | {r['spp']} | {r['gonio_rel_mse'] or '—'} |"
            f" {r['mitsuba_rel_mse']} |"
        )
    print(f"wrote {out}")


def write_tables() -> None:
    """Rewrite this benchmark's table in benchmarks/README.md from its CSV."""
    import _tables

    columns = [
        ("material", "material"),
        ("strategy", "strategy"),
        ("spp", "spp"),
        ("gonio rel. MSE", "gonio_rel_mse"),
        ("Mitsuba rel. MSE", "mitsuba_rel_mse"),
    ]
    rows = _tables.read("env_strategies.csv")
    _tables.write("env_strategies", _tables.markdown(rows, columns))


if __name__ == "__main__":
    main()
    write_tables()
