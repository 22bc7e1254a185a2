"""Parameters on their bounds, intervals the data do not constrain, and the nested family.

Every optimizer searches the fitted coordinates ``u`` inside a finite box
(:meth:`~gonio.fit.params.Layout.box`). Three questions are asked of a fit in those coordinates,
where "how far" means the same thing for an albedo (logit), a roughness (log) and a linear value:

*At a bound*
    ``u`` within :data:`AT_BOUND_RTOL` of the box width from an edge: the fit would have gone
    further (an f0 of 6e-6 on a matte paint, an albedo of 1 on a retro-reflector). Reported in the
    fit table, the JSON (``at_bound``) and the warnings.
*Unconstrained*
    a 95 % interval covering at least :data:`UNCONSTRAINED_FRACTION` of the box width: the data
    do not say where the parameter is. Such an interval is never printed or recommended; the
    table says "unconstrained" and the JSON's interval is ``[null, null]``.
*The nested family*
    a lobe of a sum (not its first term) whose amplitude (``rho_s``, ``f0``, ``A``) is at its
    lower bound on every channel has vanished or shrunk to a Fresnel-only grazing term; the sum
    without that lobe (``lambert`` for ``lambert+ts``) is then fitted as well, and
    :func:`gonio.fit.compare.summarize` recommends it when it fits as well (its loss within
    :data:`gonio.fit.compare.AS_WELL` of the larger family's).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

#: Distance from a box edge, as a fraction of the box width in fitted coordinates, within which
#: a parameter is reported "at its bound" (a logit albedo within 0.024 of |u| = 12: below
#: 6.2e-6 or above 1 - 6.2e-6).
AT_BOUND_RTOL = 1e-3
#: A 95 % interval covering at least this fraction of the box width (fitted coordinates) is
#: reported as unconstrained.
UNCONSTRAINED_FRACTION = 0.9
#: Parameter names whose lower bound makes a lobe vanish (or leaves only its Fresnel term).
AMPLITUDES = ("rho_s", "f0", "A")


def at_bounds(layout: Any, u: np.ndarray, channel_names: Sequence[str]) -> dict[str, str]:
    """``{flat name: "lower" | "upper"}`` of the fitted values at a box edge.

    Parameters
    ----------
    layout : the fit's :class:`~gonio.fit.params.Layout`.
    u : (P,) fitted coordinates of the optimum.
    channel_names : the data's channel names (flat names as ``"lambert.albedo[R]"``).
    """
    lo, hi = layout.box()
    tol = AT_BOUND_RTOL * (hi - lo)
    names = layout.flat_names(tuple(channel_names))
    out = {}
    for n, x, a, b, t in zip(names, np.asarray(u, dtype=float), lo, hi, tol, strict=True):
        if x <= a + t:
            out[n] = "lower"
        elif x >= b - t:
            out[n] = "upper"
    return out


def unconstrained(
    lo_u: np.ndarray, hi_u: np.ndarray, box: tuple[np.ndarray, np.ndarray], names: Sequence[str]
) -> list[str]:
    """Names whose interval ``[lo_u, hi_u]`` (fitted coordinates, (P,) each) covers at least
    :data:`UNCONSTRAINED_FRACTION` of the box ``(lo, hi)``; an infinite width counts as all."""
    blo, bhi = box
    width = np.clip(np.asarray(hi_u, float), blo, bhi) - np.clip(np.asarray(lo_u, float), blo, bhi)
    frac = np.where(np.isfinite(width), width / np.maximum(bhi - blo, 1e-300), 1.0)
    return [n for n, f in zip(names, frac, strict=True) if f >= UNCONSTRAINED_FRACTION]


def lobe_prefixes(keys: Sequence[str]) -> list[str]:
    """The lobes' key prefixes in order of first appearance (``["lambert", "torrancesparrow",
    "torrancesparrow2"]`` for ``lambert+ts+ts``)."""
    out: list[str] = []
    for k in keys:
        head = k.split(".", 1)[0]
        if head not in out:
            out.append(head)
    return out


def vanished_lobes(
    model_name: str, keys: Sequence[str], flat_names: Sequence[str], bound: dict[str, str]
) -> list[int]:
    """Indices (in ``model_name.split("+")``) of the lobes after the first with an amplitude
    (:data:`AMPLITUDES`) at its lower bound on every channel.

    ``keys``: the model's parameter keys in order; ``flat_names``: the fitted flat names;
    ``bound``: as :func:`at_bounds` returns it."""
    prefixes = lobe_prefixes(keys)
    if len(prefixes) != len(model_name.split("+")):
        return []
    out = []
    for i, prefix in enumerate(prefixes[1:], start=1):
        groups: dict[str, list[bool]] = {}
        for n in flat_names:
            key = n.split("[", 1)[0]
            if key.split(".", 1)[0] == prefix and key.rpartition(".")[2] in AMPLITUDES:
                groups.setdefault(key, []).append(bound.get(n) == "lower")
        if any(all(v) for v in groups.values()):
            out.append(i)
    return out


def nested_family(result: Any, available: Sequence[str]) -> str | None:
    """The preset name of ``result``'s model without its vanished lobes
    (:func:`vanished_lobes`); None when there is none or the name is not in ``available``."""
    keys = list(result.model.param_specs())
    drop = vanished_lobes(result.name, keys, result.flat_names, result.at_bound or {})
    if not drop:
        return None
    name = "+".join(p for j, p in enumerate(result.name.split("+")) if j not in drop)
    return name if name in available else None
