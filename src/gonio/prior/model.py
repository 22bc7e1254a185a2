"""The material prior: a mean and a low-rank basis in the mapped space, and what samples see of it.

A material's mapped table ``m`` (``(V, C)`` over the V valid cells of the grid, see
:mod:`gonio.prior.space`) is modelled as

    m = mean + B c + r,   c ~ N(0, diag(variances)),   r ~ N(0, diag(residual_var)),

with ``B`` the ``(V·C, K)`` orthonormal basis. A sample at ``(wi, wo)`` with channel values
``y`` (mapped) sees ``y = a·mean + (a B) c + a·r + noise``, ``a`` the multilinear interpolation
weights of :func:`gonio.prior.space.interpolation_weights`. Posterior, reconstruction and the
choice of configurations are in :mod:`gonio.prior.posterior` and :mod:`gonio.prior.design`;
:class:`Prior` is their one entry point.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from gonio.brdf.grid import Axis, Channels
from gonio.errors import ParameterError
from gonio.prior import space

if TYPE_CHECKING:
    from gonio.prior.posterior import Measured, Reconstruction


@dataclass(frozen=True)
class Observation:
    """What a set of samples sees of the prior.

    Attributes
    ----------
    design : ``(n, C, K)`` rows of the linear model, one per sample and channel.
    offset : ``(n, C)`` the mean's value at each sample (mapped space).
    residual_var : ``(n, C)`` the basis's residual variance at each sample.
    cc : ``(n,)`` ``cos θi · cos θo`` of each sample.
    usable : ``(n,)`` bool: both directions above the horizon and at least one valid corner.
    """

    design: np.ndarray
    offset: np.ndarray
    residual_var: np.ndarray
    cc: np.ndarray
    usable: np.ndarray


@dataclass(frozen=True, eq=False)
class Prior:
    """A material prior (module docstring); read one with :meth:`read`, build one with
    :func:`gonio.prior.build_prior`.

    Attributes
    ----------
    axes : the (θh, θd, φd) grid (:func:`gonio.prior.space.prior_axes`).
    mask : grid-shaped bool, the V valid cells.
    mean : ``(V, C)`` float64, mapped space.
    basis : ``(V, C, K)`` float32, orthonormal columns.
    variances : ``(K,)`` prior variance of each coefficient.
    residual_var : ``(V, C)`` variance of what the basis leaves out, per cell and channel.
    channels : the channels the prior's materials have (C of them).
    epsilon : ε of the mapped space, sr⁻¹.
    meta : the file's metadata (materials, rank selection, build).
    """

    axes: tuple[Axis, ...]
    mask: np.ndarray
    mean: np.ndarray
    basis: np.ndarray
    variances: np.ndarray
    residual_var: np.ndarray
    channels: Channels
    epsilon: float = space.EPSILON
    meta: dict[str, Any] = field(default_factory=dict)

    # -- shape --------------------------------------------------------------------------------
    @property
    def rank(self) -> int:
        """K, the number of basis vectors."""
        return int(self.basis.shape[-1])

    @property
    def n_channels(self) -> int:
        """C."""
        return int(self.mean.shape[1])

    @property
    def n_valid(self) -> int:
        """V, the number of valid cells."""
        return int(self.mean.shape[0])

    # -- files --------------------------------------------------------------------------------
    @classmethod
    def read(cls, path: str | os.PathLike[str]) -> Prior:
        """Read a ``*.prior.h5`` file (:mod:`gonio.io.prior_file`); one-line FormatError on a
        bad file."""
        from gonio.io.prior_file import read_prior_file

        meta, arrays = read_prior_file(path)
        axes = tuple(Axis.from_dict(a) for a in meta["grid"]["axes"])
        ch = meta["channels"]
        channels = Channels.from_dict(
            {"primaries": None, "white_point": None, "wavelengths_nm": None, **ch}
        )
        return cls(
            axes=axes,
            mask=np.asarray(arrays["mask"]).astype(bool),
            mean=np.asarray(arrays["mean"], np.float64),
            basis=np.asarray(arrays["basis"], np.float32),
            variances=np.asarray(arrays["variances"], np.float64),
            residual_var=np.asarray(arrays["residual_var"], np.float64),
            channels=channels,
            epsilon=float(meta["space"]["epsilon"]),
            meta={**meta, "path": os.fspath(path)},
        )

    def write(self, path: str | os.PathLike[str]) -> None:
        """Write the prior atomically as a ``*.prior.h5`` file."""
        from gonio.io.prior_file import write_prior_file

        keep = {
            k: v
            for k, v in self.meta.items()
            if k not in ("format", "format_version", "software", "created_utc", "path")
        }
        meta = {
            **keep,
            "space": {
                "name": space.SPACE,
                "epsilon": self.epsilon,
                "formula": "m = log(f cos(theta_i) cos(theta_o) + epsilon), f in 1/sr",
            },
            "grid": {
                "parameterization": "half_diff_iso",
                "axes": [a.to_dict() for a in self.axes],
            },
            "channels": self.channels.to_dict(),
            "rank": self.rank,
            "n_valid": self.n_valid,
            "materials": list(self.meta.get("materials", [])),
            "residual": self.meta.get("residual", {"kind": "per_cell", "floor": 0.0}),
        }
        arrays = {
            "mask": self.mask,
            "mean": self.mean,
            "basis": self.basis,
            "variances": self.variances,
            "residual_var": self.residual_var,
        }
        write_prior_file(path, arrays, meta)

    # -- the linear model ---------------------------------------------------------------------
    def cell_directions(self) -> tuple[np.ndarray, np.ndarray]:
        """``(wi, wo)``, each ``(V, 3)``, of the valid cells' nodes."""
        wi, wo = space.grid_directions(self.axes)
        keep = self.mask.reshape(-1)
        return wi[keep], wo[keep]

    def valid_index(self) -> np.ndarray:
        """``(n_cells,)`` int64: a grid cell's row in the valid-cell arrays, -1 if invalid."""
        flat = self.mask.reshape(-1)
        out = np.full(flat.size, -1, np.int64)
        out[flat] = np.arange(int(flat.sum()))
        return out

    def observe(self, wi: Any, wo: Any) -> Observation:
        """The rows of the linear model for samples at ``(wi, wo)`` (``(n, 3)`` unit vectors,
        local frame); see :class:`Observation`."""
        wi, wo = _directions(wi, wo)
        cells, weights = space.interpolation_weights(self.axes, self.mask, wi, wo)
        rows = self.valid_index()[cells]  # -1 where a corner is invalid (its weight is 0)
        rows = np.where(rows < 0, 0, rows)
        C, K = self.n_channels, self.rank
        n = wi.shape[0]
        design = np.zeros((n, C, K))
        offset = np.zeros((n, C))
        res = np.zeros((n, C))
        for k in range(rows.shape[1]):
            w = weights[:, k]
            r = rows[:, k]
            design += w[:, None, None] * self.basis[r]
            offset += w[:, None] * self.mean[r]
            res += w[:, None] * self.residual_var[r]
        usable = weights.sum(axis=1) > 0
        return Observation(design, offset, res, space.cos_product(wi, wo), usable)

    # -- posterior, reconstruction, design ----------------------------------------------------
    def reconstruct(
        self, wi: Any, wo: Any, values: Any, sigma: Any = None, *, meta: dict | None = None
    ) -> Reconstruction:
        """The full table from samples: posterior of the coefficients, mapped back.

        Parameters
        ----------
        wi, wo : ``(n, 3)`` unit vectors in the sample's local frame.
        values : ``(n, C)`` measured BRDF in sr⁻¹ (C = :attr:`n_channels`).
        sigma : ``(n, C)`` one standard deviation of each value in sr⁻¹, or None (then only
            the prior's residual variance is the noise: noiseless samples).
        meta : provenance merged into the table's metadata.

        Returns
        -------
        :class:`gonio.prior.posterior.Reconstruction`
        """
        from gonio.prior.posterior import reconstruct

        return reconstruct(self, wi, wo, values, sigma, meta=meta)

    def choose(
        self, candidates_wi: Any, candidates_wo: Any, count: int, measured: Measured = None
    ) -> np.ndarray:
        """Indices of ``count`` candidate configurations that best determine the coefficients
        after what is ``measured`` (greedy, deterministic; :func:`gonio.prior.design.choose`)."""
        from gonio.prior.design import choose

        return choose(self, candidates_wi, candidates_wo, count, measured)

    def variance_reduction(
        self, candidates_wi: Any, candidates_wo: Any, measured: Measured = None
    ) -> np.ndarray:
        """``(n_candidates,)``: how much measuring each candidate alone would lower the mean
        posterior variance of the mapped table over valid cells and channels
        (:func:`gonio.prior.design.variance_reduction`)."""
        from gonio.prior.design import variance_reduction

        return variance_reduction(self, candidates_wi, candidates_wo, measured)

    def predicted_error(self, measured: Measured = None) -> float:
        """Expected mean absolute error in the mapped space over the valid cells and channels
        after ``measured`` (None: before any sample), from the posterior covariance alone
        (:func:`gonio.prior.posterior.predicted_error`)."""
        from gonio.prior.posterior import covariance_after, predicted_error

        return predicted_error(self, covariance_after(self, measured))


def _directions(wi: Any, wo: Any) -> tuple[np.ndarray, np.ndarray]:
    wi = np.asarray(wi, dtype=np.float64)
    wo = np.asarray(wo, dtype=np.float64)
    if wi.ndim != 2 or wi.shape[1] != 3 or wo.shape != wi.shape:
        raise ParameterError(f"wi and wo must both be (n, 3), got {wi.shape} and {wo.shape}")
    if not (np.isfinite(wi).all() and np.isfinite(wo).all()):
        raise ParameterError("wi and wo must be finite")
    with np.errstate(invalid="ignore", divide="ignore"):
        wi = wi / np.linalg.norm(wi, axis=1, keepdims=True)
        wo = wo / np.linalg.norm(wo, axis=1, keepdims=True)
    return np.nan_to_num(wi), np.nan_to_num(wo)
