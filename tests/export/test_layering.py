"""DESIGN.md's dependency rule for gonio.export: it imports brdf, appearance, io and fit, never
render."""

from __future__ import annotations

import ast
from pathlib import Path

import gonio.export

ALLOWED = (
    "gonio.brdf",
    "gonio.appearance",
    "gonio.io",
    "gonio.fit",
    "gonio.errors",
    "gonio.export",
)


def test_export_imports_only_brdf_io_fit():
    root = Path(gonio.export.__file__).parent
    for path in sorted(root.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            for name in names:
                if name == "gonio" or name.startswith("gonio."):
                    assert name.startswith(ALLOWED), f"{path.name} imports {name}"
