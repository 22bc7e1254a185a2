"""The satin and chrome cases of issue 41: an export is exact or says, in the file, that it is a
refit and what it costs.

Satin: a satin-like ``lambert+ts-ggx-smith`` fit (values of a fit to RGL's vinyl film
``vch_golden_yellow``) exported to Mitsuba is either exact (Mitsuba's own ``BSDF.eval`` of the
exported dictionary within 2 % relative RMSE of gonio's f over the sphere's pixels under lights
at 0, 30 and 60 degrees) or a refit whose written XML states it with its price. Chrome (a
measured table, here a small one): a refit's HDR-FLIP against the measurement is at most 1.1x
the fit's. The same on four shared-data materials is ``-m slow``
(tests/export/test_price_shared.py).
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from gonio import io
from gonio.brdf import models
from gonio.brdf.tabulated import TabulatedBRDF
from gonio.export import export
from tests.export.conftest import fit_record, write_record
from tests.export.test_refit import AXES

SATIN = models.Lambert(albedo=[6.1e-6, 0.0105, 0.0196]) + models.TorranceSparrow(
    alpha=0.109, distribution="ggx", shadowing="smith", fresnel=models.Schlick([0.45, 0.26, 0.0085])
)


@pytest.fixture(scope="module")
def satin_export(tmp_path_factory):
    path = write_record(tmp_path_factory.mktemp("satin") / "satin.json", fit_record(SATIN))
    return export(path, "mitsuba")


def test_satin_to_mitsuba_is_exact_or_states_its_price(satin_export):
    e = satin_export
    if e.mapping == "exact":
        pytest.importorskip("mitsuba")
        from tests.export.mitsuba_eval import directions, gonio_values, mitsuba_values, rel_rmse

        wi, wo = directions()
        assert rel_rmse(mitsuba_values(e.data, wi, wo), gonio_values(SATIN, wi, wo)) <= 0.02
        return
    xml = e.files[".xml"]
    head = xml.split("<bsdf", 1)[0]
    assert "REFIT, not the fit" in head and "loss on these samples: fit" in head
    assert "appearance of the export against the fit" in head and "HDR-FLIP" in head
    ET.fromstring(xml)  # the comment keeps the fragment well-formed
    report = e.to_json()["refit"]
    assert report["appearance"]["export_vs_fit"]["hdr_flip"] >= 0
    assert [c["refit_metric"] for c in report["candidates"]] == ["wls"]  # no measurement
    assert report["refit_loss"] >= 0 and report["seconds"] > 0


#: A metal with a long-tailed highlight, measured as a small table, and a Ward fit of it.
METAL = models.Lambert(albedo=[0.01, 0.01, 0.012]) + models.GTR(
    rho_s=[0.5, 0.45, 0.4], alpha=0.06, gamma=1.4, f0=0.6
)
WARD = models.Lambert(albedo=[0.03, 0.03, 0.035]) + models.Ward(
    rho_s=[0.3, 0.27, 0.24], alpha_x=0.12, alpha_y=0.12
)


@pytest.mark.slow
def test_refit_of_a_measured_metal_looks_as_good_as_the_fit(tmp_path):
    table = TabulatedBRDF.from_model(METAL, axes=AXES)
    path = tmp_path / "metal.brdf.h5"
    io.save(table, path)
    fitted = WARD
    rec = write_record(
        tmp_path / "fit.json",
        fit_record(fitted, metric="sqrt-cos", loss=0.01, path=str(path), theta_max_deg=80.0),
    )
    e = export(rec, "pbrt")
    assert e.mapping == "refit" and e.refit["data"]["kind"] == "measurement"
    a = e.refit["appearance"]
    assert a["export_vs_measurement"]["hdr_flip"] <= 1.1 * a["fit_vs_measurement"]["hdr_flip"]
    text = e.files[".pbrt"]
    assert text.startswith("# gonio export: REFIT, not the fit")
    assert "appearance against the measurement: fit HDR-FLIP" in text
    json.dumps(e.to_json())
    assert np.isfinite(e.refit["on_refit_metric"]["export"])


SHARED = Path(__file__).resolve().parents[2] / ".." / "shared" / "data"


def test_a_refit_of_an_archive_member_reads_the_measurement():
    """The chrome case: a fit of ``merl_nbrdf.zip::chrome-steel`` records that path; the refit
    reads that measurement (8192 stratified cells of its 9e5: ``_refit.MAX_CELLS``), not the
    sampled model."""
    from gonio.export._refit import refit_data
    from gonio.export._source import load

    archive = SHARED / "nbrdf" / "merl_nbrdf.zip"
    if not archive.exists():
        pytest.skip(f"shared data missing: {archive}")
    rec = fit_record(models.Lambert(albedo=[0.01, 0.01, 0.01]), path=f"{archive}::chrome-steel")
    rd = refit_data(load(rec))
    assert rd.kind == "measurement" and rd.path == f"{archive}::chrome-steel"
    assert rd.data.n == 8192
