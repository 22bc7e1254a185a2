"""docs/design.md describes the code as it is.

Two checks read the design document: every path its ``layout`` block names exists under
``src/gonio`` and every module there is named (or lies in a package the block names as a whole),
and every rule of its ``dependencies`` block holds over the import graph, read with ``ast`` as
``../shared/tools/structure.py`` reads it (imports inside functions count).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src"
DESIGN = ROOT / "docs" / "design.md"


def _block(kind: str) -> list[str]:
    """The lines of the fenced block ```KIND in docs/design.md."""
    text = DESIGN.read_text(encoding="utf-8")
    m = re.search(rf"^```{kind}\n(.*?)^```", text, re.M | re.S)
    assert m, f"docs/design.md has no ```{kind} block"
    return m.group(1).splitlines()


def _layout() -> tuple[set[str], set[str]]:
    """(paths named in the layout, packages named without their modules), relative to src/."""
    named: dict[str, bool] = {}  # path -> is a package
    stack: list[tuple[int, str]] = []
    for line in _block("layout"):
        if not line.strip():
            continue
        indent = len(line) - len(line.lstrip(" "))
        name = line.split()[0]
        while stack and stack[-1][0] >= indent:
            stack.pop()
        path = "/".join([p for _, p in stack] + [name.rstrip("/")])
        named[path] = name.endswith("/")
        if name.endswith("/"):
            stack.append((indent, name.rstrip("/")))
    packages = {p for p, is_pkg in named.items() if is_pkg}
    whole = {p for p in packages if not any(q.startswith(p + "/") for q in named)}
    return set(named), whole


def test_every_path_in_the_layout_exists():
    named, _ = _layout()
    missing = sorted(p for p in named if not (SRC / p).exists())
    assert not missing, f"docs/design.md names paths that do not exist under src/: {missing}"


def test_every_module_is_in_the_layout():
    named, whole = _layout()
    unnamed = []
    for path in sorted((SRC / "gonio").rglob("*.py")):
        rel = path.relative_to(SRC).as_posix()
        if path.name.startswith("__") or rel in named:
            continue
        if any(rel.startswith(p + "/") for p in whole):
            continue
        unnamed.append(rel)
    assert not unnamed, f"modules missing from docs/design.md's layout: {unnamed}"


def _modules() -> dict[str, Path]:
    mods = {}
    for path in (SRC / "gonio").rglob("*.py"):
        rel = path.relative_to(SRC).with_suffix("").as_posix().replace("/", ".")
        mods[rel.removesuffix(".__init__")] = path
    return mods


def _imports(mods: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the gonio modules it imports (as structure.py resolves them)."""
    edges = {}
    for mod, path in mods.items():
        deps = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                if node.level == 0:
                    base = node.module
                else:
                    pkg = mod.split(".")
                    if path.name != "__init__.py":
                        pkg = pkg[:-1]
                    pkg = pkg[: len(pkg) - (node.level - 1)]
                    base = ".".join(pkg + ([node.module] if node.module else []))
                if not base or not base.startswith("gonio"):
                    continue
                for alias in node.names:
                    full = f"{base}.{alias.name}"
                    deps.add(full if full in mods else base)
            elif isinstance(node, ast.Import):
                deps.update(a.name for a in node.names if a.name.startswith("gonio"))
        edges[mod] = {d for d in deps if d in mods and d != mod}
    return edges


def _rules() -> dict[str, set[str]]:
    rules = {}
    for line in _block("dependencies"):
        line = line.split("#")[0].strip()
        if not line:
            continue
        unit, _, allowed = line.partition(":")
        names = {a.strip() for a in allowed.split(",") if a.strip() not in ("", "-")}
        rules[unit.strip()] = names
    return rules


def _unit(mod: str, rules: dict[str, set[str]]) -> str | None:
    """The rule that governs ``mod``: the longest rule name that is ``mod`` or a parent of it."""
    best = None
    for unit in rules:
        if (mod == unit or mod.startswith(unit + ".")) and (best is None or len(unit) > len(best)):
            best = unit
    return best


def test_every_module_has_a_dependency_rule():
    rules = _rules()
    ungoverned = sorted(m for m in _modules() if m != "gonio" and _unit(m, rules) is None)
    assert not ungoverned, f"modules no rule of docs/design.md governs: {ungoverned}"


def test_the_rules_name_modules_that_exist():
    mods = _modules()
    rules = _rules()
    named = set(rules) | set().union(*rules.values())
    assert not sorted(n for n in named if n not in mods)


@pytest.mark.parametrize("unit", sorted(_rules()))
def test_dependency_rule_holds(unit):
    rules = _rules()
    mods = _modules()
    broken = []
    for mod, deps in _imports(mods).items():
        if _unit(mod, rules) != unit:
            continue
        for dep in sorted(deps):
            target = _unit(dep, rules)
            if dep == "gonio" or target == unit or target in rules[unit]:
                continue
            broken.append(f"{mod} imports {dep}")
    assert not broken, f"{unit} may import only {sorted(rules[unit])}: {broken}"
