"""Fit metrics, each written as a sum of squared residuals so every optimizer can use it.

Notation: ``y`` measured and ``f`` fitted BRDF value (sr^-1) of sample n and channel c;
``sigma`` the per-value standard deviation; ``w`` the quadrature weight of the sample (the
solid-angle measure of its cell, 1 for scattered samples); ``W = sum_n w_n``; ``C`` channels;
``cos_i`` the cosine of the incident polar angle. Every loss is ``L = sum_{n,c} r_nc^2`` and the
number reported for it (``value``) is stated next to the formula.

``wls`` (weighted least squares, the statistical default)
    ``r = (f - y) / sigma`` (``sigma = 1`` when the data has none); value ``L`` = chi^2.
``ngan`` (Ngan, Durand & Matusik 2005, cosine-weighted L2 with solid-angle weights)
    ``r = sqrt(w / (C W)) (f - y) cos_i``; value ``sqrt(L)``, the weighted RMS in sr^-1.
``low-e1`` (Löw, Kronander, Ynnerman & Unger 2012, log metric with the cosine)
    ``r = sqrt(w / (C W)) [ln(1 + f cos_i) - ln(1 + y cos_i)]``; value ``sqrt(L)``.
``low-e2`` (the same without the cosine)
    ``r = sqrt(w / (C W)) [ln(1 + f) - ln(1 + y)]``; value ``sqrt(L)``.
``cube-root`` (compresses the specular peak, as in later fitting studies)
    ``r = sqrt(w / (C W)) [cbrt(f + eps) - cbrt(y + eps)]`` with ``eps = 1e-6`` sr^-1, which
    keeps the derivative finite where the model is 0; value ``sqrt(L)``.

Measured values slightly below zero (noise) are kept as measured; inside the logarithms they are
clamped so that ``1 + y cos_i >= 0.1``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from gonio.errors import FitError
from gonio.fit.data import FitData

Array = jnp.ndarray

_EPS_CBRT = 1e-6
_LOG_FLOOR = 0.1


@dataclass(frozen=True)
class Loss:
    """A selectable metric.

    Attributes
    ----------
    name : key used by ``fit(loss=...)`` and the CLI.
    value_kind : ``"chi2"`` (value = L) or ``"rms"`` (value = sqrt(L)).
    statistical : True when the residuals are standardized by the data's sigma, so that
        L is a chi-square and a Gaussian likelihood follows directly.
    doc : the formula in one line.
    """

    name: str
    value_kind: str
    statistical: bool
    doc: str
    _residual: Callable[[Array, dict[str, Array]], Array]

    def constants(self, data: FitData) -> dict[str, np.ndarray]:
        """Per-sample constants the residual needs, as float64 NumPy arrays."""
        n, c = data.values.shape
        y = data.values
        w = data.weights
        scale = np.sqrt(w / (c * w.sum()))[:, None]
        cos_i = data.wi[:, 2:3]
        inv_sigma = np.ones_like(y) if data.sigma is None else 1.0 / data.sigma
        return {
            "y": y,
            "inv_sigma": inv_sigma,
            "scale": np.broadcast_to(scale, (n, 1)).copy(),
            "cos_i": cos_i.copy(),
            "log_y_cos": np.log(np.maximum(1.0 + y * cos_i, _LOG_FLOOR)),
            "log_y": np.log(np.maximum(1.0 + y, _LOG_FLOOR)),
            "cbrt_y": np.cbrt(y + _EPS_CBRT),
        }

    def residual(self, f: Array, k: dict[str, Array]) -> Array:
        """Residuals ``(N, C)`` for model values ``f`` ``(N, C or 1)`` and constants ``k``."""
        f = jnp.broadcast_to(f, k["y"].shape)
        return self._residual(f, k)

    def value(self, sum_sq: float) -> float:
        """The reported number for ``L = sum r^2``."""
        return float(sum_sq) if self.value_kind == "chi2" else float(np.sqrt(max(sum_sq, 0.0)))


def _wls(f: Array, k: dict[str, Array]) -> Array:
    return (f - k["y"]) * k["inv_sigma"]


def _ngan(f: Array, k: dict[str, Array]) -> Array:
    return k["scale"] * (f - k["y"]) * k["cos_i"]


def _low_e1(f: Array, k: dict[str, Array]) -> Array:
    lf = jnp.log(jnp.maximum(1.0 + f * k["cos_i"], _LOG_FLOOR))
    return k["scale"] * (lf - k["log_y_cos"])


def _low_e2(f: Array, k: dict[str, Array]) -> Array:
    lf = jnp.log(jnp.maximum(1.0 + f, _LOG_FLOOR))
    return k["scale"] * (lf - k["log_y"])


def _cube_root(f: Array, k: dict[str, Array]) -> Array:
    return k["scale"] * (jnp.cbrt(jnp.maximum(f, 0.0) + _EPS_CBRT) - k["cbrt_y"])


LOSSES: dict[str, Loss] = {
    "wls": Loss("wls", "chi2", True, "sum ((f - y) / sigma)^2; sigma = 1 when absent", _wls),
    "ngan": Loss("ngan", "rms", False, "sqrt(sum w ((f - y) cos_i)^2 / (C W))", _ngan),
    "low-e1": Loss(
        "low-e1", "rms", False, "sqrt(sum w (ln(1+f cos_i) - ln(1+y cos_i))^2 / (C W))", _low_e1
    ),
    "low-e2": Loss("low-e2", "rms", False, "sqrt(sum w (ln(1+f) - ln(1+y))^2 / (C W))", _low_e2),
    "cube-root": Loss(
        "cube-root", "rms", False, "sqrt(sum w (cbrt(f+eps) - cbrt(y+eps))^2 / (C W))", _cube_root
    ),
}


def get_loss(name: str | Loss) -> Loss:
    """Look a loss up by name; FitError listing the valid names otherwise."""
    if isinstance(name, Loss):
        return name
    try:
        return LOSSES[name]
    except KeyError:
        raise FitError(f"unknown loss {name!r}; valid: {', '.join(LOSSES)}") from None


def evaluate(loss: str | Loss, f: np.ndarray, data: FitData) -> float:
    """The reported value of ``loss`` for model values ``f`` (N, C) on ``data``."""
    lo = get_loss(loss)
    k = {key: jnp.asarray(v) for key, v in lo.constants(data).items()}
    r = np.asarray(lo.residual(jnp.asarray(f), k))
    return lo.value(float(np.sum(r * r)))
