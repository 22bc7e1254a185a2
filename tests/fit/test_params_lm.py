import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import least_squares

import gonio.fit  # noqa: F401
from gonio.brdf import models
from gonio.errors import FitError
from gonio.fit.losses import get_loss
from gonio.fit.objective import Problem
from gonio.fit.optimize import optimize, run_lm, run_nlopt
from gonio.fit.params import Layout
from tests.fit.lobes import TestLobe
from tests.fit.synth import synthetic


def test_layout_round_trip_and_box():
    tmpl = models.Lambert(albedo=0.4) + TestLobe(rho_s=0.2, n=30.0)
    lay = Layout(tmpl, 3)
    assert lay.size == 7
    assert lay.flat_names(("R", "G", "B"))[0] == "lambert.albedo[R]"
    vals = {"lambert.albedo": np.array([0.1, 0.5, 0.9]), "testlobe.rho_s": 0.3, "testlobe.n": 250.0}
    u = lay.inverse(vals)
    back = lay.values(u)
    np.testing.assert_allclose(back["lambert.albedo"], [0.1, 0.5, 0.9], rtol=1e-12)
    np.testing.assert_allclose(back["testlobe.rho_s"], [0.3] * 3, rtol=1e-12)
    assert back["testlobe.n"] == pytest.approx(250.0)
    lo, hi = lay.box()
    assert np.all(lo < u) and np.all(u < hi)
    # the log-scaled exponent's box is the log of its physical bounds
    assert lo[-1] == pytest.approx(np.log(1.0)) and hi[-1] == pytest.approx(np.log(1e4))
    # values on the edge are reported
    u_edge = u.copy()
    u_edge[-1] = hi[-1]
    assert lay.on_bounds(u_edge) == ["testlobe.n"]
    # dtheta/du is the derivative of theta
    jac = jax.jacfwd(lay.theta)(jnp.asarray(u))
    np.testing.assert_allclose(np.diag(jac), lay.dtheta_du(jnp.asarray(u)), rtol=1e-10)


def test_layout_to_model_under_jit_and_grad():
    lay = Layout(models.Lambert() + TestLobe(), 3)
    wi = jnp.array([[0.3, 0.1, 0.9]]) / jnp.linalg.norm(jnp.array([0.3, 0.1, 0.9]))
    wo = wi * jnp.array([-1.0, -1.0, 1.0])

    def total(u):
        return jnp.sum(lay.to_model(u).f(wi, wo))

    u0 = jnp.asarray(lay.initial())
    g = jax.jit(jax.grad(total))(u0)
    assert g.shape == (7,) and np.all(np.isfinite(g)) and np.any(g != 0)


def test_layout_fixed_and_errors():
    lay = Layout(models.Lambert(albedo=0.2) + TestLobe(), 1, fixed={"testlobe.n": 80.0})
    assert lay.keys == ["lambert.albedo", "testlobe.rho_s"]
    assert float(lay.template.params()["testlobe.n"]) == 80.0
    with pytest.raises(FitError, match="unknown parameter"):
        Layout(models.Lambert(), 1, fixed={"ward.alpha": 0.1})
    with pytest.raises(FitError, match="nothing to fit"):
        Layout(models.Lambert(), 1, fixed={"albedo": 0.3})
    with pytest.raises(FitError, match="channels"):
        Layout(models.Lambert(albedo=[0.1, 0.2]), 3)


def test_lm_matches_scipy_least_squares():
    truth = models.Lambert(albedo=[0.6, 0.4, 0.2]) + TestLobe(rho_s=[0.3, 0.2, 0.1], n=40.0)
    data, _ = synthetic(truth, n=600, seed=5)
    lay = Layout(models.Lambert() + TestLobe(), 3)
    prob = Problem(lay, get_loss("wls"), data)
    u0 = lay.initial()
    u, cost, _, _status = run_lm(prob, u0)
    ref = least_squares(lambda x: prob.residuals(x).ravel(), u0, method="lm", xtol=1e-12)
    assert cost == pytest.approx(2 * ref.cost, rel=1e-7)
    np.testing.assert_allclose(u, ref.x, rtol=1e-5, atol=1e-6)
    # chunked normal equations agree with the dense Jacobian
    jac = jax.jacfwd(lambda x: jnp.asarray(prob.fns.residuals(x, prob.arrays, lay.template)))(
        jnp.asarray(u0)
    )
    prob_small_chunks = Problem(lay, get_loss("wls"), data, chunk=97)
    s, g, a = prob_small_chunks.normal(u0)
    r = np.asarray(prob.fns.residuals(jnp.asarray(u0), prob.arrays, lay.template))  # padded
    np.testing.assert_allclose(a, np.asarray(jac.T @ jac), rtol=1e-9)
    np.testing.assert_allclose(g, np.asarray(jac.T) @ r, rtol=1e-9, atol=1e-12)
    assert s == pytest.approx(r @ r, rel=1e-12)


@pytest.mark.parametrize("method", ["lbfgs", "crs2"])
def test_nlopt_methods_reach_the_lm_optimum(method):
    truth = models.Lambert(albedo=0.5) + TestLobe(rho_s=0.3, n=30.0)
    data, _ = synthetic(truth, n=400, seed=6)
    lay = Layout(models.Lambert() + TestLobe(), 1)
    prob = Problem(lay, get_loss("wls"), data)
    best = optimize(prob, method="lm")
    if method == "lbfgs":
        res = optimize(prob, method="lbfgs", n_starts=2)
    else:
        u, _cost, n, _msg = run_nlopt(prob, lay.initial(), "crs2", maxeval=3000, seed=1)
        res = optimize(prob, method="lm", start=u, n_starts=1)
        assert n > 10
    assert res.cost == pytest.approx(best.cost, rel=1e-6)


def test_multistart_escapes_bad_template():
    truth = models.Lambert(albedo=0.05) + TestLobe(rho_s=0.6, n=400.0)
    data, _ = synthetic(truth, n=1500, seed=8)
    # a start far away (broad lobe, bright diffuse)
    lay = Layout(models.Lambert(albedo=0.9) + TestLobe(rho_s=0.01, n=1.5), 1)
    prob = Problem(lay, get_loss("wls"), data)
    res = optimize(prob, n_starts=8, seed=0)
    vals = lay.values(res.u)
    assert vals["testlobe.n"] == pytest.approx(400.0, rel=0.1)
    assert res.converged


def test_tied_parameters_follow_their_source():
    tmpl = TestLobe(rho_s=0.2, n=10.0) + TestLobe(rho_s=0.1, n=99.0)
    lay = Layout(tmpl, 1, tied={"testlobe2.n": "testlobe.n"})
    assert lay.keys == ["testlobe.rho_s", "testlobe.n", "testlobe2.rho_s"]
    assert float(lay.template.params()["testlobe2.n"]) == 10.0
    u = lay.inverse({"testlobe.n": 42.0})
    m = lay.model(u)
    assert float(m.params()["testlobe2.n"]) == pytest.approx(42.0)
    assert float(lay.to_model(jnp.asarray(u)).params()["testlobe2.n"]) == pytest.approx(42.0)
    with pytest.raises(FitError, match="cannot tie"):
        Layout(tmpl, 1, tied={"testlobe2.n": "testlobe2.n"})


def test_lm_holds_a_parameter_on_its_bound_and_solves_the_rest():
    """A linear least-squares problem whose optimum has one parameter on its upper bound and
    strong coupling to the others: LM must reach the exact bounded optimum (scipy's
    lsq_linear) in a few passes. Clipping the full unbounded step instead bends the other
    parameters at every step (zigzag) and stops far from it or after many passes."""
    from scipy.optimize import lsq_linear

    from gonio.fit.lm import CONVERGED_F, CONVERGED_X, levenberg_marquardt

    rng = np.random.default_rng(3)
    base = rng.normal(size=(200, 4))
    m = base @ np.array(
        [[1.0, 0.9, 0.8, 0.7], [0.0, 0.5, 0.4, 0.3], [0.0, 0.0, 0.3, 0.2], [0.0, 0.0, 0.0, 0.2]]
    )
    b = m @ np.array([0.2, -0.4, 0.6, 2.0]) + 0.01 * rng.normal(size=200)
    lo, hi = np.full(4, -5.0), np.array([5.0, 5.0, 5.0, 1.0])  # the last one wants 2, gets 1
    ref = lsq_linear(m, b, bounds=(lo, hi), tol=1e-14)
    assert ref.x[3] == pytest.approx(1.0)

    def normal(u):
        r = m @ u - b
        return float(r @ r), m.T @ r, m.T @ m

    res = levenberg_marquardt(normal, np.zeros(4), lo, hi, ftol=1e-14, xtol=1e-14)
    assert res.status in (CONVERGED_F, CONVERGED_X)
    np.testing.assert_allclose(res.u, ref.x, rtol=0, atol=1e-8)
    assert res.u[3] == 1.0  # exactly on the bound
    assert res.n_eval <= 12
