"""MERL ``.binary`` isotropic BRDF tables (Matusik et al. 2003): exact read and write.

Layout (little-endian): three int32 dimensions ``(n_theta_h, n_theta_d, n_phi_d)`` = (90, 90, 180),
then three blocks of ``n`` float64 values (all red, then all green, then all blue), cell index
``i_phi_d + n_phi_d * (i_theta_d + n_theta_d * i_theta_h)``. The stored numbers are scaled: the
BRDF in 1/sr is ``stored * scale`` with scales (1/1500, 1.15/1500, 1.66/1500) for (R, G, B).
Negative values mark cells that were not measured (below the horizon); they become invalid cells.

Cells and lookups
-----------------
Cell ``i`` of each axis spans the warped index ``[i, i + 1)`` of the reference reader
(BRDFRead.cpp): ``floor(sqrt(theta_h / (pi/2)) * 90)``, ``floor(theta_d / (pi/2) * 90)`` and
``floor(phi_d / pi * 180)`` with ``phi_d += pi`` where negative (reciprocity), each clamped to
the grid. Its edges are ``theta_h = (i / 90)^2 pi/2``, ``theta_d = i / 90 * pi/2``,
``phi_d = i / 180 * pi``.

By default (``cells="centre"``) a cell's node, the position that stands for it wherever cells are
used as sample positions (fitting, conversion, plots, resampling on write), is its centre in the
warped index: ``theta_h = ((i + 1/2) / 90)^2 pi/2``, ``theta_d = (i + 1/2) / 90 * pi/2``,
``phi_d = (i + 1/2) / 180 * pi`` (axes with ``node_offset = 0.5``). Then the table's nearest
lookup (``interpolation="nearest"``, the default for MERL files) returns the cell the reference
reader returns, and multilinear interpolation interpolates between cell centres.
``cells="start"`` places nodes at the cells' lower edges (``node_offset = 0``), the convention of
fastmerl and of the Neural-BRDF code, for results that must match those; its nearest lookup
rounds to the closest lower edge, which is not the reference reader's cell.

Two limits of "the reference's cell": directions within rounding of a cell edge can fall on
either side, since gonio and BRDFRead.cpp compute the half/difference angles with different
formulas (the reference's ``acos(h_z)`` is accurate to ~1e-12 rad near the pole, about 2e-9 of
the first ``theta_h`` cell's width; elsewhere the two agree far closer); and for invalid
(unmeasured) cells the reference returns the stored negative marker, where gonio's nearest
lookup returns the nearest valid node instead.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from gonio.io._common import PathLike, atomic_output, fail, read_bytes
from gonio.io._sanity import check_brdf_values

if TYPE_CHECKING:
    from gonio.brdf.tabulated import TabulatedBRDF

#: Per-channel factors: BRDF (1/sr) = stored value * scale.
MERL_SCALES = np.array([1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0])
#: MERL's resolution (theta_h, theta_d, phi_d).
MERL_DIMS = (90, 90, 180)
_HEADER = 12
#: Bounds on a file's grid, checked on its header before the data is read: at most 4 times
#: MERL's resolution along each axis (a quarter of a cell: finer than any gonioreflectometer
#: resolves) and 4 times its cells (5.8 M cells, a 140 MB file), so that what reads, converts
#: or plots a table that passes stays far under 2 GiB.
MAX_DIMS = tuple(4 * n for n in MERL_DIMS)
MAX_CELLS = 4 * math.prod(MERL_DIMS)
#: A channel negative (MERL's "not measured") at more than this share of the cells that the
#: other two channels measured is not a marker but a corrupt (negated) channel.
MAX_CHANNEL_DISAGREEMENT = 0.5


@dataclass(frozen=True)
class MerlArrays:
    """A parsed MERL file as plain arrays.

    Attributes
    ----------
    values : ndarray, float64, shape (n_theta_h, n_theta_d, n_phi_d, 3)
        BRDF in 1/sr (already multiplied by the channel scales); 0 where invalid.
    mask : ndarray, bool, shape (n_theta_h, n_theta_d, n_phi_d)
        True where all three channels were stored non-negative.
    """

    values: np.ndarray
    mask: np.ndarray


def parse_merl_bytes(data: bytes, path: PathLike = "<bytes>") -> MerlArrays:
    """Parse the bytes of a MERL ``.binary`` file (see the module docstring for the layout)."""
    if len(data) < _HEADER:
        raise fail(path, f"truncated MERL file: {len(data)} bytes, header needs {_HEADER}")
    dims = np.frombuffer(data, dtype="<i4", count=3)
    shape = tuple(int(d) for d in dims)
    if min(shape) <= 0:
        raise fail(path, f"impossible MERL dimensions {shape}")
    n = math.prod(shape)
    if any(d > m for d, m in zip(shape, MAX_DIMS, strict=True)) or n > MAX_CELLS:
        raise fail(
            path,
            f"MERL dimensions {shape} beyond the bounds of a measured grid: at most "
            f"{MAX_DIMS} cells per axis and {MAX_CELLS} in all (4 times MERL's {MERL_DIMS})",
        )
    expected = _HEADER + 3 * 8 * n
    if len(data) != expected:
        what = "truncated" if len(data) < expected else "trailing bytes in"
        raise fail(
            path,
            f"{what} MERL file: {len(data)} bytes, dimensions {tuple(int(d) for d in dims)} "
            f"need {expected}",
        )
    raw = np.frombuffer(data, dtype="<f8", offset=_HEADER, count=3 * n).reshape(3, *dims)
    if not np.all(np.isfinite(raw)):
        bad = int(np.count_nonzero(~np.isfinite(raw)))
        raise fail(path, f"{bad} non-finite (NaN/Inf) values in MERL data")
    values = np.moveaxis(raw, 0, -1) * MERL_SCALES
    measured = raw >= 0.0
    mask = np.all(measured, axis=0)
    _check_channels_agree(measured, path)
    values = np.where(mask[..., None], values, 0.0)
    # no valid cell, or values no reflectance reaches (they would also overflow float32)
    check_brdf_values(path, "MERL values", values, mask)
    return MerlArrays(values=values, mask=mask)


def _check_channels_agree(measured: np.ndarray, path: PathLike) -> None:
    """Refuse a channel that is negative ("not measured") at most of the cells the other two
    channels measured (:data:`MAX_CHANNEL_DISAGREEMENT`): MERL marks a cell unmeasured in
    all three channels; a whole channel of markers is a negated channel, not a measurement.

    ``measured``: ``(3, ...)`` bool, the stored values >= 0 per channel."""
    for c, name in enumerate("RGB"):
        others = np.all(np.delete(measured, c, axis=0), axis=0)
        n_others = int(np.count_nonzero(others))
        n_bad = int(np.count_nonzero(others & ~measured[c]))
        if n_others and n_bad > MAX_CHANNEL_DISAGREEMENT * n_others:
            raise fail(
                path,
                f"MERL channel {name} is negative at {n_bad} of the {n_others} cells the other "
                "channels measured (negative values mark unmeasured cells: a corrupt channel)",
            )


def read_merl_arrays(path: PathLike) -> MerlArrays:
    """Read a MERL ``.binary`` file into plain arrays (no table object)."""
    return parse_merl_bytes(read_bytes(path, _HEADER + 3 * 8 * MAX_CELLS), path)


#: Node offset of each cell convention (see the module docstring).
CELL_CONVENTIONS = {"centre": 0.5, "start": 0.0}


def _node_offset(cells: str) -> float:
    if cells not in CELL_CONVENTIONS:
        from gonio.errors import ParameterError

        raise ParameterError(f"cells must be 'centre' or 'start', got {cells!r}")
    return CELL_CONVENTIONS[cells]


def merl_axes(
    dims: tuple[int, int, int] = MERL_DIMS, cells: str = "centre"
) -> tuple[Any, Any, Any]:
    """The ``(theta_h, theta_d, phi_d)`` axes of a MERL file of resolution ``dims``, with nodes
    at the cell centres (``cells="centre"``) or lower edges (``"start"``) in the warped index."""
    from gonio.brdf.tabulated import Axis

    half_pi = math.pi / 2
    off = _node_offset(cells)
    return (
        Axis("theta_h", int(dims[0]), 0.0, half_pi, "sqrt", False, off),
        Axis("theta_d", int(dims[1]), 0.0, half_pi, "linear", False, off),
        Axis("phi_d", int(dims[2]), 0.0, math.pi, "linear", True, off),
    )


def read_merl(path: PathLike, cells: str = "centre") -> TabulatedBRDF:
    """Read a MERL ``.binary`` file as a ``half_diff_iso`` :class:`TabulatedBRDF` (RGB, 1/sr),
    nodes at the cell centres (default) or, with ``cells="start"``, at their lower edges (see
    the module docstring)."""
    from gonio.brdf.tabulated import Channels, TabulatedBRDF

    axes = merl_axes(MERL_DIMS, cells)  # checks ``cells`` before reading
    arrays = read_merl_arrays(path)
    return TabulatedBRDF(
        values=arrays.values.astype(np.float32),
        axes=merl_axes(arrays.mask.shape, cells) if arrays.mask.shape != MERL_DIMS else axes,
        parameterization="half_diff_iso",
        mask=arrays.mask,
        sigma=None,
        counts=None,
        channels=Channels.rgb(),
        meta={"source": {"format": "merl", "file": str(path), "cells": cells}},
        interpolation="nearest",
    )


def merl_bytes(values: np.ndarray, mask: np.ndarray | None = None) -> bytes:
    """Encode a ``(n_theta_h, n_theta_d, n_phi_d, 3)`` RGB array in 1/sr as MERL file bytes.

    Invalid cells (``mask`` False) and non-finite values are written as -1 (MERL's marker).
    """
    values = np.asarray(values, dtype=np.float64)
    if values.ndim != 4 or values.shape[-1] != 3:
        raise ValueError(f"MERL needs an RGB half/diff grid (n1, n2, n3, 3), got {values.shape}")
    stored = values / MERL_SCALES
    bad = ~np.all(np.isfinite(stored), axis=-1)
    if mask is not None:
        bad |= ~np.asarray(mask, dtype=bool)
    stored = np.where(bad[..., None], -1.0, stored)
    header = np.asarray(values.shape[:3], dtype="<i4").tobytes()
    return header + np.ascontiguousarray(np.moveaxis(stored, -1, 0), dtype="<f8").tobytes()


def _on_merl_grid(table: TabulatedBRDF) -> bool:
    if table.parameterization != "half_diff_iso" or len(table.axes) != 3:
        return False
    want = merl_axes(tuple(a.size for a in table.axes))
    for a, b in zip(table.axes, want, strict=True):
        same = (a.size, a.warp, a.periodic) == (b.size, b.warp, b.periodic)
        # either node convention names the same cells
        close = np.allclose([a.lo, a.hi], [b.lo, b.hi]) and a.node_offset in (0.0, 0.5)
        if not (same and close):
            return False
    return True


def write_merl(table: Any, path: PathLike) -> None:
    """Write an RGB table as a MERL ``.binary`` file, atomically.

    A table already on MERL's 90 x 90 x 180 half/diff grid is written cell for cell; anything
    else (another grid, a MERL-like grid of another resolution, an anisotropic table, an analytic
    model with ``f``) is resampled by evaluating ``table.f`` at the MERL cell centres: MERL's
    reference reader accepts no other dimensions (gonio reads them). Invalid cells are written
    as -1. The bytes pass the reader's checks (:func:`parse_merl_bytes`) before anything is
    written: a table the reader would refuse (a value beyond 1e10 1/sr, no valid cell, a
    channel negative where the others are measured) is a FormatError naming ``path``.
    """
    from gonio.brdf import frames
    from gonio.brdf.measured import MeasuredSamples
    from gonio.brdf.tabulated import TabulatedBRDF

    n_channels = table.n_channels
    if n_channels not in (1, 3):
        raise fail(path, f"MERL stores RGB only; this table has {n_channels} channels")
    if isinstance(table, MeasuredSamples):
        from gonio.errors import ParameterError

        raise ParameterError(
            f"{os.fspath(path)}: scattered samples cannot be written as MERL (grid them first)"
        )
    on_grid = isinstance(table, TabulatedBRDF) and _on_merl_grid(table)
    if on_grid and table.shape[:3] == MERL_DIMS:
        values = np.asarray(table.values, dtype=np.float64)
        mask = None if table.mask is None else np.asarray(table.mask, dtype=bool)
    else:
        th, td, pd = (np.asarray(a.nodes(), dtype=np.float64) for a in merl_axes())
        grid = np.meshgrid(th, td, pd, indexing="ij")
        wi, wo = frames.half_diff_to_directions(grid[0], np.zeros_like(grid[0]), grid[1], grid[2])
        wi, wo = np.asarray(wi), np.asarray(wo)
        values = np.asarray(table.f(wi, wo), dtype=np.float64)
        mask = (wi[..., 2] > 0) & (wo[..., 2] > 0)
    if values.shape[-1] == 1:
        values = np.repeat(values, 3, axis=-1)
    data = merl_bytes(values, mask)
    parse_merl_bytes(data, path)  # the reader's checks: never write a file it refuses
    with atomic_output(path) as tmp:
        tmp.write_bytes(data)
