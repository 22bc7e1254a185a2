"""Tabulation of an RGL tensor file on a half/diff grid (the one place where it is resampled).

:meth:`gonio.io.rgl_measured.RGLMeasured.to_table` calls :func:`tabulate`: every node of the grid
is evaluated with the file's exact ``f`` (in float64) and stored as a float32
:class:`~gonio.brdf.tabulated.TabulatedBRDF`. ``gonio convert`` (RGL to MERL, native, EXR) and the
simulated rig's ground truth (:mod:`gonio.rigs.sim.truth`) read RGL files through it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from gonio.io._sanity import check_brdf_values
from gonio.io.rgl import HORIZON_MIN_COS


def default_axes(isotropic: bool) -> tuple[Any, ...]:
    """MERL's 90 x 90 x 180 half/diff grid for isotropic files; for anisotropic ones
    ``(theta_h 45, phi_h 90 over 2 pi, theta_d 45, phi_d 180 over 2 pi)``."""
    from gonio.brdf.tabulated import Axis
    from gonio.io.merl import merl_axes

    if isotropic:
        return merl_axes()
    th, td, _ = merl_axes((45, 45, 90))
    return (
        th,
        Axis("phi_h", 90, 0.0, 2 * math.pi, "linear", True, 0.0),
        td,
        Axis("phi_d", 180, 0.0, 2 * math.pi, "linear", True, 0.0),
    )


def tabulate(
    bsdf: Any,
    axes: tuple[Any, ...] | None = None,
    chunk: int = 1 << 16,
    progress: Callable[[int, int], None] | None = None,
    min_cos: float = HORIZON_MIN_COS,
    reciprocal: bool = False,
) -> Any:
    """Tabulate ``f_r`` of ``bsdf`` (an :class:`~gonio.io.rgl_measured.RGLMeasured`) on a
    half/diff grid as a :class:`~gonio.brdf.tabulated.TabulatedBRDF`.

    Parameters
    ----------
    bsdf : RGLMeasured
        The loaded file (its ``f``, ``isotropic``, ``channel_info``, ``path``, ``description``).
    axes : tuple of Axis, optional
        ``(theta_h, theta_d, phi_d)`` for isotropic data or ``(theta_h, phi_h, theta_d, phi_d)``
        for anisotropic data; default :func:`default_axes`.
    chunk : int
        Cells evaluated per batch (every batch has this size: one compiled program).
    progress : callable(done, total), optional
        Called after each batch (for progress bars).
    min_cos : float
        Cells whose ``wi`` or ``wo`` has ``cos(theta) < min_cos`` are marked invalid. The
        tabulated ``f_r cos(theta_o)`` does not vanish at the horizon (it is a bilinear
        interpolant), so ``f_r`` diverges like ``1 / cos(theta_o)`` in the last degree; the
        default ``cos(89 deg)`` keeps that artifact out of the table.
    reciprocal : bool
        Store the reciprocal part ``(f(wi, wo) + f(wo, wi)) / 2`` of the measurement. A measured
        table is not exactly reciprocal (the acrylic felt differs by ~5 % between ``phi_d`` and
        ``phi_d + pi``), but an isotropic half/diff table folds ``phi_d`` by reciprocity: taken
        from one half only, its periodic wrap joins ``f(phi_d -> pi)`` to ``f(0)``, a one-cell
        ramp (a slope discontinuity) on the plane of incidence, where in-plane geometries sit.
        The average makes the folded table continuous there. Ignored for anisotropic axes
        (``phi_d`` over ``2 pi`` is not folded).

    Returns
    -------
    TabulatedBRDF
        ``values`` float32 ``(*grid, C)``, ``mask`` the cells kept by ``min_cos``.

    Raises
    ------
    FormatError
        The tabulated values at valid cells fail the readers' checks
        (:func:`gonio.io._sanity.check_brdf_values`: NaN/Inf, beyond ``MAX_BRDF``, clearly
        negative): the file evaluates to what no table may hold.
    """
    from gonio.brdf.tabulated import TabulatedBRDF
    from gonio.io._geometry import half_diff_to_directions

    if axes is None:
        axes = default_axes(bsdf.isotropic)
    nodes = [np.asarray(a.nodes(), dtype=np.float64) for a in axes]
    grid = np.meshgrid(*nodes, indexing="ij")
    if len(axes) == 3:
        th, td, pd = grid
        ph = np.zeros_like(th)
        param = "half_diff_iso"
    elif len(axes) == 4:
        th, ph, td, pd = grid
        param = "half_diff_aniso"
    else:
        raise ValueError("axes must be (theta_h, theta_d, phi_d) or 4 half/diff axes")
    shape = th.shape
    symmetrize = reciprocal and param == "half_diff_iso"
    flat = [a.ravel() for a in (th, ph, td, pd)]
    total = flat[0].size
    values: np.ndarray | None = None
    valid = np.zeros(total, dtype=bool)
    for start in range(0, total, chunk):
        sl = slice(start, min(start + chunk, total))
        wi, wo = half_diff_to_directions(*(a[sl] for a in flat))
        ok = (wi[..., 2] >= min_cos) & (wo[..., 2] >= min_cos)
        val = _f_padded(bsdf, wi, wo, chunk)
        if symmetrize:  # phi_d + pi is the swapped pair; ok is symmetric in (wi, wo)
            val = 0.5 * (val + _f_padded(bsdf, wo, wi, chunk))
        if values is None:
            values = np.zeros((total, val.shape[-1]), dtype=np.float32)
        values[sl] = np.where(ok[:, None], val, 0.0)
        valid[sl] = ok
        if progress is not None:
            progress(sl.stop, total)
    assert values is not None  # total > 0: every axis has nodes
    # the table must pass the checks every reader of tables applies (what convert writes loads)
    check_brdf_values(bsdf.path, "tabulated f_r", values, valid)
    return TabulatedBRDF(
        values=values.reshape(*shape, values.shape[-1]),
        axes=tuple(axes),
        parameterization=param,
        mask=valid.reshape(shape),
        sigma=None,
        counts=None,
        channels=bsdf.channel_info,
        meta={
            "source": {
                "horizon_min_cos": float(min_cos),
                "format": "rgl-tensor",
                "file": bsdf.path,
                "description": bsdf.description,
            }
        },
        interpolation="linear",
    )


def _f_padded(bsdf: Any, wi: np.ndarray, wo: np.ndarray, size: int) -> np.ndarray:
    """``bsdf.f(wi, wo)`` (float64) for ``n <= size`` pairs, evaluated as a batch of ``size``
    (padded with the normal) so that every batch reuses one compiled program."""
    n = wi.shape[0]
    if n < size:
        pad = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (size - n, 3))
        wi, wo = np.concatenate([wi, pad]), np.concatenate([wo, pad])
    return np.asarray(bsdf.f(np.asarray(wi, np.float64), np.asarray(wo, np.float64)))[:n]
