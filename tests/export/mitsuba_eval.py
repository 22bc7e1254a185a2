"""Mitsuba's own ``BSDF.eval`` of an exported dictionary on the appearance sphere's pixels.

No rendering: for each pixel of :func:`gonio.appearance.sphere_pixels` and each directional
light at 0, 30 and 60 degrees from the view (:data:`gonio.appearance.LIGHT_ANGLES_DEG`), the
pixel's value ``f(wi, wo) cos theta_i`` is evaluated by Mitsuba (``scalar_rgb``; its ``eval``
includes the cosine) and by gonio, so the comparison is exact per pixel.

Under gonio's studio environment (:mod:`gonio.appearance.environment`) each pixel is the fixed
weighted sum that defines the appearance score's studio image (:func:`studio_pairs`): the
environment's fixed-seed directions per pixel, each weighted by its radiance over the sampling
density, times ``f cos`` from either side. The directions and weights do not depend on the
material, so the two images differ only by the two BSDFs' values.
"""

from __future__ import annotations

import numpy as np

from gonio.appearance import LIGHT_ANGLES_DEG, sphere_pixels
from gonio.appearance import environment as env
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


def studio_pairs(
    resolution: int = 24, samples: int = 70, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The studio image of the sphere as a fixed sum over direction pairs.

    For each pixel of :func:`gonio.appearance.sphere_pixels` the ``samples`` directions of the
    appearance score's studio estimator (:func:`gonio.appearance.environment.uniforms` with
    ``seed``, :func:`~gonio.appearance.environment.directions`), those above the horizon kept.
    Directions are rounded to float32 (Mitsuba's scalar precision) for both sides.

    Returns
    -------
    wi, wo : (n, 3) local light and view directions of each pair.
    weight : (n, 3) RGB studio radiance over ``samples`` times the proposal mixture's density,
        so that pixel ``p``'s value is ``sum(weight * f cos)`` over its pairs.
    pixel : (n,) index of each pair's pixel in ``sphere_pixels(resolution)``.
    """
    px = sphere_pixels(resolution)
    u = env.uniforms(px.index.size, samples, seed).astype(np.float64)
    wi = env.directions(px.wo, u, np).astype(np.float32).astype(np.float64)  # (P, S, 3)
    wo = np.broadcast_to(px.wo.astype(np.float32).astype(np.float64)[:, None], wi.shape)
    pdf = env.mixture_pdf(wi, wo, np)
    radiance = env.studio_radiance(np.einsum("pji,psj->psi", px.frame, wi))
    weight = radiance / (samples * pdf[..., None])
    keep = wi[..., 2] > 1e-4
    pixel = np.broadcast_to(np.arange(px.index.size)[:, None], keep.shape)
    return wi[keep], wo[keep], weight[keep], pixel[keep]


def studio_image(values: np.ndarray, weight: np.ndarray, pixel: np.ndarray) -> np.ndarray:
    """Per-pixel sums ``(P, 3)`` of ``weight * values`` (``values`` (n, C): ``f cos`` of each
    pair of :func:`studio_pairs`, 1 or 3 channels)."""
    out = np.zeros((int(pixel.max()) + 1, 3))
    np.add.at(out, pixel, weight * values)
    return out
