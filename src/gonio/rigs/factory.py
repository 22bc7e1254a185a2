"""Devices from a rig file, keyed by its kinds: ``[light] kind`` and ``[camera] kind``.

:data:`LIGHTS` and :data:`CAMERAS` map each kind to the function that builds its backend (the
table of backends is in :mod:`gonio.rigs.devices`); a new backend is one module plus one line
here. :func:`gonio.rigs.session.open_rig` is the caller: it opens the light, then the camera,
then the servos, and closes them in reverse.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from gonio.errors import RigConfigError

if TYPE_CHECKING:
    from gonio.rigs.config import RigConfig
    from gonio.rigs.devices import Camera, Light
    from gonio.rigs.sim.camera import HolderLayout, PinholeCamera
    from gonio.rigs.sim.sensor import SensorModel


def _sim_light(rig: RigConfig) -> Light:
    from gonio.rigs.lights import SimulatedLight

    return SimulatedLight(float(rig.light.get("intensity", 1.0)))


def _serial_light(rig: RigConfig) -> Light:
    from gonio.rigs.lights import SerialLEDLight

    cfg = rig.light
    if "port" not in cfg:
        raise RigConfigError(f"{rig.source}: light.port is required for kind 'serial'")
    return SerialLEDLight(
        cfg["port"],
        int(cfg.get("baudrate", 115200)),
        float(cfg.get("timeout_s", 1.0)),
        float(cfg.get("intensity", 1.0)),
    )


def optics(rig: RigConfig) -> PinholeCamera:
    """The camera's intrinsics from ``[camera] width, height, focal_px`` (pixels)."""
    from gonio.rigs.sim.camera import PinholeCamera

    c = rig.camera
    return PinholeCamera(
        int(c.get("width", 640)), int(c.get("height", 480)), float(c.get("focal_px", 2400.0))
    )


def sensor(rig: RigConfig) -> SensorModel:
    """The camera's sensor from ``[camera.sensor]``."""
    from gonio.rigs.sim.sensor import SensorModel

    return SensorModel(**dict(rig.camera.get("sensor", {})))


def holder(rig: RigConfig) -> HolderLayout:
    """The sample holder the camera sees (ChArUco board, sample, white reference)."""
    from gonio.rigs.sim.camera import HolderLayout

    return HolderLayout()


def _sim_camera(rig: RigConfig, light: Light, layout: HolderLayout) -> Camera:
    from gonio.rigs.cameras import SimulatedRawCamera
    from gonio.rigs.sim.camera import VirtualCamera
    from gonio.rigs.sim.truth import load_truth

    virtual = VirtualCamera(
        truth=load_truth(rig.sim.sample, rig.source),
        layout=layout,
        camera=optics(rig),
        sensor=sensor(rig),
        supersample=int(rig.camera.get("supersample", 2)),
        seed=rig.sim.seed,
    )
    # the rig file gives the irradiance on a surface facing the light at the sample centre
    d = rig.layout.light_distance_m
    intensity = float(rig.light.get("irradiance_w_m2", 10.0)) * d * d
    return SimulatedRawCamera(virtual, light, intensity)


def _gphoto2_camera(rig: RigConfig, light: Light, layout: HolderLayout) -> Camera:
    from gonio.rigs.cameras import CommandLineCamera

    c = rig.camera
    return CommandLineCamera(
        program=str(c.get("program", "gphoto2")),
        port=c.get("port"),
        shutter_key=str(c.get("shutter_key", "shutterspeed")),
        timeout_s=float(c.get("timeout_s", 30.0)),
        optics=optics(rig),
        sensor=sensor(rig),
    )


def _folder_camera(rig: RigConfig, light: Light, layout: HolderLayout) -> Camera:
    from gonio.rigs.cameras import FolderWatchCamera

    c = rig.camera
    if "folder" not in c:
        raise RigConfigError(f"{rig.source}: camera.folder is required for kind 'folder'")
    return FolderWatchCamera(
        c["folder"],
        str(c.get("pattern", "*.dng")),
        float(c.get("timeout_s", 60.0)),
        optics=optics(rig),
        sensor=sensor(rig),
    )


def _sim_sample_camera(rig: RigConfig, light: Light, layout: HolderLayout) -> Camera:
    from gonio.rigs.sim.sample import SimulatedSampleCamera

    return SimulatedSampleCamera(rig)


#: ``[light] kind`` -> ``build(rig)``.
LIGHTS: dict[str, Callable[[RigConfig], Light]] = {"sim": _sim_light, "serial": _serial_light}

#: ``[camera] kind`` -> ``build(rig, light, holder)`` (the simulated camera reads the light's
#: state and renders the holder).
CAMERAS: dict[str, Callable[[RigConfig, Light, HolderLayout], Camera]] = {
    "sim": _sim_camera,
    "gphoto2": _gphoto2_camera,
    "folder": _folder_camera,
    "sim-sample": _sim_sample_camera,
}


def light_kind(rig: RigConfig) -> str:
    """The rig file's ``[light] kind`` (default ``"sim"``); RigConfigError if unknown."""
    kind = rig.light.get("kind", "sim")
    if kind not in LIGHTS:
        raise RigConfigError(f"{rig.source}: light.kind {kind!r} has no backend")
    return kind


def camera_kind(rig: RigConfig) -> str:
    """The rig file's ``[camera] kind`` (default ``"sim"``); RigConfigError if unknown."""
    kind = rig.camera.get("kind", "sim")
    if kind not in CAMERAS:
        raise RigConfigError(f"{rig.source}: camera.kind {kind!r} has no backend")
    return kind


def open_light(rig: RigConfig) -> Light:
    """The light the rig file names (switched off, or on for the simulated light)."""
    return LIGHTS[light_kind(rig)](rig)


def open_camera(rig: RigConfig, light: Light, layout: HolderLayout) -> Camera:
    """The camera the rig file names, lit by ``light`` and looking at the holder ``layout``."""
    return CAMERAS[camera_kind(rig)](rig, light, layout)
