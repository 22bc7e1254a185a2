"""Turn a table or a set of scattered samples into the flat arrays a fit works on.

Whatever the source (a :class:`~gonio.brdf.tabulated.TabulatedBRDF`, a
:class:`~gonio.brdf.tabulated.MeasuredSamples`, a file path readable by :func:`gonio.io.load`),
the fitter sees one :class:`FitData`: ``N`` direction pairs in the local frame, the measured BRDF
``values`` in sr^-1 (not cosine-weighted) with channels last, an optional per-value standard
deviation ``sigma`` and per-sample quadrature ``weights`` (the measure of the cell a sample stands
for; 1 for scattered samples). Samples are dropped, and counted, when a value or sigma is not
finite, when sigma is not positive, when a direction is at or below the horizon, or when either
polar angle exceeds the cutoff ``theta_max`` (80 degrees by default: grazing cells are the least
reliable part of every gonioreflectometer measurement and the literature's fits exclude them).
A table whose metadata say ``sigma_correlated`` (a reconstruction through a material prior,
:mod:`gonio.prior`) is read without its sigma: that sigma is correlated across cells, not the
independent noise per value a chi-square weights by.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gonio.errors import FitError

#: Default polar-angle cutoff in degrees for both directions.
DEFAULT_THETA_MAX_DEG = 80.0
#: Why a table's sigma is not used (its metadata say ``sigma_correlated``: a prior
#: reconstruction, :mod:`gonio.prior`); recorded in ``FitData.source["sigma_ignored"]``.
SIGMA_CORRELATED_NOTE = (
    "its sigma is correlated across cells (a prior reconstruction): fitted and ranked as data "
    "without sigma, no chi-square or BIC from it"
)


@dataclass(frozen=True)
class FitData:
    """Flat, validated samples for fitting.

    Attributes
    ----------
    wi, wo : (N, 3) float64 unit vectors in the local frame (z = normal), both above the horizon.
    values : (N, C) float64 measured BRDF in sr^-1 (no cosine factor).
    sigma : (N, C) float64 standard deviation of each value in sr^-1, or None when unknown.
    weights : (N,) float64 positive quadrature weights (cell measure; ones for scattered data).
    channel_names : C names (``("R", "G", "B")``, wavelengths, ...).
    source : provenance and bookkeeping: ``kind``, ``name``, ``path``, ``n_input``, ``n_used``,
        ``n_invalid``, ``n_beyond_cutoff``, ``theta_max_deg``.
    """

    wi: np.ndarray
    wo: np.ndarray
    values: np.ndarray
    sigma: np.ndarray | None
    weights: np.ndarray
    channel_names: tuple[str, ...]
    source: dict[str, Any] = field(default_factory=dict)

    @property
    def n(self) -> int:
        """Number of direction pairs N."""
        return int(self.values.shape[0])

    @property
    def channels(self) -> int:
        """Number of channels C."""
        return int(self.values.shape[1])

    def subset(self, index: np.ndarray) -> FitData:
        """The samples at ``index`` (integer array or boolean mask)."""
        return FitData(
            self.wi[index],
            self.wo[index],
            self.values[index],
            None if self.sigma is None else self.sigma[index],
            self.weights[index],
            self.channel_names,
            {**self.source, "n_used": int(np.size(self.weights[index]))},
        )

    def channel(self, c: int) -> FitData:
        """One channel as mono data (for per-channel fits)."""
        sl = slice(c, c + 1)
        return FitData(
            self.wi,
            self.wo,
            self.values[:, sl],
            None if self.sigma is None else self.sigma[:, sl],
            self.weights,
            (self.channel_names[c],),
            {**self.source, "channel": self.channel_names[c]},
        )

    def random_subset(self, max_samples: int, seed: int = 0) -> FitData:
        """At most ``max_samples`` samples drawn without replacement (fixed seed); self if fewer.
        The same call on the same data returns the same object (a fit of several models to one
        table draws its subsets once)."""
        if self.n <= max_samples:
            return self
        return _memo(self, ("random", max_samples, seed), self._random_subset)

    def _random_subset(self, max_samples: int, seed: int) -> FitData:
        rng = np.random.default_rng(seed)
        idx = np.sort(rng.choice(self.n, size=max_samples, replace=False))
        return self.subset(idx)

    def stratified_subset(self, max_samples: int, seed: int = 0) -> FitData:
        """At most ``max_samples`` samples, one drawn at random (fixed seed) from each of
        ``max_samples`` strata of equal count along the half-vector polar angle theta_h; self if
        fewer. Unlike a plain random subset, the few cells near the specular peak (small theta_h)
        are represented in proportion, never missed by chance. Memoized like
        :meth:`random_subset`."""
        if self.n <= max_samples:
            return self
        return _memo(self, ("stratified", max_samples, seed), self._stratified_subset)

    def _stratified_subset(self, max_samples: int, seed: int) -> FitData:
        return self.subset(self.stratified_indices(max_samples, seed))

    def stratified_indices(self, max_samples: int, seed: int = 0) -> np.ndarray:
        """The sorted sample indices :meth:`stratified_subset` keeps (all when fewer)."""
        if self.n <= max_samples:
            return np.arange(self.n)
        h = self.wi + self.wo
        cos_h = h[:, 2] / np.linalg.norm(h, axis=1)
        order = np.argsort(-cos_h, kind="stable")  # theta_h ascending
        edges = np.linspace(0, self.n, max_samples + 1).astype(np.int64)
        rng = np.random.default_rng(seed)
        pick = edges[:-1] + (rng.random(max_samples) * np.diff(edges)).astype(np.int64)
        return np.sort(order[pick])

    def half_diff(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rusinkiewicz ``(theta_h, theta_d, phi_d)`` in radians, each (N,), for plots."""
        from gonio.brdf.frames import half_diff

        theta_h, _, theta_d, phi_d = half_diff(self.wi, self.wo)
        theta_h, theta_d = np.asarray(theta_h), np.asarray(theta_d)
        phi_d = np.mod(np.asarray(phi_d), np.pi)
        return theta_h, theta_d, phi_d

    def describe(self) -> dict[str, Any]:
        """JSON-ready description of the data (for fit results)."""
        return {
            **{k: v for k, v in self.source.items() if _jsonable(v)},
            "n_samples": self.n,
            "channels": list(self.channel_names),
            "has_sigma": self.sigma is not None,
        }


#: Subsets of the last few data sets: ``(id(data), kind, size, seed) -> (weak reference to the
#: data, subset)``.
_SUBSETS: dict[tuple[Any, ...], tuple[Any, FitData]] = {}


def _memo(data: FitData, key: tuple[Any, ...], make: Any) -> FitData:
    """``make(*key[1:])`` for ``data``, computed once while ``data`` lives."""
    full = (id(data), *key)
    hit = _SUBSETS.get(full)
    if hit is not None and hit[0]() is data:
        return hit[1]
    out = make(*key[1:])
    if len(_SUBSETS) >= 16:
        _SUBSETS.clear()
    _SUBSETS[full] = (weakref.ref(data), out)
    return out


def _jsonable(v: Any) -> bool:
    if isinstance(v, dict):
        return all(isinstance(k, str) and _jsonable(x) for k, x in v.items())
    return isinstance(v, (str, int, float, bool, type(None), list))


def load_data(path: str | Path) -> Any:
    """Read a file with :func:`gonio.io.load` (its typed errors name what is wrong)."""
    from gonio import io as gio

    return gio.load(Path(path))


def prepare(
    data: Any,
    theta_max_deg: float = DEFAULT_THETA_MAX_DEG,
    *,
    name: str | None = None,
) -> FitData:
    """Flatten and validate fit input.

    Parameters
    ----------
    data : a TabulatedBRDF, an RGL file (:class:`~gonio.io.rgl_measured.RGLMeasured`), a
        MeasuredSamples (anything with
        ``wi``, ``wo``, ``values`` and optionally ``sigma``, ``weights``, ``channels``, ``meta``),
        a :class:`FitData` (re-filtered with the cutoff), or a path read with :func:`gonio.io.load`.
    theta_max_deg : polar-angle cutoff in degrees applied to both directions, in (0, 90].
    name : material name recorded in ``source`` (default: the file stem or ``meta["name"]``).

    Returns
    -------
    FitData with every sample valid.

    Raises
    ------
    FitError
        When the input has no usable samples or inconsistent shapes.
    """
    if not (0.0 < float(theta_max_deg) <= 90.0):
        raise FitError(f"theta_max must be in (0, 90] degrees, got {theta_max_deg}")
    source: dict[str, Any] = {}
    if isinstance(data, (str, Path)):
        source["path"] = str(data)
        member = str(data).rpartition("::")[2] if "::" in str(data) else ""  # ARCHIVE.zip::NAME
        source["name"] = member or Path(data).name.split(".")[0]
        data = load_data(data)
    kind = type(data).__name__
    meta = dict(getattr(data, "meta", None) or {})
    from gonio.brdf.tabulated import TabulatedBRDF
    from gonio.io.rgl_measured import RGLMeasured

    if isinstance(data, TabulatedBRDF):
        data = _table_samples(data)
        source.setdefault("kind", kind)
    elif isinstance(data, RGLMeasured):  # the file's own nodes
        data = data.to_samples()
        source.setdefault("kind", kind)
    source.setdefault("kind", type(data).__name__)
    for key in ("name", "material", "source", "path"):
        v = meta.get(key)
        if isinstance(v, dict):  # e.g. a reader's provenance (what an NBRDF reader clamped)
            v = {str(k): x for k, x in v.items() if _jsonable(x)}
        if key != "source" and not isinstance(v, str):
            continue  # the fit-result format holds a name and a path as text
        if key in meta and _jsonable(v):
            source.setdefault("name" if key == "material" else key, v)
    if name is not None:
        source["name"] = name

    try:
        wi = np.asarray(data.wi, dtype=np.float64)
        wo = np.asarray(data.wo, dtype=np.float64)
        values = np.asarray(data.values, dtype=np.float64)
    except AttributeError:
        raise FitError(f"cannot fit a {kind}: expected a table or a set of samples") from None
    if values.ndim == 1:
        values = values[:, None]
    sigma = getattr(data, "sigma", None)
    sigma = None if sigma is None else np.asarray(sigma, dtype=np.float64)
    if sigma is not None and meta.get("sigma_correlated"):
        # a prior reconstruction's sigma comes from a few coefficients: correlated across
        # cells, so it cannot weight a chi-square of independent residuals
        sigma = None
        source["sigma_ignored"] = SIGMA_CORRELATED_NOTE
    if sigma is not None and sigma.ndim == 1:
        sigma = sigma[:, None]
    weights = getattr(data, "weights", None)
    n_in = values.shape[0]
    weights = np.ones(n_in) if weights is None else np.asarray(weights, dtype=np.float64)
    if wi.shape != (n_in, 3) or wo.shape != (n_in, 3) or weights.shape != (n_in,):
        raise FitError(
            f"inconsistent sample shapes: wi {wi.shape}, wo {wo.shape}, values {values.shape}, "
            f"weights {weights.shape}"
        )
    if sigma is not None and sigma.shape != values.shape:
        if sigma.shape[1:] == (1,):
            sigma = np.broadcast_to(sigma, values.shape).copy()
        else:
            raise FitError(f"sigma shape {sigma.shape} does not match values {values.shape}")
    if isinstance(data, FitData):
        names = data.channel_names
        source = {**data.source, **source}
    else:
        names = _channel_names(getattr(data, "channels", None), values.shape[1])

    with np.errstate(invalid="ignore", divide="ignore"):
        wi = wi / np.linalg.norm(wi, axis=-1, keepdims=True)
        wo = wo / np.linalg.norm(wo, axis=-1, keepdims=True)
    valid = np.isfinite(values).all(axis=1) & np.isfinite(weights) & (weights > 0)
    valid &= np.isfinite(wi).all(axis=1) & np.isfinite(wo).all(axis=1)
    if sigma is not None:
        valid &= (np.isfinite(sigma) & (sigma > 0)).all(axis=1)
    cos_max = math.cos(math.radians(float(theta_max_deg)))
    # a small tolerance so that samples exactly at the cutoff (80.0 deg) are kept
    inside = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    inside &= (wi[:, 2] >= cos_max - 1e-12) & (wo[:, 2] >= cos_max - 1e-12)
    keep = valid & inside
    source.update(
        n_input=int(n_in),
        n_invalid=int((~valid).sum()),
        n_beyond_cutoff=int((valid & ~inside).sum()),
        n_used=int(keep.sum()),
        theta_max_deg=float(theta_max_deg),
    )
    if not keep.any():
        raise FitError(
            f"no usable samples: {n_in} in, {source['n_invalid']} invalid (NaN/Inf/sigma<=0), "
            f"{source['n_beyond_cutoff']} beyond theta_max={theta_max_deg:g} deg or below horizon"
        )
    return FitData(
        wi=np.ascontiguousarray(wi[keep]),
        wo=np.ascontiguousarray(wo[keep]),
        values=np.ascontiguousarray(values[keep]),
        sigma=None if sigma is None else np.ascontiguousarray(sigma[keep]),
        weights=np.ascontiguousarray(weights[keep]),
        channel_names=names,
        source=source,
    )


@dataclass(frozen=True)
class _TableSamples:
    """A table's valid nodes as flat arrays (what ``to_samples`` gives, without building and
    re-validating a :class:`~gonio.brdf.measured.MeasuredSamples`: :func:`prepare` checks them)."""

    wi: np.ndarray
    wo: np.ndarray
    values: np.ndarray
    sigma: np.ndarray | None
    weights: np.ndarray
    channels: Any


def _table_samples(table: Any) -> _TableSamples:
    """The nodes of a :class:`~gonio.brdf.tabulated.TabulatedBRDF` that
    :meth:`~gonio.brdf.measured.MeasuredSamples.from_table` keeps (valid, both directions above
    the horizon), weighted by their cell measure (sr^2)."""
    return _TableSamples(*table.valid_nodes(), table.channels)


def _channel_names(channels: Any, c: int) -> tuple[str, ...]:
    names = getattr(channels, "names", None)
    if names is not None and len(names) == c:
        return tuple(str(n) for n in names)
    if c == 3:
        return ("R", "G", "B")
    if c == 1:
        return ("Y",)
    return tuple(f"c{i}" for i in range(c))


def from_arrays(
    wi: Any,
    wo: Any,
    values: Any,
    sigma: Any = None,
    weights: Any = None,
    channel_names: tuple[str, ...] | None = None,
    theta_max_deg: float = DEFAULT_THETA_MAX_DEG,
    name: str = "arrays",
) -> FitData:
    """Build :class:`FitData` from plain arrays (same validation as :func:`prepare`)."""
    values = np.asarray(values, dtype=np.float64)
    if values.ndim == 1:
        values = values[:, None]
    raw = FitData(
        np.asarray(wi, dtype=np.float64),
        np.asarray(wo, dtype=np.float64),
        values,
        None if sigma is None else np.asarray(sigma, dtype=np.float64),
        np.ones(values.shape[0]) if weights is None else np.asarray(weights, dtype=np.float64),
        channel_names or _channel_names(None, values.shape[1]),
        {"kind": "arrays", "name": name},
    )
    return prepare(raw, theta_max_deg)
