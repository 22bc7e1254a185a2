"""Reusable property checks for anything with the model interface (analytic models, tables).

Each ``check_*`` raises AssertionError with a message naming the model and the failing input.
Test modules call them with their own parameter sets.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf import frames
from gonio.brdf.chi2 import chi2_test, model_sampler

EPS1 = float(np.nextafter(np.float32(1.0), np.float32(0.0)))


def random_upper(n: int, seed: int, max_theta: float = np.pi / 2 * 0.999) -> np.ndarray:
    """``n`` directions uniform in (theta, phi) over the upper hemisphere, ``(n, 3)``."""
    rng = np.random.default_rng(seed)
    th = rng.uniform(0, max_theta, n)
    ph = rng.uniform(0, 2 * np.pi, n)
    return np.asarray(frames.spherical_to_direction(th, ph))


def stress_directions() -> np.ndarray:
    """Normal, grazing, exactly-horizon, below-horizon and opposite directions, ``(K, 3)``."""
    th = [0.0, 1e-8, 0.3, 1.0, np.pi / 2 - 1e-7, np.pi / 2, np.pi / 2 + 1e-7, 2.0, np.pi]
    ph = [0.0, 0.5, np.pi, 2 * np.pi - 1e-12]
    t, p = np.meshgrid(th, ph, indexing="ij")
    return np.asarray(frames.spherical_to_direction(t.ravel(), p.ravel()))


def check_reciprocity(model, n: int = 2000, rtol: float = 1e-5, seed: int = 1) -> None:
    wi, wo = random_upper(n, seed), random_upper(n, seed + 1)
    a, b = np.asarray(model.f(wi, wo)), np.asarray(model.f(wo, wi))
    np.testing.assert_allclose(a, b, rtol=rtol, atol=1e-12, err_msg=f"{model!r} not reciprocal")


def check_nonnegative_and_masked(model, n: int = 2000, seed: int = 2) -> None:
    wi, wo = random_upper(n, seed), random_upper(n, seed + 1)
    v = np.asarray(model.f(wi, wo))
    assert v.shape == (n, model.channels), f"{model!r}: f shape {v.shape}"
    assert np.all(np.isfinite(v)) and np.all(v >= 0), f"{model!r}: negative or non-finite f"
    below = wi * [1, 1, -1]
    assert np.all(np.asarray(model.f(below, wo)) == 0), f"{model!r}: f != 0 below the horizon"
    assert np.all(np.asarray(model.pdf(below, wo)) == 0), f"{model!r}: pdf != 0 below horizon"
    assert np.all(np.asarray(model.f(wi, below)) == 0), f"{model!r}: f != 0 for wo below"


def check_isotropy(model, n: int = 1000, seed: int = 3, rtol: float = 1e-5) -> None:
    """f and pdf are invariant under a common rotation about the normal."""
    wi, wo = random_upper(n, seed), random_upper(n, seed + 1)
    ang = np.random.default_rng(seed).uniform(0, 2 * np.pi, (n, 1))
    c, s = np.cos(ang), np.sin(ang)

    def rot(w):
        return np.concatenate(
            [c * w[:, :1] - s * w[:, 1:2], s * w[:, :1] + c * w[:, 1:2], w[:, 2:]], 1
        )

    np.testing.assert_allclose(
        np.asarray(model.f(rot(wi), rot(wo))), np.asarray(model.f(wi, wo)), rtol=rtol, atol=1e-12
    )
    np.testing.assert_allclose(
        np.asarray(model.pdf(rot(wi), rot(wo))),
        np.asarray(model.pdf(wi, wo)),
        rtol=rtol,
        atol=1e-12,
    )


def check_stress(model) -> None:
    """No NaN/Inf from f, pdf or sample on degenerate directions and extreme u."""
    d = stress_directions()
    wi = np.repeat(d, len(d), axis=0)
    wo = np.tile(d, (len(d), 1))
    for arr, what in ((model.f(wi, wo), "f"), (model.pdf(wi, wo), "pdf")):
        arr = np.asarray(arr)
        assert np.all(np.isfinite(arr)), f"{model!r}: non-finite {what}"
        assert np.all(arr >= 0), f"{model!r}: negative {what}"
    below = (wi[:, 2] <= 0) | (wo[:, 2] <= 0)
    assert np.all(np.asarray(model.f(wi, wo))[below] == 0), f"{model!r}: f != 0 below horizon"
    assert np.all(np.asarray(model.pdf(wi, wo))[below] == 0), f"{model!r}: pdf != 0 below"
    us = np.array([[0, 0], [0, EPS1], [EPS1, 0], [EPS1, EPS1], [0.5, 0.5], [1e-12, 0.25]])
    uu = np.tile(us, (len(d), 1))
    ww = np.repeat(d, len(us), axis=0)
    for dtype in (np.float64, np.float32):
        s = model.sample(ww.astype(dtype), uu.astype(dtype))
        for name in ("wi", "pdf", "weight"):
            arr = np.asarray(getattr(s, name))
            assert np.all(np.isfinite(arr)), f"{model!r}: non-finite sample.{name} ({dtype})"
        assert np.all(np.asarray(s.pdf) >= 0)
        assert np.all(np.asarray(s.weight)[ww[:, 2] <= 0] == 0), f"{model!r}: weight for wo below"


def check_properties(model, evaluated=None, isotropic: bool = True) -> None:
    """The property sequence every analytic model passes: reciprocity, non-negativity with the
    lower hemisphere masked, isotropy (when ``isotropic``), stress input, finite parameter
    gradients and sample weights that match f and pdf.

    ``evaluated`` is what the direction checks call (e.g. a :class:`Jitted` wrapper of
    ``model``, one compile per program); the gradient check always takes ``model`` itself.
    """
    e = model if evaluated is None else evaluated
    check_reciprocity(e)
    check_nonnegative_and_masked(e)
    if isotropic:
        check_isotropy(e)
    check_stress(e)
    check_param_gradients(model)
    check_sample_weight_consistent(e)


def check_param_gradients(model, names=None) -> None:
    """jax.grad of f, pdf and sample weight w.r.t. every parameter is finite on stress input.

    The loss and its gradient run under ``jax.jit`` with the model as an argument: the values are
    those of the op-by-op evaluation, and models of one class and shape share one compile.
    """
    d = stress_directions()
    wi = jnp.asarray(np.repeat(d, len(d), axis=0))
    wo = jnp.asarray(np.tile(d, (len(d), 1)))
    u = jnp.asarray(np.random.default_rng(0).random((wi.shape[0], 2)))
    params = model.params()
    chosen = {name: params[name] for name in (names or list(params))}
    for name, g in _param_gradients(model, chosen, wi, wo, u).items():
        g = np.asarray(g)
        assert np.all(np.isfinite(g)), f"{model!r}: non-finite gradient w.r.t. {name}"


@jax.jit
def _param_gradients(model, chosen, wi, wo, u):
    def loss(values):
        m = model.replace(**values)
        s = m.sample(wo, u)
        return jnp.sum(m.f(wi, wo)) + jnp.sum(m.pdf(wi, wo)) + jnp.sum(s.weight) + jnp.sum(s.pdf)

    return jax.grad(loss)(chosen)


def check_sample_weight_consistent(model, n: int = 4000, seed: int = 4) -> None:
    """``weight == f cos / pdf`` and ``pdf == model.pdf(wi, wo)`` for the samples drawn."""
    wo = random_upper(n, seed, max_theta=np.radians(85))
    u = np.random.default_rng(seed).random((n, 2))
    s = model.sample(wo, u)
    ok = np.asarray(s.pdf) > 0
    # f and pdf at every sample, compared where it succeeded: one input shape per n (a jitted
    # model compiles once, not once per count of successful samples)
    pdf, f = np.asarray(model.pdf(s.wi, wo))[ok], np.asarray(model.f(s.wi, wo))[ok]
    wi = np.asarray(s.wi)[ok]
    np.testing.assert_allclose(np.asarray(s.pdf)[ok], pdf, rtol=1e-4, atol=1e-10)
    expect = f * wi[:, 2:3] / np.asarray(s.pdf)[ok][:, None]
    np.testing.assert_allclose(np.asarray(s.weight)[ok], expect, rtol=1e-4, atol=1e-10)


#: The chi-square grid of a test that chooses neither its sample count nor its cells: 500,000
#: samples on cells of 2 x 4 degrees (45 x 90; chi2_test's own default is 1,000,000 on 1 x 2
#: degree cells). A density error whose relative size is even over such a cell adds
#: n * sum((p' - p)^2 / p) to the statistic's mean, the same sum on either grid, and the critical
#: excess over the mean grows as sqrt(2 * dof): half the samples need half the excess, which a
#: quarter of the cells gives, so the power against such errors is kept at half the draws. The
#: expected counts are integrated with 12 Gauss-Legendre nodes per cell and dimension, the node
#: spacing of chi2_test's default (6 per 1 x 2 degree cell), so a lobe a fraction of a degree
#: wide (Phong n = 20000) is integrated about as finely as there. Tests that a wrong sampler
#: fails name their sample count and keep chi2_test's cells.
CHI2_DEFAULTS = {"n_samples": 500_000, "res_theta": 45, "res_phi": 90, "order": 12}
_CHI2_CHOICES = ("n_samples", "res_theta", "res_phi", "axis", "theta_max", "mirror_cap")


def chi2_kwargs(kw: dict) -> dict:
    """``kw`` with :data:`CHI2_DEFAULTS` filled in where it chooses no count or cells."""
    if any(k in kw for k in _CHI2_CHOICES):
        return {"n_samples": 1_000_000, **kw}
    return {**CHI2_DEFAULTS, **kw}


def check_chi2(model, theta_o_deg, n_tests: int, mirror_cap=None, **kw) -> None:
    """Chi-square test of ``model.sample`` against ``model.pdf`` at each theta_o (phi_o = 0.3).

    ``mirror_cap`` (radians): histogram in a frame centred on the mirror direction of ``wo``,
    over a cap of that angular radius (for sharp lobes; see :func:`chi2_test`'s ``axis``).
    Without ``n_samples`` and cells, the grid is :data:`CHI2_DEFAULTS`.
    """
    kw = chi2_kwargs({**kw, **({} if mirror_cap is None else {"mirror_cap": mirror_cap})})
    kw.pop("mirror_cap", None)
    for t in theta_o_deg:
        wo = np.asarray(frames.spherical_to_direction(np.radians(t), 0.3))
        sample, pdf = model_sampler(model, wo)
        cap = {}
        if mirror_cap is not None:
            cap = {"axis": wo * np.array([-1.0, -1.0, 1.0]), "theta_max": mirror_cap}
        r = chi2_test(sample, pdf, n_tests=n_tests, **kw, **cap)
        assert r.passed, f"{model!r} at theta_o={t} deg: {r.message}"


def check_albedo_at_most_one(model, theta_o_deg=(0, 30, 60, 85), tol: float = 1e-3) -> np.ndarray:
    """Directional albedo <= 1 + tol at each theta_o; returns the albedos ``(K, C)``."""
    wo = np.asarray(frames.spherical_to_direction(np.radians(np.asarray(theta_o_deg)), 0.0))
    a = np.asarray(model.directional_albedo(wo, n=256))
    assert np.all(a <= 1 + tol), f"{model!r}: directional albedo {a.max():.4f} > 1"
    return a


class Jitted:
    """A model whose ``f``, ``pdf``, ``sample`` and ``directional_albedo`` are ``jax.jit``-ed.

    The checks above call the model eagerly on many shapes; op-by-op dispatch then dominates the
    test time. Wrapping a model (``check_stress(Jitted(m))``) gives the same results several times
    faster. Everything else (``params``, ``replace``, ``channels``...) is the model's own.
    """

    def __init__(self, model) -> None:
        self.model = model

    # the model is an argument (a pytree), so models of one class and shape share a compile; the
    # rows are padded to a few fixed counts (_padded), so the checks' many batch sizes share it too
    def f(self, wi, wo):
        return _padded(_jit_f, self.model, wi, wo)

    def pdf(self, wi, wo):
        return _padded(_jit_pdf, self.model, wi, wo)

    def sample(self, wo, u):
        return _padded(_jit_sample, self.model, wo, u)

    def directional_albedo(self, wo, n):
        return _jit_albedo(self.model, wo, n)

    def __getattr__(self, name):
        return getattr(self.model, name)

    def __repr__(self) -> str:
        return repr(self.model)


#: Batches of up to this many rows are evaluated as this many (then as the next power of two).
PAD_ROWS = 4096


def _padded(fn, model, a, b):
    """``fn(model, a, b)`` on ``(n, k)`` arrays padded with copies of their first row to
    :data:`PAD_ROWS` rows (or the next power of two), cut back to ``n`` rows. Each row is
    evaluated on its own, so padding changes no value, only the number of compiled shapes."""
    a, b = jnp.asarray(a), jnp.asarray(b)
    n = a.shape[0] if a.ndim == 2 else 0
    if n == 0 or b.ndim != 2 or b.shape[0] != n:
        return fn(model, a, b)
    rows = max(PAD_ROWS, 1 << (n - 1).bit_length())
    pad = [(0, rows - n), (0, 0)]
    out = fn(model, jnp.pad(a, pad, mode="edge"), jnp.pad(b, pad, mode="edge"))
    return jax.tree_util.tree_map(lambda x: x[:n], out)


_jit_f = jax.jit(lambda model, wi, wo: model.f(wi, wo))
_jit_pdf = jax.jit(lambda model, wi, wo: model.pdf(wi, wo))
_jit_sample = jax.jit(lambda model, wo, u: model.sample(wo, u))
_jit_albedo = jax.jit(lambda model, wo, n: model.directional_albedo(wo, n), static_argnums=2)
