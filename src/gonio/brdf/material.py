"""What every material answers: the :class:`Material` protocol.

A *material* is anything the renderer and the exporter take: an analytic model
(:class:`gonio.brdf.models.BRDFModel`, sums and scaled lobes included), a gridded table
(:class:`gonio.brdf.tabulated.TabulatedBRDF`), an RGL tensor file
(:class:`gonio.io.rgl_measured.RGLMeasured`) and scattered measurements
(:class:`gonio.brdf.measured.MeasuredSamples`), which answer through their documented
interpolant, the Delaunay-gridded table of :func:`gonio.brdf.gridding.filled_interpolant`.
They all offer the members below under the same names, so that code taking a material never
asks what it is.

Conventions
-----------
Directions are unit vectors ``(..., 3)`` in the local frame (z the surface normal, x the
tangent); ``wi`` points toward the light, ``wo`` toward the viewer, both away from the surface.
Uniform numbers ``u`` are ``(..., 2)`` in ``[0, 1)`` and always come from the caller.

Sampling is bound once
----------------------
A material may offer several ways to sample it (:attr:`Material.sampling_methods`; the first
is its default). :meth:`Material.with_sampling` returns a small JAX pytree, itself a material,
whose ``sample`` and ``pdf`` are the plain interface for the chosen method: a table's method and
the sampling structures built for the outgoing directions the caller will use travel inside it,
so a jitted kernel takes it as an argument and never waits on the host. Two methods are generic
and every material answers them (:mod:`gonio.brdf.sampled`): ``"cosine"`` (cosine-weighted
hemisphere sampling, ignoring the BRDF's shape) and ``"lobe"`` (directions and density from an
analytic ``proposal``, values from the material).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol, runtime_checkable

from gonio.brdf.grid import Channels
from gonio.brdf.sample_record import BRDFSample
from gonio.brdf.sampled import GENERIC_METHODS


@runtime_checkable
class Material(Protocol):
    """A BRDF the renderer and the exporter take (see the module docstring).

    Attributes
    ----------
    n_channels : int
        The channel count C of ``f`` (1, 3 or the number of wavelengths).
    channel_info : Channels or None
        What the channels are (names, RGB or spectral, wavelengths); None where the material
        does not know (an analytic model with C other than 1 or 3).
    has_delta : bool
        True when the material is, or contains, a Dirac delta lobe (a mirror): ``f`` and
        ``pdf`` never see it and only ``sample`` finds it (``BRDFSample.delta``).
    sampling_methods : tuple of str
        The material's own sampling methods, the default first: ``("native",)`` for analytic
        models and RGL files, ``("inversion", "alias", "rejection")`` for tables. The
        :data:`GENERIC_METHODS` are answered too.
    broadcasts_outgoing : bool
        ``f``, ``pdf`` and ``sample`` accept ``wo`` with size-1 axes where ``wi`` or ``u`` have
        more, and compute what depends on ``wo`` alone once per ``wo`` (a hint for callers that
        lay out their batches; the values are the same either way).
    """

    @property
    def n_channels(self) -> int: ...

    @property
    def channel_info(self) -> Channels | None: ...

    @property
    def has_delta(self) -> bool: ...

    @property
    def sampling_methods(self) -> tuple[str, ...]: ...

    @property
    def broadcasts_outgoing(self) -> bool: ...

    def f(self, wi: Any, wo: Any) -> Any:
        """The BRDF in 1/sr, **without** the cosine: ``(..., 3), (..., 3) -> (..., C)``;
        0 where either direction is on or below the horizon."""
        ...

    def pdf(self, wi: Any, wo: Any) -> Any:
        """Density of ``sample`` over ``wi`` per unit solid angle, ``(...)``; 0 on or below
        the horizon. Delta lobes have no density (they are not counted here)."""
        ...

    def sample(self, wo: Any, u: Any) -> BRDFSample:
        """``wi`` drawn for ``wo (..., 3)`` from ``u (..., 2)``, by the default method (or the
        bound one, see :meth:`with_sampling`): ``BRDFSample(wi (..., 3), pdf (...), weight =
        f cos / pdf (..., C), delta (...))``; a failed sample has pdf 0 and weight 0."""
        ...

    def select_channels(self, idx: Sequence[int]) -> Material | None:
        """The material with only channels ``idx``, evaluating only those; None when it cannot
        cut them (the caller then evaluates every channel and cuts the result)."""
        ...

    def with_sampling(
        self, method: str | None = None, *, proposal: Any = None, wo: Any = None
    ) -> Material:
        """The material bound to one sampling method, as a JAX pytree (module docstring).

        Parameters
        ----------
        method : one of :attr:`sampling_methods` (None: the default) or of
            :data:`GENERIC_METHODS`.
        proposal : for ``"lobe"``: the material whose ``sample`` and ``pdf`` propose
            directions (no delta lobes).
        wo : outgoing directions ``(..., 3)`` (or a list of such arrays) the bound material
            will be sampled at: a table builds its sampling structures for them here, once.

        Raises
        ------
        ParameterError
            A method the material does not offer, or a missing or unusable ``proposal``.
        """
        ...


__all__ = ["GENERIC_METHODS", "Material"]
