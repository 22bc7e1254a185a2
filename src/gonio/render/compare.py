"""Image error metrics and the measured | fitted | difference comparison figure.

Metrics compare a test image with a reference over the pixels where the reference sees the sphere:

``rmse``
    root mean square error of linear radiance over those pixels and all channels;
``rel_mse``
    mean of ``(x - ref)^2 / (ref^2 + eps)`` with ``eps = 0.01 mean(ref)^2`` (so dark pixels do not
    dominate), the usual relative MSE of rendering papers made scale-free;
``ssim``
    structural similarity (Wang et al. 2004) of the two images after the same tone mapping, from
    OpenCV's maintained implementation (``cv2.quality``, opencv-contrib); ``None`` when OpenCV is
    not installed. SSIM describes what a person sees, so it is computed on display values.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from gonio.errors import ParameterError
from gonio.io.atomic import atomic_output
from gonio.render.output import auto_exposure, luminance, tonemap


@dataclass(frozen=True)
class ImageErrors:
    """Errors of one image against a reference (see the module docstring)."""

    rmse: float
    rel_mse: float
    ssim: float | None

    def as_dict(self) -> dict[str, float | None]:
        return asdict(self)


def _mask(reference: np.ndarray) -> np.ndarray:
    return np.any(reference != 0, axis=-1)


def image_errors(
    image: np.ndarray, reference: np.ndarray, exposure: float | None = None
) -> ImageErrors:
    """Errors of ``image`` against ``reference``, both linear ``(H, W, C)`` of equal shape."""
    a = np.asarray(image, dtype=np.float64)
    r = np.asarray(reference, dtype=np.float64)
    if a.shape != r.shape or a.ndim != 3:
        raise ParameterError(f"images must have the same (H, W, C) shape: {a.shape} vs {r.shape}")
    m = _mask(r)
    if not np.any(m):
        raise ParameterError("the reference image is black: nothing to compare")
    d = (a - r)[m]
    ref = r[m]
    rmse = float(np.sqrt(np.mean(d * d)))
    eps = 0.01 * float(np.mean(ref)) ** 2
    rel = float(np.mean(d * d / (ref * ref + eps))) if eps > 0 else float("nan")
    return ImageErrors(rmse, rel, ssim(image, reference, exposure))


def ssim(image: np.ndarray, reference: np.ndarray, exposure: float | None = None) -> float | None:
    """Mean SSIM over RGB of the tone-mapped images (same exposure, from the reference)."""
    try:
        import cv2
    except ImportError:
        return None
    quality = getattr(cv2, "quality", None)
    if quality is None:
        return None
    exp = auto_exposure(reference) if exposure is None else exposure
    a = tonemap(image, exp).astype(np.float64) * 255.0
    b = tonemap(reference, exp).astype(np.float64) * 255.0
    score = quality.QualitySSIM_compute(a, b)[0]
    return float(np.mean(score[:3]))


@dataclass(frozen=True)
class Comparison:
    """One fitted rendering with its label and its errors against the measured rendering."""

    label: str
    image: np.ndarray
    errors: ImageErrors


def compare_images(
    measured: np.ndarray, fitted: Sequence[tuple[str, np.ndarray]]
) -> tuple[float, list[Comparison]]:
    """Errors of each fitted image against the measured one; returns (exposure, comparisons)."""
    exp = auto_exposure(measured)
    out = [Comparison(label, img, image_errors(img, measured, exp)) for label, img in fitted]
    return exp, out


def comparison_figure(
    path: str | os.PathLike,
    measured: np.ndarray,
    comparisons: Sequence[Comparison],
    exposure: float | None = None,
    title: str | None = None,
    reference_label: str = "measured",
) -> Path:
    """Write the figure: one row per fit, ``measured | fitted | |difference|`` heat map.

    Renders share one exposure (the measured image's). The heat map shows the absolute luminance
    difference relative to the measured image's 99th luminance percentile, on a shared scale
    that ends at the 99.5th percentile of the differences: larger ones are drawn at the top
    colour, which the colour bar's label says. ``reference_label`` names the first column
    (e.g. "ground truth" when the reference is a simulated sample's analytic truth).
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    if not comparisons:
        raise ParameterError("nothing to compare: give at least one fitted image")
    exp = auto_exposure(measured) if exposure is None else exposure
    lum_m = luminance(measured)
    nz = lum_m[lum_m > 0]
    norm = float(np.percentile(nz, 99)) if nz.size else 1.0
    diffs = [np.abs(luminance(c.image) - lum_m) / norm for c in comparisons]
    vmax = max(1e-6, max(float(np.percentile(d[lum_m > 0], 99.5)) for d in diffs))
    n = len(comparisons)
    fig, axes = plt.subplots(n, 3, figsize=(9.6, 3.3 * n + (0.4 if title else 0)), squeeze=False)
    shown_m = tonemap(measured, exp)
    for row, (c, d) in enumerate(zip(comparisons, diffs, strict=True)):
        ax_m, ax_f, ax_d = axes[row]
        ax_m.imshow(shown_m, interpolation="nearest")
        ax_m.set_title(reference_label, fontsize=10)
        ax_f.imshow(tonemap(c.image, exp), interpolation="nearest")
        ax_f.set_title(c.label, fontsize=10)
        im = ax_d.imshow(d, cmap="magma", vmin=0.0, vmax=vmax, interpolation="nearest")
        e = c.errors
        text = f"RMSE {e.rmse:.3g}   relMSE {e.rel_mse:.3g}"
        if e.ssim is not None:
            text += f"   SSIM {e.ssim:.3f}"
        ax_d.set_title(f"|difference| / {reference_label} p99", fontsize=10)
        ax_d.text(0.5, -0.06, text, transform=ax_d.transAxes, ha="center", va="top", fontsize=9)
        bar = fig.colorbar(im, ax=ax_d, fraction=0.046, pad=0.04, extend="max")
        bar.set_label(f"clipped at {vmax:.3g} (99.5th percentile)", fontsize=8)
        for ax in (ax_m, ax_f, ax_d):
            ax.set_xticks([])
            ax.set_yticks([])
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    path = Path(path)
    suffix = path.suffix or ".png"
    try:
        with atomic_output(path, suffix, make_parents=True) as tmp:
            fig.savefig(tmp, dpi=110, format=suffix.lstrip(".").lower())
    finally:
        plt.close(fig)
    return path
