"""MkDocs hook: the CLI reference, generated from gonio's argparse parsers.

A page holding the line ``<!-- cli-reference -->`` gets it replaced by the ``--help`` text of
``gonio`` and of every subcommand (nested ones too), as ``format_help()`` prints it. Nothing is
copied by hand, so the reference cannot drift from the parsers.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

MARKER = "<!-- cli-reference -->"
SRC = Path(__file__).resolve().parents[2] / "src"


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _sections(parser: argparse.ArgumentParser, prog: str, level: int) -> list[str]:
    out = [f"{'#' * level} `{prog}`", "", "```text", parser.format_help().rstrip(), "```", ""]
    for name, sub in _subcommands(parser).items():
        out += _sections(sub, f"{prog} {name}", min(level + 1, 4))
    return out


def cli_reference() -> str:
    """The Markdown of every command's help, top-level first."""
    if str(SRC) not in sys.path:
        sys.path.insert(0, str(SRC))
    os.environ["COLUMNS"] = "100"  # argparse wraps to the terminal width; fix it
    from gonio.cli import build_parser

    return "\n".join(_sections(build_parser("*"), "gonio", 2))


def on_page_markdown(markdown: str, page, config, files) -> str:
    """Replace the marker with the generated reference."""
    if MARKER in markdown:
        return markdown.replace(MARKER, cli_reference())
    return markdown
