"""Base classes shared by every analytic model: parameters, pytrees, sampling records, mixtures.

A model is an immutable JAX pytree. Its array leaves are the parameters listed in ``PARAMS``
(so ``jax.grad`` and ``jax.vmap`` see them), nested nodes (for example a Fresnel term) are listed
in ``CHILDREN``, and hashable options such as ``variant="duer"`` in ``STATIC``. Subclasses write
the geometry in ``_f``, ``_pdf`` and ``_sample``; the public ``f``, ``pdf`` and ``sample`` add the
conventions every model shares (below-horizon directions give 0, ``weight = f cos / pdf``, channels
last).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf.frames import safe_div, upper
from gonio.brdf.grid import Channels
from gonio.brdf.sample_record import BRDFSample
from gonio.brdf.sampled import bind_generic
from gonio.errors import ParameterError

Array = jnp.ndarray

#: Largest float32 below 1: uniform numbers are clamped to ``[0, ONE_MINUS_EPS]``.
ONE_MINUS_EPS = float(np.nextafter(np.float32(1.0), np.float32(0.0)))

_REGISTRY: dict[str, type[Node]] = {}


@dataclass(frozen=True)
class Param:
    """Metadata of one model parameter, used by validation and by the fitter.

    Attributes
    ----------
    name : keyword argument name of the model's constructor.
    default : value used when the argument is omitted (and a fitter's starting point).
    lower, upper : inclusive physical bounds; construction outside them raises ParameterError.
    unit : unit of the value, e.g. ``"1"`` (dimensionless), ``"rad"``.
    per_channel : whether the value may be an array of shape ``(C,)`` (one per channel).
    per_lobe : whether the value is an array with one entry per lobe, shape ``(L,)`` (or
        ``(L, C)`` when also ``per_channel``), for models with a variable number of lobes such
        as Lafortune's; a scalar (or ``(C,)``) means a single lobe. Bounds apply elementwise.
        Default False (backward compatible).
    scale : reparameterization a fitter should use: ``"linear"``, ``"log"`` (positive, spans
        decades, e.g. roughness) or ``"logit"`` (bounded on both sides, e.g. albedo).
    doc : one-line description.
    fit_upper : upper end of a fitter's search box where it is narrower than the range the
        model is defined on (``upper``): a value above it is a valid model (a published fit, a
        hand-made material) but no fit searches there. None: ``upper``.
    """

    name: str
    default: float
    lower: float
    upper: float
    unit: str = "1"
    per_channel: bool = False
    scale: Literal["linear", "log", "logit"] = "linear"
    doc: str = ""
    per_lobe: bool = False
    fit_upper: float | None = None


def is_concrete(x: Any) -> bool:
    return not isinstance(x, jax.core.Tracer)


class Node:
    """An immutable pytree with named parameters, nested nodes and static options."""

    PARAMS: ClassVar[tuple[Param, ...]] = ()
    CHILDREN: ClassVar[tuple[str, ...]] = ()
    STATIC: ClassVar[tuple[str, ...]] = ()

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        jax.tree_util.register_pytree_node(cls, cls._tree_flatten, cls._tree_unflatten)
        _REGISTRY[cls.__name__] = cls

    # -- pytree -------------------------------------------------------------------------------
    def _tree_flatten(self) -> tuple[tuple[Any, ...], tuple[Any, ...]]:
        leaves = tuple(getattr(self, p.name) for p in self.PARAMS)
        leaves += tuple(getattr(self, c) for c in self.CHILDREN)
        return leaves, tuple(getattr(self, s) for s in self.STATIC)

    @classmethod
    def _tree_unflatten(cls, aux: tuple[Any, ...], leaves: Sequence[Any]) -> Node:
        obj = object.__new__(cls)
        names = [p.name for p in cls.PARAMS] + list(cls.CHILDREN)
        for name, value in zip(names, leaves, strict=True):
            object.__setattr__(obj, name, value)
        for name, value in zip(cls.STATIC, aux, strict=True):
            object.__setattr__(obj, name, value)
        return obj

    # -- construction -------------------------------------------------------------------------
    def _set_params(self, **values: Any) -> None:
        """Validate and store parameters; raise ParameterError naming the bad one."""
        known = {p.name: p for p in self.PARAMS}
        for name in values:
            if name not in known:
                raise ParameterError(f"{type(self).__name__}: unknown parameter {name!r}")
        for p in self.PARAMS:
            value = values.get(p.name)
            if value is None:
                value = p.default
            if is_concrete(value):
                value = self._check(p, value)
            object.__setattr__(self, p.name, value)
        if is_concrete(self._own_values()):
            self._own_channels()  # raises on mismatched per-channel lengths

    def _check(self, p: Param, value: Any) -> Array:
        cls = type(self).__name__
        try:
            arr = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise ParameterError(f"{cls}: {p.name} must be a number, got {value!r}") from None
        if p.per_lobe:
            if arr.ndim > 1 + int(p.per_channel):
                shape = "a scalar, (L,) or (L, C)" if p.per_channel else "a scalar or (L,)"
                raise ParameterError(
                    f"{cls}: {p.name} must have one entry per lobe, shape {shape}, "
                    f"got shape {arr.shape}"
                )
        elif arr.ndim > 1 or (arr.ndim == 1 and not p.per_channel):
            shape = "a scalar or one value per channel" if p.per_channel else "a scalar"
            raise ParameterError(f"{cls}: {p.name} must be {shape}, got shape {arr.shape}")
        if arr.size == 0:
            raise ParameterError(f"{cls}: {p.name} is empty")
        if not np.all(np.isfinite(arr)):
            raise ParameterError(f"{cls}: {p.name} must be finite, got {arr.tolist()}")
        if np.any(arr < p.lower) or np.any(arr > p.upper):
            raise ParameterError(
                f"{cls}: {p.name}={arr.tolist()} is outside [{p.lower:g}, {p.upper:g}] {p.unit}"
            )
        return jnp.asarray(arr)

    def _own_values(self) -> tuple[Any, ...]:
        return tuple(getattr(self, p.name) for p in self.PARAMS)

    def _own_channels(self) -> int:
        sizes = {_channel_size(p, getattr(self, p.name)) for p in self.PARAMS if p.per_channel}
        sizes.discard(1)
        if len(sizes) > 1:
            raise ParameterError(
                f"{type(self).__name__}: per-channel parameters disagree on the channel count "
                f"({sorted(sizes)})"
            )
        return sizes.pop() if sizes else 1

    def children(self) -> dict[str, Any]:
        """Nested nodes by field name."""
        return {c: getattr(self, c) for c in self.CHILDREN}

    @property
    def channels(self) -> int:
        """Number of output channels C (1 when every per-channel parameter is a scalar)."""
        sizes = {self._own_channels()}
        for child in jax.tree_util.tree_leaves(
            list(self.children().values()), is_leaf=lambda x: isinstance(x, Node)
        ):
            if isinstance(child, Node):
                sizes.add(child.channels)
        sizes.discard(1)
        if len(sizes) > 1:
            raise ParameterError(
                f"{type(self).__name__}: parts disagree on the channel count ({sorted(sizes)})"
            )
        return sizes.pop() if sizes else 1

    # -- parameters as a flat dictionary (for the fitter) --------------------------------------
    def param_specs(self) -> dict[str, Param]:
        """Every parameter of this node and its children, keyed ``"name"`` or ``"child.name"``."""
        out = {p.name: p for p in self.PARAMS}
        for cname, child in self.children().items():
            if isinstance(child, Node):
                out.update({f"{cname}.{k}": v for k, v in child.param_specs().items()})
        return out

    def params(self) -> dict[str, Array]:
        """Current values, keyed like :meth:`param_specs`."""
        out = {p.name: getattr(self, p.name) for p in self.PARAMS}
        for cname, child in self.children().items():
            if isinstance(child, Node):
                out.update({f"{cname}.{k}": v for k, v in child.params().items()})
        return out

    def replace(self, **values: Any) -> Node:
        """A copy with some parameters replaced (keys as in :meth:`params`).

        Works with traced values inside ``jit``/``grad`` (no validation is possible there);
        concrete values are validated like the constructor does.
        """
        own: dict[str, Any] = {}
        nested: dict[str, dict[str, Any]] = {}
        specs = {p.name: p for p in self.PARAMS}
        for key, value in values.items():
            head, dot_, rest = key.partition(".")
            if dot_:
                if head not in self.CHILDREN:
                    raise ParameterError(f"{type(self).__name__}: unknown parameter {key!r}")
                nested.setdefault(head, {})[rest] = value
            elif head in specs:
                own[head] = self._check(specs[head], value) if is_concrete(value) else value
            else:
                raise ParameterError(f"{type(self).__name__}: unknown parameter {key!r}")
        leaves, aux = self._tree_flatten()
        names = [p.name for p in self.PARAMS] + list(self.CHILDREN)
        new_leaves = []
        for name, leaf in zip(names, leaves, strict=True):
            if name in own:
                leaf = own[name]
            elif name in nested:
                leaf = leaf.replace(**nested[name])
            new_leaves.append(leaf)
        return type(self)._tree_unflatten(aux, new_leaves)

    # -- serialization (fit results, model files) ----------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description: ``{"type", "params", "static", "children"}``."""
        return {
            "type": type(self).__name__,
            "params": {p.name: np.asarray(getattr(self, p.name)).tolist() for p in self.PARAMS},
            "static": {s: getattr(self, s) for s in self.STATIC},
            "children": {c: _child_to_json(getattr(self, c)) for c in self.CHILDREN},
        }

    @staticmethod
    def from_dict(d: dict[str, Any]) -> Node:
        """Inverse of :meth:`to_dict`; raises ParameterError on unknown types or bad values."""
        try:
            cls = _REGISTRY[d["type"]]
        except (KeyError, TypeError):
            raise ParameterError(f"unknown model description {str(d)[:80]!r}") from None
        return cls._from_dict(d)

    @classmethod
    def _from_dict(cls, d: dict[str, Any]) -> Node:
        kwargs = dict(d.get("params", {}))
        kwargs.update(d.get("static", {}))
        for name, child in d.get("children", {}).items():
            kwargs[name] = _child_from_json(child)
        return cls(**kwargs)

    def __repr__(self) -> str:
        parts = []
        for p in self.PARAMS:
            v = getattr(self, p.name)
            parts.append(f"{p.name}={np.asarray(v).tolist() if is_concrete(v) else '<traced>'}")
        parts += [f"{c}={getattr(self, c)!r}" for c in self.CHILDREN]
        parts += [f"{s}={getattr(self, s)!r}" for s in self.STATIC]
        return f"{type(self).__name__}({', '.join(parts)})"


def _channel_size(p: Param, value: Any) -> int:
    """Channel count implied by one per-channel parameter value (lobe axis excluded)."""
    if p.per_lobe:
        shape = np.shape(value)
        return int(shape[-1]) if len(shape) == 2 else 1
    return int(np.size(value))


def _child_to_json(child: Any) -> Any:
    if isinstance(child, Node):
        return child.to_dict()
    if isinstance(child, (tuple, list)):
        return [_child_to_json(c) for c in child]
    return child


def _child_from_json(d: Any) -> Any:
    if isinstance(d, dict):
        return Node.from_dict(d)
    if isinstance(d, list):
        return tuple(_child_from_json(c) for c in d)
    return d


def as_float(x: Any, dtype: Any = None) -> Array:
    """``jnp.asarray`` with a floating dtype (float64 unless ``dtype`` or the input says so)."""
    x = jnp.asarray(x)
    if dtype is None:
        dtype = x.dtype if jnp.issubdtype(x.dtype, jnp.floating) else jnp.float64
    return x.astype(dtype)


def on_channel_axis(p: Array, batch_ndim: int) -> Array:
    """A ``(C,)`` per-channel parameter shaped ``(C, 1, ..., 1)`` to broadcast against a
    channels-first ``(C, ...)`` array with ``batch_ndim`` batch axes."""
    return p.reshape(p.shape + (1,) * batch_ndim)


def channels_last(x: Array) -> Array:
    """``(C, ...) -> (..., C)``, the same values, with ``x`` computed in a loop of its own.

    XLA:CPU emits a loop over an ``(n, C)`` array with the short channel axis innermost, so
    whatever is fused into it runs one element at a time (no vector instructions in the
    compiled loop), re-reading each per-lane input C times; a ``(C, n)`` loop is vectorized
    along ``n``. A plain transpose (``moveaxis``) would be fused with the whole channels-first
    computation back into an ``(n, C)`` loop (``optimization_barrier`` does not stop that on
    CPU), so the axis is moved by a product with the identity: a dot is never fused, and
    ``x * 1 + 0 * y`` is exact for finite values (an inf or NaN in one channel would spread
    to the others; the models that use this return finite values). The move costs an extra
    pass over the output, so it is used only where the per-channel work is large enough to pay
    for it: Torrance-Sparrow ``f`` with a conductor Fresnel term (throughput:
    ``benchmarks/bench_throughput.py``). With the cheaper dielectric term, in the sample weight
    and for Lambert the pass costs about what it saves, so their outputs stay channels last.
    The batch axes are flattened for the product: XLA:CPU's dot over a rank-3 ``(C, S, P)``
    array is much slower than over ``(C, S * P)``, and the renderer calls this with ``(S, P)``
    batches.
    """
    c = x.shape[0]
    if c == 1:
        return x[0][..., None]
    # HIGHEST: the default float32 dot precision on GPUs may round the operands to TF32
    eye = jnp.eye(c, dtype=x.dtype)
    out = jnp.einsum("cn,cd->nd", x.reshape(c, -1), eye, precision=jax.lax.Precision.HIGHEST)
    return out.reshape(*x.shape[1:], c)


def clamp_u(u: Array) -> Array:
    """Clamp uniform numbers to ``[0, 1 - eps]`` so warps never see exactly 1."""
    return jnp.clip(u, 0.0, ONE_MINUS_EPS)


def channel_mean(x: Array) -> Array:
    """Mean over the channel axis of a per-channel parameter (scalar stays scalar)."""
    return jnp.mean(jnp.atleast_1d(x), axis=-1)


class BRDFModel(Node):
    """An analytic BRDF in the local frame (see the module docstring of :mod:`gonio.brdf`).

    Subclasses implement:

    ``_f(wi, wo) -> (..., C)`` or ``(..., 1)``
        the BRDF in sr^-1 for directions both above the horizon (the caller masks the rest);
    ``_pdf(wi, wo) -> (...)``
        the density of ``_sample`` per unit solid angle;
    ``_sample(wo, u) -> wi``
        a direction drawn with density ``_pdf``; it may fall below the horizon (then the sample
        is marked failed);
    ``sampling_weight(wo) -> (...)``
        a cheap estimate of the directional albedo, used to pick lobes in a mixture.
    """

    #: True for lobes that are Dirac deltas (perfect mirror, smooth glass).
    is_delta: ClassVar[bool] = False

    #: The model's own sampler (:meth:`sample`) is its only method (:mod:`gonio.brdf.material`).
    sampling_methods: ClassVar[tuple[str, ...]] = ("native",)

    #: See :class:`gonio.brdf.material.Material`; models evaluate ``wo`` per lane.
    broadcasts_outgoing: ClassVar[bool] = False

    # -- to implement --------------------------------------------------------------------------
    def _f(self, wi: Array, wo: Array) -> Array:
        raise NotImplementedError

    def _f_channels_first(self, wi: Array, wo: Array) -> Array | None:
        """``_f`` with the channel axis first, ``(C, ...)`` or ``(1, ...)`` (the same values),
        or None (the default) where ``f`` is computed channels last. Where given, ``f`` moves
        it to channels last once (:func:`channels_last`)."""
        return None

    def _pdf(self, wi: Array, wo: Array) -> Array:
        raise NotImplementedError

    def _sample(self, wo: Array, u: Array) -> Array:
        raise NotImplementedError

    def sampling_weight(self, wo: Array) -> Array:
        """Estimate of the directional albedo at ``wo`` (shape ``(...)``), for lobe selection."""
        raise NotImplementedError

    # -- the material interface (gonio.brdf.material.Material) ---------------------------------
    @property
    def n_channels(self) -> int:
        """Channel count C (the same as :attr:`channels`)."""
        return self.channels

    @property
    def channel_info(self) -> Channels | None:
        """Mono for C = 1, RGB for C = 3; None otherwise (a model does not know wavelengths)."""
        c = self.n_channels
        return Channels.for_count(c) if c in (1, 3) else None

    @property
    def has_delta(self) -> bool:
        """True when the model is (or, for sums, contains) a Dirac delta lobe."""
        return self.is_delta

    def select_channels(self, idx: Sequence[int]) -> BRDFModel:
        """The model with every per-channel parameter cut down to channels ``idx``
        (per-channel parameters of length C become length ``len(idx)``; scalar, grey,
        parameters stay)."""
        specs = self.param_specs()
        new = {}
        for key, value in self.params().items():
            v = np.asarray(value)
            if specs[key].per_channel and v.ndim == 1 and v.size > 1:
                new[key] = v[idx]
        return self.replace(**new) if new else self

    def with_sampling(self, method: str | None = None, *, proposal: Any = None,
                      wo: Any = None) -> Any:  # fmt: skip
        """The model itself for its own sampler (``None`` or ``"native"``: a model is a pytree
        whose :meth:`sample` is the plain interface), or the generic ``"cosine"`` / ``"lobe"``
        wrappers (:func:`gonio.brdf.sampled.bind_generic`). ``wo`` is not needed."""
        if method is None or method in self.sampling_methods:
            if proposal is not None:
                raise ParameterError("proposal= is used by lobe sampling only")
            return self
        return bind_generic(self, method, proposal)

    # -- public interface ----------------------------------------------------------------------
    def f(self, wi: Array, wo: Array) -> Array:
        """BRDF value in sr^-1, without the cosine: ``(..., 3), (..., 3) -> (..., C)``.

        Zero where either direction is on or below the horizon.
        """
        wi, wo = _directions(wi, wo)
        C = self.channels
        ok = upper(wi) & upper(wo)
        wi_s, wo_s = safe_pair(wi, wo, ok)
        first = self._f_channels_first(wi_s, wo_s)
        if first is not None:
            val = jnp.broadcast_to(first, (C, *ok.shape))
            return channels_last(jnp.where(ok, val, 0.0).astype(wi.dtype))
        val = self._f(wi_s, wo_s)
        shape = (*ok.shape, C)
        val = jnp.broadcast_to(val, shape)
        return jnp.where(ok[..., None], val, 0.0).astype(wi.dtype)

    def pdf(self, wi: Array, wo: Array) -> Array:
        """Density of :meth:`sample` over ``wi`` per unit solid angle, shape ``(...)``."""
        wi, wo = _directions(wi, wo)
        ok = upper(wi) & upper(wo)
        wi_s, wo_s = safe_pair(wi, wo, ok)
        return jnp.where(ok, self._pdf(wi_s, wo_s), 0.0).astype(wi.dtype)

    def sample(self, wo: Array, u: Array) -> BRDFSample:
        """Importance-sample ``wi`` for outgoing ``wo`` ``(..., 3)`` from ``u`` ``(..., 2)``."""
        wo, u = sample_inputs(wo, u)
        wo_s, ok_o = masked_outgoing(wo)
        # The sampled directions stored once, before the pdf, f and weight that read them:
        # XLA:CPU otherwise recomputes the cheap part of the sampler (the polynomial cos/sin
        # included) inside each of their loops. This matters for cheap samplers (Lambert), where
        # that recomputation is a large share of the cost; for Torrance-Sparrow it is neutral.
        wi = jax.lax.optimization_barrier(self._sample(wo_s, u).astype(wo.dtype))
        return self._finish(wi, wo_s, ok_o)

    def _finish(self, wi: Array, wo: Array, ok_o: Array) -> BRDFSample:
        ok = ok_o & upper(wi)
        wi_s, _ = safe_pair(wi, wo, ok)
        pdf = jnp.where(ok, self._pdf(wi_s, wo), 0.0)
        ok = ok & (pdf > 0)
        pdf = jnp.where(ok, pdf, 0.0)
        val = jnp.broadcast_to(self._f(wi_s, wo), (*ok.shape, self.channels))
        weight = safe_div(val * wi_s[..., 2:3], pdf[..., None])
        weight = jnp.where(ok[..., None], weight, 0.0)
        return BRDFSample(wi, pdf.astype(wo.dtype), weight.astype(wo.dtype), jnp.zeros_like(ok))

    def directional_albedo(self, wo: Array, n: int = 128) -> Array:
        """Directional albedo ``int f(wi, wo) cos(theta_i) dwi`` at ``wo`` (..., 3) -> (..., C).

        Estimated with the model's own importance sampler on a stratified ``n x n`` grid of
        ``u`` (deterministic). For delta lobes the sample weights already carry their mass.
        """
        wo = as_float(wo)
        g = (jnp.arange(n, dtype=wo.dtype) + 0.5) / n
        uu = jnp.stack(jnp.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
        s = self.sample(wo[..., None, :], uu)
        return jnp.mean(s.weight, axis=-2)

    def __add__(self, other: BRDFModel) -> BRDFModel:
        if not isinstance(other, BRDFModel):
            return NotImplemented
        # the Sum class by name (registered when gonio.brdf.models is imported), so that this
        # module does not import the module that subclasses it
        Sum = _REGISTRY["Sum"]
        left = self.lobes if isinstance(self, Sum) else (self,)
        right = other.lobes if isinstance(other, Sum) else (other,)
        return Sum(*left, *right)


def _directions(wi: Any, wo: Any) -> tuple[Array, Array]:
    wi = as_float(wi)
    wo = as_float(wo)
    dtype = jnp.result_type(wi, wo)
    wi, wo = jnp.broadcast_arrays(wi.astype(dtype), wo.astype(dtype))
    return wi, wo


def _broadcast_dir_u(w: Array, u: Array) -> tuple[Array, Array]:
    shape = jnp.broadcast_shapes(w.shape[:-1], u.shape[:-1])
    return jnp.broadcast_to(w, (*shape, 3)), jnp.broadcast_to(u, (*shape, 2))


def sample_inputs(wo: Any, u: Any) -> tuple[Array, Array]:
    """``wo`` and ``u`` as floats of one dtype, ``u`` clamped below 1, broadcast together:
    ``(..., 3)`` and ``(..., 2)``. The common start of every ``sample``."""
    wo = as_float(wo)
    u = clamp_u(as_float(u, wo.dtype))
    return _broadcast_dir_u(wo, u)


def masked_outgoing(wo: Array) -> tuple[Array, Array]:
    """``(wo_s, ok)``: ``ok`` where ``wo`` is above the horizon, and ``wo`` with the others
    replaced by the normal so that sampling code never sees degenerate input."""
    ok = upper(wo)
    return jnp.where(ok[..., None], wo, jnp.array([0.0, 0.0, 1.0], wo.dtype)), ok


def safe_pair(wi: Array, wo: Array, ok: Array) -> tuple[Array, Array]:
    """Replace masked-out directions by the normal so model code never sees degenerate input.

    This is what keeps gradients finite: ``jnp.where`` differentiates both branches, so the
    masked branch must itself be finite.
    """
    z = jnp.array([0.0, 0.0, 1.0], dtype=wi.dtype)
    return jnp.where(ok[..., None], wi, z), jnp.where(ok[..., None], wo, z)


def choose_lobe(u0: Array, weights: Sequence[Array]) -> tuple[Array, Array, list[Array]]:
    """Pick one of K lobes with probability proportional to ``weights`` and reuse ``u0``.

    Parameters
    ----------
    u0 : (...) uniform numbers in [0, 1).
    weights : K arrays broadcastable to ``u0``'s shape, non-negative (not necessarily normalized).

    Returns
    -------
    index : (...) int, the chosen lobe.
    u0_remapped : (...) uniform in [0, 1) again, independent of the choice.
    probs : K arrays, the normalized selection probabilities (uniform where all weights are 0).
    """
    ws = [jnp.broadcast_to(jnp.maximum(w, 0.0), u0.shape).astype(u0.dtype) for w in weights]
    total = sum(ws)
    k = len(ws)
    probs = [jnp.where(total > 0, safe_div(w, total), 1.0 / k) for w in ws]
    index = jnp.zeros(u0.shape, dtype=jnp.int32)
    lo = jnp.zeros_like(u0)
    chosen_lo = jnp.zeros_like(u0)
    chosen_p = probs[0]
    for i, p in enumerate(probs):
        hi = lo + p
        take = (u0 >= lo) & ((u0 < hi) | (i == k - 1))
        # A lobe of probability 0 is never taken, even when float rounding says u0 == lo.
        take = take & (p > 0)
        index = jnp.where(take, i, index)
        chosen_lo = jnp.where(take, lo, chosen_lo)
        chosen_p = jnp.where(take, p, chosen_p)
        lo = hi
    remapped = clamp_u(safe_div(u0 - chosen_lo, chosen_p))
    return index, remapped, probs


def mixture_sample(
    wo: Array,
    u: Array,
    weights: Sequence[Array],
    samplers: Sequence[Callable[[Array, Array], Array]],
) -> tuple[Array, list[Array]]:
    """Sample ``wi`` from a mixture of per-lobe samplers; returns ``(wi, probs)``.

    Every sampler runs on the whole batch (vectorized code has no cheaper way) and the chosen
    lobe's direction is kept. The caller's pdf is ``sum_k probs_k * pdf_k``.
    """
    index, u0, probs = choose_lobe(u[..., 0], weights)
    uu = jnp.stack([u0, u[..., 1]], -1)
    wi = samplers[0](wo, uu)
    for i, s in enumerate(samplers[1:], start=1):
        wi = jnp.where((index == i)[..., None], s(wo, uu), wi)
    return wi, probs


def registry() -> dict[str, type[Node]]:
    """Every model and Fresnel class by class name (used by :meth:`Node.from_dict`)."""
    return dict(_REGISTRY)
