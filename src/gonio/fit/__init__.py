"""Fitting analytic BRDF models to measured data, with uncertainty.

>>> from gonio import fit
>>> result = fit.fit(table, model="lambert+ward", loss="wls", uncertainty="laplace")
>>> result.save("ward.json"); model = fit.load_model("ward.json")
>>> fit.fit(table, "lambert+cook-torrance", options=fit.FitOptions(loss="ngan", n_starts=16))
>>> from gonio.fit.score import score; score(model, table)   # {"ngan": ..., "low-e2": ...}

Modules: :mod:`~gonio.fit.data` (flatten and mask input), :mod:`~gonio.fit.losses` (metrics),
:mod:`~gonio.fit.params` (reparameterization), :mod:`~gonio.fit.objective` (compiled
objective), :mod:`~gonio.fit.lm` and :mod:`~gonio.fit.optimize` (optimizers),
:mod:`~gonio.fit.uncertainty` (Laplace, MCMC), :mod:`~gonio.fit.compare` (model comparison),
:mod:`~gonio.fit.result` (JSON), :mod:`~gonio.fit.plots`, :mod:`~gonio.fit.batch`,
:mod:`~gonio.fit.score` (the literature's metrics on any model), :mod:`~gonio.fit.presets`
(model names; ``FAMILIES`` lists the literature's families as published).
"""

import gonio.brdf  # noqa: F401  (enables float64 in JAX before anything is traced)
from gonio.fit.api import FitOptions, fit
from gonio.fit.data import FitData, prepare
from gonio.fit.losses import LOSSES
from gonio.fit.presets import available as available_models
from gonio.fit.result import FitResult, load_model, read_result

__all__ = [
    "LOSSES",
    "FitData",
    "FitOptions",
    "FitResult",
    "available_models",
    "fit",
    "load_model",
    "prepare",
    "read_result",
]
