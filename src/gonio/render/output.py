"""Image output: linear OpenEXR, tone-mapped sRGB PNG. Every file is written atomically.

Linear radiance images are ``(H, W, C)`` float32. EXR keeps them as they are (channels ``R, G, B``
for three channels, ``Y`` for one, ``c0 ... c{n-1}`` otherwise). The PNG is for people: an
exposure (by default the one that maps the 99.5th percentile of the sphere's luminance to 0.8 after
tone mapping), the extended Reinhard curve, and the sRGB transfer function; one channel is shown
as grey and other channel counts as the mean of their channels.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from gonio.errors import FormatError, ParameterError
from gonio.io.atomic import atomic_output


def _channel_names(c: int) -> list[str]:
    if c == 3:
        return ["R", "G", "B"]
    if c == 1:
        return ["Y"]
    return [f"c{i}" for i in range(c)]


def _as_image(img: np.ndarray) -> np.ndarray:
    a = np.asarray(img, dtype=np.float32)
    if a.ndim == 2:
        a = a[..., None]
    if a.ndim != 3 or a.shape[0] < 1 or a.shape[1] < 1 or a.shape[2] < 1:
        raise ParameterError(f"image must be (H, W) or (H, W, C), got {np.shape(img)}")
    return a


def write_exr(
    path: str | os.PathLike, img: np.ndarray, names: list[str] | tuple[str, ...] | None = None
) -> Path:
    """Write linear float32 ``img`` (H, W, C) as a ZIP-compressed scanline OpenEXR file
    (:func:`gonio.io.exr.write_exr`, atomically).

    ``names`` are the channel names (spectral images: ``"400nm"``, ...; a spectral material's
    ``channels.names``); default ``R, G, B`` / ``Y`` / ``c<i>``.
    """
    from gonio.io import exr

    a = _as_image(img)
    exr.write_exr(path, a, list(names) if names else _channel_names(a.shape[2]))
    return Path(path)


def read_exr(path: str | os.PathLike) -> np.ndarray:
    """Read an OpenEXR file (:func:`gonio.io.exr.read_exr`) as float32 ``(H, W, C)``; RGB(A) in
    that order, alpha dropped."""
    from gonio.io import exr

    img, names = exr.read_exr(path)
    keep = [i for i, n in enumerate(names) if n != "A"]
    if not keep:
        raise FormatError(f"{path}: no image channels")
    return np.asarray(img, dtype=np.float32)[..., keep]


def luminance(img: np.ndarray) -> np.ndarray:
    """Rec. 709 luminance of an RGB image, the channel mean otherwise: (H, W)."""
    a = _as_image(img)
    if a.shape[2] == 3:
        return a @ np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
    return a.mean(axis=-1)


def auto_exposure(img: np.ndarray, percentile: float = 99.5) -> float:
    """Exposure that maps the given percentile of the non-zero luminance to 0.8 after
    :func:`tonemap` (the whole image is treated alike, so several images compared side by side
    should share one exposure)."""
    lum = luminance(img)
    lum = lum[lum > 0]
    if lum.size == 0:
        return 1.0
    ref = float(np.percentile(lum, percentile))
    if not np.isfinite(ref) or ref <= 0:
        return 1.0
    return _reinhard_inverse(0.8) / ref


_WHITE = 4.0


def _reinhard(x: np.ndarray) -> np.ndarray:
    return x * (1.0 + x / _WHITE**2) / (1.0 + x)


def _reinhard_inverse(y: float) -> float:
    lo, hi = 0.0, _WHITE
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if _reinhard(np.float64(mid)) < y:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def srgb_encode(x: np.ndarray) -> np.ndarray:
    """The sRGB transfer function on [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def tonemap(img: np.ndarray, exposure: float | None = None) -> np.ndarray:
    """Display image in [0, 1], (H, W, 3) float32: exposure, Reinhard on luminance, sRGB.

    The curve acts on luminance and scales the channels alike, so hues do not shift.
    """
    a = _as_image(img)
    if exposure is None:
        exposure = auto_exposure(a)
    if a.shape[2] != 3:
        a = np.repeat(a.mean(axis=-1, keepdims=True), 3, axis=-1)
    a = np.maximum(a, 0.0) * float(exposure)
    lum = luminance(a)
    scale = np.where(lum > 0, _reinhard(lum) / np.where(lum > 0, lum, 1.0), 0.0)
    return srgb_encode(a * scale[..., None]).astype(np.float32)


def write_png(path: str | os.PathLike, img: np.ndarray, exposure: float | None = None) -> Path:
    """Tone-map linear ``img`` and write an 8-bit sRGB PNG."""
    from PIL import Image

    disp = tonemap(img, exposure)
    data = np.round(disp * 255.0).astype(np.uint8)
    path = Path(path)
    with atomic_output(path, ".png", make_parents=True) as tmp:
        Image.fromarray(data).save(tmp, format="PNG")
    return path


#: Figure formats of the commands that write plots (by extension).
FIGURE_FORMATS = (".png", ".svg", ".pdf")


def output_path(text: str, default_name: str = "plot.png") -> Path:
    """The figure path: a folder (existing, or written with a trailing /) gets
    ``default_name`` inside; the extension must be one of :data:`FIGURE_FORMATS`."""
    p = Path(text)
    if text.endswith(("/", "\\")) or p.is_dir():
        p = p / default_name
    if p.suffix.lower() not in FIGURE_FORMATS:
        raise ParameterError(
            f"--out {text}: unsupported figure format {p.suffix or '(none)'!r}; use "
            + ", ".join(FIGURE_FORMATS)
        )
    return p
