"""An RGL-EPFL tensor file as a gonio BRDF: exact evaluation and sampling through its own warps.

:func:`gonio.io.load` returns a :class:`RGLMeasured` for a ``.bsdf`` file. It evaluates the file
as the file defines it (Dupuy & Jakob 2018; the ``measured`` plugin of Mitsuba 3 is the reference
reader) and implements the interface of every gonio BRDF (:class:`~gonio.brdf.models.BRDFModel`):
``f``, ``pdf``, ``sample``, ``directional_albedo``. It is pure JAX and a registered pytree, so the
renderer traces it into its kernels and ``jax.jit`` takes it as an argument.

Evaluation
----------
The file's fields are checked by :meth:`gonio.io.rgl.RGLFile.from_fields`; its four tables are
continuous 2-D warps (:mod:`gonio.brdf.sampling.marginal2d`). ``F(w_c, w_s)`` is computed as the
reference reader computes it:

1. the half vector ``m = normalize(w_c + w_s)`` and ``w_c`` are turned into unit coordinates
   ``u(theta) = sqrt(2 theta / pi)``, ``u(phi) = (phi + pi) / (2 pi)`` (for isotropic data the
   half vector's azimuth is taken relative to ``phi_c`` and wrapped to [0, 1));
2. the ``vndf`` warp, linearly interpolated in the parameters ``(phi_c, theta_c)``, is
   *inverted* at ``u(m)``;
3. the colour table (``rgb`` or ``spectra``) is bilinearly interpolated at the resulting point,
   conditioned on ``(phi_c, theta_c)``, at each channel;
4. if ``jacobian`` is set the value is multiplied by ``ndf(u(m)) / (4 sigma(u(w_c)))``.

Argument order
--------------
A tensor file tabulates ``F(w_c, w_s) = f_r cos(theta_s)`` conditioned on one direction ``w_c``
(its ``theta_i``, ``phi_i`` axes) and warped over the other, ``w_s``. Mitsuba evaluates it as
``eval(si.wi = w_c, wo = w_s)``, with ``si.wi`` pointing toward the camera in a path tracer and
``wo`` the sampled direction toward the light. gonio's ``f(wi, wo)`` has ``wi`` toward the light
and ``wo`` toward the viewer, so::

    gonio f(wi, wo) = F(w_c = wo, w_s = wi) / cos(theta_i)
                    = Mitsuba eval(si.wi = wo, wo = wi) / cos(theta_i)

which renders exactly what Mitsuba renders, and lets ``sample(wo, u)`` draw ``wi`` through the
file's warps conditioned on ``wo``, as Mitsuba's ``sample`` does (the test suite states this
order explicitly against Mitsuba).

Sampling
--------
``u`` (swapped, as the reference does) is warped by the ``luminance`` distribution, then by the
``vndf`` warp to the half vector's unit coordinates ``(u_theta, u_phi)`` (azimuth relative to
``wo``'s for isotropic files), and ``wi`` is the reflection of ``wo`` about that half vector. The
density is ``p_vndf(u_m) p_lum(s) / (2 pi^2 u_theta sin(theta_m) 4 (wo . m))`` per unit solid
angle (the reference's Jacobian, including its floor of 1e-6), and :meth:`pdf` computes the same
number by inverting the ``vndf`` warp. ``weight = F / pdf = f cos(theta_i) / pdf``.

Negative values
---------------
Some files hold slightly negative RGB values (colours outside the sRGB gamut reconstructed from
the measured spectra, and noise in dark cells: 3-5 % of the vinyl films' entries, down to -0.04).
By default (``negative="keep"``) ``f`` and the sample weights keep them, as the reference reader
does, so evaluations and renders equal Mitsuba's; sampling is unaffected (the ``luminance`` and
``vndf`` warps are non-negative) and a render's pixels can be slightly negative only where the
file itself is. ``negative="clamp"`` clamps the colour table at 0 when the file is loaded: then
``f >= 0`` everywhere, at the cost of no longer matching the reference reader there.
A colour table whose minimum is below ``-0.1`` times its largest magnitude
(:data:`gonio.io.rgl.COLOUR_NEGATIVE_TOLERANCE`) is refused when the file is read: no
measurement gives that (a sign-flipped or corrupted payload does).

Colour
------
RGB files give three channels (linear sRGB, as stored). Spectral files keep their wavelengths as
channels; with ``color="rgb"`` the spectra are converted to linear sRGB through CIE 1931 XYZ under
the given illuminant (:mod:`gonio.io.spectral`; a flat spectrum ``c`` maps to ``(c, c, c)`` under
D65), applied to ``f`` after interpolation (the conversion is linear, so this equals converting
the table).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf._xla import materialize
from gonio.brdf.frames import upper
from gonio.brdf.lookup import atan2 as _atan2  # exact in float64, fast polynomial in float32
from gonio.brdf.models._base import (
    BRDFModel,
    BRDFSample,
    as_float,
    clamp_u,
    masked_outgoing,
)
from gonio.brdf.sampling import marginal2d as w2
from gonio.errors import ParameterError
from gonio.io._common import PathLike

Array = jnp.ndarray

NEGATIVE_POLICIES = ("keep", "clamp")


@dataclass(frozen=True)
class _Static:
    """Hashable description of a loaded file (pytree aux data)."""

    isotropic: bool
    jacobian: bool
    reduction: int
    wavelengths: tuple[float, ...]
    spectral: bool
    to_rgb: bool
    # provenance only: not part of the function (equal files share compiled kernels)
    path: str = field(compare=False)
    description: str = field(compare=False)
    negative: str = field(compare=False)
    out_wavelengths: tuple[float, ...] | None  # output channels' wavelengths (None: RGB)


def _elevation(d: Array) -> Array:
    """Polar angle of unit vectors, stable near the pole: the reference reader's formula in
    float64; in float32 ``atan2(hypot(x, y), z)`` (as stable; XLA's float32 ``asin`` is slow)."""
    if d.dtype == jnp.float64:
        dist = jnp.sqrt(d[..., 0] ** 2 + d[..., 1] ** 2 + (d[..., 2] - 1.0) ** 2)
        return 2.0 * jnp.arcsin(jnp.clip(0.5 * dist, -1.0, 1.0))
    return _atan2(jnp.sqrt(d[..., 0] ** 2 + d[..., 1] ** 2), d[..., 2])


def _theta2u(theta: Array) -> Array:
    return jnp.sqrt(theta * (2.0 / math.pi))


def _phi2u(phi: Array) -> Array:
    return (phi + math.pi) * (1.0 / (2.0 * math.pi))


def _mulsign_neg(x: Array, s: Array) -> Array:
    """``x * -sign(s)`` with sign(+0) = +1 (the reference's fold into the tabulated wedge)."""
    return jnp.where(s >= 0, -x, x)


class RGLMeasured(BRDFModel):
    """A measured BSDF from an RGL ``tensor_file`` (see the module docstring).

    Build with :func:`load_rgl` (or :func:`gonio.io.load`). ``channels`` is the channel count C
    (the :class:`BRDFModel` convention); :attr:`channel_info` is the full description (names,
    wavelengths).
    """

    PARAMS = ()

    #: ``f``, ``pdf`` and ``sample`` take ``wo`` with size-1 axes where ``wi`` or ``u`` have
    #: more (``(P, 1, 3)`` against ``(P, S, 3)``), and then compute what depends on ``wo`` alone
    #: (its angles, the slice interpolation of every table, ``sigma``) once per ``wo``. The
    #: renderer passes its per-pixel outgoing direction so.
    broadcasts_outgoing = True

    def __init__(self, *args: Any, **kwargs: Any) -> None:  # pragma: no cover - guidance only
        raise ParameterError("build RGLMeasured with gonio.io.rgl_measured.load_rgl(path)")

    # -- pytree: leaves are the warps and the colour matrix; aux is _Static ---------------------
    def _tree_flatten(self):
        leaves = (self._ndf, self._sigma, self._vndf, self._lum, self._colour, self._matrix)
        return leaves, (self._static,)

    @classmethod
    def _tree_unflatten(cls, aux, leaves):
        obj = object.__new__(cls)
        (obj._ndf, obj._sigma, obj._vndf, obj._lum, obj._colour, obj._matrix) = leaves
        (obj._static,) = aux
        return obj

    @classmethod
    def _from_parts(cls, static: _Static, ndf, sigma, vndf, lum, colour, matrix) -> RGLMeasured:
        return cls._tree_unflatten((static,), (ndf, sigma, vndf, lum, colour, matrix))

    # -- description --------------------------------------------------------------------------
    @property
    def channels(self) -> int:
        return int(self._matrix.shape[1])

    @property
    def n_channels(self) -> int:
        return self.channels

    @property
    def channel_info(self) -> Any:
        """:class:`~gonio.brdf.tabulated.Channels` of the output (RGB or spectral)."""
        from gonio.brdf.tabulated import Channels

        if self._static.out_wavelengths is not None:
            return Channels.spectral(np.asarray(self._static.out_wavelengths))
        if self.channels == 3:
            return Channels.rgb()
        return Channels.for_count(self.channels)

    @property
    def isotropic(self) -> bool:
        return self._static.isotropic

    @property
    def path(self) -> str:
        return self._static.path

    @property
    def description(self) -> str:
        return self._static.description

    @property
    def meta(self) -> dict[str, Any]:
        """Provenance (used by the fitter to name its data)."""
        return {
            "source": {
                "format": "rgl-tensor",
                "file": self._static.path,
                "description": self._static.description,
                "negative": self._static.negative,
            }
        }

    def __repr__(self) -> str:
        kind = "spectral" if self._static.spectral else "RGB"
        return f"RGLMeasured({self._static.path!r}, {kind}, C={self.channels})"

    def to_dict(self) -> dict[str, Any]:
        return {"type": "RGLMeasured", "file": self._static.path}

    # -- the file's function ------------------------------------------------------------------
    def _fold(self, wc: Array, ws: Array) -> tuple[Array, Array, Array, Array]:
        """Mirror both directions into the tabulated wedge (anisotropic files with symmetry)."""
        red = self._static.reduction
        if red < 2:
            return wc, ws, None, None
        sy = wc[..., 1]
        sx = wc[..., 0] if red == 4 else sy

        def fold(w):
            return jnp.stack(
                [_mulsign_neg(w[..., 0], sx), _mulsign_neg(w[..., 1], sy), w[..., 2]], -1
            )

        return fold(wc), fold(ws), sx, sy

    def _cond(self, wc: Array) -> tuple[Array, Array, Array]:
        theta_c = _elevation(wc)
        phi_c = _atan2(wc[..., 1], wc[..., 0])
        return theta_c, phi_c, jnp.stack([_theta2u(theta_c), _phi2u(phi_c)], -1)

    def _colour_at(self, pos: Array, phi_c: Array, theta_c: Array) -> Array:
        """Colour table at a sample-space point, conditioned on ``w_c``: ``(..., C)``."""
        val = w2.eval_channels(self._colour, pos, (phi_c, theta_c))
        if self._static.to_rgb:
            val = val @ self._matrix.astype(val.dtype)
        return val

    def _jacobian(self, u_m: Array, u_c: Array) -> Array:
        jac = w2.eval_warp(self._ndf, u_m) / (4.0 * w2.eval_warp(self._sigma, u_c))
        # Stored once before it scales the C channels (and the pdf likewise before it divides
        # them): XLA:CPU otherwise recomputes the lookups inside the channels' loop, once per
        # channel (render times of RGL files: benchmarks/bench_rgl.py).
        (jac,) = materialize([jac], u_m[..., 0])
        return jac

    def _half(self, wc: Array, ws: Array):
        m = wc + ws
        m = m / jnp.maximum(jnp.linalg.norm(m, axis=-1, keepdims=True), 1e-30)
        theta_c, phi_c, u_c = self._cond(wc)
        theta_m = _elevation(m)
        phi_m = _atan2(m[..., 1], m[..., 0])
        um1 = _phi2u(phi_m - phi_c if self._static.isotropic else phi_m)
        u_m = jnp.stack([_theta2u(theta_m), um1 - jnp.floor(um1)], -1)
        return m, theta_m, theta_c, phi_c, u_c, u_m

    def f_cos(self, wc: Array, ws: Array) -> Array:
        """The tabulated ``F(w_c, w_s) = f_r cos(theta_s)``, ``(..., C)``, in the file's own
        argument order (``w_c`` is the direction the tables are conditioned on; Mitsuba's
        ``si.wi``). No horizon test."""
        wc, ws, _, _ = self._fold(wc, ws)
        _, _, theta_c, phi_c, u_c, u_m = self._half(wc, ws)
        pos, _ = w2.invert(self._vndf, u_m, (phi_c, theta_c))
        val = self._colour_at(pos, phi_c, theta_c)
        if self._static.jacobian:
            val = val * self._jacobian(u_m, u_c)[..., None]
        return val

    def _f(self, wi: Array, wo: Array) -> Array:
        return self.f_cos(wo, wi) / wi[..., 2:3]

    def _pdf(self, wi: Array, wo: Array) -> Array:
        wc, ws, _, _ = self._fold(wo, wi)
        m, theta_m, theta_c, phi_c, _, u_m = self._half(wc, ws)
        pos, p_vndf = w2.invert(self._vndf, u_m, (phi_c, theta_c))
        p_lum = w2.eval_warp(self._lum, pos, (phi_c, theta_c))
        jac = _measure(u_m[..., 0], theta_m, jnp.sum(wc * m, -1))
        return p_vndf * p_lum / jac

    def _sample_all(self, wo: Array, u: Array) -> tuple[Array, Array, Array]:
        """``(wi, pdf, F)`` for outgoing ``wo`` above the horizon; ``F = f cos(theta_i)``."""
        wc = wo
        red = self._static.reduction
        if red >= 2:
            sy = wc[..., 1]
            sx = wc[..., 0] if red == 4 else sy
            wc = jnp.stack(
                [_mulsign_neg(wc[..., 0], sx), _mulsign_neg(wc[..., 1], sy), wc[..., 2]], -1
            )
        theta_c, phi_c, u_c = self._cond(wc)
        params = (phi_c, theta_c)
        s, p_lum = w2.sample(self._lum, jnp.stack([u[..., 1], u[..., 0]], -1), params)
        u_m, p_vndf = w2.sample(self._vndf, s, params)
        phi_m = (2.0 * u_m[..., 1] - 1.0) * math.pi
        theta_m = u_m[..., 0] ** 2 * (math.pi / 2)
        if self._static.isotropic:
            phi_m = phi_m + phi_c
        st = jnp.sin(theta_m)
        m = jnp.stack([jnp.cos(phi_m) * st, jnp.sin(phi_m) * st, jnp.cos(theta_m)], -1)
        dot = jnp.sum(wc * m, -1)
        wi = 2.0 * dot[..., None] * m - wc
        pdf = p_vndf * p_lum / _measure(u_m[..., 0], theta_m, dot)
        val = self._colour_at(s, phi_c, theta_c)
        if self._static.jacobian:
            val = val * self._jacobian(u_m, u_c)[..., None]
        if red >= 2:
            wi = jnp.stack(
                [_mulsign_neg(wi[..., 0], sx), _mulsign_neg(wi[..., 1], sy), wi[..., 2]], -1
            )
        return wi, pdf, val

    def _sample(self, wo: Array, u: Array) -> Array:
        return self._sample_all(wo, u)[0]

    def f(self, wi: Any, wo: Any) -> Array:
        """BRDF in sr^-1, ``(..., 3), (..., 3) -> (..., C)``; 0 on or below the horizon.
        ``f(wi, wo) = F(w_c = wo, w_s = wi) / cos(theta_i)`` (module docstring)."""
        return _f_jit(self, *_dirs(wi, wo))

    def pdf(self, wi: Any, wo: Any) -> Array:
        """Density of :meth:`sample` over ``wi`` per unit solid angle, ``(...)``."""
        return _pdf_jit(self, *_dirs(wi, wo))

    def sample(self, wo: Any, u: Any) -> BRDFSample:
        """Draw ``wi`` for ``wo`` ``(..., 3)`` from ``u`` ``(..., 2)`` through the file's
        luminance and VNDF warps; ``weight = f cos(theta_i) / pdf``."""
        wo = as_float(wo)
        u = clamp_u(as_float(u, wo.dtype))
        # u spans the whole batch; wo keeps its size-1 axes (see broadcasts_outgoing)
        u = jnp.broadcast_to(u, (*jnp.broadcast_shapes(wo.shape[:-1], u.shape[:-1]), 2))
        return _sample_jit(self, wo, u)

    def _f_public(self, wi: Array, wo: Array) -> Array:
        ok_i, ok_o = upper(wi), upper(wo)
        val = self._f(_safe(wi, ok_i), _safe(wo, ok_o))
        ok = ok_i & ok_o
        return jnp.where(ok[..., None], val, 0.0).astype(wi.dtype)

    def _pdf_public(self, wi: Array, wo: Array) -> Array:
        ok_i, ok_o = upper(wi), upper(wo)
        return jnp.where(ok_i & ok_o, self._pdf(_safe(wi, ok_i), _safe(wo, ok_o)), 0.0)

    def _sample_public(self, wo: Array, u: Array) -> BRDFSample:
        wo_s, ok_o = masked_outgoing(wo)
        wi, pdf, val = self._sample_all(wo_s, u)
        ok = ok_o & (wi[..., 2] > 0) & (pdf > 0) & jnp.isfinite(pdf)
        (pdf,) = materialize([jnp.where(ok, pdf, 0.0)], pdf)
        weight = jnp.where(ok[..., None], val / jnp.where(ok, pdf, 1.0)[..., None], 0.0)
        return BRDFSample(
            wi.astype(wo.dtype),
            pdf.astype(wo.dtype),
            weight.astype(wo.dtype),
            jnp.zeros(ok.shape, bool),
        )

    def sampling_weight(self, wo: Array) -> Array:
        """Lobe-selection weight in a sum of lobes: 1 (the file's albedo is not precomputed)."""
        return jnp.ones(wo.shape[:-1], wo.dtype)

    def directional_albedo(self, wo: Any, n: int = 128) -> Array:
        """``int f cos dwi`` at ``wo`` ``(..., 3)`` -> ``(..., C)``: the mean sample weight
        over a stratified ``n x n`` grid of ``u`` (deterministic)."""
        return super().directional_albedo(wo, n)

    # -- conversions ----------------------------------------------------------------------------
    def select_channels(self, idx: Any) -> RGLMeasured:
        """The same BSDF with only the output channels ``idx`` (used by the renderer)."""
        idx = [int(i) for i in np.atleast_1d(idx)]
        st = self._static
        matrix = jnp.asarray(np.asarray(self._matrix)[:, idx])
        wl = None if st.out_wavelengths is None else tuple(st.out_wavelengths[i] for i in idx)
        static = _Static(**{**st.__dict__, "to_rgb": True, "out_wavelengths": wl})
        return self._from_parts(
            static, self._ndf, self._sigma, self._vndf, self._lum, self._colour, matrix
        )

    def to_table(self, *args: Any, **kwargs: Any) -> Any:
        """Resample onto a half/diff grid (:func:`gonio.io.rgl_table.tabulate`, which takes
        the arguments); this is the only place where the file is resampled."""
        from gonio.io.rgl_table import tabulate

        return tabulate(self, *args, **kwargs)

    def to_samples(self, theta_max_deg: float = 90.0) -> Any:
        """The file's own nodes as :class:`~gonio.brdf.measured.MeasuredSamples` (for fits).

        For each tabulated conditioning angle ``theta_i`` (``wo`` at ``phi = 0`` for isotropic
        files, every ``phi_i`` otherwise) the colour grid's nodes, taken as positions in the
        ``vndf`` warp's sample space, are mapped through the warp to half vectors and reflected
        into ``wi``: these are the direction pairs where the file stores its values, and
        ``values`` is ``f`` there (exact). ``weights`` approximate the measure of each node's
        cell in sr^2: the trapezoid weight of the node in sample space divided by the warp's
        density per solid angle of ``wi``, times the solid angle of the ``wo`` band (trapezoid in
        ``cos theta``, times ``2 pi`` for isotropic files). Pairs whose ``wi`` falls below the
        horizon or beyond ``theta_max_deg`` are dropped.
        """
        from gonio.brdf.measured import MeasuredSamples

        fields_theta = np.asarray(self._vndf.params[1])
        fields_phi = np.asarray(self._vndf.params[0])
        n = int(self._colour.shape.shape[0])
        g = np.linspace(0.0, 1.0, n)
        tw = np.full(n, 1.0 / (n - 1))
        tw[[0, -1]] *= 0.5
        sx, sy = np.meshgrid(g, g, indexing="xy")
        area = np.outer(tw, tw).ravel()
        pos = np.stack([sx.ravel(), sy.ravel()], -1)
        cos_nodes = np.cos(fields_theta.astype(np.float64))
        band = _trapezoid_weights(cos_nodes)
        phis = [0.0] if self._static.isotropic else list(fields_phi.astype(np.float64))
        dphi = 2 * math.pi if self._static.isotropic else 2 * math.pi / max(len(phis), 1)
        wis, wos, ws = [], [], []
        for k, th in enumerate(fields_theta.astype(np.float64)):
            th = min(max(th, 1e-4), math.radians(min(theta_max_deg, 89.9)))
            for ph in phis:
                wo = np.array(
                    [math.sin(th) * math.cos(ph), math.sin(th) * math.sin(ph), math.cos(th)]
                )
                wo_b = jnp.broadcast_to(jnp.asarray(wo), (pos.shape[0], 3))
                wi, dens = self._warp_nodes(wo_b, jnp.asarray(pos))
                wis.append(np.asarray(wi))
                wos.append(np.broadcast_to(wo, wi.shape))
                ws.append(area / np.maximum(np.asarray(dens), 1e-300) * band[k] * dphi)
        wi = np.concatenate(wis)
        wo = np.concatenate(wos)
        w = np.concatenate(ws)
        cmax = math.cos(math.radians(theta_max_deg)) if theta_max_deg < 90 else 0.0
        keep = (wi[:, 2] > max(cmax, 1e-6)) & np.isfinite(w)
        wi, wo, w = wi[keep], wo[keep], w[keep]
        vals = np.asarray(self.f(wi, wo))
        meta = {**self.meta, "converted_from": "RGL tensor file nodes (exact f)"}
        return MeasuredSamples(wi, wo, vals, None, self.channel_info, w, meta)

    @jax.jit
    def _warp_nodes(self, wo: Array, pos: Array) -> tuple[Array, Array]:
        theta_c, phi_c, _ = self._cond(wo)
        u_m, p_vndf = w2.sample(self._vndf, pos, (phi_c, theta_c))
        phi_m = (2.0 * u_m[..., 1] - 1.0) * math.pi + (phi_c if self._static.isotropic else 0.0)
        theta_m = u_m[..., 0] ** 2 * (math.pi / 2)
        st = jnp.sin(theta_m)
        m = jnp.stack([jnp.cos(phi_m) * st, jnp.sin(phi_m) * st, jnp.cos(theta_m)], -1)
        dot = jnp.sum(wo * m, -1)
        wi = 2.0 * dot[..., None] * m - wo
        return wi, p_vndf / _measure(u_m[..., 0], theta_m, dot)


def _dirs(wi: Any, wo: Any) -> tuple[Array, Array]:
    """Both directions as floats of one dtype; not broadcast (see ``broadcasts_outgoing``)."""
    wi, wo = as_float(wi), as_float(wo)
    if wi.shape[-1:] != (3,) or wo.shape[-1:] != (3,):
        raise ParameterError(f"directions must have shape (..., 3), got {wi.shape}, {wo.shape}")
    dtype = jnp.result_type(wi, wo)
    return wi.astype(dtype), wo.astype(dtype)


def _safe(w: Array, ok: Array) -> Array:
    """``w`` with the directions at or below the horizon replaced by the normal (the code
    never sees degenerate input; gradients stay finite)."""
    return jnp.where(ok[..., None], w, jnp.array([0.0, 0.0, 1.0], w.dtype))


# jit at the public boundary (called eagerly, op-by-op dispatch of the warps would dominate;
# under an outer jit these are inlined)
_f_jit = jax.jit(RGLMeasured._f_public)
_pdf_jit = jax.jit(RGLMeasured._pdf_public)
_sample_jit = jax.jit(RGLMeasured._sample_public)


def _measure(u_theta: Array, theta_m: Array, dot: Array) -> Array:
    """The reference's Jacobian from unit half-vector coordinates to the solid angle of the
    reflected direction: ``max(2 pi^2 u_theta sin theta_m, 1e-6) * 4 (w_c . m)``."""
    return jnp.maximum(2.0 * math.pi**2 * u_theta * jnp.sin(theta_m), 1e-6) * 4.0 * dot


def _trapezoid_weights(x: np.ndarray) -> np.ndarray:
    """Trapezoid-rule weights of the nodes ``x`` (any order) over their range."""
    order = np.argsort(x)
    xs = x[order]
    w = np.zeros_like(xs)
    if xs.size > 1:
        d = np.diff(xs)
        w[:-1] += 0.5 * d
        w[1:] += 0.5 * d
    out = np.empty_like(w)
    out[order] = w
    return out


def load_rgl(
    path: PathLike,
    *,
    negative: str = "keep",
    color: str | None = None,
    illuminant: str = "D65",
) -> RGLMeasured:
    """Read an RGL ``.bsdf`` file as an exact :class:`RGLMeasured` (milliseconds).

    Parameters
    ----------
    path : the tensor file.
    negative : ``"keep"`` (default: the file's values as they are, like the reference reader) or
        ``"clamp"`` (colour table clamped at 0); see the module docstring.
    color : ``None``/``"keep"``/``"spectral"`` keep the file's channels; ``"rgb"`` converts
        spectral files to linear sRGB (RGB files are unchanged).
    illuminant : ``"D65"`` or ``"E"``, for ``color="rgb"`` on spectral files.

    Raises
    ------
    FormatError
        A malformed file: one line naming the file and the offending field.
    """
    from gonio.io.rgl import read_rgl

    if negative not in NEGATIVE_POLICIES:
        raise ParameterError(f"negative must be one of {NEGATIVE_POLICIES}, got {negative!r}")
    if color not in (None, "keep", "spectral", "rgb"):
        raise ParameterError(f"color must be 'rgb', 'spectral' or 'keep', got {color!r}")
    bsdf = read_rgl(path)
    return from_rgl_file(bsdf, negative=negative, color=color, illuminant=illuminant)


def from_rgl_file(
    bsdf: Any, *, negative: str = "keep", color: str | None = None, illuminant: str = "D65"
) -> RGLMeasured:
    """:class:`RGLMeasured` from a checked :class:`gonio.io.rgl.RGLFile` (options as
    :func:`load_rgl`)."""
    f = bsdf.fields
    phi_i = f["phi_i"].astype(np.float64)
    theta_i = f["theta_i"].astype(np.float64)
    params = [phi_i, theta_i]
    colour = f["spectra"] if bsdf.spectral else f["rgb"]
    if negative == "clamp":
        colour = np.maximum(colour, 0.0)
    wl = np.asarray(bsdf.wavelengths, np.float64)
    to_rgb = bool(color == "rgb" and bsdf.spectral)
    if to_rgb:
        from gonio.io.spectral import spectral_to_rgb_matrix

        matrix = spectral_to_rgb_matrix(wl, illuminant)
    else:
        matrix = np.eye(len(wl))
    static = _Static(
        isotropic=bool(bsdf.isotropic),
        jacobian=bool(bsdf.jacobian),
        reduction=int(bsdf.reduction),
        wavelengths=tuple(float(x) for x in wl),
        spectral=bool(bsdf.spectral),
        to_rgb=to_rgb,
        path=bsdf.path,
        description=bsdf.description,
        negative=negative,
        out_wavelengths=tuple(float(x) for x in wl) if bsdf.spectral and not to_rgb else None,
    )
    return RGLMeasured._from_parts(
        static,
        w2.build(f["ndf"], [], cdf=False),
        w2.build(f["sigma"], [], cdf=False),
        w2.build(f["vndf"], params, cdf=True),
        w2.build(f["luminance"], params, cdf=True),
        w2.build_channels(colour, params),
        jnp.asarray(matrix),
    )
