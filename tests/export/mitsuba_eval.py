"""Mitsuba's own ``BSDF.eval`` of an exported dictionary on the appearance sphere's pixels.

No rendering: for each pixel of :func:`gonio.appearance.sphere_pixels` and each directional
light at 0, 30 and 60 degrees from the view (:data:`gonio.appearance.LIGHT_ANGLES_DEG`), the
pixel's value ``f(wi, wo) cos theta_i`` is evaluated by Mitsuba (``scalar_rgb``; its ``eval``
includes the cosine) and by gonio, so the comparison is exact per pixel.
"""

from __future__ import annotations

import numpy as np

from gonio.appearance import LIGHT_ANGLES_DEG, sphere_pixels
from gonio.appearance.scene import light_direction


def directions(resolution: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """``(wi, wo)`` local directions (n, 3) of every lit sphere pixel under each light."""
    px = sphere_pixels(resolution)
    wis, wos = [], []
    for a in LIGHT_ANGLES_DEG:
        wi = px.frame @ light_direction(a)
        lit = wi[:, 2] > 1e-4
        wis.append(wi[lit])
        wos.append(px.wo[lit])
    return np.concatenate(wis), np.concatenate(wos)


def mitsuba_values(bsdf_dict: dict, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Mitsuba's ``eval`` (``f cos theta_i``) of ``bsdf_dict`` for each pair: (n, 3)."""
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    bsdf = mi.load_dict(bsdf_dict)
    ctx = mi.BSDFContext()
    si = mi.SurfaceInteraction3f()
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    out = np.empty((len(wi), 3))
    for j, (a, b) in enumerate(zip(wi, wo, strict=True)):
        si.wi = mi.Vector3f(*b)  # Mitsuba's wi is toward the viewer
        out[j] = np.array(bsdf.eval(ctx, si, mi.Vector3f(*a)))
    return out


def gonio_values(model, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """gonio's ``f cos theta_i`` of ``model`` for each pair: (n, C)."""
    return np.asarray(model.f(wi, wo), np.float64) * wi[:, 2:3]


def rel_rmse(a: np.ndarray, b: np.ndarray) -> float:
    """``||a - b|| / ||b||`` over every pixel and channel."""
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b**2)))
