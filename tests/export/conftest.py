"""Shared pieces of the export tests: fit records of known models, the sphere scene."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

#: Direction toward the one directional light of the render tests (world frame, DESIGN.md).
LIGHT = np.array([0.4, 0.3, 1.0]) / np.linalg.norm([0.4, 0.3, 1.0])
#: Image size of the render comparisons and gonio's supersampling factor per axis: gonio traces
#: pixel centres, the renderers average over the pixel (box filter), so gonio renders SS x SS
#: centres per pixel and averages them.
SIZE, SS = 64, 8


def fit_record(model, channels=("R", "G", "B"), loss=0.0, metric="wls", **data) -> dict:
    """A fit-result dictionary (schema version 1) holding ``model``."""
    from gonio.io.fit_result import to_jsonable

    return to_jsonable(
        {
            "schema": "gonio/fit-result",
            "version": 1,
            "model": type(model).__name__.lower(),
            "model_spec": model.to_dict(),
            "params": {k: np.asarray(v).tolist() for k, v in model.params().items()},
            "intervals": {},
            "loss": loss,
            "metric": metric,
            "data": {"n_samples": 0, "channels": list(channels), "name": "test material", **data},
        }
    )


def write_record(path: Path, record: dict) -> Path:
    path.write_text(json.dumps(record))
    return path


def interior_mask(n: int = SIZE) -> np.ndarray:
    """Pixels whose whole area lies on the sphere (silhouette pixels are partly background,
    which gonio's centre sampling and a renderer's box filter treat differently)."""
    x = (np.arange(n) + 0.5) / n * 2 - 1
    xx, yy = np.meshgrid(x, -x)
    return np.hypot(xx, yy) + np.sqrt(2) / n < 1


def rel_rmse(image: np.ndarray, reference: np.ndarray) -> float:
    """``||image - reference|| / ||reference||`` over the interior pixels and all channels."""
    m = interior_mask(reference.shape[0])
    d = (np.asarray(image, np.float64) - reference)[m]
    return float(np.sqrt(np.mean(d * d)) / np.sqrt(np.mean(np.asarray(reference)[m] ** 2)))


def gonio_sphere(model, size: int = SIZE, ss: int = SS) -> np.ndarray:
    """gonio's render of the sphere under the one directional light (irradiance 1), each pixel
    the mean of ``ss x ss`` pixel-centre samples: (size, size, C) float64."""
    from gonio.render import Directional, render_sphere

    img = render_sphere(model, [Directional(LIGHT, 1.0)], resolution=size * ss)
    return img.reshape(size, ss, size, ss, -1).astype(np.float64).mean(axis=(1, 3))


def mitsuba_scene(
    mi, bsdf: dict, light: np.ndarray = LIGHT, size: int = SIZE, spp: int = 64, seed: int = 0
) -> dict:
    """Mitsuba's ``load_dict`` form of the render tests' scene: the unit sphere made of
    ``bsdf``, an orthographic camera on +z covering [-1, 1]^2 (``size`` pixels, box filter,
    ``spp`` stratified samples), one directional light of irradiance 1 toward ``light``, and the
    ``direct`` integrator sampling the emitter only (exact for a delta light)."""
    return {
        "type": "scene",
        "integrator": {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0},
        "sensor": {
            "type": "orthographic",
            "to_world": mi.ScalarTransform4f().look_at(
                origin=[0, 0, 2], target=[0, 0, 0], up=[0, 1, 0]
            ),
            "film": {
                "type": "hdrfilm",
                "width": size,
                "height": size,
                "rfilter": {"type": "box"},
                "pixel_format": "rgb",
            },
            "sampler": {"type": "stratified", "sample_count": spp, "seed": seed},
        },
        "sphere": {"type": "sphere", "bsdf": bsdf},
        "light": {
            "type": "directional",
            "direction": (-np.asarray(light)).tolist(),
            "irradiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]},
        },
    }


def path_scene(mi, bsdf: dict, size: int, spp: int, depth: int) -> dict:
    """A sphere made of ``bsdf`` under a white constant environment, seen by a perspective
    camera at z = 4 (``size`` pixels, ``spp`` independent samples), path-traced to ``depth``."""
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": depth},
        "sensor": {
            "type": "perspective",
            "to_world": mi.ScalarTransform4f().look_at(
                origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]
            ),
            "film": {"type": "hdrfilm", "width": size, "height": size},
            "sampler": {"type": "independent", "sample_count": spp},
        },
        "sphere": {"type": "sphere", "bsdf": bsdf},
        "light": {"type": "constant"},
    }


@pytest.fixture
def record_file(tmp_path):
    def make(model, name="fit.json", **kw):
        return write_record(tmp_path / name, fit_record(model, **kw))

    return make
