"""The appearance score: fitted and measured spheres compared as a person sees them.

>>> from gonio import appearance
>>> ref = appearance.Reference.of(table)          # the measurement's images, once
>>> appearance.score(ref, fitted_model)           # {"hdr_flip": ..., "rel_l1": ..., ...}

Images (:mod:`~gonio.appearance.images`): an orthographic unit sphere seen along +z under one
directional light at 0, 30 and 60 degrees from the view (exact: ``f cos theta_i`` per pixel) and
under a generated studio environment (a fixed, shared-sample estimate). Measures
(:mod:`~gonio.appearance.metrics`): HDR-FLIP and the relative L1 per image, and their means.
This package imports only :mod:`gonio.brdf`'s conventions and :mod:`gonio.errors`, so that fit,
render, export and the demo can all use it.
"""

from gonio.appearance.environment import DEFAULT_SAMPLES, studio_radiance
from gonio.appearance.images import SphereImages, render_images
from gonio.appearance.metrics import hdr_flip, relative_l1
from gonio.appearance.scene import DEFAULT_RESOLUTION, LIGHT_ANGLES_DEG, sphere_pixels
from gonio.appearance.score import IMAGES, KEYS, MEASURES, Reference, compare, score

__all__ = [
    "DEFAULT_RESOLUTION",
    "DEFAULT_SAMPLES",
    "IMAGES",
    "KEYS",
    "LIGHT_ANGLES_DEG",
    "MEASURES",
    "Reference",
    "SphereImages",
    "compare",
    "hdr_flip",
    "relative_l1",
    "render_images",
    "score",
    "sphere_pixels",
    "studio_radiance",
]
