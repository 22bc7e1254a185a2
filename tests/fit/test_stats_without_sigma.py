"""Issue 40, item 3: statistics of fits to data without a measured sigma, through the console
script. A matte paint (Lambert, no sigma) fitted with Lambert + TS: f0 ends on its bound, the
table shows no chi-square, BIC or "ok", the bound and the unconstrained interval are reported,
and the nested family (Lambert alone) is fitted and recommended."""

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
    proc = cs.run("fit", path, "-m", "lambert+ts", "--uncertainty", "laplace", "--no-plots",
                  "--out", out, columns=100)  # fmt: skip
    cs.assert_clean(proc)
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
