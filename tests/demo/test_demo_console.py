"""Issue 21 on the reduced demo run (``demo`` fixture): the terminal summary fits 80 columns
without cutting a name or a number, and the corner plot of the sample's own model marks the
truth while the others (no truth known for them) do not."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from gonio.demo.cli import print_summary
from gonio.fit.plots import TRUTH_COLOR

pytestmark = pytest.mark.xdist_group("demo-e2e")


def test_terminal_summary_fits_80_columns(demo, monkeypatch, capsys):
    _, _, summary = demo
    monkeypatch.setenv("COLUMNS", "80")
    print_summary(summary)
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert max(len(line) for line in lines) <= 80, out
    assert "\u2026" not in out
    words = out.split()
    for m in summary.models:
        assert all(w in words for w in m.label.split()), m.label
        assert f"{m.reduced_chi2:.3g}" in words and f"{m.bic:.4g}" in words
        for key, value in m.params.items():
            for x in np.ravel(value):
                assert f"{x:.4g}" in words, (m.label, key)
    assert f"{summary.out}/index.html" in out


def _truth_pixels(path) -> int:
    rgb = np.asarray(Image.open(path).convert("RGB"), dtype=int)
    target = np.array([int(TRUTH_COLOR[i : i + 2], 16) for i in (1, 3, 5)])
    return int((np.abs(rgb - target).max(-1) <= 12).sum())


def test_corner_plot_marks_the_truth_of_the_samples_own_model(demo):
    out, material, summary = demo
    corners = {m.preset: out / p for m in summary.models for p in m.files["plots"] if "corner" in p}
    assert set(material.truth_params) <= set(corners)
    for preset, path in corners.items():
        n = _truth_pixels(path)
        if preset in material.truth_params:
            assert n > 2000, (preset, n)  # 7 diagonal lines and 42 cross-hairs, 2 px wide
        else:
            assert n == 0, (preset, n)


def test_report_explains_a_run_without_reciprocal_pairs(demo):
    out, _, summary = demo
    note = summary.acquisition["table_note"]
    assert "reciprocity: 0 pairs" in note  # demo-quick measures no swapped configuration
    why = "no configuration was measured with light and camera swapped; plan iso-reciprocal does"
    assert why in note
    assert why in (out / "index.html").read_text(encoding="utf-8")
