"""The ``gonio`` command line.

Each subcommand lives with its subpackage: a module listed in :data:`COMMAND_MODULES` exposes
``register(subparsers)`` which adds its parser and sets ``func`` (taking the parsed namespace,
returning an exit status). This module only dispatches and turns :class:`gonio.errors.GonioError`
into one line on stderr and a non-zero exit status.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from gonio import __version__
from gonio.errors import GonioError

#: Modules that contribute subcommands, in the order they appear in ``--help``.
COMMAND_MODULES: tuple[str, ...] = (
    "gonio.io.cli",
    "gonio.rigs.cli",
    "gonio.acquire.cli",
    "gonio.fit.cli",
    "gonio.render.cli",
    "gonio.demo.cli",
    "gonio.export.cli",
)


def build_parser() -> argparse.ArgumentParser:
    """Build the top-level parser with every registered subcommand."""
    parser = argparse.ArgumentParser(
        prog="gonio",
        description=(
            "gonio: measured-BRDF pipeline. Drive a gonioreflectometer, store tabulated BRDFs, "
            "fit analytic models with uncertainty and render comparisons. "
            "Run 'gonio COMMAND --help' for each command's options."
        ),
    )
    parser.add_argument("--version", action="version", version=f"gonio {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``gonio`` console script; returns the process exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    func = getattr(args, "func", None)
    if func is None:
        parser.print_help()
        return 0
    if hasattr(args, "no_compile_cache"):  # commands that compile JAX kernels
        from gonio import compile_cache

        compile_cache.from_args(args)
    try:
        return int(func(args) or 0)
    except GonioError as exc:
        print(f"gonio: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("gonio: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
