"""Registry and generator of the published JSON Schemas in ``data-schema/``.

Each schema is produced by a function that lives next to the code it describes and is registered
under its file name. Adding one is a one-liner in the owning module::

    from gonio.io.schemas import register_schema

    @register_schema("rig.schema.json")
    def rig_schema() -> dict: ...

The generator imports the modules in :data:`SCHEMA_MODULES` (a listed module that does not
exist is skipped); a new schema's owner appends its module's name.
``python -m gonio.io.schemas --write`` regenerates every file; ``--check`` (and the test suite)
fails when a committed copy differs from what the code generates.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Callable
from pathlib import Path

from gonio.io.strict_json import dumps_json

#: Modules whose import registers schemas (append yours; the generator imports each one).
SCHEMA_MODULES: tuple[str, ...] = (
    "gonio.io.native_schema",  # table-metadata.schema.json
    "gonio.rigs.schema",  # rig.schema.json (owned by rigs)
    "gonio.io.fit_result",  # fit-result.schema.json
    "gonio.io.prior_file",  # prior-metadata.schema.json
)

#: JSON Schema dialect of every generated schema.
DIALECT = "https://json-schema.org/draft/2020-12/schema"

_REGISTRY: dict[str, Callable[[], dict]] = {}


def register_schema(filename: str) -> Callable[[Callable[[], dict]], Callable[[], dict]]:
    """Decorator registering a zero-argument function that returns the schema ``filename``."""
    if not filename.endswith(".schema.json"):
        raise ValueError(f"schema file names end in .schema.json, got {filename!r}")

    def deco(fn: Callable[[], dict]) -> Callable[[], dict]:
        _REGISTRY[filename] = fn
        return fn

    return deco


def generate_all() -> dict[str, dict]:
    """Import :data:`SCHEMA_MODULES` and return ``{file name: schema}`` for every registration."""
    for name in SCHEMA_MODULES:
        try:
            importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name != name:  # the module exists but one of its imports is missing
                raise
    out = {}
    for filename, fn in sorted(_REGISTRY.items()):
        schema = dict(fn())
        schema.setdefault("$schema", DIALECT)
        out[filename] = schema
    return out


def render(schema: dict) -> str:
    """The exact text committed for ``schema`` (stable key order, two-space indent, newline)."""
    return (
        dumps_json(
            schema,
            nonfinite="refuse",
            source="schema",
            indent=2,
            sort_keys=False,
            ensure_ascii=False,
        )
        + "\n"
    )


def default_dir() -> Path:
    """``data-schema/`` of the source checkout this module belongs to."""
    return Path(__file__).resolve().parents[3] / "data-schema"


def stale(folder: Path | None = None) -> list[str]:
    """Names of schema files in ``folder`` that are missing or differ from the generated text."""
    folder = folder or default_dir()
    bad = []
    for filename, schema in generate_all().items():
        path = folder / filename
        if not path.exists() or path.read_text(encoding="utf-8") != render(schema):
            bad.append(filename)
    return bad


def write_all(folder: Path | None = None) -> list[Path]:
    """(Re)write every registered schema into ``folder``; returns the paths written."""
    from gonio.io._common import atomic_output

    folder = folder or default_dir()
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for filename, schema in generate_all().items():
        with atomic_output(folder / filename) as tmp:
            tmp.write_text(render(schema), encoding="utf-8")
        written.append(folder / filename)
    return written


def main(argv: list[str] | None = None) -> int:
    """``python -m gonio.io.schemas [--write | --check] [--dir DIR]``."""
    parser = argparse.ArgumentParser(
        prog="python -m gonio.io.schemas",
        description="Generate the JSON Schemas in data-schema/ from the code's definitions.",
    )
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--write", action="store_true", help="rewrite the schema files")
    mode.add_argument(
        "--check", action="store_true", help="exit 1 if a committed schema is stale (default)"
    )
    parser.add_argument("--dir", type=Path, default=None, help="folder (default: data-schema/)")
    args = parser.parse_args(argv)
    if args.write:
        for p in write_all(args.dir):
            print(p)
        return 0
    bad = stale(args.dir)
    for name in bad:
        print(f"stale: {name} (run python -m gonio.io.schemas --write)", file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":  # pragma: no cover
    # run the package's instance of this module: registrations land in *its* registry,
    # not in the copy that ``python -m`` executes as __main__
    from gonio.io.schemas import main as _main

    sys.exit(_main())
