"""Issue 21, "what trips a new user", through the installed ``gonio`` console script: a long
output into a pipe closed early, the plan and fit tables at 80 columns, and ``gonio plan``
starting without the heavy libraries."""

from __future__ import annotations

import json
import re
import subprocess
import sys

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
