"""The RGL writer on an acquisition: the reduced demo's run, gridded, written as ``.bsdf``.

The run is the ``demo`` fixture's (plan ``demo-quick`` on the simulated ``sim`` rig, through the
acquisition engine of ``gonio acquire --rig sim``: 61 measured configurations). Its scattered
table is gridded with ``gonio grid --method interp`` (16 x 15 x 12 half/diff nodes, about a third
of them inside the samples' convex hull) and written with ``gonio convert ... x.bsdf``.

What is compared is the writer's fidelity to the gridded table: Mitsuba 3's ``measured`` eval of
the written file against the gridded table's ``f`` on the same direction pairs (up to 80 deg),
not the acquisition's fidelity to the material's truth (the demo's fit tests check that). The
gridded table is 0 where none of a lookup's corner nodes is covered; relative errors are taken
over the directions where it is not (its coverage).
"""

from __future__ import annotations

import numpy as np
import pytest

from gonio import io
from gonio.cli import main
from tests.io.rgl_compare import mitsuba_f, pairs, rel

pytestmark = pytest.mark.xdist_group("demo-e2e")


@pytest.fixture(scope="module")
def converted(demo, tmp_path_factory):
    out, _, _ = demo
    folder = tmp_path_factory.mktemp("demo-rgl")
    gridded, bsdf = folder / "run.brdf.h5", folder / "run.bsdf"
    args = ["grid", str(out / "run" / "table.brdf.h5"), str(gridded), "--method", "interp"]
    assert main(args) == 0
    assert main(["convert", str(gridded), str(bsdf), "--quiet"]) == 0
    return io.load(gridded), bsdf


def _covered(table, wi, wo):
    src = np.asarray(table.f(wi, wo))
    return src, np.all(src > 0, axis=-1)


def test_mitsuba_reads_the_written_acquisition_and_agrees_over_its_coverage(converted):
    table, bsdf = converted
    assert table.mask.mean() > 0.25  # a real part of the domain, not a nearly empty grid
    wi, wo = pairs(400, seed=5)
    ref = mitsuba_f(bsdf, wi, wo)
    src, cov = _covered(table, wi, wo)
    assert cov.mean() > 0.4, cov.mean()
    r = rel(ref[cov], src[cov])
    assert np.median(r) <= 0.02, np.median(r)
    # gonio's reader reads the written file as Mitsuba does, everywhere
    ours = np.asarray(io.load(bsdf).f(wi, wo))
    d = rel(ours, ref)
    assert np.median(d) <= 1e-4 and np.percentile(d, 99) <= 1e-3, np.percentile(d, [50, 99])


@pytest.mark.xfail(
    strict=True,
    reason="known gap: the written file's 32 x 32 colour grid smooths the step at the gridded "
    "table's coverage edge (f falls to 0 there): 95th percentile 38 % over the coverage, 6 % "
    "about 2 deg inside it, 3 % about 4 deg inside it; median 0.5 %",
)
def test_written_acquisition_meets_the_95th_percentile_target_over_its_coverage(converted):
    table, bsdf = converted
    wi, wo = pairs(4000, seed=6)
    src, cov = _covered(table, wi, wo)
    # gonio's reader stands for Mitsuba here (the test above shows they agree to 1e-4)
    r = rel(np.asarray(io.load(bsdf).f(wi, wo))[cov], src[cov])
    assert np.percentile(r, 95) <= 0.10, np.percentile(r, 95)


def test_written_acquisition_meets_the_targets_inside_its_coverage(converted):
    """Away from the coverage edge (every one of 12 random neighbours, each direction moved by
    about 4 deg, is covered too) the file meets the 2 % median and 10 % 95th percentile."""
    table, bsdf = converted
    wi, wo = pairs(4000, seed=6)
    src, inner = _covered(table, wi, wo)
    rng = np.random.default_rng(7)
    for _ in range(12):
        near = [w + rng.normal(scale=np.radians(4.0), size=w.shape) for w in (wi, wo)]
        near = [w / np.linalg.norm(w, axis=-1, keepdims=True) for w in near]
        for w in near:
            w[:, 2] = np.abs(w[:, 2])
        inner &= _covered(table, *near)[1]
    assert inner.mean() > 0.25, inner.mean()
    r = rel(np.asarray(io.load(bsdf).f(wi, wo))[inner], src[inner])
    assert np.median(r) <= 0.02 and np.percentile(r, 95) <= 0.10, np.percentile(r, [50, 95])


def test_convert_refuses_the_scattered_run_table(demo, tmp_path, capsys):
    out, _, _ = demo
    target = tmp_path / "x.bsdf"
    rc = main(["convert", str(out / "run" / "table.brdf.h5"), str(target)])
    err = capsys.readouterr().err
    assert rc != 0 and err.count("\n") == 1 and "scattered samples" in err, err
    assert "Traceback" not in err and not target.exists()
