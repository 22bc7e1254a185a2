"""The appearance score: how alike two materials look on a sphere.

``score(reference, material)`` renders ``material`` as :mod:`gonio.appearance.images` does and
compares each image with the reference's (the measurement's) by HDR-FLIP and by the relative
L1 (:mod:`gonio.appearance.metrics`). It returns a flat ``{name: float}``:

``hdr_flip_0``, ``hdr_flip_30``, ``hdr_flip_60``, ``hdr_flip_env``
    mean HDR-FLIP over the sphere under the light at 0, 30 and 60 degrees from the view and
    under the studio environment; ``hdr_flip`` is the mean of the four.
``rel_l1_0``, ..., ``rel_l1_env``, ``rel_l1``
    the same for the relative L1 ``sum |fit - measured| / sum measured``.
``resolution_px``, ``env_samples``
    the image side in pixels and the studio image's samples per pixel.

Lower is better for both measures; 0 means identical images.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from gonio.appearance import environment as env
from gonio.appearance.images import SphereImages, render_images
from gonio.appearance.metrics import hdr_flip, relative_l1
from gonio.appearance.scene import DEFAULT_RESOLUTION

#: Image names in score order.
IMAGES = ("0", "30", "60", "env")

#: The two summary measures (means over :data:`IMAGES`).
MEASURES = ("hdr_flip", "rel_l1")

#: Every key :func:`score` returns.
KEYS = (
    *MEASURES,
    *(f"{m}_{i}" for m in MEASURES for i in IMAGES),
    "resolution_px",
    "env_samples",
)


@dataclass(frozen=True)
class Reference:
    """The measured material's images, rendered once and compared with many models."""

    images: SphereImages

    @classmethod
    def of(
        cls,
        material: Any,
        resolution: int = DEFAULT_RESOLUTION,
        env_samples: int = env.DEFAULT_SAMPLES,
        seed: int = 0,
    ) -> Reference:
        """Render ``material`` (the measurement) at ``resolution`` pixels."""
        return cls(render_images(material, resolution, env_samples, seed))


def compare(ref: SphereImages, test: SphereImages) -> dict[str, float]:
    """The score of ``test``'s images against ``ref``'s (same resolution and seed)."""
    mask = ref.pixels.mask
    out: dict[str, float] = {}
    for i in IMAGES:
        r, t = ref.images[i], test.images[i]
        out[f"hdr_flip_{i}"] = hdr_flip(r, t, mask)
        out[f"rel_l1_{i}"] = relative_l1(r, t, mask)
    for m in MEASURES:
        out[m] = sum(out[f"{m}_{i}"] for i in IMAGES) / len(IMAGES)
    out["resolution_px"] = float(ref.resolution)
    out["env_samples"] = float(ref.env_samples)
    return {k: out[k] for k in KEYS}


def score(reference: Reference | Any, material: Any, **render: Any) -> dict[str, float]:
    """The appearance score of ``material`` against ``reference`` (a :class:`Reference`, or
    the measured material itself, rendered here with ``render``'s resolution, env_samples
    and seed)."""
    ref = reference if isinstance(reference, Reference) else Reference.of(reference, **render)
    im = ref.images
    test = render_images(material, im.resolution, im.env_samples, im.seed)
    return compare(im, test)
