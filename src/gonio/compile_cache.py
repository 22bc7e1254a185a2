"""Persistent JAX compilation cache for the command-line entry points.

Compiling the render and fit kernels takes seconds to tens of seconds on a small CPU; XLA can
store compiled executables on disk and reuse them in the next process (JAX's persistent
compilation cache). The ``gonio render``, ``gonio fit`` and ``gonio demo`` commands turn it on
through :func:`enable`; importing :mod:`gonio` never does (a library must not write to the user's
cache directory behind the caller's back). A library user can call :func:`enable` themselves.

Where the cache lives (platformdirs' "user cache dir" convention, without the dependency):

- ``$XDG_CACHE_HOME/gonio/jax`` when ``XDG_CACHE_HOME`` is set (any OS),
- ``~/Library/Caches/gonio/jax`` on macOS,
- ``%LOCALAPPDATA%\\gonio\\Cache\\jax`` on Windows,
- ``~/.cache/gonio/jax`` otherwise.

Turning it off: the commands' ``--no-compile-cache`` flag, or the environment variable
``GONIO_COMPILE_CACHE`` set to ``0``, ``false``, ``no`` or ``off``. Any other non-empty value of
``GONIO_COMPILE_CACHE`` is taken as the cache directory. The cache is safe to delete at any time;
JAX keys entries by the program, the JAX/XLA version and the device, so a stale entry is never
used, and JAX bounds nothing by default, so the directory grows with every distinct kernel (a few
MB per kernel).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

ENV_VAR = "GONIO_COMPILE_CACHE"
_OFF = {"0", "false", "no", "off"}

#: Kernels that compile faster than this are not written (JAX's default is 1 s; the render
#: stages each take 0.2-2 s to compile here, and together they are the time to a first image).
MIN_COMPILE_SECONDS = 0.1


def default_cache_dir() -> Path:
    """The per-user cache directory for compiled kernels (see the module docstring)."""
    xdg = os.environ.get("XDG_CACHE_HOME")
    if xdg:
        return Path(xdg) / "gonio" / "jax"
    if sys.platform == "darwin":
        return Path.home() / "Library" / "Caches" / "gonio" / "jax"
    if sys.platform == "win32":
        base = os.environ.get("LOCALAPPDATA") or str(Path.home() / "AppData" / "Local")
        return Path(base) / "gonio" / "Cache" / "jax"
    return Path.home() / ".cache" / "gonio" / "jax"


def resolve(disabled: bool = False) -> Path | None:
    """The directory to use, or None when the cache is turned off (flag or environment)."""
    if disabled:
        return None
    value = os.environ.get(ENV_VAR, "").strip()
    if value.lower() in _OFF:
        return None
    return Path(value).expanduser() if value and value != "1" else default_cache_dir()


def enable(disabled: bool = False) -> Path | None:
    """Point JAX's persistent compilation cache at :func:`resolve`'s directory.

    Returns the directory, or None when the cache is off (then JAX's configuration is left
    as it is). A directory that cannot be created turns the cache off rather than failing the
    command: the cache only saves time.
    """
    path = resolve(disabled)
    if path is None:
        return None
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    import jax

    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_SECONDS)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return path


def add_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``--no-compile-cache`` to a command's parser (read back by :func:`from_args`)."""
    parser.add_argument(
        "--no-compile-cache",
        action="store_true",
        help=f"do not keep compiled kernels on disk between runs (default: kept in "
        f"{default_cache_dir()}; also off with {ENV_VAR}=0)",
    )


def from_args(args: Any) -> Path | None:
    """:func:`enable` for a parsed namespace that has ``no_compile_cache``."""
    return enable(bool(getattr(args, "no_compile_cache", False)))
