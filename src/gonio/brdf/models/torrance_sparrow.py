"""Torrance-Sparrow / Cook-Torrance microfacet reflection with an optional diffuse term."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf.frames import dot, normalize, reflect, safe_div, upper
from gonio.brdf.models import microfacet as mf
from gonio.brdf.models._base import (
    BRDFModel,
    BRDFSample,
    Param,
    channel_mean,
    channels_last,
    is_concrete,
    mixture_sample,
    on_channel_axis,
)
from gonio.brdf.models.fresnel import Conductor, Fresnel, Schlick
from gonio.brdf.sampling import warps
from gonio.errors import ParameterError

Array = jnp.ndarray

SAMPLINGS = ("auto", "visible", "distribution")


#: Largest roughness a TorranceSparrow lobe is defined for (fits search up to 1).
ALPHA_MAX = 4.0


class TorranceSparrow(BRDFModel):
    """Microfacet BRDF ``f = rho_d / pi + D(h) G(wi, wo) F(wi.h) / (4 cos_i cos_o)``.

    Parameters
    ----------
    alpha : roughness in [1e-4, :data:`ALPHA_MAX`] (dimensionless; the RMS microfacet slope
        for Beckmann, the Blinn exponent is ``2 / alpha^2 - 2``). Fitted on a log scale within
        [1e-4, 1]; above 1 (normals steeper than 45 degrees on average, a Blinn exponent below
        0) each distribution is still normalized, so a published fit there (three of Löw et
        al.'s Cook-Torrance fits, up to 2.09) is a valid model.
    distribution : ``"blinn"``, ``"beckmann"`` or ``"ggx"`` (static; see :mod:`.microfacet`).
    shadowing : ``"vcavity"`` (Torrance-Sparrow's ``min(1, ...)``) or ``"smith"``
        (height-correlated, exact Lambda per distribution; static).
    fresnel : a :mod:`.fresnel` term, evaluated at ``cos theta_d = wi.h``: ``Conductor(eta, k)``,
        ``Dielectric(eta)``, ``Schlick(f0)`` or ``NoFresnel()``. Its parameters appear as
        ``"fresnel.<name>"``. Default ``Schlick(0.04)``: the normal-incidence reflectance of a
        dielectric of index 1.5 (plastics, paints, coatings — the usual case when fitting a
        diffuse-plus-specular material); pass ``Conductor`` for metals.
    rho_d : diffuse (Lambertian) albedo in [0, 1], scalar or per channel; default 0 (pure
        specular). The two terms are not energy-coupled: ``rho_d`` plus the specular albedo may
        exceed 1 if the parameters say so.
    sampling : ``"visible"`` (visible normals, Heitz 2018; GGX only), ``"distribution"``
        (half vectors with density ``D cos theta_h``) or ``"auto"`` (visible where available).
        Either way the returned pdf is exact, including the ``1 / (4 wo.h)`` Jacobian.

    Sampling mixes the specular sampler with cosine-weighted sampling in proportion to
    ``mean(rho_d)`` and ``mean(F(cos theta_o))`` (a cheap specular albedo estimate). Where
    ``rho_d`` is a known zero (a concrete value, not a traced one: the usual case for a metal)
    the diffuse lobe is left out of ``sample`` and ``pdf`` altogether, so that they cost what
    the specular lobe costs. The two samplers differ only where ``mean(F(cos theta_o)) = 0``
    (the mixture then picks either lobe with probability 1/2); both are exact for ``f``.
    """

    PARAMS = (
        Param("alpha", 0.2, 1e-4, ALPHA_MAX, "1", scale="log", fit_upper=1.0,
              doc="microfacet roughness (RMS slope for Beckmann)"),
        Param("rho_d", 0.0, 0.0, 1.0, "1", per_channel=True, scale="logit",
              doc="Lambertian albedo added to the specular lobe"),
    )  # fmt: skip
    CHILDREN = ("fresnel",)
    STATIC = ("distribution", "shadowing", "sampling")

    def __init__(
        self,
        alpha: Array | float = 0.2,
        distribution: str = "beckmann",
        shadowing: str = "vcavity",
        fresnel: Fresnel | None = None,
        rho_d: Array | float = 0.0,
        sampling: str = "auto",
    ) -> None:
        self._set_params(alpha=alpha, rho_d=rho_d)
        distribution = mf.check_distribution(distribution)
        shadowing = mf.check_shadowing(shadowing)
        if sampling not in SAMPLINGS:
            raise ParameterError(f"TorranceSparrow: unknown sampling {sampling!r}; use {SAMPLINGS}")
        if sampling == "auto":
            sampling = "visible" if distribution in mf.VISIBLE_SAMPLING else "distribution"
        if sampling == "visible" and distribution not in mf.VISIBLE_SAMPLING:
            raise ParameterError(
                f"TorranceSparrow: visible-normal sampling is available for "
                f"{mf.VISIBLE_SAMPLING}, not {distribution!r}"
            )
        if fresnel is None:
            fresnel = Schlick(0.04)
        if not isinstance(fresnel, Fresnel):
            raise ParameterError(
                f"TorranceSparrow: fresnel must be a Fresnel term, got {fresnel!r}"
            )
        object.__setattr__(self, "fresnel", fresnel)
        object.__setattr__(self, "distribution", distribution)
        object.__setattr__(self, "shadowing", shadowing)
        object.__setattr__(self, "sampling", sampling)
        _ = self.channels  # rho_d and the Fresnel term must agree on the channel count

    # -- evaluation -----------------------------------------------------------------------------
    def specular(self, wi: Array, wo: Array) -> Array:
        """The specular term ``D G F / (4 cos_i cos_o)`` alone, ``(..., C)`` (both upper)."""
        packed = self._packed(wi, wo)
        if self._conductor():
            return channels_last(self._specular_channels_first(packed))
        return packed[..., :1] * self.fresnel.eval(packed[..., 1])

    def _packed(self, wi: Array, wo: Array) -> Array:
        """``[D G / (4 cos_i cos_o), wi.h]`` per lane, ``(..., 2)``."""
        h = normalize(wi + wo)
        d = mf.ndf(h, self.alpha, self.distribution)
        v = mf.visibility(wi, wo, h, self.alpha, self.distribution, self.shadowing)
        # The per-lane values the channels share, stored once: without the barrier XLA:CPU
        # recomputes the cheap half of D and G in every channel's loop and splits the rest into
        # one pass over memory per expensive op; with it, GGX f compiles to 2 loops and
        # Beckmann f to 7 (throughput: benchmarks/bench_throughput.py).
        return jax.lax.optimization_barrier(jnp.stack([d * v, dot(wi, h)], -1))

    def _conductor(self) -> bool:
        """Whether ``f`` is computed channels first (see :func:`~._base.channels_last`):
        with a conductor Fresnel term, whose per-channel work outweighs the move."""
        return isinstance(self.fresnel, Conductor)

    def _specular_channels_first(self, packed: Array) -> Array:
        """``packed[..., 0] F(packed[..., 1])`` as ``(C, ...)``: the channels' loop runs along
        the lanes (see :meth:`~.fresnel.Fresnel.eval_channels_first`)."""
        return packed[..., 0][None] * self.fresnel.eval_channels_first(packed[..., 1])

    def _diffuse_free(self) -> bool:
        """True where ``rho_d`` is a concrete zero (not traced): no diffuse lobe to sample."""
        rho = self.rho_d
        return is_concrete(rho) and not np.any(np.asarray(rho))

    def _f(self, wi: Array, wo: Array) -> Array:
        rho = jnp.atleast_1d(self.rho_d).astype(wi.dtype)
        return rho / jnp.pi + self.specular(wi, wo)

    def _f_channels_first(self, wi: Array, wo: Array) -> Array | None:
        if not self._conductor():
            return None
        rho = on_channel_axis(jnp.atleast_1d(self.rho_d).astype(wi.dtype), wi.ndim - 1)
        return rho / jnp.pi + self._specular_channels_first(self._packed(wi, wo))

    # -- sampling -------------------------------------------------------------------------------
    def _weights(self, wo: Array) -> tuple[Array, Array]:
        w_d = jnp.broadcast_to(channel_mean(self.rho_d).astype(wo.dtype), wo.shape[:-1])
        w_s = self.fresnel.mean(wo[..., 2]).astype(wo.dtype)
        return w_d, w_s

    def _probs(self, wo: Array) -> tuple[Array, Array]:
        # Must match choose_lobe's normalization (uniform where both weights are 0).
        w_d, w_s = self._weights(wo)
        w_d, w_s = jnp.maximum(w_d, 0.0), jnp.maximum(w_s, 0.0)
        total = w_d + w_s
        return (
            jnp.where(total > 0, safe_div(w_d, total), 0.5),
            jnp.where(total > 0, safe_div(w_s, total), 0.5),
        )

    def sampling_weight(self, wo: Array) -> Array:
        w_d, w_s = self._weights(wo)
        return w_d + w_s

    def specular_pdf(self, wi: Array, wo: Array) -> Array:
        """Density of :meth:`sample_specular` over ``wi`` (both directions above the horizon)."""
        h = normalize(wi + wo)
        if self.sampling == "visible":
            # G1(wo) D(h) (wo.h) / cos_o, times the Jacobian 1 / (4 wo.h).
            den = 4.0 * (wo[..., 2] + mf.smith_mu(wo, self.alpha, self.distribution))
            return safe_div(mf.ndf(h, self.alpha, self.distribution), den)
        oh = jnp.maximum(dot(wo, h), 0.0)  # >= 0 in exact arithmetic; rounding can flip it
        return safe_div(mf.ndf_pdf(h, self.alpha, self.distribution), 4.0 * oh)

    def sample_specular(self, wo: Array, u: Array) -> Array:
        """Reflect ``wo`` about a sampled microfacet normal (may fall below the horizon)."""
        if self.sampling == "visible":
            h = mf.sample_visible(wo, u, self.alpha, self.distribution)
        else:
            h = mf.sample_ndf(u, self.alpha, self.distribution)
        return reflect(wo, h)

    def _finish(self, wi: Array, wo: Array, ok_o: Array) -> BRDFSample:
        """Sample weight ``f cos_i / pdf`` with ``D`` cancelled (specular lobe alone, Smith).

        With ``den = cos_i cos_o + cos_o mu_i + cos_i mu_o`` (``G2 / (4 cos_i cos_o) =
        1 / (4 den)``): visible normals give ``F cos_i (cos_o + mu_o) / den`` (``F G2 / G1(wo)``,
        as Mitsuba's ``roughconductor`` writes it), distribution sampling gives
        ``F cos_i (wo.h) / (n.h den)``. The same values as
        the generic ``f cos_i / pdf`` up to rounding, without evaluating ``D`` a second time
        (which also leaves XLA:CPU fewer loops to emit for ``sample``).
        """
        if not (self._diffuse_free() and self.shadowing == "smith"):
            return super()._finish(wi, wo, ok_o)
        a, dist = self.alpha, self.distribution
        ok = ok_o & upper(wi)
        wi_s = jnp.where(ok[..., None], wi, jnp.array([0.0, 0.0, 1.0], wi.dtype))
        h = normalize(wi_s + wo)
        d = mf.ndf(h, a, dist)
        mi, mo = mf.smith_mu(wi_s, a, dist), mf.smith_mu(wo, a, dist)
        ci, co = wi_s[..., 2], wo[..., 2]
        cif, cof = jnp.maximum(ci, mf._COS_FLOOR), jnp.maximum(co, mf._COS_FLOOR)
        den = cif * cof + cof * mi + cif * mo
        if self.sampling == "visible":
            pdf = safe_div(d, 4.0 * (co + mo))
            g = safe_div(ci * (co + mo), den)
        else:
            oh = jnp.maximum(dot(wo, h), 0.0)
            nh = jnp.maximum(h[..., 2], 0.0)
            pdf = safe_div(d * nh, 4.0 * oh)
            g = safe_div(ci * oh, nh * den)
        ok = ok & (pdf > 0)
        pdf = jnp.where(ok, pdf, 0.0)
        # Stored once before the channels' Fresnel loop (as in specular()).
        packed = jax.lax.optimization_barrier(jnp.stack([jnp.where(ok, g, 0.0), dot(wi_s, h)], -1))
        weight = jnp.where(ok[..., None], packed[..., :1] * self.fresnel.eval(packed[..., 1]), 0.0)
        return BRDFSample(wi, pdf.astype(wo.dtype), weight.astype(wo.dtype), jnp.zeros_like(ok))

    def _pdf(self, wi: Array, wo: Array) -> Array:
        if self._diffuse_free():
            return self.specular_pdf(wi, wo)
        p_d, p_s = self._probs(wo)
        return p_d * warps.cosine_hemisphere_pdf(wi) + p_s * self.specular_pdf(wi, wo)

    def _sample(self, wo: Array, u: Array) -> Array:
        if self._diffuse_free():
            return self.sample_specular(wo, u)
        w_d, w_s = self._weights(wo)

        def diffuse(wo_: Array, uu: Array) -> Array:
            return warps.square_to_cosine_hemisphere(uu)

        wi, _ = mixture_sample(wo, u, [w_d, w_s], [diffuse, self.sample_specular])
        return wi
