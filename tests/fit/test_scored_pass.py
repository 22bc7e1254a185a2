"""The last polish pass also computes the scores (Problem.value_and_grad_scored)."""

from __future__ import annotations

import numpy as np

from gonio.fit.data import from_arrays
from gonio.fit.losses import LOSSES, evaluate_many, get_loss
from gonio.fit.objective import Problem
from gonio.fit.params import Layout
from gonio.fit.presets import build


def _problem(loss: str = "low-e1") -> Problem:
    rng = np.random.default_rng(5)
    wi = rng.normal(size=(700, 3))
    wo = rng.normal(size=(700, 3))
    wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]) + 0.2, np.abs(wo[:, 2]) + 0.2
    y = rng.random((700, 3)) * 2.0 + 0.05
    data = from_arrays(wi, wo, y, weights=rng.random(700) + 0.5)
    tmpl, fixed, tied = build("lambert+cook-torrance")
    # small chunks so that the pass runs over several chunks and a padded last one
    return Problem(Layout(tmpl, 3, fixed=fixed, tied=tied), get_loss(loss), data, chunk=256)


def test_scored_pass_gives_the_gradient_and_the_scores_of_separate_passes():
    pb = _problem()
    u = pb.layout.random_starts(3, 2)[2]
    v, g = pb.value_and_grad(u)
    v2, g2 = pb.value_and_grad_scored(u)
    np.testing.assert_allclose(v2, v, rtol=1e-13)
    np.testing.assert_allclose(g2, g, rtol=1e-12, atol=1e-14 * np.abs(g).max())
    kept, _ = pb.scores(u, tuple(LOSSES))
    other = _problem()  # nothing kept: the score program
    fresh, _ = other.scores(u, tuple(LOSSES))
    want = evaluate_many(LOSSES, pb.predict(u), pb.data)  # NumPy-side formulas
    for name in LOSSES:
        np.testing.assert_allclose(kept[name], fresh[name], rtol=1e-12)
        np.testing.assert_allclose(kept[name], want[name], rtol=1e-10)


def test_kept_scores_are_used_only_at_their_point():
    pb = _problem("ngan")
    u = pb.layout.random_starts(2, 0)[1]
    pb.value_and_grad_scored(u)
    w = u + 0.05
    got, _ = pb.scores(w, tuple(LOSSES))
    want, _ = _problem("ngan").scores(w, tuple(LOSSES))
    at_u, _ = pb.scores(u, tuple(LOSSES))
    assert got == want
    assert at_u["ngan"] != got["ngan"]
    # a subset of the losses is computed, not taken from the kept sums
    some, _ = pb.scores(u, ("ngan",))
    np.testing.assert_allclose(some["ngan"], at_u["ngan"], rtol=1e-12)


def test_fit_metrics_come_from_the_last_polish_pass(monkeypatch):
    from gonio.fit import api, fit

    monkeypatch.setattr(api, "_SCORE_PASS_MIN_VALUES", 0)  # the compiled score path
    seen = []
    scores = Problem.scores

    def spy(self, u, names):
        kept = self._scored
        seen.append(kept is not None and np.array_equal(kept[0], u))
        return scores(self, u, names)

    monkeypatch.setattr(Problem, "scores", spy)
    pb = _problem("ngan")
    r = fit(pb.data, "lambert+cook-torrance", loss="ngan", subsample=200, refine=128)
    assert r.optimizer["timings"]["refine"] > 0  # refine < n / 2: the staged polish ran
    assert seen == [True]  # scored by the kept sums of the polish's last pass
    fresh, _ = Problem(pb.layout, pb.loss, pb.data).scores(r.u, tuple(LOSSES))
    for name in LOSSES:
        np.testing.assert_allclose(r.metrics[name], fresh[name], rtol=1e-12)
