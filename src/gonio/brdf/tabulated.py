"""Tabulated BRDFs on a grid (:class:`TabulatedBRDF`); scattered measurements are
:class:`gonio.brdf.measured.MeasuredSamples`.

Grids
-----
A table stores ``values`` of shape ``(n_1, ..., n_k, C)`` (float32, 1/sr, channels last) at the
nodes of ``k`` :class:`Axis` objects in the Rusinkiewicz (1998) half/difference angles:

``"half_diff_iso"``
    axes ``(theta_h, theta_d, phi_d)`` of an isotropic BRDF. ``phi_d`` is folded by reciprocity
    (``f(phi_d) = f(phi_d + pi)``) when its axis spans at most ``pi`` (MERL), and additionally by
    the mirror symmetry ``phi_d -> pi - phi_d`` when it spans at most ``pi / 2``.
``"half_diff_aniso"``
    axes ``(theta_h, phi_h, theta_d, phi_d)``, ``phi_h`` and ``phi_d`` over ``[0, 2 pi)``.

Node ``i`` of an axis sits at the warped coordinate ``x_i = (i + node_offset) / size`` and the
angle ``lo + (hi - lo) x`` (``"linear"``) or ``lo + (hi - lo) x**2`` (``"sqrt"``, MERL's
``theta_h``). Interpolation is multilinear in the *warped index* coordinates (so MERL's dense
``theta_h`` nodes near the specular peak are used as they are meant to be); periodic axes wrap
around, the others clamp at their first and last node.

Validity
--------
``mask`` marks valid nodes. Invalid nodes are excluded from interpolation and the weights of the
remaining corners are renormalized; where no corner is valid the result is 0. Whatever an
invalid node holds (NaN, garbage) never reaches a result. ``f`` is 0 when ``wi`` or ``wo`` is on
or below the horizon.

A table built with ``filled=True`` declares that its invalid nodes hold a finite extrapolation
of the valid ones (the nearest sample outside a scattered-data interpolant's coverage, see
:func:`gonio.brdf.gridding.interpolate_samples`). ``f`` still ignores them; they are kept by the
native file and used by writers of formats that have no mask (an RGL tensor file holds values
everywhere: zeros there would put a step at the coverage edge).

JAX
---
:meth:`TabulatedBRDF.f` is pure JAX, vectorized over any batch shape, and keeps float32 inputs in
float32. A table is also a registered pytree (its leaves are the float32 lookup arrays), so it can
be passed to ``jax.jit`` as an argument or closed over. The sampling structures (see
:mod:`gonio.brdf.sampling.distributions` and :meth:`TabulatedBRDF.sample`) are built lazily, on
the host, from the table's values; they are shared by every copy of the table that a pytree round
trip makes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf.grid import (
    INTERPOLATIONS,
    PARAMETERIZATIONS,
    Axis,
    Channels,
    default_axes,
    merl_axes,
    node_directions,
    numeric_array,
)
from gonio.brdf.lookup import LookupSpec, corner_bits, eval_kernel, interpolate
from gonio.brdf.sample_record import BRDFSample
from gonio.brdf.sampled import TableSampled, bind_generic
from gonio.errors import FormatError, ParameterError

Array = jnp.ndarray

_EPS_ANGLE = 1e-9

#: A table's own sampling methods (:meth:`TabulatedBRDF.sample`), the default first.
TABLE_METHODS = ("inversion", "alias", "rejection")


def _one_minus_eps(dtype: Any) -> float:
    return float(np.nextafter(np.dtype(dtype).type(1.0), np.dtype(dtype).type(0.0)))


def _as_dirs(wi: Any, wo: Any) -> tuple[Array, Array]:
    wi = jnp.asarray(wi)
    wo = jnp.asarray(wo)
    if not jnp.issubdtype(wi.dtype, jnp.floating):
        wi = wi.astype(jnp.float64)
    if not jnp.issubdtype(wo.dtype, jnp.floating):
        wo = wo.astype(jnp.float64)
    dtype = jnp.result_type(wi, wo)
    if wi.shape[-1:] != (3,) or wo.shape[-1:] != (3,):
        raise ParameterError(f"directions must have shape (..., 3), got {wi.shape}, {wo.shape}")
    wi, wo = wi.astype(dtype), wo.astype(dtype)  # the same arrays when already of dtype
    if wi.shape == wo.shape:
        # jnp.broadcast_arrays would copy them (two copies of 12 MB for a 1e6 lookup)
        return wi, wo
    return tuple(jnp.broadcast_arrays(wi, wo))


@jax.jit
def _sample_inputs(wo: Array, u: Array) -> tuple[Array, Array, Array]:
    """``(wo, wo_s, u)`` broadcast together for :meth:`TabulatedBRDF.sample`: ``wo_s`` has
    directions on or below the horizon replaced by the normal, ``u`` is clipped below 1."""
    shape = jnp.broadcast_shapes(wo.shape[:-1], u.shape[:-1])
    wo = jnp.broadcast_to(wo, (*shape, 3))
    u = jnp.clip(jnp.broadcast_to(u, (*shape, 2)), 0.0, _one_minus_eps(wo.dtype))
    wo_s = jnp.where(wo[..., 2:3] > 0, wo, jnp.array([0.0, 0.0, 1.0], wo.dtype))
    return wo, wo_s, u


@jax.jit
def _above_horizon(wo: Array) -> Array:
    """``wo`` with directions on or below the horizon replaced by the normal (as sampled)."""
    return jnp.where(wo[..., 2:3] > 0, wo, jnp.array([0.0, 0.0, 1.0], wo.dtype))


def _sampled_values(spec: LookupSpec, data: Any, wo_s: Array, wi: Array) -> tuple[Array, Array]:
    """``(wi, f)``: the table at sampled ``(wi, wo_s)``, for :meth:`TabulatedBRDF.sample`."""
    return wi, eval_kernel(data, wi, wo_s, spec)


@jax.jit
def _sample_result(wo, wi, pdf, val) -> BRDFSample:
    """The :class:`BRDFSample` of sampled ``wi`` with density ``pdf``; ``val`` is the table at
    ``(wi, wo_s)``."""
    wi = wi.astype(wo.dtype)
    pdf = pdf.astype(wo.dtype)
    ok = (wo[..., 2] > 0) & (wi[..., 2] > 0) & (pdf > 0)
    cos_i = jnp.maximum(wi[..., 2:3], 0.0)
    weight = jnp.where(ok[..., None], val * cos_i / jnp.where(ok, pdf, 1.0)[..., None], 0.0)
    return BRDFSample(wi, jnp.where(ok, pdf, 0.0), weight, jnp.zeros(ok.shape, bool))


# ---------------------------------------------------------------------------------------------
# TabulatedBRDF
# ---------------------------------------------------------------------------------------------
class _Host:
    """Host-side state shared by a table and the copies a pytree round trip makes: the NumPy
    arrays and the lazily built sampling caches. Identity-hashed (used in pytree aux data)."""

    def __init__(self) -> None:
        self.samplers: dict[Any, Any] = {}


class TabulatedBRDF:
    """A BRDF tabulated on a half/difference-angle grid (see the module docstring).

    Parameters
    ----------
    values : ``(n_1, ..., n_k, C)`` BRDF values in 1/sr (stored float32).
    axes : the k :class:`Axis` objects, named as the parameterization requires.
    parameterization : ``"half_diff_iso"`` (theta_h, theta_d, phi_d) or ``"half_diff_aniso"``
        (theta_h, phi_h, theta_d, phi_d).
    mask : ``(n_1, ..., n_k)`` bool, True for valid nodes; None means all valid. Invalid nodes
        may hold anything (NaN included).
    sigma : uncertainty (one standard deviation, 1/sr) like ``values``, or None.
    counts : number of measurements per node, ``(n_1, ..., n_k)`` or like ``values``, or None.
    channels : :class:`Channels` (default: mono for C = 1, RGB for C = 3).
    meta : provenance (rig, plan, calibration, software, time, source file, ...), JSON-ready.
    interpolation : ``"linear"`` (multilinear in warped index space) or ``"nearest"`` (the valid
        corner of the enclosing grid cell with the largest multilinear weight).
    sampling_res : ``(n_theta_o, n_theta_i, n_phi_i)`` of the sampling structures (outgoing
        buckets and the incident-direction grid); for anisotropic tables the outgoing buckets
        are ``n_theta_o x 2 n_theta_o`` in (theta_o, phi_o). Default ``(32, 64, 128)``.
    filled : True when the invalid nodes hold a finite extrapolation of the valid ones (module
        docstring); they must then be finite. Default False: invalid nodes mean nothing.

    Raises
    ------
    FormatError
        values/mask/sigma/counts of the wrong shape or dtype, NaN/Inf in valid nodes, negative
        sigma or counts.
    ParameterError
        unknown parameterization or interpolation, axes that do not fit the parameterization.
    """

    def __init__(
        self,
        values: Any,
        axes: Sequence[Axis],
        parameterization: str = "half_diff_iso",
        mask: Any = None,
        sigma: Any = None,
        counts: Any = None,
        channels: Channels | None = None,
        meta: Mapping[str, Any] | None = None,
        interpolation: str = "linear",
        *,
        sampling_res: tuple[int, int, int] = (32, 64, 128),
        filled: bool = False,
    ) -> None:
        if parameterization not in PARAMETERIZATIONS:
            raise ParameterError(
                f"unknown parameterization {parameterization!r} "
                f"(expected one of {', '.join(PARAMETERIZATIONS)})"
            )
        if interpolation not in INTERPOLATIONS:
            raise ParameterError(
                f"interpolation must be 'linear' or 'nearest', got {interpolation!r}"
            )
        axes = tuple(axes)
        if not all(isinstance(a, Axis) for a in axes):
            raise ParameterError("axes must be Axis objects")
        names = tuple(a.name for a in axes)
        if names != PARAMETERIZATIONS[parameterization]:
            raise ParameterError(
                f"{parameterization} needs axes {PARAMETERIZATIONS[parameterization]}, got {names}"
            )
        grid = tuple(a.size for a in axes)
        vals = numeric_array(values, "values", np.float32)
        if vals.ndim != len(axes) + 1 or vals.shape[:-1] != grid:
            raise FormatError(f"values have shape {vals.shape}, expected {(*grid, 'C')}")
        C = vals.shape[-1]
        if C < 1:
            raise FormatError("values have no channels")
        if mask is None:
            m = np.ones(grid, dtype=bool)
        else:
            m = np.asarray(mask)
            if m.dtype != np.bool_:
                if m.dtype.kind not in "biu" or not np.all((m == 0) | (m == 1)):
                    raise FormatError(f"mask must be boolean, got dtype {m.dtype}")
                m = m.astype(bool)
            if m.shape != grid:
                raise FormatError(f"mask has shape {m.shape}, expected {grid}")
        bad = m & ~np.all(np.isfinite(vals), axis=-1)
        if bad.any():
            first = tuple(int(i) for i in np.argwhere(bad)[0])
            raise FormatError(
                f"values are NaN or infinite at {int(bad.sum())} valid nodes (first at {first}); "
                "mark them invalid in the mask"
            )
        filled = bool(filled)
        if filled and not np.all(np.isfinite(vals)):
            raise FormatError("a filled table needs finite values at its invalid nodes too")
        sig = None
        if sigma is not None:
            sig = numeric_array(sigma, "sigma", np.float32)
            if sig.shape != vals.shape:
                raise FormatError(f"sigma has shape {sig.shape}, expected {vals.shape}")
            sv = sig[m]
            if not np.all(np.isfinite(sv)) or np.any(sv < 0):
                raise FormatError("sigma must be finite and >= 0 at valid nodes")
        cnt = None
        if counts is not None:
            cnt = np.asarray(counts)
            if cnt.dtype.kind not in "iu":
                if cnt.dtype.kind == "f" and np.all(np.isfinite(cnt)) and np.all(cnt % 1 == 0):
                    cnt = cnt.astype(np.int64)
                else:
                    raise FormatError(f"counts must be integers, got dtype {cnt.dtype}")
            if cnt.shape not in (grid, vals.shape):
                raise FormatError(f"counts have shape {cnt.shape}, expected {grid}")
            if np.any(cnt < 0):
                raise FormatError("counts must be >= 0")
        channels = Channels.describe(channels, C)
        try:
            res = tuple(int(r) for r in sampling_res)
        except (TypeError, ValueError):
            raise ParameterError("sampling_res must be three integers") from None
        if len(res) != 3 or min(res) < 1:
            raise ParameterError(f"sampling_res must be three positive integers, got {res}")

        vals.setflags(write=False)
        m.setflags(write=False)
        self.values: np.ndarray = vals
        self.axes: tuple[Axis, ...] = axes
        self.parameterization = parameterization
        self.mask: np.ndarray = m
        self.sigma: np.ndarray | None = sig
        self.counts: np.ndarray | None = cnt
        self.channels: Channels = channels
        self.meta: dict[str, Any] = dict(meta or {})
        self.interpolation = interpolation
        self.sampling_res = res
        self.filled = filled
        has_mask = not bool(m.all())
        fold = 0
        if parameterization == "half_diff_iso":
            span = axes[2].hi
            fold = 2 if span <= math.pi / 2 + _EPS_ANGLE else (1 if span <= math.pi + 1e-6 else 0)
        self._spec = LookupSpec(axes, parameterization, interpolation, has_mask, C, fold)
        clean = np.where(m[..., None], vals, np.float32(0.0)).reshape(-1, C)
        bits = jnp.asarray(corner_bits(m, axes).reshape(-1)) if has_mask else None
        self._data = (jnp.asarray(np.ascontiguousarray(clean, dtype=np.float32)), bits)
        self._host = _Host()

    # -- construction helpers ------------------------------------------------------------------
    merl_axes = staticmethod(merl_axes)
    default_axes = staticmethod(default_axes)

    @classmethod
    def from_model(
        cls,
        model: Any,
        axes: Sequence[Axis] | None = None,
        parameterization: str = "half_diff_iso",
        interpolation: str = "linear",
        channels: Channels | None = None,
        meta: Mapping[str, Any] | None = None,
        chunk: int = 1 << 18,
        **kwargs: Any,
    ) -> TabulatedBRDF:
        """Tabulate an analytic model (anything with ``f(wi, wo) -> (..., C)``) at the grid nodes.

        Nodes whose directions lie on or below the horizon are marked invalid. ``axes`` default to
        :func:`default_axes` (MERL's grid for isotropic tables). The model is evaluated in float64
        and the result stored as float32. Extra keyword arguments go to the constructor.
        """
        if parameterization not in PARAMETERIZATIONS:
            raise ParameterError(f"unknown parameterization {parameterization!r}")
        axes = tuple(axes) if axes is not None else default_axes(parameterization)
        wi, wo = node_directions(axes, parameterization)
        n = wi.shape[0]
        out = []
        for s in range(0, n, chunk):
            out.append(np.asarray(model.f(wi[s : s + chunk], wo[s : s + chunk]), np.float64))
        vals = np.concatenate(out, axis=0)
        grid = tuple(a.size for a in axes)
        valid = (wi[:, 2] > 0) & (wo[:, 2] > 0) & np.all(np.isfinite(vals), axis=-1)
        vals = np.where(valid[:, None], vals, 0.0).reshape(*grid, vals.shape[-1])
        info = {"source": "tabulated analytic model", "model": _describe(model)}
        info.update(meta or {})
        return cls(
            vals.astype(np.float32),
            axes,
            parameterization,
            mask=valid.reshape(grid),
            channels=channels,
            meta=info,
            interpolation=interpolation,
            **kwargs,
        )

    @classmethod
    def merl_like(cls, model: Any, **kwargs: Any) -> TabulatedBRDF:
        """:meth:`from_model` on MERL's 90 x 90 x 180 isotropic grid."""
        return cls.from_model(model, axes=merl_axes(), parameterization="half_diff_iso", **kwargs)

    def replace(self, **changes: Any) -> TabulatedBRDF:
        """A new table with some constructor arguments changed (validated again)."""
        kw = {
            "values": self.values,
            "axes": self.axes,
            "parameterization": self.parameterization,
            "mask": self.mask,
            "sigma": self.sigma,
            "counts": self.counts,
            "channels": self.channels,
            "meta": self.meta,
            "interpolation": self.interpolation,
            "sampling_res": self.sampling_res,
            "filled": self.filled,
        }
        unknown = set(changes) - set(kw)
        if unknown:
            raise ParameterError(f"TabulatedBRDF.replace: unknown argument(s) {sorted(unknown)}")
        kw.update(changes)
        return TabulatedBRDF(**kw)

    # -- description -----------------------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, ...]:
        """Grid shape ``(n_1, ..., n_k)``."""
        return tuple(a.size for a in self.axes)

    @property
    def n_channels(self) -> int:
        """Channel count C."""
        return len(self.channels)

    @property
    def isotropic(self) -> bool:
        return self.parameterization == "half_diff_iso"

    # -- the material interface (gonio.brdf.material.Material) ---------------------------------
    #: Sampling methods, the default first (:meth:`sample`); "cosine" and "lobe" too.
    sampling_methods = TABLE_METHODS
    has_delta = False
    broadcasts_outgoing = False

    @property
    def channel_info(self) -> Channels:
        """The channel description (the same as :attr:`channels`)."""
        return self.channels

    def select_channels(self, idx: Sequence[int]) -> TabulatedBRDF | None:
        """The table with only channels ``idx`` (values, sigma and channel description cut), or
        None when the selection has no :class:`Channels` description (two channels of an RGB
        table): the caller then evaluates every channel and cuts afterwards."""
        ch = self.channels
        names = tuple(ch.names[i] for i in idx)
        if ch.kind == "spectral":
            wl = np.asarray(ch.wavelengths_nm)[idx]
            new = Channels("spectral", names=names, wavelengths_nm=wl)
        elif len(idx) == 1:
            new = Channels("mono", names=names)
        elif list(idx) == list(range(len(ch.names))):
            return self
        else:
            return None
        sigma = None if self.sigma is None else np.asarray(self.sigma)[..., idx]
        return self.replace(values=np.asarray(self.values)[..., idx], sigma=sigma, channels=new)

    def with_sampling(self, method: str | None = None, *, proposal: Any = None,
                      wo: Any = None) -> Any:  # fmt: skip
        """The table bound to ``method`` (default ``"inversion"``) as a pytree
        (:class:`gonio.brdf.sampled.TableSampled`), with the sampling structures built for the
        outgoing directions ``wo`` (see :meth:`sampling_state`; None: built when sampled,
        eagerly only); or the generic ``"cosine"`` / ``"lobe"`` (with ``proposal``) wrappers."""
        method = self.sampling_methods[0] if method is None else method
        if method not in self.sampling_methods:
            return bind_generic(self, method, proposal)
        if proposal is not None:
            raise ParameterError("proposal= is used by lobe sampling only")
        state = None if wo is None else self.sampling_state(method, wo)
        return TableSampled(self, method, state)

    @property
    def valid_fraction(self) -> float:
        return float(self.mask.mean())

    def __repr__(self) -> str:
        return (
            f"TabulatedBRDF({self.parameterization}, grid={self.shape}, {self.channels!r}, "
            f"valid={self.valid_fraction:.3f}, interpolation={self.interpolation!r})"
        )

    # -- evaluation ------------------------------------------------------------------------------
    def f(self, wi: Any, wo: Any) -> Array:
        """BRDF value in 1/sr, ``(..., 3), (..., 3) -> (..., C)``; 0 on or below the horizon.

        Keeps the directions' dtype (float32 in, float32 out). Jittable.
        """
        wi, wo = _as_dirs(wi, wo)
        return eval_kernel(self._data, wi, wo, self._spec)

    def f_at(self, *angles: Any) -> Array:
        """Lookup at half/diff angles given per axis (radians, broadcastable) -> ``(..., C)``.

        No horizon test and no phi_d folding: the angles are used as given (periodic axes wrap,
        the others clamp).
        """
        if len(angles) != len(self.axes):
            raise ParameterError(f"f_at needs {len(self.axes)} angles, got {len(angles)}")
        arrs = jnp.broadcast_arrays(*(jnp.asarray(a) for a in angles))
        dtype = jnp.result_type(*arrs)
        if not jnp.issubdtype(dtype, jnp.floating):
            dtype = jnp.float64
        return interpolate(self._spec, self._data, [a.astype(dtype) for a in arrs])

    # -- sampling ----------------------------------------------------------------------------------
    def _sampler(self) -> Any:
        from gonio.brdf.sampling.table import TableSampler

        sampler = self._host.samplers.get("table")
        if sampler is None:
            sampler = TableSampler(self)
            self._host.samplers["table"] = sampler
        return sampler

    def sample(
        self,
        wo: Any,
        u: Any,
        method: str = "inversion",
        rng: Any = None,
        proposal: Any = "majorant",
        state: Any = None,
    ) -> BRDFSample:
        """Importance-sample ``wi`` proportionally to ``mean_channels(f) cos(theta_i)``.

        Parameters
        ----------
        wo : ``(..., 3)`` outgoing directions.
        u : ``(..., 2)`` uniform numbers in [0, 1).
        method : ``"inversion"``, ``"alias"`` (piecewise-constant density per incident-grid cell
            and outgoing bucket) or ``"rejection"`` (exactly ``g cos / rho(wo)``, the reference
            density); see :mod:`gonio.brdf.sampling.table`.
        rng : rejection only: where the extra random numbers come from (a NumPy Generator, an
            int seed or a JAX key); default: derived deterministically from ``u``.
        proposal : rejection only: ``"majorant"`` (default: a piecewise-constant bound of
            ``g cos`` per incident-grid cell and outgoing bucket, drawn from an alias table) or
            ``"cosine"``; see :mod:`gonio.brdf.sampling.table_rejection`. The sampled density is the
            same for both.
        state : the sampling structures from :meth:`sampling_state` (same ``method`` and
            ``proposal``), to trace this call inside ``jit`` with them as arguments: nothing is
            built and nothing waits on the host. Default: built here for ``wo``'s buckets.

        Returns
        -------
        BRDFSample ``(wi, pdf, weight = f cos / pdf, delta = False)``; ``pdf`` equals
        ``self.pdf(wi, wo, method, proposal)``. A failed sample has pdf 0 and weight 0.

        Sampling structures are built lazily for the outgoing buckets met (all of them when
        called under ``jit``), see :meth:`sampling_cache_size`.
        """
        wo = jnp.asarray(wo)
        if not jnp.issubdtype(wo.dtype, jnp.floating):
            wo = wo.astype(jnp.float64)
        u = jnp.asarray(u).astype(wo.dtype)
        if wo.shape[-1:] != (3,) or u.shape[-1:] != (2,):
            raise ParameterError(
                f"sample needs wo (..., 3) and u (..., 2), got {wo.shape}, {u.shape}"
            )
        wo, wo_s, u = _sample_inputs(wo, u)
        wi, pdf = self._sampler().sample(wo_s, u, method, rng, proposal, state)
        wi, val = _sampled_values(self._spec, self._data, wo_s, wi.astype(wo.dtype))
        return _sample_result(wo, wi, pdf, val)

    def pdf(
        self,
        wi: Any,
        wo: Any,
        method: str = "inversion",
        proposal: Any = "majorant",
        state: Any = None,
    ) -> Array:
        """Density of :meth:`sample` (same ``method``/``proposal``) over ``wi`` per unit solid
        angle, shape ``(...)``; 0 when either direction is on or below the horizon. ``state``:
        as for :meth:`sample`."""
        wi, wo = _as_dirs(wi, wo)
        ok_o = wo[..., 2] > 0
        wo_s = jnp.where(ok_o[..., None], wo, jnp.array([0.0, 0.0, 1.0], wo.dtype))
        p = self._sampler().pdf(wi, wo_s, method, proposal, state)
        return jnp.where(ok_o & (wi[..., 2] > 0), p, 0.0).astype(wo.dtype)

    def sampling_state(
        self, method: str, wo: Any, proposal: Any = "majorant", dtype: Any = jnp.float32
    ) -> dict[str, Any]:
        """The sampling structures of ``method`` as a pytree of device arrays, with the buckets
        of the outgoing directions ``wo`` built first (on the host, once).

        Pass it to :meth:`sample` and :meth:`pdf` (``state=``), as an argument of a jitted
        function, to sample at device speed: a renderer knows every outgoing direction of an
        image before it starts, builds once and then never waits on the host. ``wo``:
        directions ``(..., 3)``, or a list of such arrays (e.g. an image's tiles, whose fixed
        shapes compile the bucket histogram once). Directions in other buckets: see
        :meth:`gonio.brdf.sampling.table.TableSampler.state` (rejection needs each
        direction's own bucket). The arrays are in ``dtype`` (that of the ``wo`` the calls will
        get); the pytree's shapes grow when more buckets are built (capacity a power of 2), so
        a jitted caller recompiles only when the count passes one.
        """
        ws = []
        for w in wo if isinstance(wo, list | tuple) else [wo]:
            if not isinstance(w, jax.Array) or w.dtype != dtype:
                w = jax.device_put(np.asarray(w, dtype))
            if w.shape[-1:] != (3,):
                raise ParameterError(f"sampling_state needs wo (..., 3), got {w.shape}")
            ws.append(_above_horizon(w))
        dt = jnp.float64 if jnp.dtype(dtype) == jnp.float64 else jnp.float32
        return self._sampler().state(method, ws, proposal, dt)

    def sampling_cache_size(self, method: str | None = None) -> int:
        """Number of outgoing-direction buckets whose sampling structures have been built (for
        one method, or summed over all)."""
        sampler = self._host.samplers.get("table")
        return 0 if sampler is None else sampler.cache_size(method)

    def sampling_buckets(self, method: str) -> list[int]:
        """Indices of the outgoing buckets built for ``method`` (theta_o bin, or
        ``theta_bin * n_phi_bins + phi_bin`` for anisotropic tables)."""
        sampler = self._host.samplers.get("table")
        return [] if sampler is None else sampler.built_buckets(method)

    def directional_albedo(self, wo: Any, n: int = 128) -> Array:
        """``int f cos dwi`` at ``wo (..., 3)`` -> ``(..., C)``: midpoint rule over an ``n x 2n``
        grid uniform in (cos theta_i, phi_i) (deterministic)."""
        wo = jnp.asarray(wo, jnp.float64)
        c = (jnp.arange(n) + 0.5) / n
        p = (jnp.arange(2 * n) + 0.5) * (math.pi / n)
        cc, pp = jnp.meshgrid(c, p, indexing="ij")
        s = jnp.sqrt(1 - cc**2)
        wi = jnp.stack([s * jnp.cos(pp), s * jnp.sin(pp), cc], -1).reshape(-1, 3)
        val = self.f(wi, wo[..., None, :]) * wi[:, 2:3]
        return jnp.sum(val, axis=-2) * (2 * math.pi / (2 * n * n))

    # -- conversion --------------------------------------------------------------------------------
    def node_directions(self) -> tuple[np.ndarray, np.ndarray]:
        """``(wi, wo)``, each ``(n_nodes, 3)`` float64, of every node in C order (phi_h = 0 for
        isotropic tables)."""
        return node_directions(self.axes, self.parameterization)

    def cell_measure(self) -> np.ndarray:
        """Measure of each node's cell in direction-pair space, ``(n_1, ..., n_k)``, in sr^2.

        ``dwi dwo = 4 cos(theta_d) sin(theta_h) sin(theta_d) dtheta_h dphi_h dtheta_d dphi_d``
        integrated over the cell around each node (bounded by :meth:`Axis.edges`); isotropic
        tables integrate phi_h over 2 pi and count every phi_d folding. Cells partly below the
        horizon are not trimmed.
        """
        per_axis = []
        for ax in self.axes:
            e = ax.edges()
            if ax.periodic:  # a periodic node's cell is centred on it
                per_axis.append(np.full(ax.size, (ax.hi - ax.lo) / ax.size))
            elif ax.name == "theta_h":
                per_axis.append(np.cos(e[:-1]) - np.cos(e[1:]))
            elif ax.name == "theta_d":
                per_axis.append(0.5 * (np.sin(e[1:]) ** 2 - np.sin(e[:-1]) ** 2))
            else:
                per_axis.append(np.diff(e))
        w = 4.0 * per_axis[0]
        for p in per_axis[1:]:
            w = np.multiply.outer(w, p)
        if self.isotropic:
            w = w * 2 * math.pi * 2**self._spec.fold
        return w

    def valid_nodes(
        self,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None, np.ndarray]:
        """Valid nodes with both directions above the horizon, as flat NumPy arrays (what
        :meth:`gonio.brdf.measured.MeasuredSamples.from_table` keeps): ``(wi, wo, values,
        sigma, weights)``, directions ``(N, 3)``,
        values and sigma (or None) ``(N, C)``, weights the cell measures ``(N,)`` in sr^2."""
        wi, wo = self.node_directions()
        keep = np.asarray(self.mask).reshape(-1) & (wi[:, 2] > 0) & (wo[:, 2] > 0)
        C = self.n_channels
        vals = np.asarray(self.values).reshape(-1, C)[keep]
        sig = None if self.sigma is None else np.asarray(self.sigma).reshape(-1, C)[keep]
        return wi[keep], wo[keep], vals, sig, self.cell_measure().reshape(-1)[keep]

    # -- pytree --------------------------------------------------------------------------------
    def _tree_flatten(self) -> tuple[tuple[Array, Array | None], tuple[Any, ...]]:
        return self._data, (self._spec, _Ref(self))

    @classmethod
    def _tree_unflatten(cls, aux: tuple[Any, ...], leaves: Sequence[Any]) -> TabulatedBRDF:
        spec, ref = aux
        obj = object.__new__(cls)
        obj.__dict__.update(ref.obj.__dict__)
        obj._data = tuple(leaves)
        obj._spec = spec
        return obj


class _Ref:
    """Identity-compared holder of a table, for pytree aux data (tables are not hashable by
    value)."""

    __slots__ = ("obj",)

    def __init__(self, obj: Any) -> None:
        self.obj = obj

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _Ref) and other.obj._host is self.obj._host

    def __hash__(self) -> int:
        return id(self.obj._host)


jax.tree_util.register_pytree_node(
    TabulatedBRDF, TabulatedBRDF._tree_flatten, TabulatedBRDF._tree_unflatten
)


def _describe(model: Any) -> Any:
    to_dict = getattr(model, "to_dict", None)
    if callable(to_dict):
        try:
            return to_dict()
        except Exception:  # a description is best effort; tabulating must not fail on it
            pass
    return repr(model)


__all__ = [
    "Axis",
    "Channels",
    "TabulatedBRDF",
    "default_axes",
    "merl_axes",
]
