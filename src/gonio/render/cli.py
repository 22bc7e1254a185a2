"""``gonio render``: render measured and fitted spheres and write a comparison figure."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from gonio.errors import FormatError, ParameterError

# Fit files hold a model description made by ``Node.to_dict``; they are parsed through the model
# registry (gonio.brdf) so that gonio.render never imports gonio.fit (DESIGN.md dependency rule).
MAX_FIT_BYTES = 16 * 1024 * 1024


def load_fit_model(path: str | Path) -> Any:
    """The model of a fit result JSON (key ``"model"``) or of a bare model description."""
    from gonio.brdf.models import Node

    path = Path(path)
    if not path.is_file():
        raise ParameterError(f"fit file not found: {path}")
    if path.stat().st_size > MAX_FIT_BYTES:
        raise FormatError(f"{path}: larger than {MAX_FIT_BYTES} bytes; not a fit file")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise FormatError(f"{path}: not valid JSON ({exc})") from None
    # A fit result keeps the description under "model_spec" ("model" is the preset's name);
    # a bare to_dict() (or {"model": {...}}) is accepted too.
    desc = doc
    if isinstance(doc, dict) and "type" not in doc:
        desc = doc.get("model_spec", doc.get("model"))
    if not isinstance(desc, dict) or "type" not in desc:
        raise FormatError(f"{path}: no model description (expected a 'model_spec' object)")
    try:
        model = Node.from_dict(desc)
    except ParameterError as exc:
        raise FormatError(f"{path}: {exc}") from None
    except (TypeError, ValueError, KeyError) as exc:
        raise FormatError(f"{path}: bad model description ({exc})") from None
    if not hasattr(model, "sample") or not hasattr(model, "f"):
        raise FormatError(f"{path}: describes a {type(model).__name__}, not a BRDF model")
    return model


def load_table(path: str | Path) -> Any:
    """A tabulated BRDF through :func:`gonio.io.load`."""
    p = Path(path)
    if not p.exists():
        raise ParameterError(f"measured table not found: {p}")
    from gonio import io as gio

    load = getattr(gio, "load", None)
    if load is None:
        raise FormatError("this gonio build cannot read measured tables (gonio.io.load missing)")
    obj = load(p)
    if not hasattr(obj, "values"):
        raise FormatError(f"{p}: holds scattered samples, not a table; tabulate it first")
    return obj


def parse_light(spec: str, irradiance: float = 1.0):
    """``dir:THETA,PHI[,E]`` (degrees; theta from the camera axis, phi from image right,
    counter-clockwise) -> :class:`~gonio.render.lights.Directional`."""
    from gonio.render.lights import Directional

    kind, _, rest = spec.partition(":")
    if kind != "dir" or not rest:
        raise ParameterError(f"--light must look like dir:THETA,PHI[,E] (degrees), got {spec!r}")
    try:
        nums = [float(x) for x in rest.split(",")]
    except ValueError:
        raise ParameterError(f"--light {spec!r}: THETA, PHI and E must be numbers") from None
    if len(nums) not in (2, 3) or not all(math.isfinite(x) for x in nums):
        raise ParameterError(f"--light {spec!r}: give THETA,PHI or THETA,PHI,E")
    theta, phi = nums[0], nums[1]
    if not 0.0 <= theta < 90.0:
        raise ParameterError(f"--light {spec!r}: THETA must be in [0, 90) degrees")
    e = nums[2] if len(nums) == 3 else irradiance
    return Directional.from_angles(math.radians(theta), math.radians(phi), e)


def register(subparsers: Any) -> None:
    """Add ``gonio render`` to the top-level parser."""
    p = subparsers.add_parser(
        "render",
        help="render measured and fitted spheres; write a comparison figure",
        description=(
            "Render a unit sphere of a measured BRDF table and of one or more fitted models under "
            "the same lights, and write a figure: measured | fitted | difference heat map with "
            "RMSE, relative MSE and SSIM. Linear EXR and sRGB PNG of every rendering are written "
            "next to the figure. Direct lighting is exact for a convex sphere (no "
            "interreflection exists); lights are sampled with multiple importance sampling."
        ),
    )
    p.add_argument("--measured", metavar="TABLE", help="measured BRDF table (any gonio.io format)")
    p.add_argument(
        "--fitted",
        metavar="FIT.json",
        action="append",
        default=[],
        help="fit result JSON (from 'gonio fit'); repeat for several fits",
    )
    light = p.add_mutually_exclusive_group()
    light.add_argument(
        "--env",
        metavar="studio|FILE.exr",
        default=None,
        help="environment lighting: the built-in 'studio' (default) or a lat-long EXR file",
    )
    light.add_argument(
        "--light",
        metavar="dir:THETA,PHI[,E]",
        action="append",
        default=None,
        help="directional light instead of an environment, angles in degrees: THETA from the "
        "camera axis, PHI from image right counter-clockwise; E the irradiance (default 1); "
        "repeat for several",
    )
    p.add_argument(
        "--env-scale",
        type=float,
        default=1.0,
        help="multiplies the environment radiance (default 1)",
    )
    p.add_argument("--spp", type=int, default=64, help="samples per pixel (default 64)")
    p.add_argument("--resolution", type=int, default=256, help="image size in pixels (256)")
    p.add_argument(
        "--sampler",
        default="auto",
        choices=("auto", "mis", "brdf", "cosine", "inversion", "alias", "rejection", "light"),
        help="BRDF sampling strategy (default auto: MIS of light sampling with the material's "
        "own sampler; tables by tabulated inversion)",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument(
        "--out", default="compare.png", help="comparison figure (PNG/PDF/SVG; default compare.png)"
    )
    p.add_argument(
        "--no-images", action="store_true", help="write only the figure, no per-image EXR/PNG"
    )
    p.add_argument("--json", action="store_true", help="print the error numbers as JSON")
    from gonio import compile_cache

    compile_cache.add_argument(p)
    p.set_defaults(func=run)


def _lights(args: argparse.Namespace) -> list[Any]:
    from gonio.render.lights import Environment

    if args.light:
        return [parse_light(s) for s in args.light]
    env = args.env or "studio"
    if env != "studio" and not Path(env).is_file():
        raise ParameterError(f"--env: no such file {env!r} (or use 'studio')")
    return [Environment(env, scale=args.env_scale)]


def run(args: argparse.Namespace) -> int:
    """Execute ``gonio render``; returns the exit status."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    from gonio.render.compare import compare_images, comparison_figure
    from gonio.render.integrator import render_sphere
    from gonio.render.output import auto_exposure, write_exr, write_png

    if not args.measured and not args.fitted:
        raise ParameterError("give --measured TABLE and/or --fitted FIT.json")
    if args.spp < 1:
        raise ParameterError(f"--spp must be >= 1, got {args.spp}")
    if not 8 <= args.resolution <= 4096:
        raise ParameterError(f"--resolution must be in [8, 4096], got {args.resolution}")
    out = Path(args.out)
    lights = _lights(args)
    items: list[tuple[str, Any]] = []
    if args.measured:
        items.append(("measured", load_table(args.measured)))
    for f in args.fitted:
        items.append((Path(f).name.removesuffix(".json"), load_fit_model(f)))

    images: dict[str, np.ndarray] = {}
    with Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TextColumn("{task.percentage:>3.0f}%"),
        TimeRemainingColumn(),
        transient=True,
        disable=not sys.stderr.isatty(),
        console=None,
    ) as bar:
        for label, material in items:
            task = bar.add_task(f"render {label}", total=1.0)

            def progress(done: int, total: int, task=task) -> None:
                bar.update(task, completed=done / max(total, 1))

            sampler = args.sampler
            if sampler in ("inversion", "alias", "rejection") and not hasattr(material, "values"):
                sampler = "auto"  # table methods apply to the measured table only
            images[label] = render_sphere(
                material,
                lights,
                resolution=args.resolution,
                spp=args.spp,
                sampler=sampler,
                seed=args.seed,
                progress=progress,
            )
            bar.update(task, completed=1.0)

    report: dict[str, Any] = {"out": str(out), "spp": args.spp, "images": {}}
    reference = images.get("measured")
    exposure = auto_exposure(reference if reference is not None else next(iter(images.values())))
    if not args.no_images:
        for label, img in images.items():
            stem = out.with_name(f"{out.stem}-{label}")
            write_exr(stem.with_suffix(".exr"), img)
            write_png(stem.with_suffix(".png"), img, exposure)
            report["images"][label] = str(stem.with_suffix(".exr"))
    if reference is not None and len(images) > 1:
        fitted = [(k, v) for k, v in images.items() if k != "measured"]
        exp, comps = compare_images(reference, fitted)
        comparison_figure(out, reference, comps, exp, title=f"{Path(args.measured).name}")
        report["errors"] = {c.label: c.errors.as_dict() for c in comps}
    else:
        # One rendering: the figure is its tone-mapped image.
        write_png(out, next(iter(images.values())), exposure)
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        for label, e in report.get("errors", {}).items():
            ssim = "n/a" if e["ssim"] is None else f"{e['ssim']:.4f}"
            print(f"{label}: RMSE {e['rmse']:.4g}  relMSE {e['rel_mse']:.4g}  SSIM {ssim}")
        print(f"wrote {out}")
    return 0
