"""``gonio render``: render measured and fitted spheres and write a comparison figure."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from gonio.errors import FormatError, ParameterError
from gonio.io.strict_json import dumps_json

#: Largest --spp: 2^16 samples per pixel already takes minutes at 256^2 (3.4e9 samples); the
#: 10^8 of a typo would run for days with no sign of it but the progress bar.
MAX_SPP = 1 << 16
#: --sampler values every material takes (the others name a table's own methods).
_GENERIC_SAMPLERS = ("auto", "mis", "brdf", "cosine", "light")


def load_fitted(path: str | Path, illuminant: str = "D65") -> tuple[Any, list[str]]:
    """``(model, notes)`` of a fit file (:func:`gonio.io.fit_result.load_fit`: a fit result or a
    bare model description), a spectral model projected to linear sRGB
    (:mod:`gonio.render.spectral`) using the wavelengths named in the fit's ``data.channels``."""
    from gonio.io.fit_result import load_fit
    from gonio.io.spectral import wavelengths_from_names
    from gonio.render.spectral import to_rgb

    if not Path(path).is_file():
        raise ParameterError(f"fit file not found: {path}")
    record, model = load_fit(path, descriptions=True)
    c = model.n_channels
    if c in (1, 3):
        return model, []
    names = record.get("data", {}).get("channels")
    wl = wavelengths_from_names(names or ())
    if wl is None or wl.size != c:
        raise FormatError(
            f"{path}: a {c}-channel model without wavelengths in data.channels; cannot show it "
            "in colour"
        )
    note = (
        f"{c} spectral channels ({wl[0]:g}..{wl[-1]:g} nm) shown as linear sRGB under {illuminant}"
    )
    return to_rgb(model, wl, illuminant), [note]


def fitted_labels(paths: list[str]) -> tuple[list[str], list[str]]:
    """Unique image labels for fit files: the file name, prefixed by as many parent folders as
    it takes to tell same-named files apart. Returns (labels, warnings about renamed ones)."""
    resolved = [Path(p).resolve() for p in paths]
    for i, r in enumerate(resolved):
        if r in resolved[:i]:
            raise ParameterError(f"--fitted {paths[i]} is given twice")
    parts = [r.with_suffix("").parts for r in resolved]
    labels = [pt[-1] for pt in parts]
    warnings: list[str] = []
    for name in sorted({lbl for lbl in labels if labels.count(lbl) > 1}):
        group = [i for i, lbl in enumerate(labels) if lbl == name]
        depth = 2
        while len({parts[i][-depth:] for i in group}) < len(group):
            depth += 1
        for i in group:
            labels[i] = "-".join(parts[i][-depth:])
        shown = ", ".join(labels[i] for i in group)
        warnings.append(f"several --fitted files are named {name}.json; labelled {shown}")
    return labels, warnings


def load_table(path: str | Path, illuminant: str = "D65") -> Any:
    """A measured file (any :func:`gonio.io.load` format) as a renderable material.

    Scattered, holey or spectral data is adapted by :func:`gonio.render.measured.renderable`;
    use :func:`load_measured` for the notes saying how.
    """
    return load_measured(path, illuminant)[0]


def load_measured(path: str | Path, illuminant: str = "D65") -> tuple[Any, list[str]]:
    """``(material, notes)`` of a measured file; see :func:`gonio.render.measured.renderable`."""
    p = Path(path)
    if not p.exists():
        raise ParameterError(f"measured table not found: {p}")
    from gonio import io as gio
    from gonio.render.measured import renderable

    return renderable(gio.load(p), illuminant=illuminant)


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
    p.add_argument(
        "--illuminant",
        default="D65",
        choices=("D65", "E"),
        help="spectrum of the lights for spectral data (Cornell files, spectral fits), which is "
        "shown as linear sRGB through CIE 1931 XYZ under it; D65 (default) is sRGB's white, so a "
        "grey BRDF stays grey",
    )
    p.add_argument(
        "--spp", type=int, default=64, help=f"samples per pixel (default 64, at most {MAX_SPP})"
    )
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
        "--out",
        default="compare.png",
        help="comparison figure: .png (default compare.png), .pdf or .svg (other extensions are "
        "refused); a folder (ending in /) gets compare.png inside. Per-image EXR and PNG files "
        "are written next to it",
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
    if env != "studio":
        check_environment_file(env)
    return [Environment(env, scale=args.env_scale)]


def _write_figure_image(out: Path, img: np.ndarray, exposure: float) -> None:
    """A tone-mapped rendering as a PDF or SVG image (matplotlib, atomically)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gonio.io.atomic import atomic_output
    from gonio.render.output import tonemap

    shown = tonemap(img, exposure)
    if shown.shape[-1] == 1:
        shown = np.repeat(shown, 3, axis=-1)
    with atomic_output(out, out.suffix, make_parents=True) as tmp:
        plt.imsave(tmp, np.clip(shown, 0, 1), format=out.suffix.lstrip(".").lower())


def check_environment_file(path: str | Path) -> None:
    """Refuse an EXR that is not a lat-long radiance image: a BRDF slice file written by
    ``gonio convert ... .exr`` (:func:`gonio.io.exr.holds_table_slices`)."""
    from gonio.io.exr import holds_table_slices

    # an unreadable file passes here: the environment loader reports it in its own words
    if str(path).lower().endswith(".exr") and holds_table_slices(path):
        raise ParameterError(
            f"--env {path}: a BRDF slice image (theta_h x theta_d per phi_d, values in 1/sr), "
            "not a lat-long environment map"
        )


class _NoBar:
    """The progress bar's interface, doing nothing (stderr is not a terminal)."""

    def __enter__(self) -> _NoBar:
        return self

    def __exit__(self, *exc: object) -> None:
        return None

    def add_task(self, *args: Any, **kwargs: Any) -> int:
        return 0

    def update(self, *args: Any, **kwargs: Any) -> None:
        return None


def _progress_bar() -> Any:
    """A rich progress bar on a terminal; otherwise :class:`_NoBar`, without importing rich
    (its import would add to the time from a process's start to its first image, which
    ``benchmarks/bench_first_image.py`` measures)."""
    if not sys.stderr.isatty():
        return _NoBar()
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    return Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TextColumn("{task.percentage:>3.0f}%"),
        TimeRemainingColumn(),
        transient=True,
        console=None,
    )


def run(args: argparse.Namespace) -> int:
    """Execute ``gonio render``; returns the exit status."""
    from gonio.render.integrator import render_sphere
    from gonio.render.output import auto_exposure, write_exr, write_png

    if not args.measured and not args.fitted:
        raise ParameterError("give --measured TABLE and/or --fitted FIT.json")
    if not 1 <= args.spp <= MAX_SPP:
        raise ParameterError(f"--spp must be in [1, {MAX_SPP}], got {args.spp}")
    if args.seed < 0:
        raise ParameterError(f"--seed must be >= 0, got {args.seed}")
    if not 8 <= args.resolution <= 4096:
        raise ParameterError(f"--resolution must be in [8, 4096], got {args.resolution}")
    from gonio.render.output import output_path

    out = output_path(args.out, "compare.png")
    lights = _lights(args)
    items: list[tuple[str, Any]] = []
    if args.measured:
        table, notes = load_measured(args.measured, args.illuminant)
        for note in notes:
            print(f"measured: {note}", file=sys.stderr)
        items.append(("measured", table))
    labels, warnings = fitted_labels(list(args.fitted))
    for w in warnings:
        print(f"gonio: warning: {w}", file=sys.stderr)
    for label, f in zip(labels, args.fitted, strict=True):
        model, notes = load_fitted(f, args.illuminant)
        for note in notes:
            print(f"{label}: {note}", file=sys.stderr)
        items.append((label, model))

    images: dict[str, np.ndarray] = {}
    with _progress_bar() as bar:
        for label, material in items:
            task = bar.add_task(f"render {label}", total=1.0)

            def progress(done: int, total: int, task=task) -> None:
                bar.update(task, completed=done / max(total, 1))

            sampler = args.sampler
            if sampler not in (*material.sampling_methods, *_GENERIC_SAMPLERS):
                sampler = "auto"  # a table's methods apply to the measured table only
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

    out.parent.mkdir(parents=True, exist_ok=True)
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
        from gonio.render.compare import compare_images, comparison_figure

        fitted = [(k, v) for k, v in images.items() if k != "measured"]
        exp, comps = compare_images(reference, fitted)
        comparison_figure(out, reference, comps, exp, title=f"{Path(args.measured).name}")
        report["errors"] = {c.label: c.errors.as_dict() for c in comps}
    else:
        # One rendering: the figure is its tone-mapped image, in the format OUT names.
        only = next(iter(images.values()))
        if out.suffix.lower() == ".png":
            write_png(out, only, exposure)
        else:
            _write_figure_image(out, only, exposure)
    if args.json:
        print(dumps_json(report, indent=2))
    else:
        for label, e in report.get("errors", {}).items():
            ssim = "n/a" if e["ssim"] is None else f"{e['ssim']:.4f}"
            print(f"{label}: RMSE {e['rmse']:.4g}  relMSE {e['rel_mse']:.4g}  SSIM {ssim}")
        print(f"wrote {out}")
    return 0
