"""The appearance score's scene: an orthographic unit sphere seen along +z, one frame per pixel.

World frame as in ``gonio.render`` (docs/design.md, rendering scene convention): x to the right
of the image, y up, z toward the camera; the camera looks down -z, orthographically, and the
square image covers ``[-1, 1]^2`` so that the sphere just fills it. Row 0 is the top of the
image. Each pixel is evaluated once, at its centre: the normal there is ``n = (x, y, sqrt(1 - x^2
- y^2))``, the outgoing direction is the view direction ``(0, 0, 1)``, and the shading frame has
``n`` as z and the direction of increasing longitude about the world y axis, ``(n_z, 0, -n_x)``
normalized, as tangent x (the renderer's choice, so anisotropic materials look the same in both).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gonio.errors import ParameterError

#: Default image size in pixels (square). Small on purpose: the score is computed for many
#: models per material.
DEFAULT_RESOLUTION = 96

#: Angles of the directional light from the view direction, in degrees, in the x-z plane
#: (toward +x, the image's right).
LIGHT_ANGLES_DEG = (0.0, 30.0, 60.0)


@dataclass(frozen=True)
class SpherePixels:
    """The pixels of a ``resolution`` x ``resolution`` image that see the sphere.

    Attributes
    ----------
    resolution : image side in pixels.
    index : (P,) flat indices (row-major) of the pixels on the sphere.
    normal : (P, 3) unit normals in world space.
    frame : (P, 3, 3) shading frames, rows (tangent, bitangent, normal) in world space.
    wo : (P, 3) the view direction in each local frame (``wo[:, 2] > 0``).
    """

    resolution: int
    index: np.ndarray
    normal: np.ndarray
    frame: np.ndarray
    wo: np.ndarray

    @property
    def mask(self) -> np.ndarray:
        """(H, W) bool: True on the sphere."""
        m = np.zeros(self.resolution * self.resolution, bool)
        m[self.index] = True
        return m.reshape(self.resolution, self.resolution)

    def scatter(self, values: np.ndarray) -> np.ndarray:
        """``(..., P, C)`` pixel values -> ``(..., H, W, C)`` images, 0 off the sphere."""
        values = np.asarray(values)
        lead, c = values.shape[:-2], values.shape[-1]
        out = np.zeros((*lead, self.resolution * self.resolution, c), values.dtype)
        out[..., self.index, :] = values
        return out.reshape(*lead, self.resolution, self.resolution, c)


def sphere_pixels(resolution: int = DEFAULT_RESOLUTION) -> SpherePixels:
    """Geometry of the sphere image at ``resolution`` pixels (8 to 1024), float64.

    Pixels whose centre is within ``1e-3`` of the silhouette are left out (their view
    direction is grazing, ``cos theta_o < 0.045``), as a measurement never reaches there.
    """
    if not isinstance(resolution, (int, np.integer)) or not 8 <= resolution <= 1024:
        raise ParameterError(f"resolution must be an integer in [8, 1024], got {resolution!r}")
    n = int(resolution)
    c = (np.arange(n) + 0.5) / n * 2.0 - 1.0
    x, y = np.meshgrid(c, -c)  # row 0 at the top: y = +1
    r2 = x * x + y * y
    inside = r2 < (1.0 - 1e-3) ** 2
    index = np.flatnonzero(inside.ravel())
    nx, ny = x.ravel()[index], y.ravel()[index]
    nz = np.sqrt(1.0 - nx * nx - ny * ny)
    normal = np.stack([nx, ny, nz], -1)
    t = np.stack([nz, np.zeros_like(nz), -nx], -1)
    t /= np.linalg.norm(t, axis=-1, keepdims=True)
    b = np.cross(normal, t)
    frame = np.stack([t, b, normal], -2)
    wo = frame[..., :, 2]  # the local coordinates of (0, 0, 1): the z column of each frame
    return SpherePixels(n, index, normal, frame, np.ascontiguousarray(wo))


def light_direction(angle_deg: float) -> np.ndarray:
    """World direction toward a light ``angle_deg`` from the view, in the x-z plane, (3,)."""
    a = np.radians(angle_deg)
    return np.array([np.sin(a), 0.0, np.cos(a)])
