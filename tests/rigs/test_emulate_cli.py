"""`gonio rig emulate` in a subprocess, driven like hardware through a rig file's port path."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from gonio.cli import main

SRC = str(Path(__file__).resolve().parents[2] / "src")

# The emulator behind a port path is what is tested; the shipped rig with the direct BRDF
# reading (sim_sample) drives it as the imaging rig (sim) does, without rendering and measuring
# camera frames, which tests/acquire/test_imaging_run.py covers. The imaging rig runs with -m slow.
RIGS = ["sim_sample", pytest.param("sim", marks=pytest.mark.slow)]


@pytest.mark.parametrize("rig_name", RIGS)
def test_external_emulator_is_driven_like_hardware(tmp_path, capsys, rig_name):
    from importlib import resources

    env = dict(os.environ, PYTHONPATH=SRC, JAX_PLATFORMS="cpu")
    goals = tmp_path / "goals.jsonl"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "gonio",
            "rig",
            "emulate",
            "--rig",
            rig_name,
            "--goal-log",
            str(goals),
        ],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = proc.stdout.readline()
        assert line.startswith("port: /dev/"), line + proc.stderr.read()
        port = line.split(":", 1)[1].strip()
        text = resources.files("gonio.rigs").joinpath(f"{rig_name}.toml").read_text()
        rig = tmp_path / "bench.toml"
        rig.write_text(text.replace('port = "sim"', f'port = "{port}"'))
        assert main(["rig", "check", "--rig", str(rig), "--json"]) == 0
        report = json.loads(capsys.readouterr().out)
        assert report["ok"] and report["port"] == port
        run = tmp_path / "run"
        assert (
            main(
                [
                    "acquire",
                    "--rig",
                    str(rig),
                    "--plan",
                    "iso-tiny",
                    "--out",
                    str(run),
                    "--no-progress",
                    "--json",
                ]
            )
            == 0
        )
        summary = json.loads(capsys.readouterr().out)
        assert summary["complete"] and summary["done"] > 0
        assert not (run / "sim_goals.jsonl").exists()  # not the built-in emulator
        assert len(goals.read_text().splitlines()) >= 4 * summary["done"]
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=10)
    assert proc.returncode == 0
