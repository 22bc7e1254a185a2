"""The scene: a unit sphere at the origin seen by a camera on the +z axis (DESIGN.md).

World frame: x to the right of the image, y up, z toward the camera. The camera looks down -z;
the orthographic camera (the default) maps the image onto ``[-a, a] x [-1, 1]`` with ``a`` the
aspect ratio W/H, so a square image covers ``[-1, 1]^2`` and the sphere just fills it. Row 0 is
the top of the image.

Every pixel is traced once, through its centre: the geometry (hit point, normal, shading frame,
outgoing direction) is fixed per pixel and only the lighting integral is sampled. Edges are
therefore not anti-aliased, and the outgoing directions a material is asked about are exactly one
per visible pixel — the set a tabulated BRDF may build its lazy sampling structures for.

The shading frame at a hit point has the outward normal as z and the direction of increasing
longitude about the world y axis as tangent x, so at the point facing the camera the local frame
is the world frame (x right, y up, z toward the camera) and anisotropic materials are brushed
along circles of latitude.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from gonio.errors import ParameterError


@dataclass(frozen=True)
class Camera:
    """A camera on the +z axis looking at the origin.

    Attributes
    ----------
    kind : ``"orthographic"`` (default; the image covers ``[-aspect, aspect] x [-1, 1]``) or
        ``"perspective"`` (a pinhole at ``(0, 0, distance)``).
    distance : distance of the pinhole from the origin (scene units, > 1); perspective only.
    fov_deg : full vertical field of view in degrees; perspective only. ``None`` picks the angle
        under which the unit sphere just fills the image height.
    """

    kind: Literal["orthographic", "perspective"] = "orthographic"
    distance: float = 4.0
    fov_deg: float | None = None

    def __post_init__(self) -> None:
        if self.kind not in ("orthographic", "perspective"):
            raise ParameterError(
                f"camera kind must be 'orthographic' or 'perspective', got {self.kind!r}"
            )
        if self.kind == "perspective":
            if not (math.isfinite(self.distance) and self.distance > 1.0):
                raise ParameterError(
                    f"perspective camera distance must be > 1 (outside the sphere), "
                    f"got {self.distance}"
                )
            if self.fov_deg is not None and not (0.0 < self.fov_deg < 180.0):
                raise ParameterError(f"fov_deg must be in (0, 180) degrees, got {self.fov_deg}")

    @classmethod
    def perspective(cls, distance: float = 4.0, fov_deg: float | None = None) -> Camera:
        """A pinhole camera at ``(0, 0, distance)``."""
        return cls("perspective", float(distance), None if fov_deg is None else float(fov_deg))

    def half_height(self) -> float:
        """Tangent of half the vertical field of view (perspective only)."""
        if self.fov_deg is not None:
            return math.tan(math.radians(self.fov_deg) / 2.0)
        # The silhouette of the unit sphere subtends asin(1/d) from the pinhole.
        return 1.0 / math.sqrt(self.distance**2 - 1.0)


@dataclass(frozen=True)
class SphereHits:
    """The visible sphere points of an image, compacted to the pixels that hit the sphere.

    Attributes
    ----------
    shape : (H, W) of the image.
    index : (P,) flat pixel indices (row-major) of the P pixels that hit the sphere.
    position : (P, 3) world hit points (on the unit sphere, so also the outward normals).
    frame : (P, 3, 3) local shading frames, rows (tangent, bitangent, normal) in world space.
    wo : (P, 3) direction toward the camera in each local frame (``wo[:, 2] > 0``).
    """

    shape: tuple[int, int]
    index: np.ndarray
    position: np.ndarray
    frame: np.ndarray
    wo: np.ndarray

    @property
    def count(self) -> int:
        """Number of pixels that see the sphere."""
        return int(self.index.shape[0])

    def scatter(self, values: np.ndarray, fill: float = 0.0) -> np.ndarray:
        """Place per-hit values ``(P, C)`` into an image ``(H, W, C)`` (``fill`` elsewhere)."""
        h, w = self.shape
        out = np.full((h * w, values.shape[-1]), fill, dtype=values.dtype)
        out[self.index] = values
        return out.reshape(h, w, values.shape[-1])


def parse_resolution(resolution: int | tuple[int, int]) -> tuple[int, int]:
    """``256`` -> ``(256, 256)``; ``(H, W)`` stays; raises ParameterError when not positive."""
    if isinstance(resolution, (int, np.integer)):
        h = w = int(resolution)
    else:
        try:
            h, w = (int(x) for x in resolution)
        except (TypeError, ValueError):
            raise ParameterError(
                f"resolution must be an int or (height, width), got {resolution!r}"
            ) from None
    if h < 1 or w < 1 or h * w > 16384 * 16384:
        raise ParameterError(f"resolution must be positive and at most 16384^2, got {(h, w)}")
    return h, w


def primary_rays(shape: tuple[int, int], camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Ray origins and unit directions through every pixel centre, each ``(H*W, 3)`` float64."""
    h, w = shape
    aspect = w / h
    # Pixel centres; row 0 at the top (y = +1).
    x = (np.arange(w) + 0.5) / w * 2.0 - 1.0
    y = 1.0 - (np.arange(h) + 0.5) / h * 2.0
    xx, yy = np.meshgrid(x * aspect, y)
    xx, yy = xx.ravel(), yy.ravel()
    if camera.kind == "orthographic":
        origin = np.stack([xx, yy, np.full_like(xx, 2.0)], -1)
        direction = np.broadcast_to(np.array([0.0, 0.0, -1.0]), origin.shape).copy()
    else:
        t = camera.half_height()
        d = np.stack([xx * t, yy * t, -np.ones_like(xx)], -1)
        direction = d / np.linalg.norm(d, axis=-1, keepdims=True)
        origin = np.broadcast_to(np.array([0.0, 0.0, camera.distance]), d.shape).copy()
    return origin, direction


def intersect_sphere(
    resolution: int | tuple[int, int] = 256, camera: Camera | None = None
) -> SphereHits:
    """Trace one ray per pixel centre against the unit sphere; keep only the hits.

    The last few images' hits are kept (:func:`functools.lru_cache`; their arrays are read-only):
    a render of an image size and camera met before skips the tracing, a noticeable share of a
    small warm render's host time (the tracing and the memory it churns).

    Returns
    -------
    SphereHits with float32 positions, frames and local outgoing directions.
    """
    return _traced(parse_resolution(resolution), camera or Camera())


@functools.lru_cache(maxsize=4)
def _traced(shape: tuple[int, int], camera: Camera) -> SphereHits:
    origin, direction = primary_rays(shape, camera)
    # |o + t d|^2 = 1 with |d| = 1: t^2 + 2 b t + c = 0. Written per component, on the hit rows
    # only: the same bits as sums and stacks of (n, 3) arrays, in fewer passes over memory
    # (the tracing is a large part of a warm render's host time).
    b = np.einsum("ij,ij->i", origin, direction)
    c = np.einsum("ij,ij->i", origin, origin) - 1.0
    disc = b * b - c
    index = np.flatnonzero(disc > 0)
    d = direction[index]
    t = -b[index] - np.sqrt(disc[index])
    p = origin[index] + t[:, None] * d
    p /= np.sqrt(np.einsum("ij,ij->i", p, p))[:, None]
    nx, ny, nz = p.T
    # Longitude tangent about world y: d/dphi of (sin phi, ., cos phi) ~ (n_z, 0, -n_x), already
    # orthogonal to n. At the two poles (only ever at the silhouette) any tangent will do.
    tn = np.sqrt(nz * nz + nx * nx)
    pole = tn <= 1e-12
    tn = np.where(pole, 1.0, tn)
    tx = np.where(pole, 1.0, nz / tn)
    tz = np.where(pole, 0.0, -nx / tn)
    frame = np.zeros((index.size, 3, 3))
    frame[:, 0, 0], frame[:, 0, 2] = tx, tz
    frame[:, 1, 0], frame[:, 1, 1], frame[:, 1, 2] = ny * tz, nz * tx - nx * tz, -(ny * tx)  # n x t
    frame[:, 2] = p
    wo = np.einsum("pij,pj->pi", frame, -d)
    # Grazing pixels at the silhouette can round to wo_z <= 0: they see the sphere edge-on.
    keep = wo[:, 2] > 1e-6
    if not keep.all():
        index, p, frame, wo = index[keep], p[keep], frame[keep], wo[keep]
    arrays = [index, p.astype(np.float32), frame.astype(np.float32), wo.astype(np.float32)]
    for a in arrays:
        a.setflags(write=False)  # shared by every render of this image
    return SphereHits(shape, *arrays)
