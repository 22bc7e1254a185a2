"""Material priors: reconstruct a full table from a few samples, and choose which to measure.

>>> from gonio.prior import Prior, build_prior
>>> prior = build_prior([io.load(p) for p in paths], names)      # a library of materials
>>> prior.write("materials.prior.h5"); prior = Prior.read("materials.prior.h5")
>>> r = prior.reconstruct(wi, wo, values, sigma)    # (n, 3) directions, (n, C) values in 1/sr
>>> r.table, r.predicted_error                      # full isotropic table with sigma
>>> idx = prior.choose(cand_wi, cand_wo, 20)        # the 20 configurations to measure

The mapped space and grid are in :mod:`gonio.prior.space`, the model in
:mod:`gonio.prior.model`, the posterior in :mod:`gonio.prior.posterior`, the choice of
configurations in :mod:`gonio.prior.design`, the build in :mod:`gonio.prior.build`; the file
format is :mod:`gonio.io.prior_file`.
"""

from __future__ import annotations

from gonio.prior.build import build_prior
from gonio.prior.model import Observation, Prior
from gonio.prior.posterior import Measured, Reconstruction
from gonio.prior.space import EPSILON, prior_axes

__all__ = [
    "EPSILON",
    "Measured",
    "Observation",
    "Prior",
    "Reconstruction",
    "build_prior",
    "prior_axes",
]
