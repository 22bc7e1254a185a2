"""The text table of ``gonio fit``: one row per model, never wider than the terminal.

Model names are never cut or folded (they are what ``--model`` takes and what the fit JSON is
named after), and numbers are never cut. When the names and the numbers do not fit on one line
(80 columns, a long preset such as ``lambert+cook-torrance+cook-torrance``), each model's name
takes a line of its own and its numbers follow on the next, indented; numbers that still do not
fit go on further lines, each group of columns under its own header.
"""

from __future__ import annotations

from typing import Any

#: (header, how a row of ``FitComparison.to_json()["table"]`` is shown), in order.
COLUMNS: tuple[tuple[str, Any], ...] = (
    ("params", lambda r: str(r["n_params"])),
    ("loss", lambda r: f"{r['loss']:.4g}"),
    ("chi2/dof", lambda r: f"{r['chi2_dof']:.3g}"),
    ("BIC", lambda r: f"{r['bic']:.5g}"),
    ("dBIC", lambda r: f"{r['delta_bic']:.1f}"),
    ("ngan", lambda r: f"{r['metrics']['ngan']:.3g}"),
    ("low-e1", lambda r: f"{r['metrics']['low-e1']:.3g}"),
    ("ok", lambda r: "yes" if r["converged"] else "NO"),
)

#: Columns added when the rows carry an appearance score (``gonio fit --score``): the mean
#: HDR-FLIP and relative L1 of the sphere images (:mod:`gonio.appearance`).
APPEARANCE_COLUMNS: tuple[tuple[str, Any], ...] = (
    ("flip", lambda r: f"{r['appearance']['hdr_flip']:.3f}" if r.get("appearance") else "-"),
    ("relL1", lambda r: f"{r['appearance']['rel_l1']:.3f}" if r.get("appearance") else "-"),
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
        ``chi2_dof``, ``bic``, ``delta_bic``, ``metrics`` with ``ngan`` and ``low-e1``,
        ``converged``; ``appearance`` adds the :data:`APPEARANCE_COLUMNS`).
    width : the terminal's width in characters.
    """
    columns = COLUMNS + (APPEARANCE_COLUMNS if any(r.get("appearance") for r in rows) else ())
    cells = [[show(r) for _, show in columns] for r in rows]
    heads = [h for h, _ in columns]
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
