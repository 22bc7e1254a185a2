"""A Mitsuba 3 BSDF plugin, ``gonio``, that renders a gonio fit with gonio's own JAX model.

Mitsuba's stock BSDFs hold few of gonio's families (:mod:`gonio.export.mitsuba` refits the
others). This plugin holds all of them: its ``eval``, ``pdf``, ``sample`` and ``eval_pdf`` call
the fitted model's ``f``, ``pdf`` and ``sample`` (the :class:`gonio.brdf.material.Material`
interface), so a render in Mitsuba evaluates exactly the fit gonio reports. It needs gonio
importable in the rendering process; the stock-BSDF export is for users who cannot do that.

Use::

    import mitsuba as mi
    mi.set_variant("scalar_rgb")             # or "llvm_ad_rgb", see below
    import gonio.export.mitsuba_plugin as gp
    gp.register()                            # once per variant; registers BSDF type "gonio"
    bsdf = mi.load_dict({"type": "gonio", "filename": "fits/felt.json"})

Scene parameters (one of the two):

``filename`` (string)
    A fit-result JSON file written by ``gonio fit``, or a bare model description (a model's
    ``to_dict()``), read by :func:`gonio.io.fit_result.load_fit`.
``model`` (string)
    The same JSON given inline: what ``gonio export FIT --to mitsuba --plugin`` writes, so the
    scene needs no second file.

Conventions
-----------
* **Frames.** Mitsuba's local shading frame (``s``, ``t``, ``n``) is gonio's local frame
  (x = tangent ``s``, y = ``t``, z = normal): the components are used unchanged. Anisotropic
  fits are oriented by the shape's ``s`` (its dp/du).
* **Directions.** gonio's ``f(wi, wo)`` takes ``wi`` toward the light, ``wo`` toward the viewer.
  In Mitsuba's radiance transport ``si.wi`` points toward the viewer and ``wo`` toward the light,
  so ``eval`` returns ``f(wi=wo, wo=si.wi) * cos(theta(wo))`` (Mitsuba's ``eval`` includes the
  cosine of its ``wo``). Under importance transport (light tracing) the arguments of ``f`` are
  swapped, the cosine is still that of ``wo``.
* **Sampling.** ``sample`` draws Mitsuba's ``wo`` with the model's ``sample(wo=si.wi, u=sample2)``
  (gonio samples the light direction for a given view and selects a lobe from ``u`` itself, so
  ``sample1`` is unused); ``pdf`` is that sampler's density ``pdf(wi=wo, wo=si.wi)`` in either
  transport mode, and the weight is ``eval / pdf``. Delta lobes (a mirror) are sampled as
  Mitsuba's ``DeltaReflection`` component and are absent from ``eval`` and ``pdf``, as in gonio.
* **Sides.** One-sided, as gonio's models: 0 where either direction is on or below the surface
  (Mitsuba's ``diffuse`` does the same). Wrap it in a ``twosided`` BSDF for a two-sided surface.
* **Channels.** RGB fits render as they are, a one-channel fit as grey; spectral fits are
  refused (:func:`supports`): convert them to RGB first.

Variants
--------
``scalar_rgb`` calls the model once per ray (fine for tests and small images). The vectorized
``llvm_ad_rgb`` and ``cuda_ad_rgb`` call it once per wavefront: :func:`register` turns off
Dr.Jit's symbolic loops and calls for that (a JAX function cannot run inside a traced Dr.Jit
loop), before any scene is loaded. Values cross between Dr.Jit and JAX through host arrays in
float64; gradients do not flow through the plugin. Mitsuba's LLVM backend needs LLVM >= 16
(name the library with ``DRJIT_LIBLLVM_PATH`` where the system's is older).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from gonio.errors import ParameterError
from gonio.io.strict_json import dumps_json

#: The BSDF type name the plugin registers (``<bsdf type="gonio">``).
PLUGIN = "gonio"
#: What the written scene fragment and ``gonio export --help`` say about registering it.
REGISTER_HINT = (
    "import gonio.export.mitsuba_plugin; gonio.export.mitsuba_plugin.register() "
    "(after mitsuba.set_variant, before loading the scene)"
)
_REGISTERED: set[str] = set()


def supports(model: Any) -> bool:
    """True when the plugin renders ``model`` exactly: an analytic gonio model
    (:class:`gonio.brdf.models.BRDFModel`, any family) with 1 (grey) or 3 (RGB) channels."""
    from gonio.brdf.models import BRDFModel

    return isinstance(model, BRDFModel) and model.n_channels in (1, 3)


def read_model(filename: str | None = None, model: str | None = None) -> Any:
    """The model of a plugin's scene parameters (``filename`` or inline ``model`` JSON text),
    through gonio's fit-result reader :mod:`gonio.io.fit_result`.

    Raises
    ------
    ParameterError
        Neither or both given, or a model the plugin cannot render (:func:`supports`).
    FormatError
        Not a fit result or model description.
    """
    from gonio.io.fit_result import load_fit, load_fit_text
    from gonio.io.spectral import wavelengths_from_names

    if (filename is None) == (model is None):
        raise ParameterError("the gonio BSDF takes one of 'filename' (a fit JSON) or 'model'")
    if filename is not None:
        record, m = load_fit(Path(filename), descriptions=True)
        where = filename
    else:
        assert model is not None
        record, m = load_fit_text(model, "gonio BSDF 'model'", descriptions=True)
        where = "the inline model"
    if wavelengths_from_names(record.get("data", {}).get("channels", [])) is not None:
        raise ParameterError(
            f"{where}: a spectral fit; the gonio Mitsuba plugin renders RGB fits (export it "
            "without --plugin, which converts it to linear sRGB)"
        )
    if not supports(m):
        raise ParameterError(
            f"{where}: the gonio Mitsuba plugin renders analytic models with 1 or 3 channels "
            f"(RGB), not a {type(m).__name__} with {getattr(m, 'n_channels', '?')} channels"
        )
    return m


class Kernels:
    """The model's jitted JAX programs on host arrays (float64, channels padded to RGB).

    Batches are padded to a power of two (at least 1) so that a vectorized variant compiles
    each program for a few sizes only.
    """

    def __init__(self, model: Any) -> None:
        import jax

        self.model = model
        self.has_delta = bool(model.has_delta)
        grey = model.n_channels == 1

        def rgb(x: Any) -> Any:
            return jax.numpy.broadcast_to(x, (*x.shape[:-1], 3)) if grey else x

        def f(m: Any, wi: Any, wo: Any) -> Any:
            return rgb(m.f(wi, wo))

        def sample(m: Any, wo: Any, u: Any) -> Any:
            s = m.sample(wo, u)
            return s.wi, s.pdf, rgb(s.weight), s.delta

        # the model is closed over (a constant of each program): no pytree to flatten per call
        self._f = jax.jit(lambda wi, wo: f(model, wi, wo))
        self._pdf = jax.jit(lambda wi, wo: model.pdf(wi, wo))
        self._sample = jax.jit(lambda wo, u: sample(model, wo, u))

    def _run(self, fn: Callable[..., Any], *arrays: np.ndarray) -> list[np.ndarray]:
        n = max(a.shape[0] for a in arrays)  # a Dr.Jit width of 1 broadcasts
        arrays = tuple(np.broadcast_to(a, (n, a.shape[1])) for a in arrays)
        size = 1 << max(0, (n - 1).bit_length())
        if size > n:
            arrays = tuple(np.pad(a, ((0, size - n), (0, 0)), constant_values=0.5) for a in arrays)
        out = fn(*arrays)
        out = out if isinstance(out, tuple) else (out,)
        return [np.asarray(o)[:n] for o in out]

    def f(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """``f(wi, wo)`` (N, 3) in 1/sr for directions (N, 3) in gonio's convention."""
        return self._run(self._f, wi, wo)[0]

    def pdf(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """The sampler's density of ``wi`` given ``wo`` (N,), per steradian."""
        return self._run(self._pdf, wi, wo)[0]

    def sample(self, wo: np.ndarray, u: np.ndarray) -> list[np.ndarray]:
        """``[wi (N, 3), pdf (N,), weight (N, 3), delta (N,)]`` for ``wo`` (N, 3), ``u`` (N, 2)."""
        return self._run(self._sample, wo, u)


def _plugin_class(mi: Any, dr: Any) -> type:
    """The ``mi.BSDF`` subclass for the current variant (``mi.BSDF`` differs per variant)."""
    scalar = mi.variant().startswith("scalar")
    Flags = mi.BSDFFlags

    def host(v: Any, dim: int) -> np.ndarray:
        """A Mitsuba vector (scalar or wavefront) as a host array (N, dim), float64."""
        a = np.array(dr.detach(v) if not scalar else v, dtype=np.float64)
        return a.reshape(1, dim) if scalar else a.reshape(dim, -1).T

    def color(a: np.ndarray) -> Any:
        if scalar:
            return mi.Color3f(*(float(x) for x in a[0]))
        return mi.Color3f(*(mi.Float(np.ascontiguousarray(a[:, c], np.float32)) for c in range(3)))

    def floats(a: np.ndarray) -> Any:
        return mi.Float(float(a[0])) if scalar else mi.Float(np.asarray(a, np.float32))

    class GonioBSDF(mi.BSDF):
        """Mitsuba BSDF ``gonio``: a gonio fit (see :mod:`gonio.export.mitsuba_plugin`)."""

        def __init__(self, props: Any) -> None:
            super().__init__(props)
            keys = set(props.keys())
            filename = props["filename"] if "filename" in keys else None
            inline = props["model"] if "model" in keys else None
            self._model = read_model(
                None if filename is None else str(filename), None if inline is None else inline
            )
            self._k = Kernels(self._model)
            glossy = Flags.GlossyReflection | Flags.FrontSide
            components = [glossy]
            flags = glossy
            if self._k.has_delta:
                components.append(Flags.DeltaReflection | Flags.FrontSide)
                flags = flags | Flags.DeltaReflection
            self.m_components = components
            self.m_flags = flags

        def _pair(
            self, ctx: Any, si_wi: np.ndarray, wo: np.ndarray
        ) -> tuple[np.ndarray, np.ndarray]:
            """(gonio wi, gonio wo) of Mitsuba's (si.wi, wo) for ``ctx``'s transport mode."""
            if ctx.mode == mi.TransportMode.Importance:
                return si_wi, wo
            return wo, si_wi

        def _glossy_on(self, ctx: Any) -> bool:
            return bool(ctx.is_enabled(Flags.GlossyReflection, 0))

        def eval(self, ctx: Any, si: Any, wo: Any, active: Any = True) -> Any:
            if not self._glossy_on(ctx):
                return mi.Color3f(0.0)
            wo_m = host(wo, 3)
            wi_g, wo_g = self._pair(ctx, host(si.wi, 3), wo_m)
            value = self._k.f(wi_g, wo_g) * np.maximum(wo_m[:, 2:3], 0.0)
            return dr.select(active, color(value), mi.Color3f(0.0))

        def pdf(self, ctx: Any, si: Any, wo: Any, active: Any = True) -> Any:
            if not self._glossy_on(ctx):
                return mi.Float(0.0)
            p = self._k.pdf(host(wo, 3), host(si.wi, 3))
            return dr.select(active, floats(p), 0.0)

        def eval_pdf(self, ctx: Any, si: Any, wo: Any, active: Any = True) -> Any:
            return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

        def sample(self, ctx: Any, si: Any, sample1: Any, sample2: Any, active: Any = True) -> Any:
            bs = mi.BSDFSample3f()
            wo_g = host(si.wi, 3)
            wi, pdf, weight, delta = self._k.sample(wo_g, host(sample2, 2))
            delta = delta.astype(bool)
            glossy_ok = self._glossy_on(ctx)
            delta_ok = self._k.has_delta and bool(ctx.is_enabled(Flags.DeltaReflection, 1))
            keep = np.where(delta, delta_ok, glossy_ok) & (pdf > 0)
            if ctx.mode == mi.TransportMode.Importance:  # the adjoint: f's arguments swapped
                f_adj = self._k.f(wo_g, wi) * np.maximum(wi[:, 2:3], 0.0)
                smooth = f_adj / np.where(pdf > 0, pdf, 1.0)[:, None]
                weight = np.where(delta[:, None], weight, smooth)
            weight = np.where(keep[:, None], weight, 0.0)
            bs.wo = mi.Vector3f(*(floats(wi[:, c]) for c in range(3)))
            bs.pdf = floats(np.where(keep, pdf, 0.0))
            bs.eta = 1.0
            if scalar:
                d = bool(delta[0])
                bs.sampled_component = 1 if d else 0
                bs.sampled_type = int(Flags.DeltaReflection if d else Flags.GlossyReflection)
            else:
                dm = mi.Bool(delta)
                bs.sampled_component = dr.select(dm, mi.UInt32(1), mi.UInt32(0))
                bs.sampled_type = dr.select(
                    dm,
                    mi.UInt32(int(Flags.DeltaReflection)),
                    mi.UInt32(int(Flags.GlossyReflection)),
                )
            return bs, dr.select(active, color(weight), mi.Color3f(0.0))

        def traverse(self, callback: Any) -> None:
            pass  # the fit's parameters are not exposed to Mitsuba's differentiation

        def parameters_changed(self, keys: Any = None) -> None:
            pass

        def to_string(self) -> str:
            spec = dumps_json(self._model.to_dict(), source="gonio BSDF")
            return f"GonioBSDF[{spec[:200]}{'...' if len(spec) > 200 else ''}]"

    return GonioBSDF


def register() -> None:
    """Register BSDF type ``"gonio"`` with Mitsuba for the current variant (idempotent; call
    again after switching variants).

    In a JIT variant (LLVM or CUDA), Dr.Jit's symbolic loops and calls are turned off (wavefront
    mode), which the plugin needs: call this before loading a scene.

    Raises
    ------
    ParameterError
        Mitsuba is not installed or no variant is set.
    """
    try:
        import drjit as dr
        import mitsuba as mi
    except ImportError as exc:
        raise ParameterError(
            f"the gonio Mitsuba plugin needs mitsuba (pip install mitsuba): {exc}"
        ) from None
    variant = mi.variant()
    if variant is None:
        raise ParameterError("set a Mitsuba variant (mitsuba.set_variant) before register()")
    if not variant.startswith("scalar"):
        dr.set_flag(dr.JitFlag.SymbolicLoops, False)
        dr.set_flag(dr.JitFlag.SymbolicCalls, False)
    if variant in _REGISTERED:
        return
    cls = _plugin_class(mi, dr)
    mi.register_bsdf(PLUGIN, lambda props: cls(props))
    _REGISTERED.add(variant)


def scene_fragment(name: str, model: Any, header: str) -> tuple[str, dict[str, Any]]:
    """``(XML <bsdf> fragment, load_dict dictionary)`` using the plugin with ``model`` inline.

    The XML begins with comments saying how to register the plugin and the Python-API
    equivalent; the dictionary is ``{"type": "gonio", "model": <model JSON text>}``.
    """
    import xml.etree.ElementTree as ET

    spec = dumps_json(
        model.to_dict(), nonfinite="refuse", source="gonio plugin fragment", separators=(",", ":")
    )
    data = {"type": PLUGIN, "model": spec}
    el = ET.Element("bsdf", {"type": PLUGIN, "id": name})
    ET.SubElement(el, "string", {"name": "model", "value": spec})
    ET.indent(el)
    comments = [
        header,
        "needs gonio at render time: in the Python process that loads this scene, after "
        f"mitsuba.set_variant(...): {REGISTER_HINT}",
        "Python API: mi.load_dict({'type': 'gonio', 'model': <the value below>}) or "
        "{'type': 'gonio', 'filename': 'FIT.json'}; wrap it in a 'twosided' BSDF for a "
        "two-sided surface",
    ]
    text = "".join(f"<!-- {c.replace('--', '- -')} -->\n" for c in comments)
    return text + ET.tostring(el, encoding="unicode") + "\n", data


def export(fit: Any) -> Any:
    """The plugin export of a fit (``gonio export FIT --to mitsuba --plugin``): an
    :class:`~gonio.export.Export` with ``mapping == "plugin"``, files ``.xml`` (the fragment)
    and ``.json`` (its ``load_dict`` dictionary).

    Parameters
    ----------
    fit : a fit-result JSON path, a :class:`gonio.fit.FitResult` or its ``to_json()`` dict.

    Raises
    ------
    ParameterError
        For a fit the plugin cannot render (:func:`supports`: a spectral fit, a table).
    """
    from gonio.export._common import Export
    from gonio.export._lobes import describe
    from gonio.export._source import load
    from gonio.io.strict_json import dumps_json

    src = load(fit)
    if src.spectral or not supports(src.model):
        raise ParameterError(
            f"the gonio Mitsuba plugin renders RGB (or one-channel) fits; this fit has "
            f"{len(src.channels)} channels ({', '.join(src.channels[:4])}...): export it "
            "without --plugin"
        )
    family = describe(src.model)
    header = f"gonio export: {src.name} for Mitsuba 3 through the gonio BSDF plugin ({family})"
    xml, data = scene_fragment(src.name, src.model, header)
    files = {
        ".xml": xml,
        ".json": dumps_json(data, indent=2, nonfinite="refuse", source=f"{src.name}.json") + "\n",
    }
    notes = [
        f"the scene needs gonio at render time: {REGISTER_HINT}",
        "one-sided like gonio's models; evaluates and samples gonio's own model (exact)",
    ]
    out = Export(
        "mitsuba", src.name, files, "plugin", family, {"model": src.model.to_dict()},
        notes=notes, data=data,
    )  # fmt: skip
    out.source = None if src.path is None else str(src.path)
    return out
