"""A lobe multiplied by a (per-channel) scale: ``Scaled(TorranceSparrow(...), scale=[...])``.

Some published parameterizations put a free reflectance factor in front of a lobe that has none
in our form (bbm's ``scaledmodel``, e.g. Ngan et al.'s Cook-Torrance ``albedo``); this wrapper
expresses them exactly and keeps the factor fittable.
"""

from __future__ import annotations

import jax.numpy as jnp

from gonio.brdf.models._base import BRDFModel, Param, channel_mean
from gonio.errors import ParameterError

Array = jnp.ndarray


class Scaled(BRDFModel):
    """``f = scale * lobe.f``; sampling and pdf are the lobe's (a constant factor does not change
    the shape), ``sampling_weight`` is scaled so that mixtures stay proportional to albedo.

    Parameters
    ----------
    lobe : any non-delta BRDF model (its parameters appear as ``"lobe.<name>"``).
    scale : non-negative factor, scalar or per channel (dimensionless).
    """

    PARAMS = (
        Param("scale", 1.0, 0.0, 1e3, "1", per_channel=True, scale="log",
              doc="factor multiplying the lobe"),
    )  # fmt: skip
    CHILDREN = ("lobe",)

    def __init__(self, lobe: BRDFModel | None = None, scale: Array | float = 1.0) -> None:
        if not isinstance(lobe, BRDFModel) or lobe.is_delta:
            raise ParameterError(f"Scaled: lobe must be a non-delta BRDF model, got {lobe!r}")
        object.__setattr__(self, "lobe", lobe)
        self._set_params(scale=scale)
        _ = self.channels  # validates channel agreement

    def _f(self, wi: Array, wo: Array) -> Array:
        return jnp.atleast_1d(self.scale).astype(wi.dtype) * self.lobe._f(wi, wo)

    def _pdf(self, wi: Array, wo: Array) -> Array:
        return self.lobe._pdf(wi, wo)

    def _sample(self, wo: Array, u: Array) -> Array:
        return self.lobe._sample(wo, u)

    def sampling_weight(self, wo: Array) -> Array:
        return channel_mean(self.scale).astype(wo.dtype) * self.lobe.sampling_weight(wo)
