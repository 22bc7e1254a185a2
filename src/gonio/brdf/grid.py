"""Table grids: what a table's channels mean (:class:`Channels`) and its axes (:class:`Axis`).

A table stores ``values`` of shape ``(n_1, ..., n_k, C)`` at the nodes of ``k`` axes in the
Rusinkiewicz (1998) half/difference angles (see :mod:`gonio.brdf.tabulated` for the
parameterizations). Node ``i`` of an axis sits at the warped coordinate ``x_i = (i +
node_offset) / size`` and the angle ``lo + (hi - lo) x`` (``"linear"``) or ``lo + (hi - lo)
x**2`` (``"sqrt"``, MERL's ``theta_h``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import jax.numpy as jnp
import numpy as np

from gonio.errors import FormatError, ParameterError

PARAMETERIZATIONS = {
    "half_diff_iso": ("theta_h", "theta_d", "phi_d"),
    "half_diff_aniso": ("theta_h", "phi_h", "theta_d", "phi_d"),
}
INTERPOLATIONS = ("linear", "nearest")


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

    @classmethod
    def describe(cls, channels: Channels | None, n: int) -> Channels:
        """``channels`` checked against ``n`` value channels, or the default for ``n`` (None)."""
        if channels is None:
            try:
                return cls.for_count(n)
            except ParameterError as e:
                raise ParameterError(f"values have {n} channels: {e}") from None
        if not isinstance(channels, Channels):
            raise ParameterError("channels must be a Channels object")
        if len(channels) != n:
            raise FormatError(f"values have {n} channels but channels describes {len(channels)}")
        return channels

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


def node_directions(axes: Sequence[Axis], parameterization: str) -> tuple[np.ndarray, ...]:
    """``(wi, wo)``, each ``(n_nodes, 3)`` float64, of every node in C order: the inverse of
    :func:`gonio.brdf.frames.half_diff` (``frames.half_diff_to_directions``), evaluated with
    NumPy (no per-operation compilation on a million-node grid)."""
    # each axis's nodes broadcast against the others: the same numbers as on a meshgrid, with
    # the sines and cosines taken per axis instead of per node
    k = len(axes)
    nodes = [np.asarray(a.nodes()).reshape([-1 if j == i else 1 for j in range(k)])
             for i, a in enumerate(axes)]  # fmt: skip
    shape = tuple(a.size for a in axes)
    if parameterization == "half_diff_iso":
        th, td, pd = nodes
        ph = None
    else:
        th, ph, td, pd = nodes
    st = np.sin(td)
    dx, dy, dz = st * np.cos(pd), st * np.sin(pd), np.cos(td)
    sh, ch = np.sin(th), np.cos(th)

    def flat(*parts: np.ndarray) -> np.ndarray:
        out = np.empty((*shape, len(parts)))
        for i, v in enumerate(parts):
            out[..., i] = v
        return out.reshape(-1, len(parts))

    # R_y(theta_h) applied to d = (dx, dy, dz) and to (-dx, -dy, dz)
    wi = flat(ch * dx + sh * dz, dy, -sh * dx + ch * dz)
    wo = flat(-ch * dx + sh * dz, -dy, sh * dx + ch * dz)
    if ph is not None:  # then R_z(phi_h)
        c, s = flat(np.cos(ph)), flat(np.sin(ph))
        for w in (wi, wo):
            x, y = w[:, 0].copy(), w[:, 1].copy()
            w[:, 0], w[:, 1] = c[:, 0] * x - s[:, 0] * y, s[:, 0] * x + c[:, 0] * y
    return wi, wo


def numeric_array(x: Any, what: str, dtype: Any) -> np.ndarray:
    """``x`` as a new array of ``dtype``; FormatError naming ``what`` unless it is numeric."""
    try:
        arr = np.asarray(x)
    except (TypeError, ValueError):
        raise FormatError(f"{what} is not an array") from None
    if arr.dtype.kind not in "fiu":
        raise FormatError(f"{what} must be numeric, got dtype {arr.dtype}")
    return np.array(arr, dtype=dtype)


__all__ = [
    "INTERPOLATIONS",
    "PARAMETERIZATIONS",
    "Axis",
    "Channels",
    "default_axes",
    "merl_axes",
    "node_directions",
    "numeric_array",
]
