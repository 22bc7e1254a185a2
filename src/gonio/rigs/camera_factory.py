"""The camera a rig file names, decided in one place (as :func:`gonio.rigs.lights.open_light`
does for lights).

The rig file's ``[camera] kind``:

============  =========  ==============================================================
kind          measures   backend
============  =========  ==============================================================
``sim``       RAW        :class:`~gonio.rigs.cameras.SimulatedRawCamera` (virtual camera)
``gphoto2``   RAW        :class:`~gonio.rigs.cameras.CommandLineCamera` (tethered camera)
``folder``    RAW        :class:`~gonio.rigs.cameras.FolderWatchCamera` (camera software)
``sim-sample`` directly  :class:`~gonio.rigs.sim.sample.SimulatedSampleCamera` (no images)
============  =========  ==============================================================

A RAW camera takes raw files; the imaging pipeline (:mod:`gonio.acquire.imaging`) turns them
into a measurement, so the run engine opens those through
:func:`gonio.acquire.imaging.open_run_camera`, which asks :func:`is_raw` and
:func:`open_raw_camera` here. A direct camera measures the BRDF itself
(:func:`open_direct_camera`).
"""

from __future__ import annotations

from gonio.errors import RigConfigError

#: Kinds whose camera takes raw files (measured through the imaging pipeline).
RAW_KINDS = ("sim", "gphoto2", "folder")
#: Kinds whose camera returns a measurement directly.
DIRECT_KINDS = ("sim-sample",)


def camera_kind(rig) -> str:
    """The rig file's ``[camera] kind`` (default ``"sim"``); RigConfigError if unknown."""
    kind = rig.camera.get("kind", "sim")
    if kind not in RAW_KINDS + DIRECT_KINDS:
        raise RigConfigError(f"{rig.source}: camera.kind {kind!r} has no backend")
    return kind


def is_raw(rig) -> bool:
    """Whether the rig's camera takes raw files (measured through the imaging pipeline)."""
    return camera_kind(rig) in RAW_KINDS


def channels(rig) -> tuple[str, ...]:
    """Channel names of the rig's measurements: R, G, B for RAW cameras (demosaicked), the
    simulated sample's own channels for ``sim-sample``."""
    if is_raw(rig):
        return ("R", "G", "B")
    return tuple(open_direct_camera(rig).channels)


def open_direct_camera(rig):
    """The :class:`gonio.rigs.devices.Camera` of a direct kind (``"sim-sample"``)."""
    kind = camera_kind(rig)
    if kind != "sim-sample":
        raise RigConfigError(
            f"{rig.source}: camera.kind {kind!r} is a RAW camera: the imaging pipeline opens"
            " it (gonio.acquire.imaging.open_run_camera)"
        )
    from gonio.rigs.sim.sample import SimulatedSampleCamera

    return SimulatedSampleCamera(rig)


def open_raw_camera(rig, light, optics, sensor, layout):
    """The :class:`gonio.rigs.cameras.RawCamera` of a RAW kind.

    Parameters
    ----------
    rig : RigConfig
    light : the rig's :class:`gonio.rigs.lights.Light` (the simulated camera reads its state).
    optics, sensor, layout : :class:`gonio.rigs.sim.camera.PinholeCamera`,
        :class:`gonio.rigs.sim.sensor.SensorModel` and
        :class:`gonio.rigs.sim.camera.HolderLayout` (used by the simulated camera).
    """
    from gonio.rigs.cameras import CommandLineCamera, FolderWatchCamera, SimulatedRawCamera

    c = rig.camera
    kind = camera_kind(rig)
    if kind == "sim":
        from gonio.rigs.sim.camera import VirtualCamera
        from gonio.rigs.sim.truth import load_truth

        virtual = VirtualCamera(
            truth=load_truth(rig.sim.sample, rig.source),
            layout=layout,
            camera=optics,
            sensor=sensor,
            supersample=int(c.get("supersample", 2)),
            seed=rig.sim.seed,
        )
        # the rig file gives the irradiance on a surface facing the light at the sample centre
        d = rig.layout.light_distance_m
        intensity = float(rig.light.get("irradiance_w_m2", 10.0)) * d * d
        return SimulatedRawCamera(virtual, light, intensity)
    if kind == "gphoto2":
        return CommandLineCamera(
            program=str(c.get("program", "gphoto2")),
            port=c.get("port"),
            shutter_key=str(c.get("shutter_key", "shutterspeed")),
            timeout_s=float(c.get("timeout_s", 30.0)),
        )
    if kind == "folder":
        if "folder" not in c:
            raise RigConfigError(f"{rig.source}: camera.folder is required for kind 'folder'")
        return FolderWatchCamera(
            c["folder"], str(c.get("pattern", "*.dng")), float(c.get("timeout_s", 60.0))
        )
    raise RigConfigError(f"{rig.source}: camera.kind {kind!r} is not a RAW camera")
