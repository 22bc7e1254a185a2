"""The command line: rig check, plan --dry-run, acquire errors (one line, non-zero status)."""

from __future__ import annotations

import json

from gonio.cli import main


def test_rig_check_json(capsys):
    assert main(["rig", "check", "--rig", "sim", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["ok"] and [s["model"] for s in out["servos"]] == ["XM430-W350"] * 4
    assert out["servos"][2]["limits_deg"] == [-85.0, 85.0]


def test_rig_check_missing_port_is_one_line(capsys):
    assert main(["rig", "check", "--rig", "xm430_4axis"]) == 3
    err = capsys.readouterr().err
    assert err.startswith("gonio: cannot open servo bus /dev/ttyUSB0") and err.count("\n") == 1


def test_bad_rig_file_is_one_line_naming_key(tmp_path, capsys):
    from importlib import resources

    text = resources.files("gonio.rigs").joinpath("sim.toml").read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace("retries = 6", "retries = -1"))
    assert main(["plan", "--rig", str(bad), "--plan", "iso-tiny"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "bus.retries" in err and f"{bad}:" in err


def test_plan_dry_run_json(capsys):
    assert main(["plan", "--rig", "sim", "--plan", "iso-small", "--dry-run", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["targets"] == out["accepted"] + out["refused"]
    assert out["refused"] == len(out["refusals"]) > 0
    assert all(r["reason"] for r in out["refusals"])
    assert 0 < out["predicted_motion_s"] <= out["plan_order_motion_s"]


def test_acquire_argument_errors(tmp_path, capsys):
    assert main(["acquire", "--plan", "iso-tiny"]) == 2
    assert "needs --plan and --out" in capsys.readouterr().err
    assert main(["acquire", "--resume", str(tmp_path)]) == 2
    assert "not a gonio run" in capsys.readouterr().err
    assert (
        main(
            [
                "acquire",
                "--plan",
                "iso-tiny",
                "--out",
                str(tmp_path / "r"),
                "--sim-faults",
                "drop=2",
            ]
        )
        == 2
    )
    assert "probability" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()
    for scale in ("inf", "nan", "1e300", "0"):  # inf overflowed the emulator's clock
        out = ["--out", str(tmp_path / "r"), "--time-scale", scale]
        assert main(["acquire", "--rig", "sim", "--plan", "iso-tiny", *out]) == 2
        assert "--time-scale must be in (0, 1e6]" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


def test_acquire_tiny_run_text_output(tmp_path, capsys):
    assert (
        main(
            [
                "acquire",
                "--rig",
                "sim_sample",
                "--plan",
                "iso-tiny",
                "--out",
                str(tmp_path / "r"),
                "--no-progress",
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "complete" in out
    # a second run into the same directory is refused
    assert (
        main(["acquire", "--rig", "sim_sample", "--plan", "iso-tiny", "--out", str(tmp_path / "r")])
        == 2
    )


def test_resume_of_a_corrupt_journal_is_one_line(tmp_path, capsys):
    run = tmp_path / "r"
    run.mkdir()
    (run / "journal.sqlite").write_bytes(b"this is not sqlite" * 100)
    assert main(["acquire", "--resume", str(run)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("gonio: ") and err.count("\n") == 1 and "journal" in err
