"""Issue 44, locks: a run folder is held by the acquisition writing it, a serial port by the
process driving it. The bus is an emulator in a process of its own on a shared
pseudo-terminal (``gonio rig emulate --packet-log``), as a USB adapter would be; a second
``gonio acquire`` started while the first one runs is refused in one line naming the first's
PID, before it sends a single packet. Readers of the run stay allowed."""

from __future__ import annotations

import os
import signal
import subprocess
from importlib import resources
from pathlib import Path

import pytest

from gonio.acquire.engine import acquire
from gonio.cli import main
from gonio.rigs.sim.bus import read_packet_log
from tests.acquire.child import env, gonio, gonio_cmd

SIM_SAMPLE = resources.files("gonio.rigs").joinpath("sim_sample.toml").read_text()


@pytest.fixture(scope="module")
def bus(tmp_path_factory):
    """``(rig file on the emulator's pty, its packet log)``; the emulator runs for the module."""
    d = tmp_path_factory.mktemp("bus")
    packets = d / "packets.jsonl"
    emu = subprocess.Popen(
        gonio_cmd("rig", "emulate", "--rig", "sim_sample", "--packet-log", packets),
        env=env(),
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        port = emu.stdout.readline().split("port:")[1].strip()
        rig = d / "adapter.toml"
        rig.write_text(SIM_SAMPLE.replace('port = "sim"', f'port = "{port}"'))
        yield rig, packets
    finally:
        emu.send_signal(signal.SIGTERM)
        emu.wait(timeout=10)


def n_packets(log: Path) -> int:
    return len(read_packet_log(log)) if log.exists() else 0


def assert_refused(r: subprocess.CompletedProcess, *needles: str) -> None:
    err = r.stderr
    assert r.returncode == 6, err
    assert "Traceback" not in err and err.startswith("gonio: ") and err.count("\n") == 1, err
    for n in needles:
        assert n in err, err


def test_second_acquisition_of_a_running_run_folder_is_refused(tmp_path, bus):
    rig, packets = bus
    run = tmp_path / "run"
    seen = []

    def second(n, ses):
        if n != 2:
            return
        # the first acquisition waits in this callback: every packet from here on is the
        # second process's
        before = n_packets(packets)
        seen.append(gonio("acquire", "--no-progress", "--resume", run))
        seen.append(n_packets(packets) - before)

    s = acquire(run, str(rig), "iso-tiny", progress=False, on_sample=second)
    assert s.complete
    refused, sent = seen
    assert_refused(refused, f"run folder {run} is in use by process {os.getpid()}")
    assert sent == 0
    # released at the end: a reader of its table takes no lock, a resume takes it again
    assert main(["info", str(run / "table.brdf.h5")]) == 0
    assert acquire(run, resume=True, progress=False).complete
    assert not (run / ".lock.pid").exists()


def test_second_acquisition_on_a_busy_serial_port_is_refused(tmp_path, bus, capsys):
    rig, packets = bus
    seen = []

    def second(n, ses):
        if n != 2:
            return
        before = n_packets(packets)
        out = tmp_path / "run2"
        seen.append(
            gonio("acquire", "--no-progress", "--rig", rig, "--plan", "iso-tiny", "--out", out)
        )
        seen.append(n_packets(packets) - before)
        seen.append(out.exists())
        seen.append(main(["rig", "check", "--rig", str(rig)]))  # in this process: its own lock

    s = acquire(tmp_path / "run1", str(rig), "iso-tiny", progress=False, on_sample=second)
    assert s.complete
    refused, sent, left_a_run, check = seen
    port = rig.read_text().split('port = "')[1].split('"')[0]
    assert_refused(refused, f"serial port {port} is in use by process {os.getpid()}")
    assert sent == 0 and not left_a_run
    assert check == 6
    assert f"serial port {port} is in use by process {os.getpid()}" in capsys.readouterr().err
