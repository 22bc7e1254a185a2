"""Issue 40, items 3 and 5, through the console script. A matte paint (Lambert, no sigma)
fitted with Lambert + TS: f0 ends on its bound, the table shows no chi-square, BIC or "ok", the
bound and the unconstrained interval are reported, and the nested family (Lambert alone) is
fitted and recommended. The corner plot's library warnings go to the run's log, not the
terminal; a rerun into the same folder replaces the run as a whole and says so."""

from __future__ import annotations

import json

import numpy as np

from gonio.brdf import models
from tests import console_script as cs


def _paint(path):
    from gonio import io as gio
    from gonio.brdf.tabulated import Axis, TabulatedBRDF

    axes = (
        Axis("theta_h", 12, 0, np.pi / 2, warp="sqrt"),
        Axis("theta_d", 12, 0, np.pi / 2),
        Axis("phi_d", 12, 0, np.pi, periodic=True),
    )
    gio.save(TabulatedBRDF.from_model(models.Lambert(albedo=[0.8, 0.7, 0.6]), axes), path)


def test_matte_paint_without_sigma_reports_bounds_and_recommends_lambert(tmp_path):
    path = tmp_path / "paint.brdf.h5"
    _paint(path)
    out = tmp_path / "fits"
    proc = cs.run("fit", path, "-m", "lambert+ts", "--uncertainty", "laplace", "--out", out,
                  columns=100, timeout=600)  # fmt: skip
    cs.assert_clean(proc)
    # corner's "Too few points to create valid contours" (f0 pinned at its bound) is logged
    assert "WARNING" not in proc.stderr and "Too few points" not in proc.stderr, proc.stderr
    assert "Too few points" in (out / "log.txt").read_text()
    assert f"written to {out / 'log.txt'}" in proc.stderr
    text = proc.stdout
    for word in ("chi2", "BIC", "dBIC", " ok"):
        assert word not in text, text
    assert "recommended: lambert " in text  # the nested family, fitted because f0 vanished
    assert "no sigma in the data" in text
    rec = json.loads((out / "lambert+ts.json").read_text())
    assert rec["chi2"] is None and rec["bic"] is None and rec["reduced_chi2"] is None
    assert {rec["at_bound"][f"torrancesparrow.fresnel.f0[{c}]"] for c in "RGB"} == {"lower"}
    # an interval spanning the search box is reported as unconstrained (null), never as numbers
    f0 = rec["intervals"]["torrancesparrow.fresnel.f0"]
    assert all(v is None for v in f0[0] + f0[1])
    assert "torrancesparrow.fresnel.f0[R]" in rec["unconstrained"]
    row = next(line for line in text.splitlines() if line.startswith("lambert+ts "))
    assert "bound" in row and "unconstr" in row
    summary = json.loads((out / "summary.json").read_text())
    assert summary["recommended"] == "lambert"
    assert all("bic" not in r and r["rank_by"] == "loss" for r in summary["table"])

    # the parameters with their intervals and units, on the terminal
    assert "lambert+ts: fitted parameters, 95 % intervals (laplace)" in text
    f0_row = next(line for line in text.splitlines() if "fresnel.f0[R]" in line)
    assert "unconstrained" in f0_row and "at lower bound" in f0_row
    albedo = next(line for line in text.splitlines() if "lambert.albedo[R]" in line)
    assert albedo.split()[2].startswith("[") and albedo.split()[-1] == "1"  # interval, unit
    assert (out / "lambert+ts-corner.png").exists()

    # a rerun into the same folder: the earlier run (its corner plot included) is replaced whole
    again = cs.run(
        "fit", path, "-m", "lambert", "--no-plots", "--out", out, columns=100, timeout=600
    )
    cs.assert_clean(again)
    assert sorted(p.name for p in out.iterdir()) == ["lambert.json", "summary.json"]
    said = [line for line in again.stderr.splitlines() if "replaced the previous run" in line]
    assert len(said) == 1 and "lambert+ts, lambert" in said[0], again.stderr
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
