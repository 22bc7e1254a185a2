"""Lafortune et al. (1997) generalized cosine lobes, any number of lobes, plus a diffuse term.

Lafortune, Foo, Torrance, Greenberg, "Non-linear approximation of reflectance functions",
SIGGRAPH 1997. Each lobe is ``(Cx wi_x wo_x + Cy wi_y wo_y + Cz wi_z wo_z)^n`` (zero where the
bracket is negative); ``C = (-1, -1, 1)`` is a Phong lobe about the mirror direction, ``Cx = Cy >
0`` a retro-reflective lobe, ``|Cz| > |Cx|`` pushes the lobe towards grazing (off-specular peak).

Parameter layout (``Param.per_lobe``): ``cx``, ``cy``, ``cz`` and ``n`` are arrays of shape
``(L,)``, one entry per lobe; ``rho_s`` is ``(L,)`` or ``(L, C)`` (a lobe scale, per channel where
given); ``rho_d`` is a scalar or ``(C,)``. A 1-D ``rho_s`` of length L is per lobe; one lobe with
RGB scales is written ``rho_s=[[r, g, b]]`` (``[r, g, b]`` is also accepted when L = 1).

Fitting: a fitter that knows ``Param.per_lobe`` fits all lobes of one node. One that does not
(it treats non-per-channel parameters as scalars) can fit a single lobe, and several lobes as a
sum of single-lobe models, ``Lafortune(...) + Lafortune(..., rho_d=0)``: scalar lobe parameters
and a ``(C,)`` ``rho_s`` are accepted for that case.
"""

from __future__ import annotations

from typing import Literal

import jax.numpy as jnp
import numpy as np

from gonio.brdf import frames
from gonio.brdf.models._base import BRDFModel, Param, channel_mean, mixture_sample
from gonio.brdf.sampling import warps
from gonio.errors import ParameterError

Array = jnp.ndarray

#: Largest exponent of e a lobe may reach before it is clamped (keeps float32 finite when an
#: un-normalized lobe with |C| > 1 is raised to a large power).
_MAX_LOG = 80.0
_NORMALIZATIONS = ("normalized", "none")


class Lafortune(BRDFModel):
    """Sum of generalized cosine lobes plus a Lambertian term.

    ``f = rho_d / pi + sum_l rho_s[l] N_l max(0, Cx_l wi_x wo_x + Cy_l wi_y wo_y + Cz_l wi_z wo_z)
    ^ n_l`` with, per ``normalization``:

    ``"normalized"`` (default)
        ``N_l = (n_l + 2) / (2 pi max(|Cx_l|, |Cy_l|, |Cz_l|) ^ n_l)``: the normalization Ngan et
        al. (2005) used for their Lafortune fits (bbm's ``NganLafortune``), generalized to
        anisotropic lobes. The lobe's peak is then ``rho_s (n + 2) / (2 pi)`` as for the modified
        Phong lobe (``C = (-1, -1, 1)`` gives exactly ``Phong(rho_s, n)``), and ``rho_s`` is
        roughly the lobe's albedo, independent of ``|C|``.
    ``"none"``
        ``N_l = 1``: the original 1997 form, where ``|C|^n`` carries the lobe's magnitude
        (``rho_s = 1`` reproduces the paper's equation).

    Sampling: lobe ``l`` is drawn about its axis ``a_l = normalize(Cx_l wo_x, Cy_l wo_y, Cz_l
    wo_z)`` with the cosine-power density ``(n_l + 1) / (2 pi) cos^n_l`` (Lafortune & Willems
    1994), the diffuse term cosine-weighted; the lobe is chosen in proportion to an albedo
    estimate and the pdf is the exact mixture. Samples below the horizon are failed samples.

    Parameters
    ----------
    cx, cy, cz : (L,) lobe coefficients (dimensionless).
    n : (L,) lobe exponents, 0 to 1e5.
    rho_s : (L,) or (L, C) lobe scales (dimensionless).
    rho_d : diffuse albedo, scalar or (C,).
    normalization : ``"normalized"`` or ``"none"`` (see above).
    """

    PARAMS = (
        Param("cx", -1.0, -10.0, 10.0, "1", per_lobe=True, doc="lobe coefficient Cx"),
        Param("cy", -1.0, -10.0, 10.0, "1", per_lobe=True, doc="lobe coefficient Cy"),
        Param("cz", 1.0, -10.0, 10.0, "1", per_lobe=True, doc="lobe coefficient Cz"),
        Param("n", 20.0, 0.0, 1e5, "1", per_lobe=True, scale="log", doc="lobe exponent"),
        Param("rho_s", 0.5, 0.0, 100.0, "1", per_channel=True, per_lobe=True, scale="log",
              doc="lobe scale (about the lobe albedo when normalized)"),
        Param("rho_d", 0.0, 0.0, 1.0, "1", per_channel=True, scale="logit",
              doc="diffuse albedo"),
    )  # fmt: skip
    STATIC = ("normalization",)

    def __init__(
        self,
        cx: Array | float = -1.0,
        cy: Array | float = -1.0,
        cz: Array | float = 1.0,
        n: Array | float = 20.0,
        rho_s: Array | float = 0.5,
        rho_d: Array | float = 0.0,
        normalization: Literal["normalized", "none"] = "normalized",
    ) -> None:
        if normalization not in _NORMALIZATIONS:
            raise ParameterError(
                f"Lafortune: normalization must be one of {_NORMALIZATIONS}, got {normalization!r}"
            )
        object.__setattr__(self, "normalization", normalization)
        lobes = {"cx": cx, "cy": cy, "cz": cz, "n": n, "rho_s": rho_s}
        arrays = {}
        for key, value in lobes.items():
            try:
                arrays[key] = np.asarray(value, dtype=np.float64)
            except (TypeError, ValueError):
                raise ParameterError(f"Lafortune: {key} must be numeric, got {value!r}") from None
        counts = {a.shape[0] for a in arrays.values() if a.ndim >= 1}
        if len(counts) > 1:
            raise ParameterError(f"Lafortune: lobe parameters disagree on the lobe count {counts}")
        count = counts.pop() if counts else 1
        if count == 0:
            raise ParameterError("Lafortune: needs at least one lobe")
        for key, a in arrays.items():
            if a.ndim == 0:
                arrays[key] = np.full(count, float(a))
        self._set_params(**arrays, rho_d=rho_d)

    @property
    def lobe_count(self) -> int:
        """Number of lobes L."""
        return max(int(np.size(getattr(self, k))) for k in ("cx", "cy", "cz", "n"))

    # -- pieces ---------------------------------------------------------------------------------
    def _coeffs(self, dtype) -> tuple[Array, Array, Array, Array]:
        shape = (self.lobe_count,)
        return tuple(
            jnp.broadcast_to(jnp.asarray(getattr(self, k), dtype), shape)
            for k in ("cx", "cy", "cz", "n")
        )

    def _rho_s(self, dtype) -> Array:
        """``(L, C or 1)``. A 1-D value is per lobe, except for a single lobe, where a length
        other than 1 can only mean channels (as a generic fitter without per-lobe support
        passes it); a scalar applies to every lobe."""
        r = jnp.asarray(self.rho_s, dtype)
        count = self.lobe_count
        if r.ndim == 0:
            return jnp.broadcast_to(r, (count, 1))
        if r.ndim == 1:
            return r[None, :] if count == 1 and r.shape[0] != 1 else r[:, None]
        return r

    def _cmax(self, cx: Array, cy: Array, cz: Array) -> Array:
        m = jnp.maximum(jnp.maximum(jnp.abs(cx), jnp.abs(cy)), jnp.abs(cz))
        return jnp.maximum(m, 1e-30)

    def _powered(self, x: Array, n: Array) -> Array:
        """``max(x, 0) ** n`` with finite gradients (x, n broadcast)."""
        pos = x > 0
        logx = jnp.log(jnp.where(pos, x, 1.0))
        return jnp.where(pos, jnp.exp(jnp.minimum(n * logx, _MAX_LOG)), 0.0)

    def _lobes(self, wi: Array, wo: Array) -> Array:
        """Per-lobe values without ``rho_s``: ``(..., L)``."""
        cx, cy, cz, n = self._coeffs(wi.dtype)
        p = wi * wo
        x = cx * p[..., 0:1] + cy * p[..., 1:2] + cz * p[..., 2:3]
        if self.normalization == "normalized":
            x = x / self._cmax(cx, cy, cz)
            return (n + 2.0) / (2.0 * jnp.pi) * self._powered(x, n)
        return self._powered(x, n)

    def _axes(self, wo: Array) -> tuple[Array, Array]:
        """Lobe axes ``(..., L, 3)`` and the length of ``C * wo`` ``(..., L)``."""
        cx, cy, cz, _ = self._coeffs(wo.dtype)
        c = jnp.stack([cx, cy, cz], -1)  # (L, 3)
        v = c * wo[..., None, :]
        length = frames.safe_sqrt(jnp.sum(v * v, -1))
        return frames.normalize(v), length

    def _weights(self, wo: Array) -> list[Array]:
        cx, cy, cz, n = self._coeffs(wo.dtype)
        axes, length = self._axes(wo)
        if self.normalization == "normalized":
            mag = self._powered(length / self._cmax(cx, cy, cz), n)
        else:
            mag = self._powered(length, n) * 2.0 * jnp.pi / (n + 2.0)
        rho = jnp.mean(self._rho_s(wo.dtype), axis=-1)  # (L,)
        lobe_w = rho * mag * jnp.maximum(axes[..., 2], 0.0)  # (..., L)
        ws = [lobe_w[..., k] for k in range(self.lobe_count)]
        ws.append(jnp.broadcast_to(channel_mean(self.rho_d).astype(wo.dtype), wo.shape[:-1]))
        return ws

    def _probs(self, wo: Array) -> list[Array]:
        ws = [jnp.maximum(w, 0.0) for w in self._weights(wo)]
        total = sum(ws)
        k = len(ws)
        return [jnp.where(total > 0, frames.safe_div(w, total), 1.0 / k) for w in ws]

    # -- model interface ------------------------------------------------------------------------
    def _f(self, wi: Array, wo: Array) -> Array:
        spec = jnp.einsum("...l,lc->...c", self._lobes(wi, wo), self._rho_s(wi.dtype))
        rho_d = jnp.atleast_1d(self.rho_d).astype(wi.dtype)
        return spec + rho_d / jnp.pi

    def _pdf(self, wi: Array, wo: Array) -> Array:
        _, _, _, n = self._coeffs(wi.dtype)
        axes, _ = self._axes(wo)
        cos_a = jnp.sum(axes * wi[..., None, :], -1)  # (..., L)
        lobe_pdf = warps.cosine_power_lobe_pdf(cos_a, n)
        probs = self._probs(wo)
        total = probs[-1] * warps.cosine_hemisphere_pdf(wi)
        for k in range(self.lobe_count):
            total = total + probs[k] * lobe_pdf[..., k]
        return total

    def _sample(self, wo: Array, u: Array) -> Array:
        _, _, _, n = self._coeffs(wo.dtype)
        axes, _ = self._axes(wo)

        def lobe_sampler(k: int):
            def sample(w: Array, uu: Array) -> Array:
                local = warps.square_to_cosine_power_lobe(uu, n[k])
                return frames.to_world(frames.frame_from_normal(axes[..., k, :]), local)

            return sample

        samplers = [lobe_sampler(k) for k in range(self.lobe_count)]
        samplers.append(lambda w, uu: warps.square_to_cosine_hemisphere(uu))
        wi, _ = mixture_sample(wo, u, self._weights(wo), samplers)
        return wi

    def sampling_weight(self, wo: Array) -> Array:
        return sum(self._weights(wo))
