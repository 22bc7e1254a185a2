"""Device interfaces the run engine talks to (camera, measurement geometry).

The imaging work adds RAW-writing cameras behind the same :class:`Camera` protocol; until then
the simulated rig's camera (:class:`gonio.rigs.sim.sample.SimulatedSampleCamera`) returns the
reflectance of a simulated sample computed from the joint angles read back from the bus.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np


@dataclass(frozen=True)
class Geometry:
    """Where the rig actually is when a frame is taken.

    Attributes
    ----------
    index : int
        Journal index of the configuration (also seeds simulated noise).
    joints_deg : dict
        Joint angles read back from the servos (degrees, by joint name).
    wi, wo : (3,) arrays
        Directions toward light and camera in the sample frame, from those angles.
    light_pos_m, camera_pos_m : (3,) arrays or None
        Nominal light and camera positions in the sample frame (m): the directions times the
        rig file's layout distances (finite-distance geometry for the imaging side).
    """

    index: int
    joints_deg: dict[str, float]
    wi: np.ndarray
    wo: np.ndarray
    light_pos_m: np.ndarray | None = None
    camera_pos_m: np.ndarray | None = None


@dataclass(frozen=True)
class Capture:
    """One measurement: BRDF value and its 1-sigma uncertainty per channel (1/sr)."""

    value: np.ndarray
    sigma: np.ndarray
    channels: tuple[str, ...]
    meta: dict = field(default_factory=dict)


class Camera(Protocol):
    """A camera (with its light) that measures the sample at the current rig geometry."""

    channels: tuple[str, ...]

    def capture(self, geometry: Geometry, exposure_s: float | None = None) -> Capture:
        """Take one measurement at ``geometry``; ``exposure_s`` overrides the default."""
        ...


def open_camera(rig) -> Camera:
    """The non-imaging camera backend of the rig file's ``[camera] kind`` (``"sim-sample"``).

    RAW cameras (``"sim"``, ``"gphoto2"``, ``"folder"``) are opened by
    :func:`gonio.acquire.imaging.open_imaging_camera`.
    """
    from gonio.errors import RigConfigError

    kind = rig.camera.get("kind", "sim")
    if kind == "sim-sample":
        from gonio.rigs.sim.sample import SimulatedSampleCamera

        return SimulatedSampleCamera(rig)
    if kind in ("sim", "gphoto2", "folder"):
        # RAW cameras measure through the imaging pipeline (gonio.acquire.imaging), which needs
        # a run directory for its files; the run engine opens them there.
        raise RigConfigError(
            f"{rig.source}: camera.kind {kind!r} is a RAW camera: open it with"
            " gonio.acquire.imaging.open_imaging_camera"
        )
    raise RigConfigError(f"{rig.source}: camera.kind {kind!r} has no backend")
