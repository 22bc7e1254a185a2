"""Light sources, in the world frame of the scene (x right, y up, z toward the camera).

Every light answers three questions for shading points ``p`` (..., 3) on the sphere, inside the
jitted render kernel (float32):

``sample(p, u) -> LightSample(wi, value, pdf)``
    a direction toward the light from ``u`` (..., 2). For an area or environment light ``value``
    is the radiance arriving along ``wi`` and ``pdf`` its density per unit solid angle; for a delta
    light (directional, point) ``value`` is the irradiance on a surface facing the light and
    ``pdf`` is 1, so the estimator ``f cos(theta_i) value / pdf`` has one form for both.
``radiance(p, wi)``
    radiance arriving at ``p`` from direction ``wi`` (0 for delta lights: a BRDF-sampled direction
    never hits them).
``pdf(p, wi)``
    the density of ``sample`` at ``wi`` per unit solid angle (0 for delta lights).

Light values are a scalar or one value per channel. The sphere is convex, so a direction above
a point's tangent plane is never blocked by the sphere itself: no shadow rays are needed.

Lights are JAX pytrees (their arrays are leaves), so new values do not recompile the kernel.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any, ClassVar, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf._trig import cos_sin_turns
from gonio.brdf.lookup import atan2
from gonio.brdf.sampling.quadtree import HierarchicalWarp2D
from gonio.errors import ParameterError

Array = jnp.ndarray


class LightSample(NamedTuple):
    """A sampled direction toward a light: ``wi`` (..., 3), ``value`` (..., C), ``pdf`` (...)."""

    wi: Array
    value: Array
    pdf: Array


def _spectrum(value: Any, name: str) -> np.ndarray:
    arr = np.atleast_1d(np.asarray(value, dtype=np.float64))
    if arr.ndim != 1 or arr.size == 0:
        raise ParameterError(f"{name} must be a scalar or one value per channel, got {arr.shape}")
    if not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ParameterError(f"{name} must be finite and non-negative, got {arr.tolist()}")
    return arr.astype(np.float32)


def _vector(value: Any, name: str, unit: bool = False) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(3)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be 3 numbers (x, y, z), got {value!r}") from None
    if not np.all(np.isfinite(arr)):
        raise ParameterError(f"{name} must be finite, got {arr.tolist()}")
    if unit:
        n = np.linalg.norm(arr)
        if n == 0:
            raise ParameterError(f"{name} must not be the zero vector")
        arr = arr / n
    return arr.astype(np.float32)


def _dot(a: Array, b: Array) -> Array:
    return jnp.sum(a * b, axis=-1)


def _normalize(v: Array) -> Array:
    return v / jnp.sqrt(jnp.maximum(_dot(v, v), 1e-30))[..., None]


class Light:
    """Base class; see the module docstring for the interface."""

    is_delta: ClassVar[bool] = False
    _LEAVES: ClassVar[tuple[str, ...]] = ()
    _STATIC: ClassVar[tuple[str, ...]] = ()
    #: the leaf holding the light's value per channel ("" for lights without one)
    _SPECTRUM: ClassVar[str] = ""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        jax.tree_util.register_pytree_node(cls, cls._flatten, cls._unflatten)

    def _flatten(self):
        return tuple(getattr(self, k) for k in self._LEAVES), tuple(
            getattr(self, k) for k in self._STATIC
        )

    @classmethod
    def _unflatten(cls, aux, leaves):
        obj = object.__new__(cls)
        for k, v in zip(cls._LEAVES, leaves, strict=True):
            object.__setattr__(obj, k, v)
        for k, v in zip(cls._STATIC, aux, strict=True):
            object.__setattr__(obj, k, v)
        return obj

    @property
    def channels(self) -> int:
        """Number of channels of the light's value (1 means grey, broadcast to any material)."""
        raise NotImplementedError

    def with_channels(self, idx: np.ndarray) -> Light:
        """This light restricted to the channels ``idx`` (a grey light stays as it is)."""
        raise NotImplementedError

    def broadcast_channels(self, c: int) -> Light:
        """This light with a grey value repeated over ``c`` channels (the same light): grey and
        coloured lights of one kind then share a kernel shape and a stacked group."""
        if not self._SPECTRUM or c <= 1 or self.channels != 1:
            return self
        out = copy.copy(self)
        value = np.repeat(np.asarray(getattr(self, self._SPECTRUM), np.float32), c, axis=-1)
        object.__setattr__(out, self._SPECTRUM, value)
        return out

    def sample(self, p: Array, u: Array) -> LightSample:
        raise NotImplementedError

    def radiance(self, p: Array, wi: Array) -> Array:
        return jnp.zeros((*wi.shape[:-1], self.channels), dtype=jnp.float32)

    def pdf(self, p: Array, wi: Array) -> Array:
        return jnp.zeros(wi.shape[:-1], dtype=jnp.float32)

    def radiance_pdf(self, p: Array, wi: Array) -> tuple[Array, Array]:
        """``(radiance(p, wi), pdf(p, wi))`` sharing the work both need."""
        return self.radiance(p, wi), self.pdf(p, wi)


def _take(arr: Any, idx: np.ndarray) -> Any:
    a = np.asarray(arr)
    return a if a.shape[-1] == 1 else a[..., idx]


class Directional(Light):
    """A distant light along unit vector ``direction`` (toward the light), irradiance ``E``.

    Parameters
    ----------
    direction : (3,) world vector pointing toward the light (normalized here).
    irradiance : W m^-2 (or any consistent unit) on a surface facing the light; scalar or (C,).
    """

    is_delta = True
    _LEAVES = ("direction", "irradiance")
    _SPECTRUM = "irradiance"

    def __init__(self, direction: Any = (0.0, 0.0, 1.0), irradiance: Any = 1.0) -> None:
        self.direction = _vector(direction, "direction", unit=True)
        self.irradiance = _spectrum(irradiance, "irradiance")

    @classmethod
    def from_angles(cls, theta: float, phi: float, irradiance: Any = 1.0) -> Directional:
        """From polar angle ``theta`` off the camera axis (+z) and azimuth ``phi`` from +x
        counter-clockwise in the image plane (radians)."""
        st = math.sin(theta)
        return cls((st * math.cos(phi), st * math.sin(phi), math.cos(theta)), irradiance)

    @property
    def channels(self) -> int:
        return int(np.shape(self.irradiance)[-1])

    def with_channels(self, idx: np.ndarray) -> Directional:
        return Directional(self.direction, _take(self.irradiance, idx))

    def sample(self, p: Array, u: Array) -> LightSample:
        shape = p.shape[:-1]
        wi = jnp.broadcast_to(jnp.asarray(self.direction, jnp.float32), (*shape, 3))
        e = jnp.broadcast_to(jnp.asarray(self.irradiance, jnp.float32), (*shape, self.channels))
        return LightSample(wi, e, jnp.ones(shape, jnp.float32))


class PointLight(Light):
    """An isotropic point light at ``position`` with radiant ``intensity`` (W sr^-1).

    The irradiance at distance r on a surface facing it is ``intensity / r^2``. The position must
    lie outside the unit sphere.
    """

    is_delta = True
    _LEAVES = ("position", "intensity")
    _SPECTRUM = "intensity"

    def __init__(self, position: Any, intensity: Any = 1.0) -> None:
        self.position = _vector(position, "position")
        if np.linalg.norm(self.position) <= 1.0:
            raise ParameterError(
                f"point light position {self.position.tolist()} is inside the unit sphere"
            )
        self.intensity = _spectrum(intensity, "intensity")

    @property
    def channels(self) -> int:
        return int(np.shape(self.intensity)[-1])

    def with_channels(self, idx: np.ndarray) -> PointLight:
        return PointLight(self.position, _take(self.intensity, idx))

    def sample(self, p: Array, u: Array) -> LightSample:
        d = jnp.asarray(self.position, jnp.float32) - p
        r2 = jnp.maximum(_dot(d, d), 1e-12)
        wi = d / jnp.sqrt(r2)[..., None]
        e = jnp.asarray(self.intensity, jnp.float32) / r2[..., None]
        return LightSample(wi, e, jnp.ones(p.shape[:-1], jnp.float32))


class SphereLight(Light):
    """A spherical area light of uniform ``radiance`` (W m^-2 sr^-1), sampled by solid angle.

    Directions are drawn uniformly inside the cone the light subtends from the shading point,
    which is exactly the set of directions that hit it (density ``1 / (2 pi (1 - cos theta_max))``).
    The light must not intersect the unit sphere.
    """

    _LEAVES = ("center", "radius", "radiance_value")
    _SPECTRUM = "radiance_value"

    def __init__(self, center: Any, radius: float, radiance: Any = 1.0) -> None:
        self.center = _vector(center, "center")
        r = float(radius)
        if not (math.isfinite(r) and r > 0):
            raise ParameterError(f"sphere light radius must be positive, got {radius!r}")
        if np.linalg.norm(self.center) <= 1.0 + r:
            raise ParameterError("sphere light overlaps the unit sphere; move it further out")
        self.radius = np.float32(r)
        self.radiance_value = _spectrum(radiance, "radiance")

    @property
    def channels(self) -> int:
        return int(np.shape(self.radiance_value)[-1])

    def with_channels(self, idx: np.ndarray) -> SphereLight:
        return SphereLight(self.center, float(self.radius), _take(self.radiance_value, idx))

    def _cone(self, p: Array) -> tuple[Array, Array, Array]:
        d = jnp.asarray(self.center, jnp.float32) - p
        dist2 = _dot(d, d)
        sin2 = jnp.clip(self.radius**2 / dist2, 0.0, 1.0)
        cos_max = jnp.sqrt(1.0 - sin2)
        # 1 - cos_max without cancellation for small, distant lights.
        one_minus = sin2 / (1.0 + cos_max)
        return _normalize(d), cos_max, one_minus

    def sample(self, p: Array, u: Array) -> LightSample:
        axis, _, one_minus = self._cone(p)
        cos_t = 1.0 - u[..., 0] * one_minus
        sin_t = jnp.sqrt(jnp.maximum(0.0, (1.0 - cos_t) * (1.0 + cos_t)))
        phi = 2.0 * jnp.pi * u[..., 1]
        t, b = _basis(axis)
        wi = (
            (sin_t * jnp.cos(phi))[..., None] * t
            + (sin_t * jnp.sin(phi))[..., None] * b
            + cos_t[..., None] * axis
        )
        pdf = 1.0 / (2.0 * jnp.pi * one_minus)
        le = jnp.broadcast_to(
            jnp.asarray(self.radiance_value, jnp.float32), (*p.shape[:-1], self.channels)
        )
        return LightSample(wi, le, pdf)

    def _inside(self, p: Array, wi: Array) -> tuple[Array, Array]:
        axis, _, one_minus = self._cone(p)
        # A sample drawn at the rim must test as inside despite float32 rounding of its
        # cosine (about 1e-7 absolute); widening the cone by that much is a negligible bias.
        return 1.0 - _dot(wi, axis) <= one_minus * (1.0 + 1e-4) + 2e-7, one_minus

    def radiance(self, p: Array, wi: Array) -> Array:
        return self.radiance_pdf(p, wi)[0]

    def radiance_pdf(self, p: Array, wi: Array) -> tuple[Array, Array]:
        inside, one_minus = self._inside(p, wi)
        le = jnp.asarray(self.radiance_value, jnp.float32)
        pdf = jnp.where(inside, 1.0 / (2.0 * jnp.pi * one_minus), 0.0)
        return jnp.where(inside[..., None], le, 0.0), pdf

    def pdf(self, p: Array, wi: Array) -> Array:
        inside, one_minus = self._inside(p, wi)
        return jnp.where(inside, 1.0 / (2.0 * jnp.pi * one_minus), 0.0)


def _basis(n: Array) -> tuple[Array, Array]:
    """Two unit vectors completing ``n`` (..., 3) to an orthonormal frame (Duff et al. 2017)."""
    s = jnp.where(n[..., 2] >= 0, 1.0, -1.0)
    a = -1.0 / (s + n[..., 2])
    b = n[..., 0] * n[..., 1] * a
    t = jnp.stack([1.0 + s * n[..., 0] ** 2 * a, s * b, -s * n[..., 0]], -1)
    bt = jnp.stack([b, s + n[..., 1] ** 2 * a, -n[..., 1]], -1)
    return t, bt


# -- environment -----------------------------------------------------------------------------


def latlong_to_direction(xy: Array) -> Array:
    """Lat-long image coordinates ``(x, y)`` in ``[0, 1)^2`` -> world directions (..., 3).

    ``y = 0`` is the top row (straight up, +y) and ``y = 1`` the bottom (-y). The centre column
    ``x = 0.5`` faces the way the camera looks (-z, the backdrop behind the sphere); ``x = 0.75``
    is +x (image right) and ``x = 0`` / ``1`` is +z (behind the camera).
    """
    return _latlong_direction_sin(xy)[0]


def _latlong_direction_sin(xy: Array) -> tuple[Array, Array]:
    """:func:`latlong_to_direction` and sin(theta) (..., the solid angle's Jacobian)."""
    xy = jnp.asarray(xy)
    # theta = pi y and phi = 2 pi (x - 1/2) in turns, through the exact-reduction polynomial
    # (XLA's float32 sin/cos are far slower than an exp; gonio.brdf._trig)
    ct, st = cos_sin_turns(0.5 * xy[..., 1])
    cp, sp = cos_sin_turns(xy[..., 0] - 0.5)
    return jnp.stack([st * sp, ct, -st * cp], -1), st


def direction_to_latlong(w: Array) -> Array:
    """Inverse of :func:`latlong_to_direction` -> ``(x, y)`` in ``[0, 1]^2``.

    Both angles go through :func:`gonio.brdf.lookup.atan2` (a float32 polynomial within
    2.2e-7 relative, exact ``arctan2`` in float64): XLA's float32 ``arccos`` and ``arctan2``
    are not vectorized on CPU and would be most of the cost of evaluating the environment at
    BRDF-sampled directions.
    """
    cy = jnp.clip(w[..., 1], -1.0, 1.0)
    y = atan2(jnp.sqrt(jnp.maximum(0.0, (1.0 - cy) * (1.0 + cy))), cy) / jnp.pi
    x = atan2(w[..., 0], -w[..., 2]) / (2.0 * jnp.pi) + 0.5
    return jnp.stack([x, y], -1)


class Environment(Light):
    """Distant illumination from every direction, given as a lat-long radiance image.

    Parameters
    ----------
    image : ``"studio"`` (the built-in procedural studio, :func:`studio_environment`), a number
        or per-channel values (a uniform environment of that radiance), an array ``(H, W)`` or
        ``(H, W, C)`` of linear radiance, or the path of a lat-long EXR file.
    scale : multiplies the radiance.

    The importance map (a 2-D piecewise-constant distribution proportional to the channel mean
    times sin(theta), sampled down a quadtree:
    :class:`gonio.brdf.sampling.quadtree.HierarchicalWarp2D`)
    is built the first time the light is sampled, so a render that never samples the
    environment (BRDF sampling only) never builds it.
    """

    _LEAVES = ("image", "_dist")
    #: Where the image came from ("studio", "uniform", "array" or the file name), for display.
    #: Not part of the pytree: a kernel must not recompile because a file has another name
    #: (a light rebuilt inside a trace shows this default).
    name: str = "environment"

    def __init__(self, image: Any = "studio", scale: float = 1.0) -> None:
        name = "array"
        if isinstance(image, str | Path):
            if str(image) == "studio":
                arr = studio_environment()
                name = "studio"
            else:
                arr = _read_env_file(Path(image))
                name = Path(image).name
        else:
            arr = np.asarray(image, dtype=np.float64)
            if arr.ndim <= 1:
                # Uniform: a small grid so the sin(theta) weighting still applies per row.
                arr = np.broadcast_to(_spectrum(arr, "environment radiance"), (16, 32, arr.size))
                name = "uniform"
        if arr.ndim == 2:
            arr = arr[..., None]
        if arr.ndim != 3 or arr.shape[0] < 1 or arr.shape[1] < 1:
            raise ParameterError(f"environment image must be (H, W) or (H, W, C), got {arr.shape}")
        if not np.all(np.isfinite(arr)) or np.any(arr < 0):
            raise ParameterError("environment image must be finite and non-negative")
        scale = float(scale)
        if not (math.isfinite(scale) and scale >= 0):
            raise ParameterError(f"environment scale must be finite and >= 0, got {scale}")
        # cast on the host: device_put compiles nothing (jnp.asarray would convert on the device)
        self.image = jax.device_put((arr * scale).astype(np.float32))
        self.name = name
        self._dist = None

    @property
    def channels(self) -> int:
        return int(self.image.shape[-1])

    def with_channels(self, idx: np.ndarray) -> Environment:
        out = object.__new__(Environment)
        out.image = self.image if self.channels == 1 else self.image[..., np.asarray(idx)]
        out.name = self.name
        out._dist = None
        return out

    def importance(self) -> Environment:
        """This light with its importance map built (idempotent; called before sampling)."""
        if self._dist is None:
            img = np.asarray(jax.device_get(self.image), dtype=np.float64)  # once per light
            h = img.shape[0]
            sin_t = np.sin(np.pi * (np.arange(h) + 0.5) / h)
            lum = img.mean(axis=-1) * sin_t[:, None]
            if not np.any(lum > 0):
                raise ParameterError("environment is black everywhere; nothing to sample")
            self._dist = HierarchicalWarp2D(lum)  # rows: latitude (y), columns: longitude (x)
        return self

    def sample(self, p: Array, u: Array) -> LightSample:
        if self._dist is None:
            raise ParameterError("Environment.importance() must be called before sampling")
        # u[..., 1] picks the row (y), u[..., 0] the column (x)
        xy, pdf_uv, cell = self._dist.sample(jnp.asarray(u)[..., ::-1])
        wi, sin_t = _latlong_direction_sin(xy)
        pdf = jnp.where(sin_t > 0, pdf_uv / (2.0 * jnp.pi**2 * jnp.maximum(sin_t, 1e-30)), 0.0)
        texel = jnp.take(self.image.reshape(-1, self.image.shape[-1]), cell, axis=0, mode="clip")
        value = jnp.where((pdf > 0)[..., None], texel, 0.0)
        return LightSample(wi, value, pdf)

    def _texel(self, xy: Array) -> Array:
        h, w = self.image.shape[0], self.image.shape[1]
        col = jnp.clip(jnp.floor(xy[..., 0] * w).astype(jnp.int32), 0, w - 1)
        row = jnp.clip(jnp.floor(xy[..., 1] * h).astype(jnp.int32), 0, h - 1)
        return self.image[row, col]

    def radiance(self, p: Array, wi: Array) -> Array:
        return self._texel(direction_to_latlong(wi))

    def pdf(self, p: Array, wi: Array) -> Array:
        return self.radiance_pdf(p, wi)[1]

    def radiance_pdf(self, p: Array, wi: Array) -> tuple[Array, Array]:
        xy = direction_to_latlong(wi)
        # sin(theta) from the direction itself: no trigonometry needed.
        sin_t = jnp.sqrt(jnp.maximum(0.0, 1.0 - wi[..., 1] ** 2))
        # one cell index for the density and the texel (xy is inside [0, 1]^2, clamped)
        cell = self._dist.cell_of(xy)
        pdf_uv = self._dist.cell_density(cell, xy.dtype)
        pdf = jnp.where(sin_t > 0, pdf_uv / (2.0 * jnp.pi**2 * jnp.maximum(sin_t, 1e-30)), 0.0)
        texel = jnp.take(self.image.reshape(-1, self.image.shape[-1]), cell, axis=0, mode="clip")
        return texel, pdf


def _read_env_file(path: Path) -> np.ndarray:
    """Read a lat-long EXR as float (H, W, C); FormatError when unreadable."""
    if not path.exists():
        raise ParameterError(f"environment file not found: {path}")
    from gonio.render.output import read_exr

    return read_exr(path)


def _smoothstep(e0: float, e1: float, x: np.ndarray) -> np.ndarray:
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


#: Soft boxes of the studio: (direction toward the box, half-width deg, half-height deg,
#: RGB radiance). Key light upper left in front, a large dim fill on the right, a strip overhead
#: behind the sphere for a rim highlight.
STUDIO_BOXES: tuple[tuple[tuple[float, float, float], float, float, tuple[float, ...]], ...] = (
    ((-0.55, 0.55, 0.63), 14.0, 18.0, (16.0, 15.5, 14.5)),
    ((0.85, 0.05, 0.52), 18.0, 28.0, (1.1, 1.2, 1.35)),
    ((0.05, 0.75, -0.66), 30.0, 5.0, (6.0, 6.0, 6.0)),
)


def latlong_pixel_directions(height: int, width: int) -> np.ndarray:
    """:func:`latlong_to_direction` at the pixel centres of an ``(height, width)`` lat-long
    image, computed on the host in NumPy float64 -> ``(height, width, 3)`` unit vectors.

    For images built on the host (:func:`studio_environment`): the JAX function, called
    outside a trace, compiles and runs its ops one by one, a cost paid by every process
    (more with a cold compilation cache) for an image that NumPy builds almost at once.
    """
    theta = np.pi * (np.arange(height) + 0.5) / height
    phi = 2.0 * np.pi * ((np.arange(width) + 0.5) / width - 0.5)
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    sp, cp = np.sin(phi)[None, :], np.cos(phi)[None, :]
    return np.stack(np.broadcast_arrays(st * sp, ct, -st * cp), -1)


def studio_environment(height: int = 128, width: int = 256) -> np.ndarray:
    """The built-in procedural studio: soft boxes on a dim gradient, lat-long ``(H, W, 3)``.

    Linear RGB radiance. The gradient runs from a dark floor (0.01) to a slightly cool ceiling
    (about 0.06); each soft box is a rectangle in angle with smooth 2-degree edges. Computed at
    pixel centres, so the image is exactly what the renderer samples.
    """
    d = latlong_pixel_directions(height, width)
    up = d[..., 1]
    t = _smoothstep(-0.3, 1.0, up)[..., None]
    floor = np.array([0.01, 0.01, 0.01])
    ceiling = np.array([0.05, 0.055, 0.065])
    img = floor + (ceiling - floor) * t
    for center, hw, hh, rgb in STUDIO_BOXES:
        c = np.asarray(center, dtype=np.float64)
        c /= np.linalg.norm(c)
        hint = np.array([0.0, 1.0, 0.0]) if abs(c[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
        r = np.cross(hint, c)
        r /= np.linalg.norm(r)
        s = np.cross(c, r)
        dc = d @ c
        ax = np.degrees(np.arctan2(d @ r, dc))
        ay = np.degrees(np.arctan2(d @ s, dc))
        soft = 2.0
        mask = _smoothstep(hw + soft, hw - soft, np.abs(ax)) * _smoothstep(
            hh + soft, hh - soft, np.abs(ay)
        )
        mask = np.where(dc > 0, mask, 0.0)
        img = img + mask[..., None] * np.asarray(rgb)
    return img.astype(np.float32)


def merge_environments(lights: Sequence[Light]) -> list[Light]:
    """The same lights with every set of environments of one image size replaced by one
    environment whose image is their sum (grey images broadcast to the others' channels).

    Lights add up and a distant light does not depend on the shading point, so the sum is the
    same illumination; one importance map for the sum samples it at least as well as one map
    per image, and the render kernel's shape does not depend on how many images there were.
    The merged light takes the place of the first of its members.
    """
    by_size: dict[tuple[int, int], list[Environment]] = {}
    for lt in lights:
        if isinstance(lt, Environment):
            by_size.setdefault(tuple(lt.image.shape[:2]), []).append(lt)
    out: list[Light] = []
    for lt in lights:
        if not isinstance(lt, Environment):
            out.append(lt)
            continue
        members = by_size[tuple(lt.image.shape[:2])]
        if len(members) == 1:
            out.append(lt)
        elif lt is members[0]:
            merged = object.__new__(Environment)
            total = members[0].image
            for m in members[1:]:
                total = total + m.image
            merged.image = total
            merged.name = "+".join(m.name for m in members)
            merged._dist = None
            out.append(merged)
    return out


def light_list(lights: Any) -> list[Light]:
    """Validate the ``lights`` argument of the renderer: a Light or a sequence of them."""
    if isinstance(lights, Light):
        lights = [lights]
    try:
        out = list(lights)
    except TypeError:
        raise ParameterError(
            f"lights must be a light or a list of lights, got {lights!r}"
        ) from None
    for light in out:
        if not isinstance(light, Light):
            raise ParameterError(f"not a light: {light!r}")
    if not out:
        raise ParameterError("the scene needs at least one light")
    return out


__all__ = [
    "Directional",
    "Environment",
    "Light",
    "LightSample",
    "PointLight",
    "SphereLight",
    "direction_to_latlong",
    "latlong_pixel_directions",
    "latlong_to_direction",
    "merge_environments",
    "studio_environment",
]
