"""Reparameterization: a model's named, bounded parameters <-> one flat unconstrained vector ``u``.

Each parameter's :class:`~gonio.brdf.models.Param` metadata chooses its map (elementwise, so the
Jacobian ``dtheta/du`` is diagonal):

``"log"``     ``theta = exp(u)`` (roughness, exponents: values spanning decades);
``"logit"``   ``theta = lo + (hi - lo) * sigmoid(u)`` (albedo-like values bounded on both sides);
``"linear"``  ``theta = u``.

Every optimizer searches ``u`` inside a finite box (``Entry.box``): for "logit" ``|u| <= 12``
(within 6e-6 of the physical bounds), for "log" between the logarithms of the positive bounds
(an infinite or zero bound is replaced by 1e4 times / 1e-4 times the default's magnitude), for
"linear" the physical bounds (an infinite one replaced by the default plus/minus 1e3 times its
magnitude). A solution on the box edge is reported as "on bound".

Channels: a parameter flagged ``per_channel`` (albedos, Fresnel reflectance) gets one value per
data channel; the others (lobe shapes) are shared by every channel. ``gonio.fit.fit(...,
channels="separate")`` instead fits each channel on its own.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf.models import BRDFModel, Param
from gonio.errors import FitError

Array = jnp.ndarray

LOGIT_BOX = 12.0


@dataclass(frozen=True)
class Entry:
    """One fitted parameter (possibly a per-channel vector).

    Attributes
    ----------
    key : model key (``"albedo"``, ``"ward.alpha_x"``).
    spec : the model's Param metadata.
    size : number of values (1, C for per-channel, L or L*C for per-lobe parameters).
    offset : position of the first value in ``u``.
    scale : map used (``"log"``, ``"logit"`` or ``"linear"``).
    lo, hi : physical bounds of the transform (finite).
    box : (lo_u, hi_u) search box in ``u``.
    """

    key: str
    spec: Param
    size: int
    offset: int
    scale: str
    lo: float
    hi: float
    box: tuple[float, float]
    shape: tuple[int, ...] = ()


def _entry(key: str, spec: Param, size: int, offset: int) -> Entry:
    lo, d = float(spec.lower), float(spec.default)
    hi = float(spec.upper if spec.fit_upper is None else spec.fit_upper)  # the search box
    mag = max(abs(d), 1e-3)
    scale = spec.scale
    if scale == "logit" and not (math.isfinite(lo) and math.isfinite(hi)):
        scale = "log" if lo >= 0 else "linear"
    if scale == "log" and lo < 0:
        scale = "linear"
    if scale == "log":
        plo = lo if lo > 0 else mag * 1e-4
        phi = hi if math.isfinite(hi) else mag * 1e4
        return Entry(key, spec, size, offset, "log", plo, phi, (math.log(plo), math.log(phi)))
    if scale == "logit":
        return Entry(key, spec, size, offset, "logit", lo, hi, (-LOGIT_BOX, LOGIT_BOX))
    plo = lo if math.isfinite(lo) else d - 1e3 * mag
    phi = hi if math.isfinite(hi) else d + 1e3 * mag
    return Entry(key, spec, size, offset, "linear", plo, phi, (plo, phi))


def _shape(spec: Param, channels: int, lobes: int) -> tuple[int, ...]:
    """Shape of a fitted parameter: (), (C,), (L,) or (L, C)."""
    if spec.per_lobe:
        return (lobes, channels) if spec.per_channel else (lobes,)
    return (channels,) if spec.per_channel else ()


def _lobe_values(e: Entry, v: np.ndarray, channels: int) -> np.ndarray:
    """A per-lobe value brought to the entry's shape: (L,) or (L, C)."""
    lobes = e.shape[0]
    if len(e.shape) == 2:
        if v.ndim == 1 and v.size == lobes:
            v = v[:, None]  # one scale per lobe, shared by the channels
        elif v.ndim == 1 and lobes == 1 and v.size == channels:
            v = v[None, :]  # a single lobe written with its channels
    try:
        return np.broadcast_to(v, e.shape).copy()
    except ValueError:
        raise FitError(f"{e.key} has shape {v.shape}, expected {e.shape}") from None


class Layout:
    """The map between a template model and the flat vector ``u`` an optimizer works on.

    Parameters
    ----------
    model : template; its current values are the starting point and the values of fixed
        parameters.
    channels : number of data channels C; per-channel parameters get C values.
    fixed : keys (as in ``model.params()``) held at the given value (None: the template's).
    tied : ``{target: source}``: the target parameter always equals the source (e.g. an
        isotropic Ward fit ties ``alpha_y`` to ``alpha_x``); the target is not fitted.
    shared : per-channel keys fitted as one value for every channel (a grey Fresnel ``f0`` on
        spectral data); the template's value is replaced by its channel mean.
    """

    def __init__(
        self,
        model: BRDFModel,
        channels: int,
        fixed: Mapping[str, Any] | None = None,
        tied: Mapping[str, str] | None = None,
        shared: Sequence[str] = (),
    ):
        specs = model.param_specs()
        shared = tuple(k for k in shared if k in specs and specs[k].per_channel)
        specs = {
            k: dataclasses.replace(v, per_channel=False) if k in shared else v
            for k, v in specs.items()
        }
        fixed = dict(fixed or {})
        tied = dict(tied or {})
        for target, source in tied.items():
            if target not in specs or source not in specs or target == source:
                raise FitError(f"cannot tie {target!r} to {source!r}")
            if source in tied:
                raise FitError(f"cannot tie {target!r} to {source!r}, which is itself tied")
            if specs[target].per_channel != specs[source].per_channel:
                raise FitError(f"cannot tie {target!r} to {source!r}: different shapes")
            if source in fixed:
                fixed[target] = fixed[source]
        tied = {t: s for t, s in tied.items() if t not in fixed}
        unknown = sorted(set(fixed) - set(specs))
        if unknown:
            raise FitError(
                f"cannot fix unknown parameter(s) {', '.join(unknown)}; "
                f"{type(model).__name__} has {', '.join(specs)}"
            )
        if fixed:
            model = model.replace(**{k: v for k, v in fixed.items() if v is not None})
        grey = {k: float(np.mean(model.params()[k])) for k in shared if k not in fixed}
        if grey:
            model = model.replace(**grey)
        self.channels = int(channels)
        current = model.params()
        # Lobe count of each node with per-lobe parameters (Lafortune): the length of its
        # per-lobe, not-per-channel values, whose shape (L,) is unambiguous.
        lobes: dict[str, int] = {}
        for key, spec in specs.items():
            if spec.per_lobe and not spec.per_channel:
                node = key.rpartition(".")[0]
                lobes[node] = max(lobes.get(node, 1), int(np.size(current[key])))
        entries: list[Entry] = []
        offset = 0
        for key, spec in specs.items():
            if key in fixed or key in tied:
                continue
            shape = _shape(spec, self.channels, lobes.get(key.rpartition(".")[0], 1))
            size = int(np.prod(shape, dtype=np.int64))
            entries.append(dataclasses.replace(_entry(key, spec, size, offset), shape=shape))
            offset += size
        if not entries:
            raise FitError("every parameter is fixed: nothing to fit")
        # Broadcast per-channel values of the template to C so the model has C channels.
        template_kw = {}
        for e in entries:
            v = np.asarray(current[e.key], dtype=np.float64)
            if e.spec.per_lobe:
                template_kw[e.key] = _lobe_values(e, v, self.channels)
            elif e.spec.per_channel:
                if v.size not in (1, self.channels):
                    raise FitError(
                        f"{e.key} has {v.size} values but the data has {self.channels} channels"
                    )
                template_kw[e.key] = np.broadcast_to(v, (self.channels,)).copy()
        for key, spec in specs.items():
            if key in fixed and spec.per_channel:
                v = np.asarray(current[key], dtype=np.float64)
                if v.size not in (1, self.channels):
                    raise FitError(
                        f"{key} has {v.size} values but the data has {self.channels} channels"
                    )
        for target, source in tied.items():
            template_kw[target] = template_kw.get(source, current[source])
        self.template = model.replace(**template_kw) if template_kw else model
        self.entries = tuple(entries)
        self.size = offset
        self.fixed = tuple(sorted(fixed))
        self.tied = dict(sorted(tied.items()))
        self.shared = tuple(k for k in shared if k in grey)
        self._specs = specs

    # -- names ----------------------------------------------------------------------------------
    @property
    def keys(self) -> list[str]:
        """Fitted parameter keys, in ``u`` order."""
        return [e.key for e in self.entries]

    def flat_names(self, channel_names: tuple[str, ...] | None = None) -> list[str]:
        """One name per entry of ``u``: ``"albedo[R]"`` for per-channel values (C > 1),
        ``"n[lobe1]"`` and ``"rho_s[lobe1,R]"`` for per-lobe ones."""
        labels = channel_names or tuple(str(i) for i in range(self.channels))
        out = []
        for e in self.entries:
            if e.size == 1:
                out.append(e.key)
            elif not e.spec.per_lobe:
                out.extend(f"{e.key}[{labels[i]}]" for i in range(e.size))
            elif len(e.shape) == 1:
                out.extend(f"{e.key}[lobe{i}]" for i in range(e.size))
            else:
                out.extend(
                    f"{e.key}[lobe{i},{labels[c]}]"
                    for i in range(e.shape[0])
                    for c in range(e.shape[1])
                )
        return out

    # -- transforms (JAX, traceable) ------------------------------------------------------------
    def _forward(self, e: Entry, u: Array) -> Array:
        if e.scale == "log":
            return jnp.exp(u)
        if e.scale == "logit":
            return e.lo + (e.hi - e.lo) * jax.nn.sigmoid(u)
        return u

    def theta(self, u: Array) -> Array:
        """Physical values, flat ``(P,)``, for ``u`` ``(P,)``."""
        parts = [self._forward(e, u[e.offset : e.offset + e.size]) for e in self.entries]
        return jnp.concatenate(parts)

    def dtheta_du(self, u: Array) -> Array:
        """Diagonal of the Jacobian ``dtheta/du`` ``(P,)``."""
        parts = []
        for e in self.entries:
            ue = u[e.offset : e.offset + e.size]
            if e.scale == "log":
                parts.append(jnp.exp(ue))
            elif e.scale == "logit":
                s = jax.nn.sigmoid(ue)
                parts.append((e.hi - e.lo) * s * (1 - s))
            else:
                parts.append(jnp.ones_like(ue))
        return jnp.concatenate(parts)

    def to_model(self, u: Array) -> BRDFModel:
        """The template with the fitted parameters replaced (works under jit/grad/vmap)."""
        return self.template.replace(**self.kwargs(u))

    def kwargs(self, u: Array) -> dict[str, Array]:
        """``replace`` keyword arguments for ``u`` (fitted and tied keys; traceable)."""
        th = self.theta(u)
        kw = {}
        for e in self.entries:
            kw[e.key] = th[e.offset : e.offset + e.size].reshape(e.shape)
        for target, source in self.tied.items():
            kw[target] = kw[source]
        return kw

    # -- NumPy side -----------------------------------------------------------------------------
    def inverse(self, values: Mapping[str, Any]) -> np.ndarray:
        """``u`` for physical values (missing keys: the template's), clipped into the box."""
        current = self.template.params()
        u = np.empty(self.size)
        for e in self.entries:
            v = np.asarray(values.get(e.key, current[e.key]), dtype=np.float64)
            v = _lobe_values(e, v, self.channels) if e.spec.per_lobe else v
            v = np.broadcast_to(v, e.shape).reshape(e.size)
            if e.scale == "log":
                ue = np.log(np.clip(v, e.lo, e.hi))
            elif e.scale == "logit":
                t = np.clip((v - e.lo) / (e.hi - e.lo), 1e-300, 1.0)
                with np.errstate(divide="ignore"):
                    ue = np.log(t) - np.log1p(-np.minimum(t, 1 - 1e-16))
            else:
                ue = v
            u[e.offset : e.offset + e.size] = np.clip(ue, *e.box)
        return u

    def initial(self) -> np.ndarray:
        """``u`` of the template, pulled slightly inside the box."""
        u = self.inverse({})
        lo, hi = self.box()
        margin = 1e-3 * (hi - lo)
        return np.clip(u, lo + margin, hi - margin)

    def box(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper ``u`` bounds ``(P,)`` each."""
        lo = np.concatenate([np.full(e.size, e.box[0]) for e in self.entries])
        hi = np.concatenate([np.full(e.size, e.box[1]) for e in self.entries])
        return lo, hi

    def start_box(self) -> tuple[np.ndarray, np.ndarray]:
        """A narrower box for random starts: ``|u| <= 4`` for logit, the full box otherwise."""
        lo, hi = self.box()
        for e in self.entries:
            if e.scale == "logit":
                sl = slice(e.offset, e.offset + e.size)
                lo[sl], hi[sl] = -4.0, 4.0
        return lo, hi

    def random_starts(self, n: int, seed: int) -> np.ndarray:
        """``n`` starting points: the template first, then uniform in :meth:`start_box`."""
        rng = np.random.default_rng(seed)
        lo, hi = self.start_box()
        starts = [self.initial()]
        starts += [rng.uniform(lo, hi) for _ in range(max(n - 1, 0))]
        return np.stack(starts)

    def theta_np(self, u: np.ndarray) -> np.ndarray:
        """:meth:`theta` in NumPy (no per-operation compilation outside a trace)."""
        u = np.asarray(u, dtype=np.float64)
        parts = []
        for e in self.entries:
            ue = u[e.offset : e.offset + e.size]
            if e.scale == "log":
                parts.append(np.exp(ue))
            elif e.scale == "logit":
                parts.append(e.lo + (e.hi - e.lo) / (1.0 + np.exp(-ue)))
            else:
                parts.append(ue)
        return np.concatenate(parts)

    def values(self, u: np.ndarray) -> dict[str, np.ndarray | float]:
        """Physical values by key (float for shared, array (C,) for per-channel)."""
        th = self.theta_np(u)
        out: dict[str, np.ndarray | float] = {}
        for e in self.entries:
            v = th[e.offset : e.offset + e.size]
            out[e.key] = float(v[0]) if e.shape == () else v.reshape(e.shape).copy()
        return out

    def on_bounds(self, u: np.ndarray, rtol: float = 1e-4) -> list[str]:
        """Flat names (channel index form) of the values lying on their box edge."""
        lo, hi = self.box()
        tol = rtol * (hi - lo)
        names = self.flat_names()
        return [
            n
            for n, x, a, b, t in zip(names, u, lo, hi, tol, strict=True)
            if x <= a + t or x >= b - t
        ]

    def model(self, u: np.ndarray) -> BRDFModel:
        """Concrete model (validated) for ``u``, with values clipped into the physical bounds."""
        vals = self.values(u)
        specs = {e.key: e.spec for e in self.entries}
        kw = {k: np.clip(v, specs[k].lower, specs[k].upper) for k, v in vals.items()}
        for target, source in self.tied.items():
            kw[target] = kw[source]
        return self.template.replace(**kw)
