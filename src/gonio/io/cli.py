"""``gonio info`` and ``gonio convert``: inspect and convert BRDF files."""

from __future__ import annotations

import argparse
import os
import sys
from typing import Any

from gonio.errors import ParameterError
from gonio.io.atomic import same_file
from gonio.io.strict_json import dumps_json


def register(subparsers: Any) -> None:
    """Add the ``info`` and ``convert`` subcommands."""
    p = subparsers.add_parser(
        "info",
        help="describe a BRDF file",
        description="Describe a BRDF file (native .brdf.h5, MERL .binary, RGL .bsdf, Cornell "
        ".brdf, ALTA): kind, grid, channels, valid fraction, value range (1/sr), provenance, "
        "size on disk and compression ratio. The format is detected from the content.",
    )
    p.add_argument("file", help="file to describe")
    p.add_argument("--json", action="store_true", help="print machine-readable JSON")
    p.set_defaults(func=cmd_info)

    c = subparsers.add_parser(
        "convert",
        help="convert between BRDF formats",
        description="Convert a BRDF file. The input format is detected from its content; the "
        "output format comes from OUT's extension: .brdf.h5 (native HDF5), .binary (MERL, RGB "
        "tables; other grids are resampled), .exr (one image per phi_d slice) or .bsdf (RGL "
        "tensor file for Mitsuba's measured BSDF, from any isotropic table; an RGL input is "
        "copied unchanged). Output is written atomically: on any error nothing is written.",
    )
    c.add_argument("input", metavar="IN", help="input file")
    c.add_argument("output", metavar="OUT", help="output file (.brdf.h5, .binary, .exr or .bsdf)")
    c.add_argument(
        "--lossy",
        metavar="PRECISION",
        default=None,
        help="store values log-quantized with this guaranteed relative error, as a fraction "
        "(0.005) or percent (0.5%%); .brdf.h5 gridded output only. Default: lossless float32.",
    )
    c.add_argument(
        "--color",
        choices=("keep", "rgb"),
        default="keep",
        help="spectral inputs (Cornell): keep the spectrum (default) or convert to linear sRGB "
        "through the CIE 1931 2-degree observer",
    )
    c.add_argument(
        "--illuminant",
        choices=("D65", "E"),
        default="D65",
        help="illuminant for --color rgb (default D65, the sRGB white)",
    )
    c.add_argument(
        "--every",
        type=int,
        default=1,
        metavar="N",
        help=".exr output: keep every N-th phi_d slice (default 1: all)",
    )
    c.add_argument("--quiet", action="store_true", help="no progress bar or summary line")
    c.set_defaults(func=cmd_convert)


def parse_precision(text: str) -> float:
    """``"0.005"`` or ``"0.5%"`` -> 0.005; anything else is a :class:`ParameterError`."""
    s = text.strip()
    scale = 0.01 if s.endswith("%") else 1.0
    try:
        value = float(s.rstrip("%")) * scale
    except ValueError:
        raise ParameterError(f"--lossy: not a number: {text!r}") from None
    if not (0.0 < value < 0.5):
        raise ParameterError(f"--lossy must be a relative precision in (0, 0.5), got {text!r}")
    return value


def _fmt_bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.2f} {unit}"
        n /= 1024
    return str(n)


def cmd_info(args: argparse.Namespace) -> int:
    """Print the summary of a file."""
    from gonio.io.summary import summarize

    s = summarize(args.file)
    if args.json:
        print(dumps_json(s, indent=2))
        return 0
    from rich.console import Console
    from rich.table import Table

    t = Table(show_header=False, box=None, pad_edge=False)
    t.add_column(style="bold")
    t.add_column()
    t.add_row("file", s["file"])
    t.add_row("format", s["format"])
    t.add_row("kind", s["kind"])
    if s["kind"] == "gridded":
        g = s["grid"]
        axes = ", ".join(f"{a['name']}[{a['size']}, {a['warp']}]" for a in g["axes"])
        t.add_row("grid", f"{g['parameterization']}: {axes} ({g['interpolation']})")
    elif s["kind"] == "scattered":
        t.add_row("samples", str(s["samples"]))
    else:
        t.add_row("grid", ", ".join(f"{k} {v}" for k, v in s["grid"].items()))
        t.add_row("description", s.get("description", ""))
    ch = s["channels"]
    names = ch["names"] if len(ch["names"]) <= 6 else [*ch["names"][:3], "…", ch["names"][-1]]
    extra = f", {ch['primaries']}/{ch['white_point']}" if ch.get("primaries") else ""
    if ch.get("wavelengths_nm"):
        wl = ch["wavelengths_nm"]
        extra = f", {wl[0]:g}..{wl[-1]:g} nm"
    t.add_row("channels", f"{ch['kind']} ({len(ch['names'])}: {' '.join(names)}{extra})")
    t.add_row("valid fraction", f"{s['valid_fraction']:.4f}")
    r = s["value_range"]
    if r["min"] is not None:
        label = "values (1/sr)" if "value_range_note" not in s else "BRDF values (1/sr)*"
        t.add_row(label, f"min {r['min']:.4g}  max {r['max']:.4g}  mean {r['mean']:.4g}")
    if "stored_range" in s and s["stored_range"]["min"] is not None:
        st = s["stored_range"]
        t.add_row(
            "stored values",
            f"min {st['min']:.4g}  max {st['max']:.4g}  mean {st['mean']:.4g} (file units)",
        )
    if "value_range_note" in s:
        t.add_row("", f"* {s['value_range_note']}")
    if "encoding" in s:
        e = s["encoding"]
        text = e["values"]
        if e["values"] != "float32":
            a = e.get("achieved", {})
            text += (
                f" (bound {e['bound_relative']:.3%}, achieved median "
                f"{a.get('median_relative', float('nan')):.3%}, p99 "
                f"{a.get('p99_relative', float('nan')):.3%})"
            )
        t.add_row("encoding", text)
    t.add_row(
        "size",
        f"{_fmt_bytes(s['size_bytes'])} (compression ratio "
        f"{s['compression_ratio']:.2f} vs float32 in memory)",
    )
    prov = s.get("provenance") or {}
    for k, v in prov.items():
        t.add_row(f"provenance.{k}", dumps_json(v) if not isinstance(v, str) else v)
    Console().print(t)
    return 0


def cmd_convert(args: argparse.Namespace) -> int:
    """Load IN, save OUT; a progress bar covers the slow steps (RGL tabulation, writing)."""
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    from gonio import io
    from gonio.io.detect import detect_format

    lossy = None if args.lossy is None else parse_precision(args.lossy)
    if args.every < 1:
        raise ParameterError("--every must be >= 1")
    if same_file(args.input, args.output):
        raise ParameterError("IN and OUT are the same file")
    out_name = args.output.lower()
    if not out_name.endswith((".h5", ".hdf5", ".binary", ".exr", ".bsdf")):
        raise ParameterError(
            f"{args.output}: unknown output extension (use .brdf.h5, .binary, .exr or .bsdf)"
        )
    if lossy is not None and not out_name.endswith((".h5", ".hdf5")):
        raise ParameterError("--lossy applies to .brdf.h5 output only")
    fmt = detect_format(args.input)
    console = Console(stderr=True)
    progress = Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.percentage:>3.0f}%"),
        TimeRemainingColumn(),
        console=console,
        disable=args.quiet or not console.is_terminal,
        transient=True,
    )
    with progress:
        task = progress.add_task(f"reading {fmt}", total=1)
        if fmt == "rgl" and not out_name.endswith(".bsdf"):
            from gonio.io.rgl_measured import load_rgl

            progress.update(task, description="tabulating RGL BSDF")
            obj = load_rgl(args.input).to_table(
                progress=lambda done, total: progress.update(task, completed=done, total=total)
            )
        else:
            color = "rgb" if args.color == "rgb" else None
            obj = io.load(args.input, color=color, illuminant=args.illuminant)
        progress.update(task, completed=1, total=1)
        wtask = progress.add_task("writing", total=None)
        if out_name.endswith(".exr"):
            from gonio.io.exr import write_table_slices

            write_table_slices(obj, args.output, every=args.every)
        else:
            io.save(obj, args.output, lossy=lossy)
        progress.update(wtask, total=1, completed=1)
    if not args.quiet:
        archive = args.input.rpartition("::")[0] or args.input  # ARCHIVE.zip::NAME
        size_in, size_out = os.path.getsize(archive), os.path.getsize(args.output)
        print(
            f"wrote {args.output} ({_fmt_bytes(size_out)}; input {_fmt_bytes(size_in)})",
            file=sys.stderr,
        )
    return 0
