"""Scattered BRDF measurements (:class:`MeasuredSamples`): one row per (wi, wo) pair, as
acquired or read from a scattered format.

As a material (:class:`gonio.brdf.material.Material`) scattered samples are their documented
interpolant: :func:`gonio.brdf.gridding.filled_interpolant`, the log-linear Delaunay
interpolant tabulated on the 64 x 32 x 32 isotropic half/diff grid of
:func:`gonio.brdf.gridding.render_axes`, every node above the horizon valid (outside the
samples' convex hull, the nearest sample's value). It is built on first use and kept; ``f``,
``pdf``, ``sample``, ``select_channels`` and ``with_sampling`` are that table's.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from gonio.brdf.grid import Channels, numeric_array
from gonio.brdf.sample_record import BRDFSample
from gonio.brdf.tabulated import TABLE_METHODS, TabulatedBRDF
from gonio.errors import FormatError


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
        wi = numeric_array(wi, "wi", np.float64)
        wo = numeric_array(wo, "wo", np.float64)
        vals = numeric_array(values, "values", np.float64)
        if wi.ndim != 2 or wi.shape[1] != 3 or wo.shape != wi.shape:
            raise FormatError(f"wi and wo must both be (N, 3), got {wi.shape} and {wo.shape}")
        n = wi.shape[0]
        if vals.ndim == 1:
            vals = vals[:, None]
        if vals.ndim != 2 or vals.shape[0] != n or vals.shape[1] < 1:
            raise FormatError(f"values must be ({n}, C), got {vals.shape}")
        sig = None
        if sigma is not None:
            sig = numeric_array(sigma, "sigma", np.float64)
            if sig.ndim == 1:
                sig = sig[:, None]
            if sig.shape != vals.shape:
                raise FormatError(f"sigma has shape {sig.shape}, expected {vals.shape}")
        w = None
        if weights is not None:
            w = numeric_array(weights, "weights", np.float64)
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
        channels = Channels.describe(channels, C)
        for arr in (wi, wo, vals, sig, w):
            if arr is not None:
                arr.setflags(write=False)
        self.wi, self.wo, self.values, self.sigma, self.weights = wi, wo, vals, sig, w
        self.channels = channels
        self.meta: dict[str, Any] = dict(meta or {})
        self._interpolant: tuple[TabulatedBRDF, float] | None = None

    @classmethod
    def from_table(cls, table: TabulatedBRDF) -> MeasuredSamples:
        """A table's valid nodes whose directions are both above the horizon, as samples.

        ``weights`` are the cell measures of :meth:`TabulatedBRDF.cell_measure` (sr^2), so that
        sums over the samples approximate integrals over direction pairs.
        """
        wi, wo, vals, sig, weights = table.valid_nodes()
        meta = dict(table.meta)
        meta["converted_from"] = f"TabulatedBRDF {table.parameterization} {table.shape}"
        return cls(wi, wo, vals, sig, table.channels, weights, meta)

    def __len__(self) -> int:
        return self.wi.shape[0]

    @property
    def n_channels(self) -> int:
        return len(self.channels)

    @property
    def channel_info(self) -> Channels:
        """The channel description (the same as :attr:`channels`)."""
        return self.channels

    def __repr__(self) -> str:
        return f"MeasuredSamples(N={len(self)}, {self.channels!r})"

    # -- the Material interface, through the interpolant (module docstring) ---------------------
    sampling_methods = TABLE_METHODS
    has_delta = False
    broadcasts_outgoing = False

    def interpolant(self) -> TabulatedBRDF:
        """The table these samples are as a material (module docstring), built once."""
        return self._filled()[0]

    def interpolant_coverage(self) -> float:
        """Fraction of the interpolant's above-horizon nodes inside the samples' convex hull
        (the rest hold the nearest sample's value)."""
        return self._filled()[1]

    def _filled(self) -> tuple[TabulatedBRDF, float]:
        if self._interpolant is None:
            from gonio.brdf.gridding import filled_interpolant

            self._interpolant = filled_interpolant(self)
        return self._interpolant

    def f(self, wi: Any, wo: Any) -> Any:
        """The interpolant's BRDF in 1/sr, no cosine: ``(..., 3), (..., 3) -> (..., C)``."""
        return self.interpolant().f(wi, wo)

    def pdf(self, wi: Any, wo: Any) -> Any:
        """Density of :meth:`sample` over ``wi`` per unit solid angle, ``(...)``."""
        return self.interpolant().pdf(wi, wo)

    def sample(self, wo: Any, u: Any) -> BRDFSample:
        """``wi`` for ``wo (..., 3)`` from ``u (..., 2)`` by the interpolant's default method."""
        return self.interpolant().sample(wo, u)

    def select_channels(self, idx: Any) -> TabulatedBRDF | None:
        """The interpolant with only channels ``idx`` (None where it cannot cut them)."""
        return self.interpolant().select_channels(idx)

    def with_sampling(
        self, method: str | None = None, *, proposal: Any = None, wo: Any = None
    ) -> Any:
        """The interpolant bound to one sampling method
        (:meth:`gonio.brdf.material.Material.with_sampling`)."""
        return self.interpolant().with_sampling(method, proposal=proposal, wo=wo)


__all__ = ["MeasuredSamples"]
