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
``sqrt-cos`` (tracks appearance: what a sphere image shows, square-rooted)
    ``r = sqrt(w / (C W)) [sqrt(f cos_i + eps) - sqrt(y cos_i + eps)]`` with ``eps = 1e-4``
    sr^-1; value ``sqrt(L)``. A pixel of a lit sphere is ``f cos_i``; for a relative error ``e``
    of a cell whose pixel value is ``p = y cos_i``, ``r^2 ~ w e^2 p / 4``: errors weigh in
    proportion to the brightness they are seen at, as in the relative L1 of a rendered image,
    where ``low-e1`` weighs a dark grazing cell's relative error as much as the highlight's and
    ``ngan`` (L2) lets the peak alone decide.
``cube-root`` (compresses the specular peak, as in later fitting studies)
    ``r = sqrt(w / (C W)) [cbrt(f + eps) - cbrt(y + eps)]`` with ``eps = 1e-6`` sr^-1, which
    keeps the derivative finite where the model is 0; value ``sqrt(L)``.

Measured values slightly below zero (noise) are kept as measured; inside the logarithms they are
clamped so that ``1 + y cos_i >= 0.1``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import jax.numpy as jnp
import numpy as np

from gonio.errors import FitError
from gonio.fit.data import FitData

Array = jnp.ndarray

_EPS_CBRT = 1e-6
_EPS_SQRT = 1e-4
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
    needs : names of the per-sample constants the residual uses.
    """

    name: str
    value_kind: str
    statistical: bool
    doc: str
    _residual: Callable[[Any, dict[str, Any], Any], Any]
    needs: tuple[str, ...]

    def constants(self, data: FitData) -> dict[str, np.ndarray]:
        """Per-sample constants the residual needs, as float64 NumPy arrays."""
        return _constants(self.needs, data.values, data.sigma, data.weights, data.wi[:, 2:3], np)

    def residual(self, f: Array, k: dict[str, Array]) -> Array:
        """Residuals ``(N, C)`` for model values ``f`` ``(N, C or 1)`` and constants ``k`` (JAX)."""
        f = jnp.broadcast_to(f, k["y"].shape)
        return self._residual(f, k, jnp)

    def residual_np(self, f: np.ndarray, k: dict[str, np.ndarray]) -> np.ndarray:
        """The same in NumPy (for reporting without tracing or device transfers)."""
        f = np.broadcast_to(f, k["y"].shape)
        return self._residual(f, k, np)

    def value(self, sum_sq: float) -> float:
        """The reported number for ``L = sum r^2``."""
        return float(sum_sq) if self.value_kind == "chi2" else float(np.sqrt(max(sum_sq, 0.0)))


def _constants(
    needs: tuple[str, ...], y: Any, sigma: Any, w: Any, cos_i: Any, xp: Any
) -> dict[str, Any]:
    """The constants named in ``needs`` from values ``y`` (N, C), ``sigma`` (N, C) or None,
    weights ``w`` (N,) and ``cos_i`` (N, 1), with array module ``xp`` (NumPy or jax.numpy)."""
    out: dict[str, Any] = {"y": y}
    for key in needs:
        if key == "inv_sigma":
            out[key] = xp.ones_like(y) if sigma is None else 1.0 / sigma
        elif key == "scale":
            out[key] = xp.sqrt(w / (y.shape[1] * w.sum()))[:, None]
        elif key == "cos_i":
            out[key] = np.ascontiguousarray(cos_i) if xp is np else xp.asarray(cos_i)
        elif key == "log_y_cos":
            out[key] = xp.log(xp.maximum(1.0 + y * cos_i, _LOG_FLOOR))
        elif key == "log_y":
            out[key] = xp.log(xp.maximum(1.0 + y, _LOG_FLOOR))
        elif key == "cbrt_y":
            out[key] = xp.cbrt(y + _EPS_CBRT)
        elif key == "sqrt_y_cos":
            out[key] = xp.sqrt(xp.maximum(y * cos_i, 0.0) + _EPS_SQRT)
    return out


def data_constants(needs: tuple[str, ...], data: FitData) -> dict[str, np.ndarray]:
    """The constants named in ``needs`` for every sample of ``data``, float64 NumPy (N, C)
    or (N, 1); ``scale`` normalized by the data's total weight."""
    return _constants(needs, data.values, data.sigma, data.weights, data.wi[:, 2:3], np)


def constants_of(
    needs: tuple[str, ...], y: Any, inv_sigma: Any, w: Any, cos_i: Any, skip: tuple[str, ...] = ()
) -> dict[str, Any]:
    """The constants named in ``needs`` for one chunk of samples (JAX), with ``scale`` left
    unnormalized: ``sqrt(w)`` instead of ``sqrt(w / (C W))``, so that a loss's sum of squares
    over the chunks is ``C W`` times its own (the caller divides; the chunked score pass of
    :meth:`gonio.fit.objective.Problem.scores`).

    ``y`` ``(N, C)``; ``inv_sigma`` ``1 / sigma`` ``(N, C)`` or None (then 1); ``w`` the
    weights ``(N, 1)``; ``cos_i`` ``(N, 1)``; ``skip``: constants the caller already has.
    """
    rest = tuple(n for n in needs if n not in ("inv_sigma", "scale", *skip))
    k = _constants(rest, y, None, w[..., 0], cos_i, jnp)
    if "inv_sigma" in needs:
        k["inv_sigma"] = jnp.ones_like(y) if inv_sigma is None else inv_sigma
    if "scale" in needs:
        k["scale"] = jnp.sqrt(w)
    return k


def _wls(f: Any, k: dict[str, Any], xp: Any) -> Any:
    return (f - k["y"]) * k["inv_sigma"]


def _ngan(f: Any, k: dict[str, Any], xp: Any) -> Any:
    return k["scale"] * (f - k["y"]) * k["cos_i"]


def _low_e1(f: Any, k: dict[str, Any], xp: Any) -> Any:
    lf = xp.log(xp.maximum(1.0 + f * k["cos_i"], _LOG_FLOOR))
    return k["scale"] * (lf - k["log_y_cos"])


def _low_e2(f: Any, k: dict[str, Any], xp: Any) -> Any:
    lf = xp.log(xp.maximum(1.0 + f, _LOG_FLOOR))
    return k["scale"] * (lf - k["log_y"])


def _sqrt_cos(f: Any, k: dict[str, Any], xp: Any) -> Any:
    return k["scale"] * (xp.sqrt(xp.maximum(f * k["cos_i"], 0.0) + _EPS_SQRT) - k["sqrt_y_cos"])


def _cube_root(f: Any, k: dict[str, Any], xp: Any) -> Any:
    # exp(ln(x) / 3) for x > 0: equal to cbrt to 1e-15 and much cheaper than XLA's float64 cbrt
    return k["scale"] * (xp.exp(xp.log(xp.maximum(f, 0.0) + _EPS_CBRT) / 3.0) - k["cbrt_y"])


LOSSES: dict[str, Loss] = {
    "wls": Loss(
        "wls", "chi2", True, "sum ((f - y) / sigma)^2; sigma = 1 when absent", _wls,
        ("inv_sigma",),
    ),
    "ngan": Loss(
        "ngan", "rms", False, "sqrt(sum w ((f - y) cos_i)^2 / (C W))", _ngan, ("scale", "cos_i")
    ),
    "low-e1": Loss(
        "low-e1", "rms", False, "sqrt(sum w (ln(1+f cos_i) - ln(1+y cos_i))^2 / (C W))", _low_e1,
        ("scale", "cos_i", "log_y_cos"),
    ),
    "low-e2": Loss(
        "low-e2", "rms", False, "sqrt(sum w (ln(1+f) - ln(1+y))^2 / (C W))", _low_e2,
        ("scale", "log_y"),
    ),
    "sqrt-cos": Loss(
        "sqrt-cos", "rms", False, "sqrt(sum w (sqrt(f cos_i+eps) - sqrt(y cos_i+eps))^2 / (C W))",
        _sqrt_cos, ("scale", "cos_i", "sqrt_y_cos"),
    ),
    "cube-root": Loss(
        "cube-root", "rms", False, "sqrt(sum w (cbrt(f+eps) - cbrt(y+eps))^2 / (C W))",
        _cube_root, ("scale", "cbrt_y"),
    ),
}  # fmt: skip


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
    r = lo.residual_np(np.asarray(f, dtype=np.float64), lo.constants(data))
    return lo.value(float(np.sum(r * r)))


#: Data at least this large is scored by one compiled pass (:func:`evaluate_many`); smaller data
#: by NumPy (no compilation per data size).
_JIT_MIN_VALUES = 1 << 18


def _sums(names: tuple[str, ...], f: Any, y: Any, sigma: Any, w: Any, cos_i: Any) -> Any:
    needs = tuple(dict.fromkeys(n for name in names for n in LOSSES[name].needs))
    k = _constants(needs, y, sigma, w, cos_i, jnp)
    f = jnp.broadcast_to(f, y.shape)
    return [jnp.sum(LOSSES[name]._residual(f, k, jnp) ** 2) for name in names]


_SUMS_JIT: list[Any] = []


def evaluate_many(names: Any, f: np.ndarray, data: FitData) -> dict[str, float]:
    """``{name: evaluate(name, f, data)}`` for several losses at once.

    On large data (a MERL table: 2.7e6 values) the losses are summed by one compiled pass
    (float64, the same formulas) instead of several NumPy passes each, which made the reported
    metrics a sizeable share of a whole fit."""
    names = tuple(get_loss(n).name for n in names)
    f = np.asarray(f, dtype=np.float64)
    if data.values.size < _JIT_MIN_VALUES:
        return {n: evaluate(n, f, data) for n in names}
    if not _SUMS_JIT:
        import jax

        _SUMS_JIT.append(jax.jit(_sums, static_argnums=0))
    sums = _SUMS_JIT[0](names, f, data.values, data.sigma, data.weights, data.wi[:, 2:3])
    return {n: LOSSES[n].value(float(v)) for n, v in zip(names, sums, strict=True)}
