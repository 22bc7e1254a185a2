"""The rig session opens every device of a rig file in order and closes them in reverse."""

from __future__ import annotations

import signal

import pytest

from gonio.errors import DeviceError, Interrupted, ParameterError
from gonio.rigs import factory
from gonio.rigs.config import load_rig
from gonio.rigs.dynamixel import ServoChain
from gonio.rigs.session import DEVICES, open_rig
from gonio.rigs.sim.bus import ServoChainEmulator

RIG = load_rig("sim_sample")


@pytest.fixture
def events(monkeypatch):
    """The devices' opening and closing, in order."""
    seen: list[str] = []
    open_light, open_camera = factory.open_light, factory.open_camera

    def light(rig):
        lt = open_light(rig)
        seen.append("light")
        monkeypatch.setattr(lt, "close", lambda: seen.append("close light"))
        return lt

    def camera(rig, lt, holder):
        cam = open_camera(rig, lt, holder)
        seen.append("camera")
        monkeypatch.setattr(cam, "close", lambda: seen.append("close camera"))
        return cam

    def closing(cls, name, event):
        original = getattr(cls, name)

        def wrapped(self):
            seen.append(event)
            return original(self)

        monkeypatch.setattr(cls, name, wrapped)

    closing(ServoChainEmulator, "start", "start emulator")
    closing(ServoChain, "close", "close servos")
    closing(ServoChainEmulator, "stop", "stop emulator")
    monkeypatch.setattr(factory, "open_light", light)
    monkeypatch.setattr(factory, "open_camera", camera)
    return seen


def test_session_opens_every_device_and_closes_them_in_reverse(events):
    assert DEVICES == ("light", "camera", "servos")
    with pytest.raises(RuntimeError, match="stop"):
        with open_rig(RIG) as ses:
            assert ses.light.is_on and ses.camera.channels == ("R", "G", "B")
            assert ses.chain is not None and ses.emulator is not None
            events.append("servos")
            raise RuntimeError("stop")
    assert events == [
        "light", "camera", "start emulator", "servos", "close servos", "stop emulator",
        "close camera", "close light",
    ]  # fmt: skip
    events.clear()
    with open_rig(RIG, devices=("servos",)) as ses:  # what `gonio rig check` opens
        assert ses.camera is None and ses.light is None and ses.chain is not None
    assert events == ["start emulator", "close servos", "stop emulator"]
    with pytest.raises(ParameterError, match="with its light"):
        with open_rig(RIG, devices=("camera",)):
            pass
    with pytest.raises(ParameterError, match="no such device"):
        with open_rig(RIG, devices=("servos", "turntable")):
            pass


def test_a_camera_that_fails_to_open_closes_the_light_and_powers_nothing(events, monkeypatch):
    def broken(rig, lt, holder):
        events.append("camera")
        raise DeviceError("camera: no such folder")

    monkeypatch.setattr(factory, "open_camera", broken)
    with pytest.raises(DeviceError, match="no such folder"):
        with open_rig(RIG):
            pytest.fail("the session opened")
    assert events == ["light", "camera", "close light"]


def test_before_servos_runs_between_the_camera_and_the_servos(events):
    def stop():
        events.append("before servos")
        raise Interrupted("interrupted (SIGINT)", signal.SIGINT)

    with pytest.raises(Interrupted):
        with open_rig(RIG, before_servos=stop):
            pytest.fail("the session opened")
    assert events == ["light", "camera", "before servos", "close camera", "close light"]
