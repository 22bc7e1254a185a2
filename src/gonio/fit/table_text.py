"""The text table of ``gonio fit``: one row per model, never wider than the terminal.

Model names are never cut or folded (they are what ``--model`` takes and what the fit JSON is
named after), and numbers are never cut. When the names and the numbers do not fit on one line
(80 columns, a long preset such as ``lambert+cook-torrance+cook-torrance``), each model's name
takes a line of its own and its numbers follow on the next, indented; numbers that still do not
fit go on further lines, each group of columns under its own header.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

#: Short forms of :func:`gonio.fit.compare.flags` for the ``flags`` column.
_FLAG_SHORT = {
    "parameters at their bounds": "bound",
    "not converged": "no-conv",
    "unconstrained parameters": "unconstr",
}


def _metric(name: str) -> Callable[[dict[str, Any]], Any]:
    return lambda r: (r.get("metrics") or {}).get(name)


def _key(name: str) -> Callable[[dict[str, Any]], Any]:
    return lambda r: r.get(name)


def percent_above(rel: float) -> str:
    """``+1.2%`` for a relative excess of 0.012; ``x12.3`` beyond +1000 %."""
    return f"+{100 * rel:.1f}%" if rel <= 10 else f"x{1 + rel:.3g}"


def _flags(r: dict[str, Any]) -> str:
    return ",".join(_FLAG_SHORT.get(f, f) for f in r.get("flags") or []) or "-"


#: (header, value of a row of ``Comparison.to_json()["table"]`` (None: not shown), format), in
#: order. A column is shown when any row has its value: ``chi2/dof``, ``BIC`` and ``dBIC`` only
#: for data with a measured sigma, ``vs best`` (the rank measure's excess over the best, percent)
#: only without; ``appearance`` and ``cv`` once the rows carry them (``metrics["appearance"]``,
#: ``metrics["cv_loss"]``). The one place the fit table's columns are defined.
COLUMNS: tuple[tuple[str, Callable[[dict[str, Any]], Any], Callable[[Any], str]], ...] = (
    ("params", _key("n_params"), str),
    ("loss", _key("loss"), lambda v: f"{v:.4g}"),
    ("chi2/dof", _key("chi2_dof"), lambda v: f"{v:.3g}"),
    ("BIC", _key("bic"), lambda v: f"{v:.5g}"),
    ("dBIC", _key("delta_bic"), lambda v: f"{v:.1f}"),
    ("appearance", _metric("appearance"), lambda v: f"{v:.4g}"),
    ("cv", _metric("cv_loss"), lambda v: f"{v:.4g}"),
    ("vs best", _key("delta_rank"), percent_above),
    ("ngan", _metric("ngan"), lambda v: f"{v:.3g}"),
    ("low-e1", _metric("low-e1"), lambda v: f"{v:.3g}"),
    ("flags", _flags, str),
)

_GAP = "  "
_INDENT = "    "


def _groups(widths: list[int], room: int) -> list[list[int]]:
    """Column indices split into consecutive groups whose joined width fits ``room``."""
    groups: list[list[int]] = [[]]
    used = 0
    for i, w in enumerate(widths):
        need = w if not groups[-1] else len(_GAP) + w
        if groups[-1] and used + need > room:
            groups.append([])
            used, need = 0, w
        groups[-1].append(i)
        used += need
    return groups


def fit_table_lines(rows: list[dict[str, Any]], width: int = 80) -> list[str]:
    """The table as lines of at most ``width`` characters (but for a model name or a single
    number longer than that, which is never cut).

    Parameters
    ----------
    rows : the ``table`` entries of a fit comparison's JSON (``model``, ``n_params``, ``loss``,
        ``metrics``, ``flags``; ``chi2_dof``, ``bic``, ``delta_bic`` with sigma, ``delta_rank``
        without); the columns are :data:`COLUMNS` that any row has a value for.
    width : the terminal's width in characters.
    """
    shown = [(h, get, fmt) for h, get, fmt in COLUMNS if any(get(r) is not None for r in rows)]
    cells = [["" if get(r) is None else fmt(get(r)) for _, get, fmt in shown] for r in rows]
    heads = [h for h, _, _ in shown]
    widths = [max([len(h)] + [len(c[i]) for c in cells]) for i, h in enumerate(heads)]
    names = [str(r["model"]) for r in rows]
    name_w = max([len("model")] + [len(n) for n in names])

    def numbers(values: list[str], group: list[int]) -> str:
        return _GAP.join(values[i].rjust(widths[i]) for i in group)

    one_line = name_w + len(_GAP) + sum(widths) + len(_GAP) * (len(widths) - 1)
    if one_line <= width:
        all_cols = list(range(len(heads)))
        head = "model".ljust(name_w) + _GAP + numbers(heads, all_cols)
        out = [head, "-" * len(head)]
        for n, c in zip(names, cells, strict=True):
            out.append(n.ljust(name_w) + _GAP + numbers(c, all_cols))
        return out
    groups = _groups(widths, max(width - len(_INDENT), 1))
    head = ["model"] + [_INDENT + numbers(heads, g) for g in groups]
    out = [*head, "-" * min(width, max(len(h) for h in head))]
    for n, c in zip(names, cells, strict=True):
        out.append(n)
        out += [_INDENT + numbers(c, g) for g in groups]
    return out
