"""He, Torrance, Sillion & Greenberg (1991): a wave-optics reflection model.

He, Torrance, Sillion, Greenberg, "A comprehensive physical model for light reflection",
SIGGRAPH 1991 (equation numbers below refer to it), with the erratum to its eq. 25 (the missing
``exp(-a^2)`` in the shadowing function's Lambda, also in Westin's reference code).

The surface is a Gaussian random height field with rms height ``sigma0`` and autocorrelation
length ``tau`` (both in micrometres). Reflection splits into

* a **specular** term (a Dirac delta about the mirror direction) with reflectance
  ``F(theta_o) exp(-g) S``, ``g = (4 pi sigma cos theta_o / lambda)^2`` (eq. 72);
* a **directional-diffuse** term ``F(k.h) G S D / (pi cos_i cos_o)`` (eq. 76) with the
  Kirchhoff series ``D = pi^2 tau^2 / (4 lambda^2) sum_{m >= 1} g^m e^-g / (m! m)
  exp(-tau^2 v_xy^2 / (4 m))`` (eq. 78), ``g = (2 pi sigma (cos_i + cos_o) / lambda)^2``,
  ``v_xy = 2 pi / lambda |(wi + wo)_xy|``, ``G = (|wi + wo|^2 / (wi + wo)_z)^2``;
* a **uniform-diffuse** term ``rho_ud / pi`` (the paper's ``a(lambda)``).

``sigma`` is the effective roughness ``sigma0 / sqrt(1 + (z0 / sigma0)^2)`` (eq. 80) where ``z0``
solves ``sqrt(pi / 2) z0 = sigma0 / 4 (K_i + K_o) exp(-z0^2 / (2 sigma0^2))`` with ``K = tan theta
erfc(tau cot theta / (2 sigma0))`` (eqs. 81-83); it is found by Newton-Raphson from an upper
bound (monotone convergence, a fixed number of steps, then one differentiable step so gradients
are the exact implicit derivative). ``S = S(theta_i) S(theta_o)`` is Smith's shadowing for the
Gaussian surface (eqs. 24-25). ``F`` is any Fresnel node (``Conductor(eta, k)`` for the complex
index of refraction, ``Dielectric(eta)``), evaluated at the local (bisector) angle ``k.h``.

Series truncation
-----------------
The summand of eq. 78 is a Poisson weight ``g^m e^-g / m!`` times ``exp(-c / m) / m``. It is
summed over a window of ``terms`` (M) indices ``m0, m0 + s, ..., m0 + (M - 1) s`` that spans
``[max(1, m* - 6 sd), m* + 6 min(sqrt(m*), 2 sd)]``, where ``m*`` is the summand's peak (Newton
in ``log m`` on ``log(g / m) + c / m^2 = 0``), ``sd = (1 / m* + 2 c / m*^3)^(-1/2)`` the width
of its left flank (steepened by ``exp(-c / m)``) and the right flank, which decays like the
Poisson weight, is allowed up to twice that; the stride
``s >= 1`` is the smallest that lets M terms span the window, and the strided sum is multiplied
by ``s``. With stride 1 the truncation error of ``D`` is rigorously bounded by
``pi^2 tau^2 / (4 lambda^2) [P(N < m0) exp(-c / (m0 - 1)) + P(N > m1) / (m1 + 1)]`` with
``N ~ Poisson(g)`` and window ``[m0, m1]`` (:meth:`HTSG.series_error_bound`). A stride > 1 is
only used for wide peaks (large ``g``), where the strided sum is a trapezoidal rule on a smooth
bell at least ``(M - 1) / 12`` strides wide, whose error decays like ``exp(-2 pi^2 (sd / s)^2)``;
Measured over a log grid of ``g`` in [1e-3, 5e3] and ``c`` in {0} U [1e-2, 1e5] against a
40000-term direct sum (float64): max relative error 7e-5 with M = 32, 1.4e-8 with M = 48 (the
default), 8e-9 with M = 64, medians below 1e-13; in float32 rounding limits it to about 5e-6.
benchmarks/bench_zoo.py measures the resulting error of ``f`` and the cost against M.
Precomputed: the Stirling remainder ``log m! - (m log m - m + log(2 pi m) / 2)`` for m <= 64 (the
asymptotic series above), so each term costs one log1p, one log and one exp and stays accurate
in float32 even for ``g`` in the thousands (no cancellation between ``m log g`` and ``log m!``).

Wavelengths: one per channel (static ``wavelengths_um``); by default 0.55 um for one channel and
the dominant wavelengths of the sRGB primaries (0.611, 0.549, 0.464 um) for three.
"""

from __future__ import annotations

import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import erfc, gammainc, gammaincc

from gonio.brdf import frames
from gonio.brdf.frames import safe_div, safe_sqrt, upper
from gonio.brdf.models._base import (
    BRDFModel,
    BRDFSample,
    Node,
    Param,
    channel_mean,
    choose_lobe,
    masked_outgoing,
    safe_pair,
    sample_inputs,
)
from gonio.brdf.models.fresnel import Conductor
from gonio.brdf.sampling import warps
from gonio.errors import ParameterError

Array = jnp.ndarray

#: Default wavelengths (micrometres) by channel count.
DEFAULT_WAVELENGTHS_UM = {1: (0.55,), 3: (0.611, 0.549, 0.464)}
#: Newton steps for z0 (from an upper bound; 6 already reach float64 precision in tests).
_Z0_STEPS = 8
#: Newton steps for the peak of the series summand.
_PEAK_STEPS = 8
#: Half-width of the summation window in standard deviations of the summand.
_WINDOW_SD = 6.0
_SMALL_M = 64
_m = np.arange(1, _SMALL_M + 1, dtype=np.float64)
_STIRLING_REMAINDER = np.array(
    [math.lgamma(m + 1) - (m * math.log(m) - m + 0.5 * math.log(2 * math.pi * m)) for m in _m]
)


def _stirling_remainder(m: Array) -> Array:
    """``log m! - (m log m - m + log(2 pi m) / 2)`` for integer-valued ``m >= 1``."""
    table = jnp.asarray(_STIRLING_REMAINDER, dtype=m.dtype)
    idx = jnp.clip(m.astype(jnp.int32) - 1, 0, _SMALL_M - 1)
    inv = 1.0 / m
    inv2 = inv * inv
    series = inv * (1.0 / 12.0 - inv2 * (1.0 / 360.0 - inv2 / 1260.0))
    return jnp.where(m <= _SMALL_M, table[idx], series)


def _shadow_a(cos: Array, sigma0: Array, tau: Array) -> Array:
    """``a = tau cot theta / (2 sigma0)``, large (not infinite) at the pole or for sigma0 = 0."""
    sin = jnp.maximum(safe_sqrt(1.0 - cos * cos), 1e-12)
    big = jnp.asarray(1e12 if cos.dtype == jnp.float64 else 1e6, cos.dtype)
    return jnp.minimum(tau * cos / (2.0 * jnp.maximum(sigma0, 1e-30) * sin), big)


def shadowing(cos: Array, sigma0: Array, tau: Array) -> Array:
    """Smith shadowing of one direction for the Gaussian surface (eqs. 24-25 with erratum)."""
    a = _shadow_a(cos, sigma0, tau)
    ec = erfc(a)
    lam = 0.5 * (jnp.exp(-a * a) / (jnp.sqrt(jnp.pi) * a) - ec)
    return (1.0 - 0.5 * ec) / (lam + 1.0)


def effective_roughness(cos_i: Array, cos_o: Array, sigma0: Array, tau: Array) -> Array:
    """Effective roughness sigma (eq. 80), z0 from eqs. 81-83 by Newton-Raphson."""
    big_tan = 1e8 if cos_i.dtype == jnp.float64 else 1e6

    def k_term(cos: Array) -> Array:
        tan = jnp.minimum(safe_div(safe_sqrt(1.0 - cos * cos), cos), big_tan)
        return tan * erfc(_shadow_a(cos, sigma0, tau))

    # x = z0 / sigma0 solves x exp(x^2 / 2) = f0.
    f0 = (k_term(cos_i) + k_term(cos_o)) / math.sqrt(8.0 * math.pi)
    f0s = jax.lax.stop_gradient(f0)
    # Both branches are upper bounds of the root, so Newton decreases monotonically to it.
    x = jnp.where(f0s <= math.exp(0.5), f0s, safe_sqrt(2.0 * jnp.log(jnp.maximum(f0s, 1.0))))
    for _ in range(_Z0_STEPS):
        e = jnp.exp(0.5 * x * x)
        x = jnp.maximum(x - (x * e - f0s) / ((1.0 + x * x) * e), 0.0)
    x = jax.lax.stop_gradient(x)
    e = jnp.exp(0.5 * x * x)
    x = x - (x * e - f0) / ((1.0 + x * x) * e)  # exact implicit derivative at the root
    return sigma0 / jnp.sqrt(1.0 + x * x)


def _series_window(g: Array, c: Array, terms: int) -> tuple[Array, Array]:
    """Window start ``m0`` and stride ``s`` (no gradient) for the eq. 78 sum."""
    g = jax.lax.stop_gradient(g)
    c = jax.lax.stop_gradient(c)
    log_g = jnp.log(g)
    # Start near the root of u = log g + c exp(-2u) (u = log m), which for large c sits where
    # c exp(-2u) ~ u - log g; Newton converges from either side (phi is convex, decreasing).
    half_log_c = 0.5 * jnp.log(jnp.maximum(c, 1.0))
    u = jnp.maximum(
        jnp.maximum(log_g, 0.0),
        half_log_c - 0.5 * jnp.log(jnp.maximum(half_log_c - log_g, 1.0)),
    )
    for _ in range(_PEAK_STEPS):
        e2 = c * jnp.exp(-2.0 * u)
        u = jnp.maximum(u + (log_g - u + e2) / (1.0 + 2.0 * e2), 0.0)  # m >= 1 anyway
    m_pk = jnp.maximum(jnp.exp(jnp.minimum(u, 30.0)), 1.0)
    sd = 1.0 / jnp.sqrt(1.0 / m_pk + 2.0 * c / m_pk**3)
    m0 = jnp.maximum(jnp.floor(m_pk - _WINDOW_SD * sd), 1.0)
    # exp(-c / m) steepens only the left flank; the right one decays like the Poisson weight.
    span = m_pk + _WINDOW_SD * jnp.minimum(jnp.sqrt(m_pk), 2.0 * sd) - m0
    s = jnp.maximum(jnp.ceil(span / max(terms - 1, 1)), 1.0)
    return m0, s


def kirchhoff_sum(g: Array, c: Array, terms: int) -> Array:
    """``sum_{m >= 1} g^m e^-g / (m! m) exp(-c / m)`` by the windowed series (see module doc).

    ``g``, ``c`` broadcast together; ``g`` must be > 0.
    """
    m0, s = _series_window(g, c, terms)
    j = jnp.arange(terms, dtype=g.dtype)
    m = m0[..., None] + s[..., None] * j  # (..., M)
    gg, cc = g[..., None], c[..., None]
    a = (gg - m) / m
    # m log(g / m) + m - g, written to avoid cancellation both near g = m and for g << m.
    near = a > -0.5
    a_near = jnp.where(near, a, 0.0)
    core = jnp.where(
        near, -m * (a_near - jnp.log1p(a_near)), m * (jnp.log(gg) - jnp.log(m)) + (m - gg)
    )
    log_pois = core - 0.5 * jnp.log(2.0 * jnp.pi * m) - _stirling_remainder(m)
    log_t = log_pois - jnp.log(m) - cc / m
    return s * jnp.sum(jnp.exp(log_t), axis=-1)


class HTSG(BRDFModel):
    """He-Torrance-Sillion-Greenberg (1991): specular (delta) + directional diffuse + uniform.

    ``f`` and ``pdf`` describe the non-delta part (directional + uniform diffuse); ``sample``
    also returns specular samples (``delta=True``, weight = specular reflectance / selection
    probability), as :class:`~gonio.brdf.models.Sum` does for delta lobes. The model already
    contains its uniform-diffuse term; inside a ``Sum`` (``a + HTSG(...)``) only its non-delta
    part is sampled (consistently), and the specular delta is lost, so use it on its own.

    Parameters
    ----------
    sigma0 : rms surface height in micrometres (0 = optically smooth).
    tau : autocorrelation length in micrometres.
    rho_ud : uniform-diffuse albedo ``a`` (scalar or per channel).
    fresnel : Fresnel node for the complex index of refraction (default ``Conductor()``).
    wavelengths_um : one wavelength per channel in micrometres (see module doc for defaults).
    terms : number of series terms M per evaluation (static, default 48; see module doc).

    Sampling: the specular delta, the directional-diffuse term through a Beckmann half-vector
    proposal with ``alpha^2 = (2 sigma0 / tau)^2 + (lambda / (2 pi tau))^2`` (the lobe width of
    the rough (large g) and smooth (m = 1 term) limits of eq. 78, ``lambda`` the mean
    wavelength) whose exact pdf ``D_B(h) cos theta_h / (4 wo.h)`` is used, and the
    uniform-diffuse term cosine-weighted; lobes are chosen by albedo estimates. ``pdf`` is the
    density of the non-delta samples (it integrates to one minus the delta probability).
    """

    PARAMS = (
        Param("sigma0", 0.18, 0.0, 10.0, "um", scale="log", doc="rms surface height"),
        Param("tau", 3.0, 0.01, 1000.0, "um", scale="log", doc="autocorrelation length"),
        Param("rho_ud", 0.0, 0.0, 1.0, "1", per_channel=True, scale="logit",
              doc="uniform-diffuse albedo a(lambda)"),
    )  # fmt: skip
    CHILDREN = ("fresnel",)
    STATIC = ("wavelengths_um", "terms")

    def __init__(
        self,
        sigma0: Array | float = 0.18,
        tau: Array | float = 3.0,
        rho_ud: Array | float = 0.0,
        fresnel: Node | None = None,
        wavelengths_um: Any = None,
        terms: int = 48,
    ) -> None:
        fresnel = Conductor() if fresnel is None else fresnel
        if not isinstance(fresnel, Node) or not hasattr(fresnel, "eval"):
            raise ParameterError(f"HTSG: fresnel must be a Fresnel node, got {fresnel!r}")
        if not isinstance(terms, (int, np.integer)) or not 1 <= int(terms) <= 4096:
            raise ParameterError(f"HTSG: terms must be an integer in [1, 4096], got {terms!r}")
        object.__setattr__(self, "fresnel", fresnel)
        object.__setattr__(self, "terms", int(terms))
        self._set_params(sigma0=sigma0, tau=tau, rho_ud=rho_ud)
        channels = self.channels
        if wavelengths_um is None:
            if channels not in DEFAULT_WAVELENGTHS_UM:
                raise ParameterError(
                    f"HTSG: give wavelengths_um for {channels} channels (defaults exist for 1, 3)"
                )
            wl = DEFAULT_WAVELENGTHS_UM[channels]
        else:
            try:
                wl = tuple(float(w) for w in np.atleast_1d(np.asarray(wavelengths_um, float)))
            except (TypeError, ValueError):
                raise ParameterError(f"HTSG: bad wavelengths_um {wavelengths_um!r}") from None
            if len(wl) not in (1, channels) or not all(0.05 < w < 100 and w == w for w in wl):
                raise ParameterError(
                    f"HTSG: wavelengths_um must be {channels} values in (0.05, 100) um, got {wl}"
                )
        object.__setattr__(self, "wavelengths_um", wl)

    @property
    def channels(self) -> int:
        c = super().channels
        wl = getattr(self, "wavelengths_um", None)
        return max(c, len(wl)) if wl is not None else c

    # -- physics ----------------------------------------------------------------------------------
    def _lam(self, dtype) -> Array:
        return jnp.asarray(self.wavelengths_um, dtype=dtype)

    def _rough(self, dtype) -> tuple[Array, Array]:
        return self.sigma0.astype(dtype), self.tau.astype(dtype)

    def _gc(self, wi: Array, wo: Array) -> tuple[Array, Array, Array]:
        """``g`` and ``c`` of eq. 78 per channel ``(..., C)`` and the shadowing ``(...)``."""
        dtype = wi.dtype
        sigma0, tau = self._rough(dtype)
        ci, co = wi[..., 2], wo[..., 2]
        sigma = effective_roughness(ci, co, sigma0, tau)
        k0 = 2.0 * jnp.pi / self._lam(dtype)  # (C,)
        tiny = jnp.finfo(dtype).tiny * 1e6
        g = jnp.maximum((k0 * (sigma * (ci + co))[..., None]) ** 2, tiny)
        h = wi + wo
        vxy2 = h[..., 0] ** 2 + h[..., 1] ** 2
        c = (k0 * tau) ** 2 * vxy2[..., None] / 4.0
        s = shadowing(ci, sigma0, tau) * shadowing(co, sigma0, tau)
        return g, c, s

    def _parts(self, wi: Array, wo: Array) -> tuple[Array, Array]:
        """``(F G S / (pi cos_i cos_o), D)`` of eqs. 76 and 78, each ``(..., C)``."""
        dtype = wi.dtype
        _, tau = self._rough(dtype)
        g, c, s = self._gc(wi, wo)
        d = (jnp.pi * tau / self._lam(dtype)) ** 2 / 4.0 * kirchhoff_sum(g, c, self.terms)
        h = wi + wo
        geo = (jnp.sum(h * h, -1) / jnp.maximum(h[..., 2], 1e-30)) ** 2
        fres = self.fresnel.eval(frames.dot(wi, frames.normalize(h)))
        scale = s * geo / (jnp.pi * jnp.maximum(wi[..., 2] * wo[..., 2], 1e-30))
        return fres * scale[..., None], d

    def _prefactor(self, wi: Array, wo: Array) -> Array:
        return self._parts(wi, wo)[0]

    def distribution(self, wi: Array, wo: Array) -> Array:
        """``D`` of eq. 78 by the truncated series, ``(..., C)``."""
        return self._parts(wi, wo)[1]

    def directional_diffuse(self, wi: Array, wo: Array) -> Array:
        """The directional-diffuse term alone, ``(..., C)`` (directions above the horizon)."""
        pre, d = self._parts(wi, wo)
        return pre * d

    def specular_reflectance(self, wo: Array) -> Array:
        """Reflectance of the delta lobe ``F(theta_o) exp(-g) S`` at ``wo``, ``(..., C)``."""
        dtype = wo.dtype
        sigma0, tau = self._rough(dtype)
        co = jnp.clip(wo[..., 2], 0.0, 1.0)
        sigma = effective_roughness(co, co, sigma0, tau)
        g = (4.0 * jnp.pi * (sigma * co)[..., None] / self._lam(dtype)) ** 2
        s = shadowing(co, sigma0, tau) ** 2
        return self.fresnel.eval(co) * jnp.exp(-g) * s[..., None]

    def series_error_bound(self, wi: Array, wo: Array, terms: int | None = None) -> Array:
        """Rigorous bound on the truncation error of :meth:`distribution` ``(..., C)``.

        Where the window uses a stride > 1 the bound does not apply and ``nan`` is returned.
        """
        terms = self.terms if terms is None else terms
        wi, wo = jnp.asarray(wi, jnp.float64), jnp.asarray(wo, jnp.float64)
        g, c, _ = self._gc(wi, wo)
        m0, s = _series_window(g, c, terms)
        m1 = m0 + terms - 1
        below = jnp.where(m0 > 1, gammaincc(m0, g) * jnp.exp(-c / jnp.maximum(m0 - 1, 1)), 0.0)
        above = gammainc(m1 + 1, g) / (m1 + 1)
        _, tau = self._rough(jnp.float64)
        bound = (jnp.pi * tau / self._lam(jnp.float64)) ** 2 / 4.0 * (below + above)
        return jnp.where(s > 1, jnp.nan, bound)

    # -- model interface ----------------------------------------------------------------------
    def _f(self, wi: Array, wo: Array) -> Array:
        rho = jnp.atleast_1d(self.rho_ud).astype(wi.dtype)
        return self.directional_diffuse(wi, wo) + rho / jnp.pi

    def _alpha(self, dtype) -> Array:
        sigma0, tau = self._rough(dtype)
        lam = float(np.mean(self.wavelengths_um))
        return jnp.sqrt((2.0 * sigma0 / tau) ** 2 + (lam / (2.0 * jnp.pi * tau)) ** 2)

    def _weights(self, wo: Array) -> list[Array]:
        dtype = wo.dtype
        sigma0, tau = self._rough(dtype)
        co = jnp.clip(wo[..., 2], 0.0, 1.0)
        spec = jnp.mean(self.specular_reflectance(wo), -1)
        total = jnp.mean(self.fresnel.eval(co), -1) * shadowing(co, sigma0, tau)
        dd = jnp.maximum(total - spec, 0.0)
        ud = jnp.broadcast_to(channel_mean(self.rho_ud).astype(dtype), co.shape)
        return [spec, dd, ud]

    def _probs(self, wo: Array) -> list[Array]:
        ws = self._weights(wo)
        total = sum(ws)
        return [jnp.where(total > 0, safe_div(w, total), 1.0 / 3.0) for w in ws]

    def _dd_pdf(self, wi: Array, wo: Array) -> Array:
        alpha = self._alpha(wi.dtype)
        h = frames.half_vector(wi, wo)
        ch = jnp.maximum(h[..., 2], 1e-30)
        tan2 = safe_div(1.0 - ch * ch, ch * ch)
        d_cos = jnp.exp(-tan2 / (alpha * alpha)) / (jnp.pi * alpha * alpha * ch**3)
        oh = frames.dot(wo, h)
        return jnp.where((oh > 0) & (h[..., 2] > 0), safe_div(d_cos, 4.0 * oh), 0.0)

    def _sample_dd(self, wo: Array, u: Array) -> Array:
        alpha = self._alpha(wo.dtype)
        tan2 = -alpha * alpha * jnp.log1p(-jnp.minimum(u[..., 0], 1.0 - 1e-7))
        cos_h = 1.0 / jnp.sqrt(1.0 + tan2)
        sin_h = safe_sqrt(1.0 - cos_h * cos_h)
        phi = 2.0 * jnp.pi * u[..., 1]
        h = jnp.stack([sin_h * jnp.cos(phi), sin_h * jnp.sin(phi), cos_h], -1)
        return frames.reflect(wo, h)

    def _smooth_probs(self, wo: Array) -> tuple[Array, Array]:
        """Selection probabilities of the directional- and uniform-diffuse samplers among the
        non-delta part (they sum to 1)."""
        _, w_dd, w_ud = self._weights(wo)
        total = w_dd + w_ud
        p_dd = jnp.where(total > 0, safe_div(w_dd, total), 0.5)
        return p_dd, 1.0 - p_dd

    def _pdf(self, wi: Array, wo: Array) -> Array:
        # The non-delta part alone, normalized: what ``_sample`` draws (so HTSG inside a Sum is
        # consistent there, with its delta lobe never sampled). The public ``pdf`` and
        # ``sample`` scale it by the probability of not choosing the delta lobe.
        p_dd, p_ud = self._smooth_probs(wo)
        return p_dd * self._dd_pdf(wi, wo) + p_ud * warps.cosine_hemisphere_pdf(wi)

    def _sample(self, wo: Array, u: Array) -> Array:
        p_dd, p_ud = self._smooth_probs(wo)
        index, u0, _ = choose_lobe(u[..., 0], [p_dd, p_ud])
        uu = jnp.stack([u0, u[..., 1]], -1)
        return jnp.where(
            (index == 0)[..., None], self._sample_dd(wo, uu), warps.square_to_cosine_hemisphere(uu)
        )

    def pdf(self, wi: Array, wo: Array) -> Array:
        """Density of the non-delta samples of :meth:`sample` (integrates to ``1 - P(delta)``),
        the convention of :class:`~gonio.brdf.models.Sum` for lobes with a delta part."""
        p = super().pdf(wi, wo)
        wo_b = jnp.broadcast_to(jnp.asarray(wo, p.dtype), (*p.shape, 3))
        ok = upper(wo_b)
        wo_s = jnp.where(ok[..., None], wo_b, jnp.array([0.0, 0.0, 1.0], p.dtype))
        return p * (1.0 - self._probs(wo_s)[0])

    def sampling_weight(self, wo: Array) -> Array:
        return sum(self._weights(wo))

    def sample(self, wo: Array, u: Array) -> BRDFSample:
        wo, u = sample_inputs(wo, u)
        wo_s, ok_o = masked_outgoing(wo)

        index, u0, probs = choose_lobe(u[..., 0], self._weights(wo_s))
        uu = jnp.stack([u0, u[..., 1]], -1)
        wi = jnp.where(
            (index == 1)[..., None],
            self._sample_dd(wo_s, uu),
            warps.square_to_cosine_hemisphere(uu),
        )
        is_delta = index == 0
        wi = jnp.where(is_delta[..., None], frames.reflect(wo_s), wi)

        ok = ok_o & upper(wi) & ~is_delta
        wi_s, _ = safe_pair(wi, wo_s, ok)
        pdf = (1.0 - probs[0]) * self._pdf(wi_s, wo_s)
        ok = ok & (pdf > 0)
        val = self._f(wi_s, wo_s)
        weight = jnp.where(ok[..., None], safe_div(val * wi_s[..., 2:3], pdf[..., None]), 0.0)
        pdf = jnp.where(ok, pdf, 0.0)

        delta_w = safe_div(self.specular_reflectance(wo_s), probs[0][..., None])
        pdf = jnp.where(is_delta, jnp.where(ok_o, probs[0], 0.0), pdf)
        weight = jnp.where(is_delta[..., None] & ok_o[..., None], delta_w, weight)
        return BRDFSample(wi, pdf.astype(wo.dtype), weight.astype(wo.dtype), is_delta & ok_o)
