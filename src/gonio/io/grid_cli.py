"""``gonio grid``: scattered samples (a run's table, ALTA, Cornell) onto a half/diff grid."""

from __future__ import annotations

import argparse
import os
import sys
from typing import Any

from gonio.errors import ParameterError
from gonio.io.atomic import same_file

DEFAULT_RES = (16, 15, 12)


def register(subparsers: Any) -> None:
    """Add ``gonio grid`` to the top-level parser."""
    p = subparsers.add_parser(
        "grid",
        help="grid scattered samples into a half/diff table with coverage mask and sigma",
        description=(
            "Tabulate scattered BRDF samples (RUN/table.brdf.h5 from 'gonio acquire', ALTA, "
            "Cornell, or any native scattered file) on an isotropic half/diff grid "
            "(theta_h sqrt-warped, theta_d linear, phi_d over [0, 180) deg, folded by "
            "reciprocity) and write it as a native gridded .brdf.h5 with a coverage mask, sigma "
            "and counts. --method bin (default) is what a run's /gridded group holds: the "
            "inverse-variance mean of the samples in each cell, sigma 1/sqrt(sum of weights), "
            "cells without samples masked invalid. --method interp tabulates the log-linear "
            "Delaunay interpolant of the samples (gonio.brdf.gridding): mask = nodes inside the "
            "samples' convex hull, sigma propagated through the interpolation weights; the "
            "nodes outside keep the nearest sample's value as an extrapolation (a filled table, "
            "/mask attribute invalid_values = extrapolated), which gonio's lookups ignore and "
            "the RGL writer (gonio convert OUT x.bsdf) uses beyond the coverage."
        ),
    )
    p.add_argument("input", metavar="IN", help="scattered BRDF file (e.g. RUN/table.brdf.h5)")
    p.add_argument("output", metavar="OUT", help="gridded output (.brdf.h5); must not exist")
    p.add_argument(
        "--res",
        metavar="NTH,NTD,NPD",
        default=",".join(str(n) for n in DEFAULT_RES),
        help="nodes along theta_h, theta_d and phi_d (default 16,15,12, the grid of a run's "
        "/gridded group); one number N means N,N,N",
    )
    p.add_argument(
        "--method",
        choices=("bin", "interp"),
        default="bin",
        help="bin (default): cell means, uncovered cells masked; interp: scattered-data "
        "interpolant, mask = convex hull of the samples",
    )
    p.add_argument("--force", action="store_true", help="replace OUT if it exists")
    p.set_defaults(func=cmd_grid)


def parse_res(text: str) -> tuple[int, int, int]:
    """``"16,15,12"`` or ``"32"`` -> node counts; a :class:`ParameterError` otherwise."""
    parts = [x.strip() for x in text.split(",")]
    try:
        nums = [int(x) for x in parts]
    except ValueError:
        raise ParameterError(f"--res must be integers NTH,NTD,NPD, got {text!r}") from None
    if len(nums) == 1:
        nums = nums * 3
    if len(nums) != 3 or min(nums) < 1 or max(nums) > 1024:
        raise ParameterError(f"--res needs 1 or 3 integers in [1, 1024], got {text!r}")
    return nums[0], nums[1], nums[2]


def cmd_grid(args: argparse.Namespace) -> int:
    """Execute ``gonio grid``; returns the exit status."""
    res = parse_res(args.res)
    if not args.output.lower().endswith((".h5", ".hdf5")):
        raise ParameterError(f"{args.output}: the output must be a .brdf.h5 file")
    if not os.path.exists(args.input):
        raise ParameterError(f"file not found: {args.input}")
    if same_file(args.input, args.output):
        raise ParameterError("IN and OUT are the same file")
    if os.path.isdir(args.output):
        raise ParameterError(f"{args.output} is a folder; give a .brdf.h5 file name")
    if os.path.exists(args.output) and not args.force:
        raise ParameterError(f"{args.output} exists (use --force to replace it)")
    from gonio import io
    from gonio.brdf import gridding
    from gonio.brdf.measured import MeasuredSamples

    obj = io.load(args.input)
    if not isinstance(obj, MeasuredSamples):
        raise ParameterError(
            f"{args.input} holds a gridded table, not scattered samples (use 'gonio convert')"
        )
    if len(obj) == 0:
        raise ParameterError(f"{args.input} holds no samples")
    axes = gridding.default_grid(*res)
    if args.method == "bin":
        table = gridding.grid_samples(obj, axes)
    else:
        table = gridding.interpolate_samples(obj, axes)
    io.save(table, args.output)
    covered = int(table.mask.sum())
    print(
        f"wrote {args.output}: {len(obj)} samples -> {'x'.join(str(n) for n in res)} grid "
        f"({args.method}), {covered}/{table.mask.size} nodes covered",
        file=sys.stderr,
    )
    return 0
