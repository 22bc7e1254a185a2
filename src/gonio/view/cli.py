"""``gonio view``: measurements and fits as one interactive page (spheres, slices, maps,
coverage, fit parameters); written with ``--out`` or served on 127.0.0.1."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from gonio.errors import ParameterError


def register(subparsers: Any) -> None:
    """Add ``gonio view`` to the top-level parser."""
    p = subparsers.add_parser(
        "view",
        help="look at measurements and fits interactively in the browser (one self-contained page)",
        description=(
            "Open measured files and fits as one interactive page: spheres rendered in the "
            "browser (WebGL2) from the data itself under a light you drag and/or gonio's studio "
            "environment (refined progressively), with exposure; "
            "in-plane slices at a chosen theta_i (measured samples with sigma error bars, fit "
            "curves; log or linear f in 1/sr); polar plots with a logarithmic radius; "
            "theta_h-theta_d maps at a chosen phi_d; a run's coverage; each fit's parameters, "
            "intervals and loss. Inputs: any file gonio reads (native tables and runs, MERL, "
            "RGL, Cornell, ALTA, ARCHIVE.zip::NAME), a run folder, fit JSON files. With --out "
            "the page is written as one file that needs no network; without it, it is served on "
            "127.0.0.1 at a random-token URL until Ctrl-C and the browser is opened."
        ),
    )
    p.add_argument("inputs", nargs="+", metavar="FILE|RUN|FIT.json", help="files and fits")
    p.add_argument("--out", metavar="PAGE.html", help="write the page here instead of serving it")
    p.add_argument(
        "--port", type=int, default=0, help="port to serve on (default: a free one); 127.0.0.1 only"
    )
    p.add_argument("--no-browser", action="store_true", help="serve without opening a browser")
    from gonio import compile_cache

    compile_cache.add_argument(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``gonio view``; returns the exit status."""
    if not 0 <= args.port <= 65535:
        raise ParameterError(f"--port must be in 0..65535, got {args.port}")
    from gonio.view.sources import from_path, unique_labels

    sources = [from_path(p) for p in args.inputs]  # every input read before any output
    unique_labels(sources)
    if args.out:
        from gonio.view.page import write_page

        out = write_page(sources, args.out)
        print(f"wrote {out}", file=sys.stderr)
        return 0
    from gonio.view.page import build_page
    from gonio.view.server import serve

    serve(build_page(sources), port=args.port, open_browser=not args.no_browser)
    return 0
