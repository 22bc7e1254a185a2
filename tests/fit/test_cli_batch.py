import json

import numpy as np
import pytest

import gonio.fit.data as fit_data
from gonio.brdf import models
from gonio.cli import main
from gonio.errors import FitError
from gonio.fit.batch import expand_inputs, run_batch
from tests.fit.synth import cosine_directions


def test_unknown_model_is_one_line_error(tmp_path, capsys):
    f = tmp_path / "x.brdf"
    f.write_text("")
    rc = main(["fit", str(f), "--model", "wardd"])
    err = capsys.readouterr().err
    assert rc == FitError.exit_code
    assert err.startswith("gonio: unknown model 'wardd'; valid: lambert")
    assert err.count("\n") == 1 and "Traceback" not in err


def test_missing_input_and_bad_flags(tmp_path, capsys):
    # A missing file is bad input, as in 'gonio info' (exit 2 in both).
    assert main(["fit", str(tmp_path / "nope.brdf"), "-m", "lambert"]) == 2
    assert "no such file" in capsys.readouterr().err
    assert main(["info", str(tmp_path / "nope.brdf")]) == 2
    capsys.readouterr()
    f = tmp_path / "x.brdf"
    f.write_text("")
    assert main(["fit", str(f), "-m", "lambert", "--fix", "albedo"]) == FitError.exit_code
    assert "KEY=NUMBER" in capsys.readouterr().err
    assert main(["fit", str(f), "-m", "lambert", "--theta-max", "95"]) == FitError.exit_code
    assert "--theta-max" in capsys.readouterr().err
    assert main(["fit", str(tmp_path / "*.none"), "-m", "lambert"]) == FitError.exit_code
    assert "no measurement files" in capsys.readouterr().err


def test_list_models(capsys):
    assert main(["fit", "--list-models"]) == 0  # no dummy argument needed
    names = capsys.readouterr().out.split()
    assert "lambert" in names
    assert main(["fit"]) == 2
    assert "give at least one measurement file" in capsys.readouterr().err


def test_out_that_is_a_file_is_refused_before_the_fit(tmp_path, capsys):
    import time

    f = tmp_path / "x.brdf"
    f.write_text("")
    out = tmp_path / "taken.json"
    out.write_text("{}")
    t0 = time.monotonic()
    assert main(["fit", str(f), "-m", "lambert", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "exists and is not a folder" in err and err.count("\n") == 1
    assert out.read_text() == "{}" and time.monotonic() - t0 < 30


def test_help_documents_every_flag(capsys):
    with pytest.raises(SystemExit):
        main(["fit", "--help"])
    out = capsys.readouterr().out
    for flag in (
        "--model",
        "--loss",
        "--uncertainty",
        "--theta-max",
        "--out",
        "--json",
        "--scheduler",
        "--jobs",
        "--global",
        "--fix",
        "--refine",
    ):
        assert flag in out


class _Samples:
    def __init__(self, wi, wo, values, name):
        self.wi, self.wo, self.values = wi, wo, values
        self.sigma = None
        self.weights = None
        self.meta = {"name": name}


def _fake_loader(path):
    seed = int(np.frombuffer(path.read_bytes()[:4], dtype="<i4")[0])
    rng = np.random.default_rng(seed)
    wi, wo = cosine_directions(300, rng), cosine_directions(300, rng)
    albedo = 0.2 + 0.1 * seed
    y = np.asarray(models.Lambert(albedo=albedo).f(wi, wo)) * (
        1 + 0.01 * rng.standard_normal((300, 1))
    )
    return _Samples(wi, wo, y, path.stem)


def test_batch_resumes_after_interrupt(tmp_path, monkeypatch):
    monkeypatch.setattr(fit_data, "load_data", _fake_loader)
    src = tmp_path / "in"
    src.mkdir()
    for i in range(3):
        (src / f"m{i}.dat").write_bytes(np.int32(i).tobytes())
    (src / "README.md").write_text("not data")
    paths = expand_inputs([src])
    assert [p.name for p in paths] == ["m0.dat", "m1.dat", "m2.dat"]
    out = tmp_path / "out"
    opts = {"models": ["lambert"], "fit": {"n_starts": 2}, "plots": False}

    seen = []

    def stop_after_first(s):
        seen.append(s["material"])
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_batch(paths, out, opts, jobs=1, on_done=stop_after_first)
    assert seen == ["m0"]
    first = out / "m0" / "summary.json"
    assert first.exists() and not (out / "m1").exists()
    stamp = first.stat().st_mtime_ns

    again = run_batch(paths, out, opts, jobs=1)
    assert [s["material"] for s in again] == ["m1", "m2"]
    assert all(s["status"] == "ok" for s in again)
    assert first.stat().st_mtime_ns == stamp
    journal = [json.loads(x) for x in (out / "batch.jsonl").read_text().splitlines()]
    assert [j["material"] for j in journal] == ["m0", "m1", "m2"]
    res = json.loads((out / "m2" / "lambert.json").read_text())
    assert res["params"]["albedo"] == pytest.approx(0.4, abs=0.01)
    assert run_batch(paths, out, opts, jobs=1) == []  # all done: nothing to do
    # asking for another model redoes the materials (keeping finished model files)
    more = run_batch(paths, out, {**opts, "models": ["lambert", "oren-nayar"]}, jobs=1)
    assert [s["material"] for s in more] == ["m0", "m1", "m2"]
    assert (out / "m0" / "oren-nayar.json").exists()


def _native_files(folder, n=2):
    """Small native tables written with gonio.io (skips when io cannot save yet)."""
    gio = pytest.importorskip("gonio.io")
    if not hasattr(gio, "save"):
        pytest.skip("gonio.io.save not available")
    from gonio.brdf.tabulated import Axis, TabulatedBRDF

    axes = (
        Axis("theta_h", 12, 0, np.pi / 2, warp="sqrt"),
        Axis("theta_d", 12, 0, np.pi / 2),
        Axis("phi_d", 12, 0, np.pi, periodic=True),
    )
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for i in range(n):
        model = models.Phong(rho_d=[0.1 + 0.1 * i] * 3, rho_s=0.3, n=40.0 + 20 * i)
        p = folder / f"mat{i}.brdf.h5"
        gio.save(TabulatedBRDF.from_model(model, axes=axes), p)
        paths.append(p)
    return paths


def test_cli_single_file_writes_results_and_plots(tmp_path, capsys):
    (path,) = _native_files(tmp_path / "in", n=1)
    out = tmp_path / "out"
    rc = main(["fit", str(path), "-m", "phong", "-m", "lambert", "--uncertainty", "laplace",
               "--out", str(out), "--json"])  # fmt: skip
    assert rc == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["recommended"] == "phong"
    from gonio.fit import load_model

    m = load_model(out / "phong.json")
    assert float(m.params()["n"]) == pytest.approx(40.0, rel=1e-3)
    for name in ("phong-residuals.png", "phong-slices.png", "phong-corner.png", "summary.json"):
        assert (out / name).stat().st_size > 0


@pytest.mark.slow
def test_batch_process_pool_and_dask_local_cluster(tmp_path):
    paths = _native_files(tmp_path / "in", n=2)
    opts = {"models": ["phong"], "fit": {"n_starts": 2}, "plots": False}
    res = run_batch(paths, tmp_path / "pool", opts, jobs=2)
    assert sorted(s["material"] for s in res) == ["mat0", "mat1"]
    assert all(s["status"] == "ok" for s in res)
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True) as cluster:
        res = run_batch(paths, tmp_path / "dask", opts, scheduler=cluster.scheduler_address)
    assert sorted(s["material"] for s in res) == ["mat0", "mat1"]
    assert all(s["status"] == "ok" for s in res)
    assert (tmp_path / "dask" / "mat1" / "phong.json").exists()


def test_ctrl_c_while_writing_leaves_no_half_written_folder(tmp_path, monkeypatch, capsys):
    (path,) = _native_files(tmp_path / "in", n=1)
    out = tmp_path / "out"
    import gonio.fit.plots as plots

    calls = []

    def interrupted(*a, **k):
        calls.append(1)
        raise KeyboardInterrupt

    monkeypatch.setattr(plots, "plot_result", interrupted)
    rc = main(["fit", str(path), "-m", "lambert", "--out", str(out)])
    assert rc == 130 and calls
    assert "interrupted" in capsys.readouterr().err
    # No result folder, no staging folder left beside it.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in"]


def test_batch_redoes_other_options_and_keeps_every_model_in_the_summary(tmp_path, monkeypatch):
    monkeypatch.setattr(fit_data, "load_data", _fake_loader)
    src = tmp_path / "in"
    src.mkdir()
    (src / "m0.dat").write_bytes(np.int32(0).tobytes())
    paths = expand_inputs([src])
    out = tmp_path / "out"
    opts = {"models": ["lambert"], "fit": {"n_starts": 2}, "plots": False}
    assert [s["material"] for s in run_batch(paths, out, opts, jobs=1)] == ["m0"]
    assert run_batch(paths, out, opts, jobs=1) == []  # same options: done
    # Another --theta-max is another fit: redone, not skipped.
    other = {**opts, "fit": {"n_starts": 2, "theta_max_deg": 60.0}}
    assert [s["material"] for s in run_batch(paths, out, other, jobs=1)] == ["m0"]
    summary = json.loads((out / "m0" / "summary.json").read_text())
    assert summary["fit_options"]["theta_max_deg"] == 60.0
    # A new model: the summary compares it with the earlier one, not the new one alone.
    run_batch(paths, out, {**other, "models": ["oren-nayar"]}, jobs=1)
    summary = json.loads((out / "m0" / "summary.json").read_text())
    assert sorted(summary["models"]) == ["lambert", "oren-nayar"]
    assert sorted(r["model"] for r in summary["table"]) == ["lambert", "oren-nayar"]


def test_archive_members_are_materials_of_their_own(tmp_path):
    from gonio.fit.batch import material_name, pending

    zip_path = tmp_path / "merl_nbrdf.zip"
    zip_path.write_bytes(b"")
    paths = expand_inputs([f"{zip_path}::gold-paint", f"{zip_path}::pvc"])
    assert [material_name(p) for p in paths] == ["gold-paint", "pvc"]
    assert material_name(tmp_path / "x.brdf.h5") == "x"
    todo, done = pending(paths, tmp_path / "out")
    assert len(todo) == 2 and not done
