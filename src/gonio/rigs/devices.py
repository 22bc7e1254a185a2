"""The rig's devices: one protocol per kind (servos, camera, light), and what a camera is told
and returns.

Who opens what
--------------
:func:`gonio.rigs.session.open_rig` opens every device of a rig file in the order of
:data:`gonio.rigs.session.DEVICES` (light, camera, servos) and closes them in reverse on every
way out; the backends are built by :mod:`gonio.rigs.factory`, keyed by the rig file's kinds:

=========  ===============  ==================================================================
device     kind             backend
=========  ===============  ==================================================================
servos     ``[bus] port``   :class:`~gonio.rigs.dynamixel.ServoChain` (the emulator's pty for
                            ``"sim"``)
light      ``sim``          :class:`~gonio.rigs.lights.SimulatedLight`
light      ``serial``       :class:`~gonio.rigs.lights.SerialLEDLight` (LED driver)
camera     ``sim``          :class:`~gonio.rigs.cameras.SimulatedRawCamera` (virtual camera)
camera     ``gphoto2``      :class:`~gonio.rigs.cameras.CommandLineCamera` (tethered camera)
camera     ``folder``       :class:`~gonio.rigs.cameras.FolderWatchCamera` (camera software)
camera     ``sim-sample``   :class:`~gonio.rigs.sim.sample.SimulatedSampleCamera` (no images)
=========  ===============  ==================================================================

The run engine (:mod:`gonio.acquire.engine`) receives the open devices from the session. A
camera whose :attr:`Camera.takes_raw` is true (a :class:`RawCamera`) takes raw frames, which the
imaging chain of :mod:`gonio.acquire.imaging` turns into a measurement (brackets, HDR merge,
pose, radiometry); otherwise it is a :class:`DirectCamera` that reads the BRDF itself.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

if TYPE_CHECKING:
    from gonio.rigs.dynamixel import MoveResult, ServoInfo
    from gonio.rigs.sim.camera import PinholeCamera
    from gonio.rigs.sim.sensor import SensorModel


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


class Servos(Protocol):
    """The servo chain that moves the rig (:class:`gonio.rigs.dynamixel.ServoChain`).

    Angles are degrees by joint name. :attr:`should_abort` is polled while a move settles; True
    aborts it. :meth:`park` and :meth:`torque_off` are what every way out of a run uses
    (:mod:`gonio.acquire.stopping`).
    """

    should_abort: Callable[[], bool]

    def open(self) -> None: ...

    def initialize(self) -> None:
        """Identify every servo (a wrong model refuses the rig with no torque on), configure
        it, torque on."""
        ...

    def check(self) -> list[ServoInfo]:
        """Ping every servo: model, firmware, hardware error, torque, position."""
        ...

    def move(self, targets_deg: Mapping[str, float]) -> MoveResult:
        """Move every joint at once and wait until all settle; returns the angles read back."""
        ...

    def park(self) -> MoveResult: ...

    def torque_off(self) -> list[int]:
        """Torque off everywhere; the ids of servos that did not acknowledge."""
        ...

    def bus_stats(self) -> dict[str, int]: ...

    def close(self) -> None: ...


class Light(Protocol):
    """A light source: ``intensity`` is relative, in [0, 1]; the session switches it on once
    open, the imaging chain off and on again around dark frames."""

    is_on: bool
    intensity: float

    def on(self) -> None: ...

    def off(self) -> None: ...

    def set_intensity(self, value: float) -> None: ...

    def close(self) -> None: ...


class Camera(Protocol):
    """What every camera offers: its measurement channels, whether it takes raw frames (then it
    is a :class:`RawCamera`, else a :class:`DirectCamera`), and :meth:`close`."""

    takes_raw: bool
    channels: tuple[str, ...]

    def close(self) -> None: ...


class RawCamera(Camera, Protocol):
    """A camera that takes raw exposures as files (``takes_raw`` true; channels R, G, B after
    demosaicking).

    Attributes
    ----------
    optics : :class:`gonio.rigs.sim.camera.PinholeCamera`
        Intrinsics (pixels); ``optics.matrix`` is the 3x3 camera matrix K.
    sensor : :class:`gonio.rigs.sim.sensor.SensorModel`
        Noise parameters (``gain`` DN/e-, ``read_noise`` e-, ``dark_current`` e-/s,
        ``full_well`` e-) for exposure planning and merge weights.
    """

    optics: PinholeCamera
    sensor: SensorModel

    def point(self, geometry: Geometry) -> None:
        """The geometry the next frames are taken at (a simulated camera renders from it; a
        real camera has nothing to do)."""
        ...

    def capture(
        self,
        exposure_s: float,
        path: str | os.PathLike,
        key: str | None = None,
        meta: dict | None = None,
    ) -> Path:
        """Expose for ``exposure_s`` seconds and write the raw file at ``path`` (the suffix may
        be changed to the camera's format); return where it is. ``key`` names the frame in a
        simulated camera's noise stream and ``meta`` goes into its file; real cameras ignore
        both."""
        ...


class DirectCamera(Camera, Protocol):
    """A camera that measures the sample at the rig's geometry itself (``takes_raw`` false)."""

    def capture(self, geometry: Geometry, exposure_s: float | None = None) -> Capture:
        """Take one measurement at ``geometry``; ``exposure_s`` overrides the default."""
        ...
