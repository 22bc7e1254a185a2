"""Time from a fresh process to its first sphere image: gonio (cold and warm compilation cache,
and with the cache off) next to Mitsuba 3 (fresh Dr.Jit kernel cache and warm one).

gonio runs its real entry point, ``gonio render --fitted lambert.json --env FILE.exr`` (a
Lambertian sphere, albedo 0.5, under a lat-long environment, ``--res``² pixels, ``--spp``
samples per pixel, one PNG written). Mitsuba renders the same scene (``sphere`` with
``diffuse``, ``envmap`` of the same EXR, orthographic camera, ``direct`` integrator, same
resolution and spp) in a fresh ``python`` process and writes one PNG. Each figure is wall time
measured by this script from spawning the process to its exit: interpreter start, imports,
kernel compilation or cache load, rendering and writing.

- gonio cold: an empty ``XDG_CACHE_HOME`` (no compiled kernels on disk),
- gonio warm: the cache filled by an earlier run (the second process a user starts),
- gonio off: ``--no-compile-cache``,
- import jax alone: ``python -c "import jax, jax.numpy"``, the floor under every gonio figure
  (its ratio is to Mitsuba cold),
- Mitsuba cold: ``HOME`` pointed at an empty folder (Dr.Jit keeps its kernel cache in
  ``~/.drjit``), Mitsuba warm: that folder kept from an earlier run.

Rounds alternate the order of the configurations (ABBA), so that a drift of the machine's speed
favours none; the table reports medians and the ratios gonio / Mitsuba of each round's figures,
and the median CPU time of each process (user + system over all its threads, from
``getrusage``): on a machine shared with other work the wall time includes waiting for a core,
the CPU time does not.

``--compare-python PATH`` adds, in the same rounds, a warm gonio process and ``import jax`` run
by another interpreter (another environment, e.g. one with another ``ml_dtypes``), labelled by
its ``ml_dtypes`` version; the CSV's second line names the version of the main one.

Writes benchmarks/results/first_image.csv and first_image.png and prints a Markdown table.
Run: PYTHONPATH=src python benchmarks/bench_first_image.py [--rounds K] [--quick]
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"
SRC = Path(__file__).resolve().parent.parent / "src"

MITSUBA_SCRIPT = r"""
import sys
import mitsuba as mi
mi.set_variant(sys.argv[1])
res, spp, env, out = int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], sys.argv[5]
scene = mi.load_dict({
    "type": "scene",
    "integrator": {"type": "direct"},
    "sensor": {
        "type": "orthographic",
        "to_world": mi.ScalarTransform4f.look_at(origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0])
        @ mi.ScalarTransform4f.scale([1, 1, 1]),
        "film": {"type": "hdrfilm", "width": res, "height": res},
        "sampler": {"type": "independent", "sample_count": spp},
    },
    "sphere": {
        "type": "sphere",
        "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.5}},
    },
    "env": {"type": "envmap", "filename": env},
})
img = mi.render(scene, spp=spp)
mi.util.write_bitmap(out, img)
"""


#: CPU seconds (user + system, all threads) of each child run, in the order they ran.
CPU: dict[str, list[float]] = {}


def _child_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _ml_dtypes(python: str) -> str:
    """The ml_dtypes version an interpreter imports (its cost is most of `import jax`)."""
    code = "import importlib.metadata as m; print(m.version('ml_dtypes'))"
    out = subprocess.run([python, "-c", code], capture_output=True, text=True, check=True)
    return out.stdout.strip()


def _run(cmd: list[str], env: dict[str, str]) -> float:
    c0 = _child_cpu()
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=900)
    dt = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{cmd[:4]} failed: {proc.stderr.strip().splitlines()[-1:]}")
    _run.last_cpu = _child_cpu() - c0  # type: ignore[attr-defined]
    return dt


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--variant", default="llvm_ad_rgb", help="Mitsuba variant (llvm_ad_rgb)")
    ap.add_argument("--quick", action="store_true", help="2 rounds")
    ap.add_argument(
        "--compare-python",
        type=Path,
        help="a second interpreter (another environment, e.g. another ml_dtypes): adds its warm "
        "gonio process and its `import jax` to the same rounds",
    )
    args = ap.parse_args()
    if args.compare_python is not None and not args.compare_python.is_file():
        raise SystemExit(f"bench_first_image: no such interpreter: {args.compare_python}")
    rounds = 2 if args.quick else args.rounds
    load0 = os.getloadavg()[0]

    from gonio.brdf.models import Lambert
    from gonio.render.lights import studio_environment
    from gonio.render.output import write_exr

    work = Path(tempfile.mkdtemp(prefix="gonio-first-image-"))
    try:
        env_file = write_exr(work / "env.exr", studio_environment())
        fit = work / "lambert.json"
        fit.write_text(json.dumps(Lambert(albedo=0.5).to_dict()))
        mi_script = work / "mi_first.py"
        mi_script.write_text(MITSUBA_SCRIPT)
        base = {k: v for k, v in os.environ.items() if k != "GONIO_COMPILE_CACHE"}
        base.update(PYTHONPATH=f"{SRC}{os.pathsep}{base.get('PYTHONPATH', '')}")
        base.setdefault("JAX_PLATFORMS", "cpu")
        gonio_cmd = [sys.executable, "-m", "gonio", "render", "--fitted", str(fit)]
        gonio_cmd += ["--env", str(env_file), "--resolution", str(args.res), "--spp"]
        gonio_cmd += [str(args.spp), "--no-images", "--out", str(work / "g.png")]
        mi_cmd = [sys.executable, str(mi_script), args.variant, str(args.res), str(args.spp)]
        mi_cmd += [str(env_file), str(work / "m.png")]
        warm_cache, warm_home = work / "warm-cache", work / "warm-home"
        # Fill the warm caches once (not timed).
        _run(gonio_cmd, {**base, "XDG_CACHE_HOME": str(warm_cache)})
        _run(mi_cmd, {**base, "HOME": str(warm_home)})
        alt = None
        if args.compare_python is not None:
            alt_cmd = [str(args.compare_python), *gonio_cmd[1:]]
            alt = (_ml_dtypes(str(args.compare_python)), alt_cmd)
            _run(alt_cmd, {**base, "XDG_CACHE_HOME": str(warm_cache)})

        def gonio_cold() -> float:
            d = Path(tempfile.mkdtemp(dir=work))
            try:
                return _run(gonio_cmd, {**base, "XDG_CACHE_HOME": str(d)})
            finally:
                shutil.rmtree(d, ignore_errors=True)

        def mitsuba_cold() -> float:
            d = Path(tempfile.mkdtemp(dir=work))
            try:
                return _run(mi_cmd, {**base, "HOME": str(d)})
            finally:
                shutil.rmtree(d, ignore_errors=True)

        configs = {
            "gonio cold cache": gonio_cold,
            "gonio warm cache": lambda: _run(
                gonio_cmd, {**base, "XDG_CACHE_HOME": str(warm_cache)}
            ),
            "gonio cache off": lambda: _run(
                [*gonio_cmd, "--no-compile-cache"], {**base, "XDG_CACHE_HOME": str(warm_cache)}
            ),
            # The floor under every gonio figure: the interpreter and JAX's own import (with
            # jax.numpy), nothing of gonio's, in a process of its own.
            "import jax alone": lambda: _run(
                [sys.executable, "-c", "import jax, jax.numpy"], {**base}
            ),
            "Mitsuba cold": mitsuba_cold,
            "Mitsuba warm": lambda: _run(mi_cmd, {**base, "HOME": str(warm_home)}),
        }
        if alt is not None:
            version, alt_cmd = alt
            configs[f"gonio warm cache, ml_dtypes {version}"] = lambda: _run(
                alt_cmd, {**base, "XDG_CACHE_HOME": str(warm_cache)}
            )
            configs[f"import jax alone, ml_dtypes {version}"] = lambda: _run(
                [alt_cmd[0], "-c", "import jax, jax.numpy"], {**base}
            )
        times: dict[str, list[float]] = {k: [] for k in configs}
        cpu: dict[str, list[float]] = {k: [] for k in configs}
        order = list(configs)
        for r in range(rounds):
            for name in order if r % 2 == 0 else order[::-1]:
                times[name].append(configs[name]())
                cpu[name].append(_run.last_cpu)  # type: ignore[attr-defined]
                print(f"round {r}: {name} {times[name][-1]:.2f} s, CPU {cpu[name][-1]:.2f} s",
                      flush=True)  # fmt: skip
    finally:
        shutil.rmtree(work, ignore_errors=True)

    load = os.getloadavg()[0]
    RESULTS.mkdir(exist_ok=True)
    rows = []
    for name, ts in times.items():
        ref = times["Mitsuba warm" if "warm" in name else "Mitsuba cold"]
        ratio = statistics.median(a / b for a, b in zip(ts, ref, strict=True))
        rows.append((name, statistics.median(ts), min(ts), max(ts), ratio,
                     statistics.median(cpu[name])))  # fmt: skip
    with open(RESULTS / "first_image.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["config", "median_s", "min_s", "max_s", "ratio_to_mitsuba", "median_cpu_s",
                    "load_avg_1min"])  # fmt: skip
        w.writerow(["# res", args.res, "spp", args.spp, args.variant, f"rounds {rounds}",
                    f"load at start {load0:.1f}",
                    f"ml_dtypes {_ml_dtypes(sys.executable)}"])  # fmt: skip
        for row in rows:
            w.writerow([row[0], *(f"{x:.3f}" for x in row[1:]), f"{load:.1f}"])

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 3))
    names = [r[0] for r in rows]
    colors = ["C0"] * 3 + ["C2"] + ["C1"] * 2 + ["C0", "C2"][: len(rows) - 6]
    ax.barh(names, [r[1] for r in rows], xerr=None, color=colors)
    for i, ts in enumerate(times.values()):
        ax.plot(ts, [i] * len(ts), "k.", ms=4)
    ax.invert_yaxis()
    ax.set_xlabel("fresh process to first image (s)")
    ax.set_title(f"{args.res}² sphere, {args.spp} spp, load avg {load:.1f}", fontsize=9)
    fig.tight_layout()
    fig.savefig(RESULTS / "first_image.png", dpi=120)

    print(f"\n{args.res}² Lambert sphere, {args.spp} spp, Mitsuba {args.variant}, "
          f"{rounds} rounds, load average {load:.1f}\n")  # fmt: skip
    print("| process | median (s) | range (s) | / Mitsuba (same cache state) | CPU (s) |")
    print("|---|---:|---:|---:|---:|")
    for name, med, lo, hi, ratio, c in rows:
        print(f"| {name} | {med:.2f} | {lo:.2f}–{hi:.2f} | {ratio:.2f} | {c:.2f} |")


def write_tables() -> None:
    """Rewrite this benchmark's table in benchmarks/README.md from its CSV."""
    import _tables

    columns = [
        ("process", "config"),
        ("median (s)", "median_s"),
        ("min (s)", "min_s"),
        ("max (s)", "max_s"),
        ("/ Mitsuba (same cache state)", "ratio_to_mitsuba"),
        ("CPU (s)", "median_cpu_s"),
        ("load", "load_avg_1min"),
    ]
    _tables.write("first_image", _tables.markdown(_tables.read("first_image.csv"), columns))


if __name__ == "__main__":
    main()
    write_tables()
