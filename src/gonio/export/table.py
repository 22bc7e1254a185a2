"""Which fitted family each export target holds: the family x target table.

For every model family ``gonio fit --model`` offers (:data:`FAMILIES`, the names of
:func:`gonio.fit.presets.available`) and every registered target, :func:`cells` asks the
target's own ``check`` (:mod:`gonio.export.registry`) about the family's lobes and answers

``exact``
    the target's stock BSDF evaluates the same f (written unchanged apart from documented
    renames such as ``roughness = sqrt(alpha)``);
``plugin``
    not a stock BSDF, but exact through the gonio Mitsuba plugin (Mitsuba only, when the plugin
    module :data:`PLUGIN_MODULE` is installed: ``gonio export --to mitsuba --plugin``). The
    plugin holds every analytic model of 1 or 3 channels (its ``supports(model)``), so every
    family here in an RGB fit; a test asks ``supports`` about each family's model, which this
    module cannot build without JAX;
``refit``
    the target's family is refitted to the fit's data and the price is reported (the reason is
    the target's ``check`` message).

The families' lobes are described here without building the models (:data:`LOBES`), so that
``gonio export --help`` prints the table without importing JAX; a test keeps :data:`FAMILIES`
and :data:`LOBES` equal to what :mod:`gonio.fit.presets` builds and
:func:`gonio.export._lobes.split` sees. A cell holds for the family's form: a fit whose values
fall outside it (e.g. a diffuse albedo above 1 in pbrt) is refitted, and says so.
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass

import numpy as np

from gonio.export import registry
from gonio.export._lobes import Lobes, Specular

#: Each lobe name as the exporter sees it: ``"diffuse"``, a microfacet lobe's
#: ``(distribution, shadowing, fresnel)``, or the gonio class that no renderer lobe matches.
LOBES: dict[str, str | tuple[str, str, str]] = {
    "lambert": "diffuse",
    "oren-nayar": "OrenNayar",
    "phong": "Phong",
    "blinn-phong": "BlinnPhong",
    "ward": "Ward",
    "ward-duer": "Ward",
    "ward-balanced": "Ward",
    "torrance-sparrow": ("beckmann", "vcavity", "schlick"),
    "ts": ("beckmann", "vcavity", "schlick"),
    "ts-ggx-smith": ("ggx", "smith", "schlick"),
    "lafortune": "Lafortune",
    "lafortune-2": "Lafortune",
    "ashikhmin-shirley": "AshikhminShirley",
    "cook-torrance": "CookTorrance",
    "ngan-blinn-phong": "NganBlinnPhong",
    "low": "LowMicrofacet",
    "gtr": "GTR",
    "retro": "Retroreflection",
}

#: Model names of ``gonio fit --model`` (single lobes, then sums), as
#: :func:`gonio.fit.presets.available` lists them (which builds models, so imports JAX); a test
#: keeps the two equal.
FAMILIES: tuple[str, ...] = (
    *(name for name in LOBES if name != "ts"),
    *"""lambert+ward lambert+ts lambert+ts+ts lambert+ts-ggx-smith lambert+cook-torrance
    lambert+cook-torrance+cook-torrance lambert+ngan-blinn-phong lambert+ward+ward lambert+low
    lambert+low+low lambert+gtr lambert+gtr+gtr lambert+retro lambert+retro+gtr""".split(),
)

#: The gonio BSDF plugin for Mitsuba 3: a module with ``supports(model) -> bool``.
PLUGIN_MODULE = "gonio.export.mitsuba_plugin"
#: The target the plugin serves.
PLUGIN_TARGET = "mitsuba"
#: Representative values for the checks: a diffuse albedo and Schlick's f0 (the checks look at
#: structure, and at values only where a target bounds them).
_ALBEDO, _F0, _ALPHA = 0.5, 0.04, 0.2


@dataclass(frozen=True)
class Cell:
    """One family in one target: ``kind`` (``exact``, ``plugin`` or ``refit``) and, unless
    exact, why the stock export refits (the target's ``check`` message; a ``plugin`` cell's
    stock export, without ``--plugin``, is that refit)."""

    kind: str
    reason: str | None = None


def family_lobes(family: str) -> Lobes | str:
    """The :class:`~gonio.export._lobes.Lobes` of a family (with :data:`_ALBEDO`, :data:`_F0`),
    or why it is not one diffuse term plus one microfacet lobe (as :func:`~._lobes.split`
    says it)."""
    diffuse = None
    spec: Specular | None = None
    for part in family.split("+"):
        what = LOBES[part]
        if what == "diffuse":
            diffuse = np.full(3, _ALBEDO)
        elif isinstance(what, tuple):
            if spec is not None:
                return "more than one microfacet lobe"
            dist, shadowing, fresnel = what
            spec = Specular(_ALPHA, dist, shadowing, fresnel, f0=np.full(3, _F0))
        else:
            return f"{what} lobe (no target's stock BSDF evaluates gonio's form)"
    return Lobes(3, diffuse, spec)


def plugin_installed() -> bool:
    """Whether the gonio Mitsuba plugin module (:data:`PLUGIN_MODULE`) is part of this gonio."""
    return importlib.util.find_spec(PLUGIN_MODULE) is not None


def cell(family: str, target: str) -> Cell:
    """The table's cell of ``family`` (a :data:`FAMILIES` name) in ``target``."""
    mod = registry.target(target)
    lobes = family_lobes(family)
    reason = lobes if isinstance(lobes, str) else mod.check(lobes)
    if reason is None:
        return Cell("exact")
    if target == PLUGIN_TARGET and plugin_installed():
        return Cell("plugin", reason)
    return Cell("refit", reason)


def cells() -> dict[str, dict[str, Cell]]:
    """``{family: {target: Cell}}`` for every family and registered target."""
    return {f: {t: cell(f, t) for t in registry.names()} for f in FAMILIES}


def _numbered(table: dict[str, dict[str, Cell]]) -> tuple[dict[str, int], list[str]]:
    reasons: dict[str, int] = {}
    for row in table.values():
        for c in row.values():
            if c.reason is not None and c.reason not in reasons:
                reasons[c.reason] = len(reasons) + 1
    return reasons, list(reasons)


def _label(c: Cell, numbers: dict[str, int]) -> str:
    if c.reason is None:
        return c.kind
    refit = f"refit {numbers[c.reason]}"
    return refit if c.kind == "refit" else f"plugin ({refit})"


def text() -> str:
    """The table as plain text for ``gonio export --help``: one row per family, then the
    numbered refit reasons."""
    table = cells()
    names = registry.names()
    numbers, reasons = _numbered(table)
    width = max(len(f) for f in FAMILIES) + 2
    cols = {
        n: max(len(n), *(len(_label(r[n], numbers)) for r in table.values())) + 2 for n in names
    }
    rows = ["  " + "family".ljust(width) + "".join(n.ljust(cols[n]) for n in names).rstrip()]
    for fam, row in table.items():
        line = "".join(_label(row[n], numbers).ljust(cols[n]) for n in names)
        rows.append("  " + fam.ljust(width) + line.rstrip())
    rows.append("")
    rows += [f"  refit {i}: {r}" for i, r in enumerate(reasons, 1)]
    return "\n".join(rows)


def markdown() -> str:
    """The table as Markdown (docs/guide/export.md shows it between ``<!-- table:export -->``
    markers; a test keeps the two equal)."""
    table = cells()
    names = registry.names()
    numbers, reasons = _numbered(table)
    head = "| family | " + " | ".join(names) + " |"
    sep = "|---|" + "---|" * len(names)
    rows = [head, sep]
    for fam, row in table.items():
        rows.append(f"| `{fam}` | " + " | ".join(_label(row[n], numbers) for n in names) + " |")
    rows.append("")
    rows += [f"{i}. {r}" for i, r in enumerate(reasons, 1)]
    return "\n".join(rows)
