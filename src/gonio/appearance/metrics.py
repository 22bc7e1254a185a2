"""Image differences of the appearance score: HDR-FLIP and the relative L1.

``relative_l1(ref, test, mask) = sum |test - ref| / sum ref`` over the sphere's pixels and every
channel (dimensionless; 0 for identical images, ``|s - 1|`` for ``test = s ref``). A model's
negative values (a published fit may have some, e.g. Bagher et al.'s Fresnel term) count as
they are here; HDR-FLIP sees them as 0.

``hdr_flip(ref, test, mask)``: NVIDIA's HDR-FLIP (Andersson et al., "FLIP: A Difference Evaluator
for Alternating Images", HPG 2020; "Visualizing Errors in Rendered High Dynamic Range Images",
Eurographics 2021) through the ``flip-evaluator`` package, the mean of its per-pixel error map
over the sphere's pixels (in [0, 1]; 0 for identical images). Choices:

* Inputs are linear RGB (a 1-channel image is repeated to grey), reference first: the measured
  image is the reference, so every fit of a material is judged under the same exposures.
* HDR-FLIP tone-maps both images (ACES, the default) at a range of exposures and keeps the
  largest LDR-FLIP error per pixel. ``flip-evaluator`` chooses the range from the reference:
  ``start = log2(x_max / Y_max)``, ``stop = log2(x_max / Y_median)`` of the reference's
  luminance, ``max(2, ceil(stop - start))`` exposures, ``x_max`` the value the tone mapper maps
  to 0.85. Over a whole sphere image the median would count the black background (and, with the
  light at 60 degrees, the unlit half), so gonio passes the range computed by the same rule from
  the **lit sphere pixels** of the reference (luminance > 0); ``x_max`` is read from
  ``flip-evaluator`` itself (:func:`_x_max`), not copied.
* Viewing condition: ``flip-evaluator``'s default, 67 pixels per degree (a 0.7 m wide 4K display
  seen from 0.7 m): the sphere is seen as the small thumbnail it is.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from gonio.errors import ParameterError

#: Luminance weights of linear sRGB (Rec. 709), as FLIP uses them.
_LUMA = np.array([0.2126, 0.7152, 0.0722])


def relative_l1(ref: np.ndarray, test: np.ndarray, mask: np.ndarray) -> float:
    """``sum |test - ref| / sum ref`` over ``mask``'s pixels (``(H, W)`` bool) and channels;
    NaN when the reference is 0 there."""
    r = np.asarray(ref, np.float64)[mask]
    t = np.asarray(test, np.float64)[mask]
    if r.shape != t.shape:
        raise ParameterError(f"images differ in shape: {ref.shape} and {test.shape}")
    total = r.sum()
    return float(np.abs(t - r).sum() / total) if total > 0 else math.nan


def _rgb(img: np.ndarray) -> np.ndarray:
    img = np.asarray(img, np.float32)
    if img.shape[-1] == 1:
        img = np.repeat(img, 3, axis=-1)
    if img.shape[-1] != 3:
        raise ParameterError(f"HDR-FLIP compares 1- or 3-channel images, got {img.shape[-1]}")
    return np.ascontiguousarray(np.maximum(img, 0.0))


@functools.cache
def _x_max() -> float:
    """The linear value FLIP's ACES tone mapper maps to 0.85, from its own exposure rule."""
    import flip_evaluator

    one = np.ones((8, 8, 3), np.float32)
    _, _, params = flip_evaluator.evaluate(one, one, "HDR", applyMagma=False)
    return float(2.0 ** params["startExposure"])  # Y_max = 1 here


def exposure_range(ref: np.ndarray, mask: np.ndarray) -> dict[str, float | int] | None:
    """FLIP's exposure range for ``ref`` from its lit pixels in ``mask`` (module docstring);
    None when no pixel is lit."""
    y = _rgb(ref)[mask] @ _LUMA
    y = y[y > 0]
    if y.size == 0:
        return None
    start = math.log2(_x_max() / float(y.max()))
    stop = math.log2(_x_max() / float(np.median(y)))
    return {
        "startExposure": start,
        "stopExposure": stop,
        "numExposures": max(2, math.ceil(stop - start)),
    }


def hdr_flip(ref: np.ndarray, test: np.ndarray, mask: np.ndarray) -> float:
    """Mean HDR-FLIP error over ``mask``'s pixels of ``test`` against ``ref`` (``(H, W, C)``
    linear images); 0 when both are black there, 1 when only the reference is."""
    import flip_evaluator

    r, t = _rgb(ref), _rgb(test)
    if r.shape != t.shape:
        raise ParameterError(f"images differ in shape: {ref.shape} and {test.shape}")
    params = exposure_range(r, mask)
    if params is None:
        return 0.0 if not np.any(t[mask] > 0) else 1.0
    err, _, _ = flip_evaluator.evaluate(
        r, t, "HDR", applyMagma=False, computeMeanError=False, parameters=params
    )
    return float(np.asarray(err)[..., 0][mask].mean())
