"""Error of the scattered-data interpolant the renderer uses, on a simulated acquisition.

Acquires a plan (default ``demo``, the demo's isotropic sweep refined around the specular peak)
on the ``sim_sample`` rig (direct BRDF readings with the rig file's noise, no images: fast)
measuring the demo's built-in paint (Lambert + Beckmann Torrance-Sparrow, alpha 0.18), whose
BRDF is known exactly. The scattered samples are then tabulated the ways ``gonio render`` and
``gonio grid`` can:

* ``interp``: the log-linear Delaunay interpolant of :mod:`gonio.brdf.gridding` on the render
  grid (64 x 32 x 32), what ``gonio render --measured RUN/table.brdf.h5`` uses;
* ``bin+fill``: the run's binned ``/gridded`` table (16 x 15 x 12, cell means), its empty cells
  filled by the same interpolant, what rendering that table gives.

Each is compared with the truth at direction pairs drawn cosine-weighted over both hemispheres
(the measure a rendering integrates over), kept where both polar angles are at most 75 degrees
(the plan's range), and separately at those whose half vector is within 15 degrees of the
normal (the specular lobe): median relative error and
relative RMS error ``sqrt(mean (f - f_true)^2) / sqrt(mean f_true^2)``. Also reported: the
fraction of the render grid inside the samples' convex hull. Writes
``benchmarks/results/scattered_render.csv``.
"""

from __future__ import annotations

import argparse
import csv
import re
import sys
import tempfile
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"


def _cos_dirs(rng: np.random.Generator, n: int) -> np.ndarray:
    u = rng.random((n, 2))
    r, p = np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]
    return np.stack([r * np.cos(p), r * np.sin(p), np.sqrt(1 - u[:, 0])], -1)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plan", default="demo")
    args = ap.parse_args(argv)

    from gonio import io
    from gonio.acquire.engine import acquire
    from gonio.brdf import gridding, models
    from gonio.brdf.gridding import half_diff_iso
    from gonio.demo.materials import builtin_material
    from gonio.render.measured import renderable

    mat = builtin_material()
    truth = models.Node.from_dict(mat.sample)
    with tempfile.TemporaryDirectory() as tmp:
        rig = Path(tmp) / "rig.toml"
        # the direct-reading rig (same geometry, no camera) measuring the demo's paint, its
        # [sim.sample] table replaced as gonio.demo.pipeline.rig_text does for the sim rig
        from importlib import resources

        import tomli_w

        base = resources.files("gonio.rigs").joinpath("sim_sample.toml").read_text()
        pattern = re.compile(r"(?:#[^\n]*\n)*\[sim\.sample\]\n(?:[^\[\n][^\n]*\n|\n)*")
        sample = tomli_w.dumps({"sim": {"sample": mat.sample}})
        base, n = pattern.subn(lambda _: sample + "\n", base)
        assert n == 1
        rig.write_text(base)
        acquire(Path(tmp) / "run", rig, args.plan, progress=False)
        path = Path(tmp) / "run" / "table.brdf.h5"
        samples = io.load(path)
        binned = __import__("gonio.io.native", fromlist=["read_native"]).read_native(
            path, group="gridded"
        )
    rng = np.random.default_rng(0)
    wi, wo = _cos_dirs(rng, 20000), _cos_dirs(rng, 20000)
    # Inside the plan's range (the rig refuses polar angles beyond 75-80 deg): beyond it the
    # table can only extrapolate, and the paint's grazing Fresnel peak (f up to ~1e3 1/sr)
    # would dominate every RMS.
    keep = (wi[:, 2] > np.cos(np.radians(75))) & (wo[:, 2] > np.cos(np.radians(75)))
    wi, wo = wi[keep], wo[keep]
    th, _, _ = half_diff_iso(wi, wo)
    lobe = np.degrees(th) < 15
    f_true = np.asarray(truth.f(wi, wo))
    interp = gridding.interpolate_samples(samples)
    variants = {
        "interp": renderable(samples)[0],
        "bin+fill": renderable(binned)[0],
    }
    rows = []
    for name, table in variants.items():
        f = np.asarray(table.f(wi, wo))
        for region, sel in (("all", np.ones_like(lobe)), ("lobe (theta_h < 15 deg)", lobe)):
            a, b = f[sel], f_true[sel]
            rows.append(
                {
                    "tabulation": name,
                    "region": region,
                    "pairs": int(sel.sum()),
                    "median_rel_error": float(np.median(np.abs(a - b) / b)),
                    "rel_rms_error": float(np.sqrt(np.mean((a - b) ** 2) / np.mean(b**2))),
                }
            )
    inside = float(interp.mask.sum()) / max(int(interp.mask.size), 1)
    RESULTS.mkdir(exist_ok=True)
    with open(RESULTS / "scattered_render.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print(f"{len(samples)} samples ({args.plan} plan); {inside:.0%} of the render grid inside "
          "their convex hull")  # fmt: skip
    print("| tabulation | region | pairs | median relative error | relative RMS error |")
    print("|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['tabulation']} | {r['region']} | {r['pairs']} | "
              f"{r['median_rel_error']:.2%} | {r['rel_rms_error']:.2%} |")  # fmt: skip
    return 0


def write_tables() -> None:
    """Rewrite this benchmark's table in benchmarks/README.md from its CSV."""
    import _tables

    columns = [
        ("tabulation", "tabulation"),
        ("region", "region"),
        ("direction pairs", "pairs"),
        ("median rel. error", "median_rel_error"),
        ("relative RMS error", "rel_rms_error"),
    ]
    rows = _tables.read("scattered_render.csv")
    _tables.write("scattered_render", _tables.markdown(rows, columns))


if __name__ == "__main__":
    _rc = main()
    if not _rc:
        write_tables()
    sys.exit(_rc)
