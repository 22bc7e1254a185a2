"""Spectral models rendered in colour: a model's spectrum projected to linear sRGB.

A fit of spectral data (Cornell's 31 wavelengths) is a model with 31 channels. The renderer's
lights are RGB, and an RGB light's white is sRGB's white, D65, so a spectral BRDF is shown as
the linear sRGB colour of its spectrum under the lights' spectrum (``illuminant``, D65 by
default): ``f_rgb = f_spectral @ M`` with ``M`` (n, 3) from CIE 1931 XYZ
(:func:`gonio.io.spectral.spectral_to_rgb_matrix`). The projection is linear, so the
rendered image equals the spectral rendering under a grey light of that spectrum followed by the
same projection; out-of-gamut colours are clipped at 0 per channel. Sampling and pdf are the
spectral model's own.
"""

from __future__ import annotations

from typing import Any, ClassVar

import jax.numpy as jnp
import numpy as np

from gonio.brdf.models._base import BRDFModel, BRDFSample
from gonio.io.spectral import spectral_to_rgb_matrix


class SpectralToRGB(BRDFModel):
    """``base`` (C spectral channels) seen as linear sRGB through the (C, 3) matrix ``matrix``.

    ``matrix`` is a tuple of C rows of 3 floats (static, hashable); build it with
    :func:`to_rgb`.
    """

    CHILDREN: ClassVar[tuple[str, ...]] = ("base",)
    STATIC: ClassVar[tuple[str, ...]] = ("matrix",)

    def __init__(self, base: BRDFModel, matrix: Any) -> None:
        m = tuple(tuple(float(x) for x in row) for row in np.asarray(matrix, dtype=float))
        object.__setattr__(self, "base", base)
        object.__setattr__(self, "matrix", m)
        self._set_params()

    @property
    def channels(self) -> int:
        return 3

    @property
    def is_delta(self) -> bool:  # type: ignore[override]
        return self.base.is_delta

    @property
    def has_delta(self) -> bool:
        return self.base.has_delta

    def _project(self, x: Any) -> Any:
        m = jnp.asarray(self.matrix, dtype=jnp.result_type(x))
        return jnp.maximum(x @ m, 0.0)

    def f(self, wi: Any, wo: Any) -> Any:
        return self._project(self.base.f(wi, wo))

    def pdf(self, wi: Any, wo: Any) -> Any:
        return self.base.pdf(wi, wo)

    def sample(self, wo: Any, u: Any) -> BRDFSample:
        s = self.base.sample(wo, u)
        return BRDFSample(s.wi, s.pdf, self._project(s.weight), s.delta)

    def sampling_weight(self, wo: Any) -> Any:
        return self.base.sampling_weight(wo)


def to_rgb(model: Any, wavelengths_nm: Any, illuminant: str = "D65") -> SpectralToRGB:
    """``model`` (one channel per wavelength in ``wavelengths_nm``) as an RGB model."""
    return SpectralToRGB(model, spectral_to_rgb_matrix(wavelengths_nm, illuminant))


__all__ = ["SpectralToRGB", "to_rgb"]
