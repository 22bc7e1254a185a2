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
#: only without; ``flip``, ``relL1`` and ``cv`` once the rows carry them (``appearance``,
#: ``metrics["cv_loss"]``). The one place the fit table's columns are defined.
COLUMNS: tuple[tuple[str, Callable[[dict[str, Any]], Any], Callable[[Any], str]], ...] = (
    ("params", _key("n_params"), str),
    ("loss", _key("loss"), lambda v: f"{v:.4g}"),
    ("chi2/dof", _key("chi2_dof"), lambda v: f"{v:.3g}"),
    ("BIC", _key("bic"), lambda v: f"{v:.5g}"),
    ("dBIC", _key("delta_bic"), lambda v: f"{v:.1f}"),
    ("flip", lambda r: (r.get("appearance") or {}).get("hdr_flip"), lambda v: f"{v:.3f}"),
    ("relL1", lambda r: (r.get("appearance") or {}).get("rel_l1"), lambda v: f"{v:.3f}"),
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


def _number(v: Any) -> str:
    return "nan" if v is None or v != v else f"{float(v):.4g}"


#: Headers of :func:`param_rows`.
PARAM_HEADERS = ("parameter", "value", "95 % interval", "unit", "note")


def param_rows(result: Any) -> list[tuple[str, str, str, str, str]]:
    """The parameter table of one fit: ``(parameter, value, 95 % interval, unit, note)`` per
    scalar value (per-channel values one row each, labelled with the channel).

    The interval column says ``fixed``, ``= KEY`` (tied), ``unconstrained`` (an interval over
    the search box, :mod:`gonio.fit.bounds`), or ``[lo, hi]``; empty without uncertainty. The
    note says ``at lower bound`` / ``at upper bound`` where the value ended on its search
    bound. ``result``: a :class:`~gonio.fit.result.FitResult`.
    """
    import numpy as np

    specs = result.model.param_specs()
    channels = list(result.data.get("channels") or [])
    iv = result.intervals(95)
    bound = result.at_bound or {}
    rows = []
    for key, value in result.params.items():
        unit = getattr(specs.get(key), "unit", "")
        vals = np.ravel(np.asarray(value, dtype=float))
        if vals.size == len(channels) and vals.size > 1:
            labels = [f"{key}[{c}]" for c in channels]
        elif vals.size > 1:
            labels = [f"{key}[{i}]" for i in range(vals.size)]
        else:
            labels = [key]
        lo = hi = None
        if key in iv:
            lo = np.ravel(np.asarray(iv[key][0], dtype=float))
            hi = np.ravel(np.asarray(iv[key][1], dtype=float))
        for i, (label, v) in enumerate(zip(labels, vals, strict=True)):
            if key in result.fixed:
                text = "fixed"
            elif key in result.tied:
                text = f"= {result.tied[key]}"
            elif lo is None or hi is None:
                text = ""
            elif not (np.isfinite(lo[i % lo.size]) and np.isfinite(hi[i % hi.size])):
                text = "unconstrained"
            else:
                text = f"[{_number(lo[i % lo.size])}, {_number(hi[i % hi.size])}]"
            side = bound.get(label)
            note = f"at {side} bound" if side and key not in result.fixed else ""
            rows.append((label, _number(v), text, unit, note))
    return rows


def params_compact(params: dict[str, Any]) -> str:
    """``albedo 0.79/0.69/0.59, alpha 0.12`` for a fit's ``params`` (keys cut to their last
    part, per-channel values joined by ``/``; fixed zeros such as a lobe's own ``rho_d`` in a
    sum with Lambert are left out)."""
    import numpy as np

    out = []
    for key, value in params.items():
        vals = np.ravel(np.asarray(value, dtype=float))
        if key.rpartition(".")[2] == "rho_d" and not np.any(vals):
            continue
        out.append(f"{key.rpartition('.')[2]} " + "/".join(f"{v:.3g}" for v in vals))
    return ", ".join(out)
