"""Helpers for RGL writer tests: random direction pairs, relative errors, Mitsuba 3's eval."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

COS_80 = math.cos(math.radians(80.0))


def pairs(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` pairs ``(wi, wo)`` of unit vectors, each uniform in ``cos(theta)`` over 0-80 deg.

    Returns
    -------
    wi, wo : (n, 3) arrays in the local shading frame (z = normal).
    """
    rng = np.random.default_rng(seed)

    def hemi():
        u = rng.random((n, 2))
        z = COS_80 + (1 - COS_80) * u[:, 0]
        r = np.sqrt(1 - z * z)
        p = 2 * math.pi * u[:, 1]
        return np.stack([r * np.cos(p), r * np.sin(p), z], -1)

    return hemi(), hemi()


def rel(a, b):
    """``|a - b| / max(|b|, 1e-6)``, elementwise."""
    return np.abs(a - b) / np.maximum(np.abs(b), 1e-6)


def mitsuba_f(path: Path, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """``f_r(wi, wo)`` (1/sr, RGB, shape (n, 3)) of ``path`` in Mitsuba 3's ``measured`` plugin.

    Mitsuba's ``eval(ctx, si, wo')`` conditions on ``si.wi`` and includes the cosine of its
    ``wo'``: gonio's ``wo`` is Mitsuba's ``si.wi``, gonio's ``wi`` its ``wo'``, and the cosine
    ``wi.z`` is divided out. Skips the test without the ``validate`` extra.
    """
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
    ctx = mi.BSDFContext()
    out = np.zeros((len(wi), 3))
    for k in range(len(wi)):
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*wo[k])
        v = bsdf.eval(ctx, si, mi.Vector3f(*wi[k]))
        out[k] = np.array([v[0], v[1], v[2]]) / wi[k, 2]
    return out
