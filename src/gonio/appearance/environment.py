"""The appearance score's environment: a generated studio, and the fixed estimator of its image.

The environment (:func:`studio_radiance`) is computed, not read from a file: a sky gradient, a
ground, and two soft round area lights (a key light above left in front, a rim light at the
right behind), with edges blended over about ten degrees so that a mirror-like sphere shows
smooth highlights. Radiance in the world frame of :mod:`gonio.appearance.scene` (y up, camera on
+z); linear RGB.

The pixel value under it is ``L_o = integral L(wi) f(wi, wo) cos theta_i dwi`` over the local
upper hemisphere. It is estimated by :func:`estimate` with a fixed, material-independent mixture
of proposals, so that any material (a table, a fit with any lobe width) is integrated by the same
rule:

* cosine-weighted hemisphere directions (diffuse-like parts), and
* half vectors from cosine-power lobes ``(m + 1) / (2 pi) cos^m theta_h`` with ``m`` in
  :data:`LOBE_EXPONENTS` (10 to 1e6: from broad gloss to a near-mirror), reflected about ``h``,

with the same number of samples from each proposal per pixel and the balance heuristic
(multi-sample MIS: every sample divided by the mixture's density), which is unbiased for every
``f``. The uniform numbers are a fixed-seed stratified set (:func:`uniforms`) shared by the
measured and the fitted sphere, so that both images are estimated at the same directions and most
of the noise cancels in their difference. The sample count was chosen so that the noise of the
score is a tenth of the differences it ranks (``benchmarks/bench_appearance.py`` measures it
with two seeds and reports the ratio).
"""

from __future__ import annotations

import numpy as np

#: Exponents of the half-vector cosine-power proposals.
LOBE_EXPONENTS = (10.0, 100.0, 1e3, 1e4, 1e5, 1e6)

#: Number of proposals (cosine + the lobes).
N_PROPOSALS = 1 + len(LOBE_EXPONENTS)

#: Default samples per pixel (a multiple of :data:`N_PROPOSALS`).
DEFAULT_SAMPLES = 16 * N_PROPOSALS

# (unit direction toward the light's centre, RGB radiance, cos of the inner and outer radius)
_LIGHTS = (
    ((-0.6, 0.6, 0.52), (9.0, 8.6, 8.0), np.cos(np.radians(12.0)), np.cos(np.radians(24.0))),
    ((0.85, 0.25, -0.45), (3.5, 3.8, 4.2), np.cos(np.radians(8.0)), np.cos(np.radians(20.0))),
)
_SKY_ZENITH = np.array([0.30, 0.36, 0.46])
_SKY_HORIZON = np.array([0.55, 0.55, 0.55])
_GROUND = np.array([0.12, 0.10, 0.08])


def _smoothstep(e0, e1, x, xp):
    t = xp.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def studio_radiance(w, xp=np):
    """Radiance of the studio toward world directions ``w`` ``(..., 3)`` -> ``(..., 3)`` RGB.

    ``xp`` is the array module (NumPy, or ``jax.numpy`` inside a jitted kernel).
    """
    y = w[..., 1:2]
    sky = _SKY_HORIZON + (_SKY_ZENITH - _SKY_HORIZON) * xp.clip(y, 0.0, 1.0)
    ground_mix = _smoothstep(-0.05, 0.05, y, xp)
    out = _GROUND + (sky - _GROUND) * ground_mix
    for d, rgb, c_in, c_out in _LIGHTS:
        d = np.asarray(d) / np.linalg.norm(d)
        c = (w * d).sum(-1, keepdims=True)
        out = out + np.asarray(rgb) * _smoothstep(c_out, c_in, c, xp)
    return out


def uniforms(n_pixels: int, samples: int, seed: int = 0) -> np.ndarray:
    """``(n_pixels, samples, 2)`` float32 uniforms in [0, 1) from a fixed seed (NumPy PCG64):
    per pixel and proposal, a Latin hypercube (each axis stratified into as many intervals as
    the proposal has samples, one sample in each, jittered), which is unbiased for any count."""
    per = samples // N_PROPOSALS
    rng = np.random.default_rng(seed)
    cells = np.tile(np.arange(per), (n_pixels, N_PROPOSALS, 1))
    axes = [(rng.permuted(cells, axis=-1) + rng.random(cells.shape)) / per for _ in range(2)]
    u = np.stack(axes, -1).transpose(0, 2, 1, 3)  # (P, per, proposals, 2): s % N = proposal
    return np.clip(u.reshape(n_pixels, samples, 2), 0.0, 1.0 - 1e-7).astype(np.float32)


def directions(wo, u, xp):
    """Sample directions ``(P, S, 3)`` (local frames) for outgoing ``wo (P, 3)``, uniforms
    ``u (P, S, 2)``: sample ``s`` comes from proposal ``s % N_PROPOSALS``."""
    s = u.shape[1]
    which = np.arange(s) % N_PROPOSALS
    u0, u1 = u[..., 0], u[..., 1]
    phi = 2.0 * np.pi * u1
    # cosine hemisphere
    r = xp.sqrt(u0)
    cos_d = xp.sqrt(xp.clip(1.0 - u0, 0.0, 1.0))
    wi_cos = xp.stack([r * xp.cos(phi), r * xp.sin(phi), cos_d], -1)
    # power lobes about the normal for h, reflected about h
    m = np.array([0.0, *LOBE_EXPONENTS])[which]
    cos_h = xp.exp(xp.log(xp.maximum(u0, 1e-30)) / (m + 1.0))
    sin_h = xp.sqrt(xp.clip(1.0 - cos_h * cos_h, 0.0, 1.0))
    h = xp.stack([sin_h * xp.cos(phi), sin_h * xp.sin(phi), cos_h], -1)
    wo_b = wo[:, None, :]
    wi_lobe = 2.0 * (wo_b * h).sum(-1, keepdims=True) * h - wo_b
    return xp.where((which == 0)[None, :, None], wi_cos, wi_lobe)


def mixture_pdf(wi, wo, xp):
    """Density per unit solid angle of the proposal mixture at ``wi`` for ``wo``, ``(...)``."""
    p = xp.maximum(wi[..., 2], 0.0) / np.pi
    h = wi + wo
    h = h / xp.maximum(xp.sqrt((h * h).sum(-1, keepdims=True)), 1e-30)
    ch = xp.clip(h[..., 2], 0.0, 1.0)
    oh = xp.maximum((wo * h).sum(-1), 1e-12)
    log_ch = xp.log(xp.maximum(ch, 1e-30))
    for m in LOBE_EXPONENTS:
        p = p + (m + 1.0) / (2.0 * np.pi) * xp.exp(m * log_ch) / (4.0 * oh)
    return p / N_PROPOSALS
