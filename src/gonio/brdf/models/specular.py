"""Delta lobes: a perfect mirror and the BSDF of a smooth dielectric interface (glass).

Both are Dirac deltas in ``wi``: ``f`` and ``pdf`` are 0 for every given pair of directions, and
``sample`` returns the one direction each event produces with ``delta = True``, ``pdf`` = the
discrete probability of the chosen event and ``weight`` = the event's throughput divided by that
probability. Callers (a renderer, :class:`~gonio.brdf.models.Sum`) must never evaluate delta
samples as densities; ``is_delta`` flags these classes.
"""

from __future__ import annotations

import jax.numpy as jnp

from gonio.brdf.frames import reflect, refract
from gonio.brdf.models._base import (
    BRDFModel,
    BRDFSample,
    Param,
    sample_inputs,
)
from gonio.brdf.models.fresnel import Fresnel, NoFresnel, dielectric_reflectance
from gonio.errors import ParameterError

Array = jnp.ndarray

TRANSPORTS = ("radiance", "importance")


class _Delta(BRDFModel):
    is_delta = True

    def _f(self, wi: Array, wo: Array) -> Array:
        return jnp.zeros((*wi.shape[:-1], self.channels), dtype=wi.dtype)

    def _pdf(self, wi: Array, wo: Array) -> Array:
        return jnp.zeros(wi.shape[:-1], dtype=wi.dtype)

    _inputs = staticmethod(sample_inputs)


class SpecularReflection(_Delta):
    """Perfect mirror: ``wi`` is ``wo`` mirrored about the normal, with reflectance ``F(cos_o)``.

    ``sample`` returns ``pdf = 1`` (the only event) and ``weight = F(cos theta_o)`` per channel;
    ``wo`` on or below the horizon gives a failed sample (pdf and weight 0).

    Parameters
    ----------
    fresnel : reflectance as a :mod:`.fresnel` term (``Conductor`` for a metal mirror,
        ``Dielectric`` for the reflection off glass); default ``NoFresnel()`` (an ideal mirror).
        Its parameters appear as ``"fresnel.<name>"``.
    """

    CHILDREN = ("fresnel",)

    def __init__(self, fresnel: Fresnel | None = None) -> None:
        self._set_params()
        fresnel = NoFresnel() if fresnel is None else fresnel
        if not isinstance(fresnel, Fresnel):
            raise ParameterError(
                f"SpecularReflection: fresnel must be a Fresnel term, got {fresnel!r}"
            )
        object.__setattr__(self, "fresnel", fresnel)

    def _sample(self, wo: Array, u: Array) -> Array:
        return reflect(wo)

    def sampling_weight(self, wo: Array) -> Array:
        return self.fresnel.mean(wo[..., 2]).astype(wo.dtype)

    def sample(self, wo: Array, u: Array) -> BRDFSample:
        wo, u = self._inputs(wo, u)
        ok = wo[..., 2] > 0
        wi = reflect(wo)
        f = jnp.broadcast_to(self.fresnel.eval(wo[..., 2]), (*ok.shape, self.channels))
        weight = jnp.where(ok[..., None], f, 0.0).astype(wo.dtype)
        pdf = jnp.where(ok, 1.0, 0.0).astype(wo.dtype)
        return BRDFSample(wi, pdf, weight, ok)


class SpecularTransmission(_Delta):
    """Smooth dielectric interface (e.g. glass): Fresnel-weighted reflection or refraction.

    ``wo`` may lie on either side: ``cos theta_o > 0`` is the outside (relative index ``eta``),
    ``cos theta_o < 0`` the inside (relative index ``1 / eta``). ``sample`` picks reflection with
    probability ``F`` (the exact dielectric reflectance at ``wo``, 1 beyond the critical angle)
    and refraction with probability ``1 - F``:

    * reflection: ``wi`` = mirror of ``wo``; ``pdf = F``; ``weight = 1``;
    * refraction: ``wi`` = refracted ``wo`` (Snell's law, other side); ``pdf = 1 - F``;
      ``weight = 1 / eta_rel^2`` with ``transport="radiance"`` (radiance is compressed by
      ``(n_o / n_i)^2`` when it crosses into a medium of index ``n_o`` from ``n_i``; for ``wo``
      outside, ``eta_rel = eta``), or ``1`` with ``transport="importance"`` (adjoint transport,
      which carries no such factor).

    So ``pdf * weight`` is ``F`` for reflection and ``(1 - F) / eta_rel^2`` for refraction: the
    two events carry all the energy (``F + (1 - F) = 1`` before the radiance scaling).
    ``wo`` exactly on the horizon gives a failed sample.

    Inside a :class:`~gonio.brdf.models.Sum` (a BRDF), ``wo`` below the horizon is invalid
    like for every other lobe; call this model directly for paths inside the material.

    Parameters
    ----------
    eta : relative index of refraction (inside / outside), a scalar (one direction per sample,
        so no dispersion). Default 1.5 (common glass).
    transport : ``"radiance"`` (default; camera paths) or ``"importance"`` (light paths).
    """

    PARAMS = (
        Param("eta", 1.5, 1e-2, 10.0, "1", scale="log",
              doc="relative index of refraction (inside over outside)"),
    )  # fmt: skip
    STATIC = ("transport",)

    def __init__(self, eta: Array | float = 1.5, transport: str = "radiance") -> None:
        self._set_params(eta=eta)
        if transport not in TRANSPORTS:
            raise ParameterError(
                f"SpecularTransmission: unknown transport {transport!r}; use one of {TRANSPORTS}"
            )
        object.__setattr__(self, "transport", transport)

    def reflectance(self, cos_theta_o: Array) -> Array:
        """Probability ``F`` of reflection at ``cos theta_o`` (either side), shape ``(...)``."""
        return dielectric_reflectance(cos_theta_o, self.eta)

    def _sample(self, wo: Array, u: Array) -> Array:
        return self.sample(wo, u).wi

    def sampling_weight(self, wo: Array) -> Array:
        # Reflection plus transmission carry all the incident energy.
        return jnp.ones(wo.shape[:-1], dtype=wo.dtype)

    def sample(self, wo: Array, u: Array) -> BRDFSample:
        wo, u = self._inputs(wo, u)
        cos_o = wo[..., 2]
        ok = cos_o != 0
        outside = cos_o > 0
        eta = jnp.asarray(self.eta).astype(wo.dtype)
        eta_rel = jnp.where(outside, eta, 1.0 / eta)
        f = self.reflectance(cos_o)
        n = jnp.zeros_like(wo).at[..., 2].set(jnp.where(outside, 1.0, -1.0))
        wt, can_refract = refract(wo, eta_rel, n)
        do_reflect = (u[..., 0] < f) | ~can_refract
        wi = jnp.where(do_reflect[..., None], reflect(wo), wt)
        pdf = jnp.where(do_reflect, f, 1.0 - f)
        if self.transport == "radiance":
            t_weight = 1.0 / (eta_rel * eta_rel)
        else:
            t_weight = jnp.ones_like(eta_rel)
        weight = jnp.where(do_reflect, 1.0, t_weight)
        ok = ok & (pdf > 0)
        pdf = jnp.where(ok, pdf, 0.0).astype(wo.dtype)
        weight = jnp.where(ok, weight, 0.0)[..., None].astype(wo.dtype)
        return BRDFSample(wi, pdf, weight, ok)
