"""``gonio plot``'s panels: a logarithmic polar radius, no empty panel, and theta_h on the
horizontal axis of every theta_h-theta_d map (the fit's residual maps included)."""

from __future__ import annotations

import math

import numpy as np
import pytest


@pytest.fixture(scope="module")
def glossy():
    from gonio.brdf import models
    from gonio.render.plots import PlotInput

    m = models.Lambert(albedo=0.05) + models.TorranceSparrow(
        alpha=0.05, distribution="ggx", rho_d=0.0
    )
    return PlotInput("glossy", m, measured=False)


def _panels(fig):
    return [ax for ax in fig.axes if ax.get_label() != "<colorbar>"]


@pytest.mark.parametrize("n_inputs", [1, 3])
def test_every_panel_holds_data_and_no_slot_is_empty(glossy, n_inputs):
    import matplotlib.pyplot as plt

    from gonio.render.plots import materials_figure

    fig = materials_figure([glossy] * n_inputs, theta_i_deg=(30.0,), n=31)
    try:
        panels = _panels(fig)
        assert len(panels) == 2 + n_inputs
        assert all(ax.lines or ax.images for ax in panels)
        slots = {id(ax.get_subplotspec().get_gridspec()): ax.get_subplotspec().get_gridspec()
                 for ax in panels}  # fmt: skip
        assert sum(g.nrows * g.ncols for g in slots.values()) == len(panels)
    finally:
        plt.close(fig)


def test_polar_radius_is_logarithmic_and_spans_the_glossy_peak(glossy):
    import matplotlib.pyplot as plt

    from gonio.render.plots import materials_figure

    fig = materials_figure([glossy], theta_i_deg=(30.0,), kinds=("polar",), n=61)
    try:
        (ax,) = _panels(fig)
        assert ax.get_yscale() == "log"
        lo, hi = ax.get_ylim()
        r = ax.lines[0].get_ydata()
        assert lo <= np.nanmin(r) and np.nanmax(r) <= hi and hi / lo > 100
    finally:
        plt.close(fig)


def test_maps_put_theta_h_on_the_horizontal_axis(glossy):
    import matplotlib.pyplot as plt

    from gonio.fit.plots import residual_figure
    from gonio.render.plots import materials_figure

    fig = materials_figure([glossy], kinds=("halfdiff",))
    try:
        assert _panels(fig)[0].get_xlabel().startswith("θh")
    finally:
        plt.close(fig)

    class Data:  # one sample at theta_h = 11 deg, theta_d = 61 deg, fitted 2x too high
        values = np.ones((1, 1))

        def half_diff(self):
            return np.radians([11.0]), np.radians([61.0]), np.zeros(1)

    fig = residual_figure(Data(), np.full((1, 1), 2.0))
    try:
        ax = fig.axes[0]
        assert ax.get_xlabel().startswith("θh") and ax.get_ylabel().startswith("θd")
        z = ax.collections[0].get_array().reshape(45, 45)  # rows theta_d, columns theta_h
        row, col = np.argwhere(np.isfinite(z))[0]
        assert (col, row) == (5, 30) and math.isclose(z[row, col], math.log(2.0), rel_tol=1e-3)
    finally:
        plt.close(fig)
