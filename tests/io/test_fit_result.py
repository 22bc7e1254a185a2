"""The fit-result format (:mod:`gonio.io.fit_result`): one reader for every command.

A fit JSON whose fields have the wrong type is refused in one line naming the field, by the
Python reader and by every command that reads fits, never with a traceback."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from gonio.brdf import models
from gonio.errors import FormatError
from gonio.io import fit_result
from tests import console_script

GGX = models.Lambert(albedo=[0.5, 0.4, 0.3]) + models.TorranceSparrow(
    alpha=0.2, distribution="ggx", shadowing="smith", fresnel=models.Schlick([0.04, 0.05, 0.06])
)


def _record(model=GGX) -> dict:
    return fit_result.to_jsonable(
        {
            "schema": fit_result.SCHEMA_ID,
            "version": fit_result.SCHEMA_VERSION,
            "model": "lambert+ggx",
            "model_spec": model.to_dict(),
            "params": {k: np.asarray(v).tolist() for k, v in model.params().items()},
            "intervals": {},
            "loss": 0.0,
            "metric": "wls",
            "data": {"n_samples": 0, "channels": ["R", "G", "B"], "name": "m"},
        }
    )


def _with_children(value) -> dict:
    r = _record()
    r["model_spec"]["lobes"][1]["children"] = value
    return r


#: name -> (bad record, words the one-line message must contain)
BAD = {
    "data_path_number": ({**_record(), "data": {**_record()["data"], "path": 3}}, "data/path"),
    "children_null": (_with_children(None), "children is not an object"),
    "child_number": (_with_children({"fresnel": 7}), "fresnel: not an object"),
    "spec_number": ({**_record(), "model_spec": 5}, "model_spec"),
    "params_number": (
        {**_record(), "model_spec": {"type": "Lambert", "params": 2}},
        "params is not an object",
    ),
}


@pytest.mark.parametrize("name", sorted(BAD))
def test_reader_refuses_mistyped_fields_in_one_line(tmp_path, name):
    record, words = BAD[name]
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(record))
    with pytest.raises(FormatError) as exc:
        fit_result.load_model(path)
    assert words in str(exc.value) and "\n" not in str(exc.value), str(exc.value)


@pytest.mark.parametrize("command", ["export", "render"])
@pytest.mark.parametrize("name", ["data_path_number", "children_null", "child_number"])
def test_console_script_refuses_a_mistyped_fit_in_one_line(tmp_path, command, name):
    record, words = BAD[name]
    if name == "data_path_number":  # a model export cannot map: it needs the data to refit
        record = {**record, "model_spec": models.Ward(0.1, 0.2, 0.2, 0.2).to_dict()}
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(record))
    out = tmp_path / "out"
    args = {
        "export": ["export", path, "--to", "pbrt", "--out", out / "m.pbrt"],
        "render": [
            "render",
            "--fitted",
            path,
            "--light",
            "dir:0,0",
            "--resolution",
            "8",
            "--out",
            out / "c.png",
        ],
    }[command]
    proc = console_script.run(*args)
    assert proc.returncode == FormatError.exit_code, proc.stderr
    assert proc.stderr.count("\n") == 1 and proc.stderr.startswith("gonio: "), proc.stderr
    assert words in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
    assert not out.exists()


def test_round_trip_and_strict_writer(tmp_path):
    path = fit_result.write_result(_record(), tmp_path / "fit.json")
    model = fit_result.load_model(path)
    np.testing.assert_allclose(np.asarray(model.lobes[0].albedo), [0.5, 0.4, 0.3])
    record = fit_result.read_result(path)
    assert record["data"]["channels"] == ["R", "G", "B"]
    with pytest.raises(FormatError, match=r"nan.json: loss is NaN; JSON has no NaN"):
        fit_result.write_result({**_record(), "loss": math.nan}, tmp_path / "nan.json")
    assert not (tmp_path / "nan.json").exists()
    # the writer applies the reader's checks: a record read_result would refuse is not written
    with pytest.raises(FormatError, match=r"bad.json: .*model_spec"):
        bad = {**_record(), "model_spec": {"children": None}}
        fit_result.write_result(bad, tmp_path / "bad.json")
    assert not (tmp_path / "bad.json").exists()
    assert fit_result.to_jsonable({"loss": math.inf})["loss"] is None


def test_an_unsupported_version_is_named(tmp_path):
    path = tmp_path / "fit.json"
    path.write_text(json.dumps({**_record(), "version": 2}))
    with pytest.raises(FormatError, match="schema version 2 is not supported"):
        fit_result.read_result(path)


def test_a_model_family_needs_no_line_in_the_reader(tmp_path):
    """A model family is its module (here one defined in the tests) plus its import line: the
    reader finds it through the model registry, with nothing to add here."""
    from tests.fit.lobes import TestLobe

    model = models.Lambert(0.2) + TestLobe(rho_s=0.3, n=40.0)
    path = fit_result.write_json(_record(model), tmp_path / "fit.json")
    back = fit_result.load_model(path)
    assert type(back.lobes[1]).__name__ == "TestLobe" and float(back.lobes[1].n) == 40.0
