"""``gonio demo``: run the whole pipeline on the simulated rig and write a report."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from gonio.io.strict_json import dumps_json


def register(sub: Any) -> None:
    p = sub.add_parser(
        "demo",
        help="the whole pipeline on the simulated rig: acquire, fit, render, report",
        description=(
            "Start the simulated rig (Dynamixel servos emulated on a pseudo-terminal, a virtual"
            " camera writing DNG brackets), measure a real material with it, build the table,"
            " fit Lambert, Oren-Nayar, Lambert + Ward and Lambert + Torrance-Sparrow with 95%"
            " intervals, render measured and fitted spheres and write OUT/index.html. The"
            " material is an RGL-EPFL measurement found in $GONIO_DATA/rgl or ../shared/data/rgl"
            " (the simulated sample's ground truth), else a built-in analytic paint. About 2.3"
            " minutes on an idle 2-core machine (--quick: about 45 s; benchmarks/bench_demo.py),"
            " several times as long on a machine busy with other work (the simulated camera is"
            " CPU-bound)."
        ),
    )
    p.add_argument("--out", default="gonio-demo", help="output folder (default gonio-demo)")
    p.add_argument(
        "--material",
        default="auto",
        metavar="auto|builtin|FILE",
        help="the simulated sample: 'auto' (first RGL measurement found, else built-in;"
        " default), 'builtin' (analytic, known parameters), or a tabulated BRDF file",
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help="reduced run: plan 'demo-quick' (64 planned configurations), 96 px spheres at 16 spp",
    )
    p.add_argument(
        "--uncertainty",
        choices=("laplace", "mcmc"),
        default="laplace",
        help="interval method of the fits (default laplace; mcmc takes ~10 s per model)",
    )
    p.add_argument("--resolution", type=int, help="sphere render size in pixels (default 256)")
    p.add_argument("--spp", type=int, help="render samples per pixel (default 64)")
    p.add_argument(
        "--keep-images",
        action="store_true",
        help="keep every raw bracket and HDR frame (~4 MB per configuration; default: the"
        " first 3 configurations' are kept, the table holds all measurements)",
    )
    p.add_argument("--force", action="store_true", help="replace OUT when it holds an earlier demo")
    p.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    from gonio import compile_cache

    compile_cache.add_argument(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from gonio.demo.materials import find_material
    from gonio.demo.pipeline import DemoSettings, check_out, run_demo
    from gonio.errors import ParameterError

    extra: dict[str, Any] = {"uncertainty": args.uncertainty, "keep_images": args.keep_images}
    if args.resolution is not None:
        if not 16 <= args.resolution <= 2048:
            raise ParameterError(f"--resolution must be in [16, 2048], got {args.resolution}")
        extra["resolution"] = args.resolution
    if args.spp is not None:
        if args.spp < 1:
            raise ParameterError(f"--spp must be >= 1, got {args.spp}")
        extra["spp"] = args.spp
    settings = DemoSettings.quick(**extra) if args.quick else DemoSettings(**extra)
    check_out(Path(args.out), args.force)  # before loading the material, which can take seconds
    material = find_material(args.material)
    progress = not args.no_progress
    summary = run_demo(args.out, material, settings, force=args.force, progress=progress)
    if args.json:
        sys.stdout.write(dumps_json(summary.to_json(), indent=2))
        print()
    else:
        print_summary(summary)
    return 0


def print_summary(summary: Any) -> None:
    """The final summary on the terminal: one table of fit quality, one of parameters.

    Both fit 80 columns (``COLUMNS`` when set, 80 when piped): cells wrap at words and a word
    is never cut (``overflow="fold"``: it continues on the next line)."""
    from rich import box
    from rich.console import Console
    from rich.table import Table

    quality = Table(
        title=f"gonio demo: {summary.material['name']}", box=box.SIMPLE_HEAD, pad_edge=False
    )
    quality.add_column("model", overflow="fold")
    for col in ("red.\nchi2", "BIC", "render\nRMSE", "SSIM"):
        quality.add_column(col, justify="right", no_wrap=True)
    quality.add_column("truth\nmax |z|", justify="right", overflow="fold")
    params = Table(title="fitted parameters (95% intervals)", box=box.SIMPLE_HEAD, pad_edge=False)
    for col in ("model", "parameter", "value", "interval"):
        params.add_column(
            col, justify="left" if col in ("model", "parameter") else "right", overflow="fold"
        )
    for m in summary.models:
        chk = "-"
        if m.truth_check is not None:
            tc = m.truth_check
            chk = f"{tc.max_z:.2f} " + ("ok" if tc.consistent else "TOO FAR")
        quality.add_row(
            m.label,
            f"{m.reduced_chi2:.3g}",
            f"{m.bic:.4g}",
            "-" if m.rmse is None else f"{m.rmse:.3g}",
            "-" if m.ssim is None else f"{m.ssim:.3f}",
            chk,
        )
        rows = list(_flat_rows(m.params, m.intervals))
        for i, (name, value, interval) in enumerate(rows):
            params.add_row(
                m.label if i == 0 else "", name, value, interval, end_section=i == len(rows) - 1
            )
    console = Console(markup=False, highlight=False, emoji=False)  # names like "f0[B]"
    console.print(quality)
    console.print(params)
    t = summary.timings_s
    console.print(
        f"acquire {t['acquire']:.0f} s, fit {t['fit']:.0f} s, render {t['render']:.0f} s,"
        f" total {t['total']:.0f} s. Report: {summary.out}/index.html"
    )


def _flat_rows(params: dict[str, Any], intervals: dict[str, Any]):
    """``(name, value, interval)`` text per scalar: per-channel values get one row each."""
    import numpy as np

    for key, value in params.items():
        v = np.atleast_1d(np.asarray(value, dtype=float)).ravel()
        iv = intervals.get(key)
        lo, hi = (np.atleast_1d(np.asarray(x, dtype=float)).ravel() for x in iv) if iv else ([], [])
        short = key.split(".", 1)[-1] if "." in key else key
        for c, x in enumerate(v):
            name = short if v.size == 1 else f"{short}[{'RGB'[c] if v.size == 3 else c}]"
            interval = f"[{lo[c]:.4g}, {hi[c]:.4g}]" if len(lo) == v.size else "-"
            yield name, f"{x:.4g}", interval
