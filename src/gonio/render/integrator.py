"""Direct-lighting Monte Carlo integrator for spheres, with multiple importance sampling.

The scene is one convex sphere, so light reaches a point only directly: a direction above the
tangent plane never meets the sphere again (no interreflection, no self-shadowing). Direct
lighting is therefore the *complete* solution, not an approximation. Per pixel it estimates

    L_o(wo) = sum over lights of  int f(wi, wo) L_i(wi) cos(theta_i) dwi

with, per sample, one light sample per group of (non-delta) lights and one BRDF sample shared
by all lights, combined by the power heuristic (beta = 2). A group is one environment
(environments of one image size are first merged into one, their images summed) or all lights
of one other kind (sphere lights), of which each sample picks one uniformly (its density
divided by the group's count, in the MIS weights too). Delta lights (directional, point) are
evaluated exactly, once per pixel: no samples, no BRDF sampling.

Sampling strategies (``sampler``):

``"auto"`` / ``"mis"``
    MIS of light sampling and the material's best BRDF sampler (an analytic model's own
    ``sample``; tabulated inversion for tables).
``"brdf"``
    the material's own sampler (tables: ``"inversion"``; with ``proposal=model``, a table is
    sampled by that analytic model's sampler, "analytic lobe" sampling of a table by its fit).
``"cosine"``
    cosine-weighted hemisphere sampling, ignoring the BRDF's shape (the baseline).
``"inversion"`` / ``"alias"`` / ``"rejection"``
    a table's sampler by that method (tables only).
``"light"``
    light sampling alone (no BRDF sampling; refused for materials with delta lobes, which light
    sampling can never find).

``mis`` (default: on) combines the chosen BRDF sampler with light sampling; ``mis=False`` uses the
BRDF sampler alone (then area and environment lights are found only by BRDF samples).

Random numbers: ``2 + 2 K`` per sample (BRDF sample, then one pair per sampled light group), from
a rank-1 lattice sequence (:mod:`gonio.brdf.sampling.points`): every pair is that 2-D lattice, the
light pairs in an order permuted per pixel ("padding"), each rotated per pixel by an independent
uniform shift modulo 1 (random 32-bit words, seeded), so pixels are independent unbiased
estimates while every pair keeps the lattice. Of the point sets tried for this (scrambled
Sobol' points rotated per pixel; further Sobol' dimensions for the light pairs, digitally
shifted; padded Sobol' pairs), the padded lattice gives the lowest error, for diffuse and
glossy materials alike (``benchmarks/bench_equal_time.py`` measures the renderer's error).

Work is split into tiles of pixels x samples of bounded size (``tile_samples``), laid out
samples-major (S, P, ...): XLA:CPU vectorizes elementwise code along the innermost axis, so
a (P, S) batch with its short samples axis innermost runs much slower than the same number of
lanes flat, and (S, P) keeps the long pixel axis innermost (the light and material stages
gain; the shading stage is about even). Each tile runs as three jitted float32 stages:
light sampling, the material (``f`` and ``pdf`` at the light samples, BRDF samples), shading.
Tile shapes do not follow the request:
``spp`` is padded to a multiple of :data:`SAMPLE_BATCH` (padding has zero weight) and pixels
to equal tiles of one of at most 17 sizes (:func:`gonio.render.tiling.sample_tile`), and delta
and area lights of one kind are stacked and looped over (or picked from) with a traced count,
so that a new ``spp`` or number of delta, area or environment lights reuses the compiled
kernels, and so does a new image size unless it needs a tile size not compiled yet (with the
persistent cache of :mod:`gonio.compile_cache`, across processes too). Each tile's sums stay on
the device until the end of the render (one transfer back). Every material is traced into the
middle stage: a table sampled by one of its own methods gets, as kernel arguments, its sampling
structures for the outgoing directions of the image (built once per render, before the first
tile, for the buckets those directions fall in), and rejection draws its extra random numbers
from a hash of each sample's uniforms, so no kernel call waits on the host.
"""

from __future__ import annotations

import collections
import functools
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf._xla import materialize
from gonio.brdf.frames import dot
from gonio.brdf.material import Material
from gonio.brdf.sampling import points as _sobol_mod
from gonio.errors import ParameterError
from gonio.render.delta import render_delta
from gonio.render.lights import Environment, Light, LightSample, light_list, merge_environments
from gonio.render.materials import channel_index, restrict_channels
from gonio.render.scene import Camera, SphereHits, intersect_sphere
from gonio.render.tiling import device_array, pad_rows, sample_tile, sampled_groups, tile_spans

Array = jnp.ndarray

SAMPLERS = ("auto", "mis", "brdf", "cosine", "inversion", "alias", "rejection", "light")

#: Samples (pixels x spp) processed per kernel call: bounds memory to a few tens of MB.
DEFAULT_TILE_SAMPLES = 1 << 17

#: Samples per pixel in one kernel call: ``spp`` is padded up to a multiple of it (masked by zero
#: weights), so that every ``spp`` runs the same compiled kernel; an ``spp`` that is a multiple
#: of ``4 * SAMPLE_BATCH`` uses that larger batch (a second kernel shape): fewer, larger kernel
#: calls per tile (``benchmarks/bench_render.py`` times renders by spp).
SAMPLE_BATCH = 16

#: Tiles dispatched ahead of the one being collected (one per core keeps every core busy).
IN_FLIGHT = max(1, min(4, os.cpu_count() or 1))


@dataclass(frozen=True)
class _Technique:
    """How BRDF samples are drawn: ``kind`` is "none" (light sampling only) or the method the
    material is bound to (:meth:`gonio.brdf.material.Material.with_sampling`): one of its own
    ``sampling_methods``, "cosine" or "lobe" (an analytic proposal)."""

    kind: str
    mis: bool
    light_sampling: bool

    @property
    def samples_brdf(self) -> bool:
        return self.kind != "none"


#: Samplers that name one of a material's own methods (a table's).
_OWN_METHODS = ("inversion", "alias", "rejection")


def resolve_sampler(
    material: Any, sampler: str, mis: bool | None, proposal: Any = None
) -> _Technique:
    """Check ``sampler`` against the material and return the technique to run."""
    if sampler not in SAMPLERS:
        raise ParameterError(f"sampler must be one of {', '.join(SAMPLERS)}; got {sampler!r}")
    if sampler == "light":
        if mis:
            raise ParameterError("sampler='light' samples lights only; it cannot use MIS")
        if material.has_delta:
            raise ParameterError(
                "sampler='light' cannot render a material with delta lobes (mirror, glass)"
            )
        return _Technique("none", False, True)
    methods = tuple(material.sampling_methods)
    if sampler in _OWN_METHODS and sampler not in methods:
        raise ParameterError(
            f"sampler={sampler!r} is not a sampling method of this material (it offers "
            f"{', '.join(methods)})"
        )
    if sampler == "cosine" and material.has_delta:
        raise ParameterError("sampler='cosine' cannot find the delta lobes of this material")
    if proposal is not None:
        if sampler != "brdf":  # rejection proposes from its own rigorous majorant
            raise ParameterError(
                "proposal= is used by sampler='brdf' only (a material sampled by an analytic lobe)"
            )
        if not isinstance(proposal, Material):
            raise ParameterError("proposal must be a material (an analytic BRDF model)")
        if material.has_delta or proposal.has_delta:
            raise ParameterError("sampler='brdf' with a proposal cannot sample delta lobes")
        kind = "lobe"
    elif sampler in ("auto", "mis", "brdf"):
        kind = methods[0]
    else:
        kind = sampler
    use_mis = True if mis is None else bool(mis)
    if sampler == "mis" and not use_mis:
        raise ParameterError("sampler='mis' with mis=False is contradictory")
    return _Technique(kind, use_mis, use_mis)


def _material_ops(material: Any):
    """Traceable ``f``, ``pdf`` and ``sample`` of a material bound to its sampling method
    (:meth:`gonio.brdf.material.Material.with_sampling`); ``f`` in the directions' dtype."""

    def f(wi, wo):
        return jnp.asarray(material.f(wi, wo), wi.dtype)

    def sample(wo, u):
        s = material.sample(wo, u)
        return s.wi, s.pdf, s.weight, s.delta

    return f, material.pdf, sample


# -- kernels -----------------------------------------------------------------------------------


# Per component through frames.dot: XLA on CPU turns a batched 3x3 einsum into a slow
# dot_general, and a sum over the size-3 axis into a reduction loop of its own; written out,
# the products fuse into their consumers.
def _local(frame: Array, w: Array) -> Array:
    f = frame[None]
    return jnp.stack([dot(f[..., i, :], w) for i in range(3)], -1)


def _world(frame: Array, w: Array) -> Array:
    f = frame[None]
    return jnp.stack([dot(w, f[..., :, j]) for j in range(3)], -1)


def _power(a: Array, b: Array) -> Array:
    """Power heuristic weight a^2 / (a^2 + b^2), written to avoid overflow; 0 where a = 0."""
    r = jnp.where(a > 0, b / jnp.where(a > 0, a, 1.0), 0.0)
    return jnp.where(a > 0, 1.0 / (1.0 + r * r), 0.0)


def _pick(stacked: Any, i: Array) -> Any:
    """Light ``i`` of a stacked group (``i`` a traced scalar, or an index array: then every
    leaf gains its shape in front)."""
    return jax.tree_util.tree_map(lambda leaf: jnp.take(leaf, i, axis=0), stacked)


def _light_stage(groups: tuple, position: Array, frame: Array, u: Array):
    """One light sample per group and sample: list of (wi local (S,P,3), value (S,P,C), pdf
    (S,P)). In a stacked group the light is chosen uniformly among its ``count`` members by
    the first of the pair's numbers (rescaled to [0, 1) for the light's own sampling), and
    ``pdf`` includes the choice (divided by ``count``)."""
    out = []
    p = jnp.broadcast_to(position[None], (*u.shape[:-1], 3))
    for k, (light, count) in enumerate(groups):
        uk = u[..., 2 + 2 * k : 4 + 2 * k]
        if count is None:
            ls = light.sample(p, uk)
        else:
            n = count.astype(jnp.float32)
            x = uk[..., 0] * n
            j = jnp.clip(jnp.floor(x).astype(jnp.int32), 0, count - 1)
            u0 = jnp.clip(x - j.astype(jnp.float32), 0.0, 1.0 - 2.0**-24)
            ls = _pick(light, j).sample(p, jnp.stack([u0, uk[..., 1]], -1))
            ls = LightSample(ls.wi, ls.value, ls.pdf / n)
        # stored before the rotation: fused into it, the light's sampler (the environment's
        # quadtree descent) would run once per component, three times over;
        # the runtime 1.0 comes from the uniform numbers, which are always finite
        wi = materialize([ls.wi], uk[..., 0])[0]
        out.append((_local(frame, wi), ls.value, ls.pdf))
    return out


def _shade_light(lights, light_samples, f_vals, brdf_pdfs, weights, mis: bool):
    """Sum over lights of f L cos / pdf (times the MIS weight); (S, P, C)."""
    total = 0.0
    for (light, _), (wi, value, pdf), f, pb in zip(
        lights, light_samples, f_vals, brdf_pdfs, strict=True
    ):
        cos = jnp.maximum(wi[..., 2], 0.0)
        ok = pdf > 0
        c = f * value * jnp.where(ok, cos / jnp.where(ok, pdf, 1.0), 0.0)[..., None]
        if mis and not light.is_delta:
            c = c * _power(pdf, pb)[..., None]
        total = total + c
    return total * weights[:, None, None]


def _shade_brdf(lights, position, frame, brdf, mis: bool, weights):
    """Sum over lights of L(wi_b) f cos / pdf_b (times the MIS weight); (S, P, C). Every
    member of a stacked group is looked at, in a loop with a traced trip count; its light
    sampling density is its own times the chance ``1 / count`` of being chosen."""
    wi, pdf_b, weight, delta = brdf
    wi_w = _world(frame, wi)
    p = jnp.broadcast_to(position[None], wi_w.shape)

    def term(light, n):
        if mis:
            le, pl = light.radiance_pdf(p, wi_w)
            return weight * le * jnp.where(delta, 1.0, _power(pdf_b, pl / n))[..., None]
        return weight * light.radiance(p, wi_w)

    total = 0.0
    for light, count in lights:
        if count is None:
            total = total + term(light, 1.0)
            continue
        n = count.astype(jnp.float32)
        first = term(_pick(light, 0), n)
        total = total + jax.lax.fori_loop(
            1, count, lambda i, acc, light=light, n=n: acc + term(_pick(light, i), n), first
        )
    return total * weights[:, None, None]


def _uniforms(sobol: Array, shift: Array) -> Array:
    return _sobol_mod.padded_unit(sobol, shift, samples_first=True)


# A tile runs as three jitted stages: light sampling; the material (f and pdf at the light
# samples, BRDF samples); shading. On CPU this is cheaper than one fused kernel, where XLA
# recomputes the gather-heavy sampling code inside several consumers. It is also the
# structure tables need, whose samplers keep host-side state between calls.


@jax.jit
def _light_stage_jit(lights, position, frame, sobol, shift):
    return _light_stage(lights, position, frame, _uniforms(sobol, shift))


def _pixel_major(material: Any, kind: str) -> bool:
    """Whether the material stage gets its arrays pixel-major ``(P, S, ...)``: materials
    sampled by their own default method that compute what depends on wo once per pixel
    (``broadcasts_outgoing``: their table slices) and gather every sample of a pixel from
    them, where consecutive lanes then gather from one slice."""
    return kind == material.sampling_methods[0] and material.broadcasts_outgoing


@functools.partial(jax.jit, static_argnames=("samples",))
def _outgoing_per_sample(wo: Array, samples: int) -> Array:
    """``wo`` (P, 3) repeated for each of a batch's samples -> (S, P, 3), as a buffer: the
    models' kernels run faster reading one than with the broadcast fused into them, and the
    buffer costs one cheap pass to make."""
    return jnp.broadcast_to(wo[None], (samples, *wo.shape))


@functools.partial(
    jax.jit, static_argnames=("samples_brdf", "pixel_major", "mis", "light_sampling")
)
def _model_stage(material, light_wi, wo, sobol, shift, *, samples_brdf, pixel_major, mis,
                 light_sampling):  # fmt: skip
    """``material`` bound to its sampling method; ``wo`` is (P, 3) when ``pixel_major``
    (:func:`_pixel_major`), (S, P, 3) otherwise."""
    f, pdf, sample = _material_ops(material)
    u = _uniforms(sobol, shift)[..., :2]

    def swap(x):
        return jnp.swapaxes(x, 0, 1) if pixel_major else x

    if pixel_major:
        wo, light_wi, u = wo[:, None], [swap(wi) for wi in light_wi], swap(u)
    fv = [swap(f(wi, wo)) for wi in light_wi] if light_sampling else None
    pb = [swap(pdf(wi, wo)) for wi in light_wi] if light_sampling and mis else None
    brdf = tuple(swap(x) for x in sample(wo, u)) if samples_brdf else None
    return fv, pb, brdf


@functools.partial(jax.jit, static_argnames=("mis",))
def _shade_stage(lights, ls, fv, pb, position, frame, brdf, weights, acc, *, mis):
    """``acc`` (P, C) plus this batch's radiance sums: a tile's sums stay on the device."""
    total = 0.0
    if ls is not None:
        pbs = pb if pb is not None else [None] * len(ls)
        total = total + _shade_light(lights, ls, fv, pbs, weights, mis)
    if brdf is not None:
        total = total + _shade_brdf(lights, position, frame, brdf, mis, weights)
    return acc + _sum_samples(jnp.broadcast_to(total, (weights.shape[0], *acc.shape)))


def _sum_samples(x: Array) -> Array:
    """``x`` (S, P, C) summed over its samples axis -> (P, C), as S - 1 elementwise adds: XLA:CPU
    runs ``jnp.sum`` over that axis as a slow loop of its own, where the adds fuse with the
    shading that produces ``x``."""
    out = x[0]
    for s in range(1, x.shape[0]):
        out = out + x[s]
    return out


def _tile(material, lights, pos, frame, wo, sob, shift, weights, acc, tech: _Technique,
          pixel_major: bool):  # fmt: skip
    """``acc`` plus the radiance sums (P, C) of one tile: P pixels x S samples (``weights``
    masks padding; ``material`` bound to its sampling method, ``wo`` as :func:`_model_stage`
    takes it); three kernel calls, nothing waits on the host."""
    ls = _light_stage_jit(lights, pos, frame, sob, shift) if tech.light_sampling else None
    light_wi = [wi for wi, _, _ in ls] if ls is not None else []
    fv, pb, brdf = _model_stage(
        material, light_wi, wo, sob, shift, samples_brdf=tech.samples_brdf,
        pixel_major=pixel_major, mis=tech.mis, light_sampling=tech.light_sampling,
    )  # fmt: skip
    return _shade_stage(lights, ls, fv, pb, pos, frame, brdf, weights, acc, mis=tech.mis)


# -- driver ------------------------------------------------------------------------------------


@dataclass
class RenderStats:
    """What a render did (for benchmarks): pixels shaded, samples drawn, kernel calls."""

    pixels: int = 0
    samples: int = 0
    calls: int = 0
    env_maps_built: int = 0


def _output_channels(c_mat: int, lights: Sequence[Light]) -> int:
    sizes = {c_mat} | {light.channels for light in lights}
    sizes.discard(1)
    if len(sizes) > 1:
        raise ParameterError(
            f"material and lights disagree on the channel count ({sorted(sizes)}); "
            "give grey lights or matching per-channel values"
        )
    return sizes.pop() if sizes else 1


def render_sphere(
    material: Any,
    lights: Any = None,
    resolution: int | tuple[int, int] = 256,
    spp: int = 64,
    sampler: str = "auto",
    seed: int = 0,
    channels: Any = None,
    *,
    camera: Camera | None = None,
    mis: bool | None = None,
    tile_samples: int = DEFAULT_TILE_SAMPLES,
    progress: Callable[[int, int], None] | None = None,
    stats: RenderStats | None = None,
    proposal: Any = None,
    optimize: bool = True,
) -> np.ndarray:
    """Render the unit sphere made of ``material``: linear radiance, float32 ``(H, W, C)``.

    Parameters
    ----------
    material : any material (:class:`gonio.brdf.material.Material`): an analytic model, a
        tabulated BRDF, an RGL file.
    lights : a light or a list of lights (:mod:`gonio.render.lights`); default the built-in
        studio environment.
    resolution : image size, ``N`` for N x N or ``(H, W)``.
    spp : samples per pixel for area and environment lights (delta lights are exact and take
        none; a scene of delta lights only is rendered with one evaluation per pixel).
    sampler : BRDF sampling strategy, see the module docstring.
    seed : seeds the per-pixel rotations of the lattice points (and through them a table's
        rejection sampler, whose extra numbers hash each sample's uniforms).
    channels : ``None`` for all channels, or indices / names of the channels to render; only
        those are evaluated.
    camera : :class:`~gonio.render.scene.Camera` (default orthographic).
    mis : combine BRDF and light sampling (default True; ignored for ``sampler="light"``).
    tile_samples : pixels x samples per kernel call (memory bound).
    progress : called as ``progress(done, total)`` after each tile.
    stats : filled with counts of what was done.
    proposal : an analytic model without delta lobes (typically a table's fit). With
        ``sampler="brdf"`` the material is sampled by the model's own sampler ("analytic lobe"
        sampling: directions and pdf from the model, values from the material). Other samplers
        refuse it (``"rejection"`` proposes from the table's own majorant: an exact reference
        needs a rigorous bound that an analytic model's density does not give).
    optimize : for benchmarks only: ``False`` turns off every shortcut that skips work a scene
        does not need (pixels that miss the sphere are shaded and thrown away, delta lights are
        sampled ``spp`` times with BRDF samples wasted on them, the environment importance map
        is built even when unused, all channels are rendered and then cut). The image is the
        same up to noise.

    Returns
    -------
    (H, W, C) float32 linear radiance (same unit as the lights' values times sr^-1 x sr); pixels
    that miss the sphere are 0.
    """
    lights = light_list(lights if lights is not None else [Environment("studio")])
    if isinstance(spp, bool) or not isinstance(spp, int | np.integer) or spp < 1:
        raise ParameterError(f"spp must be a positive integer, got {spp!r}")
    spp = int(spp)
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ParameterError(f"seed must be a non-negative integer, got {seed!r}")
    c_mat = material.n_channels
    idx = channel_index(material, channels, max(c_mat, *(lt.channels for lt in lights)))
    post_idx = idx  # channels still to cut from the result
    if idx is not None and optimize:
        restricted = restrict_channels(material, idx)
        if restricted is not None:
            material = restricted
            lights = [lt.with_channels(idx) for lt in lights]
            c_mat = material.n_channels
            post_idx = None
    tech = resolve_sampler(material, sampler, mis, proposal)
    c_out = _output_channels(c_mat, lights)

    hits = intersect_sphere(resolution, camera)
    stats = stats if stats is not None else RenderStats()
    stats.pixels = hits.count
    h, w = hits.shape
    n_hit = hits.count
    if n_hit == 0:
        return np.zeros((h, w, c_out if idx is None else len(idx)), np.float32)
    if not optimize:
        # No early-out: shade as many pixels as the image has (misses get a copy of a hit's
        # geometry, which costs the same) and keep only the real hits afterwards.
        hits = _padded_hits(hits, h * w)
        stats.pixels = h * w

    out = np.zeros((hits.count, c_out), dtype=np.float64)
    if optimize:
        delta_lights = tuple(lt for lt in lights if lt.is_delta)
        area_lights = tuple(lt for lt in lights if not lt.is_delta)
    else:
        delta_lights, area_lights = (), tuple(lights)

    # Delta lights: exact, one evaluation per pixel.
    if delta_lights:
        out += render_delta(material, delta_lights, hits, tile_samples, stats, c_out)

    if area_lights:
        area_lights = tuple(merge_environments(area_lights))
        if tech.light_sampling or not optimize:
            area_lights = tuple(
                lt.importance() if isinstance(lt, Environment) else lt for lt in area_lights
            )
            stats.env_maps_built = sum(isinstance(lt, Environment) for lt in area_lights)
        out += _render_area(
            material, area_lights, hits, spp, tech, seed, tile_samples, progress, stats, proposal
        )
    elif progress is not None:
        progress(1, 1)
    out = out[:n_hit]
    if post_idx is not None:
        out = out[..., post_idx] if out.shape[-1] > 1 else out
    return SphereHits(
        hits.shape, hits.index[:n_hit], hits.position[:n_hit], hits.frame[:n_hit], hits.wo[:n_hit]
    ).scatter(out.astype(np.float32))


def _padded_hits(hits: SphereHits, n: int) -> SphereHits:
    reps = np.resize(np.arange(hits.count), n)
    return SphereHits(
        hits.shape,
        np.concatenate([hits.index, np.zeros(n - hits.count, hits.index.dtype)]),
        hits.position[reps],
        hits.frame[reps],
        hits.wo[reps],
    )


def _render_area(
    material, lights, hits, spp, tech, seed, tile_samples, progress, stats, proposal=None
):
    n_pix = hits.count
    c_out = max(1, _out_c(material, lights))
    groups = sampled_groups(lights, c_out)
    dims = 2 + 2 * len(groups)
    sobol = _sobol_mod.sobol_ints(spp, 1)  # the radical inverses the lattice is built on
    shift = _sobol_mod.shifts(np.random.default_rng([seed, 1]), n_pix, dims)
    s_batch = 4 * SAMPLE_BATCH if spp % (4 * SAMPLE_BATCH) == 0 else SAMPLE_BATCH
    n_batches = math.ceil(spp / s_batch)
    sob = np.zeros((n_batches * s_batch, 1), np.uint32)
    sob[:spp] = sobol
    wts = np.zeros(n_batches * s_batch, np.float32)
    wts[:spp] = 1.0
    p_tile = sample_tile(n_pix, max(1, tile_samples // s_batch))
    tiles = list(tile_spans(n_pix, p_tile))
    total = len(tiles) * n_batches
    done = 0
    wo_tiles = [device_array(pad_rows(hits.wo[a:b], p_tile)) for a, b in tiles]
    pixel_major = _pixel_major(material, tech.kind)
    if tech.samples_brdf:
        # every outgoing direction of the image is known here: a table's sampling structures
        # for their buckets are built once, and the kernels take them inside the bound material
        material = material.with_sampling(tech.kind, proposal=proposal, wo=wo_tiles)
    # Sample points and weights go to the device once; each tile's sums stay there (the shade
    # stage adds each batch into them) and come back in one transfer at the end, so that no
    # kernel call waits on a copy to the host.
    batches = [
        (
            device_array(sob[k * s_batch : (k + 1) * s_batch]),
            device_array(wts[k * s_batch : (k + 1) * s_batch]),
        )
        for k in range(n_batches)
    ]
    sums = []
    # Kernel calls are dispatched asynchronously; keeping a few in flight lets the XLA CPU
    # runtime execute tiles concurrently on several cores, and waiting (without a copy) for the
    # call dispatched IN_FLIGHT calls earlier bounds the memory held by queued calls.
    pending: collections.deque = collections.deque()

    def drain(limit: int) -> None:
        nonlocal done
        while len(pending) > limit:
            jax.block_until_ready(pending.popleft())
            done += 1
            if progress is not None:
                progress(done, total)

    for (a, b), wo_tile in zip(tiles, wo_tiles, strict=True):
        pos = device_array(pad_rows(hits.position[a:b], p_tile))
        frame = device_array(pad_rows(hits.frame[a:b], p_tile))
        sh = device_array(pad_rows(shift[a:b], p_tile))
        acc = device_array(np.zeros((p_tile, c_out), np.float32))
        wo = wo_tile if pixel_major else _outgoing_per_sample(wo_tile, s_batch)
        for k, (sb, wb) in enumerate(batches):
            acc = _tile(material, groups, pos, frame, wo, sb, sh, wb, acc, tech, pixel_major)
            pending.append(acc)
            drain(IN_FLIGHT)
            stats.calls += 1
            stats.samples += (b - a) * int(np.sum(wts[k * s_batch : (k + 1) * s_batch]))
        sums.append(acc)
    drain(0)
    out = np.zeros((n_pix, c_out), np.float64)
    for (a, b), tile_sum in zip(tiles, jax.device_get(sums), strict=True):
        out[a:b] = tile_sum[: b - a]
    return out / spp


def _out_c(material, lights) -> int:
    return _output_channels(material.n_channels, lights)
