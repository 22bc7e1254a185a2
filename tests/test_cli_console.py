"""Issue 21, "what trips a new user", through the installed ``gonio`` console script: a long
output into a pipe closed early, the plan and fit tables at 80 columns, and ``gonio plan``
starting without the heavy libraries."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests import console_script as cs

PLAN = ("plan", "--rig", "sim", "--plan", "iso-small")


@pytest.mark.parametrize(
    "args",
    [
        ("fit", "--list-models"),
        PLAN,
        (*PLAN, "--json"),
        ("rig", "schema"),
        ("rig", "list"),
        ("--help",),
        ("fit", "--help"),
    ],
    ids=lambda a: " ".join(a[:2]),
)
def test_output_into_a_closed_pipe_is_silent(args):
    # `gonio fit --list-models | head -1` where head has gone before the first write
    proc = subprocess.Popen(
        [cs.script(), *args], env=cs.env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    proc.stdout.close()
    err = proc.stderr.read().decode()
    proc.wait(timeout=300)
    assert err == ""
    # as a program killed by SIGPIPE (128 + 13); argparse's --help ignores the closed pipe
    assert proc.returncode == (0 if "--help" in args else 141)


def test_info_into_a_closed_pipe_is_silent(tmp_path):
    from gonio import io
    from gonio.brdf.measured import MeasuredSamples

    w = np.random.default_rng(0).normal(size=(50, 3))
    w[:, 2] = np.abs(w[:, 2]) + 0.1
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    path = tmp_path / "t.brdf.h5"
    io.save(MeasuredSamples(w, w[::-1], np.full((50, 3), 0.1)), path)
    proc = subprocess.Popen(
        [cs.script(), "info", path], env=cs.env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    proc.stdout.close()
    err = proc.stderr.read().decode()
    proc.wait(timeout=300)
    # rich (which prints the description) exits 1 on a closed pipe, without a message
    assert err == "" and proc.returncode == 1


def test_list_models_piped_into_head_gives_the_first_line():
    proc = subprocess.run(
        f"'{cs.script()}' fit --list-models | head -1",
        shell=True,
        env=cs.env(),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.stdout == "lambert\n" and proc.stderr == ""


def test_plan_imports_neither_jax_nor_scipy_nor_matplotlib():
    # the rig's [sim.sample] model is checked by `gonio acquire`, not by the dry run
    proc = subprocess.run(
        [sys.executable, "-X", "importtime", cs.script(), *PLAN],
        env=cs.env(),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    imported = {
        line.split("|")[-1].strip().split(".")[0]
        for line in proc.stderr.splitlines()
        if line.startswith("import time:")
    }
    assert "gonio" in imported and "numpy" in imported  # the listing is the real one
    assert not imported & {"jax", "jaxlib", "scipy", "matplotlib"}, sorted(imported)
    assert "accepted 177, refused 5" in proc.stdout


def test_plan_text_fits_80_columns_and_lists_every_refusal_whole():
    proc = cs.run(*PLAN, "--list-refused", "100", columns=80)
    cs.assert_clean(proc)
    lines = proc.stdout.splitlines()
    assert max(len(line) for line in lines) <= 80, proc.stdout
    assert "\u2026" not in proc.stdout and "..." not in proc.stdout
    info = json.loads(cs.run(*PLAN, "--json").stdout)
    assert f"{info['targets']} targets" in lines[0]
    assert f"total {info['predicted_total_s']:.1f} s wall" in proc.stdout
    words = " ".join(proc.stdout.split())
    table = [line for line in lines if re.match(r"^\s+\d+\s+\d", line)]
    assert len(table) == info["refused"] == len(info["refusals"])
    for row, r in zip(table, info["refusals"], strict=True):
        cells = row.split()
        assert int(cells[0]) == r["index"]
        assert [float(c) for c in cells[1:5]] == pytest.approx(
            [r[k] for k in ("theta_i_deg", "phi_i_deg", "theta_o_deg", "phi_o_deg")], abs=0.05
        )
    # every reason whole, once the column's line breaks are joined
    reasons = [" ".join(r["reason"].split()) for r in info["refusals"]]
    assert all(reason in words for reason in reasons)


def test_plan_text_says_how_many_refusals_it_left_out():
    proc = cs.run(*PLAN, "--list-refused", "2", columns=80)
    cs.assert_clean(proc)
    assert "the first 2" in proc.stdout and "3 more refused" in proc.stdout


def test_a_bad_sample_model_passes_plan_and_is_refused_by_acquire(tmp_path):
    from importlib import resources

    text = resources.files("gonio.rigs").joinpath("sim_sample.toml").read_text()
    rig = tmp_path / "bad-sample.toml"
    rig.write_text(text.replace('type = "Phong"', 'type = "Phongg"', 1))
    plan = cs.run("plan", "--rig", rig, "--plan", "iso-tiny")
    cs.assert_clean(plan)
    run = tmp_path / "RUN"
    acq = cs.run("acquire", "--rig", rig, "--plan", "iso-tiny", "--out", run, "--no-progress")
    assert acq.returncode != 0 and "Traceback" not in acq.stderr
    assert acq.stderr.count("\n") == 1 and "sim.sample" in acq.stderr, acq.stderr
    assert "not a gonio model" in acq.stderr and not run.exists()


def test_fit_out_an_existing_file_is_one_line_before_any_work(tmp_path):
    data = tmp_path / "x.brdf"
    data.write_text("")  # never read: --out is checked first
    taken = tmp_path / "taken.json"
    taken.write_text("{}")
    proc = cs.run("fit", data, "-m", "lambert", "--out", taken)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr == f"gonio: --out {taken}: exists and is not a folder\n"
    assert taken.read_text() == "{}"


def test_a_missing_file_exits_2_in_info_and_in_fit(tmp_path):
    missing = tmp_path / "nope.brdf"
    for args in (("info", missing), ("fit", missing, "-m", "lambert")):
        proc = cs.run(*args)
        assert proc.returncode == 2, (args, proc.stderr)
        assert proc.stderr.startswith("gonio: ") and proc.stderr.count("\n") == 1, proc.stderr
        assert "no such file" in proc.stderr and proc.stdout == ""


def test_demo_times_are_stated_with_the_machine_state():
    # the quick demo took 7 minutes on a busy machine where the help said "about 1"
    proc = cs.run("demo", "--help", columns=300)
    cs.assert_clean(proc)
    text = " ".join(proc.stdout.split())
    assert "About 2.3 minutes on an idle 2-core machine (--quick: about 45 s;" in text
    assert "several times as long on a machine busy with other work" in text
    readme = (Path(cs.SRC).parent / "README.md").read_text(encoding="utf-8")
    sentences = re.split(r"(?<=[.;])\s", " ".join(readme.split()))
    timed = [s for s in sentences if "demo" in s and re.search(r"\d\s*(minutes?|s)\b", s)]
    assert len(timed) >= 2
    for s in timed:
        assert re.search(r"idle|load|busy", s), s


def test_plan_refuses_a_negative_refusal_count():
    proc = cs.run(*PLAN, "--list-refused", "-1", columns=80)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.strip() == "gonio: --list-refused must be >= 0, got -1"
