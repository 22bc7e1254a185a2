"""Issue 21, the report's plots: every text readable at the PNG's native size (at least
13.5 px: points x dpi / 72; the exponents of log-axis tick labels, mathtext superscripts drawn
at 70 % of the size, at least 10 px), and the corner plot marks the known truth (lines and a
legend), inside its axis ranges even when the fit misses it."""

from __future__ import annotations

import matplotlib
import numpy as np
import pytest
from matplotlib.lines import Line2D
from matplotlib.text import Text
from PIL import Image

import gonio.fit as gf
from gonio.fit import plots, presets
from tests.fit.synth import synthetic

MIN_PX = 13.5
MIN_SCRIPT_PX = 10.0
TRUTH = {
    "lambert.albedo": [0.55, 0.22, 0.06],
    "torrancesparrow.alpha": 0.18,
    "torrancesparrow.fresnel.f0": [0.05, 0.05, 0.05],
}


@pytest.fixture(scope="module")
def fitted():
    model, _, _ = presets.build("lambert+ts")
    data, _ = synthetic(model.replace(**TRUTH), n=1500, seed=11)
    result = gf.fit(data, model="lambert+ts", uncertainty="laplace", seed=0)
    assert len(result.uncertainty.names) == 7  # the 7-parameter corner plot of the demo
    return data, result


def _texts(fig) -> list[Text]:
    fig.canvas.draw()  # tick labels exist once drawn
    return [t for t in fig.findobj(Text) if t.get_visible() and t.get_text().strip()]


def _figures(data, result):
    f = np.asarray(result.model.f(data.wi, data.wo))
    unc = result.uncertainty
    return {
        "residuals": plots.residual_figure(data, f, "lambert+ts"),
        "slices": plots.slices_figure(data, result.model, "lambert+ts", f=f),
        "corner": plots.corner_figure(unc.samples, unc.names, TRUTH, "lambert+ts (laplace)"),
    }


def test_every_text_is_readable_at_native_size(fitted):
    for name, fig in _figures(*fitted).items():
        try:
            texts = _texts(fig)
            assert len(texts) > 10, name
            small = [
                (t.get_text(), t.get_fontsize() * plots.DPI / 72)
                for t in texts
                if t.get_fontsize() * plots.DPI / 72 < MIN_PX
            ]
            assert not small, (name, small)
            # mathtext only for the 10^n of log axes; its superscripts are 70 % of the size
            math = [t for t in texts if "$" in t.get_text()]
            assert all(t.get_text().startswith("$\\mathdefault{10^{") for t in math), name
            tiny = [
                (t.get_text(), px)
                for t in math
                if (px := 0.7 * t.get_fontsize() * plots.DPI / 72) < MIN_SCRIPT_PX
            ]
            assert not tiny, (name, tiny)
        finally:
            matplotlib.pyplot.close(fig)


def test_pngs_are_written_at_the_stated_dpi(fitted, tmp_path):
    data, result = fitted
    for p in plots.plot_result(result, data, tmp_path, "lts", truth=TRUTH):
        dpi = Image.open(p).info["dpi"]
        assert dpi == pytest.approx((plots.DPI, plots.DPI), abs=0.01), p.name


def _truth_lines(ax) -> list[Line2D]:
    return [
        ln
        for ln in ax.get_lines()
        if matplotlib.colors.same_color(ln.get_color(), plots.TRUTH_COLOR)
    ]


def test_corner_plot_marks_the_truth_with_a_legend(fitted):
    _, result = fitted
    unc = result.uncertainty
    fig = plots.corner_figure(unc.samples, unc.names, TRUTH)
    try:
        k = len(unc.names)
        axes = np.asarray(fig.axes).reshape(k, k)
        truth = plots.truth_values(unc.names, TRUTH)
        assert truth == [0.55, 0.22, 0.06, 0.18, 0.05, 0.05, 0.05]
        for j, t in enumerate(truth):
            lines = _truth_lines(axes[j, j])
            assert lines and all(np.allclose(ln.get_xdata(), t) for ln in lines), unc.names[j]
            assert axes[j, j].get_xlim()[0] < t < axes[j, j].get_xlim()[1]
        legend = [t.get_text() for lg in fig.legends for t in lg.get_texts()]
        assert "true value" in legend and "2.5, 50, 97.5 % quantiles" in legend
        labels = [ax.get_xlabel() for ax in axes[-1]]
        assert labels == ["albedo[R]", "albedo[G]", "albedo[B]", "alpha", "f0[R]", "f0[G]",
                          "f0[B]"]  # fmt: skip
    finally:
        matplotlib.pyplot.close(fig)


def test_a_truth_far_outside_the_posterior_stays_in_view():
    rng = np.random.default_rng(3)
    samples = rng.normal([1.0, 2.0], [0.01, 0.02], size=(2000, 2))
    fig = plots.corner_figure(samples, ["a.x", "b.y"], [1.5, None])
    try:
        axes = np.asarray(fig.axes).reshape(2, 2)
        lo, hi = axes[0, 0].get_xlim()
        assert lo < 1.5 < hi and lo < 0.97
        assert _truth_lines(axes[0, 0]) and not _truth_lines(axes[1, 1])
    finally:
        matplotlib.pyplot.close(fig)


def test_corner_plot_without_truth_has_no_truth_lines(fitted):
    _, result = fitted
    unc = result.uncertainty
    fig = plots.corner_figure(unc.samples, unc.names, None)
    try:
        assert not any(_truth_lines(ax) for ax in fig.axes)
        legend = [t.get_text() for lg in fig.legends for t in lg.get_texts()]
        assert "true value" not in legend
    finally:
        matplotlib.pyplot.close(fig)


def test_short_labels_stay_unique():
    names = ["ward.alpha", "ward_2.alpha", "lambert.albedo[R]", "ts.fresnel.f0", "x.f0"]
    assert plots.short_labels(names) == ["ward.alpha", "ward_2.alpha", "albedo[R]",
                                         "fresnel.f0", "x.f0"]  # fmt: skip
