"""RGL tensor files: gonio's exact evaluator and sampler against Mitsuba 3's ``measured`` plugin,
and the exact path against the resampled (MERL-grid table) one in fitting and rendering.

1. Load time of :func:`gonio.io.rgl_measured.load_rgl` (parse, validate, build the warps), and
   throughput, same run, same files (``../shared/data/rgl``), same random queries: ``f`` and
   ``sample`` of :class:`gonio.io.rgl_measured.RGLMeasured` (jitted JAX on the CPU, float32 and
   float64) against ``eval`` and ``sample`` of Mitsuba's ``measured`` BSDF in the ``llvm_ad_rgb``
   variant (vectorized; needs Debian's ``libllvm19``), or ``scalar_rgb`` (a Python loop over
   scalar calls, far slower, measured on fewer queries) when LLVM is not available. Warm
   timings: best of ``ROUNDS`` rounds that run gonio's and Mitsuba's calls in turn, after an
   untimed call of each (JIT compilation excluded).
   Mitsuba's time includes moving the results to NumPy, gonio's too.
2. Fit: ``gonio.fit.fit(..., "lambert+ward", loss="ngan")`` on the exact file (its own nodes,
   :meth:`RGLMeasured.to_samples`) and on its MERL-grid resampling (``to_table()``, whose
   tabulation time is reported separately).
3. Render: 64 x 64 sphere under the studio environment at ``SPP`` spp, MIS with the material's
   sampler (the file's own warps for the exact path, tabulated inversion for the resampled
   table); warm wall time (best of ``REPEAT``, the two paths alternating, after an untimed
   render) and MSE against a ``REF_SPP``-spp render of the exact file; efficiency
   1 / (time x MSE). The resampled table's MSE includes its resampling bias (it renders another
   function). The sampling efficiency alone is ``efficiency_own``: MSE against a
   ``REF_SPP``-spp render of the same material (its own converged image), so bias plays no part;
   ``efficiency_own_cpu`` takes the process CPU time (all threads) instead of the wall time,
   which other work on a shared machine disturbs less.

Writes benchmarks/results/rgl_throughput.csv, rgl_fit_render.csv and rgl.png; prints Markdown.
Run: PYTHONPATH=src python benchmarks/bench_rgl.py [--quick]
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "rgl"
FILES = [
    "paper_white_rgb.bsdf",
    "acrylic_felt_green_rgb.bsdf",
    "cc_ibiza_sunset_rgb.bsdf",
    "vch_golden_yellow_rgb.bsdf",
]
SPP = 32
REF_SPP = 1024
REPEAT = 5
ROUNDS = 5  # alternating throughput rounds (gonio and Mitsuba in turn)
RES = 64


def _queries(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)

    def hemi():
        u = rng.random((n, 2))
        z = math.cos(math.radians(85)) + (1 - math.cos(math.radians(85))) * u[:, 0]
        r = np.sqrt(1 - z * z)
        p = 2 * math.pi * u[:, 1]
        return np.stack([r * np.cos(p), r * np.sin(p), z], -1)

    return hemi(), hemi(), rng.random((n, 2))


def _best(fn, repeat: int = 3) -> float:
    fn()  # warm: compile
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def _mitsuba():
    """(variant, module) of the fastest Mitsuba variant that runs here, or (None, None)."""
    try:
        import mitsuba as mi
    except ImportError:
        return None, None
    for variant in ("llvm_ad_rgb", "scalar_rgb"):
        try:
            mi.set_variant(variant)
            mi.load_dict({"type": "diffuse"})
            return variant, mi
        except Exception:
            continue
    return None, None


def _mitsuba_ops(mi, variant: str, path: Path, wi, wo, u):
    bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
    ctx = mi.BSDFContext()
    if variant.startswith("llvm"):
        import drjit as dr

        si = dr.zeros(mi.SurfaceInteraction3f, wo.shape[0])
        si.wi = mi.Vector3f(wo[:, 0], wo[:, 1], wo[:, 2])  # the file's conditioning direction
        d = mi.Vector3f(wi[:, 0], wi[:, 1], wi[:, 2])
        s1 = mi.Float(u[:, 0])
        s2 = mi.Point2f(u[:, 0], u[:, 1])

        def ev():
            return np.asarray(bsdf.eval(ctx, si, d))

        def sa():
            bs, w = bsdf.sample(ctx, si, s1, s2)
            return np.asarray(bs.wo), np.asarray(w)

        return ev, sa

    def ev():
        out = []
        for k in range(wo.shape[0]):
            si = mi.SurfaceInteraction3f()
            si.wi = mi.Vector3f(*wo[k])
            out.append(bsdf.eval(ctx, si, mi.Vector3f(*wi[k])))
        return out

    def sa():
        out = []
        for k in range(wo.shape[0]):
            si = mi.SurfaceInteraction3f()
            si.wi = mi.Vector3f(*wo[k])
            out.append(bsdf.sample(ctx, si, float(u[k, 0]), mi.Point2f(*u[k])))
        return out

    return ev, sa


def _alternating(fns: dict, rounds: int) -> dict:
    """Best time of each callable over ``rounds`` rounds that run them in turn (after an
    untimed warm call of each): load on a shared machine then disturbs all of them alike."""
    for fn in fns.values():
        fn()
    best = dict.fromkeys(fns, float("inf"))
    for _ in range(rounds):
        for key, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            best[key] = min(best[key], time.perf_counter() - t0)
    return best


def throughput(n: int, files: list[str], rounds: int = ROUNDS) -> list[dict]:
    import jax

    from gonio.io.rgl_measured import load_rgl

    variant, mi = _mitsuba()
    dtypes = (np.float32, np.float64)
    rows = []
    for name in files:
        path = DATA / name
        t_load = _best(lambda: load_rgl(path))  # noqa: B023
        m = load_rgl(path)
        f_jit = jax.jit(lambda m, a, b: m.f(a, b))
        s_jit = jax.jit(lambda m, a, b: m.sample(a, b).weight)
        fns = {}
        for dtype in dtypes:
            wi, wo, u = (x.astype(dtype) for x in _queries(n))
            key = np.dtype(dtype).name
            fns[("f", key)] = lambda wi=wi, wo=wo: np.asarray(f_jit(m, wi, wo))  # noqa: B023
            fns[("s", key)] = lambda wo=wo, u=u: np.asarray(s_jit(m, wo, u))  # noqa: B023
        k = n if variant is not None and variant.startswith("llvm") else min(n, 2000)
        if mi is not None:
            ev, sa = _mitsuba_ops(mi, variant, path, *_queries(k))
            fns["mi_eval"], fns["mi_sample"] = ev, sa
        best = _alternating(fns, rounds)
        for dtype in dtypes:
            key = np.dtype(dtype).name
            row = {"file": name, "load_ms": 1e3 * t_load, "gonio_dtype": key, "n": n,
                   "gonio_f_Mps": n / best[("f", key)] / 1e6,
                   "gonio_sample_Mps": n / best[("s", key)] / 1e6}  # fmt: skip
            if mi is not None:
                row.update(
                    mitsuba_variant=variant,
                    mitsuba_n=k,
                    mitsuba_eval_Mps=k / best["mi_eval"] / 1e6,
                    mitsuba_sample_Mps=k / best["mi_sample"] / 1e6,
                )
                row["ratio_f"] = row["gonio_f_Mps"] / row["mitsuba_eval_Mps"]
                row["ratio_sample"] = row["gonio_sample_Mps"] / row["mitsuba_sample_Mps"]
            row["load_avg_1min"] = os.getloadavg()[0]
            rows.append(row)
            print(row, flush=True)
    return rows


def fit_render(files: list[str], spp: int, ref_spp: int, res: int, fit: bool = True) -> list[dict]:
    import gonio.fit as gf
    from gonio.io.rgl_measured import load_rgl
    from gonio.render import render_sphere

    rows = []
    for name in files:
        m = load_rgl(DATA / name)
        t0 = time.perf_counter()
        table = m.to_table()
        t_tab = time.perf_counter() - t0
        for label, data in (("exact", m), ("resampled", table)) if fit else ():
            t0 = time.perf_counter()
            res_fit = gf.fit(data, model="lambert+ward", loss="ngan")
            t_fit = time.perf_counter() - t0
            rows.append({"file": name, "path": label, "what": "fit", "seconds": t_fit,
                         "tabulate_s": t_tab if label == "resampled" else 0.0,
                         "loss": float(res_fit.loss), "mse": "", "efficiency": ""})  # fmt: skip
        ref = render_sphere(m, None, resolution=res, spp=ref_spp, seed=7)
        hit = ref.sum(-1) > 0
        mats = {"exact": m, "resampled": table}
        own = {"exact": ref, "resampled": render_sphere(table, None, resolution=res,
                                                        spp=ref_spp, seed=7)}  # fmt: skip
        for mat in mats.values():
            render_sphere(mat, None, resolution=res, spp=spp, seed=1)  # warm: compile, build
        best = dict.fromkeys(mats, float("inf"))
        cpu = dict.fromkeys(mats, float("inf"))
        img = {}
        for _ in range(REPEAT):  # alternating, best of REPEAT: the machine is shared
            for label, mat in mats.items():
                t0, c0 = time.perf_counter(), time.process_time()
                img[label] = render_sphere(mat, None, resolution=res, spp=spp, seed=2)
                best[label] = min(best[label], time.perf_counter() - t0)
                cpu[label] = min(cpu[label], time.process_time() - c0)
        for label in mats:
            t_r = best[label]
            mse = float(np.mean((img[label][hit] - ref[hit]) ** 2))
            mse_own = float(np.mean((img[label][hit] - own[label][hit]) ** 2))
            rows.append({"file": name, "path": label, "what": f"render {spp} spp", "seconds": t_r,
                         "tabulate_s": t_tab if label == "resampled" else 0.0, "loss": "",
                         "mse": mse, "efficiency": 1.0 / (mse * t_r), "mse_own": mse_own,
                         "efficiency_own": 1.0 / (mse_own * t_r), "cpu_seconds": cpu[label],
                         "efficiency_own_cpu": 1.0 / (mse_own * cpu[label]),
                         "load_avg_1min": os.getloadavg()[0]})  # fmt: skip
        for r in rows[-4:]:
            print(r, flush=True)
    return rows


def write_csv(path: Path, rows: list[dict]) -> None:
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)


def plot(tp: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in tp if r["gonio_dtype"] == "float32"]
    names = [r["file"].replace("_rgb.bsdf", "") for r in rows]
    x = np.arange(len(rows))
    fig, ax = plt.subplots(figsize=(7, 3.2))
    ax.bar(x - 0.3, [r["gonio_f_Mps"] for r in rows], 0.2, label="gonio f (f32)")
    ax.bar(x - 0.1, [r["gonio_sample_Mps"] for r in rows], 0.2, label="gonio sample (f32)")
    if "mitsuba_eval_Mps" in rows[0]:
        v = rows[0]["mitsuba_variant"]
        ax.bar(x + 0.1, [r["mitsuba_eval_Mps"] for r in rows], 0.2, label=f"Mitsuba eval ({v})")
        ax.bar(x + 0.3, [r["mitsuba_sample_Mps"] for r in rows], 0.2, label=f"Mitsuba sample ({v})")
    ax.set_xticks(x, names, fontsize=7)
    ax.set_ylabel("million queries / s")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def markdown(tp: list[dict], fr: list[dict]) -> str:
    lines = ["| file | load (ms) | dtype | gonio f (M/s) | Mitsuba eval (M/s) | ratio "
             "| gonio sample (M/s) | Mitsuba sample (M/s) | ratio |",
             "|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in tp:
        lines.append(
            f"| {r['file']} | {r['load_ms']:.0f} | {r['gonio_dtype']} | {r['gonio_f_Mps']:.2f} | "
            f"{r.get('mitsuba_eval_Mps', float('nan')):.2f} | {r.get('ratio_f', float('nan')):.2f} "
            f"| {r['gonio_sample_Mps']:.2f} | {r.get('mitsuba_sample_Mps', float('nan')):.2f} | "
            f"{r.get('ratio_sample', float('nan')):.2f} |"
        )
    if not tp:
        lines = []
    lines += ["", "| file | path | what | seconds | tabulation s | fit loss | MSE | 1/(MSE t) "
              "| MSE, own ref. | 1/(MSE t), own ref. | CPU s | 1/(MSE t_cpu), own ref. |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip

    def g(r: dict, key: str, fmt: str) -> str:
        return format(r[key], fmt) if r.get(key, "") != "" else ""

    for r in fr:
        lines.append(
            f"| {r['file']} | {r['path']} | {r['what']} | {r['seconds']:.2f} | "
            f"{r['tabulate_s']:.2f} | {g(r, 'loss', '.4g')} | {g(r, 'mse', '.3g')} | "
            f"{g(r, 'efficiency', '.3g')} | {g(r, 'mse_own', '.3g')} | "
            f"{g(r, 'efficiency_own', '.3g')} | {g(r, 'cpu_seconds', '.2f')} | "
            f"{g(r, 'efficiency_own_cpu', '.3g')} |"
        )
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer queries, two files, small renders")
    ap.add_argument("--skip-fit-render", action="store_true", help="throughput only")
    ap.add_argument(
        "--skip-throughput",
        action="store_true",
        help="fit and render only (rgl_throughput.csv and rgl.png are left as they are)",
    )
    ap.add_argument(
        "--all-files",
        action="store_true",
        help="fit and render every file (default: the felt and the vinyl film)",
    )
    ap.add_argument("--skip-fit", action="store_true", help="render only (no fit rows)")
    args = ap.parse_args(argv)
    RESULTS.mkdir(exist_ok=True)
    files = [f for f in FILES if (DATA / f).exists()]
    if not files:
        print(f"no RGL files in {DATA}")
        return 1
    n = 1 << 16 if args.quick else 1 << 18
    tp: list[dict] = []
    if not args.skip_throughput:
        tp = throughput(n, files[:2] if args.quick else files)
        write_csv(RESULTS / "rgl_throughput.csv", tp)
        plot(tp, RESULTS / "rgl.png")
    fr: list[dict] = []
    if not args.skip_fit_render:
        chosen = [files[1]] if args.quick else [files[1], files[-1]]
        if args.all_files:
            chosen = files
        fr = fit_render(
            chosen,
            SPP,
            REF_SPP // 4 if args.quick else REF_SPP,
            32 if args.quick else RES,
            fit=not args.skip_fit,
        )
        write_csv(RESULTS / "rgl_fit_render.csv", fr)
    print(markdown(tp, fr))
    return 0


def write_tables() -> None:
    """Rewrite this benchmark's tables in benchmarks/README.md from its CSVs."""
    import _tables

    throughput = [
        ("file", "file"),
        ("load (ms)", "load_ms"),
        ("dtype", "gonio_dtype"),
        ("gonio f (M/s)", "gonio_f_Mps"),
        ("Mitsuba eval (M/s)", "mitsuba_eval_Mps"),
        ("ratio", "ratio_f"),
        ("gonio sample (M/s)", "gonio_sample_Mps"),
        ("Mitsuba sample (M/s)", "mitsuba_sample_Mps"),
        ("ratio", "ratio_sample"),
    ]
    rows = _tables.read("rgl_throughput.csv")
    _tables.write("rgl_throughput", _tables.markdown(rows, throughput))
    fit_render = [
        ("file", "file"),
        ("path", "path"),
        ("what", "what"),
        ("seconds", "seconds"),
        ("tabulation (s)", "tabulate_s"),
        ("fit loss", "loss"),
        ("MSE", "mse"),
        ("1/(MSE t)", "efficiency"),
        ("MSE, own ref.", "mse_own"),
        ("CPU (s)", "cpu_seconds"),
        ("1/(MSE t_cpu), own ref.", "efficiency_own_cpu"),
    ]
    rows = _tables.read("rgl_fit_render.csv")
    _tables.write("rgl_fit_render", _tables.markdown(rows, fit_render))


if __name__ == "__main__":
    _rc = main()
    if not _rc:
        write_tables()
    raise SystemExit(_rc)
