"""The smooth-surface model of Löw, Kronander, Ynnerman & Unger (2012).

Löw, Kronander, Ynnerman, Unger, "BRDF models for accurate and efficient rendering of glossy
surfaces", ACM Trans. Graph. 31(1), 2012, section 4 (eqs. 10-14), in the form of the BSDF
benchmark library (bbm, ``include/bsdfmodel/lowsmooth.h``), which the published fits
(``low_lowsmooth_E2.fit``) follow: no shadowing (``G = 1``) and no cosine division.
"""

from __future__ import annotations

import jax.numpy as jnp

from gonio.brdf.frames import safe_sqrt
from gonio.brdf.models._base import BRDFModel, Param
from gonio.brdf.models._lobes import HalfVectorPowerProposal
from gonio.brdf.models.fresnel import dielectric_reflectance

Array = jnp.ndarray


class LowSmooth(HalfVectorPowerProposal, BRDFModel):
    """``f = A S(|D_p|^2) Q(theta_d)`` in sr^-1 (specular).

    With ``I_p``, ``O_p`` the projections of ``wi`` and ``wo`` on the surface plane (their x, y
    components): ``D_p = I_p + O_p`` (0 in the mirror direction), ``S(x) = (1 + B x)^-C`` (the
    ABC model of the surface's power spectrum), ``cos theta_d = sqrt(1 - |I_p - O_p|^2 / 4)``
    and ``Q`` the exact unpolarized Fresnel reflectance of a dielectric of index ``eta`` at
    ``theta_d`` (Cook and Torrance's formula; one ``eta`` for every channel).

    Parameters
    ----------
    A : amplitude per channel in [0, 1e5], sr^-1.
    B : sharpness in [0, 1e9] (dimensionless).
    C : fall-off exponent in [1e-4, 20] (dimensionless).
    eta : index of refraction in [1.0001, 50] (dimensionless).

    Sampling: half vectors from ``cos^m theta_h`` with ``m = 8 B C`` (the lobe's curvature at
    the peak, where ``|D_p|^2 ~ 8 (1 - cos theta_h)``), reflected about ``h``.
    """

    PARAMS = (
        Param("A", 1.0, 0.0, 1e5, "1/sr", per_channel=True, scale="log", doc="amplitude"),
        Param("B", 100.0, 0.0, 1e9, "1", scale="log", doc="sharpness"),
        Param("C", 1.0, 1e-4, 20.0, "1", scale="log", doc="fall-off exponent"),
        Param("eta", 1.5, 1.0001, 50.0, "1", scale="log", doc="index of refraction (Fresnel)"),
    )  # fmt: skip

    def __init__(
        self,
        A: Array | float = 1.0,
        B: Array | float = 100.0,
        C: Array | float = 1.0,
        eta: Array | float = 1.5,
    ) -> None:
        self._set_params(A=A, B=B, C=C, eta=eta)

    def _f(self, wi: Array, wo: Array) -> Array:
        dt = wi.dtype
        dp2 = (wi[..., 0] + wo[..., 0]) ** 2 + (wi[..., 1] + wo[..., 1]) ** 2
        dm2 = (wi[..., 0] - wo[..., 0]) ** 2 + (wi[..., 1] - wo[..., 1]) ** 2
        b, c = jnp.asarray(self.B).astype(dt), jnp.asarray(self.C).astype(dt)
        s = jnp.exp(-c * jnp.log1p(b * dp2))
        q = dielectric_reflectance(safe_sqrt(1.0 - 0.25 * dm2), jnp.asarray(self.eta).astype(dt))
        return jnp.atleast_1d(self.A).astype(dt) * (s * q)[..., None]

    def _exponent(self, dt: object) -> Array:
        return 8.0 * jnp.asarray(self.B).astype(dt) * jnp.asarray(self.C).astype(dt)

    def _amplitude(self) -> Array:
        return self.A
