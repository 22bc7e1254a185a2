"""Sums of lobes: ``Lambert(...) + TorranceSparrow(...)`` is a model."""

from __future__ import annotations

from typing import Any

import jax.numpy as jnp

from gonio.brdf.frames import safe_div, upper
from gonio.brdf.models._base import (
    BRDFModel,
    BRDFSample,
    Node,
    Param,
    choose_lobe,
    masked_outgoing,
    safe_pair,
    sample_inputs,
)
from gonio.errors import ParameterError

Array = jnp.ndarray


class Sum(BRDFModel):
    """A sum of lobes: ``f`` adds; sampling picks a lobe in proportion to its albedo estimate
    (``sampling_weight``) and ``pdf`` is the matching mixture of the non-delta lobes.

    Parameters are exposed as ``"<lobe>.<name>"`` where ``<lobe>`` is the lower-case class name
    (``"lambert.albedo"``), numbered from the second occurrence on (``"ward2.alpha_x"``).
    """

    CHILDREN = ("lobes",)

    def __init__(self, *lobes: BRDFModel) -> None:
        flat: list[BRDFModel] = []
        for lobe in lobes:
            if isinstance(lobe, Sum):
                flat.extend(lobe.lobes)
            elif isinstance(lobe, BRDFModel):
                flat.append(lobe)
            else:
                raise ParameterError(f"Sum: {lobe!r} is not a BRDF model")
        if not flat:
            raise ParameterError("Sum: needs at least one lobe")
        object.__setattr__(self, "lobes", tuple(flat))
        _ = self.channels  # validates channel agreement

    @property
    def channels(self) -> int:
        sizes = {lobe.channels for lobe in self.lobes} - {1}
        if len(sizes) > 1:
            raise ParameterError(f"Sum: lobes disagree on the channel count ({sorted(sizes)})")
        return sizes.pop() if sizes else 1

    @property
    def has_delta(self) -> bool:
        """True when at least one lobe is a Dirac delta."""
        return any(lobe.is_delta for lobe in self.lobes)

    def lobe_keys(self) -> list[str]:
        """Name of each lobe in parameter keys (``"lambert"``, ``"ward"``, ``"ward2"``)."""
        seen: dict[str, int] = {}
        keys = []
        for lobe in self.lobes:
            base = type(lobe).__name__.lower()
            seen[base] = seen.get(base, 0) + 1
            keys.append(base if seen[base] == 1 else f"{base}{seen[base]}")
        return keys

    def param_specs(self) -> dict[str, Param]:
        out: dict[str, Param] = {}
        for key, lobe in zip(self.lobe_keys(), self.lobes, strict=True):
            out.update({f"{key}.{k}": v for k, v in lobe.param_specs().items()})
        return out

    def params(self) -> dict[str, Array]:
        out: dict[str, Array] = {}
        for key, lobe in zip(self.lobe_keys(), self.lobes, strict=True):
            out.update({f"{key}.{k}": v for k, v in lobe.params().items()})
        return out

    def replace(self, **values: Any) -> Sum:
        keys = self.lobe_keys()
        per: dict[str, dict[str, Any]] = {k: {} for k in keys}
        for key, value in values.items():
            head, _, rest = key.partition(".")
            if head not in per or not rest:
                raise ParameterError(f"Sum: unknown parameter {key!r}")
            per[head][rest] = value
        lobes = tuple(
            lobe.replace(**per[k]) if per[k] else lobe
            for k, lobe in zip(keys, self.lobes, strict=True)
        )
        return Sum._tree_unflatten((), [lobes])

    def to_dict(self) -> dict[str, Any]:
        return {"type": "Sum", "lobes": [lobe.to_dict() for lobe in self.lobes]}

    @classmethod
    def _from_dict(cls, d: dict[str, Any]) -> Sum:
        return cls(*(Node.from_dict(x) for x in d.get("lobes", [])))

    def __repr__(self) -> str:
        return " + ".join(repr(lobe) for lobe in self.lobes)

    # -- evaluation -----------------------------------------------------------------------------
    def _smooth(self) -> list[BRDFModel]:
        return [lobe for lobe in self.lobes if not lobe.is_delta]

    def _f(self, wi: Array, wo: Array) -> Array:
        shape = (*wi.shape[:-1], self.channels)
        total = jnp.zeros(shape, dtype=wi.dtype)
        for lobe in self._smooth():
            total = total + lobe._f(wi, wo)
        return total

    def _probs(self, wo: Array) -> list[Array]:
        ws = [jnp.maximum(lobe.sampling_weight(wo), 0.0) for lobe in self.lobes]
        total = sum(ws)
        k = len(ws)
        return [jnp.where(total > 0, safe_div(w, total), 1.0 / k) for w in ws]

    def _pdf(self, wi: Array, wo: Array) -> Array:
        total = jnp.zeros(wi.shape[:-1], dtype=wi.dtype)
        for lobe, p in zip(self.lobes, self._probs(wo), strict=True):
            if not lobe.is_delta:
                total = total + p * lobe._pdf(wi, wo)
        return total

    def sampling_weight(self, wo: Array) -> Array:
        return sum(lobe.sampling_weight(wo) for lobe in self.lobes)

    def sample(self, wo: Array, u: Array) -> BRDFSample:
        wo, u = sample_inputs(wo, u)
        wo_s, ok_o = masked_outgoing(wo)
        shape = ok_o.shape

        weights = [lobe.sampling_weight(wo_s) for lobe in self.lobes]
        index, u0, probs = choose_lobe(u[..., 0], weights)
        uu = jnp.stack([u0, u[..., 1]], -1)

        wi = jnp.zeros_like(wo_s)
        is_delta = jnp.zeros(shape, dtype=bool)
        delta_pdf = jnp.zeros(shape, dtype=wo.dtype)
        delta_weight = jnp.zeros((*shape, self.channels), dtype=wo.dtype)
        for i, (lobe, p) in enumerate(zip(self.lobes, probs, strict=True)):
            take = index == i
            if lobe.is_delta:
                s = lobe.sample(wo_s, uu)
                wi = jnp.where(take[..., None], s.wi, wi)
                is_delta = is_delta | take
                delta_pdf = jnp.where(take, p * s.pdf, delta_pdf)
                delta_weight = jnp.where(
                    take[..., None], safe_div(s.weight, p[..., None]), delta_weight
                )
            else:
                wi = jnp.where(take[..., None], lobe._sample(wo_s, uu).astype(wo.dtype), wi)

        # Smooth part: the mixture pdf over every non-delta lobe.
        ok = ok_o & upper(wi) & ~is_delta
        wi_s, _ = safe_pair(wi, wo_s, ok)
        pdf = jnp.zeros(shape, dtype=wo.dtype)
        for lobe, p in zip(self.lobes, probs, strict=True):
            if not lobe.is_delta:
                pdf = pdf + p * lobe._pdf(wi_s, wo_s)
        ok = ok & (pdf > 0)
        val = self._f(wi_s, wo_s)
        weight = jnp.where(ok[..., None], safe_div(val * wi_s[..., 2:3], pdf[..., None]), 0.0)
        pdf = jnp.where(ok, pdf, 0.0)

        pdf = jnp.where(is_delta, jnp.where(ok_o, delta_pdf, 0.0), pdf)
        weight = jnp.where(is_delta[..., None] & ok_o[..., None], delta_weight, weight)
        return BRDFSample(wi, pdf.astype(wo.dtype), weight.astype(wo.dtype), is_delta & ok_o)
