"""Virtual camera: renders what a gonioreflectometer's camera sees and writes it as DNG.

The scene lives in the *sample frame* (metres): the sample holder is the plane z = 0 with its
normal +z, x along the holder's tangent. On it lie

* a ChArUco board (printed, near-Lambertian: albedo 0.04 on black, 0.90 on white) used to
  recover the holder's pose in every frame;
* the sample, a disk whose reflectance is any gonio model or table (the ground truth);
* a white reference, a disk of a near-Lambertian material with reflectance 0.99.

A point light of radiant intensity ``I`` (W/sr, per colour plane) at ``light_pos`` gives the
irradiance ``E = I cos(theta_i) / d^2`` at a point ``d`` away (inverse-square falloff). The camera
is a pinhole with natural ``cos^4`` vignetting; a pixel's photo-electron rate is
``L * throughput * cos^4(alpha)`` with ``L`` the radiance it sees (W/(m^2 sr)); the
:class:`~gonio.rigs.sim.sensor.SensorModel` turns rates into noisy raw DN. Each pixel averages
``supersample^2`` rays, and the lens and sensor blur (point spread function, anti-aliasing
filter) is modelled as a Gaussian of ``psf_px`` pixels applied to the board's printed pattern at
the camera's distance: a few point samples of a sharp pattern alias its edges by up to
1/(2 supersample) pixel, depending on where each edge falls on the pixel grid, which moves the
ChArUco corners by ~0.1 px and the recovered camera direction by up to ~0.1 deg, the same in
every frame of the same geometry (``benchmarks/bench_acquisition_accuracy.py`` reports each
frame's camera-direction error).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from gonio.errors import ParameterError
from gonio.io.dng import write_dng
from gonio.rigs.sim.sensor import SensorModel


@dataclass(frozen=True)
class HolderLayout:
    """Geometry of the sample holder in the sample frame (metres, z = 0 plane).

    The board is centred on the origin; ``squares`` is (columns along x, rows along y).
    """

    squares: tuple[int, int] = (9, 7)
    square_m: float = 0.016
    marker_m: float = 0.012
    dictionary: str = "DICT_4X4_50"
    sample_center: tuple[float, float] = (0.0, 0.0)
    sample_radius: float = 0.008
    reference_center: tuple[float, float] = (0.048, 0.0)
    reference_radius: float = 0.008
    reference_albedo: float = 0.99
    board_black: float = 0.04
    board_white: float = 0.90
    texture_px_per_square: int = 64

    @property
    def board_size_m(self) -> tuple[float, float]:
        """Board extent (width along x, height along y) in metres."""
        return self.squares[0] * self.square_m, self.squares[1] * self.square_m

    @cached_property
    def board(self) -> Any:
        """The OpenCV ``CharucoBoard`` matching this layout."""
        import cv2

        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard(self.squares, self.square_m, self.marker_m, d)

    @cached_property
    def texture(self) -> np.ndarray:
        """Board image (rows along -y from the top edge), float albedo in [black, white]."""
        w = self.squares[0] * self.texture_px_per_square
        h = self.squares[1] * self.texture_px_per_square
        img = self.board.generateImage((w, h), marginSize=0, borderBits=1).astype(np.float64)
        return self.board_black + (self.board_white - self.board_black) * img / 255.0

    def board_to_holder(self, obj_points: np.ndarray) -> np.ndarray:
        """Board object points (OpenCV: origin top-left, x right, y down) -> sample frame."""
        w, h = self.board_size_m
        p = np.asarray(obj_points, dtype=np.float64).reshape(-1, 3)
        return np.stack([p[:, 0] - w / 2, h / 2 - p[:, 1], -p[:, 2]], -1)


@dataclass(frozen=True)
class PinholeCamera:
    """Intrinsics of an ideal pinhole camera (pixels); no distortion."""

    width: int = 960
    height: int = 720
    focal_px: float = 2400.0

    @property
    def matrix(self) -> np.ndarray:
        """3x3 OpenCV camera matrix K."""
        return np.array(
            [[self.focal_px, 0, self.width / 2], [0, self.focal_px, self.height / 2], [0, 0, 1]],
            dtype=np.float64,
        )


def look_at(position: np.ndarray, target: np.ndarray, up_hint: np.ndarray | None = None):
    """World-to-camera rotation for a camera at ``position`` looking at ``target``.

    OpenCV convention: camera x right, y down, z forward. Returns ``R`` (3, 3) such that
    ``x_cam = R @ (x_world - position)``.
    """
    position = np.asarray(position, dtype=np.float64)
    fwd = np.asarray(target, dtype=np.float64) - position
    fwd /= np.linalg.norm(fwd)
    up = np.array([0.0, 0.0, 1.0]) if up_hint is None else np.asarray(up_hint, dtype=np.float64)
    if abs(np.dot(up, fwd)) > 0.999:
        up = np.array([0.0, 1.0, 0.0])
    right = np.cross(fwd, up)
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    return np.stack([right, down, fwd])


@dataclass
class CameraPose:
    """Camera position (m) and world-to-camera rotation in the sample frame."""

    position: np.ndarray
    rotation: np.ndarray

    @classmethod
    def looking_at_origin(cls, position: np.ndarray) -> CameraPose:
        return cls(np.asarray(position, dtype=np.float64), look_at(position, np.zeros(3)))


@dataclass
class VirtualCamera:
    """Renders the holder and writes DNG files.

    Parameters
    ----------
    truth : ground-truth BRDF of the sample: anything with ``f(wi, wo) -> (..., 3)`` (a gonio
        model or table), in the sample frame.
    layout, camera, sensor : scene, optics and sensor.
    throughput : (3,) photo-electrons per second per pixel per unit radiance W/(m^2 sr) for the
        R, G, B planes (quantum efficiency, aperture, pixel area folded together).
    supersample : rays per pixel along each axis.
    seed : base of every frame's noise stream.
    psf_px : standard deviation (pixels) of the Gaussian blur of the lens and sensor, applied to
        the board's texture scaled by the camera's distance to the holder centre (exact for a
        frontal view; foreshortening narrows it along the tilt). 0.8 px: a sharp lens behind a
        Bayer anti-aliasing filter. The sample and the white reference are rendered unblurred
        (their radiance varies slowly; their rims are outside the measured regions).
    """

    truth: Any
    layout: HolderLayout = field(default_factory=HolderLayout)
    camera: PinholeCamera = field(default_factory=PinholeCamera)
    sensor: SensorModel = field(default_factory=SensorModel)
    throughput: tuple[float, float, float] = (2.0e6, 2.4e6, 1.7e6)
    supersample: int = 2
    seed: int = 0
    psf_px: float = 0.8
    _textures: dict[int, np.ndarray] = field(default_factory=dict, init=False, repr=False)

    def board_texture(self, distance_m: float) -> np.ndarray:
        """The board's texture blurred by :attr:`psf_px` as seen from ``distance_m`` (cached
        per micrometre of blur)."""
        lay = self.layout
        texel_m = lay.square_m / lay.texture_px_per_square
        key = round(1e6 * self.psf_px * distance_m / self.camera.focal_px)
        if key <= 0:
            return lay.texture
        if key not in self._textures:
            from scipy import ndimage

            self._textures[key] = ndimage.gaussian_filter(
                lay.texture, 1e-6 * key / texel_m, mode="nearest"
            )
        return self._textures[key]

    def radiance(
        self, pose: CameraPose, light_pos: np.ndarray, intensity: np.ndarray
    ) -> np.ndarray:
        """Radiance image (H, W, 3) in W/(m^2 sr), before vignetting and the sensor.

        ``intensity`` is the light's radiant intensity (W/sr) per colour plane.
        """
        cam, ss = self.camera, self.supersample
        light_pos = np.asarray(light_pos, dtype=np.float64)
        intensity = np.broadcast_to(np.asarray(intensity, dtype=np.float64), (3,))
        offs = (np.arange(ss) + 0.5) / ss
        px = (np.arange(cam.width)[:, None] + offs[None, :]).ravel()
        py = (np.arange(cam.height)[:, None] + offs[None, :]).ravel()
        xs = (px - cam.width / 2) / cam.focal_px
        ys = (py - cam.height / 2) / cam.focal_px
        gx, gy = np.meshgrid(xs, ys)
        d_cam = np.stack([gx, gy, np.ones_like(gx)], -1)
        d = d_cam @ pose.rotation  # camera -> sample frame (R is orthonormal)
        o = pose.position
        with np.errstate(divide="ignore", invalid="ignore"):
            s = -o[2] / d[..., 2]
        hit = np.isfinite(s) & (s > 0)
        L = np.zeros((*hit.shape, 3))
        # Only rays that hit the holder plane are shaded (the rest stay black): on the flat
        # arrays of those rays, not on the whole supersampled image.
        d, s = d[hit], s[hit]
        p = o + s[:, None] * d
        to_light = light_pos - p
        dist2 = np.sum(to_light**2, -1)
        wi = to_light / np.sqrt(dist2)[:, None]
        wo = -d / np.linalg.norm(d, axis=-1, keepdims=True)
        irradiance = intensity * (np.maximum(wi[:, 2], 0.0) / dist2)[:, None]  # W/m^2

        lay = self.layout
        in_sample = _in_disk(p, lay.sample_center, lay.sample_radius)
        in_ref = _in_disk(p, lay.reference_center, lay.reference_radius) & ~in_sample
        w, h = lay.board_size_m
        in_board = (np.abs(p[:, 0]) < w / 2) & (np.abs(p[:, 1]) < h / 2) & ~in_sample & ~in_ref

        Lh = np.zeros((len(p), 3))
        tex = self.board_texture(float(np.linalg.norm(o)))
        pb = p[in_board]
        board_albedo = _bilinear(tex, (pb[:, 0] + w / 2) / w, (h / 2 - pb[:, 1]) / h)
        Lh[in_board] = (board_albedo / np.pi)[:, None] * irradiance[in_board]
        Lh[in_ref] = lay.reference_albedo / np.pi * irradiance[in_ref]
        if in_sample.any():
            # Pad to a power of two: JAX models compile once per input shape, and the number of
            # sample pixels changes with every geometry.
            a, b = wi[in_sample], wo[in_sample]
            n = len(a)
            pad = np.tile([0.0, 0.0, 1.0], ((1 << (n - 1).bit_length()) - n, 1))
            a, b = np.concatenate([a, pad]), np.concatenate([b, pad])
            f = np.asarray(self.truth.f(a, b), dtype=np.float64)[:n]
            if f.shape[-1] == 1:
                f = np.repeat(f, 3, axis=-1)
            Lh[in_sample] = f * irradiance[in_sample]
        L[hit] = Lh
        return L.reshape(cam.height, ss, cam.width, ss, 3).mean(axis=(1, 3))

    def electron_rate(
        self, pose: CameraPose, light_pos: np.ndarray, intensity: np.ndarray
    ) -> np.ndarray:
        """Photo-electron rate (H, W, 3) in e-/s: radiance x throughput x cos^4 vignetting."""
        cam = self.camera
        L = self.radiance(pose, light_pos, intensity)
        x = (np.arange(cam.width) + 0.5 - cam.width / 2) / cam.focal_px
        y = (np.arange(cam.height) + 0.5 - cam.height / 2) / cam.focal_px
        r2 = x[None, :] ** 2 + y[:, None] ** 2
        cos4 = 1.0 / (1.0 + r2) ** 2
        return L * np.asarray(self.throughput)[None, None, :] * cos4[..., None]

    def capture(
        self,
        path: str | Path,
        rate: np.ndarray,
        exposure_s: float,
        key: str,
        meta: dict[str, Any] | None = None,
    ) -> tuple[Path, float]:
        """Expose the sensor to an electron-rate image and write the DNG.

        Returns the path and the exposure time the shutter actually gave. ``key`` names the
        frame in the noise stream (e.g. the configuration index and exposure), so the same
        (seed, key) always gives the same file.
        """
        if rate.shape[:2] != (self.camera.height, self.camera.width):
            raise ParameterError("rate image does not match the camera size")
        dn, actual = self.sensor.expose(rate, exposure_s, seed=self.seed, key=key)
        info = {"exposure_nominal_s": exposure_s, **(meta or {})}
        path = write_dng(
            path,
            dn,
            exposure_s=exposure_s,
            black_level=self.sensor.black_level,
            white_level=self.sensor.white_level,
            cfa=self.sensor.cfa,
            meta=info,
        )
        return path, actual


def _in_disk(p: np.ndarray, center: tuple[float, float], radius: float) -> np.ndarray:
    return (p[..., 0] - center[0]) ** 2 + (p[..., 1] - center[1]) ** 2 <= radius**2


def _bilinear(tex: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear lookup of ``tex`` (rows, cols) at normalized coordinates u (cols), v (rows)
    (texel centres at (i + 0.5) / size; clamped to the edge texels outside)."""
    from scipy import ndimage

    rows, cols = tex.shape
    coords = np.stack([v * rows - 0.5, u * cols - 0.5])
    return ndimage.map_coordinates(tex, coords, order=1, mode="nearest")
