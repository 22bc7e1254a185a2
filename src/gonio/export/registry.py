"""The export targets: one module each, listed once in :data:`TARGET_MODULES`.

Adding a renderer is one module plus one line here. The module declares itself:

``TARGET``
    the name ``gonio export --to`` and ``gonio.export.to_<TARGET>`` take, e.g. ``"openpbr"``.
``TITLE``
    the renderer and format in a few words, e.g. ``"OpenPBR/MaterialX"``.
``SUFFIXES``
    the suffixes of the files it writes, main file first, e.g. ``(".mtlx",)``.
``HELP``
    its entry of ``gonio export --help``'s table: one line saying what is written, the model
    families expressed exactly in brackets, then the parameter mapping (plain text lines).
``check(lobes) -> str | None``
    None when the target expresses the :class:`~gonio.export._lobes.Lobes` exactly, else why not.
``refit_template(model, lobes) -> (template, fixed, family)``
    the target's family to refit when ``check`` says no.
``build(name, lobes) -> Export``
    the files of representable lobes.

The command line, the Python API (``export(fit, target)``, ``to_<target>``) and the demo read
this registry; nothing else names the targets. A target module imports JAX only inside its
functions, so that ``gonio export --help`` lists the targets without it.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from gonio.errors import ParameterError

#: The target modules, in the order help and the demo list them.
TARGET_MODULES: tuple[str, ...] = (
    "gonio.export.mitsuba",
    "gonio.export.pbrt",
    "gonio.export.blender",
    "gonio.export.openpbr",
    "gonio.export.usd",
)

#: What a target module must define (see the module docstring).
DECLARATION = ("TARGET", "TITLE", "SUFFIXES", "HELP", "check", "refit_template", "build")


def targets() -> dict[str, ModuleType]:
    """``{name: module}`` of every registered target, in :data:`TARGET_MODULES` order.

    Raises
    ------
    TypeError
        When a listed module lacks part of its declaration or two modules share a name.
    """
    out: dict[str, ModuleType] = {}
    for module_name in TARGET_MODULES:
        mod = importlib.import_module(module_name)
        missing = [a for a in DECLARATION if a not in vars(mod)]
        if missing:
            raise TypeError(f"export target {module_name} does not define {', '.join(missing)}")
        if mod.TARGET in out:
            raise TypeError(f"export target {mod.TARGET!r} is declared twice ({module_name})")
        out[mod.TARGET] = mod
    return out


def names() -> list[str]:
    """The registered target names."""
    return list(targets())


def target(name: str) -> ModuleType:
    """The module of target ``name``; ParameterError naming the choices for an unknown one."""
    found = targets()
    if name not in found:
        raise ParameterError(f"unknown export target {name!r}; choose one of {', '.join(found)}")
    return found[name]


def listing(items: list[str], conjunction: str = "or") -> str:
    """``"a, b or c"`` (for help and messages)."""
    if len(items) == 1:
        return items[0]
    return f"{', '.join(items[:-1])} {conjunction} {items[-1]}"
