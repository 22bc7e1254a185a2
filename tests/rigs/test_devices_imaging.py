"""Camera and light backends: gphoto2 (a fake program on PATH), folder watch, LED protocol."""

import dataclasses
import os
import shutil
import stat
import sys
import threading
import time

import numpy as np
import pytest

from gonio.errors import DeviceError, ParameterError
from gonio.io.dng import read_dng, write_dng
from gonio.rigs.cameras import (
    CommandLineCamera,
    FolderWatchCamera,
    format_shutter,
    parse_saved_path,
)
from gonio.rigs.lights import SerialLEDLight, SimulatedLight
from gonio.rigs.sim.led import LEDDriverEmulator

# --- gphoto2 ------------------------------------------------------------------------------

FAKE_GPHOTO2 = """#!{python}
import json, sys
from pathlib import Path
args = sys.argv[1:]
Path({log!r}).open("a").write(json.dumps(args) + "\\n")
if "--version" in args:
    print("gphoto2 2.5.28 (fake)")
    sys.exit(0)
if {fail!r}:
    print("*** Error: No camera found. ***", file=sys.stderr)
    sys.exit(1)
name = args[args.index("--filename") + 1]
dest = Path(name).with_suffix(".dng")
dest.write_bytes(Path({src!r}).read_bytes())
print("New file is in location /capt0000.dng on the camera")
print("Saving file as " + str(dest))
print("Deleting file /capt0000.dng on the camera")
"""


def _fake_program(tmp_path, monkeypatch, fail=False):
    src = tmp_path / "source.dng"
    data = ((np.arange(64 * 64).reshape(64, 64) * 7) % 3000 + 512).astype(np.uint16)
    write_dng(src, data, exposure_s=0.004, black_level=512, white_level=4095)
    bindir = tmp_path / "bin"
    bindir.mkdir()
    prog = bindir / "gphoto2"
    log = tmp_path / "calls.jsonl"
    prog.write_text(
        FAKE_GPHOTO2.format(python=sys.executable, log=str(log), fail=fail, src=str(src))
    )
    prog.chmod(prog.stat().st_mode | stat.S_IEXEC)
    monkeypatch.setenv("PATH", f"{bindir}{os.pathsep}{os.environ['PATH']}")
    return data, log


def test_shutter_text():
    assert format_shutter(1 / 250) == "1/250"
    assert format_shutter(0.004) == "1/250"
    assert format_shutter(2.0) == "2"
    assert format_shutter(0.3) == "1/3.33333"
    with pytest.raises(ParameterError):
        format_shutter(0.0)


def test_command_line_is_gphoto2s(tmp_path):
    cam = CommandLineCamera(port="usb:001,004")
    cmd = cam.command(1 / 125, tmp_path / "c0.dng")
    assert cmd == [
        "gphoto2", "--port", "usb:001,004", "--set-config-value", "shutterspeed=1/125",
        "--capture-image-and-download", "--filename", str(tmp_path / "c0.dng"),
        "--force-overwrite",
    ]  # fmt: skip
    out = "New file is in location /x.cr2\nSaving file as /tmp/a b/c0.cr2\nDeleting\n"
    assert str(parse_saved_path(out)) == "/tmp/a b/c0.cr2"
    assert parse_saved_path("nothing saved") is None


def test_fake_gphoto2_capture_round_trip(tmp_path, monkeypatch):
    data, log = _fake_program(tmp_path, monkeypatch)
    cam = CommandLineCamera(timeout_s=20)
    assert "fake" in cam.version()
    path = cam.capture(0.004, tmp_path / "c0001.dng")
    assert path == tmp_path / "c0001.dng"
    assert np.array_equal(read_dng(path).data, data)
    import json

    calls = [json.loads(x) for x in log.read_text().splitlines()]
    assert calls[-1][:2] == ["--set-config-value", "shutterspeed=1/250"]


def test_fake_gphoto2_failure_is_a_device_error(tmp_path, monkeypatch):
    _fake_program(tmp_path, monkeypatch, fail=True)
    with pytest.raises(DeviceError, match="No camera found"):
        CommandLineCamera(timeout_s=20).capture(0.01, tmp_path / "x.dng")


def test_missing_program_is_a_device_error(tmp_path):
    with pytest.raises(DeviceError, match="not found"):
        CommandLineCamera(program="gonio-no-such-camera-program").capture(0.01, tmp_path / "x")


@pytest.mark.skipif(shutil.which("gphoto2") is None, reason="gphoto2 is not installed")
def test_real_gphoto2_runs():
    assert "gphoto2" in CommandLineCamera().version().lower()


# --- folder watch ---------------------------------------------------------------------------


def test_folder_watch_takes_the_next_new_file(tmp_path):
    watched = tmp_path / "camera"
    watched.mkdir()
    (watched / "old.dng").write_bytes(b"old")
    cam = FolderWatchCamera(watched, timeout_s=10, stable_s=0.1, poll_s=0.02)

    def shoot(exposure_s):
        def later():
            time.sleep(0.2)
            p = watched / "IMG_0002.dng"
            with open(p, "wb") as fh:  # written in two parts: must wait until it stops growing
                fh.write(b"a" * 100)
                fh.flush()
                time.sleep(0.05)
                fh.write(b"b" * 100)

        threading.Thread(target=later, daemon=True).start()

    cam.trigger = shoot
    (tmp_path / "out").mkdir()
    got = cam.capture(0.01, tmp_path / "out" / "c0.dng")
    assert got == tmp_path / "out" / "c0.dng"
    assert got.read_bytes() == b"a" * 100 + b"b" * 100
    assert (watched / "old.dng").exists() and not (watched / "IMG_0002.dng").exists()


def test_folder_watch_times_out(tmp_path):
    cam = FolderWatchCamera(tmp_path, timeout_s=0.3, poll_s=0.02)
    with pytest.raises(DeviceError, match="no new"):
        cam.capture(0.01, tmp_path / "x.dng")
    with pytest.raises(DeviceError, match="does not exist"):
        FolderWatchCamera(tmp_path / "nope")


# --- lights -----------------------------------------------------------------------------------


def test_simulated_light_state():
    light = SimulatedLight(0.5)
    assert light.output == 0.5
    light.off()
    assert light.output == 0.0
    light.on()
    light.set_intensity(1.0)
    assert light.output == 1.0
    with pytest.raises(ParameterError):
        light.set_intensity(1.5)


def test_serial_led_protocol_byte_for_byte():
    with LEDDriverEmulator() as emu:
        light = SerialLEDLight(emu.port, timeout_s=2.0, intensity=0.25)
        try:
            light.on()
            assert emu.level == 250 and light.level() == 250
            light.set_intensity(0.5)
            assert emu.level == 500
            light.off()
            assert emu.level == 0
        finally:
            light.close()
        assert emu.received == [b"ID?", b"L 0", b"L 250", b"L?", b"L 500", b"L 0", b"L 0"]


def test_serial_led_errors():
    with LEDDriverEmulator() as emu:
        light = SerialLEDLight(emu.port, timeout_s=2.0)
        try:
            with pytest.raises(DeviceError, match="ERR range"):
                light._set(1001)
        finally:
            light.close()
    with LEDDriverEmulator(silent=True) as emu:
        with pytest.raises(DeviceError, match="no reply"):
            SerialLEDLight(emu.port, timeout_s=0.3)
    with pytest.raises(DeviceError, match="cannot open"):
        SerialLEDLight("/dev/gonio-no-such-port")


def test_factory_decides_the_kind_in_one_place():
    from gonio.errors import RigConfigError
    from gonio.rigs import factory
    from gonio.rigs.config import load_rig
    from gonio.rigs.sim.sample import SimulatedSampleCamera

    sim, direct = load_rig("sim"), load_rig("sim_sample")
    light = factory.open_light(sim)
    raw = factory.open_camera(sim, light, factory.holder(sim))
    reading = factory.open_camera(direct, light, factory.holder(direct))
    assert raw.takes_raw and not reading.takes_raw
    assert raw.channels == ("R", "G", "B")
    assert reading.channels == ("R", "G", "B")  # the Phong truth is RGB
    assert isinstance(reading, SimulatedSampleCamera)
    assert isinstance(light, SimulatedLight)
    with pytest.raises(RigConfigError, match="has no backend"):
        factory.open_camera(dataclasses.replace(sim, camera={"kind": "webcam"}), light, None)
    with pytest.raises(RigConfigError, match="has no backend"):
        factory.open_light(dataclasses.replace(sim, light={"kind": "candle"}))
