"""Tabulated BRDFs on a grid (:class:`TabulatedBRDF`) and scattered measurements
(:class:`MeasuredSamples`).

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

JAX
---
:meth:`TabulatedBRDF.f` is pure JAX, vectorized over any batch shape, and keeps float32 inputs in
float32. A table is also a registered pytree (its leaves are the float32 lookup arrays), so it can
be passed to ``jax.jit`` as an argument or closed over. The sampling structures (see
:mod:`gonio.brdf.sampling` and :meth:`TabulatedBRDF.sample`) are built lazily, on the host, from the
table's values; they are shared by every copy of the table that a pytree round trip makes.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any, Literal

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf import frames
from gonio.brdf._xla import materialize
from gonio.brdf.models._base import BRDFSample
from gonio.errors import FormatError, ParameterError

Array = jnp.ndarray

PARAMETERIZATIONS = {
    "half_diff_iso": ("theta_h", "theta_d", "phi_d"),
    "half_diff_aniso": ("theta_h", "phi_h", "theta_d", "phi_d"),
}
INTERPOLATIONS = ("linear", "nearest")
_EPS_ANGLE = 1e-9


def _one_minus_eps(dtype: Any) -> float:
    return float(np.nextafter(np.dtype(dtype).type(1.0), np.dtype(dtype).type(0.0)))


# ---------------------------------------------------------------------------------------------
# Channels
# ---------------------------------------------------------------------------------------------
class Channels:
    """What the last axis of a table's values means.

    Parameters
    ----------
    kind : ``"rgb"``, ``"spectral"`` or ``"mono"``.
    names : one name per channel (defaults: ``("R", "G", "B")``, ``("Y",)``, ``("450nm", ...)``).
    wavelengths_nm : for ``"spectral"``, the strictly increasing wavelengths in nm, shape ``(C,)``.
    primaries : for ``"rgb"``, the colour primaries (``"sRGB"`` or ``"Rec709"``; default sRGB).
    white_point : for ``"rgb"``, the white point (default ``"D65"``).

    ``len(channels)`` (and ``operator.index``) is the channel count C. Instances are immutable,
    hashable and compare by value.
    """

    __slots__ = ("_names", "_wl", "kind", "primaries", "white_point")

    def __init__(
        self,
        kind: Literal["rgb", "spectral", "mono"],
        names: Sequence[str] | None = None,
        wavelengths_nm: Any = None,
        primaries: str | None = None,
        white_point: str | None = None,
    ) -> None:
        if kind not in ("rgb", "spectral", "mono"):
            raise ParameterError(f"Channels: kind must be rgb, spectral or mono, got {kind!r}")
        wl: tuple[float, ...] | None = None
        if kind == "spectral":
            if wavelengths_nm is None:
                raise ParameterError("Channels: spectral channels need wavelengths_nm")
            try:
                arr = np.asarray(wavelengths_nm, dtype=np.float64).reshape(-1)
            except (TypeError, ValueError):
                raise ParameterError("Channels: wavelengths_nm must be numbers") from None
            if arr.size == 0 or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
                raise ParameterError("Channels: wavelengths_nm must be positive and finite")
            if np.any(np.diff(arr) <= 0):
                raise ParameterError("Channels: wavelengths_nm must be strictly increasing")
            wl = tuple(float(x) for x in arr)
            default_names = tuple(f"{x:g}nm" for x in wl)
        elif wavelengths_nm is not None:
            raise ParameterError(f"Channels: wavelengths_nm given for {kind} channels")
        elif kind == "rgb":
            default_names = ("R", "G", "B")
        else:
            default_names = ("Y",)
        names = tuple(str(n) for n in names) if names is not None else default_names
        if len(names) != len(default_names):
            raise ParameterError(
                f"Channels: {kind} needs {len(default_names)} names, got {len(names)}"
            )
        if kind == "rgb":
            primaries = primaries or "sRGB"
            white_point = white_point or "D65"
            if primaries not in ("sRGB", "Rec709"):
                raise ParameterError(f"Channels: unknown primaries {primaries!r}")
        elif primaries is not None or white_point is not None:
            raise ParameterError(f"Channels: primaries/white_point only apply to rgb, not {kind}")
        object.__setattr__(self, "kind", kind)
        object.__setattr__(self, "_names", names)
        object.__setattr__(self, "_wl", wl)
        object.__setattr__(self, "primaries", primaries)
        object.__setattr__(self, "white_point", white_point)

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("Channels is immutable")

    @classmethod
    def rgb(cls, primaries: str = "sRGB", white_point: str = "D65") -> Channels:
        """Three linear RGB channels."""
        return cls("rgb", primaries=primaries, white_point=white_point)

    @classmethod
    def mono(cls) -> Channels:
        """A single channel."""
        return cls("mono")

    @classmethod
    def spectral(cls, wavelengths_nm: Any) -> Channels:
        """One channel per wavelength (nm)."""
        return cls("spectral", wavelengths_nm=wavelengths_nm)

    @classmethod
    def for_count(cls, n: int) -> Channels:
        """Default description for ``n`` channels: mono for 1, RGB for 3 (else ParameterError)."""
        if n == 1:
            return cls.mono()
        if n == 3:
            return cls.rgb()
        raise ParameterError(f"{n} channels need an explicit Channels description (spectral?)")

    @property
    def names(self) -> tuple[str, ...]:
        return self._names

    @property
    def wavelengths_nm(self) -> np.ndarray | None:
        """Wavelengths in nm ``(C,)`` for spectral channels, else None."""
        return None if self._wl is None else np.array(self._wl)

    def __len__(self) -> int:
        return len(self._names)

    def __index__(self) -> int:
        return len(self._names)

    def _key(self) -> tuple[Any, ...]:
        return (self.kind, self._names, self._wl, self.primaries, self.white_point)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Channels) and self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())

    def __repr__(self) -> str:
        if self.kind == "spectral":
            return f"Channels.spectral({list(self._wl or ())})"
        if self.kind == "rgb":
            return f"Channels.rgb({self.primaries!r}, {self.white_point!r})"
        return "Channels.mono()"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description (inverse: :meth:`from_dict`)."""
        return {
            "kind": self.kind,
            "names": list(self._names),
            "wavelengths_nm": None if self._wl is None else list(self._wl),
            "primaries": self.primaries,
            "white_point": self.white_point,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Channels:
        """Inverse of :meth:`to_dict`; raises FormatError on a malformed description."""
        try:
            return cls(
                d["kind"],
                names=d.get("names"),
                wavelengths_nm=d.get("wavelengths_nm"),
                primaries=d.get("primaries"),
                white_point=d.get("white_point"),
            )
        except (KeyError, TypeError) as e:
            raise FormatError(f"malformed channel description: {e}") from None
        except ParameterError as e:
            raise FormatError(str(e)) from None


# ---------------------------------------------------------------------------------------------
# Axis
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Axis:
    """One axis of a table grid.

    Attributes
    ----------
    name : ``"theta_h"``, ``"phi_h"``, ``"theta_d"`` or ``"phi_d"``.
    size : number of nodes (>= 1).
    lo, hi : angle range in radians; the warped coordinate ``x in [0, 1]`` maps onto it.
    warp : ``"linear"`` (angle = lo + (hi - lo) x) or ``"sqrt"`` (angle = lo + (hi - lo) x**2,
        MERL's theta_h: nodes dense near lo).
    periodic : whether the axis wraps around with period ``hi - lo`` (azimuths); only with a
        linear warp.
    node_offset : node ``i`` sits at ``x_i = (i + node_offset) / size``, in [0, 1): 0 puts nodes
        at cell starts (MERL), 0.5 at cell centres.
    """

    name: str
    size: int
    lo: float
    hi: float
    warp: Literal["linear", "sqrt"] = "linear"
    periodic: bool = False
    node_offset: float = 0.0

    def __post_init__(self) -> None:
        try:
            size = int(self.size)
            lo, hi, off = float(self.lo), float(self.hi), float(self.node_offset)
        except (TypeError, ValueError):
            raise ParameterError(
                f"Axis {self.name!r}: size/lo/hi/node_offset must be numbers"
            ) from None
        if size != self.size or size < 1:
            raise ParameterError(f"Axis {self.name!r}: size must be a positive integer")
        if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
            raise ParameterError(f"Axis {self.name!r}: need finite lo < hi, got [{lo}, {hi}]")
        if self.warp not in ("linear", "sqrt"):
            raise ParameterError(f"Axis {self.name!r}: warp must be linear or sqrt")
        if not (0.0 <= off < 1.0):
            raise ParameterError(f"Axis {self.name!r}: node_offset must be in [0, 1), got {off}")
        if self.periodic and self.warp != "linear":
            raise ParameterError(f"Axis {self.name!r}: a periodic axis must be linear")
        object.__setattr__(self, "size", size)
        object.__setattr__(self, "lo", lo)
        object.__setattr__(self, "hi", hi)
        object.__setattr__(self, "node_offset", off)
        object.__setattr__(self, "periodic", bool(self.periodic))

    # -- host-side helpers (NumPy, float64) ----------------------------------------------------
    def nodes(self) -> np.ndarray:
        """Angles of the nodes in radians, ``(size,)`` float64."""
        return self.angle_of(np.arange(self.size, dtype=np.float64))

    def angle_of(self, index: Any) -> np.ndarray:
        """Angle (radians) at a continuous node index (NumPy)."""
        x = (np.asarray(index, dtype=np.float64) + self.node_offset) / self.size
        if self.warp == "sqrt":
            x = np.sign(x) * x * x
        return self.lo + (self.hi - self.lo) * x

    def edges(self) -> np.ndarray:
        """Angles of the cell boundaries halfway (in index space) between nodes, ``(size + 1,)``.

        The first and last edges are the axis ends ``lo`` and ``hi``: what lies beyond the end
        nodes is clamped to them (or wraps, for periodic axes).
        """
        e = self.angle_of(np.arange(self.size + 1, dtype=np.float64) - 0.5)
        e[0], e[-1] = self.lo, self.hi
        return np.clip(e, self.lo, self.hi)

    def continuous_index(self, angle: Any) -> Any:
        """Continuous node index of ``angle`` (JAX, keeps dtype); not clamped or wrapped."""
        a = jnp.asarray(angle)
        x = (a - self.lo) * (1.0 / (self.hi - self.lo))
        if self.warp == "sqrt":
            x = jnp.sqrt(jnp.maximum(x, 0.0))
        return x * self.size - self.node_offset

    def nearest_index(self, angle: Any) -> Any:
        """Index of the nearest node (int32; clamped, or wrapped for periodic axes)."""
        t = jnp.round(self.continuous_index(angle)).astype(jnp.int32)
        if self.periodic:
            return jnp.mod(t, self.size)
        return jnp.clip(t, 0, self.size - 1)

    def cell_index(self, angle: Any) -> Any:
        """``floor(x * size)`` clamped to ``0..size-1`` (wrapped if periodic), int32.

        With ``node_offset = 0`` this is the binning of MERL's reference code: the cell whose lower
        edge is at or below ``angle``.
        """
        a = jnp.asarray(angle)
        x = (a - self.lo) * (1.0 / (self.hi - self.lo))
        if self.warp == "sqrt":
            x = jnp.sqrt(jnp.maximum(x, 0.0))
        i = jnp.floor(x * self.size).astype(jnp.int32)
        if self.periodic:
            return jnp.mod(i, self.size)
        return jnp.clip(i, 0, self.size - 1)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description (inverse: :meth:`from_dict`)."""
        return {
            "name": self.name,
            "size": self.size,
            "lo": self.lo,
            "hi": self.hi,
            "warp": self.warp,
            "periodic": self.periodic,
            "node_offset": self.node_offset,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Axis:
        """Inverse of :meth:`to_dict`; raises FormatError on a malformed description."""
        try:
            return cls(
                str(d["name"]),
                d["size"],
                d["lo"],
                d["hi"],
                d.get("warp", "linear"),
                bool(d.get("periodic", False)),
                d.get("node_offset", 0.0),
            )
        except (KeyError, TypeError) as e:
            raise FormatError(f"malformed axis description: {e}") from None
        except ParameterError as e:
            raise FormatError(str(e)) from None


def merl_axes() -> tuple[Axis, Axis, Axis]:
    """MERL's 90 x 90 x 180 isotropic grid (Matusik et al. 2003).

    theta_h: 90 nodes at ``(i / 90)**2 * pi / 2`` ("sqrt" warp); theta_d: 90 nodes at
    ``i / 90 * pi / 2``; phi_d: 180 nodes at ``i / 180 * pi`` over ``[0, pi)``, periodic (folded by
    reciprocity). All with ``node_offset = 0``.
    """
    half = math.pi / 2
    return (
        Axis("theta_h", 90, 0.0, half, "sqrt", False, 0.0),
        Axis("theta_d", 90, 0.0, half, "linear", False, 0.0),
        Axis("phi_d", 180, 0.0, math.pi, "linear", True, 0.0),
    )


def default_axes(
    parameterization: str = "half_diff_iso",
    n_theta_h: int = 90,
    n_theta_d: int = 90,
    n_phi_d: int | None = None,
    n_phi_h: int = 180,
) -> tuple[Axis, ...]:
    """Axes for a new table: MERL-like (sqrt-warped theta_h), nodes at ``node_offset = 0``.

    ``n_phi_d`` defaults to 180 over ``[0, pi)`` (isotropic, folded) or 360 over ``[0, 2 pi)``
    (anisotropic); ``n_phi_h`` is used only for anisotropic tables.
    """
    half = math.pi / 2
    th = Axis("theta_h", n_theta_h, 0.0, half, "sqrt", False, 0.0)
    td = Axis("theta_d", n_theta_d, 0.0, half, "linear", False, 0.0)
    if parameterization == "half_diff_iso":
        return (th, td, Axis("phi_d", n_phi_d or 180, 0.0, math.pi, "linear", True, 0.0))
    if parameterization == "half_diff_aniso":
        ph = Axis("phi_h", n_phi_h, 0.0, 2 * math.pi, "linear", True, 0.0)
        pd = Axis("phi_d", n_phi_d or 360, 0.0, 2 * math.pi, "linear", True, 0.0)
        return (th, ph, td, pd)
    raise ParameterError(f"unknown parameterization {parameterization!r}")


# ---------------------------------------------------------------------------------------------
# Lookup kernels (pure JAX)
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Spec:
    """Static description of a table needed by the lookup kernel (hashable)."""

    axes: tuple[Axis, ...]
    parameterization: str
    interpolation: str
    has_mask: bool
    n_channels: int
    fold: int  # phi_d folding for iso tables: 0 none, 1 reciprocity, 2 reciprocity + mirror


# atan(a) ~= a P(a^2) on [0, 1]: odd polynomial fitted for minimal relative error (max 9e-8 in
# float64, 2.2e-7 evaluated in float32). XLA's float32 atan2 is ~40x slower on CPU and this is the
# hot path of every table lookup; float64 input keeps jnp.arctan2.
_ATAN_COEFFS = (
    0.9999999110764471,
    -0.33332092081615694,
    0.19971358427746339,
    -0.1402933562974844,
    0.09942544849997133,
    -0.05990181920915065,
    0.024555142746539572,
    -0.004779915421027742,
)


def atan2(y: Array, x: Array) -> Array:
    """``arctan2(y, x)`` in (-pi, pi]; a fast polynomial for float32/float16, exact for float64."""
    dtype = jnp.result_type(y, x)
    if dtype == jnp.float64:
        return jnp.arctan2(y, x)
    ax, ay = jnp.abs(x), jnp.abs(y)
    mx, mn = jnp.maximum(ax, ay), jnp.minimum(ax, ay)
    a = mn / jnp.where(mx > 0, mx, 1.0)
    s = a * a
    r = jnp.full_like(a, _ATAN_COEFFS[-1])
    for c in reversed(_ATAN_COEFFS[:-1]):
        r = r * s + c
    r = r * a
    r = jnp.where(ay > ax, np.float32(np.pi / 2) - r, r)
    r = jnp.where(x < 0, np.float32(np.pi) - r, r)
    return jnp.where(y < 0, -r, r).astype(dtype)


def _half_diff_fast(wi: Array, wo: Array, need_phi_h: bool) -> tuple[Array, ...]:
    """Rusinkiewicz angles without trigonometric round trips (same conventions as
    :func:`gonio.brdf.frames.half_diff`); hand-written because this is the hot path of lookups."""
    # per component, not jnp.sum over the last axis: a reduction would store h as (..., 3)
    hx, hy, hz = wi[..., 0] + wo[..., 0], wi[..., 1] + wo[..., 1], wi[..., 2] + wo[..., 2]
    inv_h = jax.lax.rsqrt(jnp.maximum(hx * hx + hy * hy + hz * hz, 1e-30))
    hx, hy, hz = hx * inv_h, hy * inv_h, hz * inv_h
    r2 = hx * hx + hy * hy
    pole = r2 <= 0
    inv_r = jnp.where(pole, 0.0, jax.lax.rsqrt(jnp.where(pole, 1.0, r2)))
    r = r2 * inv_r
    c = jnp.where(pole, 1.0, hx * inv_r)
    s = jnp.where(pole, 0.0, hy * inv_r)
    x, y, z = wi[..., 0], wi[..., 1], wi[..., 2]
    x1 = c * x + s * y
    y1 = -s * x + c * y
    dx = hz * x1 - r * z
    dz = r * x1 + hz * z
    theta_h = atan2(r, hz)
    theta_d = atan2(jnp.sqrt(dx * dx + y1 * y1), dz)
    two_pi = 2 * jnp.pi
    phi_d = atan2(y1, dx)
    phi_d = jnp.where(phi_d < 0, phi_d + two_pi, phi_d)
    if not need_phi_h:
        return theta_h, theta_d, phi_d
    phi_h = jnp.where(pole, 0.0, atan2(hy, hx))
    phi_h = jnp.where(phi_h < 0, phi_h + two_pi, phi_h)
    return theta_h, phi_h, theta_d, phi_d


def _coords(spec: _Spec, wi: Array, wo: Array) -> list[Array]:
    """Angles along each axis of the table for the direction pairs."""
    if spec.parameterization == "half_diff_iso":
        th, td, pd = _half_diff_fast(wi, wo, need_phi_h=False)
        if spec.fold >= 1:
            pd = jnp.where(pd >= jnp.pi, pd - jnp.pi, pd)
        if spec.fold >= 2:
            pd = jnp.minimum(pd, jnp.pi - pd)
        return [th, td, pd]
    th, ph, td, pd = _half_diff_fast(wi, wo, need_phi_h=True)
    return [th, ph, td, pd]


def _axis_corners(ax: Axis, angle: Array) -> tuple[Array, Array, Array]:
    """``(i0, i1, frac)`` of the two nodes bracketing ``angle`` and the weight of ``i1``."""
    return _index_corners(ax, _wrapped_index(ax, angle))


def _wrapped_index(ax: Axis, angle: Array) -> Array:
    """Continuous node index of ``angle``, wrapped into ``[0, n)`` on periodic axes."""
    t = ax.continuous_index(angle)
    if ax.periodic and ax.size > 1:
        t = jnp.mod(t, float(ax.size))
    return t


def _index_corners(ax: Axis, t: Array) -> tuple[Array, Array, Array]:
    """:func:`_axis_corners` from the output of :func:`_wrapped_index`."""
    n = ax.size
    if n == 1:
        zero = jnp.zeros(t.shape, jnp.int32)
        return zero, zero, jnp.zeros_like(t)
    if ax.periodic:
        i0f = jnp.floor(t)
        frac = t - i0f
        i0 = i0f.astype(jnp.int32)
        i0 = jnp.where(i0 >= n, i0 - n, i0)  # mod can round up to exactly n
        i1 = jnp.where(i0 + 1 >= n, 0, i0 + 1)
        return i0, i1, frac
    t = jnp.clip(t, 0.0, float(n - 1))
    i0 = jnp.minimum(jnp.floor(t).astype(jnp.int32), n - 2)
    frac = t - i0.astype(t.dtype)
    return i0, i0 + 1, frac


def _corner_params(spec: _Spec, coords: Sequence[Array]) -> list[tuple[Array, Array, Array]]:
    """Per axis ``(i0, i1, frac)`` (see :func:`_axis_corners`) from continuous indices stored
    once (:func:`gonio.brdf._xla.materialize`): otherwise XLA recomputes the angle-to-index
    arithmetic inside each of the gather loops, as scalar code."""
    ts = [_wrapped_index(ax, a) for ax, a in zip(spec.axes, coords, strict=True)]
    ts = materialize(ts, coords[0])
    return [_index_corners(ax, t) for ax, t in zip(spec.axes, ts, strict=True)]


def _strides(axes: Sequence[Axis]) -> list[int]:
    strides = [1] * len(axes)
    for a in range(len(axes) - 2, -1, -1):
        strides[a] = strides[a + 1] * axes[a + 1].size
    return strides


def _corner_bits(mask: np.ndarray, axes: Sequence[Axis]) -> np.ndarray:
    """Per node, which corners of the interpolation cell it starts are valid: bit ``j`` of
    entry ``flat`` is the mask at corner ``j`` (in :func:`_interpolate`'s order) of the cell
    whose first corner is node ``flat``. ``(*mask.shape)``, uint8 for 3-D tables (8 corners),
    uint16 for 4-D.

    One gather of these bits replaces a gather of the mask per corner in every lookup (a
    corner's second index is a function of its first: the next node, wrapped on periodic
    axes); the weights and sums are the same, so lookups are bit for bit those of the mask.
    """
    d = mask.ndim
    dtype = np.min_scalar_type(2 ** (2**d) - 1).type  # one bit per corner
    firsts, seconds = [], []
    for ax in axes:
        i0 = np.arange(ax.size)
        if ax.size == 1:
            i1 = i0
        elif ax.periodic:
            i1 = np.where(i0 + 1 >= ax.size, 0, i0 + 1)
        else:  # the last node never starts a cell (see _index_corners)
            i1 = np.minimum(i0 + 1, ax.size - 1)
        firsts.append(i0)
        seconds.append(i1)
    bits = np.zeros(mask.shape, dtype)
    for j, corner in enumerate(itertools.product((0, 1), repeat=d)):
        idx = np.ix_(*(s if b else f for f, s, b in zip(firsts, seconds, corner, strict=True)))
        bits |= mask[idx].astype(dtype) << dtype(j)
    return bits


def _interpolate(spec: _Spec, data: tuple[Array, Array | None], coords: Sequence[Array]) -> Array:
    """Multilinear or nearest lookup at axis angles.

    ``data`` is ``(values, bits)``: values ``(n_nodes, C)`` premultiplied by the mask (invalid
    nodes hold 0), and per node the validity of the corners of the cell it starts
    (:func:`_corner_bits`), or None when every node is valid. Invalid corners get no weight:
    the result is the weighted mean of the valid ones (0 where none is).
    """
    vals, bits = data
    strides = _strides(spec.axes)
    dtype = coords[0].dtype
    per_axis = _corner_params(spec, coords)
    if spec.interpolation == "nearest" and bits is None:
        flat = sum(
            jnp.where(frac >= 0.5, i1, i0) * s
            for (i0, i1, frac), s in zip(per_axis, strides, strict=True)
        )
        return jnp.take(vals, flat, axis=0, mode="clip").astype(dtype)
    corners = []
    for corner in itertools.product((0, 1), repeat=len(per_axis)):
        flat = None
        w = None
        for (i0, i1, frac), b, s in zip(per_axis, corner, strides, strict=True):
            idx = (i1 if b else i0) * s
            flat = idx if flat is None else flat + idx
            wa = frac if b else 1 - frac
            w = wa if w is None else w * wa
        corners.append((flat, w))
    if bits is not None:
        # the cell's corner validity, one gather (corner 0 is the cell's first node)
        cell = jnp.take(bits, corners[0][0], axis=0, mode="clip").astype(jnp.int32)
        valid = [((cell >> j) & 1).astype(dtype) for j in range(len(corners))]
    if spec.interpolation == "nearest":
        best_w = None
        best_flat = None
        for (flat, w), m in zip(corners, valid, strict=True):
            score = w * m + m * 1e-6  # a valid corner always beats an invalid one
            if best_w is None:
                best_w, best_flat = score, flat
            else:
                better = score >= best_w  # ties go to the upper node: floor of the index
                best_w = jnp.where(better, score, best_w)
                best_flat = jnp.where(better, flat, best_flat)
        val = jnp.take(vals, best_flat, axis=0, mode="clip").astype(dtype)
        return jnp.where(best_w[..., None] > 0, val, 0.0)
    num = sum(w[..., None] * jnp.take(vals, flat, axis=0, mode="clip") for flat, w in corners)
    num = num.astype(dtype)
    if bits is None:
        return num
    den = sum(w * m for (_, w), m in zip(corners, valid, strict=True))
    (den,) = materialize([den.astype(dtype)], coords[0])  # once, not once per channel
    den = den[..., None]
    ok = den > 0
    return jnp.where(ok, num / jnp.where(ok, den, 1.0), 0.0)


@partial(jax.jit, static_argnames=("spec",))
def _eval_kernel(data: tuple[Array, Array | None], wi: Array, wo: Array, spec: _Spec) -> Array:
    coords = _coords(spec, wi, wo)
    val = _interpolate(spec, data, coords)
    ok = (wi[..., 2] > 0) & (wo[..., 2] > 0)
    return jnp.where(ok[..., None], val, 0.0)


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


def _sampled_values(spec: _Spec, data: Any, wo_s: Array, wi: Array) -> tuple[Array, Array]:
    """``(wi, f)``: the table at sampled ``(wi, wo_s)``, for :meth:`TabulatedBRDF.sample` when
    the sampler has not looked it up. Called eagerly, the lookup is a jit call of its own, not
    part of :func:`_sample_result`, where XLA's CPU backend fuses the weight arithmetic into
    the lookup's gather loops (about 1.1x slower)."""
    if isinstance(wi, jax.core.Tracer):
        # under an outer jit, wi stored once, per component, before the lookup and used after
        # it: otherwise XLA fuses the sampler's arithmetic into the lookup's loops (about 5 %
        # slower; called eagerly, storing it costs 13 %)
        wi = jnp.stack(materialize([wi[..., 0], wi[..., 1], wi[..., 2]], wi[..., 0]), -1)
    return wi, _eval_kernel(data, wi, wo_s, spec)


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
        vals = _float_array(values, "values")
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
        sig = None
        if sigma is not None:
            sig = _float_array(sigma, "sigma")
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
        if channels is None:
            try:
                channels = Channels.for_count(C)
            except ParameterError as e:
                raise ParameterError(f"values have {C} channels: {e}") from None
        if not isinstance(channels, Channels):
            raise ParameterError("channels must be a Channels object")
        if len(channels) != C:
            raise FormatError(f"values have {C} channels but channels describes {len(channels)}")
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
        has_mask = not bool(m.all())
        fold = 0
        if parameterization == "half_diff_iso":
            span = axes[2].hi
            fold = 2 if span <= math.pi / 2 + _EPS_ANGLE else (1 if span <= math.pi + 1e-6 else 0)
        self._spec = _Spec(axes, parameterization, interpolation, has_mask, C, fold)
        clean = np.where(m[..., None], vals, np.float32(0.0)).reshape(-1, C)
        bits = jnp.asarray(_corner_bits(m, axes).reshape(-1)) if has_mask else None
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
        wi, wo = _node_directions(axes, parameterization)
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
        return _eval_kernel(self._data, wi, wo, self._spec)

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
        return _interpolate(self._spec, self._data, [a.astype(dtype) for a in arrs])

    # -- sampling ----------------------------------------------------------------------------------
    def _sampler(self) -> Any:
        from gonio.brdf._table_sampling import TableSampler

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
    ) -> BRDFSample:
        """Importance-sample ``wi`` proportionally to ``mean_channels(f) cos(theta_i)``.

        Parameters
        ----------
        wo : ``(..., 3)`` outgoing directions.
        u : ``(..., 2)`` uniform numbers in [0, 1).
        method : ``"inversion"``, ``"alias"`` (piecewise-constant density per incident-grid cell
            and outgoing bucket) or ``"rejection"`` (exactly ``g cos / rho(wo)``); see
            :mod:`gonio.brdf._table_sampling`.
        rng : rejection only: where the extra random numbers come from (a NumPy Generator, an
            int seed or a JAX key); default: derived deterministically from ``u``.
        proposal : rejection only: ``"majorant"`` (default: a piecewise-constant bound of
            ``g cos`` per incident-grid cell and outgoing bucket, drawn from an alias table; the
            fastest), ``"cosine"``, or an analytic model whose ``sample``/``pdf`` is used (mixed
            with 10 % cosine sampling). The sampled density is the same for all three.

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
        wi, pdf, val = self._sampler().sample(wo_s, u, method, rng, proposal)
        if val is None:  # the sampler did not look the table up at wi
            wi, val = _sampled_values(self._spec, self._data, wo_s, wi.astype(wo.dtype))
        return _sample_result(wo, wi, pdf, val)

    def pdf(self, wi: Any, wo: Any, method: str = "inversion", proposal: Any = "majorant") -> Array:
        """Density of :meth:`sample` (same ``method``/``proposal``) over ``wi`` per unit solid
        angle, shape ``(...)``; 0 when either direction is on or below the horizon."""
        wi, wo = _as_dirs(wi, wo)
        ok_o = wo[..., 2] > 0
        wo_s = jnp.where(ok_o[..., None], wo, jnp.array([0.0, 0.0, 1.0], wo.dtype))
        p = self._sampler().pdf(wi, wo_s, method, proposal)
        return jnp.where(ok_o & (wi[..., 2] > 0), p, 0.0).astype(wo.dtype)

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
        return _node_directions(self.axes, self.parameterization)

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

    def to_samples(self) -> MeasuredSamples:
        """Valid nodes whose directions are both above the horizon, as :class:`MeasuredSamples`.

        ``weights`` are the cell measures of :meth:`cell_measure` (sr^2), so that sums over the
        samples approximate integrals over direction pairs.
        """
        wi, wo = self.node_directions()
        keep = self.mask.reshape(-1) & (wi[:, 2] > 0) & (wo[:, 2] > 0)
        C = self.n_channels
        vals = self.values.reshape(-1, C)[keep]
        sig = None if self.sigma is None else self.sigma.reshape(-1, C)[keep]
        weights = self.cell_measure().reshape(-1)[keep]
        meta = dict(self.meta)
        meta["converted_from"] = f"TabulatedBRDF {self.parameterization} {self.shape}"
        return MeasuredSamples(wi[keep], wo[keep], vals, sig, self.channels, weights, meta)

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


def _float_array(x: Any, what: str) -> np.ndarray:
    try:
        arr = np.asarray(x)
    except (TypeError, ValueError):
        raise FormatError(f"{what} is not an array") from None
    if arr.dtype.kind not in "fiu":
        raise FormatError(f"{what} must be numeric, got dtype {arr.dtype}")
    return np.array(arr, dtype=np.float32)


def _describe(model: Any) -> Any:
    to_dict = getattr(model, "to_dict", None)
    if callable(to_dict):
        try:
            return to_dict()
        except Exception:  # a description is best effort; tabulating must not fail on it
            pass
    return repr(model)


def _node_directions(axes: Sequence[Axis], parameterization: str) -> tuple[np.ndarray, ...]:
    nodes = [a.nodes() for a in axes]
    mesh = np.meshgrid(*nodes, indexing="ij")
    if parameterization == "half_diff_iso":
        th, td, pd = (m.reshape(-1) for m in mesh)
        ph = np.zeros_like(th)
    else:
        th, ph, td, pd = (m.reshape(-1) for m in mesh)
    wi, wo = frames.half_diff_to_directions(th, ph, td, pd)
    return np.asarray(wi, np.float64), np.asarray(wo, np.float64)


# ---------------------------------------------------------------------------------------------
# MeasuredSamples
# ---------------------------------------------------------------------------------------------
class MeasuredSamples:
    """Scattered BRDF measurements, as acquired: one row per (wi, wo) pair.

    Parameters
    ----------
    wi, wo : ``(N, 3)`` unit directions in the local frame (renormalized; a norm off by more
        than 1e-3 is an error).
    values : ``(N, C)`` BRDF values in 1/sr (stored float64).
    sigma : ``(N, C)`` one-standard-deviation uncertainty in 1/sr, or None.
    channels : :class:`Channels` (default from C: mono or RGB).
    weights : ``(N,)`` non-negative measure or fitting weights, or None.
    meta : provenance, JSON-ready.
    mask : ``(N,)`` bool, optional: rows marked False are dropped here (they may hold NaN).

    Raises
    ------
    FormatError
        wrong shapes, non-finite values in kept rows, negative sigma or weights.
    """

    def __init__(
        self,
        wi: Any,
        wo: Any,
        values: Any,
        sigma: Any = None,
        channels: Channels | None = None,
        weights: Any = None,
        meta: Mapping[str, Any] | None = None,
        *,
        mask: Any = None,
    ) -> None:
        wi = _f64(wi, "wi")
        wo = _f64(wo, "wo")
        vals = _f64(values, "values")
        if wi.ndim != 2 or wi.shape[1] != 3 or wo.shape != wi.shape:
            raise FormatError(f"wi and wo must both be (N, 3), got {wi.shape} and {wo.shape}")
        n = wi.shape[0]
        if vals.ndim == 1:
            vals = vals[:, None]
        if vals.ndim != 2 or vals.shape[0] != n or vals.shape[1] < 1:
            raise FormatError(f"values must be ({n}, C), got {vals.shape}")
        sig = None
        if sigma is not None:
            sig = _f64(sigma, "sigma")
            if sig.ndim == 1:
                sig = sig[:, None]
            if sig.shape != vals.shape:
                raise FormatError(f"sigma has shape {sig.shape}, expected {vals.shape}")
        w = None
        if weights is not None:
            w = _f64(weights, "weights")
            if w.shape != (n,):
                raise FormatError(f"weights must be ({n},), got {w.shape}")
        keep = np.ones(n, dtype=bool)
        if mask is not None:
            keep = np.asarray(mask)
            if keep.shape != (n,) or keep.dtype != np.bool_:
                raise FormatError(f"mask must be a boolean ({n},) array")
        wi, wo, vals = wi[keep], wo[keep], vals[keep]
        sig = None if sig is None else sig[keep]
        w = None if w is None else w[keep]
        for arr, what in ((wi, "wi"), (wo, "wo"), (vals, "values")):
            if not np.all(np.isfinite(arr)):
                raise FormatError(f"{what} contains NaN or Inf (mask those rows out)")
        for d, what in ((wi, "wi"), (wo, "wo")):
            norm = np.linalg.norm(d, axis=1)
            if np.any(np.abs(norm - 1) > 1e-3):
                raise FormatError(f"{what} must be unit vectors (a norm is {norm.max():.4g})")
        wi = wi / np.linalg.norm(wi, axis=1, keepdims=True)
        wo = wo / np.linalg.norm(wo, axis=1, keepdims=True)
        if sig is not None and (not np.all(np.isfinite(sig)) or np.any(sig < 0)):
            raise FormatError("sigma must be finite and >= 0")
        if w is not None and (not np.all(np.isfinite(w)) or np.any(w < 0)):
            raise FormatError("weights must be finite and >= 0")
        C = vals.shape[1]
        if channels is None:
            try:
                channels = Channels.for_count(C)
            except ParameterError as e:
                raise ParameterError(f"values have {C} channels: {e}") from None
        if not isinstance(channels, Channels):
            raise ParameterError("channels must be a Channels object")
        if len(channels) != C:
            raise FormatError(f"values have {C} channels but channels describes {len(channels)}")
        for arr in (wi, wo, vals, sig, w):
            if arr is not None:
                arr.setflags(write=False)
        self.wi, self.wo, self.values, self.sigma, self.weights = wi, wo, vals, sig, w
        self.channels = channels
        self.meta: dict[str, Any] = dict(meta or {})

    def __len__(self) -> int:
        return self.wi.shape[0]

    @property
    def n_channels(self) -> int:
        return len(self.channels)

    def __repr__(self) -> str:
        return f"MeasuredSamples(N={len(self)}, {self.channels!r})"


def _f64(x: Any, what: str) -> np.ndarray:
    try:
        arr = np.asarray(x)
    except (TypeError, ValueError):
        raise FormatError(f"{what} is not an array") from None
    if arr.dtype.kind not in "fiu":
        raise FormatError(f"{what} must be numeric, got dtype {arr.dtype}")
    return np.array(arr, dtype=np.float64)


__all__ = [
    "Axis",
    "Channels",
    "MeasuredSamples",
    "TabulatedBRDF",
    "default_axes",
    "merl_axes",
]
