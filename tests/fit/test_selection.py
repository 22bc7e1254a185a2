"""The default fit's model choice on held-out cells (gonio.fit.selection)."""

import json

import numpy as np
import pytest

from gonio.brdf import models
from gonio.fit import selection
from gonio.fit.data import from_arrays, prepare
from tests.fit.synth import cosine_directions, synthetic


def _directions(n, seed):
    rng = np.random.default_rng(seed)
    return cosine_directions(n, rng), cosine_directions(n, rng)


def _synthetic(model, seed):
    # one size for every test here: the fits share their compiled programs
    data, _ = synthetic(model, n=1000, seed=seed, with_sigma=False, rel_noise=0.02,
                        abs_noise=0.0, theta_max_deg=90.0)  # fmt: skip
    return data


def test_split_is_disjoint_seeded_and_stratified_on_large_data():
    n = selection.TRAIN_CELLS + selection.TEST_CELLS + 3000
    wi, wo = _directions(n, 1)
    data = from_arrays(wi, wo, np.full((n, 1), 0.2))
    train, test = selection.split_cells(data, seed=0)
    assert (train.n, test.n) == (selection.TRAIN_CELLS, selection.TEST_CELLS)
    rows = {tuple(r) for r in np.concatenate([train.wi, train.wo], 1)}
    assert not rows & {tuple(r) for r in np.concatenate([test.wi, test.wo], 1)}
    again = selection.split_cells(data, seed=0)[1]
    np.testing.assert_array_equal(again.wi, test.wi)


def test_small_data_holds_out_a_fifth():
    wi, wo = _directions(500, 2)
    data = from_arrays(wi, wo, np.full((500, 1), 0.2), theta_max_deg=90.0)
    train, test = selection.split_cells(data, seed=3)
    assert (data.n, train.n, test.n) == (500, 400, 100)


def test_matte_data_gets_the_nested_lambert_family():
    # a white paint: Lambert alone; the lobe's parameters would only fit the noise
    data = _synthetic(models.Lambert([0.8, 0.82, 0.85]), seed=4)
    sel = selection.select(data, families=("lambert", "lambert+gtr"), n_starts=4)
    assert sel.chosen == "lambert", sel.reason
    assert sel.loss == selection.DEFAULT_LOSS


@pytest.mark.slow
def test_long_tailed_highlight_gets_the_gtr_family():
    truth = models.Lambert(0.05) + models.GTR([0.6, 0.5, 0.4], alpha=0.08, gamma=1.3, f0=0.9)
    sel = selection.select(_synthetic(truth, seed=5), families=("lambert", "lambert+gtr"),
                           n_starts=4)  # fmt: skip
    assert sel.chosen == "lambert+gtr", sel.reason
    assert sel.cv_errors["lambert+gtr"] < 0.5 * sel.cv_errors["lambert"]
    gamma = sel.result.params["gtr.gamma"]
    assert 1.1 < gamma < 1.6, gamma  # the tail is found, not a GGX (2) or Beckmann-like one


@pytest.mark.slow
def test_default_cli_recommends_by_held_out_cells(tmp_path):
    """``gonio fit FILE`` with no options through the console script: the default families,
    each with its held-out error, and the choice they make."""
    from gonio import io
    from gonio.brdf.tabulated import Axis, TabulatedBRDF
    from tests import console_script as cs

    truth = models.Lambert(0.05) + models.GTR([0.6, 0.5, 0.4], alpha=0.08, gamma=1.3, f0=0.9)
    axes = (
        Axis("theta_h", 16, 0, np.pi / 2, warp="sqrt"),
        Axis("theta_d", 12, 0, np.pi / 2),
        Axis("phi_d", 12, 0, np.pi, periodic=True),
    )
    path = tmp_path / "tail.brdf.h5"
    io.save(TabulatedBRDF.from_model(truth, axes), path)
    proc = cs.run("fit", path, "--no-plots", "--out", tmp_path / "out")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    rows = {r["model"]: r for r in summary["table"]}
    assert set(rows) == set(selection.DEFAULT_FAMILIES)
    assert all(np.isfinite(r["metrics"]["cv_loss"]) for r in rows.values())
    assert summary["recommended"] in ("lambert+gtr", "lambert+gtr+gtr", "lambert+retro+gtr")
    assert "held-out" in summary["reason"]


@pytest.mark.slow
def test_retro_reflective_tape_gets_a_peak_at_the_light():
    from tests.conftest import shared_file

    data = prepare(shared_file("alta", "retro-gray-tape.dat"))
    sel = selection.select(data)
    assert sel.chosen == "lambert+retro+gtr", sel.reason
    without = min(v for k, v in sel.cv_errors.items() if "retro" not in k)
    assert sel.cv_errors["lambert+retro+gtr"] < 0.6 * without
    assert sel.result.params["lambert.albedo"] < 0.9  # not on its bound of 1
    # the fitted model's largest value over incident directions in the plane is at wi = wo
    th = np.radians(np.arange(-80, 81, 2.0))
    wi = np.stack([np.sin(th), 0 * th, np.cos(th)], -1)
    wo = np.broadcast_to(np.array([np.sin(np.radians(30)), 0, np.cos(np.radians(30))]), wi.shape)
    f = np.asarray(sel.result.model.f(wi, wo))[:, 0]
    assert round(float(np.degrees(th[np.argmax(f)]))) == 30


@pytest.mark.slow
def test_retro_tape_scores_better_than_every_family_without_the_retro_lobe(tmp_path):
    """``gonio fit TAPE --score`` (console script): the chosen retro family's HDR-FLIP beats
    the best family without the retro lobe, and the command prints the two side by side."""
    from tests import console_script as cs
    from tests.conftest import shared_file

    out = tmp_path / "o"
    proc = cs.run("fit", shared_file("alta", "retro-gray-tape.dat"), "--score", "--no-plots",
                  "-o", out, columns=200)  # fmt: skip
    cs.assert_clean(proc)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["recommended"] == "lambert+retro+gtr"
    flip = {r["model"]: r["appearance"]["hdr_flip"] for r in summary["table"]}
    best_without = min((v, k) for k, v in flip.items() if "retro" not in k)
    assert flip["lambert+retro+gtr"] < 0.8 * best_without[0]
    assert (f"appearance: recommended lambert+retro+gtr HDR-FLIP {flip['lambert+retro+gtr']:.3f}"
            f", rel. L1") in proc.stdout  # fmt: skip
    assert f"best other family by HDR-FLIP {best_without[1]}" in proc.stdout


def test_appearance_line_puts_the_recommended_fit_beside_the_best_other():
    from types import SimpleNamespace

    from gonio.fit.cli import appearance_beside_next

    def fit(name, flip, l1):
        return SimpleNamespace(name=name, channel=None, appearance={"hdr_flip": flip, "rel_l1": l1})

    fits = [
        fit("lambert", 0.75, 2.4),
        fit("lambert+gtr", 0.79, 3.5),
        fit("lambert+retro", 0.5, 4.3),
    ]
    line = appearance_beside_next(fits, "lambert+retro")
    assert line == ("appearance: recommended lambert+retro HDR-FLIP 0.500, rel. L1 4.300; best "
                    "other family by HDR-FLIP lambert HDR-FLIP 0.750, rel. L1 2.400")  # fmt: skip
    assert appearance_beside_next(fits[:1], "lambert") == ""
    assert appearance_beside_next([fit("lambert", 0.7, 1.0), *fits[1:2]], "x") == ""
