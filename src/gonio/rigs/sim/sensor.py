"""Simulated image sensor: Bayer mosaic, shot/read/dark noise, black level, quantization, clipping.

Units: the input is the expected photo-electron *rate* per pixel in e-/s for each colour plane
(what the optics deliver after quantum efficiency). The output is raw DN as a sensor's ADC would
produce them. The noise model is the standard one of EMVA 1288:

    e   ~ Poisson((rate + dark_current) * t)       electrons, clipped at the full-well capacity
    DN  = round(gain * (e + N(0, read_noise^2))) + black_level, clipped to [0, 2^bits - 1]

so a pixel's DN variance is ``gain^2 (mean_e + read_noise^2) + 1/12``. The same (seed, frame key)
always gives the same frame.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from gonio.errors import ParameterError


@dataclass(frozen=True)
class SensorModel:
    """Parameters of the simulated sensor (defaults: a 14-bit CMOS machine-vision sensor).

    Attributes
    ----------
    gain : conversion gain, DN per electron.
    read_noise : read noise, electrons RMS.
    dark_current : electrons per second per pixel.
    full_well : saturation capacity, electrons.
    black_level : DN offset added to every pixel.
    bits : ADC bit depth (12 to 16).
    cfa : Bayer tile, row-major, e.g. "RGGB".
    shutter_error : relative standard deviation of the actual exposure time around the nominal
        one (real mechanical and rolling shutters are not exact; the HDR merge estimates ratios
        from the data).
    """

    gain: float = 0.25
    read_noise: float = 3.0
    dark_current: float = 2.0
    full_well: float = 60000.0
    black_level: int = 512
    bits: int = 14
    cfa: str = "RGGB"
    shutter_error: float = 0.0

    def __post_init__(self) -> None:
        if not 8 <= self.bits <= 16:
            raise ParameterError(f"sensor bits must be in [8, 16], got {self.bits}")
        if self.gain <= 0 or self.full_well <= 0 or self.read_noise < 0 or self.dark_current < 0:
            raise ParameterError("sensor gain, full well must be > 0; noise and dark current >= 0")
        if sorted(self.cfa) != sorted("RGGB") and sorted(self.cfa) != sorted("GBRG"):
            raise ParameterError(f"sensor cfa must be a Bayer tile, got {self.cfa!r}")

    @property
    def white_level(self) -> int:
        """DN at which a pixel saturates (full well or ADC range, whichever comes first)."""
        adc_max = (1 << self.bits) - 1
        return int(min(adc_max, self.black_level + np.floor(self.gain * self.full_well)))

    def plane_index(self, shape: tuple[int, int]) -> np.ndarray:
        """(H, W) int array: 0 for R, 1 for G, 2 for B sites of the mosaic."""
        codes = {"R": 0, "G": 1, "B": 2}
        tile = np.array([[codes[self.cfa[0]], codes[self.cfa[1]]],
                         [codes[self.cfa[2]], codes[self.cfa[3]]]])  # fmt: skip
        h, w = shape
        return np.tile(tile, ((h + 1) // 2, (w + 1) // 2))[:h, :w]

    def mosaic(self, rgb_rate: np.ndarray) -> np.ndarray:
        """Pick each pixel's colour plane: (H, W, 3) e-/s -> (H, W) e-/s."""
        idx = self.plane_index(rgb_rate.shape[:2])
        return np.take_along_axis(rgb_rate, idx[..., None], axis=-1)[..., 0]

    def dn_variance(self, mean_electrons: np.ndarray) -> np.ndarray:
        """Predicted DN variance for a mean signal (signal + dark electrons), before clipping."""
        return self.gain**2 * (np.maximum(mean_electrons, 0.0) + self.read_noise**2) + 1.0 / 12.0

    def expose(
        self, rate: np.ndarray, exposure_s: float, seed: int, key: str = ""
    ) -> tuple[np.ndarray, float]:
        """Simulate one exposure.

        Parameters
        ----------
        rate : (H, W) e-/s per pixel (already mosaicked) or (H, W, 3) per colour plane.
        exposure_s : nominal exposure time, seconds.
        seed, key : the frame's random stream is derived from both, so the same (seed, key)
            always gives the same DN.

        Returns
        -------
        dn : (H, W) uint16 raw values.
        actual_s : the exposure time the shutter really gave (differs from nominal by
            ``shutter_error``).
        """
        rate = np.asarray(rate, dtype=np.float64)
        if rate.ndim == 3:
            rate = self.mosaic(rate)
        if rate.ndim != 2 or not np.all(np.isfinite(rate)) or np.any(rate < 0):
            raise ParameterError("sensor input must be a finite, non-negative (H, W) rate image")
        if not exposure_s > 0:
            raise ParameterError(f"exposure time must be positive, got {exposure_s}")
        rng = np.random.default_rng(_stream(seed, key, exposure_s))
        actual = exposure_s * (1.0 + self.shutter_error * rng.standard_normal())
        actual = max(actual, 1e-9)
        electrons = rng.poisson((rate + self.dark_current) * actual).astype(np.float64)
        electrons = np.minimum(electrons, self.full_well)
        analog = self.gain * (electrons + self.read_noise * rng.standard_normal(rate.shape))
        dn = np.rint(analog) + self.black_level
        dn = np.clip(dn, 0, min(self.white_level, (1 << self.bits) - 1))
        return dn.astype(np.uint16), actual


def _stream(seed: int, key: str, exposure_s: float) -> int:
    """A 64-bit seed from (seed, key, exposure) so each frame has its own reproducible noise."""
    h = hashlib.blake2b(f"{seed}|{key}|{exposure_s!r}".encode(), digest_size=8)
    return int.from_bytes(h.digest(), "little")
