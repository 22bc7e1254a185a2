"""The page's plots as Plotly figure dictionaries (JSON-ready; drawn by Plotly's own bundle).

Geometry and channel as ``gonio plot`` (:mod:`gonio.render.plots`): in-plane slices with the light
in the x-z plane at ``theta_i`` and signed ``theta_o`` (positive toward the mirror direction);
theta_h-theta_d maps at one ``phi_d`` with theta_h on the horizontal axis; colour data as
luminance ``Y`` of linear sRGB. f is in 1/sr.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from gonio.render.plots import channel_values, evaluate, half_diff_grid, in_plane, near_plane
from gonio.view.encode import fold_of
from gonio.view.sources import Source

#: Incident angles offered by the slice and polar plots' slider (degrees).
THETA_I_DEG = (0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0)
#: phi_d offered by the theta_h-theta_d maps' slider (degrees).
PHI_D_DEG = (0.0, 30.0, 60.0, 90.0, 120.0, 150.0)
#: Half-width of the band around the plane of incidence whose samples are drawn (degrees).
PLANE_TOL_DEG = 2.5
COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2")
UNIT = "f, luminance Y (1/sr)"


def _finite(a: np.ndarray) -> list[float | None]:
    """A JSON list with NaN/inf as null (Plotly draws a gap)."""
    return [float(x) if math.isfinite(x) else None for x in np.asarray(a, np.float64).ravel()]


def _slider(n_traces: list[int], labels: Sequence[str], prefix: str, active: int) -> dict:
    """A slider showing one group of traces at a time (groups laid out one after another)."""
    total = sum(n_traces)
    steps, start = [], 0
    for n, lab in zip(n_traces, labels, strict=True):
        vis = [start <= i < start + n for i in range(total)]
        steps.append({"method": "restyle", "label": lab, "args": [{"visible": vis}]})
        start += n
    return {"active": active, "currentvalue": {"prefix": prefix}, "steps": steps, "pad": {"t": 40}}


def _visible(groups: list[list[dict]], active: int) -> list[dict]:
    out = []
    for g, traces in enumerate(groups):
        for t in traces:
            t["visible"] = g == active
            out.append(t)
    return out


def _curves(sources: list[Source], theta_o: np.ndarray) -> dict[tuple[int, float], np.ndarray]:
    """Every input's in-plane curves at every :data:`THETA_I_DEG`, one evaluation per input."""
    pairs = [in_plane(t, theta_o) for t in THETA_I_DEG]
    wi = np.concatenate([p[0] for p in pairs])
    wo = np.concatenate([p[1] for p in pairs])
    out = {}
    for k, s in enumerate(sources):
        y = evaluate(s.material, wi, wo, "Y").reshape(len(THETA_I_DEG), -1)
        for j, t in enumerate(THETA_I_DEG):
            out[k, t] = y[j]
    return out


def slices_figure(sources: list[Source], n: int = 181, active: int = 3) -> dict:
    """In-plane slices at a chosen theta_i (slider), every input's curve, a run's samples near
    the plane as points with their sigma as error bars; log or linear f (buttons)."""
    theta_o = np.linspace(-89.5, 89.5, n)
    curves = _curves(sources, theta_o)
    groups = []
    for t in THETA_I_DEG:
        traces = []
        for k, s in enumerate(sources):
            color = COLORS[k % len(COLORS)]
            y = curves[k, t]
            traces.append(
                {
                    "type": "scatter",
                    "mode": "lines",
                    "name": s.label,
                    "x": _finite(theta_o),
                    "y": _finite(np.where(y > 0, y, np.nan)),
                    "line": {"color": color, "dash": "solid" if s.measured else "dash"},
                }
            )
            if s.samples is not None:
                wi, wo, v, sig = s.samples
                sel, signed = near_plane(wi, wo, t, PLANE_TOL_DEG)
                pts = {
                    "type": "scatter",
                    "mode": "markers",
                    "name": f"{s.label}: samples",
                    "x": _finite(signed),
                    "y": _finite(channel_values(v[sel], "Y")),
                    "marker": {"color": color, "size": 6, "symbol": "circle-open"},
                }
                if sig is not None:
                    pts["error_y"] = {
                        "type": "data",
                        "array": _finite(channel_values(sig[sel], "Y")),
                        "visible": True,
                    }
                traces.append(pts)
        groups.append(traces)
    scale_buttons = [
        {"label": kind, "method": "relayout", "args": [{"yaxis.type": kind}]}
        for kind in ("log", "linear")
    ]
    return {
        "data": _visible(groups, active),
        "layout": {
            "title": {"text": "in-plane slice: light in the x-z plane at θi"},
            "xaxis": {
                "title": {"text": "θo (deg), + toward the mirror direction, − toward the light"},
                "range": [-90, 90],
            },
            "yaxis": {"title": {"text": UNIT}, "type": "log"},
            "sliders": [
                _slider([len(g) for g in groups], [f"{t:g}°" for t in THETA_I_DEG], "θi = ", active)
            ],
            "updatemenus": [
                {
                    "type": "buttons",
                    "direction": "right",
                    "x": 1.0,
                    "y": 1.15,
                    "buttons": scale_buttons,
                }
            ],
            "margin": {"t": 80},
        },
    }


def polar_figure(sources: list[Source], n: int = 181, active: int = 3) -> dict:
    """Polar plot of the in-plane slices with a logarithmic radius (glossy data spans decades)."""
    theta_o = np.linspace(-89.5, 89.5, n)
    curves = _curves(sources, theta_o)
    groups = []
    for t in THETA_I_DEG:
        groups.append(
            [
                {
                    "type": "scatterpolar",
                    "mode": "lines",
                    "name": s.label,
                    "theta": _finite(theta_o),
                    "r": _finite(np.where(curves[k, t] > 0, curves[k, t], np.nan)),
                    "line": {
                        "color": COLORS[k % len(COLORS)],
                        "dash": "solid" if s.measured else "dash",
                    },
                }
                for k, s in enumerate(sources)
            ]
        )
    return {
        "data": _visible(groups, active),
        "layout": {
            "title": {"text": "polar, plane of incidence: log radius " + UNIT},
            "polar": {
                "sector": [0, 180],
                "angularaxis": {
                    "rotation": 0,
                    "direction": "counterclockwise",
                    "thetaunit": "degrees",
                    "ticksuffix": "°",
                    "tickvals": [-90, -60, -30, 0, 30, 60, 90],
                },
                "radialaxis": {"type": "log", "title": {"text": "f (1/sr)"}},
            },
            "sliders": [
                _slider([len(g) for g in groups], [f"{t:g}°" for t in THETA_I_DEG], "θi = ", active)
            ],
        },
    }


def _log_maps(material: Any, phi_d: Sequence[float], n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(theta deg (n,), log10 f (len(phi_d), n, n))``; NaN below the horizon and where f <= 0."""
    grids = [half_diff_grid(n, p) for p in phi_d]
    wi = np.stack([g[1] for g in grids])
    wo = np.stack([g[2] for g in grids])
    ok = (wi[..., 2] > 0) & (wo[..., 2] > 0)
    v = evaluate(material, np.nan_to_num(wi).reshape(-1, 3), np.nan_to_num(wo).reshape(-1, 3), "Y")
    v = v.reshape(ok.shape)
    return grids[0][0], np.where(ok & (v > 0), np.log10(np.maximum(v, 1e-30)), np.nan)


def maps_figure(source: Source, lo: float, hi: float, n: int = 90, active: int = 3) -> dict:
    """log10 f over theta_h (horizontal) and theta_d (vertical) at a chosen phi_d (slider);
    colour range ``[lo, hi]`` (log10 1/sr) shared by the page's maps; unmeasured (masked) cells
    of a gridded input are blank."""
    groups = []
    deg, zs = _log_maps(source.material, PHI_D_DEG, n)
    for p, z in zip(PHI_D_DEG, zs, strict=True):
        if source.table is not None:
            z = np.where(_masked(source.table, p, n), np.nan, z)
        groups.append(
            [
                {
                    "type": "heatmap",
                    "x": _finite(deg),
                    "y": _finite(deg),
                    "z": [_finite(row) for row in z],
                    "zmin": lo,
                    "zmax": hi,
                    "colorscale": "Magma",
                    "colorbar": {"title": {"text": "log10 f (1/sr)"}},
                    "hovertemplate": "θh %{x:.1f}°, θd %{y:.1f}°: %{z:.3f}<extra></extra>",
                }
            ]
        )
    return {
        "data": _visible(groups, active),
        "layout": {
            "title": {"text": f"{source.label}: θh–θd map"},
            "xaxis": {"title": {"text": "θh (deg)"}, "range": [0, 90]},
            "yaxis": {"title": {"text": "θd (deg)"}, "range": [0, 90], "scaleanchor": "x"},
            "plot_bgcolor": "#bbbbbb",
            "sliders": [
                _slider([1] * len(PHI_D_DEG), [f"{p:g}°" for p in PHI_D_DEG], "φd = ", active)
            ],
        },
    }


def _masked(table: Any, phi_d: float, n: int) -> np.ndarray:
    """Where the map's pixels ``(n, n)`` (rows theta_d, columns theta_h, as
    :func:`gonio.render.plots.half_diff_grid`) fall on an invalid node of a gridded table
    (nearest node, phi_d folded as the table folds it)."""
    if table.parameterization != "half_diff_iso" or bool(np.all(table.mask)):
        return np.zeros((n, n), bool)
    deg = (np.arange(n) + 0.5) * 90.0 / n
    pd = math.radians(phi_d) % (2 * math.pi)
    fold = fold_of(table.axes[2])
    if fold >= 1 and pd >= math.pi:
        pd -= math.pi
    if fold >= 2:
        pd = min(pd, math.pi - pd)
    ih = np.asarray(table.axes[0].nearest_index(np.radians(deg)))
    id_ = np.asarray(table.axes[1].nearest_index(np.radians(deg)))
    ip = int(np.asarray(table.axes[2].nearest_index(pd)))
    return ~np.asarray(table.mask)[ih[None, :], id_[:, None], ip]


def map_range(sources: list[Source], n: int = 90) -> tuple[float, float]:
    """Shared colour range of the maps: 1st to 99.9th percentile of log10 f at phi_d = 90°."""
    vals = [z[np.isfinite(z)] for s in sources for z in [_log_maps(s.material, [90.0], n)[1]]]
    finite = np.concatenate(vals) if vals else np.zeros(0)
    if not finite.size:
        return -3.0, 1.0
    lo, hi = np.percentile(finite, [1, 99.9])
    return float(lo), float(max(hi, lo + 1e-3))


def coverage_figure(source: Source) -> dict | None:
    """A scattered input's (wi, wo) pairs: ``wo`` on the hemisphere (orthographic view from
    above, x right, y up) and every pair in half/diff space (theta_h, theta_d), coloured by
    log10 f or by sigma (buttons). Trace 0 holds exactly one point per sample. None for inputs
    without samples."""
    if source.samples is None:
        return None
    from gonio.brdf.gridding import half_diff_iso

    wi, wo, v, sig = source.samples
    y = channel_values(v, "Y")
    logf = np.where(y > 0, np.log10(np.maximum(y, 1e-30)), np.nan)
    th, td, _ = (np.degrees(a) for a in half_diff_iso(wi, wo))
    ti = np.degrees(np.arccos(np.clip(wi[:, 2], -1, 1)))
    pi = np.degrees(np.arctan2(wi[:, 1], wi[:, 0]))
    hover = [f"θi {a:.1f}°, φi {b:.1f}°" for a, b in zip(ti, pi, strict=True)]
    marker = {
        "color": _finite(logf),
        "colorscale": "Viridis",
        "size": 5,
        "colorbar": {"title": {"text": "log10 f"}},
    }
    n = len(y)
    data = [
        {
            "type": "scatter",
            "mode": "markers",
            "name": f"wo of {n} samples",
            "x": _finite(wo[:, 0]),
            "y": _finite(wo[:, 1]),
            "text": hover,
            "marker": marker,
            "xaxis": "x",
            "yaxis": "y",
        },
        {
            "type": "scatter",
            "mode": "markers",
            "name": "half/diff",
            "x": _finite(th),
            "y": _finite(td),
            "marker": {**marker, "showscale": False},
            "xaxis": "x2",
            "yaxis": "y2",
            "text": hover,
        },
    ]
    buttons = [
        {
            "label": "colour: log10 f",
            "method": "restyle",
            "args": [{"marker.color": [_finite(logf)] * 2}],
        }
    ]
    if sig is not None:
        s = channel_values(sig, "Y")
        buttons.append(
            {
                "label": "colour: σ (1/sr)",
                "method": "restyle",
                "args": [{"marker.color": [_finite(s)] * 2}],
            }
        )
    circle = {
        "type": "circle",
        "xref": "x",
        "yref": "y",
        "x0": -1,
        "y0": -1,
        "x1": 1,
        "y1": 1,
        "line": {"color": "#888"},
    }
    return {
        "data": data,
        "layout": {
            "title": {"text": f"{source.label}: coverage, {n} samples"},
            "xaxis": {"domain": [0, 0.45], "range": [-1.05, 1.05], "title": {"text": "wo x"}},
            "yaxis": {"range": [-1.05, 1.05], "scaleanchor": "x", "title": {"text": "wo y"}},
            "xaxis2": {"domain": [0.55, 1], "range": [0, 90], "title": {"text": "θh (deg)"}},
            "yaxis2": {"anchor": "x2", "range": [0, 90], "title": {"text": "θd (deg)"}},
            "shapes": [circle],
            "showlegend": False,
            "updatemenus": [
                {"type": "buttons", "direction": "right", "x": 1.0, "y": 1.15, "buttons": buttons}
            ],
        },
    }
