"""Direction helpers in NumPy for the parsers (angles in radians, local frame, z = normal).

They mirror :mod:`gonio.brdf.frames` but stay in NumPy: parsers call them on arrays whose length
changes from file to file, and the JAX versions would compile once per new shape.
"""

from __future__ import annotations

import numpy as np


def spherical(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Unit vectors ``(..., 3)`` from polar angle ``theta`` and azimuth ``phi`` (radians)."""
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)


def half_diff_to_directions(
    theta_h: np.ndarray, phi_h: np.ndarray, theta_d: np.ndarray, phi_d: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """NumPy twin of :func:`gonio.brdf.frames.half_diff_to_directions` (same convention)."""
    th, ph, td, pd = np.broadcast_arrays(
        *(np.asarray(a, dtype=np.float64) for a in (theta_h, phi_h, theta_d, phi_d))
    )
    d = spherical(td, pd)
    d_o = d * np.array([-1.0, -1.0, 1.0])

    def rot(v: np.ndarray) -> np.ndarray:
        cy, sy = np.cos(th), np.sin(th)
        x, y, z = v[..., 0], v[..., 1], v[..., 2]
        x, z = cy * x + sy * z, -sy * x + cy * z
        cz, sz = np.cos(ph), np.sin(ph)
        return np.stack([cz * x - sz * y, sz * x + cz * y, z], -1)

    return rot(d), rot(d_o)
