"""DNG raw files: a minimal, standard-conforming writer and a reader through rawpy (LibRaw).

The writer produces a single-IFD, uncompressed Bayer DNG (version 1.4) with the tags a raw
decoder needs: CFA layout, black and white level, a colour matrix, exposure time, and gonio's
own metadata (joint angles, pose, seed) as JSON in ``ImageDescription``. tifffile does the TIFF
container; we only choose the tags. Reading goes through rawpy so that the simulated camera's
files take exactly the path a real camera's files take.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gonio.errors import FormatError
from gonio.io.atomic import atomic_output
from gonio.io.strict_json import dumps_json

#: DNG CFAPattern codes: 0 red, 1 green, 2 blue.
_CFA_CODES = {"R": 0, "G": 1, "B": 2}
_CODE_NAMES = {0: "R", 1: "G", 2: "B", 3: "G"}


@dataclass(frozen=True)
class RawFrame:
    """One decoded raw exposure.

    Attributes
    ----------
    data : (H, W) uint16 raw sensor values in DN, Bayer mosaic, visible area only.
    cfa : 2x2 tuple of "R"/"G"/"B" giving the colour of each site of the repeating tile
        (row-major; ``cfa[0][0]`` is the top-left pixel).
    black_level : DN offset of a pixel that received no light (per CFA site, shape (2, 2)).
    white_level : DN at which the sensor or ADC saturates.
    exposure_s : exposure time from the file's metadata, seconds.
    meta : gonio metadata stored with the frame (decoded JSON, or empty).
    """

    data: np.ndarray
    cfa: tuple[tuple[str, str], tuple[str, str]]
    black_level: np.ndarray
    white_level: int
    exposure_s: float
    meta: dict[str, Any] = field(default_factory=dict)

    def channel_masks(self) -> dict[str, np.ndarray]:
        """Boolean (H, W) masks of the R, G and B sites."""
        h, w = self.data.shape
        rows = np.arange(h)[:, None] % 2
        cols = np.arange(w)[None, :] % 2
        out = {c: np.zeros((h, w), dtype=bool) for c in "RGB"}
        for i in range(2):
            for j in range(2):
                out[self.cfa[i][j]] |= (rows == i) & (cols == j)
        return out

    def black_map(self) -> np.ndarray:
        """Black level of every pixel, (H, W) float64."""
        h, w = self.data.shape
        tile = np.asarray(self.black_level, dtype=np.float64).reshape(2, 2)
        return np.tile(tile, ((h + 1) // 2, (w + 1) // 2))[:h, :w]


def write_dng(
    path: str | os.PathLike[str],
    data: np.ndarray,
    *,
    exposure_s: float,
    black_level: int,
    white_level: int,
    cfa: str = "RGGB",
    iso: int = 100,
    meta: dict[str, Any] | None = None,
    camera_model: str = "gonio simulated camera",
) -> Path:
    """Write a Bayer mosaic as an uncompressed DNG, atomically.

    Parameters
    ----------
    path : destination; written to a temporary file in the same folder, then renamed.
    data : (H, W) uint16 raw values in DN (H and W even).
    exposure_s : exposure time in seconds (stored as a rational).
    black_level, white_level : DN of no light and of saturation.
    cfa : four letters for the 2x2 tile, row-major (default RGGB).
    iso : ISO speed rating stored in the EXIF-style tag.
    meta : JSON-serializable dictionary stored in ImageDescription.
    """
    import tifffile

    data = np.asarray(data)
    if data.ndim != 2 or data.dtype != np.uint16:
        raise FormatError(
            f"{path}: DNG data must be a 2-D uint16 mosaic, got {data.dtype} {data.shape}"
        )
    if data.shape[0] % 2 or data.shape[1] % 2:
        raise FormatError(f"{path}: DNG mosaic dimensions must be even, got {data.shape}")
    if len(cfa) != 4 or any(c not in _CFA_CODES for c in cfa):
        raise FormatError(f"{path}: CFA pattern must be four of R/G/B, got {cfa!r}")
    if not (0 <= black_level < white_level <= 65535):
        raise FormatError(f"{path}: need 0 <= black_level < white_level <= 65535")
    num, den = _rational(exposure_s)
    identity = (1, 1, 0, 1, 0, 1, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1, 1, 1)
    extratags = [
        (50706, "B", 4, (1, 4, 0, 0), True),  # DNGVersion
        (50707, "B", 4, (1, 4, 0, 0), True),  # DNGBackwardVersion
        (50708, "s", 0, camera_model, True),  # UniqueCameraModel
        (33421, "H", 2, (2, 2), True),  # CFARepeatPatternDim
        (33422, "B", 4, tuple(_CFA_CODES[c] for c in cfa), True),  # CFAPattern
        (50710, "B", 3, (0, 1, 2), True),  # CFAPlaneColor
        (50711, "H", 1, 1, True),  # CFALayout: rectangular
        (50714, "H", 1, int(black_level), True),  # BlackLevel
        (50717, "H", 1, int(white_level), True),  # WhiteLevel
        (50721, "2i", 9, identity, True),  # ColorMatrix1 (linear camera = XYZ-ish identity)
        (50728, "2I", 3, (1, 1, 1, 1, 1, 1), True),  # AsShotNeutral
        (50778, "H", 1, 21, True),  # CalibrationIlluminant1: D65
        (33434, "2I", 1, (num, den), True),  # ExposureTime
        (34855, "H", 1, int(iso), True),  # ISOSpeedRatings
    ]
    description = dumps_json(meta or {}, sort_keys=True)
    path = Path(path)
    with atomic_output(path) as tmp:
        tifffile.imwrite(
            tmp,
            data,
            photometric=32803,  # CFA
            subfiletype=0,
            description=description,
            metadata=None,
            software="gonio",
            extratags=extratags,
        )
    return path


def read_dng(path: str | os.PathLike[str]) -> RawFrame:
    """Decode a raw file with rawpy (LibRaw) in linear, unprocessed form.

    Raises FormatError when the file is missing, unreadable or not a Bayer raw.
    """
    import rawpy

    path = Path(path)
    if not path.is_file():
        raise FormatError(f"{path}: not a file")
    try:
        with rawpy.imread(str(path)) as raw:
            data = np.array(raw.raw_image_visible, dtype=np.uint16, copy=True)
            pattern = np.asarray(raw.raw_pattern)
            desc = raw.color_desc.decode("ascii", "replace")
            black = np.asarray(raw.black_level_per_channel, dtype=np.float64)
            white = int(raw.white_level)
    except (rawpy.LibRawError, OSError, ValueError) as exc:
        raise FormatError(f"{path}: cannot decode raw file ({type(exc).__name__}: {exc})") from None
    if pattern is None or pattern.shape != (2, 2):
        raise FormatError(f"{path}: not a 2x2 Bayer raw file")
    cfa = tuple(tuple(desc[int(pattern[i, j])] for j in range(2)) for i in range(2))
    black_tile = np.array([[black[int(pattern[i, j])] for j in range(2)] for i in range(2)])
    exposure, meta = _read_tiff_metadata(path)
    return RawFrame(data, cfa, black_tile, white, exposure, meta)  # type: ignore[arg-type]


def _read_tiff_metadata(path: Path) -> tuple[float, dict[str, Any]]:
    """Exposure time and gonio's JSON description from the TIFF tags (not executed, parsed)."""
    import tifffile

    try:
        with tifffile.TiffFile(path) as tif:
            tags = tif.pages[0].tags
            exp = tags.get(33434)
            exposure = float("nan") if exp is None else float(exp.value[0]) / float(exp.value[1])
            desc = tags.get(270)
            text = desc.value if desc is not None else ""
    except (tifffile.TiffFileError, OSError, ValueError, ZeroDivisionError) as exc:
        raise FormatError(f"{path}: unreadable TIFF metadata ({exc})") from None
    try:
        meta = json.loads(text) if text else {}
    except json.JSONDecodeError:
        meta = {"description": text}
    if not isinstance(meta, dict):
        meta = {"description": meta}
    return exposure, meta


def _rational(x: float, max_den: int = 1_000_000_000) -> tuple[int, int]:
    from fractions import Fraction

    if not (x > 0 and np.isfinite(x)):
        raise FormatError(f"exposure time must be positive and finite, got {x}")
    f = Fraction(x).limit_denominator(max_den)
    num, den = f.numerator, f.denominator
    while num > 0xFFFFFFFF or den > 0xFFFFFFFF:
        num //= 2
        den //= 2
    return max(num, 1), max(den, 1)
