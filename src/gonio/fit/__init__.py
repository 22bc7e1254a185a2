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
:mod:`~gonio.fit.result` (the result record; its file format is :mod:`gonio.io.fit_result`),
:mod:`~gonio.fit.plots`, :mod:`~gonio.fit.batch`,
:mod:`~gonio.fit.score` (the literature's metrics on any model), :mod:`~gonio.fit.presets`
(model names; ``FAMILIES`` lists the literature's families as published).
"""

from importlib import import_module
from typing import Any

# The names below are loaded on first use (PEP 562), so that ``gonio fit --help`` and the
# command-line parser do not import JAX, the largest part of their start-up
# (benchmarks/bench_startup.py). gonio.fit.api
# imports gonio.brdf, which enables float64 in JAX before anything is traced.
_LAZY = {
    "FitOptions": ("gonio.fit.api", "FitOptions"),
    "fit": ("gonio.fit.api", "fit"),
    "FitData": ("gonio.fit.data", "FitData"),
    "prepare": ("gonio.fit.data", "prepare"),
    "LOSSES": ("gonio.fit.losses", "LOSSES"),
    "available_models": ("gonio.fit.presets", "available"),
    "FitResult": ("gonio.fit.result", "FitResult"),
    "load_model": ("gonio.io.fit_result", "load_model"),
    "read_result": ("gonio.io.fit_result", "read_result"),
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        module, attr = _LAZY[name]
        import gonio.brdf  # noqa: F401  (float64 in JAX before anything is traced)

        value = getattr(import_module(module), attr)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'gonio.fit' has no attribute {name!r}")


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
