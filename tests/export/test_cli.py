"""``gonio export``: help, outputs, --json, and bad input (one line, non-zero, nothing written)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gonio.brdf import models
from gonio.cli import main
from tests.export.conftest import fit_record, write_record

GGX = models.Lambert(albedo=[0.5, 0.4, 0.3]) + models.TorranceSparrow(
    alpha=0.2, distribution="ggx", shadowing="smith", fresnel=models.Schlick([0.04, 0.05, 0.06])
)


def test_help_documents_targets_mapping_and_refit(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["export", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for word in ("mitsuba", "pbrt", "blender", "openpbr", "usd"):
        assert f"  {word} " in out
    for phrase in ("sqrt(alpha)", "remaproughness", "alpha = alpha", "what is refitted",
                   "refit loss", "linear sRGB", "Ward"):  # fmt: skip
        assert phrase in out, phrase


def test_export_writes_files_and_json(tmp_path, capsys):
    fit = write_record(tmp_path / "fit.json", fit_record(GGX))
    args = ["--to", "mitsuba", "--out", str(tmp_path / "m.xml"), "--json", "--no-price"]
    assert main(["export", str(fit), *args]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["refit"]["appearance"] is None  # --no-price: the losses only
    assert report["notes"][0].startswith("REFIT, not the fit: mitsuba cannot express")
    assert report["mapping"] == "refit"  # Schlick Fresnel: Mitsuba's conductor has eta, k
    assert report["refit"]["refit_loss"] > 0 and report["refit"]["original_loss"] == 0.0
    assert sorted(report["files"]) == sorted([str(tmp_path / "m.xml"), str(tmp_path / "m.json")])
    d = json.loads((tmp_path / "m.json").read_text())
    assert d["type"] == "blendbsdf"
    assert main(["export", str(fit), "--to", "usd"]) == 0
    cap = capsys.readouterr()
    assert cap.out.startswith("#usda 1.0") and "usd: exact mapping" in cap.err


def _files(tmp_path):
    return sorted(p.name for p in tmp_path.iterdir())


@pytest.mark.parametrize(
    ("edit", "args", "message"),
    [
        (lambda r: {**r, "version": 2}, ["--to", "blender"], "schema version 2 is not supported"),
        (lambda r: r, ["--to", "maya"], "unknown export target 'maya'"),
        (lambda r: {**r, "model_spec": {"type": "NoSuchModel"}}, ["--to", "pbrt"], "model_spec"),
        (
            lambda r: {
                **r,
                "model_spec": models.Ward(rho_d=0.1, rho_s=0.2, alpha_x=0.2, alpha_y=0.2).to_dict(),
                "data": {**r["data"], "path": "/nonexistent/table.brdf.h5"},
            },
            ["--to", "blender", "--refit-from", "measurement"],
            "no data to refit from",
        ),
        (
            lambda r: {**r, "model_spec": models.SpecularReflection().to_dict()},
            ["--to", "usd"],
            "no data to refit from",
        ),
    ],
)
def test_bad_input_one_line_nonzero_nothing_written(tmp_path, capsys, edit, args, message):
    fit = write_record(tmp_path / "fit.json", edit(fit_record(GGX)))
    before = _files(tmp_path)
    rc = main(["export", str(fit), *args, "--out", str(tmp_path / "out.any")])
    err = capsys.readouterr().err
    assert rc != 0
    assert err.count("\n") == 1 and err.startswith("gonio: ") and message in err, err
    assert _files(tmp_path) == before


@pytest.mark.parametrize("out", ["fit.json", "fit.xml", "link.xml"])
def test_an_output_that_would_overwrite_the_fit_is_refused(tmp_path, capsys, out):
    # Mitsuba's export writes FILE.json beside FILE.xml: "--out fit.xml" would replace the fit
    fit = write_record(tmp_path / "fit.json", fit_record(GGX))
    (tmp_path / "link.json").symlink_to(fit)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    rc = main(["export", str(fit), "--to", "mitsuba", "--out", str(tmp_path / out)])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "would overwrite the input" in err, err
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_a_refused_file_operation_becomes_one_line(tmp_path, capsys):
    # an output folder below a regular file: the system refuses (an OSError, as for a read-only
    # folder or a full disk), which the command line prints as one line; nothing is written
    fit = write_record(tmp_path / "fit.json", fit_record(GGX))
    (tmp_path / "afile").write_text("")
    out = str(tmp_path / "afile/sub/m.pbrt")
    rc = main(["export", str(fit), "--to", "pbrt", "--out", out, "--no-price"])
    err = capsys.readouterr().err
    assert rc == 1 and err.count("\n") == 1 and err.startswith("gonio: "), err
    assert str(tmp_path / "afile") in err
    assert _files(tmp_path) == ["afile", "fit.json"]


def test_spectral_fit_exports_rgb(tmp_path):
    """A spectral Lambert + GGX/Schlick fit: albedo and f0 are converted with
    gonio.io.spectral's matrix (exactly for the albedo); the mapping stays exact."""
    from gonio.export import to_blender
    from gonio.io import spectral

    wl = np.arange(400.0, 701.0, 20.0)
    albedo = np.linspace(0.2, 0.6, wl.size)
    f0 = np.full(wl.size, 0.04)
    model = models.Lambert(albedo=albedo) + models.TorranceSparrow(
        alpha=0.2, distribution="ggx", shadowing="smith", fresnel=models.Schlick(f0)
    )
    e = to_blender(fit_record(model, channels=[f"{w:g}nm" for w in wl]))
    assert e.mapping == "exact"
    want = spectral.spectrum_to_linear_srgb(albedo, wl, "D65")
    assert e.params["Diffuse BSDF"]["Color"] == pytest.approx(want.tolist(), rel=1e-12)
    assert any("linear sRGB" in n for n in e.notes)


def test_spectral_conductor_is_refitted_in_rgb():
    """An index of refraction is not linear in RGB: a spectral conductor fit is refitted on the
    RGB-converted samples of the model, and the export has three channels."""
    from gonio.export import to_mitsuba

    wl = np.arange(400.0, 701.0, 50.0)
    model = models.Lambert(albedo=np.linspace(0.2, 0.5, wl.size)) + models.TorranceSparrow(
        alpha=0.2,
        distribution="ggx",
        shadowing="smith",
        fresnel=models.Conductor(eta=np.linspace(0.2, 1.2, wl.size), k=np.full(wl.size, 3.0)),
    )
    e = to_mitsuba(fit_record(model, channels=[f"{w:g}nm" for w in wl]))
    assert e.mapping == "refit" and "index of refraction" in e.notes[0]
    assert e.refit["data"]["kind"] == "sampled model"
    assert len(e.params["eta"]) == 3 and len(e.params["reflectance"]) == 3
    # the spectral model's own RGB prediction on its RGB-converted samples: no error
    assert e.refit["original_loss_on_refit_data"] == pytest.approx(0.0, abs=1e-20)
