"""The imaging measurement of one configuration: brackets -> DNG -> HDR -> EXR -> pose -> f.

:class:`ImagingCamera` is the run engine's measurement (``capture(geometry) -> Capture``, as a
:class:`gonio.rigs.devices.DirectCamera` measures) over a :class:`gonio.rigs.devices.RawCamera`
and the rig's light, both opened by the rig session (:func:`measurement` picks it for the
session's camera). Per configuration it

1. plans the exposures from the previous frame's sample and white-reference rates
   (:func:`gonio.acquire.hdr.plan_exposures`: the fewest brackets keeping both unsaturated at the
   target SNR), or takes a probe exposure when there is no previous frame; with planning off it
   uses a fixed wide bracket set (the benchmark's baseline);
2. captures each bracket as a raw file into ``RUN/raw/`` and, once per exposure time, a dark
   frame with the light off (cached in memory and on disk, so a resumed run reuses it);
3. merges them on the raw mosaic (:func:`gonio.acquire.hdr.merge_brackets`), finds the holder
   pose from the ChArUco board, checks that the sample and the reference are unsaturated and
   well exposed, and adds a bracket where they are not (at most ``max_rounds``);
4. writes the HDR frame as OpenEXR into ``RUN/hdr/`` (demosaicked R, G, B and the raw mosaic
   in DN/s, its sigma, with exposures, pose, joint angles and directions in the header);
5. measures ``f`` and its sigma through the white reference
   (:func:`gonio.acquire.radiometry.measure_brdf`), with the directions from the actual light and
   camera positions.

The returned :class:`~gonio.rigs.devices.Capture` carries the measured directions in ``meta``;
the engine journals them with the value and sigma, so kill/resume works as for any camera.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gonio.acquire.hdr import Bracket, NoiseModel, merge_brackets, plan_exposures
from gonio.acquire.pose import BoardPose, estimate_pose, mosaic_to_gray, pose_samples, to_8bit
from gonio.acquire.radiometry import measure_brdf, pixel_rays_to_plane
from gonio.errors import DeviceError, FrameError
from gonio.io.dng import read_dng
from gonio.io.strict_json import dumps_json
from gonio.rigs.devices import Capture, Geometry


@dataclass
class ImagingSettings:
    """How a configuration is imaged (the rig file's ``[camera]`` keys of the same names).

    Attributes
    ----------
    exposure_s : first (probe) exposure when there is no previous frame, seconds.
    t_min_s, t_max_s : the camera's exposure limits, seconds.
    snr_target : SNR every sample and reference pixel must reach in at least one bracket.
    headroom : fraction of the full well the brightest pixel of interest may fill.
    planning : plan exposures from the previous frame (False: the fixed brackets below).
    fixed_brackets : exposures (relative to ``exposure_s``) used when ``planning`` is off.
    spot_radius_m : radius of the measured spot at the sample centre, metres.
    max_rounds : capture rounds per configuration (each may add brackets).
    fit_order : surface fitted through the spot's pixels (1 plane, 2 quadratic: removes the
        lobe-curvature bias of a larger spot).
    bloom_guard_px : a bracket is not used for pixels within this distance (pixels) of one it
        saturates (see :func:`gonio.acquire.hdr.merge_brackets`); 0 turns the guard off.
    """

    exposure_s: float = 0.01
    t_min_s: float = 1e-5
    t_max_s: float = 2.0
    snr_target: float = 50.0
    headroom: float = 0.8
    planning: bool = True
    fixed_brackets: tuple[float, ...] = (1 / 64, 1 / 16, 1 / 4, 1.0, 4.0)
    spot_radius_m: float = 0.002
    max_rounds: int = 5
    fit_order: int = 2
    bloom_guard_px: int = 1


@dataclass
class FrameTimes:
    """Where a configuration's capture time went (seconds)."""

    exposure: float = 0.0  # shutter open (sum of exposure times, darks included)
    capture: float = 0.0  # wall time in the camera backend (rendering/IO for the simulator)
    processing: float = 0.0  # decode, merge, pose, radiometry, EXR
    capture_cpu: float = 0.0  # the same two as CPU time of this process (robust to a busy host)
    processing_cpu: float = 0.0


@dataclass
class _Hint:
    rate_max: float  # e-/s, brightest pixel of interest at full light
    rate_min: float  # e-/s, darkest


@dataclass
class ImagingCamera:
    """The engine's camera for RAW backends (see the module docstring).

    Parameters
    ----------
    raw : a :class:`gonio.rigs.devices.RawCamera`.
    light : a :class:`gonio.rigs.devices.Light` (switched off for dark frames).
    layout : :class:`gonio.rigs.sim.camera.HolderLayout` of the holder (board, sample, reference).
    camera_matrix : (3, 3) intrinsics K, pixels.
    sensor : the sensor's noise parameters: an object with ``gain``, ``read_noise``,
        ``dark_current``, ``full_well`` (e.g. :class:`gonio.rigs.sim.sensor.SensorModel`).
    run_dir : the run directory (``raw/`` and ``hdr/`` are created in it).
    settings : :class:`ImagingSettings`.
    """

    raw: Any
    light: Any
    layout: Any
    camera_matrix: np.ndarray
    sensor: Any
    run_dir: Path
    settings: ImagingSettings = field(default_factory=ImagingSettings)
    channels: tuple[str, ...] = ("R", "G", "B")

    def __post_init__(self) -> None:
        self.run_dir = Path(self.run_dir)
        self.raw_dir = self.run_dir / "raw"
        self.hdr_dir = self.run_dir / "hdr"
        self.raw_dir.mkdir(parents=True, exist_ok=True)
        self.hdr_dir.mkdir(parents=True, exist_ok=True)
        sen = self.sensor
        self.noise = NoiseModel(sen.gain, sen.read_noise, sen.dark_current)
        self._darks: dict[float, np.ndarray] = {}
        self._hint: _Hint | None = self._hint_from_disk()
        self.last_times = FrameTimes()

    # --- the engine's interface ---------------------------------------------------------------
    def capture(self, geometry: Geometry, exposure_s: float | None = None) -> Capture:
        """Measure one configuration (see the module docstring).

        Raises FrameError when the frame cannot be measured (board not found, sample or
        reference outside it, exposures inadequate) on the first shots and again on one retake
        with fresh frames (a real camera's next frame has new noise; a passing obstruction may
        have gone): the engine then skips the configuration.
        """
        if geometry.light_pos_m is None or geometry.camera_pos_m is None:
            raise DeviceError("imaging needs the light and camera positions (rig layout)")
        self.raw.point(geometry)
        times = FrameTimes()
        tag = f"c{geometry.index:05d}"
        try:
            frames, hdr, pose, hint, m = self._measure(geometry, exposure_s, tag, times)
        except FrameError as first:
            try:
                frames, hdr, pose, hint, m = self._measure(
                    geometry, exposure_s, f"{tag}_retake", times
                )
            except FrameError as exc:
                raise FrameError(
                    f"configuration {geometry.index}: {first}; on a retake: {exc}"
                ) from None
        t0, c0 = time.monotonic(), time.process_time()
        self._hint = hint
        self._write_exr(tag, hdr, pose, geometry, sorted(frames), m, hint)
        times.processing += time.monotonic() - t0
        times.processing_cpu += time.process_time() - c0
        self.last_times = times
        return Capture(
            value=m.f,
            sigma=m.sigma,
            channels=self.channels,
            meta={
                "wi": m.wi,
                "wo": m.wo,
                "exposures_s": sorted(frames),
                "t_exposure": times.exposure,
                "t_camera": times.capture,
                "t_processing": times.processing,
                "t_camera_cpu": times.capture_cpu,
                "t_processing_cpu": times.processing_cpu,
                "pose_corners": pose.n_corners,
                "reprojection_px": pose.reprojection_px,
            },
        )

    # --- steps ----------------------------------------------------------------------------------
    def _measure(self, geometry: Geometry, exposure_s: float | None, tag: str, times):
        """Shoot, merge and check brackets (files named ``tag``) until the sample and the
        reference are covered; returns (frames, hdr, pose, hint, measurement)."""
        exposures = self._initial_exposures(exposure_s)
        frames: dict[float, Path] = {}
        pose = hdr = None
        for _round in range(self.settings.max_rounds):
            for t in exposures:
                if t not in frames:
                    frames[t] = self._shoot(t, f"{tag}_t{t:.6g}", times, geometry)
            t0, c0 = time.monotonic(), time.process_time()
            hdr = self._merge(frames, times)
            try:
                pose = self._pose(hdr)
            except FrameError:
                # no board in the frame: a probe far off the right exposure leaves it saturated
                # or buried in noise; bracket towards the side that is wrong, then give up
                pose = None
                more = self._rescue(hdr, sorted(frames))
                if not more:
                    raise
            else:
                more, hint = self._check(hdr, pose, sorted(frames))
            times.processing += time.monotonic() - t0
            times.processing_cpu += time.process_time() - c0
            if not more:
                break
            exposures = sorted(set(frames) | set(more))
        else:
            raise FrameError(
                f"exposures still inadequate after {self.settings.max_rounds} rounds"
                f" ({sorted(frames)})"
            )
        t0, c0 = time.monotonic(), time.process_time()
        assert hdr is not None and pose is not None
        m = self._radiometry(hdr, pose, geometry)
        times.processing += time.monotonic() - t0
        times.processing_cpu += time.process_time() - c0
        return frames, hdr, pose, hint, m

    def _initial_exposures(self, exposure_s: float | None) -> list[float]:
        s = self.settings
        base = float(exposure_s or s.exposure_s)
        if not s.planning:
            return [self._clip(base * r) for r in s.fixed_brackets]
        if self._hint is None:
            return [self._clip(base)]
        return self._plan(self._hint.rate_max * 1.25, self._hint.rate_min / 1.25)

    def _clip(self, t: float) -> float:
        """Clip to the camera's limits and round *down* to the half-stop ladder
        ``t_min * 2^(k/2)``, so configurations share exposure times (and cached dark frames)."""
        lo, hi = self.settings.t_min_s, self.settings.t_max_s
        t = float(np.clip(t, lo, hi))
        k = math.floor(2.0 * math.log2(t / lo) + 1e-9)
        return float(f"{lo * 2.0 ** (k / 2.0):.4g}")

    def _plan(self, rate_max: float, rate_min: float) -> list[float]:
        s, sen = self.settings, self.sensor
        p = plan_exposures(
            rate_max,
            min(rate_min, rate_max),
            gain=sen.gain,
            read_noise=sen.read_noise,
            dark_current=sen.dark_current,
            full_well=sen.full_well,
            t_min=s.t_min_s,
            t_max=s.t_max_s,
            snr_target=s.snr_target,
            headroom=s.headroom,
        )
        return sorted({self._clip(t) for t in p.exposures_s})

    def _shoot(self, t: float, name: str, times: FrameTimes, geometry: Geometry) -> Path:
        """One light frame (and the dark of this exposure if not cached)."""
        if t not in self._darks:
            dark_path = self.raw_dir / f"dark_t{t:.6g}.dng"
            if not dark_path.is_file():
                self.light.off()
                try:
                    t0, c0 = time.monotonic(), time.process_time()
                    dark_path = self.raw.capture(
                        t, dark_path, key=f"dark_t{t!r}", meta={"dark": True}
                    )
                    times.capture += time.monotonic() - t0
                    times.capture_cpu += time.process_time() - c0
                    times.exposure += t
                finally:
                    self.light.on()
            self._darks[t] = read_dng(dark_path).data
        t0, c0 = time.monotonic(), time.process_time()
        meta = {
            "index": geometry.index,
            "joints_deg": geometry.joints_deg,
            "light_pos_m": np.asarray(geometry.light_pos_m).tolist(),
            "camera_pos_m": np.asarray(geometry.camera_pos_m).tolist(),
        }
        path = self.raw.capture(t, self.raw_dir / f"{name}.dng", key=name, meta=meta)
        times.capture += time.monotonic() - t0
        times.capture_cpu += time.process_time() - c0
        times.exposure += t
        return path

    def _merge(self, frames: dict[float, Path], times: FrameTimes):
        brackets, darks = [], []
        for t in sorted(frames):
            fr = read_dng(frames[t])
            if fr.data.shape != self._darks[t].shape:
                raise DeviceError(f"{frames[t]}: frame size differs from its dark frame")
            brackets.append(Bracket(fr.data, t, fr.black_map(), fr.white_level))
            darks.append(self._darks[t])
        hdr = merge_brackets(
            brackets, self.noise, dark=darks, bloom_guard_px=self.settings.bloom_guard_px
        )
        self._cfa = "".join("".join(r) for r in fr.cfa)
        return hdr

    def _pose(self, hdr) -> BoardPose:
        gray = board_gray(hdr.rate, self._cfa)
        lin = linear_8bit(gray)
        try:
            return estimate_pose(lin, self.layout, self.camera_matrix)
        except FrameError:
            pass
        # strong light fall-off across the board: the log tone map
        log = to_8bit(gray)
        try:
            return estimate_pose(log, self.layout, self.camera_matrix)
        except FrameError as exc:
            first = exc
        # OpenCV's board check rejects sound detections of a steeply foreshortened board
        # (see estimate_pose); the pose's reprojection error checks them instead
        for img in (lin, log):
            try:
                return estimate_pose(img, self.layout, self.camera_matrix, check_board=False)
            except FrameError:
                pass
        raise first

    def _rescue(self, hdr, exposures: list[float]) -> list[float]:
        """Exposures to add when the board was not found: 8x shorter when more than 1 % of the
        frame is saturated in every bracket, else 8x longer (within the camera's limits)."""
        saturated = float(np.mean(~np.isfinite(hdr.rate)))
        if saturated > 0.01:
            t = self._clip(min(exposures) / 8.0)
        else:
            t = self._clip(max(exposures) * 8.0)
        return [t] if t not in exposures else []

    def _regions(self, shape, pose: BoardPose) -> tuple[np.ndarray, np.ndarray]:
        pts, hit = pixel_rays_to_plane(shape, self.camera_matrix, pose.rotation, pose.translation)
        lay = self.layout

        def disk(c, r):
            return hit & ((pts[..., 0] - c[0]) ** 2 + (pts[..., 1] - c[1]) ** 2 <= r * r)

        return disk(lay.sample_center, 0.8 * lay.sample_radius), disk(
            lay.reference_center, 0.8 * lay.reference_radius
        )

    def _check(self, hdr, pose: BoardPose, exposures: list[float]):
        """Brackets to add (empty when the sample and reference are covered) and the new hint."""
        s_mask, r_mask = self._regions(hdr.rate.shape, pose)
        roi = s_mask | r_mask
        if not roi.any():
            raise FrameError("sample and white reference are outside the frame")
        rate = hdr.rate[roi]
        missing = ~np.isfinite(rate)
        e_rate = np.where(missing, np.nan, rate) / self.sensor.gain  # DN/s -> e-/s
        good = e_rate[np.isfinite(e_rate)]
        lo = float(np.percentile(good[good > 0], 1)) if np.any(good > 0) else None
        hi = float(np.max(good)) if good.size else None
        more: list[float] = []
        if missing.any() or hi is None:
            # saturated in every bracket: go 8x shorter than the shortest
            more.append(self._clip(min(exposures) / 8.0))
        if lo is not None:
            # SNR of the darkest pixel of interest in the longest frame that holds it unsaturated
            t_long = max(exposures)
            sig = lo * t_long
            snr = sig / math.sqrt(
                sig + self.sensor.dark_current * t_long + self.sensor.read_noise**2
            )
            if snr < self.settings.snr_target and t_long < self.settings.t_max_s:
                more.extend(t for t in self._plan(hi or lo, lo) if t > t_long)
        more = [t for t in more if t not in exposures]
        hint = _Hint(hi if hi is not None else 0.0, lo if lo is not None else 0.0)
        if hint.rate_max <= 0 or hint.rate_min <= 0:
            hint = None  # type: ignore[assignment]
        return more, hint

    def _radiometry(self, hdr, pose: BoardPose, geometry: Geometry):
        lay = self.layout
        plane = _plane_index(hdr.rate.shape, self._cfa)
        return measure_brdf(
            hdr.rate,
            hdr.variance,
            plane,
            self.camera_matrix,
            pose.rotation,
            pose.translation,
            np.asarray(geometry.light_pos_m, dtype=float),
            lay.sample_center,
            lay.sample_radius,
            lay.reference_center,
            lay.reference_radius,
            lay.reference_albedo,
            spot_radius=self.settings.spot_radius_m,
            frame_fraction=hdr.frame_fraction,
            log_time_cov=hdr.log_time_cov,
            pose_sigma_points=pose_samples(pose),
            fit_order=self.settings.fit_order,
            direction_uncertainty=True,
            variance_at=hdr.variance_at,
        )

    def _write_exr(self, tag, hdr, pose, geometry, exposures, m, hint) -> None:
        from gonio.io.exr import write_exr

        rate = np.where(np.isfinite(hdr.rate), hdr.rate, 0.0)
        rgb = demosaic(rate, self._cfa)
        img = np.concatenate(
            [rgb, rate[..., None], np.sqrt(np.nan_to_num(hdr.variance))[..., None]], -1
        )
        attrs = {
            "gonio_units": "DN/s (dark-subtracted, relative to the full light output)",
            "gonio_index": str(geometry.index),
            "gonio_exposures_s": dumps_json(list(exposures)),
            "gonio_effective_exposures_s": dumps_json([float(x) for x in hdr.exposures_s]),
            "gonio_pose_R": dumps_json(np.asarray(pose.rotation).tolist()),
            "gonio_pose_t_m": dumps_json(np.asarray(pose.translation).tolist()),
            "gonio_pose_reprojection_px": f"{pose.reprojection_px:.6g}",
            "gonio_joints_deg": dumps_json(geometry.joints_deg),
            "gonio_light_pos_m": dumps_json(np.asarray(geometry.light_pos_m).tolist()),
            "gonio_camera_pos_m": dumps_json(pose.camera_position.tolist()),
            "gonio_wi": dumps_json(np.asarray(m.wi).tolist()),
            "gonio_wo": dumps_json(np.asarray(m.wo).tolist()),
            "gonio_f": dumps_json(np.asarray(m.f).tolist()),
            "gonio_sigma": dumps_json(np.asarray(m.sigma).tolist()),
            "gonio_plan_hint_e_per_s": dumps_json(
                None if hint is None else [hint.rate_max, hint.rate_min]
            ),
        }
        write_exr(
            self.hdr_dir / f"{tag}.exr",
            img,
            channel_names=["R", "G", "B", "mosaic", "mosaic_sigma"],
            attributes=attrs,
        )

    def _hint_from_disk(self) -> _Hint | None:
        """On resume: the planning hint of the newest HDR frame already written."""
        frames = sorted(self.hdr_dir.glob("c*.exr"), key=lambda p: p.stat().st_mtime)
        if not frames:
            return None
        try:
            import OpenEXR

            with OpenEXR.File(str(frames[-1])) as f:
                h = json.loads(f.header()["gonio_plan_hint_e_per_s"])
        except Exception:  # an unreadable frame only costs a probe exposure
            return None
        return _Hint(*h) if h else None


def board_gray(rate: np.ndarray, cfa: str) -> np.ndarray:
    """Grey image (H, W) for finding the board in an HDR mosaic (H, W) (NaN: unusable).

    The mosaic is white-balanced on the (neutral) board, each colour plane divided by its 90th
    percentile, so that demosaicking does not turn the planes' different sensitivities into a
    pixel-level checkerboard; then demosaicked to grey (:func:`gonio.acquire.pose.mosaic_to_gray`).
    """
    rate = np.where(np.isfinite(rate), rate, 0.0)
    plane = _plane_index(rate.shape, cfa)
    for c in range(3):
        sel = plane == c
        level = float(np.percentile(rate[sel], 90))
        if level > 0:
            rate = np.where(sel, rate / level, rate)
    return mosaic_to_gray(rate, cfa)


def linear_8bit(gray: np.ndarray) -> np.ndarray:
    """8-bit image for board detection: linear, the 97th percentile of the positive values at
    full scale, which keeps the board's black squares near black (what the marker decoder
    expects); the small specular highlight may clip."""
    pos = gray[gray > 0]
    hi = float(np.percentile(pos, 97)) if pos.size else 1.0
    return (np.clip(gray / hi, 0.0, 1.0) * 255 + 0.5).astype(np.uint8)


def _plane_index(shape: tuple[int, int], cfa: str) -> np.ndarray:
    codes = {"R": 0, "G": 1, "B": 2}
    tile = np.array([[codes[cfa[0]], codes[cfa[1]]], [codes[cfa[2]], codes[cfa[3]]]])
    h, w = shape
    return np.tile(tile, ((h + 1) // 2, (w + 1) // 2))[:h, :w]


def demosaic(mosaic: np.ndarray, cfa: str = "RGGB") -> np.ndarray:
    """Bayer mosaic (H, W) float -> (H, W, 3) float32 R, G, B by OpenCV's bilinear demosaic.

    OpenCV demosaics integer images only, so the mosaic is scaled to 16 bits and back (1/65535
    of the range). The ``COLOR_Bayer<tile>2RGB`` codes name the sensor's tile row-major, so
    ``RGGB`` maps to ``COLOR_BayerRGGB2RGB`` (the older two-letter codes name the second row).
    """
    import cv2

    code = getattr(cv2, f"COLOR_Bayer{cfa}2RGB")
    img = np.nan_to_num(np.asarray(mosaic, dtype=np.float64))
    scale = max(float(img.max()), 1e-30)
    img16 = np.clip(img / scale * 65535, 0, 65535).astype(np.uint16)
    return cv2.cvtColor(img16, code).astype(np.float32) * np.float32(scale / 65535)


# --- construction from a rig file --------------------------------------------------------------


def settings_from_rig(rig) -> ImagingSettings:
    c = rig.camera
    s = ImagingSettings()
    for key in ("exposure_s", "t_min_s", "t_max_s", "snr_target", "headroom", "spot_radius_m"):
        if key in c:
            setattr(s, key, float(c[key]))
    if "planning" in c:
        s.planning = bool(c["planning"])
    if "bloom_guard_px" in c:
        s.bloom_guard_px = int(c["bloom_guard_px"])
    if "fixed_brackets" in c:
        s.fixed_brackets = tuple(float(x) for x in c["fixed_brackets"])
    return s


def measurement(session, run_dir: str | Path, planning: bool | None = None):
    """The run's measurement over the devices of an open :class:`gonio.rigs.session.RigSession`:
    :class:`ImagingCamera` over a camera that takes raw frames (and the session's light and
    holder), the camera itself when it reads the BRDF directly (e.g. ``"sim-sample"``).

    ``planning`` overrides the rig file's ``camera.planning``.
    """
    camera = session.camera
    if not camera.takes_raw:
        return camera
    settings = settings_from_rig(session.rig)
    if planning is not None:
        settings.planning = planning
    return ImagingCamera(
        camera,
        session.light,
        session.holder,
        camera.optics.matrix,
        camera.sensor,
        Path(run_dir),
        settings,
    )
