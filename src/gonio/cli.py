"""The ``gonio`` command line.

Each subcommand lives with its subpackage: a module listed in :data:`COMMAND_MODULES` exposes
``register(subparsers)`` which adds its parser and sets ``func`` (taking the parsed namespace,
returning an exit status). This module only dispatches and turns :class:`gonio.errors.GonioError`
into one line on stderr and a non-zero exit status.

Start-up is kept short by importing only the module of the command being run: the commands of
the modules named in :data:`LAZY_COMMANDS` appear in ``gonio --help`` with the one-line help
stored there, and their module (with jax, scipy and the rest) is imported only when one of them
is invoked. A module listed in :data:`COMMAND_MODULES` but not in :data:`LAZY_COMMANDS` is
imported eagerly, at start-up.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence

from gonio import interrupts
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
    "gonio.view.cli",
    "gonio.demo.cli",
    "gonio.export.cli",
    "gonio.prior.cli",
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
    "view": (
        "gonio.view.cli",
        "look at measurements and fits interactively in the browser (one self-contained page)",
    ),
    "demo": (
        "gonio.demo.cli",
        "the whole pipeline on the simulated rig: acquire, fit, render, report",
    ),
    "export": (
        "gonio.export.cli",
        "write a fit as a renderer's material (gonio export --help lists the targets)",
    ),
    "prior": (
        "gonio.prior.cli",
        "build a material prior (mean + low-rank basis) from a library of BRDF tables",
    ),
    "reconstruct": (
        "gonio.prior.cli",
        "reconstruct a full table with sigma from sparse samples through a prior",
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
    from gonio import __version__

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


def _one_line(exc: BaseException, default: str = "") -> str:
    """``gonio: message; note; ...`` (notes say, e.g., whether the rig was parked)."""
    parts = [str(exc) or default, *getattr(exc, "__notes__", ())]
    return "gonio: " + "; ".join(p for p in parts if p)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``gonio`` console script; returns the process exit status.

    SIGINT and SIGTERM are routed to :data:`gonio.interrupts.FLAG` before any command module
    is imported: an interrupt at any moment is one line on stderr and exit status 128 + signal
    number, never a traceback.
    """
    # signals are only recorded while the command modules are imported (an exception raised
    # inside the import of a native module can abort the interpreter), then checked
    with interrupts.installed(hold=True) as flag:
        return _run(argv, flag)


def _run(argv: Sequence[str] | None, flag: interrupts.StopFlag) -> int:
    try:
        parser = build_parser(_command_of(argv))
        args, _ = parser.parse_known_args(argv)
        lazy = getattr(args, "_lazy", None)
        if lazy is not None:  # the command was not where _command_of looked: import and reparse
            parser = build_parser(lazy)
        args = parser.parse_args(argv)
        if flag.requested:
            raise flag.interrupted()
        # a command that checks the flag itself (acquire) keeps the hold; others may be
        # interrupted anywhere from here on
        flag.shield = bool(getattr(args, "checks_interrupts", False))
        func = getattr(args, "func", None)
        if func is None:
            parser.print_help()
            return 0
        if hasattr(args, "no_compile_cache"):  # commands that compile JAX kernels
            from gonio import compile_cache

            compile_cache.from_args(args)
        status = int(func(args) or 0)
        sys.stdout.flush()  # a closed pipe shows here, not in the interpreter's exit
        if flag.requested:
            raise flag.interrupted()
        return status
    except BrokenPipeError:
        # the reader went away (`gonio plan ... | head`): stop quietly, as a program killed
        # by SIGPIPE would; stdout goes to /dev/null so the final flush cannot fail again
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 128 + 13
    except GonioError as exc:
        print(_one_line(exc), file=sys.stderr)
        return exc.exit_code
    except OSError as exc:
        # the system refused a file operation (a read-only or full disk, a file where a folder
        # is needed): the path and the reason are the whole story; atomic writers leave nothing
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"gonio: {where}{exc.strerror or exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as exc:
        print(_one_line(exc, "interrupted"), file=sys.stderr)
        return 128 + int(getattr(exc, "signum", 2))


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
