"""The staged fit of large data: multi-start on a random subsample, refinement on a stratified
subset, polish on every sample with the subset's curvature. The final optimum must be the one
of the plain path (``refine=0``: every LM step on every sample)."""

import subprocess
import sys

import numpy as np
import pytest

import gonio.fit  # noqa: F401
from gonio.brdf import models
from gonio.fit import presets
from gonio.fit.cli import LOSS_NAMES
from gonio.fit.losses import LOSSES, evaluate, evaluate_many, get_loss
from gonio.fit.objective import Problem
from gonio.fit.optimize import optimize, subset_curvature
from gonio.fit.params import Layout
from tests.fit.synth import synthetic


def _misfit_data(n: int, seed: int):
    """Cook-Torrance-like samples (Beckmann lobe with a Fresnel rise) to be fitted by Ward:
    a model that cannot reach the data, as on real tables (large residuals)."""
    truth, _, _ = presets.build("lambert+cook-torrance")
    data, _ = synthetic(truth, n=n, seed=seed, rel_noise=0.02, abs_noise=0.002)
    return data


def test_stratified_subset_covers_theta_h_evenly():
    data = _misfit_data(20000, seed=3)
    sub = data.stratified_subset(500, seed=1)
    assert sub.n == 500
    assert data.stratified_subset(500, seed=1).wi.tobytes() == sub.wi.tobytes()  # seeded
    assert data.stratified_subset(50000) is data
    th_all = np.sort(data.half_diff()[0])
    th_sub = np.sort(sub.half_diff()[0])
    # one sample per stratum of equal count: the k-th smallest subset theta_h lies in stratum k
    edges = np.linspace(0, data.n, 501).astype(int)
    assert np.all(th_sub >= th_all[edges[:-1]] - 1e-12)
    assert np.all(th_sub <= th_all[edges[1:] - 1] + 1e-12)
    # distinct samples
    assert np.unique(sub.wi, axis=0).shape[0] == 500


@pytest.mark.parametrize("loss", ["ngan", "low-e2", "wls"])
def test_subset_curvature_keeps_full_loss_and_gradient(loss):
    data = _misfit_data(12000, seed=4)
    tmpl, fixed, tied = presets.build("lambert+ward")
    lay = Layout(tmpl, data.channels, fixed=fixed, tied=tied)
    full = Problem(lay, get_loss(loss), data)
    sub = full.with_data(data.stratified_subset(3000, seed=0))
    u = lay.random_starts(2, seed=5)[1]
    c_full, g_full, a_full = full.normal(u)
    c, g, a = subset_curvature(full, sub)(u)
    assert c == pytest.approx(c_full, rel=1e-12)
    np.testing.assert_allclose(g, g_full, rtol=1e-9, atol=1e-12 * np.abs(g_full).max())
    # the subset's J^T J on the full data's scale (25 % of the samples: a few % off)
    assert np.linalg.norm(a - a_full) <= 0.15 * np.linalg.norm(a_full)


@pytest.mark.parametrize("loss", ["ngan", "low-e2", "wls"])
def test_refined_fit_reaches_the_plain_optimum(loss):
    data = _misfit_data(12000, seed=6)
    tmpl, fixed, tied = presets.build("lambert+ward")
    lay = Layout(tmpl, data.channels, fixed=fixed, tied=tied)
    prob = Problem(lay, get_loss(loss), data)
    plain = optimize(prob, n_starts=8, seed=0, subsample=2000, refine=0)
    staged = optimize(prob, n_starts=8, seed=0, subsample=2000, refine=3000)
    assert staged.timings["refine"] > 0 and plain.converged and staged.converged
    assert staged.cost == pytest.approx(plain.cost, rel=1e-8)
    np.testing.assert_allclose(staged.u, plain.u, rtol=2e-3, atol=2e-3)


def test_refine_only_for_data_twice_its_size():
    data, _ = synthetic(models.Lambert(albedo=0.4), n=1000, seed=0)
    prob = Problem(Layout(models.Lambert(albedo=0.2), 1), get_loss("wls"), data)
    res = optimize(prob, n_starts=2, refine=600)  # 1000 samples < 2 x 600: no refinement
    assert res.timings["refine"] < 1e-3
    assert res.converged


def test_cli_loss_names_match_the_losses():
    assert LOSS_NAMES == tuple(sorted(LOSSES))


def test_fit_cli_parser_does_not_import_jax():
    code = (
        "import sys, argparse; from gonio.fit import cli; "
        "p = argparse.ArgumentParser(); cli.register(p.add_subparsers()); "
        "print('jax' in sys.modules, 'scipy.stats' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"]


@pytest.mark.parametrize("with_sigma", [True, False])
def test_evaluate_many_compiled_pass_equals_numpy(with_sigma):
    from gonio.fit.data import from_arrays
    from tests.fit.synth import cosine_directions

    rng = np.random.default_rng(11)
    n = 100_000  # 3e5 values: above the size where the compiled pass is used
    wi, wo = cosine_directions(n, rng), cosine_directions(n, rng)
    y = rng.gamma(0.5, 1.0, size=(n, 3)) - 0.01  # a few slightly negative values
    f = np.abs(y + 0.1 * rng.standard_normal((n, 3)))
    sigma = 0.05 + 0.1 * np.abs(y) if with_sigma else None
    data = from_arrays(wi, wo, y, sigma=sigma, weights=rng.uniform(0.5, 2.0, n))
    assert data.values.size >= 1 << 18
    fast = evaluate_many(LOSSES, f[: data.n], data)
    for name in LOSSES:
        assert fast[name] == pytest.approx(evaluate(name, f[: data.n], data), rel=1e-10)


@pytest.mark.parametrize("with_sigma", [True, False])
def test_compiled_score_pass_equals_predict_and_evaluate_many(with_sigma):
    from gonio.fit.data import from_arrays
    from tests.fit.synth import cosine_directions

    rng = np.random.default_rng(12)
    n = 90_000  # chunked (3 chunks) and padded
    wi, wo = cosine_directions(n, rng), cosine_directions(n, rng)
    y = rng.gamma(0.5, 1.0, size=(n, 3)) - 0.01
    sigma = 0.05 + 0.1 * np.abs(y) if with_sigma else None
    data = from_arrays(wi, wo, y, sigma=sigma, weights=rng.uniform(0.5, 2.0, n))
    tmpl, fixed, tied = presets.build("lambert+ward")
    lay = Layout(tmpl, data.channels, fixed=fixed, tied=tied)
    prob = Problem(lay, get_loss("ngan"), data)
    u = lay.random_starts(3, seed=2)[2]
    got, n_bad = prob.scores(u, tuple(LOSSES))
    f = prob.predict(u)
    want = evaluate_many(LOSSES, f, data)
    assert n_bad == 0 and prob.n_chunks > 1
    for name in LOSSES:
        assert got[name] == pytest.approx(want[name], rel=1e-10)
    sig = 1.0 if sigma is None else data.sigma
    assert got["wls"] == pytest.approx(float(np.sum(((f - data.values) / sig) ** 2)), rel=1e-10)


@pytest.mark.parametrize("loss", ["ngan", "low-e2"])
def test_subset_hessian_polish_converges_in_fewer_passes(loss):
    """Large residuals (Ward fitted to Cook-Torrance-like data): from the subset's optimum,
    the full gradient with the subset's exact Hessian gets much closer to the full optimum in
    one pass over the data than with the subset's J^T J, and both reach the same loss."""
    from gonio.fit.lm import levenberg_marquardt
    from gonio.fit.optimize import subset_hessian

    data = _misfit_data(40000, seed=8)
    tmpl, fixed, tied = presets.build("lambert+ward")
    lay = Layout(tmpl, data.channels, fixed=fixed, tied=tied)
    full = Problem(lay, get_loss(loss), data)
    mid = full.with_data(data.stratified_subset(4000, seed=0))
    lo, hi = lay.box()
    u_mid = levenberg_marquardt(mid.normal, lay.random_starts(1, seed=0)[0], lo, hi).u
    ref = levenberg_marquardt(full.normal, u_mid, lo, hi, ftol=1e-13)  # exact J^T J, every pass
    hess = subset_hessian(mid, u_mid)
    assert hess is not None
    newton = levenberg_marquardt(subset_curvature(full, mid, hess), u_mid, lo, hi, ftol=1e-10)
    gauss = levenberg_marquardt(subset_curvature(full, mid), u_mid, lo, hi, ftol=1e-10)
    assert newton.cost == pytest.approx(ref.cost, rel=1e-9)
    assert gauss.cost == pytest.approx(ref.cost, rel=1e-9)
    assert newton.n_eval <= gauss.n_eval
    # after one step from the subset's optimum, the gap to the optimum is at most half the
    # Gauss-Newton step's (measured: 1.1e-6 against 1.9e-5 for ngan, 2.0e-8 against 5.4e-8
    # for low-e2; on MERL tables 1e-8 against 4e-7 relative)
    gap_newton, gap_gauss = newton.history[1] - ref.cost, gauss.history[1] - ref.cost
    assert 0 <= gap_newton <= 0.5 * gap_gauss


def test_subset_hessian_refuses_indefinite_or_nonfinite():
    from gonio.fit.optimize import subset_hessian

    class Fake:
        def __init__(self, h):
            self.h = h

        def hessian(self, u):
            return self.h

    assert subset_hessian(Fake(np.diag([2.0, 4.0])), np.zeros(2)) == pytest.approx(
        np.diag([1.0, 2.0])
    )
    assert subset_hessian(Fake(np.diag([2.0, -1.0])), np.zeros(2)) is None
    assert subset_hessian(Fake(np.array([[1.0, np.nan], [np.nan, 1.0]])), np.zeros(2)) is None


def test_subsets_are_drawn_once_per_data():
    data = _misfit_data(5000, seed=9)
    a = data.random_subset(300, seed=2)
    assert data.random_subset(300, seed=2) is a
    assert data.random_subset(300, seed=3) is not a
    s = data.stratified_subset(300, seed=2)
    assert data.stratified_subset(300, seed=2) is s and s is not a
    other = _misfit_data(5000, seed=10)  # equal sizes, other data: its own subsets
    assert other.random_subset(300, seed=2).values.tobytes() != a.values.tobytes()


def test_score_pass_shares_data_constants_and_matches_numpy():
    data = _misfit_data(3000, seed=11)
    tmpl, fixed, tied = presets.build("lambert+ward")
    lay = Layout(tmpl, data.channels, fixed=fixed, tied=tied)
    u = lay.random_starts(2, seed=1)[1]
    p1 = Problem(lay, get_loss("ngan"), data, chunk=1024)
    p2 = Problem(lay, get_loss("low-e2"), data, chunk=1024)
    s1, _ = p1.scores(u, tuple(LOSSES))
    s2, _ = p2.scores(u, tuple(LOSSES))
    assert p1._score_arrays is p2._score_arrays  # built once for the data and chunking
    f = p1.predict(u)
    for name in LOSSES:
        assert s1[name] == pytest.approx(evaluate(name, f, data), rel=1e-10)
        assert s2[name] == s1[name]
