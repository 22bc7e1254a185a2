"""What a refitted export costs: time, and how it looks against the measurement.

For shared-data materials of four kinds (a metal, a plastic, a felt, an RGL vinyl film): gonio's
default fit and a ``lambert+ts-ggx-smith`` fit, each exported to every target
(:mod:`gonio.export.registry`). For each export: the mapping (exact or refit); for a refit its
wall time cold (first export of the process) and warm (the same export again in the same
process: compiled programs and the measurement's images reused), the chosen refit's own time,
and the appearance score (HDR-FLIP and relative L1, :mod:`gonio.appearance`) of the fit and of
the exported material against the measurement, with their ratio (issue 41 asks <= 1.1).

``python benchmarks/bench_export.py [MATERIAL ...]`` writes ``results/bench_export.csv`` and the
README's ``export`` table. Times are wall seconds on whatever machine runs it (the README table
says which load it ran under).
"""

from __future__ import annotations

import csv
import os
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
DATA = HERE.parent / ".." / "shared" / "data"
MATERIALS = {
    "chrome-steel (metal)": DATA / "nbrdf" / "merl_nbrdf.zip::chrome-steel",
    "red-specular-plastic": DATA / "nbrdf" / "merl_nbrdf.zip::red-specular-plastic",
    "acrylic_felt_green": DATA / "rgl" / "acrylic_felt_green_rgb.bsdf",
    "vch_golden_yellow (RGL)": DATA / "rgl" / "vch_golden_yellow_rgb.bsdf",
}
FIELDS = (
    "material", "family", "target", "mapping", "cold_s", "warm_s", "refit_s", "refit_metric",
    "fit_flip", "export_flip", "flip_ratio", "fit_l1", "export_l1", "load",
)  # fmt: skip


def _fits(spec: str, out: Path) -> dict[str, Path]:
    from gonio.fit import fit
    from gonio.fit.data import prepare
    from gonio.fit.selection import select

    fd = prepare(spec, 80.0)
    sel = select(fd)
    ts = fit(fd, model="lambert+ts-ggx-smith")
    return {
        f"default ({sel.chosen})": sel.result.save(out / "default.json"),
        "lambert+ts-ggx-smith": ts.save(out / "ts.json"),
    }


def run(
    names: list[str], fits: dict[str, dict[str, Path]] | None = None
) -> list[dict[str, object]]:
    """Rows of the table; ``fits`` (``{material: {family: fit JSON}}``) skips the fitting."""
    rows: list[dict[str, object]] = []
    for name in names:
        spec = MATERIALS[name]
        if not Path(str(spec).partition("::")[0]).exists():
            print(f"skip {name}: {spec} missing")
            continue
        with tempfile.TemporaryDirectory() as tmp:
            given = (fits or {}).get(name) or _fits(str(spec), Path(tmp))
            rows += _export_rows(name, given)
    return rows


def _export_rows(name: str, fits: dict[str, Path]) -> list[dict[str, object]]:
    from gonio.export import export, registry

    rows: list[dict[str, object]] = []
    for family, path in fits.items():
        for target in registry.names():
            t0 = time.perf_counter()
            e = export(path, target)
            cold = time.perf_counter() - t0
            row: dict[str, object] = {
                "material": name, "family": family, "target": target, "mapping": e.mapping,
            }  # fmt: skip
            if e.refit is not None:
                t0 = time.perf_counter()
                e = export(path, target)
                warm = time.perf_counter() - t0
                a = e.refit["appearance"]
                fm, em = a["fit_vs_measurement"], a["export_vs_measurement"]
                row.update(
                    cold_s=cold, warm_s=warm, refit_s=e.refit["seconds"],
                    refit_metric=e.refit["refit_metric"],
                    fit_flip=fm and fm["hdr_flip"], export_flip=em and em["hdr_flip"],
                    flip_ratio=fm and em and em["hdr_flip"] / fm["hdr_flip"],
                    fit_l1=fm and fm["rel_l1"], export_l1=em and em["rel_l1"],
                    load=os.getloadavg()[0],
                )  # fmt: skip
            rows.append(row)
            print(row, flush=True)
    return rows


def main(argv: list[str]) -> None:
    """``argv``: material names of :data:`MATERIALS`, or ``NAME=FAMILY:FIT.json`` to export
    saved fits instead of fitting (repeatable)."""
    names: list[str] = []
    fits: dict[str, dict[str, Path]] = {}
    for arg in argv:
        if "=" in arg:
            name, _, rest = arg.partition("=")
            family, _, path = rest.partition(":")
            fits.setdefault(name, {})[family] = Path(path)
            if name not in names:
                names.append(name)
        else:
            names.append(arg)
    rows = run(names or list(MATERIALS), fits)
    (HERE / "results").mkdir(exist_ok=True)
    with open(HERE / "results" / "bench_export.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, FIELDS)
        w.writeheader()
        w.writerows(rows)


def write_tables() -> None:
    """Rewrite this benchmark's table in benchmarks/README.md from its CSV."""
    import _tables

    columns = [
        ("material", "material"),
        ("fit", "family"),
        ("target", "target"),
        ("mapping", "mapping"),
        ("refit (s)", "refit_s"),
        ("export warm (s)", "warm_s"),
        ("export cold (s)", "cold_s"),
        ("refit loss", "refit_metric"),
        ("HDR-FLIP fit", "fit_flip"),
        ("HDR-FLIP export", "export_flip"),
        ("ratio", "flip_ratio"),
        ("rel. L1 fit", "fit_l1"),
        ("rel. L1 export", "export_l1"),
        ("load", "load"),
    ]
    _tables.write("export", _tables.markdown(_tables.read("bench_export.csv"), columns))


if __name__ == "__main__":
    main(sys.argv[1:])
    write_tables()
