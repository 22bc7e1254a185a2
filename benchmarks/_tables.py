"""Write the tables of ``benchmarks/README.md`` from ``benchmarks/results/*.csv``.

Each benchmark ends by calling its own ``write_tables()``, which reads the CSV files it has
just written and replaces its sections of the README, each between the markers
``<!-- table:NAME -->`` and ``<!-- /table:NAME -->``. Text outside the markers is left alone.

``python benchmarks/_tables.py`` rewrites every table from the CSV files as they are, without
running any benchmark.
"""

from __future__ import annotations

import csv
import importlib
import math
import re
import sys
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
README = HERE / "README.md"

#: The benchmarks whose tables the README holds, in the README's order.
BENCHMARKS = (
    "bench_demo",
    "bench_truth_check",
    "bench_acquisition_accuracy",
    "bench_imaging",
    "bench_rig",
    "bench_route",
    "bench_soak",
    "bench_formats",
    "bench_fit",
    "bench_published",
    "bench_appearance",
    "bench_prior",
    "bench_render",
    "bench_scattered_render",
    "bench_equal_time",
    "bench_env_strategies",
    "bench_first_image",
    "bench_startup",
    "bench_throughput",
    "bench_mitsuba",
    "bench_rgl",
    "bench_gpu",
    "bench_zoo",
    "bench_mcmc_agreement",
    "bench_view",
    "bench_mitsuba_plugin",
    "bench_export",
    "bench_guided",
)

Row = dict[str, str]
#: A column: its header, and the CSV field it shows or a function of the row.
Column = tuple[str, "str | Callable[[Row], object]"]


def read(name: str) -> list[Row]:
    """The rows of ``results/NAME`` (lines starting with ``#`` are comments)."""
    with open(RESULTS / name, newline="") as fh:
        return list(csv.DictReader(line for line in fh if not line.startswith("#")))


def num(value: object, digits: int = 3) -> str:
    """``value`` to ``digits`` significant digits; empty, ``nan`` and text pass through."""
    if value is None or value == "":
        return ""
    text = str(value).strip()
    if re.fullmatch(r"-?\d+", text):  # counts and integers as written
        return text
    try:
        x = float(text)
    except ValueError:
        return text
    if math.isnan(x):
        return ""
    if x == 0:
        return "0"
    if 10**digits <= abs(x) < 1e9:
        return f"{x:.0f}"
    if 1e-3 <= abs(x) < 10**digits:
        return f"{x:.{digits}g}"
    return f"{x:.{digits - 1}e}"


def markdown(rows: Iterable[Row], columns: Sequence[Column], digits: int = 3) -> str:
    """A Markdown table of ``rows``: numbers to ``digits`` significant digits."""
    lines = [
        "| " + " | ".join(header for header, _ in columns) + " |",
        "|" + "---|" * len(columns),
    ]
    for row in rows:
        cells = []
        for _, field in columns:
            value = field(row) if callable(field) else row.get(field, "")
            cells.append(num(value, digits))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_csv(rows: list[dict], name: str, comment: str = "") -> None:
    """Write ``rows`` (dicts; the union of their keys, in first-seen order, but ``published``)
    as ``results/NAME``, with ``comment`` as a first ``#`` line."""
    RESULTS.mkdir(exist_ok=True)
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys and k != "published"]
    with open(RESULTS / name, "w", newline="") as fh:
        if comment:
            fh.write(f"# {comment}\n")
        w = csv.DictWriter(fh, keys, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)


def write(name: str, table: str, readme: Path = README) -> None:
    """Replace the text between ``<!-- table:NAME -->`` and ``<!-- /table:NAME -->``."""
    text = readme.read_text(encoding="utf-8")
    pattern = re.compile(
        rf"(<!-- table:{re.escape(name)} -->).*?(<!-- /table:{re.escape(name)} -->)", re.S
    )
    if not pattern.search(text):
        raise KeyError(f"{readme} has no markers for table {name!r}")
    body = "\n" + table.strip("\n") + "\n"
    text = pattern.sub(lambda m: m.group(1) + body + m.group(2), text, count=1)
    readme.write_text(text, encoding="utf-8")


def main() -> int:
    sys.path.insert(0, str(HERE))
    for module in BENCHMARKS:
        importlib.import_module(module).write_tables()
        print(f"{module}: tables written")
    return 0


if __name__ == "__main__":
    sys.exit(main())
