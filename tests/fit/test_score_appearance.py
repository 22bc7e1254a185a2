"""``gonio fit --score``: every published fit file, and the appearance score beside the table
metrics (console script; a small scattered measurement so that it stays fast)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gonio import appearance
from gonio.brdf import ngan, published
from gonio.cli import main
from gonio.io.fit_result import read_result
from tests import console_script as cs
from tests.conftest import shared_file
from tests.fit.synth import cosine_directions


@pytest.fixture(scope="module")
def pvc(tmp_path_factory):
    """300 samples of Löw's smooth-surface fit of pvc, times 1.1, named pvc."""
    from gonio.brdf.measured import MeasuredSamples
    from gonio.io import save

    text = shared_file("fits", "low_lowsmooth_E2.fit").read_text()
    m = published.to_model(ngan.parse_ngan_fits(text)["pvc"])
    rng = np.random.default_rng(0)
    wi, wo = cosine_directions(300, rng), cosine_directions(300, rng)
    p = tmp_path_factory.mktemp("score") / "pvc.brdf.h5"
    save(MeasuredSamples(wi, wo, np.asarray(m.f(wi, wo)) * 1.1, meta={"name": "pvc"}), p)
    return p


def test_score_reads_low_and_bagher_files_with_the_appearance_score(pvc):
    low = shared_file("fits", "low_lowsmooth_E2.fit")
    bagher = shared_file("fits", "bagher_sgd.fit")
    he = shared_file("fits", "ngan_he.fit")
    proc = cs.run("fit", pvc, "--score", low, bagher, he, "--json")
    cs.assert_clean(proc)
    rows = json.loads(proc.stdout)
    assert [r["label"] for r in rows] == ["published low_lowsmooth_E2", "published bagher_sgd"]
    for r in rows:
        assert r["ngan"] > 0 and r["low-e2"] > 0
        assert set(r["appearance"]) == set(appearance.KEYS)
        assert 0 < r["appearance"]["hdr_flip"] < 1 and r["appearance"]["resolution_px"] == 96
    # the model the data was made from looks closer than another family's fit
    assert rows[0]["appearance"]["rel_l1"] < rows[1]["appearance"]["rel_l1"]


def test_fitted_models_carry_the_score_in_table_and_json(pvc, tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["fit", str(pvc), "-m", "lambert", "--score", "--no-plots", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "flip" in text and "relL1" in text and "HDR-FLIP" in text
    rec = read_result(out / "lambert.json")
    assert set(rec["appearance"]) == set(appearance.KEYS)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["table"][0]["appearance"]["hdr_flip"] == rec["appearance"]["hdr_flip"]


def _batch_of_two(pvc, tmp_path):
    import shutil

    src = tmp_path / "in"
    src.mkdir()
    for name in ("a", "b"):
        shutil.copy(pvc, src / f"{name}.brdf.h5")
    return src


def test_batch_score_puts_each_materials_score_in_the_csv_and_table(
    pvc, tmp_path, capsys, monkeypatch
):
    """A batch with --score scores every material (the score itself stubbed: fast; the real
    one in the slow test below)."""
    import csv

    from gonio.fit import score as fit_score

    seen = []

    def stub(path, results):
        seen.append(path.name)
        for r in results:
            r.appearance = {**dict.fromkeys(appearance.KEYS, 0.5), "hdr_flip": 0.25,
                            "rel_l1": 0.125 * len(seen)}  # fmt: skip
        return None

    monkeypatch.setattr(fit_score, "score_results", stub)
    out = tmp_path / "o"
    src = _batch_of_two(pvc, tmp_path)
    args = ["fit", str(src), "-m", "lambert", "--score", "--no-plots", "-j", "1", "-o", str(out)]
    assert main(args) == 0  # in this process (-j 1): the stub applies
    text = capsys.readouterr().out
    assert sorted(seen) == ["a.brdf.h5", "b.brdf.h5"]
    assert "HDR-FLIP" in text and "rel. L1" in text and "0.25" in text
    rows = {r["material"]: r for r in csv.DictReader((out / "fits.csv").open())}
    assert float(rows["a"]["hdr_flip"]) == 0.25 and float(rows["b"]["hdr_flip"]) == 0.25
    assert {float(rows[m]["rel_l1"]) for m in "ab"} == {0.125, 0.25}


@pytest.mark.slow
def test_batch_score_carries_the_appearance_score_per_material(pvc, tmp_path, capsys):
    import csv

    src = _batch_of_two(pvc, tmp_path)
    out = tmp_path / "o"
    assert main(["fit", str(src), "-m", "lambert", "--score", "--no-plots", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "HDR-FLIP" in text and "rel. L1" in text
    rows = list(csv.DictReader((out / "fits.csv").open()))
    assert sorted(r["material"] for r in rows) == ["a", "b"]
    for r in rows:
        summary = json.loads((out / r["material"] / "summary.json").read_text())
        score = summary["table"][0]["appearance"]
        assert float(r["hdr_flip"]) == pytest.approx(score["hdr_flip"], rel=1e-12)
        assert float(r["rel_l1"]) == pytest.approx(score["rel_l1"], rel=1e-12)
        assert 0 < float(r["hdr_flip"]) < 1
