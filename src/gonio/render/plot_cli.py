"""``gonio plot``: polar plots, in-plane slices and theta_h-theta_d maps of files and fits."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

from gonio.errors import ParameterError
from gonio.render.output import output_path


def register(subparsers: Any) -> None:
    """Add ``gonio plot`` to the top-level parser."""
    p = subparsers.add_parser(
        "plot",
        help="plot BRDFs without fitting: polar, in-plane and theta_h-theta_d views",
        description=(
            "Plot measured files and fitted models on shared axes: a polar plot and an "
            "in-plane slice (light in the x-z plane at each --theta-i; theta_o signed, positive "
            "toward the mirror direction; f in 1/sr, log scale for the slice, measured samples "
            "near the plane drawn as points) and one theta_h-theta_d map per input side by side "
            "(log10 f at --phi-d, shared colour scale). Inputs are any file gonio reads "
            "(scattered data through the same interpolant as 'gonio render', spectral data as "
            "linear sRGB under D65) and fit JSON files from 'gonio fit'. Colour is shown as one "
            "channel (--channel, default luminance Y)."
        ),
    )
    p.add_argument("inputs", nargs="+", metavar="FILE|FIT.json", help="measured files and fits")
    p.add_argument(
        "--out",
        default="plot.png",
        help="output figure; .png (default plot.png), .svg or .pdf; a folder (ending in /) "
        "gets plot.png inside",
    )
    p.add_argument(
        "--theta-i",
        default="0,30,60",
        metavar="DEG[,DEG...]",
        help="incident polar angles of the slices, degrees (default 0,30,60)",
    )
    p.add_argument(
        "--phi-d", type=float, default=90.0, help="phi_d of the theta_h-theta_d maps, degrees"
    )
    p.add_argument("--channel", choices=("Y", "R", "G", "B"), default="Y", help="channel shown")
    p.add_argument(
        "--kind",
        action="append",
        choices=("polar", "in-plane", "halfdiff"),
        help="which views (repeatable; default all three)",
    )
    p.set_defaults(func=run)


def parse_angles(text: str) -> list[float]:
    try:
        vals = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise ParameterError(
            f"--theta-i must be degrees separated by commas, got {text!r}"
        ) from None
    if not vals or not all(math.isfinite(v) and 0 <= v < 90 for v in vals):
        raise ParameterError(f"--theta-i angles must be in [0, 90) degrees, got {text!r}")
    return vals


def _load(path: str) -> Any:
    from gonio.render.plots import PlotInput

    p = Path(path)
    if not p.exists():
        raise ParameterError(f"file not found: {p}")
    if p.suffix.lower() == ".json":
        from gonio.render.cli import load_fitted

        model, _ = load_fitted(p)
        return PlotInput(p.name.removesuffix(".json"), model, measured=False)
    from gonio import io
    from gonio.brdf.measured import MeasuredSamples
    from gonio.render.measured import renderable

    obj = io.load(p)
    material, _ = renderable(obj)
    samples = None
    if isinstance(obj, MeasuredSamples):
        if obj.channels.kind == "spectral":
            from gonio.render.measured import rgb_samples

            obj = rgb_samples(obj, "D65")
        samples = (obj.wi, obj.wo, obj.values)
    return PlotInput(p.name, material, measured=True, samples=samples)


def run(args: argparse.Namespace) -> int:
    """Execute ``gonio plot``; returns the exit status."""
    out = output_path(args.out)
    angles = parse_angles(args.theta_i)
    if not -360 <= args.phi_d <= 360:
        raise ParameterError("--phi-d must be in [-360, 360] degrees")
    inputs = [_load(p) for p in args.inputs]
    labels = [i.label for i in inputs]
    for i, lbl in enumerate(labels):
        if labels.count(lbl) > 1:
            inputs[i].label = f"{Path(args.inputs[i]).parent.name}/{lbl}"
    from gonio.render.plots import plot_materials

    plot_materials(
        inputs,
        out,
        theta_i_deg=angles,
        phi_d_deg=args.phi_d,
        channel=args.channel,
        kinds=args.kind or ("polar", "in-plane", "halfdiff"),
    )
    print(f"wrote {out}", file=sys.stderr)
    return 0
