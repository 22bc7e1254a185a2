"""Regenerate the tiny example files next to this script (run from the repository root):

    python data-schema/examples/make_examples.py

tiny-gridded.brdf.h5: an isotropic half/diff RGB table (8 x 6 x 10) of Lambert + a Blinn-like
lobe, with sigma, counts and a validity mask; tiny-scattered.brdf.h5: 40 scattered spectral
samples (5 wavelengths) with sigma and weights.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from gonio.brdf import frames
from gonio.brdf.tabulated import Axis, Channels, MeasuredSamples, TabulatedBRDF
from gonio.io import save

HERE = Path(__file__).resolve().parent


def gridded() -> TabulatedBRDF:
    axes = (
        Axis("theta_h", 8, 0.0, math.pi / 2, "sqrt", False, 0.0),
        Axis("theta_d", 6, 0.0, math.pi / 2, "linear", False, 0.0),
        Axis("phi_d", 10, 0.0, math.pi, "linear", True, 0.0),
    )
    th, td, pd = np.meshgrid(*(a.nodes() for a in axes), indexing="ij")
    wi, wo = (np.asarray(w) for w in frames.half_diff_to_directions(th, 0 * th, td, pd))
    mask = (wi[..., 2] > 0) & (wo[..., 2] > 0)
    lobe = 0.5 * np.cos(th) ** 40
    values = np.stack([0.25 + lobe, 0.15 + lobe, 0.05 + lobe], -1) / math.pi
    rng = np.random.default_rng(0)
    counts = rng.integers(1, 5, th.shape)
    sigma = 0.02 * values / np.sqrt(counts)[..., None]
    meta = {
        "rig": {"name": "example-rig", "file": "rigs/example.toml"},
        "plan": {"name": "example-plan", "n_poses": int(mask.sum())},
        "calibration": {"white_reference": "Spectralon 99%"},
        "software_version": "gonio example",
        "notes": "synthetic example written by data-schema/examples/make_examples.py",
    }
    return TabulatedBRDF(
        values=values,
        axes=axes,
        parameterization="half_diff_iso",
        mask=mask,
        sigma=sigma,
        counts=counts,
        channels=Channels.rgb(),
        meta=meta,
    )


def scattered() -> MeasuredSamples:
    rng = np.random.default_rng(1)
    n = 40
    ti, to = rng.uniform(0.1, 1.2, n), rng.uniform(0.0, 1.3, n)
    po = rng.uniform(0, 2 * math.pi, n)
    wi = np.stack([np.sin(ti), 0 * ti, np.cos(ti)], -1)
    wo = np.stack([np.sin(to) * np.cos(po), np.sin(to) * np.sin(po), np.cos(to)], -1)
    wl = np.array([450.0, 500.0, 550.0, 600.0, 650.0])
    values = np.outer(np.ones(n), [0.05, 0.08, 0.12, 0.2, 0.25]) * (1 + 0.1 * rng.random((n, 1)))
    return MeasuredSamples(
        wi=wi,
        wo=wo,
        values=values,
        sigma=0.01 * values,
        channels=Channels.spectral(wl),
        weights=np.ones(n),
        meta={"source": {"format": "synthetic", "file": "make_examples.py"}},
    )


if __name__ == "__main__":
    save(gridded(), HERE / "tiny-gridded.brdf.h5")
    save(scattered(), HERE / "tiny-scattered.brdf.h5")
    print("wrote", HERE / "tiny-gridded.brdf.h5", HERE / "tiny-scattered.brdf.h5")
