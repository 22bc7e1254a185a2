"""Diagnostic plots of a fit (matplotlib, Agg backend; PNG files written atomically).

``residual_map``   mean log ratio ``ln((f + e) / (y + e))`` over (theta_h, theta_d) bins,
                   averaged over channels (e = 1e-3 sr^-1 keeps dark cells readable): red where
                   the model is too bright, blue where too dark.
``polar_slices``   in-plane slices (wo in the plane of incidence, within 3 degrees) of the
                   measurement for a few incident angles, with the fitted model as lines; and
                   fitted-vs-measured values for all samples.
``corner_plot``    the posterior's 1-D and 2-D marginals (``corner``), from MCMC samples or
                   from draws of the Laplace Gaussian; with the true values marked (lines and a
                   legend) when they are known, as for a simulated sample.

Readable at native size: PNGs are written at :data:`DPI` and no text is smaller than
:data:`MIN_FONT_PT` points, i.e. at least 13.75 px at the image's native resolution (the demo
report shows every image at that size); only the exponents of log-axis tick labels are
smaller (matplotlib draws them at 70 % of the 10 pt tick labels: 10.7 px). The ``*_figure``
functions return the matplotlib figure (for tests and callers that add to it); the others
write the PNG.
"""

from __future__ import annotations

import contextlib
import logging
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from gonio.fit.data import FitData
from gonio.fit.programs import model_f
from gonio.io.atomic import atomic_output

_EPS = 1e-3

#: Resolution of the PNGs (dots per inch): a font of ``s`` points is ``s * DPI / 72`` px tall.
DPI = 110
#: Smallest font used, in points (9 pt at 110 dpi: 13.75 px).
MIN_FONT_PT = 9.0
#: Colour of the true-value lines on corner plots (corner's own default).
TRUTH_COLOR = "#4682b4"
#: Most parameters a corner plot is drawn for (a spectral fit has one albedo per wavelength).
MAX_CORNER_PARAMS = 12


class _Collect(logging.Handler):
    def __init__(self, out: list[str]) -> None:
        super().__init__(logging.WARNING)
        self.out = out

    def emit(self, record: logging.LogRecord) -> None:
        self.out.append(f"{record.levelname}:{record.name}: {record.getMessage()}")


@contextlib.contextmanager
def library_messages(out: list[str]) -> Iterator[None]:
    """Collect the warnings (``warnings.warn``) and log records of warning level or above that
    the plotting libraries emit while the body runs into ``out`` (one line each), instead of
    letting them reach the terminal: e.g. corner's ``Too few points to create valid contours``
    (a posterior concentrated on a few values), which says nothing about the fit. The caller
    writes them to the run's log."""
    root = logging.getLogger()
    handler = _Collect(out)
    saved = root.handlers[:]
    root.handlers = [handler]  # also keeps logging's last-resort stderr handler out
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            yield
        out += [f"{w.category.__name__}: {w.message}" for w in caught]
    finally:
        root.handlers = saved


def _save(fig: Any, path: str | Path) -> Path:
    path = Path(path)
    try:
        with atomic_output(path, ".png", make_parents=True) as tmp:
            fig.savefig(tmp, dpi=DPI, bbox_inches="tight")
    finally:
        plt.close(fig)
    return path


def residual_map(data: FitData, f: np.ndarray, path: str | Path, title: str = "") -> Path:
    """Plot the binned log-ratio residual over theta_h (horizontal) and theta_d (vertical), in
    degrees, as every theta_h-theta_d map of gonio (``gonio plot``, ``gonio view``, the report);
    returns the path."""
    return _save(residual_figure(data, f, title), path)


def residual_figure(data: FitData, f: np.ndarray, title: str = "") -> Any:
    """The figure of :func:`residual_map`."""
    th, td, _ = data.half_diff()
    ratio = np.mean(np.log((np.maximum(f, 0) + _EPS) / (np.maximum(data.values, 0) + _EPS)), -1)
    x, y, bins, box = np.degrees(th), np.degrees(td), 45, [[0, 90], [0, 90]]
    total, xe, ye = np.histogram2d(x, y, bins=bins, range=box, weights=ratio)
    count = np.histogram2d(x, y, bins=bins, range=box)[0]
    with np.errstate(invalid="ignore", divide="ignore"):
        stat = total / count  # mean per bin, NaN where empty
    lim = np.nanpercentile(np.abs(stat), 98) if np.isfinite(stat).any() else 1.0
    lim = max(float(lim), 1e-3)
    fig, ax = plt.subplots(figsize=(5.2, 4.4))
    im = ax.pcolormesh(xe, ye, stat.T, cmap="RdBu_r", vmin=-lim, vmax=lim)
    fig.colorbar(im, ax=ax, label="mean ln((f+e)/(y+e))")
    ax.set_xlabel("θh (deg)")
    ax.set_ylabel("θd (deg)")
    ax.set_title(title or "residuals (fitted vs measured)")
    return fig


#: Incident angles of the in-plane slices (degrees) and outgoing angles of their curves.
SLICE_THETA_I = (0.0, 20.0, 40.0, 60.0)
_SLICE_THETA_O = np.radians(np.linspace(-89, 89, 357))
#: Samples drawn on the fitted-vs-measured scatter at most.
SCATTER_POINTS = 6000


def slice_directions() -> tuple[np.ndarray, np.ndarray]:
    """``(wi, wo)``, each ``(len(SLICE_THETA_I) * 357, 3)``: the in-plane curves' directions
    (wo in the plane of incidence, theta_o from -89 to 89 degrees, + on the mirror side)."""
    wo = np.stack([-np.sin(_SLICE_THETA_O), np.zeros_like(_SLICE_THETA_O),
                   np.cos(_SLICE_THETA_O)], -1)  # fmt: skip
    ti = np.radians(np.asarray(SLICE_THETA_I))
    wi = np.stack([np.sin(ti), np.zeros_like(ti), np.cos(ti)], -1)
    return np.repeat(wi, len(wo), 0), np.tile(wo, (len(ti), 1))


def polar_slices(
    data: FitData, model: Any, path: str | Path, title: str = "", f: np.ndarray | None = None,
    curves: np.ndarray | None = None,
) -> Path:  # fmt: skip
    """In-plane slices measured (dots) vs fitted (lines), plus fitted-vs-measured scatter."""
    return _save(slices_figure(data, model, title, f, curves), path)


def slices_figure(
    data: FitData, model: Any, title: str = "", f: np.ndarray | None = None,
    curves: np.ndarray | None = None,
) -> Any:  # fmt: skip
    """The figure of :func:`polar_slices`. ``f``: the model at the data's directions
    ``(N, C)``, ``curves``: at :func:`slice_directions` (each evaluated when not given)."""
    if curves is None:
        curves = model_f(model, *slice_directions())
    curves = np.mean(curves, -1).reshape(len(SLICE_THETA_I), -1)
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(10.5, 4.2))
    theta_i = np.degrees(np.arccos(np.clip(data.wi[:, 2], -1, 1)))
    phi_i = np.arctan2(data.wi[:, 1], data.wi[:, 0])
    phi_o = np.arctan2(data.wo[:, 1], data.wo[:, 0])
    dphi = np.angle(np.exp(1j * (phi_o - phi_i)))
    sin_o = np.hypot(data.wo[:, 0], data.wo[:, 1])
    off_plane = np.degrees(np.arcsin(np.clip(np.abs(np.sin(dphi)) * sin_o, 0, 1)))
    colors = plt.cm.viridis(np.linspace(0, 0.9, 4))
    shown = 0
    for target, col, fm in zip(SLICE_THETA_I, colors, curves, strict=True):
        sel = (np.abs(theta_i - target) < 3.0) & (off_plane < 3.0)
        if sel.sum() < 3:
            continue
        shown += 1
        theta_o = np.degrees(np.arccos(np.clip(data.wo[sel, 2], -1, 1)))
        signed = np.where(np.cos(dphi[sel]) < 0, theta_o, -theta_o)  # + on the mirror side
        y = np.mean(data.values[sel], -1)
        ax.scatter(signed, np.maximum(y, 1e-4), s=6, color=col, alpha=0.6)
        ax.plot(np.degrees(_SLICE_THETA_O), np.maximum(fm, 1e-4), color=col,
                label=f"theta_i = {target:g}")  # fmt: skip
    ax.set_yscale("log")
    ax.set_xlabel("theta_o in the plane of incidence (deg, + = mirror side)")
    ax.set_ylabel("BRDF (1/sr), channel mean")
    ax.set_title("in-plane slices" if shown else "no in-plane samples")
    if shown:
        ax.legend(fontsize=MIN_FONT_PT)
    if f is None:
        f = model_f(model, data.wi, data.wo)
    f = np.broadcast_to(f, data.values.shape)
    idx = np.random.default_rng(0).choice(data.n, size=min(data.n, SCATTER_POINTS), replace=False)
    for c in range(data.channels):
        ax2.scatter(
            np.maximum(data.values[idx, c], 1e-5),
            np.maximum(f[idx, c], 1e-5),
            s=2,
            alpha=0.3,
            label=data.channel_names[c] if data.channels <= 4 else None,
        )
    lims = [1e-5, max(float(np.nanmax(data.values)), 1e-3) * 2]
    ax2.plot(lims, lims, "k--", lw=0.8)
    ax2.set_xscale("log")
    ax2.set_yscale("log")
    ax2.set_xlabel("measured (1/sr)")
    ax2.set_ylabel("fitted (1/sr)")
    if data.channels <= 4:
        ax2.legend(fontsize=MIN_FONT_PT, markerscale=4)
    fig.suptitle(title)
    return fig


def corner_plot(
    samples: np.ndarray, names: list[str], path: str | Path, truths: Any = None, title: str = ""
) -> Path:
    """Corner plot of posterior samples (S, P) in physical units; see :func:`corner_figure`."""
    return _save(corner_figure(samples, names, truths, title), path)


def short_labels(names: list[str]) -> list[str]:
    """Each dotted parameter name cut to its shortest tail that no other name shares:
    ``torrancesparrow.fresnel.f0[R]`` -> ``f0[R]``, ``lambert.albedo[G]`` -> ``albedo[G]``."""
    parts = [n.split(".") for n in names]
    out = []
    for p in parts:
        for k in range(1, len(p) + 1):
            tail = p[-k:]
            if sum(q[-k:] == tail for q in parts) == 1:
                out.append(".".join(tail))
                break
        else:
            out.append(".".join(p))
    return out


def truth_values(names: list[str], truth: dict[str, Any] | None) -> list[float | None]:
    """The true value of each flat parameter name (``"lambert.albedo[R]"``) from a
    ``{key: value}`` dict of model parameters (per-channel values in channel order, a scalar
    shared by every channel), None where the dict has no value for it."""
    truth = truth or {}
    seen: dict[str, int] = {}
    out: list[float | None] = []
    for n in names:
        key = n.split("[", 1)[0]
        if key not in truth:
            out.append(None)
            continue
        v = np.ravel(np.asarray(truth[key], dtype=float))
        i = seen.get(key, 0)
        seen[key] = i + 1
        out.append(float(v[i] if v.size > 1 else v[0]))
    return out


def corner_figure(
    samples: np.ndarray, names: list[str], truths: Any = None, title: str = ""
) -> Any:
    """The posterior's marginals with the 2.5, 50 and 97.5 % quantiles dashed.

    Parameters
    ----------
    samples : (S, P) samples in physical units; parameters that do not vary are left out.
    names : P flat parameter names; the axes show each cut to its shortest unique tail.
    truths : P true values (None where unknown), or a ``{key: value}`` dict of model parameters
        (:func:`truth_values`), or None. Known values are drawn as lines in
        :data:`TRUTH_COLOR`, inside every axis range, with a legend.
    title : figure title.
    """
    import corner
    from matplotlib.lines import Line2D

    samples = np.asarray(samples, dtype=float)
    if isinstance(truths, dict):
        truths = truth_values(names, truths)
    keep = np.flatnonzero(np.ptp(samples, axis=0) > 0)
    x = samples[:, keep]
    labels = short_labels([names[i] for i in keep])
    tv = None if truths is None else [truths[i] for i in keep]
    if tv is not None and all(t is None for t in tv):
        tv = None
    ranges = []
    for j in range(x.shape[1]):
        lo, hi = float(x[:, j].min()), float(x[:, j].max())
        if tv is not None and tv[j] is not None:
            lo, hi = min(lo, tv[j]), max(hi, tv[j])  # the truth stays in view
        pad = 0.05 * (hi - lo)
        ranges.append((lo - pad, hi + pad))
    fig = corner.corner(
        x,
        labels=labels,
        range=ranges,
        truths=tv,
        truth_color=TRUTH_COLOR,
        quantiles=[0.025, 0.5, 0.975],
        max_n_ticks=4,
        label_kwargs={"fontsize": 11},
    )
    k = x.shape[1]
    axes = np.asarray(fig.axes).reshape(k, k)
    for j in range(k):
        q = np.percentile(x[:, j], [2.5, 50, 97.5])
        axes[j, j].set_title(
            f"{labels[j]}\n{q[1]:.3g} [{q[0]:.3g}, {q[2]:.3g}]", fontsize=10, loc="center"
        )
    for ax in fig.axes:
        ax.tick_params(labelsize=MIN_FONT_PT)
    handles = [Line2D([], [], color="k", ls="--", label="2.5, 50, 97.5 % quantiles")]
    if tv is not None:
        handles.insert(0, Line2D([], [], color=TRUTH_COLOR, lw=2, label="true value"))
    fig.legend(handles=handles, loc="upper right", fontsize=12, frameon=False)
    if title:
        fig.suptitle(title, fontsize=14)
    return fig


def plot_result(
    result: Any,
    data: FitData,
    out_dir: str | Path,
    stem: str,
    truth: dict | None = None,
    *,
    skipped: list[str] | None = None,
    log: list[str] | None = None,
) -> list[Path]:
    """Every plot of one result into ``out_dir`` as ``<stem>-*.png``; returns the paths.

    ``truth``: the true parameters (``{key: value}``, as the result's ``params``) when known,
    marked on the corner plot. ``skipped`` receives one line per plot not drawn and why;
    ``log`` the plotting libraries' warnings (:func:`library_messages`), which never reach the
    terminal (dropped when ``log`` is None: they concern the drawing, not the fit)."""
    out_dir = Path(out_dir)
    messages: list[str] = []
    with library_messages(messages):
        paths = _plots(result, data, out_dir, stem, truth, skipped)
    if log is not None:
        log += [f"{stem}: {m}" for m in messages]
    return paths


def _plots(
    result: Any,
    data: FitData,
    out_dir: Path,
    stem: str,
    truth: dict | None,
    skipped: list[str] | None,
) -> list[Path]:
    # the model at the data's cells and on the slices' curves in one compiled call
    swi, swo = slice_directions()
    both = model_f(result.model, np.concatenate([data.wi, swi]), np.concatenate([data.wo, swo]))
    f, curves = both[: data.n], both[data.n :]
    paths = [
        residual_map(data, f, out_dir / f"{stem}-residuals.png", title=result.name),
        polar_slices(
            data, result.model, out_dir / f"{stem}-slices.png", result.name, f=f, curves=curves
        ),
    ]
    unc = result.uncertainty
    if unc is None or unc.samples is None:
        return paths
    if not 1 <= len(unc.names) <= MAX_CORNER_PARAMS:
        if skipped is not None:
            skipped.append(
                f"{stem}-corner.png not drawn: {len(unc.names)} parameters, more than "
                f"{MAX_CORNER_PARAMS} (one per channel of {data.channels}); the intervals are "
                f"in {stem}.json"
            )
        return paths
    paths.append(
        corner_plot(
            unc.samples,
            unc.names,
            out_dir / f"{stem}-corner.png",
            truths=truth_values(unc.names, truth) if truth else None,
            title=f"{result.name} ({unc.method})",
        )
    )
    return paths
