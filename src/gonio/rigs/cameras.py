"""RAW cameras (:class:`gonio.rigs.devices.RawCamera`): ``capture(exposure_s, path) -> Path``
of a raw file (DNG or the camera's own).

Backends (the rig file's ``[camera] kind``):

* ``"sim"`` — :class:`SimulatedRawCamera`: the virtual camera of :mod:`gonio.rigs.sim.camera`,
  rendering the holder at the geometry the rig *reached* (joint angles read back from the bus,
  through the forward kinematics to finite light and camera positions) and lit by a
  :class:`~gonio.rigs.lights.SimulatedLight`; it writes DNG files.
* ``"gphoto2"`` — :class:`CommandLineCamera`: a tethered camera driven by a command-line program
  (gphoto2 by default) run as a subprocess, with the exposure set per shot.
* ``"folder"`` — :class:`FolderWatchCamera`: a camera driven by its own software that drops raw
  files into a folder; gonio waits for the next new file.

:mod:`gonio.rigs.factory` builds them from the rig file. The HDR pipeline
(:mod:`gonio.acquire.imaging`) decodes every file with rawpy, so any raw format LibRaw reads works
for the real backends.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import time
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gonio.errors import DeviceError, ParameterError

if TYPE_CHECKING:
    from gonio.rigs.devices import Geometry
    from gonio.rigs.sim.camera import PinholeCamera
    from gonio.rigs.sim.sensor import SensorModel

#: Channels of a RAW camera's measurements (demosaicked).
RGB = ("R", "G", "B")


# --- simulated ------------------------------------------------------------------------------


class SimulatedRawCamera:
    """The virtual camera at the rig's current geometry.

    Parameters
    ----------
    virtual : :class:`gonio.rigs.sim.camera.VirtualCamera` (scene, optics, sensor, seed).
    light : :class:`gonio.rigs.lights.SimulatedLight` (its state scales the light's intensity).
    intensity_w_sr : radiant intensity of the light at full output, W/sr (per colour plane).

    :meth:`point` is called by the imaging chain before every configuration's frames with the
    light and camera positions (sample frame, metres) from the read-back joint angles; the
    rendered electron-rate image is cached until the geometry changes. Each file's noise is
    keyed by the frame ``key`` passed to :meth:`capture` (defaults to the file name), so the
    same (seed, configuration) always gives the same file.
    """

    takes_raw = True
    channels = RGB

    def __init__(self, virtual: Any, light: Any, intensity_w_sr: float) -> None:
        self.virtual = virtual
        self.light = light
        self.intensity_w_sr = float(intensity_w_sr)
        self._geometry: tuple[np.ndarray, np.ndarray] | None = None
        self._rate: np.ndarray | None = None

    @property
    def optics(self) -> PinholeCamera:
        return self.virtual.camera

    @property
    def sensor(self) -> SensorModel:
        return self.virtual.sensor

    def point(self, geometry: Geometry) -> None:
        """Where the light and the camera are (``geometry.light_pos_m``, ``camera_pos_m``:
        sample frame, metres); the camera looks at the holder centre."""
        if geometry.light_pos_m is None or geometry.camera_pos_m is None:
            raise DeviceError("simulated camera: the geometry has no light and camera positions")
        g = (
            np.asarray(geometry.light_pos_m, dtype=float),
            np.asarray(geometry.camera_pos_m, dtype=float),
        )
        if self._geometry is None or not all(
            np.array_equal(a, b) for a, b in zip(g, self._geometry, strict=True)
        ):
            self._geometry = g
            self._rate = None

    @property
    def camera_pose(self):
        from gonio.rigs.sim.camera import CameraPose

        if self._geometry is None:
            raise DeviceError("simulated camera: no geometry set (the rig has not moved)")
        return CameraPose.looking_at_origin(self._geometry[1])

    def rate(self) -> np.ndarray:
        """Electron-rate image (H, W, 3), e-/s, at full light output."""
        if self._rate is None:
            pose = self.camera_pose
            assert self._geometry is not None
            self._rate = self.virtual.electron_rate(pose, self._geometry[0], self.intensity_w_sr)
        return self._rate

    def capture(
        self, exposure_s: float, path: str | os.PathLike, key: str | None = None, meta=None
    ) -> Path:
        out = self.light.output
        rate = self.rate() * out if out > 0 else np.zeros_like(self.rate())
        k = key if key is not None else Path(path).stem
        p, _ = self.virtual.capture(Path(path), rate, float(exposure_s), key=k, meta=meta)
        return p

    def close(self) -> None:
        pass


class _TetheredCamera:
    """What the real RAW backends share: frames in R, G, B, the rig file's optics and sensor
    (defaults: :class:`~gonio.rigs.sim.camera.PinholeCamera` and
    :class:`~gonio.rigs.sim.sensor.SensorModel`), nothing to point and nothing to close."""

    takes_raw = True
    channels = RGB

    def __init__(self, optics: PinholeCamera | None, sensor: SensorModel | None) -> None:
        from gonio.rigs.sim.camera import PinholeCamera
        from gonio.rigs.sim.sensor import SensorModel

        self.optics = optics if optics is not None else PinholeCamera()
        self.sensor = sensor if sensor is not None else SensorModel()

    def point(self, geometry: Geometry) -> None:
        pass

    def close(self) -> None:
        pass


# --- command line (gphoto2) ----------------------------------------------------------------


def format_shutter(exposure_s: float) -> str:
    """gphoto2's shutter-speed text for an exposure: ``1/250`` below one second, else ``2``
    or ``2.5``."""
    if not exposure_s > 0:
        raise ParameterError(f"exposure must be positive, got {exposure_s}")
    if exposure_s < 1.0:
        f = Fraction(1.0 / exposure_s).limit_denominator(10)
        if f.denominator == 1:
            return f"1/{f.numerator}"
        return f"1/{float(f):g}"
    return f"{exposure_s:g}"


class CommandLineCamera(_TetheredCamera):
    """A tethered camera driven by gphoto2 (or a compatible program) per exposure.

    Each capture runs::

        <program> [--port PORT] --set-config-value <shutter_key>=<1/250>
                  --capture-image-and-download --filename <path> --force-overwrite

    and parses the ``Saving file as <path>`` line of its output (gphoto2 may change the suffix
    to the camera's raw format). Non-zero exit status, a missing file or a timeout raise
    DeviceError with the program's last output line.

    Parameters
    ----------
    program : executable name or path (looked up on PATH).
    port : gphoto2 ``--port`` (e.g. ``usb:001,004``); None lets gphoto2 pick the only camera.
    shutter_key : the camera's config key for the shutter speed (``shutterspeed`` on most).
    timeout_s : longest a capture may take beyond its exposure, seconds.
    extra_args : more arguments inserted before the capture action (ISO, image format...).
    optics, sensor : the camera's intrinsics and noise model (:class:`_TetheredCamera`).
    """

    def __init__(
        self,
        program: str = "gphoto2",
        port: str | None = None,
        shutter_key: str = "shutterspeed",
        timeout_s: float = 30.0,
        extra_args: tuple[str, ...] = (),
        optics: PinholeCamera | None = None,
        sensor: SensorModel | None = None,
    ) -> None:
        super().__init__(optics, sensor)
        self.program = program
        self.port = port
        self.shutter_key = shutter_key
        self.timeout_s = float(timeout_s)
        self.extra_args = tuple(extra_args)

    def executable(self) -> str:
        exe = shutil.which(self.program)
        if exe is None:
            raise DeviceError(f"camera program {self.program!r} not found on PATH")
        return exe

    def command(self, exposure_s: float, path: str | os.PathLike) -> list[str]:
        """The argument list of one capture (without running it)."""
        cmd = [self.program]
        if self.port:
            cmd += ["--port", self.port]
        cmd += ["--set-config-value", f"{self.shutter_key}={format_shutter(exposure_s)}"]
        cmd += list(self.extra_args)
        cmd += ["--capture-image-and-download", "--filename", os.fspath(path), "--force-overwrite"]
        return cmd

    def capture(self, exposure_s: float, path: str | os.PathLike, **_: Any) -> Path:
        exe = self.executable()
        cmd = self.command(exposure_s, path)
        cmd[0] = exe
        try:
            proc = subprocess.run(
                cmd, capture_output=True, text=True, timeout=self.timeout_s + float(exposure_s)
            )
        except subprocess.TimeoutExpired:
            raise DeviceError(
                f"camera: {self.program} did not finish within {self.timeout_s:g} s"
            ) from None
        except OSError as exc:
            raise DeviceError(f"camera: cannot run {self.program}: {exc}") from None
        output = (proc.stdout or "") + (proc.stderr or "")
        if proc.returncode != 0:
            last = next((ln for ln in reversed(output.splitlines()) if ln.strip()), "")
            raise DeviceError(
                f"camera: {self.program} failed (exit {proc.returncode}): {last.strip()}"
            )
        saved = parse_saved_path(output) or Path(path)
        if not saved.is_file():
            raise DeviceError(f"camera: {self.program} reported success but {saved} is missing")
        return saved

    def version(self) -> str:
        """First line of ``<program> --version`` (checks that the program runs)."""
        try:
            proc = subprocess.run(
                [self.executable(), "--version"], capture_output=True, text=True, timeout=10
            )
        except (OSError, subprocess.TimeoutExpired) as exc:
            raise DeviceError(f"camera: cannot run {self.program}: {exc}") from None
        lines = (proc.stdout or proc.stderr or "").splitlines()
        return lines[0].strip() if lines else ""


_SAVED = re.compile(r"^Saving file as (.+?)\s*$", re.MULTILINE)


def parse_saved_path(output: str) -> Path | None:
    """The last ``Saving file as <path>`` of gphoto2's output, if any."""
    found = _SAVED.findall(output)
    return Path(found[-1]) if found else None


# --- folder watch ---------------------------------------------------------------------------


class FolderWatchCamera(_TetheredCamera):
    """A camera run by its own software, which writes raw files into ``folder``.

    :meth:`capture` notes the files already there, optionally calls ``trigger(exposure_s)``
    (e.g. to tell an operator or another program to shoot), then waits for a new file matching
    ``pattern`` whose size has stopped changing for ``stable_s``, and moves it to ``path``
    (keeping its suffix). No new file within ``timeout_s`` is a DeviceError. ``optics`` and
    ``sensor`` as for :class:`_TetheredCamera`.
    """

    def __init__(
        self,
        folder: str | os.PathLike,
        pattern: str = "*.dng",
        timeout_s: float = 60.0,
        stable_s: float = 0.2,
        poll_s: float = 0.05,
        trigger: Any = None,
        optics: PinholeCamera | None = None,
        sensor: SensorModel | None = None,
    ) -> None:
        super().__init__(optics, sensor)
        self.folder = Path(folder)
        self.pattern = pattern
        self.timeout_s = float(timeout_s)
        self.stable_s = float(stable_s)
        self.poll_s = float(poll_s)
        self.trigger = trigger
        if not self.folder.is_dir():
            raise DeviceError(f"camera: watched folder {self.folder} does not exist")

    def _listing(self) -> set[str]:
        return {p.name for p in self.folder.glob(self.pattern) if not p.name.startswith(".")}

    def capture(self, exposure_s: float, path: str | os.PathLike, **_: Any) -> Path:
        before = self._listing()
        if self.trigger is not None:
            self.trigger(float(exposure_s))
        deadline = time.monotonic() + self.timeout_s
        seen: dict[str, tuple[int, float]] = {}
        while time.monotonic() < deadline:
            for name in sorted(self._listing() - before):
                p = self.folder / name
                try:
                    size = p.stat().st_size
                except FileNotFoundError:
                    continue
                now = time.monotonic()
                last = seen.get(name)
                if last is None or last[0] != size:
                    seen[name] = (size, now)
                elif size > 0 and now - last[1] >= self.stable_s:
                    dest = Path(path).with_suffix(p.suffix)
                    shutil.move(str(p), dest)
                    return dest
            time.sleep(self.poll_s)
        raise DeviceError(
            f"camera: no new {self.pattern} file in {self.folder} within {self.timeout_s:g} s"
        )
