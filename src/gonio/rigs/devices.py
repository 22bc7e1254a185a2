"""Device protocols the run engine talks to: the camera and what it is told and returns.

Only the interfaces live here. The camera a rig file names is opened by
:mod:`gonio.rigs.camera_factory` (RAW cameras through the imaging pipeline,
:class:`gonio.acquire.imaging.ImagingCamera`; the direct ``sim-sample`` reading,
:class:`gonio.rigs.sim.sample.SimulatedSampleCamera`); the servos by
:func:`gonio.rigs.session.open_rig`.
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
