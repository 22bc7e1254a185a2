"""Equal-time error under an environment alone: gonio's integrator against Mitsuba 3's ``direct``.

Scene: the unit sphere seen orthographically from +z, ``--res``² pixels, lit only by the studio
environment (the same lat-long EXR on both sides), made of a Lambertian (albedo 0.5), a GGX
conductor (alpha 0.2, glossy, and 0.02, near mirror; Smith, gold-like eta and k; Mitsuba
``roughconductor`` with visible-normal sampling), or an RGL tensor file (``--rgl``, gonio's
exact evaluator and sampler against Mitsuba's ``measured``); Mitsuba's ``--sampler`` is by
default ``multijitter``, stratified as gonio's Sobol' points are. Each renderer is scored
against its own converged image (``--ref-spp``), so the two need not agree on environment
orientation or pixel filtering: the figure is ``time x MSE`` at ``--spp`` (the inverse of the
usual efficiency), over the pixels inside 0.9 of the sphere's radius (away from the silhouette,
where Mitsuba's pixel filter mixes in the background). Times are the second render call
(compilation and Dr.Jit's kernel cache excluded); MSE is relative (divided by the mean squared
reference value) and averaged over channels. Rounds alternate the order; in a round each side
renders ``--repeats`` times with its own seeds, and the round's figures are the fastest call's
time (and its CPU time) and the mean MSE of the calls. The table gives medians over rounds and
the ratio gonio / Mitsuba of ``time x MSE`` (< 1: gonio reaches a given error in less time), in
wall time and in CPU time (the process's user + system time over all threads
during the render: both renderers run two threads; on a machine shared with other work the wall
time also counts waiting for a core).

Writes benchmarks/results/equal_time.csv and equal_time.png and prints a Markdown table.
Run: PYTHONPATH=src python benchmarks/bench_equal_time.py [--quick]
"""

from __future__ import annotations

import argparse
import csv
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
GOLD_ETA = [0.143, 0.374, 1.442]
GOLD_K = [3.983, 2.385, 1.603]


def disk_mask(res: int, radius: float = 0.9) -> np.ndarray:
    c = (np.arange(res) + 0.5) / res * 2 - 1
    x, y = np.meshgrid(c, c)
    return x * x + y * y < radius * radius


def cpu_model() -> str:
    """The processor's model name (Linux), for the CSV: ratios against Mitsuba depend on it
    (its vector gathers, for one, run at very different speeds on different cores)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown"


def rel_mse(img: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> float:
    d = (img[mask] - ref[mask]) ** 2
    return float(np.mean(d) / np.mean(ref[mask] ** 2))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--ref-spp", type=int, default=1024)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument(
        "--repeats",
        type=int,
        default=5,
        help="renders per side and round, each with its own seed: the round's time is the "
        "fastest, its MSE their mean (default 5)",
    )
    ap.add_argument("--variant", default="llvm_ad_rgb")
    ap.add_argument(
        "--sampler",
        default="multijitter",
        help="Mitsuba sampler (default multijitter: stratified, like gonio's lattice points)",
    )
    ap.add_argument(
        "--rgl",
        type=Path,
        default=Path(__file__).resolve().parents[1].parent / "shared/data/rgl/paper_white_rgb.bsdf",
        help="RGL tensor file for the measured row (skipped when missing)",
    )
    ap.add_argument("--quick", action="store_true", help="64², 16 spp, reference 512 spp, 2 rounds")
    ap.add_argument("--csv", default="equal_time.csv", help="results file name in results/")
    args = ap.parse_args()
    if args.quick:
        args.res, args.spp, args.ref_spp, args.rounds = 64, 16, 512, 2

    import drjit as dr
    import mitsuba as mi

    from gonio.brdf import models
    from gonio.render import Environment, render_sphere
    from gonio.render.lights import studio_environment
    from gonio.render.output import write_exr

    mi.set_variant(args.variant)
    tmp = Path(tempfile.mkdtemp(prefix="gonio-equal-time-"))
    env_file = write_exr(tmp / "env.exr", studio_environment())
    env = [Environment(str(env_file))]
    gold = models.Conductor(eta=GOLD_ETA, k=GOLD_K)

    def ggx(alpha: float) -> tuple:
        return (
            models.TorranceSparrow(
                alpha=alpha, distribution="ggx", shadowing="smith", fresnel=gold
            ),
            {"type": "roughconductor", "distribution": "ggx", "alpha": alpha,
             "eta": {"type": "rgb", "value": GOLD_ETA}, "k": {"type": "rgb", "value": GOLD_K}},
        )  # fmt: skip

    cases = {
        "Lambert / diffuse": (
            models.Lambert([0.5, 0.5, 0.5]),
            {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.5}},
        ),
        "GGX conductor / roughconductor": ggx(0.2),
        "near-mirror GGX conductor (alpha 0.02) / roughconductor": ggx(0.02),
    }
    if args.rgl is not None and args.rgl.is_file():
        from gonio.io.rgl_measured import load_rgl

        cases[f"RGL {args.rgl.stem} / measured"] = (
            load_rgl(args.rgl),
            {"type": "measured", "filename": str(args.rgl)},
        )
    mask = disk_mask(args.res)

    def mitsuba_scene(bsdf: dict):
        return mi.load_dict({
            "type": "scene",
            "integrator": {"type": "direct"},
            "sensor": {
                "type": "orthographic",
                "to_world": mi.ScalarTransform4f.look_at(
                    origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0]
                ),
                "film": {"type": "hdrfilm", "width": args.res, "height": args.res,
                         "rfilter": {"type": "box"}},
                "sampler": {"type": args.sampler},
            },
            "sphere": {"type": "sphere", "bsdf": bsdf},
            # gonio's lat-long u = atan2(x, -z) / 2 pi + 1/2; Mitsuba's lacks the 1/2: a half
            # turn about +y puts the same texel in the same direction (checked below by
            # comparing the converged images' means)
            "env": {"type": "envmap", "filename": str(env_file),
                    "to_world": mi.ScalarTransform4f.rotate([0, 1, 0], 180.0)},
        })  # fmt: skip

    rows = []
    for name, (model, bsdf) in cases.items():
        scene = mitsuba_scene(bsdf)

        def g_render(spp: int, seed: int, model=model) -> tuple[np.ndarray, float, float]:
            t0, c0 = time.perf_counter(), time.process_time()
            img = render_sphere(model, env, resolution=args.res, spp=spp, seed=seed)
            return img, time.perf_counter() - t0, time.process_time() - c0

        def m_render(spp: int, seed: int, scene=scene) -> tuple[np.ndarray, float, float]:
            t0, c0 = time.perf_counter(), time.process_time()
            img = mi.render(scene, spp=spp, seed=seed)
            dr.eval(img)
            dr.sync_thread()
            out = np.asarray(img)[..., :3]
            return out, time.perf_counter() - t0, time.process_time() - c0

        g_ref = g_render(args.ref_spp, 1000)[0]
        m_ref = m_render(args.ref_spp, 1000)[0]
        g_render(args.spp, 0)  # compile
        m_render(args.spp, 0)
        res = {"gonio": [], "mitsuba": []}
        for r in range(args.rounds):
            sides = [("gonio", g_render, g_ref), ("mitsuba", m_render, m_ref)]
            for side, fn, ref in sides if r % 2 == 0 else sides[::-1]:
                calls = [fn(args.spp, 1 + r * args.repeats + k) for k in range(args.repeats)]
                best = min(calls, key=lambda c: c[1])
                mse = statistics.mean(rel_mse(c[0], ref, mask) for c in calls)
                res[side].append((best[1], mse, best[2]))
        pairs = list(zip(res["gonio"], res["mitsuba"], strict=True))
        ratio = statistics.median((g[0] * g[1]) / (m[0] * m[1]) for g, m in pairs)
        cpu_ratio = statistics.median((g[2] * g[1]) / (m[2] * m[1]) for g, m in pairs)
        row = {"case": name, "res": args.res, "spp": args.spp, "ref_spp": args.ref_spp,
               "mitsuba_sampler": args.sampler,
               "gonio_ref_mean": f"{g_ref[mask].mean():.4g}",
               "mitsuba_ref_mean": f"{m_ref[mask].mean():.4g}"}  # fmt: skip
        for side in ("gonio", "mitsuba"):
            row[f"{side}_s"] = f"{statistics.median(x[0] for x in res[side]):.3f}"
            row[f"{side}_rel_mse"] = f"{statistics.median(x[1] for x in res[side]):.3g}"
            row[f"{side}_cpu_s"] = f"{statistics.median(x[2] for x in res[side]):.3f}"
        row["time_x_mse_ratio_gonio_over_mitsuba"] = f"{ratio:.3g}"
        row["cpu_time_x_mse_ratio_gonio_over_mitsuba"] = f"{cpu_ratio:.3g}"
        row["load_avg_1min"] = f"{os.getloadavg()[0]:.1f}"
        row["cpu"] = cpu_model()
        rows.append(row)
        print(row, flush=True)

    RESULTS.mkdir(exist_ok=True)
    with open(RESULTS / args.csv, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 0.5 + 0.45 * len(rows)))
    ax.barh([r["case"] for r in rows], [float(r["time_x_mse_ratio_gonio_over_mitsuba"])
                                        for r in rows])  # fmt: skip
    ax.axvline(1.0, color="gray", ls="--", lw=0.8)
    ax.set_xscale("log")
    ax.set_xlabel("time x MSE, gonio / Mitsuba direct (<1: gonio better)")
    ax.set_title(f"environment only, {args.res}², {args.spp} spp, load {rows[-1]['load_avg_1min']}",
                 fontsize=9)  # fmt: skip
    fig.tight_layout()
    fig.savefig(RESULTS / Path(args.csv).with_suffix(".png"), dpi=120)

    print("\n| material | gonio s (CPU s) | gonio rel. MSE | Mitsuba s (CPU s) | Mitsuba rel. MSE "
          "| time × MSE, gonio / Mitsuba | CPU time × MSE |")  # fmt: skip
    print("|---|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['case']} | {r['gonio_s']} ({r['gonio_cpu_s']}) | {r['gonio_rel_mse']} "
              f"| {r['mitsuba_s']} ({r['mitsuba_cpu_s']}) | {r['mitsuba_rel_mse']} "
              f"| {r['time_x_mse_ratio_gonio_over_mitsuba']} "
              f"| {r['cpu_time_x_mse_ratio_gonio_over_mitsuba']} |")  # fmt: skip


def write_tables() -> None:
    """Rewrite this benchmark's table in benchmarks/README.md from its CSV."""
    import _tables

    columns = [
        ("material", "case"),
        ("gonio s", "gonio_s"),
        ("gonio CPU s", "gonio_cpu_s"),
        ("gonio rel. MSE", "gonio_rel_mse"),
        ("Mitsuba s", "mitsuba_s"),
        ("Mitsuba CPU s", "mitsuba_cpu_s"),
        ("Mitsuba rel. MSE", "mitsuba_rel_mse"),
        ("ratio, wall", "time_x_mse_ratio_gonio_over_mitsuba"),
        ("ratio, CPU", "cpu_time_x_mse_ratio_gonio_over_mitsuba"),
        ("load", "load_avg_1min"),
    ]
    rows = _tables.read("equal_time.csv")
    cpus = sorted({r["cpu"] for r in rows if r.get("cpu")})
    note = f"\n\nProcessor: {', '.join(cpus)}." if cpus else ""
    _tables.write("equal_time", _tables.markdown(rows, columns) + note)


if __name__ == "__main__":
    main()
    write_tables()
