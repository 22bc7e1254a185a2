"""Write RGL ``tensor_file`` BSDFs (Dupuy & Jakob 2018) from any isotropic gonio BRDF.

A tensor file stores ``F(w_c, w_s) = f_r cos(theta_s)`` as ``rgb(s) * D(m) / (4 sigma(w_c))``
where ``m`` is the half vector, ``s`` the point of the unit square that the file's ``vndf`` warp
maps to ``m`` (conditioned on ``w_c``), ``D`` the microfacet distribution (``ndf``) and
``sigma(w) = int D(m) max(0, w . m) dm`` its projected area. This module builds every field from a
source with ``f(wi, wo)`` (gonio's argument order; the file is conditioned on ``wo``, see
:mod:`gonio.io.rgl_measured`):

1. **NDF** (``ndf``, 2 x 128 over ``(u_phi, u_theta)``, ``u_theta = sqrt(2 theta / pi)``): from the
   retro-reflection ``f(w, w)``. For a microfacet BRDF with Smith's ``G1(w) = cos(theta) /
   sigma(w)`` and a slowly varying Fresnel term, ``f(w, w) = F D(w) / (4 sigma(w)^2)``, so
   ``D`` is the fixed point of ``D <- f(w, w) sigma[D](w)^2`` normalized by ``int D cos = 1``
   (the relation of Dupuy et al. 2015, solved by damped fixed-point iteration instead of their
   power iteration; 40 iterations, geometric-mean damping), then softened to ``D^0.75``
   (renormalized). Any positive ``D`` gives a valid file: the colour table holds the rest of the
   function. The estimated ``D`` makes the ``vndf`` warp follow the specular lobe, so the colour
   table is smooth there; the softening keeps part of the colour grid for the tails of sharp
   lobes (for GGX at alpha 0.05 it takes the 95th-percentile error over directions up to 80 deg
   from 42 % with a 20 % uniform share, or far more without, to 3 %).
2. **sigma** (2 x 128): the projected area of the interpolated ``D`` by quadrature.
3. **vndf** (1 x 16 x 128 x 128 over ``(theta_i, u_phi, u_theta)``): the visible-normal density
   ``D(m) max(0, w_c . m)`` times the Jacobian ``2 pi^2 u_theta sin(theta_m)`` of the unit
   coordinates, with ``u_phi`` relative to ``w_c``'s azimuth.
4. **rgb** (1 x 16 x 3 x 32 x 32, or ``spectra`` + ``wavelengths``): at each node ``s`` of the
   unit square, ``F(w_c, w_s) 4 sigma(w_c) / D(m)`` with ``m`` the image of ``s`` under the
   ``vndf`` warp (computed with the same warp code that reads the file) and ``w_s`` the reflection
   of ``w_c`` about ``m``; 0 where ``w_s`` is below the horizon.
5. **luminance** (1 x 16 x 32 x 32): the Rec. 709 luminance of the colour table (its mean for mono
   and the CIE Y weights for spectral data), clamped at a small positive floor, the density that
   sampling warps the unit square with first.

``theta_i`` holds 16 conditioning angles, every 6.7 deg from 0 to 80 deg, then 84, 87 and 89 deg
(the last one off the horizon, where ``f`` is not defined; beyond it the reader clamps). The
database's files have 8, uniform in ``cos``; the colour table is interpolated linearly between
slices, and 8 leave errors of 5-20 % between them for glossy sources at normal and grazing
incidence. ``phi_i`` is ``[0]`` (isotropic). ``jacobian`` is 1.

A tensor file has no mask: it gives a value for every pair of directions. A table with invalid
nodes is evaluated as gonio evaluates it (0 where no corner node of a lookup is valid), except a
*filled* table (:attr:`TabulatedBRDF.filled`, e.g. from ``gonio grid --method interp``), which is
evaluated from every node, its extrapolation included: the colour grid would otherwise have to
hold a step to 0 at the coverage edge, which its 32 x 32 nodes smooth into errors of tens of
percent inside the coverage (on the reduced demo's acquisition, the 95th percentile over the
coverage goes from 38 % to 7 %).
"""

from __future__ import annotations

import math
import os
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf.sampling import marginal2d as w2
from gonio.errors import ParameterError
from gonio.io._common import PathLike, atomic_output, fail

#: Resolutions of the written fields (those of the RGL database's files).
N_NDF = 128
N_VNDF = 128
N_GRID = 32
#: Conditioning angles (radians).
THETA_I = np.radians(np.concatenate([np.linspace(0.0, 80.0, 13), [84.0, 87.0, 89.0]]))
#: Exponent applied to the estimated NDF (see :func:`estimate_ndf`).
SOFTEN = 0.75
_REC709_Y = np.array([0.2126, 0.7152, 0.0722])
Array = jnp.ndarray


@jax.jit
def _forward(
    warp: w2.Marginal2D, ndf: w2.Marginal2D, s: Array, theta: Array
) -> tuple[Array, Array]:
    """Images ``u_m`` of the sample-space points ``s`` under the vndf warp at ``theta``, and
    the file's ``ndf`` there."""
    th = jnp.full(s.shape[:-1], theta)
    u_m, _ = w2.sample(warp, s, (jnp.zeros_like(th), th))
    return u_m, w2.eval_warp(ndf, u_m)


def _dirs(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], -1)


@jax.jit
def _model_f(model: Any, wi: Array, wo: Array) -> Array:
    return model.f(wi, wo)


def _evaluate(src: Any, wi: np.ndarray, wo: np.ndarray, chunk: int = 1 << 17) -> np.ndarray:
    from gonio.brdf.models import BRDFModel

    fn = (lambda a, b: _model_f(src, a, b)) if isinstance(src, BRDFModel) else src.f
    out = []
    flat_i, flat_o = wi.reshape(-1, 3), wo.reshape(-1, 3)
    for a in range(0, flat_i.shape[0], chunk):
        v = np.asarray(fn(flat_i[a : a + chunk], flat_o[a : a + chunk]), np.float64)
        out.append(v.reshape(v.shape[0], -1))
    vals = np.concatenate(out, 0)
    vals = np.where(np.isfinite(vals), vals, 0.0)
    return vals.reshape(*wi.shape[:-1], vals.shape[-1])


class _NDF:
    """An isotropic NDF tabulated at ``u_theta`` nodes, linear in ``u_theta`` (as the file's
    ``ndf`` field is read), with its projected area by quadrature."""

    def __init__(self, n: int = N_NDF, n_theta: int = 384, n_phi: int = 96) -> None:
        self.u = np.linspace(0.0, 1.0, n)
        # quadrature over m: midpoints in u_theta (dense near the pole) and phi
        um = (np.arange(n_theta) + 0.5) / n_theta
        tm = um**2 * (math.pi / 2)
        self.dm = (math.pi * um) * (math.pi / n_theta) * np.sin(tm) * (2 * math.pi / n_phi)
        self.um, self.tm = um, tm
        self.phi = (np.arange(n_phi) + 0.5) * (2 * math.pi / n_phi)

    def at(self, d: np.ndarray, u: np.ndarray) -> np.ndarray:
        return np.interp(u, self.u, d)

    def normalize(self, d: np.ndarray) -> np.ndarray:
        total = np.sum(self.at(d, self.um) * np.cos(self.tm) * self.dm) * len(self.phi)
        return d / total

    def sigma(self, d: np.ndarray, theta_w: np.ndarray) -> np.ndarray:
        """``int D(m) max(0, w . m) dm`` for ``w`` at polar angles ``theta_w`` (azimuth 0)."""
        dm = self.at(d, self.um)[:, None] * self.dm[:, None]  # (T, 1)
        st, ct = np.sin(self.tm)[:, None], np.cos(self.tm)[:, None]
        cp = np.cos(self.phi)[None, :]
        out = np.empty(len(theta_w))
        for k, t in enumerate(theta_w):
            dot = math.sin(t) * st * cp + math.cos(t) * ct
            out[k] = np.sum(dm * np.maximum(dot, 0.0))
        return out


def estimate_ndf(src: Any, iterations: int = 40) -> tuple[np.ndarray, np.ndarray, _NDF]:
    """``(ndf, sigma)`` at the ``u_theta`` nodes from the retro-reflection (module docstring)."""
    grid = _NDF()
    theta = np.minimum(grid.u**2 * (math.pi / 2), math.radians(89.0))
    w = _dirs(theta, np.zeros_like(theta))
    retro = _evaluate(src, w, w)
    lum = _luminance(retro)
    lum = np.maximum(lum, 1e-6 * max(float(lum.max()), 1e-30))
    d = grid.normalize(lum.copy())
    for _ in range(iterations):
        s = grid.sigma(d, grid.u**2 * (math.pi / 2))
        new = grid.normalize(lum * s**2)
        d = grid.normalize(np.sqrt(d * new))
    # softened: keeps some of the warp's resolution for the tails of sharp lobes, which the
    # colour table must otherwise resolve in a few nodes
    d = grid.normalize(d**SOFTEN)
    return d, grid.sigma(d, grid.u**2 * (math.pi / 2)), grid


def _luminance(vals: np.ndarray, wavelengths: np.ndarray | None = None) -> np.ndarray:
    c = vals.shape[-1]
    if wavelengths is not None:
        from gonio.io.spectral import spectral_weights

        return vals @ spectral_weights(wavelengths)[:, 1]
    if c == 3:
        return vals @ _REC709_Y
    return vals.mean(axis=-1)


def _source_channels(src: Any) -> tuple[int, np.ndarray | None]:
    """Channel count C and, for spectral sources, their wavelengths (nm)."""
    info = src.channel_info
    if info is not None and info.kind == "spectral":
        return src.n_channels, np.asarray(info.wavelengths_nm, np.float64)
    return src.n_channels, None


def rgl_fields(src: Any, description: str = "") -> dict[str, np.ndarray]:
    """All fields of an RGL tensor file for the isotropic BRDF ``src`` (module docstring)."""
    c, wavelengths = _source_channels(src)
    d, sig, _ = estimate_ndf(src)
    n_t = len(THETA_I)
    u = np.linspace(0.0, 1.0, N_VNDF)
    ux, uy = np.meshgrid(u, u, indexing="xy")  # (H = u_phi, W = u_theta)
    tm = ux**2 * (math.pi / 2)
    pm = (2 * uy - 1) * math.pi
    m = _dirs(tm, pm)
    d_m = np.interp(ux, np.linspace(0, 1, N_NDF), d)
    jac = 2 * math.pi**2 * ux * np.sin(tm)
    vndf = np.empty((1, n_t, N_VNDF, N_VNDF))
    for k, t in enumerate(THETA_I):
        wc = np.array([math.sin(t), 0.0, math.cos(t)])
        vndf[0, k] = d_m * np.maximum(m @ wc, 0.0) * jac
    vndf = vndf.astype(np.float32)
    params = [np.zeros(1), THETA_I.astype(np.float32).astype(np.float64)]
    warp = w2.build(vndf, params, cdf=True)
    ndf_warp = w2.build(np.stack([d, d]).astype(np.float32), [], cdf=False)
    sig_warp = w2.build(np.stack([sig, sig]).astype(np.float32), [], cdf=False)

    g = np.linspace(0.0, 1.0, N_GRID)
    sx, sy = np.meshgrid(g, g, indexing="xy")
    s = np.stack([sx.ravel(), sy.ravel()], -1)
    colour = np.zeros((1, n_t, max(c, 1), N_GRID, N_GRID))
    for k, t in enumerate(THETA_I):
        u_m, d_at = (np.asarray(x) for x in _forward(warp, ndf_warp, jnp.asarray(s), params[1][k]))
        theta_m = u_m[:, 0] ** 2 * (math.pi / 2)
        phi_m = (2 * u_m[:, 1] - 1) * math.pi
        mm = _dirs(theta_m, phi_m)
        wc = np.broadcast_to([math.sin(t), 0.0, math.cos(t)], mm.shape)
        dot = np.sum(wc * mm, -1)
        ws = 2 * dot[:, None] * mm - wc
        ok = ws[:, 2] > 1e-9
        f_cos = _evaluate(src, np.where(ok[:, None], ws, [0, 0, 1.0]), wc) * ws[:, 2:3]
        u_c = jnp.asarray([[math.sqrt(2 * t / math.pi), 0.5]])
        s_c = float(np.asarray(w2.eval_warp(sig_warp, u_c))[0])
        val = f_cos * (4 * s_c) / np.maximum(d_at, 1e-30)[:, None]
        val = np.where(ok[:, None], val, 0.0)
        colour[0, k] = val.T.reshape(-1, N_GRID, N_GRID)
    if c == 1 and wavelengths is None:
        colour = np.repeat(colour, 3, axis=2)
    lum = _luminance(np.moveaxis(colour, 2, -1), wavelengths)
    floor = 1e-6 * np.maximum(lum.max(axis=(-2, -1), keepdims=True), 1e-30)
    lum = np.maximum(lum, floor)
    fields: dict[str, np.ndarray] = {
        "description": np.frombuffer(description.encode("utf-8"), np.uint8).copy(),
        "version": np.array([1, 0], np.uint32),
        "jacobian": np.array([1], np.uint8),
        "theta_i": params[1].astype(np.float32),
        "phi_i": np.zeros(1, np.float32),
        "ndf": np.stack([d, d]).astype(np.float32),
        "sigma": np.stack([sig, sig]).astype(np.float32),
        "vndf": vndf,
        "luminance": lum.astype(np.float32),
    }
    if wavelengths is not None:
        fields["spectra"] = colour.astype(np.float32)
        fields["wavelengths"] = wavelengths.astype(np.float32)
    else:
        fields["rgb"] = colour.astype(np.float32)
    return fields


def _loaded_fields(obj: Any, fields: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The fields of a loaded RGL file as loaded: unchanged (a lossless copy), or with its
    colour table clamped (``negative="clamp"``) or converted to RGB (``color="rgb"``)."""
    st = obj._static
    fields = dict(fields)
    key = "spectra" if st.spectral else "rgb"
    colour = fields[key]
    if st.negative == "clamp":
        colour = np.maximum(colour, np.float32(0.0))
    if st.to_rgb:
        matrix = np.asarray(obj._matrix, np.float64)
        if matrix.shape[1] != 3:
            raise ParameterError("a channel subset of an RGL file cannot be written as .bsdf")
        colour = np.einsum("ptcyx,cd->ptdyx", colour.astype(np.float64), matrix)
        fields.pop("spectra", None)
        fields.pop("wavelengths", None)
        key = "rgb"
    fields[key] = colour.astype(np.float32)
    return fields


def _everywhere(obj: Any) -> Any:
    """The function the file is written from: a filled table with every node valid, else
    ``obj`` (module docstring)."""
    from gonio.brdf.tabulated import TabulatedBRDF

    if isinstance(obj, TabulatedBRDF) and obj.filled:
        return obj.replace(mask=None, filled=False)
    return obj


def write_rgl(obj: Any, path: PathLike, description: str | None = None) -> None:
    """Write ``obj`` as an RGL ``.bsdf`` tensor file, atomically.

    ``obj`` is an RGL file loaded by gonio (its fields are written back unchanged, or as loaded
    with ``negative="clamp"`` / ``color="rgb"``), or any
    isotropic BRDF with ``f(wi, wo)``: a table, an acquisition's gridded table, an analytic
    model. Scattered samples and anisotropic tables are refused (grid them first).
    """
    from gonio.brdf.measured import MeasuredSamples
    from gonio.brdf.tabulated import TabulatedBRDF
    from gonio.io.rgl import RGLFile, read_rgl, tensor_file_bytes
    from gonio.io.rgl_measured import RGLMeasured

    if isinstance(obj, RGLMeasured) and os.path.exists(obj.path):
        fields = _loaded_fields(obj, read_rgl(obj.path).fields)
    elif isinstance(obj, RGLFile):  # a file's checked fields, written back unchanged
        fields = dict(obj.fields)
    else:
        if isinstance(obj, MeasuredSamples):
            raise ParameterError(
                f"{os.fspath(path)}: scattered samples cannot be written as an RGL file "
                "(grid them first: gonio grid)"
            )
        if isinstance(obj, TabulatedBRDF) and not obj.isotropic:
            raise ParameterError(f"{os.fspath(path)}: only isotropic BRDFs can be written as .bsdf")
        if description is None:
            meta = obj.meta if isinstance(obj, TabulatedBRDF) else {}
            description = str(meta.get("name") or meta.get("material") or type(obj).__name__)
        fields = rgl_fields(_everywhere(obj), description)
        for name, arr in fields.items():
            if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
                raise fail(path, f"computed field {name!r} is not finite (source returns NaN?)")
    RGLFile.from_fields(dict(fields), path)  # the reader's checks, before anything is written
    data = tensor_file_bytes(fields)
    with atomic_output(path) as tmp:
        tmp.write_bytes(data)
