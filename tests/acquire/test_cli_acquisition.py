"""Issue 21, acquisition items, through the real console entry (``python -m gonio``): one line on
stderr and no traceback for a lost or stale serial port and a closed pipe, no run directory
after a failed start, ``--resume RUN --rig OTHER`` refused."""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time
from importlib import resources

import pytest

from gonio.acquire.engine import acquire
from tests.acquire.child import done_samples, env, gonio, gonio_cmd

SIM_SAMPLE = resources.files("gonio.rigs").joinpath("sim_sample.toml").read_text()


def assert_one_line(err: str, *needles: str) -> None:
    assert "Traceback" not in err and "Exception ignored" not in err, err
    assert err.startswith("gonio: ") and err.count("\n") == 1, err
    for n in needles:
        assert n in err, err


def test_serial_adapter_unplugged_mid_acquisition_is_one_line(tmp_path):
    # the emulator in a process of its own stands for the USB adapter; killing it closes the
    # pseudo-terminal under the running acquisition, as unplugging does
    emu = subprocess.Popen(
        gonio_cmd("rig", "emulate", "--rig", "sim_sample"),
        env=env(),
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        port = emu.stdout.readline().split("port:")[1].strip()
        rig = tmp_path / "adapter.toml"
        rig.write_text(SIM_SAMPLE.replace('port = "sim"', f'port = "{port}"'))
        run = tmp_path / "run"
        acq = subprocess.Popen(
            gonio_cmd(
                "acquire", "--no-progress", "--rig", rig, "--plan", "iso-small", "--out", run
            ),
            env=env(),
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        t0 = time.monotonic()
        while acq.poll() is None and time.monotonic() - t0 < 120:
            if done_samples(run) >= 3:
                break
            time.sleep(0.01)
        emu.kill()
        _, err = acq.communicate(timeout=120)
    finally:
        emu.kill()
        emu.wait()
    assert acq.returncode == 3
    assert_one_line(err, f"servo bus {port} lost", "rig not parked", "torque state unknown")


def test_rig_check_on_a_stale_port_is_one_line(tmp_path):
    # a port that opens but whose device is gone at the first packet (a stale /dev/pts/N, an
    # adapter pulled while the port is open)
    master, slave = os.openpty()
    path = os.ttyname(slave)

    def unplug_on_first_byte():
        try:
            os.read(master, 1)
        except OSError:
            pass
        finally:
            os.close(master)

    t = threading.Thread(target=unplug_on_first_byte, daemon=True)
    t.start()
    rig = tmp_path / "stale.toml"
    rig.write_text(
        resources.files("gonio.rigs")
        .joinpath("sim.toml")
        .read_text()
        .replace('port = "sim"', f'port = "{path}"')
    )
    try:
        # the slave stays open here until the end, so that the master reads block until the
        # command's first packet (with no slave open they fail at once)
        out = gonio("rig", "check", "--rig", rig)
    finally:
        t.join(5)
        os.close(slave)
    assert out.returncode == 3
    assert_one_line(out.stderr, f"servo bus {path} lost")


def test_plan_into_a_closed_pipe_is_silent(tmp_path):
    # `gonio plan ... | head -1` where head has already gone
    proc = subprocess.Popen(
        gonio_cmd("plan", "--rig", "sim", "--plan", "iso-small"),
        env=env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    proc.stdout.close()
    err = proc.stderr.read().decode()
    proc.wait(timeout=120)
    assert err == "" and proc.returncode == 128 + signal.SIGPIPE


def test_failed_acquisition_start_leaves_no_run_directory(tmp_path):
    run = tmp_path / "RUN"
    for _ in range(2):  # the second attempt fails the same way: no "exists and is not empty"
        out = gonio("acquire", "--rig", "xm430_4axis", "--plan", "iso-tiny", "--out", run)
        assert out.returncode == 3
        assert_one_line(out.stderr, "cannot open servo bus /dev/ttyUSB0")
        assert not run.exists() and list(tmp_path.iterdir()) == []


@pytest.fixture(scope="module")
def interrupted_run(tmp_path_factory):
    """A sim_sample run of iso-small stopped after 3 samples (resumable)."""
    from gonio.errors import DeviceError

    run = tmp_path_factory.mktemp("resume") / "run"

    def stop(n, ses):
        if n == 3:
            raise DeviceError("stop here")

    with pytest.raises(DeviceError):
        acquire(run, "sim_sample", "iso-small", progress=False, on_sample=stop)
    return run


def test_resume_with_a_different_rig_is_refused(interrupted_run):
    out = gonio("acquire", "--resume", interrupted_run, "--rig", "sim")
    assert out.returncode == 2
    assert_one_line(out.stderr, "recorded on rig 'sim_sample'", "drop --rig")
    assert done_samples(interrupted_run) == 3  # nothing measured
    # the recorded rig itself may be named
    out = gonio("acquire", "--resume", interrupted_run, "--rig", "sim_sample", "--no-progress")
    assert out.returncode == 0, out.stderr
    assert "complete" in out.stdout


def test_plan_total_counts_the_measured_capture_cost():
    import json

    # the virtual camera's 2.99 s per configuration (measured), not the 5 ms exposure
    out = gonio("plan", "--rig", "sim", "--plan", "demo-quick", "--json")
    assert out.returncode == 0, out.stderr
    est = json.loads(out.stdout)
    assert est["per_configuration_s"]["capture"] == 2.99 and est["capture_cost_known"]
    assert est["predicted_total_s"] > 61 * 3.0  # a run of it took 183 s
    assert est["predicted_total_s"] - est["predicted_motion_s"] / est["time_scale"] == (
        pytest.approx(61 * (2.99 + 0.043 + 0.0075), abs=0.01)
    )
    help_text = gonio("plan", "--help").stdout
    assert "--timing-from" in help_text and "2.99 s per configuration" in help_text


def test_plan_of_a_never_measured_real_camera_says_so(tmp_path):
    text = resources.files("gonio.rigs").joinpath("xm430_4axis.toml").read_text()
    rig = tmp_path / "tethered.toml"
    rig.write_text(
        text.replace('kind = "sim"\nexposure_s = 0.02', 'kind = "gphoto2"\nexposure_s = 0.02')
    )
    out = gonio("plan", "--rig", rig, "--plan", "iso-tiny")
    assert out.returncode == 0, out.stderr
    # the text wraps at 80 columns when piped
    assert "capture cost of camera kind 'gphoto2' unknown: measure it with --timing-from RUN" in (
        " ".join(out.stdout.split())
    )


def test_plan_timing_from_a_previous_run_predicts_that_run(tmp_path):
    import json

    run = tmp_path / "run"
    acquire(run, "sim_sample", "iso-small", progress=False, write_table=False)
    out = gonio(
        "plan", "--rig", "sim_sample", "--plan", "iso-small", "--timing-from", run, "--json"
    )
    assert out.returncode == 0, out.stderr
    est = json.loads(out.stdout)
    assert est["costs_source"].startswith("measured: medians of")
    events = [json.loads(x) for x in (run / "log.jsonl").read_text().splitlines()]
    samples = [e for e in events if e["event"] == "sample"]
    n = len(samples)
    assert n == est["accepted"]
    import statistics

    per = est["per_configuration_s"]
    assert per["capture"] == round(statistics.median(e["t_capture"] for e in samples), 4)
    assert per["bookkeeping"] == round(statistics.median(e["t_book"] for e in samples), 4)
    overhead = statistics.median(e["move_wall_s"] - e["profile_wall_s"] for e in samples)
    assert per["move_overhead"] == round(max(0.0, overhead), 4)
    # the motion it predicts is the motion that run planned and executed (the wall time of the
    # run itself is not compared: on a shared machine it measures the load, not the planner)
    planned = sum(e["predicted_motion_s"] for e in events if e["event"] == "stage_planned")
    assert est["predicted_motion_s"] == pytest.approx(planned, abs=1e-3)
    scale = est["time_scale"]
    # each move's profile is recomputed from where the servos settled, not the planned pose
    assert sum(e["profile_wall_s"] for e in samples) == pytest.approx(planned / scale, rel=0.05)
    per_cfg = per["capture"] + per["bookkeeping"] + per["move_overhead"]
    # the three printed per-configuration costs are rounded to 1e-4 s each (the same error in
    # every configuration, so up to n x 1.5e-4 s), the total to 1e-3 s; the last term is slack
    # for the dry run's motion against the journal's (equal up to rounding, checked above)
    rounding = n * 3 * 0.5e-4 + 0.5e-3 + 0.5e-3 / scale
    assert est["predicted_total_s"] == pytest.approx(planned / scale + n * per_cfg, abs=rounding)
