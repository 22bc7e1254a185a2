"""Synthetic measurements from known models for fitter tests (fixed seeds)."""

from __future__ import annotations

import numpy as np

from gonio.fit.data import FitData, from_arrays


def cosine_directions(n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` cosine-distributed unit vectors in the upper hemisphere, (n, 3)."""
    u = rng.uniform(size=(n, 2))
    th = np.arccos(np.sqrt(u[:, 0]))
    ph = 2 * np.pi * u[:, 1]
    return np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)


def synthetic(
    model,
    n: int = 2000,
    seed: int = 0,
    rel_noise: float = 0.05,
    abs_noise: float = 0.005,
    with_sigma: bool = True,
    theta_max_deg: float = 80.0,
) -> tuple[FitData, np.ndarray]:
    """Noisy samples of ``model`` with sigma = abs_noise + rel_noise * f; returns (data, f)."""
    rng = np.random.default_rng(seed)
    wi, wo = cosine_directions(n, rng), cosine_directions(n, rng)
    f = np.asarray(model.f(wi, wo), dtype=np.float64)
    sigma = abs_noise + rel_noise * f
    y = f + sigma * rng.standard_normal(f.shape)
    data = from_arrays(
        wi, wo, y, sigma=sigma if with_sigma else None, theta_max_deg=theta_max_deg, name="synth"
    )
    return data, f
