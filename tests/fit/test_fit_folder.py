"""Issue 40, item 5: results a person can read. A batch writes one CSV and one table across
materials (console script); an interrupted rerun leaves the previous run intact; a corner plot
that is not drawn says why."""

from __future__ import annotations

import csv

import numpy as np

from gonio.brdf import models
from gonio.cli import main
from tests import console_script as cs
from tests.fit.test_cli_batch import _native_files


def test_batch_writes_one_csv_and_one_table_across_materials(tmp_path):
    paths = _native_files(tmp_path / "in", n=2)
    out = tmp_path / "out"
    proc = cs.run("fit", *paths, "-m", "lambert", "--no-plots", "-j", "1", "--out", out,
                  columns=140, timeout=600)  # fmt: skip
    cs.assert_clean(proc)
    rows = list(csv.DictReader((out / "fits.csv").open()))
    assert [r["material"] for r in rows] == ["mat0", "mat1"]
    assert all(r["model"] == "lambert" and r["recommended"] == "1" for r in rows)
    assert float(rows[0]["param:albedo[0]"]) > 0 and float(rows[0]["loss"]) > 0
    table = [line.split() for line in proc.stdout.splitlines()]
    for name in ("mat0", "mat1"):
        row = next(t for t in table if t[:1] == [name])
        assert row[1] == "lambert" and "albedo" in row


def test_an_interrupted_rerun_leaves_the_previous_run_intact(tmp_path, monkeypatch, capsys):
    (path,) = _native_files(tmp_path / "in", n=1)
    out = tmp_path / "out"
    assert main(["fit", str(path), "-m", "lambert", "--no-plots", "--out", str(out)]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    import gonio.fit.plots as plots

    def interrupted(result, data, folder, stem, **kw):
        (folder / f"{stem}-residuals.png").write_bytes(b"half")  # mid-write
        raise KeyboardInterrupt

    monkeypatch.setattr(plots, "plot_result", interrupted)
    assert main(["fit", str(path), "-m", "phong", "--out", str(out)]) == 130
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in", "out"]  # no staging left
    capsys.readouterr()


def test_a_corner_plot_not_drawn_says_why(tmp_path, capsys):
    from gonio.brdf.measured import MeasuredSamples
    from gonio.io import save
    from tests.fit.synth import cosine_directions

    rng = np.random.default_rng(0)
    wi, wo = cosine_directions(400, rng), cosine_directions(400, rng)
    albedo = np.linspace(0.2, 0.8, 13)  # 13 channels: 13 albedos, more than a corner plot takes
    y = np.asarray(models.Lambert(albedo).f(wi, wo)) * rng.uniform(0.97, 1.03, (400, 13))
    p = tmp_path / "spectral.brdf.h5"
    from gonio.brdf.grid import Channels

    ch = Channels("spectral", wavelengths_nm=np.linspace(400, 700, 13))
    save(MeasuredSamples(wi, wo, y, channels=ch, meta={"name": "spectral"}), p)
    out = tmp_path / "out"
    rc = main(["fit", str(p), "-m", "lambert", "--uncertainty", "laplace", "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 0
    assert "lambert-corner.png not drawn: 13 parameters, more than 12" in err
    assert not (out / "lambert-corner.png").exists() and (out / "lambert-slices.png").exists()
