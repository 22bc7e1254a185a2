"""Fresnel reflectance terms: exact conductor and dielectric formulas, Schlick's approximation.

Each term is a :class:`~gonio.brdf.models._base.Node` (a pytree with parameter metadata) rather
than a BRDF: models hold one as a child (``TorranceSparrow(fresnel=Conductor(...))``), so its
parameters appear in the model's ``params()`` as ``"fresnel.eta"`` and are differentiable.

Every term has ``eval(cos_theta) -> (..., C)``: the unpolarized reflectance of a smooth interface
for light arriving at angle ``theta`` to the (micro)normal, channels last (C = 1 for scalar
parameters). Indices of refraction are relative: ``eta`` = index of the material behind the
interface divided by the index of the medium the light comes from (the outside, usually air).

All formulas stay finite, with finite parameter gradients, from normal incidence
(``cos_theta = 1``) to grazing incidence (``cos_theta = 0``), in float32 and float64.
"""

from __future__ import annotations

from collections.abc import Callable

import jax.numpy as jnp

from gonio.brdf.frames import safe_div, safe_sqrt
from gonio.brdf.models._base import Node, Param, channel_mean, on_channel_axis

Array = jnp.ndarray


class Fresnel(Node):
    """Base class of the Fresnel terms: ``eval(cos_theta) -> (..., C)``."""

    def eval(self, cos_theta: Array) -> Array:
        """Reflectance in [0, 1] for incidence cosine ``cos_theta`` (...) -> (..., C)."""
        return self._reflectance(jnp.asarray(cos_theta)[..., None], lambda p: p)

    def eval_channels_first(self, cos_theta: Array) -> Array:
        """:meth:`eval` with the channel axis first: ``(...) -> (C, ...)``, the same values.

        For kernels whose outputs are ``(..., C)``: XLA:CPU compiles a loop over a ``(n, C)``
        array fed by ``(n,)`` values to scalar code (one lane at a time, the per-lane input
        re-indexed per element), while the ``(C, n)`` loop is vectorized along ``n``. The
        caller transposes once at the end.
        """
        c = jnp.asarray(cos_theta)
        return self._reflectance(c[None], lambda p: on_channel_axis(p, c.ndim))

    def _reflectance(self, c: Array, place: Callable[[Array], Array]) -> Array:
        """The formula on ``c`` (cosines with a size-1 channel axis in place) and the
        per-channel parameters as ``(C,)`` arrays put on that axis by ``place``."""
        raise NotImplementedError

    def mean(self, cos_theta: Array) -> Array:
        """Channel mean of :meth:`eval`, shape ``(...)`` (used for lobe-selection weights)."""
        e = self.eval(cos_theta)
        # Summed per channel: jnp.mean's reduction over the short channel axis is a separate
        # XLA:CPU pass that costs more than the whole Fresnel evaluation; the explicit sum fuses.
        total = e[..., 0]
        for i in range(1, e.shape[-1]):
            total = total + e[..., i]
        return total / e.shape[-1]


def _per_channel(p: Array, like: Array) -> Array:
    """Per-channel parameter as ``(C,)`` in the dtype of ``like``."""
    return jnp.atleast_1d(p).astype(like.dtype)


class Conductor(Fresnel):
    """Exact unpolarized Fresnel reflectance of a conductor with complex index ``eta + i k``.

    ``F = (R_s + R_p) / 2`` with (e.g. Born & Wolf; Cook & Torrance 1982), for ``c = cos theta``,
    ``s2 = sin^2 theta``, ``t = eta^2 - k^2 - s2``, ``a^2 + b^2 = sqrt(t^2 + 4 eta^2 k^2)``,
    ``a = sqrt((a^2 + b^2 + t) / 2)``::

        R_s = (a^2 + b^2 - 2 a c + c^2) / (a^2 + b^2 + 2 a c + c^2)
        R_p = R_s (c^2 (a^2 + b^2) - 2 a c s2 + s2^2) / (c^2 (a^2 + b^2) + 2 a c s2 + s2^2)

    With ``k = 0`` it reduces to the exact dielectric formula (including total internal
    reflection when ``eta < 1``).

    Parameters
    ----------
    eta : real part of the relative index of refraction, scalar or per channel (dimensionless).
    k : extinction coefficient (imaginary part), scalar or per channel (dimensionless).
    """

    PARAMS = (
        Param("eta", 0.2, 1e-3, 10.0, "1", per_channel=True, scale="log",
              doc="real part of the complex index of refraction (relative to the outside)"),
        Param("k", 3.9, 0.0, 20.0, "1", per_channel=True, scale="linear",
              doc="extinction coefficient (imaginary part of the index)"),
    )  # fmt: skip

    def __init__(self, eta: Array | float = 0.2, k: Array | float = 3.9) -> None:
        self._set_params(eta=eta, k=k)

    def _reflectance(self, c: Array, place: Callable[[Array], Array]) -> Array:
        c = jnp.clip(jnp.abs(c), 0.0, 1.0)
        n = place(_per_channel(self.eta, c))
        k = place(_per_channel(self.k, c))
        c2 = c * c
        s2 = 1.0 - c2
        t = n * n - k * k - s2
        ab2 = safe_sqrt(t * t + 4.0 * n * n * k * k)  # a^2 + b^2 = |eta^2 - sin^2|
        a = safe_sqrt(0.5 * (ab2 + t))
        two_ac = 2.0 * a * c
        rs = safe_div(ab2 - two_ac + c2, ab2 + two_ac + c2)
        p_common = c2 * ab2 + s2 * s2
        p_cross = two_ac * s2
        rp = rs * safe_div(p_common - p_cross, p_common + p_cross)
        return jnp.clip(0.5 * (rs + rp), 0.0, 1.0)


class Dielectric(Fresnel):
    """Exact unpolarized Fresnel reflectance of a smooth dielectric interface.

    ``cos_theta`` may come from either side: ``cos_theta >= 0`` means the light arrives from the
    outside (relative index ``eta``), ``cos_theta < 0`` from inside (relative index ``1/eta``).
    Beyond the critical angle (total internal reflection) the reflectance is exactly 1.
    With ``c_t`` the cosine of the refracted ray and ``e`` the relative index::

        r_s = (c - e c_t) / (c + e c_t),   r_p = (e c - c_t) / (e c + c_t),
        F = (r_s^2 + r_p^2) / 2

    Parameters
    ----------
    eta : relative index of refraction (inside / outside) in [0.01, 100], scalar or per
        channel (Löw et al.'s published Ashikhmin-Shirley fits reach 10.1).
    """

    PARAMS = (
        Param("eta", 1.5, 1e-2, 100.0, "1", per_channel=True, scale="log",
              doc="relative index of refraction (inside over outside)"),
    )  # fmt: skip

    def __init__(self, eta: Array | float = 1.5) -> None:
        self._set_params(eta=eta)

    def _reflectance(self, c: Array, place: Callable[[Array], Array]) -> Array:
        return dielectric_reflectance(c, place(_per_channel(self.eta, c)))


def dielectric_reflectance(cos_theta: Array, eta: Array) -> Array:
    """Exact unpolarized reflectance of a dielectric interface (see :class:`Dielectric`).

    ``cos_theta`` and ``eta`` broadcast together; ``cos_theta < 0`` means from inside.
    """
    cos_theta = jnp.asarray(cos_theta)
    c = jnp.clip(jnp.abs(cos_theta), 0.0, 1.0)
    e = jnp.asarray(eta).astype(c.dtype)
    e = jnp.where(cos_theta < 0, 1.0 / e, e)
    sin2_t = (1.0 - c * c) / (e * e)
    tir = sin2_t >= 1.0
    ct = safe_sqrt(1.0 - sin2_t)
    rs = safe_div(c - e * ct, c + e * ct)
    rp = safe_div(e * c - ct, e * c + ct)
    f = 0.5 * (rs * rs + rp * rp)
    return jnp.clip(jnp.where(tir, 1.0, f), 0.0, 1.0)


class Schlick(Fresnel):
    """Schlick's (1994) approximation ``F = f0 + (1 - f0) (1 - |cos theta|)^5``.

    Parameters
    ----------
    f0 : reflectance at normal incidence, in [0, 1], scalar or per channel. 0.04 corresponds to
        a dielectric of index 1.5.
    """

    PARAMS = (
        Param("f0", 0.04, 0.0, 1.0, "1", per_channel=True, scale="logit",
              doc="reflectance at normal incidence"),
    )  # fmt: skip

    def __init__(self, f0: Array | float = 0.04) -> None:
        self._set_params(f0=f0)

    def _reflectance(self, c: Array, place: Callable[[Array], Array]) -> Array:
        c = jnp.clip(jnp.abs(c), 0.0, 1.0)
        f0 = place(_per_channel(self.f0, c))
        m = 1.0 - c
        m2 = m * m
        return f0 + (1.0 - f0) * (m2 * m2 * m)

    def mean(self, cos_theta: Array) -> Array:
        c = jnp.clip(jnp.abs(jnp.asarray(cos_theta)), 0.0, 1.0)
        f0 = channel_mean(self.f0).astype(c.dtype)
        return f0 + (1.0 - f0) * (1.0 - c) ** 5


class NoFresnel(Fresnel):
    """Constant reflectance 1 (no Fresnel factor), for models fitted without one."""

    def __init__(self) -> None:
        self._set_params()

    def eval(self, cos_theta: Array) -> Array:
        c = jnp.asarray(cos_theta)
        dtype = c.dtype if jnp.issubdtype(c.dtype, jnp.floating) else jnp.float64
        return jnp.ones((*c.shape, 1), dtype=dtype)

    def eval_channels_first(self, cos_theta: Array) -> Array:
        return jnp.moveaxis(self.eval(cos_theta), -1, 0)
