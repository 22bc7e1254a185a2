"""Plots of BRDFs without fitting: polar and in-plane slices, theta_h-theta_d maps.

Every input (a measured file or a fitted model) is evaluated through the same ``f(wi, wo)``:
measured files go through :func:`gonio.render.measured.renderable` (scattered samples by the
log-linear Delaunay interpolant, spectral data as linear sRGB under D65), so curves of a
measurement and of its fit share their axes. Colour data is plotted as one channel: luminance
``Y = 0.2126 R + 0.7152 G + 0.0722 B`` of linear sRGB by default, or one of R, G, B.

Geometry (local frame, z the normal): the light is in the x-z plane at polar angle
``theta_i`` (``wi = (sin theta_i, 0, cos theta_i)``); in-plane views are
``wo = (-sin theta_o, 0, cos theta_o)`` for a signed ``theta_o`` in (-90, 90) degrees, so that
``theta_o = theta_i`` is the mirror direction and negative angles are on the light's side
(backscattering). The theta_h-theta_d map is at one ``phi_d`` (Rusinkiewicz angles; 90 degrees
by default, where ``theta_h`` and ``theta_d`` are most independent).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

LUMA = np.array([0.2126, 0.7152, 0.0722])
CHANNELS = ("Y", "R", "G", "B")


@dataclass
class PlotInput:
    """One curve set: a label, a material with ``f(wi, wo)`` and whether it is measured.

    ``samples`` are the raw scattered measurements (wi, wo, values) when the input had them,
    drawn as points on the in-plane slice near the plane.
    """

    label: str
    material: Any
    measured: bool
    samples: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None


def channel_values(values: np.ndarray, channel: str) -> np.ndarray:
    """One channel of ``(..., C)`` values (C = 1 or 3): luminance ``Y``, or ``R``, ``G``, ``B``."""
    v = np.asarray(values, dtype=np.float64)
    if v.shape[-1] == 1:
        return v[..., 0]
    if v.shape[-1] != 3:
        raise ValueError(f"plots take 1 or 3 channels, got {v.shape[-1]}")
    if channel == "Y":
        return v @ LUMA
    return v[..., "RGB".index(channel)]


def evaluate(material: Any, wi: np.ndarray, wo: np.ndarray, channel: str) -> np.ndarray:
    """``f`` (1/sr) of one channel at direction pairs ``(..., 3)``."""
    return channel_values(np.asarray(material.f(wi, wo)), channel)


def in_plane(theta_i_deg: float, theta_o_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Direction pairs of the in-plane slice (module docstring), shapes ``(n, 3)``."""
    ti = math.radians(theta_i_deg)
    to = np.radians(np.asarray(theta_o_deg, dtype=float))
    wi = np.broadcast_to([math.sin(ti), 0.0, math.cos(ti)], (to.size, 3)).copy()
    wo = np.stack([-np.sin(to), np.zeros_like(to), np.cos(to)], -1)
    return wi, wo


def half_diff_grid(n: int, phi_d_deg: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(theta_h, theta_d)`` node angles in degrees (n,) and direction pairs ``(n, n, 3)`` x 2
    (rows theta_d, columns theta_h) at ``phi_d``; pairs below the horizon are NaN."""
    from gonio.brdf import frames

    deg = (np.arange(n) + 0.5) * 90.0 / n
    th, td = np.meshgrid(np.radians(deg), np.radians(deg))
    wi, wo = frames.half_diff_to_directions(
        th, np.zeros_like(th), td, np.full_like(th, math.radians(phi_d_deg))
    )
    wi, wo = np.asarray(wi, dtype=np.float64), np.asarray(wo, dtype=np.float64)
    return deg, wi, wo


def near_plane(
    wi: np.ndarray, wo: np.ndarray, theta_i_deg: float, tol_deg: float
) -> tuple[np.ndarray, np.ndarray]:
    """``(sel, signed)``: which direction pairs ``(N, 3)`` lie within ``tol_deg`` of the in-plane
    slice at ``theta_i`` (isotropic: only the relative azimuth matters), ``(N,)`` bool, and
    their signed theta_o in degrees (positive toward the mirror direction), ``(sel.sum(),)``."""
    ti = np.degrees(np.arccos(np.clip(wi[:, 2], -1, 1)))
    to = np.degrees(np.arccos(np.clip(wo[:, 2], -1, 1)))
    dphi = np.degrees(np.abs(np.angle(np.exp(1j * (np.arctan2(wo[:, 1], wo[:, 0]) -
                                                   np.arctan2(wi[:, 1], wi[:, 0]))))))  # fmt: skip
    # Opposite azimuths (dphi ~ 180) are the mirror side, equal azimuths the light's side.
    mirror = np.abs(dphi - 180.0) <= tol_deg / max(math.sin(math.radians(max(to.min(), 1))), 0.1)
    back = dphi <= tol_deg
    near = np.abs(ti - theta_i_deg) <= tol_deg
    sel = near & (mirror | back)
    return sel, np.where(mirror, to, -to)[sel]


def _samples_near_plane(
    s: tuple[np.ndarray, np.ndarray, np.ndarray], theta_i_deg: float, tol_deg: float, channel: str
) -> tuple[np.ndarray, np.ndarray]:
    """Signed theta_o (deg) and f of measured samples near the slice (:func:`near_plane`)."""
    wi, wo, v = s
    sel, signed = near_plane(wi, wo, theta_i_deg, tol_deg)
    return signed, channel_values(v[sel], channel)


def plot_materials(
    inputs: Sequence[PlotInput],
    out: str | Path,
    *,
    theta_i_deg: Sequence[float] = (0.0, 30.0, 60.0),
    phi_d_deg: float = 90.0,
    channel: str = "Y",
    kinds: Sequence[str] = ("polar", "in-plane", "halfdiff"),
    n: int = 181,
) -> Path:
    """Write :func:`materials_figure`; ``out``'s extension picks the format (.png, .svg, .pdf)."""
    import matplotlib.pyplot as plt

    out = Path(out)
    fig = materials_figure(
        inputs, theta_i_deg=theta_i_deg, phi_d_deg=phi_d_deg, channel=channel, kinds=kinds, n=n
    )
    from gonio.io.atomic import atomic_output

    try:
        with atomic_output(out, out.suffix, make_parents=True) as tmp:
            fig.savefig(tmp, dpi=120, format=out.suffix.lstrip(".").lower())
    finally:
        plt.close(fig)
    return out


def _panel_axes(fig: Any, n_top: int, n_map: int) -> tuple[list[Any], list[Any]]:
    """Grid slots for the slice panels and the maps, with no empty slot: one row when there are
    at most four panels, else the slices on a first row and the maps on a second."""
    if n_top + n_map <= 4:
        grid = fig.add_gridspec(1, n_top + n_map)
        slots = [grid[0, k] for k in range(n_top + n_map)]
        return slots[:n_top], slots[n_top:]
    rows = [r for r in (n_top, n_map) if r]
    subs = fig.subfigures(len(rows), 1) if len(rows) > 1 else [fig]
    out = []
    for sub, count in zip(subs, rows, strict=True):
        grid = sub.add_gridspec(1, count)
        out.append([(sub, grid[0, k]) for k in range(count)])
    top = out[0] if n_top else []
    return top, (out[-1] if n_map else [])


def _add(fig: Any, slot: Any, **kwargs: Any) -> Any:
    if isinstance(slot, tuple):
        return slot[0].add_subplot(slot[1], **kwargs)
    return fig.add_subplot(slot, **kwargs)


def materials_figure(
    inputs: Sequence[PlotInput],
    *,
    theta_i_deg: Sequence[float] = (0.0, 30.0, 60.0),
    phi_d_deg: float = 90.0,
    channel: str = "Y",
    kinds: Sequence[str] = ("polar", "in-plane", "halfdiff"),
    n: int = 181,
) -> Any:
    """The figure: polar (logarithmic radius: glossy data spans decades) and in-plane slices of
    every input on shared axes (colour per ``theta_i``, line style per input), and one
    theta_h-theta_d map per input (theta_h horizontal) with a shared colour scale; every panel
    holds data (no empty grid slot)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter

    styles = ["-", "--", ":", "-."]
    slices = [k for k in kinds if k in ("polar", "in-plane")]
    maps = "halfdiff" in kinds
    n_top = len(slices)
    n_map = len(inputs) if maps else 0
    one_row = n_top + n_map <= 4
    cols = n_top + n_map if one_row else max(n_top, n_map, 1)
    rows = 1 if one_row else int(n_top > 0) + int(n_map > 0)
    fig = plt.figure(figsize=(5.6 * max(cols, 1), 5.6 * rows), constrained_layout=True)
    top_slots, map_slots = _panel_axes(fig, n_top, n_map)
    cmap = plt.get_cmap("viridis")
    ti_colors = {t: cmap(i / max(len(theta_i_deg) - 1, 1) * 0.85) for i, t in
                 enumerate(theta_i_deg)}  # fmt: skip
    theta_o = np.linspace(-89.5, 89.5, n)
    curves = {}
    for inp in inputs:
        for t in theta_i_deg:
            wi, wo = in_plane(t, theta_o)
            curves[inp.label, t] = evaluate(inp.material, wi, wo, channel)
    unit = f"f, {'luminance Y' if channel == 'Y' else channel + ' channel'} (1/sr)"
    positive = np.concatenate([c[c > 0] for c in curves.values()] or [np.ones(1)])
    r_hi = float(positive.max()) * 1.5 if positive.size else 1.0
    r_lo = max(float(positive.min()) / 1.5 if positive.size else 1e-3, r_hi * 1e-5)
    for col, kind in enumerate(slices):
        polar = kind == "polar"
        ax = _add(fig, top_slots[col], projection="polar" if polar else None)
        for k, inp in enumerate(inputs):
            for t in theta_i_deg:
                y = curves[inp.label, t]
                label = f"{inp.label}, θi = {t:g}°"
                ls = styles[k % len(styles)]
                if polar:
                    ax.plot(np.radians(theta_o), np.where(y > 0, y, np.nan), ls,
                            color=ti_colors[t], label=label)  # fmt: skip
                else:
                    ax.semilogy(theta_o, np.maximum(y, 1e-6), ls, color=ti_colors[t],
                                label=label)  # fmt: skip
                    if inp.samples is not None:
                        xs, ys = _samples_near_plane(inp.samples, t, 2.5, channel)
                        if xs.size:
                            ax.plot(xs, np.maximum(ys, 1e-6), "o", ms=3.5, mfc="none",
                                    color=ti_colors[t], label=f"{inp.label} samples")  # fmt: skip
        if polar:
            ax.set_theta_zero_location("N")
            ax.set_theta_direction(-1)
            ax.set_thetamin(-90)
            ax.set_thetamax(90)
            ax.set_rscale("log")
            ax.set_rlim(r_lo, r_hi)
            ax.yaxis.set_minor_formatter(NullFormatter())
            ax.set_title("polar, plane of incidence: radius " + unit + " (log)\nangle θo (deg), "
                         "+ toward the mirror direction; light at -θi", fontsize=9)  # fmt: skip
        else:
            ax.set_xlabel("θo (deg), + toward the mirror direction, − toward the light")
            ax.set_ylabel(unit)
            ax.set_xlim(-90, 90)
            ax.grid(True, which="both", alpha=0.3)
            ax.set_title("in-plane slice (light in the x-z plane at θi)", fontsize=9)
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=2)
    if maps:
        _, wi, wo = half_diff_grid(90, phi_d_deg)
        ok = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        images = []
        for inp in inputs:
            v = evaluate(inp.material, wi.reshape(-1, 3), wo.reshape(-1, 3), channel)
            v = v.reshape(ok.shape)
            images.append(np.where(ok & (v > 0), np.log10(np.maximum(v, 1e-12)), np.nan))
        finite = np.concatenate([im[np.isfinite(im)] for im in images])
        lo, hi = np.percentile(finite, [1, 99.9]) if finite.size else (-3, 1)
        for k, (inp, im) in enumerate(zip(inputs, images, strict=True)):
            ax = _add(fig, map_slots[k])
            h = ax.imshow(im, origin="lower", extent=(0, 90, 0, 90), vmin=lo, vmax=hi,
                          cmap="magma", aspect="equal")  # fmt: skip
            ax.set_xlabel("θh (deg)")
            ax.set_ylabel("θd (deg)")
            ax.set_title(f"{inp.label}: θh–θd at φd = {phi_d_deg:g}°", fontsize=9)
            fig.colorbar(h, ax=ax, label=f"log10 {unit}", shrink=0.85)
    return fig
