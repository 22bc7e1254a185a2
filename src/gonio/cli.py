"""The ``gonio`` command line.

Each subcommand lives with its subpackage: a module listed in :data:`COMMAND_MODULES` exposes
``register(subparsers)`` which adds its parser and sets ``func`` (taking the parsed namespace,
returning an exit status). This module only dispatches and turns :class:`gonio.errors.GonioError`
into one line on stderr and a non-zero exit status.
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
    from gonio import __version__

    parser.add_argument("--version", action="version", version=f"gonio {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
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
        parser = build_parser()
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
    except KeyboardInterrupt as exc:
        print(_one_line(exc, "interrupted"), file=sys.stderr)
        return 128 + int(getattr(exc, "signum", 2))


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
