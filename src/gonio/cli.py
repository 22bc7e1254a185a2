"""The ``gonio`` command line.

Each subcommand lives with its subpackage: a module listed in :data:`COMMAND_MODULES` exposes
``register(subparsers)`` which adds its parser and sets ``func`` (taking the parsed namespace,
returning an exit status). This module only dispatches and turns :class:`gonio.errors.GonioError`
into one line on stderr and a non-zero exit status.

Start-up is kept short by importing only the module of the command being run: the commands of
the modules named in :data:`LAZY_COMMANDS` appear in ``gonio --help`` with the one-line help
stored there, and their module (with jax, scipy and the rest) is imported only when one of them
is invoked. A module listed in :data:`COMMAND_MODULES` but not in :data:`LAZY_COMMANDS` is
imported eagerly, as before.
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
    "gonio.io.grid_cli",
    "gonio.rigs.cli",
    "gonio.acquire.cli",
    "gonio.fit.cli",
    "gonio.render.cli",
    "gonio.render.plot_cli",
    "gonio.demo.cli",
)

#: command -> (module that registers it, its one-line help as that module states it); a test
#: checks that the help here matches the module's.
LAZY_COMMANDS: dict[str, tuple[str, str]] = {
    "info": ("gonio.io.cli", "describe a BRDF file"),
    "convert": ("gonio.io.cli", "convert between BRDF formats"),
    "grid": (
        "gonio.io.grid_cli",
        "grid scattered samples into a half/diff table with coverage mask and sigma",
    ),
    "rig": (
        "gonio.rigs.cli",
        "inspect a rig: check its servos, print the rig-file schema, run its bus emulator",
    ),
    "plan": (
        "gonio.acquire.cli",
        "dry-run an acquisition plan: count, predicted motion and time, refused poses",
    ),
    "acquire": ("gonio.acquire.cli", "run (or resume) an acquisition on a rig"),
    "fit": ("gonio.fit.cli", "fit analytic BRDF models (with uncertainty) to measured files"),
    "render": ("gonio.render.cli", "render measured and fitted spheres; write a comparison figure"),
    "plot": (
        "gonio.render.plot_cli",
        "plot BRDFs without fitting: polar, in-plane and theta_h-theta_d views",
    ),
    "demo": (
        "gonio.demo.cli",
        "the whole pipeline on the simulated rig: acquire, fit, render, report",
    ),
}


def _command_of(argv: Sequence[str] | None) -> str | None:
    """The subcommand named on the command line (the first argument not starting with '-')."""
    args = sys.argv[1:] if argv is None else list(argv)
    for a in args:
        if not a.startswith("-"):
            return a
    return None


def build_parser(command: str | None = "*") -> argparse.ArgumentParser:
    """Build the top-level parser.

    ``command`` is the subcommand that will run: only its module is imported, the others are
    listed with their help from :data:`LAZY_COMMANDS`. ``"*"`` (default) imports every module.
    """
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
        lazy = [c for c, (m, _) in LAZY_COMMANDS.items() if m == name]
        if not lazy or command == "*" or command in lazy:
            importlib.import_module(name).register(sub)
            continue
        for c in lazy:
            stub = sub.add_parser(c, help=LAZY_COMMANDS[c][1], add_help=False)
            stub.set_defaults(_lazy=c)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``gonio`` console script; returns the process exit status."""
    parser = build_parser(_command_of(argv))
    args, _ = parser.parse_known_args(argv)
    lazy = getattr(args, "_lazy", None)
    if lazy is not None:  # the command was not where _command_of looked: import it and reparse
        parser = build_parser(lazy)
    args = parser.parse_args(argv)
    func = getattr(args, "func", None)
    if func is None:
        parser.print_help()
        return 0
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
