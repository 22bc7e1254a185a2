"""The record every material's ``sample(wo, u)`` returns (:class:`BRDFSample`)."""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp

Array = jnp.ndarray


class BRDFSample(NamedTuple):
    """Result of ``sample(wo, u)``.

    Attributes
    ----------
    wi : (..., 3) sampled incident direction (toward the light).
    pdf : (...) its density per unit solid angle; for a delta lobe, the discrete probability of
        having chosen it. 0 marks a failed sample (then ``weight`` is 0 too).
    weight : (..., C) ``f(wi, wo) cos(theta_i) / pdf`` (for delta lobes, the lobe's reflectance
        divided by its selection probability).
    delta : (...) bool, True where ``wi`` came from a delta lobe and must not be evaluated as a
        density (``f`` and ``pdf`` of a delta lobe are 0 for every given pair of directions).
    """

    wi: Array
    pdf: Array
    weight: Array
    delta: Array


__all__ = ["BRDFSample"]
