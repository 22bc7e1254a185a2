"""A material bound to one sampling method: small JAX pytrees whose ``sample`` and ``pdf`` are
the plain :class:`~gonio.brdf.material.Material` interface.

:class:`CosineSampled` and :class:`LobeSampled` sample *any* material (the generic methods
``"cosine"`` and ``"lobe"`` that every material's ``with_sampling`` answers);
:class:`TableSampled` is a table with one of its own methods and the sampling structures built
for the outgoing directions its caller will use (``TabulatedBRDF.with_sampling``). ``f``, the
channels and the delta flag are the wrapped material's.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp

from gonio.brdf.sample_record import BRDFSample
from gonio.brdf.sampling import warps as warp
from gonio.errors import ParameterError

Array = jnp.ndarray

#: The sampling methods every material answers in ``with_sampling``.
GENERIC_METHODS = ("cosine", "lobe")


class _Bound:
    """What every bound material passes through from the material it wraps."""

    base: Any

    @property
    def n_channels(self) -> int:
        return self.base.n_channels

    @property
    def channel_info(self) -> Any:
        return self.base.channel_info

    @property
    def has_delta(self) -> bool:
        return self.base.has_delta

    @property
    def sampling_methods(self) -> tuple[str, ...]:
        return self.base.sampling_methods

    #: Batches are laid out samples-major for a bound material.
    broadcasts_outgoing = False

    def f(self, wi: Any, wo: Any) -> Array:
        """The wrapped material's ``f``, in the dtype of ``wi``."""
        return jnp.asarray(self.base.f(wi, wo), wi.dtype)

    def with_sampling(self, method: str | None = None, *, proposal: Any = None,
                      wo: Any = None) -> Any:  # fmt: skip
        """The wrapped material bound to another method."""
        return self.base.with_sampling(method, proposal=proposal, wo=wo)


@jax.tree_util.register_pytree_node_class
class CosineSampled(_Bound):
    """``base`` sampled cosine-weighted over the hemisphere (the shape of ``f`` ignored):
    ``pdf = cos(theta_i) / pi`` (0 when ``wo`` is below the horizon), ``weight = pi f``."""

    def __init__(self, base: Any) -> None:
        if base.has_delta:
            raise ParameterError("cosine sampling cannot find the delta lobes of this material")
        self.base = base

    def pdf(self, wi: Any, wo: Any) -> Array:
        return warp.cosine_hemisphere_pdf(wi) * (wo[..., 2] > 0)

    def sample(self, wo: Any, u: Any) -> BRDFSample:
        wi = warp.square_to_cosine_hemisphere(u)
        pdf = warp.cosine_hemisphere_pdf(wi)
        f = self.f(wi, wo)
        weight = jnp.where((pdf > 0)[..., None], f * jnp.pi, 0.0)
        return BRDFSample(wi, pdf, weight, jnp.zeros(pdf.shape, dtype=bool))

    def select_channels(self, idx: Sequence[int]) -> CosineSampled | None:
        cut = self.base.select_channels(idx)
        return None if cut is None else CosineSampled(cut)

    def tree_flatten(self) -> tuple[tuple[Any], None]:
        return (self.base,), None

    @classmethod
    def tree_unflatten(cls, aux: None, leaves: Sequence[Any]) -> CosineSampled:
        obj = object.__new__(cls)
        obj.base = leaves[0]
        return obj


@jax.tree_util.register_pytree_node_class
class LobeSampled(_Bound):
    """``base`` sampled by ``proposal``'s own sampler ("analytic lobe" sampling, e.g. a table
    by its fit): directions and density from ``proposal``, values from ``base``, ``weight = f
    cos / pdf``. The proposal must have no delta lobes (its density must be one)."""

    def __init__(self, base: Any, proposal: Any) -> None:
        if proposal is None:
            raise ParameterError("lobe sampling needs a proposal (an analytic model)")
        if proposal.has_delta:
            raise ParameterError("the proposal must have no delta lobes")
        if base.has_delta:
            raise ParameterError("lobe sampling cannot find the delta lobes of this material")
        self.base = base
        self.proposal = proposal

    def pdf(self, wi: Any, wo: Any) -> Array:
        return self.proposal.pdf(wi, wo)

    def sample(self, wo: Any, u: Any) -> BRDFSample:
        s = self.proposal.sample(wo, u)
        ok = s.pdf > 0
        cos = jnp.maximum(s.wi[..., 2], 0.0)
        w = self.f(s.wi, wo) * jnp.where(ok, cos / jnp.where(ok, s.pdf, 1.0), 0.0)[..., None]
        return BRDFSample(s.wi, s.pdf, w, jnp.zeros(s.pdf.shape, bool))

    def select_channels(self, idx: Sequence[int]) -> LobeSampled | None:
        cut = self.base.select_channels(idx)
        return None if cut is None else LobeSampled(cut, self.proposal)

    def tree_flatten(self) -> tuple[tuple[Any, Any], None]:
        return (self.base, self.proposal), None

    @classmethod
    def tree_unflatten(cls, aux: None, leaves: Sequence[Any]) -> LobeSampled:
        obj = object.__new__(cls)
        obj.base, obj.proposal = leaves
        return obj


@jax.tree_util.register_pytree_node_class
class TableSampled(_Bound):
    """A table sampled by one of its own methods, with the sampling structures (``state``,
    from ``TabulatedBRDF.sampling_state``) as pytree leaves; ``state=None`` builds them when
    called (eagerly only)."""

    def __init__(self, base: Any, method: str, state: Any = None) -> None:
        self.base = base
        self.method = method
        self.state = state

    def pdf(self, wi: Any, wo: Any) -> Array:
        return self.base.pdf(wi, wo, method=self.method, state=self.state)

    def sample(self, wo: Any, u: Any) -> BRDFSample:
        return self.base.sample(wo, u, method=self.method, state=self.state)

    def select_channels(self, idx: Sequence[int]) -> None:
        """None: the sampling structures belong to every channel (cut the table, then bind)."""
        return None

    def tree_flatten(self) -> tuple[tuple[Any, Any], str]:
        return (self.base, self.state), self.method

    @classmethod
    def tree_unflatten(cls, aux: str, leaves: Sequence[Any]) -> TableSampled:
        obj = object.__new__(cls)
        obj.base, obj.state = leaves
        obj.method = aux
        return obj


def bind_generic(material: Any, method: str | None, proposal: Any = None) -> Any:
    """``material`` bound to a generic method (``"cosine"`` or ``"lobe"``): the part of every
    material's ``with_sampling`` that is not its own."""
    if method == "cosine":
        if proposal is not None:
            raise ParameterError("proposal= is used by lobe sampling only")
        return CosineSampled(material)
    if method == "lobe":
        return LobeSampled(material, proposal)
    offered = ", ".join((*material.sampling_methods, *GENERIC_METHODS))
    raise ParameterError(f"this material is sampled by {offered}; got {method!r}")


__all__ = ["GENERIC_METHODS", "CosineSampled", "LobeSampled", "TableSampled", "bind_generic"]
