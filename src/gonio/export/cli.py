"""``gonio export FIT.json --to TARGET``: a fit as a renderer's material."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from gonio.errors import ParameterError
from gonio.io.atomic import same_file
from gonio.io.strict_json import dumps_json

#: ``gonio export``'s one-line help (``gonio --help`` shows it without importing this module).
HELP = "write a fit as a renderer's material (gonio export --help lists the targets)"

EPILOG_HEAD = """\
targets and parameter mapping (gonio's alpha is its microfacet roughness; models in brackets
are the families a target expresses exactly):
"""

EPILOG_TAIL = """\
what is refitted: any fit outside the target's families in brackets (Ward, Phong, Blinn-Phong,
Oren-Nayar, HTSG, Lafortune, Ashikhmin-Shirley, V-cavity shadowing, a distribution, Fresnel
term or form of sum the target lacks, a Lambert-only fit where none is listed). The family is
then fitted with gonio.fit under the original fit's metric and angle cutoff to the measurement
file recorded in the fit (data.path), or, when that file is gone, to the fitted model sampled on
a dense half/difference grid; the output reports the refit loss next to the original fit's loss.
Layered materials (Mitsuba roughplastic/principled, pbrt coateddiffuse, OpenPBR's dielectric
base) are not used: no gonio model expresses them, so they could be neither exact nor refitted.
Spectral fits are exported in linear sRGB (CIE 1931, D65; gonio.io.spectral); their indices of
refraction are refitted on the RGB-converted data.

Without --out the main file is printed on stdout and the summary on stderr; with --json the
summary (mapping, target parameters, refit losses, notes) is printed as JSON on stdout.
"""


TABLE_HEAD = """\
family x target (gonio.export.table): exact = the target's stock BSDF evaluates the fitted f;
plugin (refit N) = exact through the gonio Mitsuba plugin (--plugin), refit N without it;
refit N = the target's family is refitted to the fit's data, for reason N below, and the export
states its price (both losses and the appearance score of export and fit against the
measurement) on the terminal, in --json and as a comment in the written file:
"""


def epilog(targets: dict[str, Any]) -> str:
    """``gonio export --help``'s text below the options: each target's ``HELP`` entry, the
    family x target table, then what is refitted and how."""
    from gonio.export import table

    rows = []
    for name, mod in targets.items():
        first, *rest = mod.HELP.strip("\n").split("\n")
        rows.append(f"  {name:<9} {first}")
        rows += [f"{'':12}{line}" for line in rest]
    return (
        EPILOG_HEAD + "\n" + "\n".join(rows) + "\n\n" + TABLE_HEAD + "\n" + table.text()
        + "\n\n" + EPILOG_TAIL
    )  # fmt: skip


def register(subparsers: Any) -> None:
    """Add ``gonio export`` to the top-level parser."""
    from gonio.export import registry

    targets = registry.targets()
    p = subparsers.add_parser(
        "export",
        help=HELP,
        description=(
            "Write a fit result (from 'gonio fit') as a renderer's material. Parameters are\n"
            "exact where the target has the fitted model family; otherwise the target's family\n"
            "is refitted to the fit's own data and both losses are reported. Nothing is\n"
            "written when the input is bad."
        ),
        epilog=epilog(targets),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("fit", metavar="FIT.json", help="fit result JSON written by 'gonio fit'")
    p.add_argument(
        "--to",
        required=True,
        metavar="TARGET",
        help=f"{registry.listing(list(targets))} (see below)",
    )
    p.add_argument(
        "--out",
        metavar="FILE",
        help="output file; its suffix is replaced by the target's (Mitsuba writes FILE.xml and "
        "FILE.json). Default: print the main file on stdout",
    )
    p.add_argument(
        "--refit-from",
        default="auto",
        metavar="auto|measurement|model",
        help="data of a refit: the recorded measurement file, else the sampled model (auto, "
        "default); only the measurement (an error when it is gone); only the sampled model",
    )
    p.add_argument(
        "--plugin",
        action="store_true",
        help="with --to mitsuba: write a fragment for gonio's Mitsuba BSDF plugin, exact for "
        "every RGB fit (the renderer's process must import gonio and call "
        "gonio.export.mitsuba_plugin.register()); default: Mitsuba's stock BSDFs",
    )
    p.add_argument(
        "--no-price",
        action="store_true",
        help="skip the appearance part of a refit's price (sphere images and HDR-FLIP against "
        "the measurement, a few seconds per refit); the losses are still reported",
    )
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=run)


def _summary_lines(e: Any) -> list[str]:
    """The summary: mapping, then the notes (a refit's price first)."""
    return [f"{e.target}: {e.mapping} mapping of {e.family}", *(f"note: {n}" for n in e.notes)]


def _refuse_overwrite(args: argparse.Namespace, suffixes: Any) -> None:
    """ParameterError when a file written for ``--out`` would be one of the inputs."""
    out = Path(args.out)
    main = suffixes[0]
    stem = out.name[: -len(main)] if out.name.endswith(main) else out.stem
    for path in (out.with_name(stem + s) for s in suffixes):
        for src in (args.fit, *([args.refit_from] if args.refit_from else [])):
            if same_file(src, path):
                raise ParameterError(
                    f"--out {args.out} would overwrite the input {src} (as {path}); "
                    "choose another name"
                )


def run(args: argparse.Namespace) -> int:
    """Execute ``gonio export``."""
    from gonio.export import registry

    registry.target(args.to)  # an unknown target is refused before the fit is read
    if not Path(args.fit).is_file():
        raise ParameterError(f"fit file not found: {args.fit}")
    if getattr(args, "plugin", False):
        if args.to != "mitsuba":
            raise ParameterError(f"--plugin is for --to mitsuba, not {args.to}")
        from gonio.export import mitsuba_plugin

        e = mitsuba_plugin.export(args.fit)
    else:
        from gonio.export import export

        if args.out:  # refuse before any refit: the paths depend on the target alone
            _refuse_overwrite(args, registry.target(args.to).SUFFIXES)
        price = not getattr(args, "no_price", False)
        e = export(args.fit, args.to, refit_from=args.refit_from, price=price)
    report = e.to_json()
    if args.out:
        _refuse_overwrite(args, list(e.files))  # the files written (the plugin's too)
        paths = e.write(args.out)
        report["files"] = [str(p) for p in paths]
        if args.json:
            print(dumps_json(report, indent=2))
        else:
            for line in _summary_lines(e):
                print(line)
            for p in paths:
                print(f"wrote {p}")
        return 0
    if args.json:
        report["files"] = e.files
        print(dumps_json(report, indent=2))
    else:
        sys.stdout.write(e.text)
        for line in _summary_lines(e):
            print(line, file=sys.stderr)
    return 0
