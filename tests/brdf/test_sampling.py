"""Tests of gonio.brdf.sampling.distributions (distributions, alias tables, rejection) and of
table sampling.

Statistical tests use fixed seeds; chi-square tests run at a family-wise level of 0.01 with a
Sidak correction over the tests of each group (N_DISCRETE, N_TABLE).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from gonio.brdf import frames
from gonio.brdf.chi2 import chi2_test
from gonio.brdf.sampling.distributions import (
    AliasTable,
    Distribution1D,
    Distribution2D,
    hash_uniform,
    rejection_sample_traced,
    seeds_from_u,
)
from gonio.brdf.tabulated import Axis, TabulatedBRDF
from gonio.errors import ParameterError
from tests.brdf.model_checks import CHI2_DEFAULTS
from tests.brdf.test_tabulated import _GGXLike

HALF = math.pi / 2
N_DISCRETE = 9  # statistical tests on discrete outcomes in this module
N_TABLE = 16  # chi-square tests of table samplers (default + slow)
SIDAK_DISCRETE = 1 - (1 - 0.01) ** (1 / N_DISCRETE)


def _pearson(counts: np.ndarray, probs: np.ndarray) -> float:
    n = counts.sum()
    keep = probs > 0
    assert counts[~keep].sum() == 0, "outcomes of probability 0 were drawn"
    exp = probs[keep] * n
    assert exp.min() >= 5, "test design: expected counts too small"
    return float(stats.chisquare(counts[keep], exp).pvalue)


def _weights(shape, seed):
    rng = np.random.default_rng(seed)
    w = rng.uniform(0.05, 1.0, shape) ** 2
    w[rng.random(shape) < 0.1] = 0.0
    return w


# -- discrete distributions ---------------------------------------------------------------------
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_distribution1d_chi2_and_pdf(dtype):
    w = _weights(50, 1)
    d = Distribution1D(w)
    u = np.random.default_rng(2).random(1_000_000).astype(dtype)
    x, pdf, k = d.sample(u)
    counts = np.bincount(np.asarray(k), minlength=50)
    assert _pearson(counts, w / w.sum()) > SIDAK_DISCRETE
    assert x.dtype == dtype and pdf.dtype == dtype
    np.testing.assert_allclose(np.asarray(d.pdf(x)), np.asarray(pdf), rtol=1e-6)
    # the continuous position lands in the sampled bin (edges k / n in the sample's precision)
    kk, xx = np.asarray(k).astype(dtype), np.asarray(x)
    assert np.all((kk / dtype(50) <= xx) & (xx < (kk + 1) / dtype(50)))
    # pdf integrates to 1
    grid = (np.arange(50) + 0.5) / 50
    assert np.sum(np.asarray(d.pdf(grid))) / 50 == pytest.approx(1.0, abs=1e-6)


def test_distribution2d_chi2_and_batches():
    w = _weights((3, 12, 20), 3)
    d = Distribution2D(w)
    rng = np.random.default_rng(4)
    which = rng.integers(0, 3, 1_000_000)
    xy, pdf, (iy, ix) = d.sample(rng.random((1_000_000, 2)), which)
    np.testing.assert_allclose(np.asarray(d.pdf(xy, which)), np.asarray(pdf), rtol=1e-9)
    for b in range(3):
        sel = np.asarray(which) == b
        cells = np.asarray(iy)[sel] * 20 + np.asarray(ix)[sel]
        counts = np.bincount(cells, minlength=240)
        p = w[b] / w[b].sum()
        assert _pearson(counts, p.ravel()) > 1 - (1 - SIDAK_DISCRETE) ** (1 / 3)
    np.testing.assert_allclose(d.probs.sum(axis=(1, 2)), 1.0)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_alias_table_chi2(dtype):
    w = _weights(300, 5)
    a = AliasTable(w)
    np.testing.assert_allclose(a.probs, w / w.sum(), atol=1e-12)
    u = np.random.default_rng(6).random(1_000_000).astype(dtype)
    k, r, p = a.sample_discrete(u)
    k = np.asarray(k)
    counts = np.bincount(k, minlength=300)
    assert _pearson(counts, w / w.sum()) > SIDAK_DISCRETE
    np.testing.assert_allclose(np.asarray(p), (w / w.sum())[k], rtol=1e-5)
    # the remapped number is uniform again (used to place the sample inside its cell)
    assert stats.kstest(np.asarray(r, np.float64), "uniform").pvalue > SIDAK_DISCRETE


def test_alias_two_numbers_keep_rare_outcomes_right_in_float32():
    """8192 outcomes, half of them 1e4 times rarer (keep thresholds 2e-4 < 2**-11): drawn with
    float32 numbers, the rare half must come up with its probability. Splitting one float32
    over 8192 columns leaves 11 bits for the keep decision and draws them 2.4x too often."""
    from gonio.brdf.sampling.distributions import alias_sample_2d

    n = 8192
    w = np.where(np.arange(n) % 2 == 0, 1.0, 1e-4)
    a = AliasTable(w)
    u = np.random.default_rng(12).random((1_000_000, 2)).astype(np.float32)
    base = jnp.zeros(u.shape[0], jnp.int32)
    k, _, _, _ = alias_sample_2d(
        a._q[jnp.float32], a._alias, a._p[jnp.float32], base, n, u[:, 0], u[:, 1]
    )
    rare = int(np.sum(np.asarray(k) % 2 == 1))
    p_rare = float(a.probs[1::2].sum())
    assert stats.binomtest(rare, u.shape[0], p_rare).pvalue > SIDAK_DISCRETE, (rare, p_rare)


def test_alias_table_batched():
    w = _weights((4, 30), 7)
    a = AliasTable(w)
    rng = np.random.default_rng(8)
    which = rng.integers(0, 4, 400_000)
    k, _, p = a.sample_discrete(rng.random(400_000), which)
    k, which = np.asarray(k), np.asarray(which)
    np.testing.assert_allclose(np.asarray(p), (w / w.sum(1, keepdims=True))[which, k], rtol=1e-9)
    counts = np.bincount(which * 30 + k, minlength=120).reshape(4, 30)
    stat = sum(
        stats.chisquare(
            counts[b][w[b] > 0], (w[b] / w[b].sum())[w[b] > 0] * counts[b].sum()
        ).statistic
        for b in range(4)
    )
    dof = int((w > 0).sum()) - 4
    assert stats.chi2.sf(stat, dof) > SIDAK_DISCRETE


def test_hash_uniform_is_uniform_and_deterministic():
    seeds = seeds_from_u(jnp.asarray(np.random.default_rng(9).random((200_000, 2))))
    x = np.asarray(hash_uniform(seeds, 7, jnp.float64))
    assert x.min() >= 0 and x.max() < 1
    counts = np.histogram(x, bins=100, range=(0, 1))[0]
    assert _pearson(counts, np.full(100, 0.01)) > SIDAK_DISCRETE
    np.testing.assert_array_equal(np.asarray(hash_uniform(seeds, 7, jnp.float64)), x)
    y = np.asarray(hash_uniform(seeds, 8, jnp.float64))
    assert abs(np.corrcoef(x, y)[0, 1]) < 0.01


def _cubic_round(dummy, up, ua):
    """One uniform proposal on [0, 1), accepted with probability x^2: target 3 x^2."""
    x = up[:, 0]
    return x[:, None], ua < x * x


def _sequential_reference(u, seeds, max_rounds):
    """Query by query, proposal by proposal: what rejection_sample_traced must return for the
    target 3 x^2 (the counters of its documentation)."""
    n = u.shape[0]
    x = np.zeros(n)
    rounds = np.zeros(n, int)
    ok = np.zeros(n, bool)
    pending = np.arange(n)
    for r in range(max_rounds):
        if r == 0:
            up0 = u[:, 0]
            ua = np.asarray(hash_uniform(jnp.asarray(seeds), 2, jnp.float64))
        else:
            up0 = np.asarray(hash_uniform(jnp.asarray(seeds), 3 * r, jnp.float64))
            ua = np.asarray(hash_uniform(jnp.asarray(seeds), 3 * r + 2, jnp.float64))
        acc = ua[pending] < up0[pending] ** 2
        x[pending] = up0[pending]
        rounds[pending] = r + 1
        ok[pending[acc]] = True
        pending = pending[~acc]
    return x, ok, rounds


@pytest.mark.parametrize("max_rounds", [1, 3, 4096])
@pytest.mark.parametrize("n", [700, 5000])
def test_rejection_sample_traced_matches_sequential_rounds(max_rounds, n):
    """Under jit the compacting while loop (lanes of pending queries, several proposals each
    when few are left) gives the same samples, flags and counts as query-by-query rounds."""
    u = np.random.default_rng(12).random((n, 2))
    seeds = seeds_from_u(jnp.asarray(u))
    run = jax.jit(
        lambda uu, s: rejection_sample_traced(_cubic_round, (jnp.zeros(n),), uu, s, max_rounds)
    )
    x, ok, rounds = run(jnp.asarray(u), seeds)
    x_ref, ok_ref, rounds_ref = _sequential_reference(u, np.asarray(seeds), min(max_rounds, 60))
    np.testing.assert_array_equal(np.asarray(ok), ok_ref)
    np.testing.assert_array_equal(np.asarray(rounds), rounds_ref)
    np.testing.assert_array_equal(np.asarray(x)[:, 0], x_ref)


def test_bad_weights():
    with pytest.raises(ParameterError):
        Distribution1D([1.0, -1.0])
    with pytest.raises(ParameterError):
        AliasTable([np.nan, 1.0])
    with pytest.raises(ParameterError):
        Distribution2D([1.0, 2.0])
    with pytest.raises(ParameterError, match="which"):
        Distribution1D(np.ones((2, 3))).sample(0.5)


# -- table sampling -----------------------------------------------------------------------------
def _axes(n=45):
    return (
        Axis("theta_h", n, 0.0, HALF, "sqrt"),
        Axis("theta_d", n, 0.0, HALF),
        Axis("phi_d", n, 0.0, math.pi, periodic=True),
    )


@pytest.fixture(scope="module")
def glossy():
    return TabulatedBRDF.from_model(_GGXLike(kd=0.2, ks=0.7, alpha=0.25), axes=_axes())


@pytest.fixture(scope="module")
def rough():
    return TabulatedBRDF.from_model(_GGXLike(kd=0.2, ks=0.7, alpha=0.5), axes=_axes())


def _chi2(table, theta_o_deg, method, proposal="majorant", phi_o=0.0):
    wo = np.asarray(frames.spherical_to_direction(math.radians(theta_o_deg), phi_o))

    def sample(u):
        s = table.sample(wo, u, method=method, proposal=proposal)
        return np.asarray(s.wi), np.asarray(s.pdf)

    def pdf(wi):
        return np.asarray(table.pdf(wi, wo, method=method, proposal=proposal))

    if method != "rejection":
        # inversion/alias densities are constant on the sampler's 64 x 128 (theta, phi - phi_o)
        # grid: histogram on the same grid so the expected counts are integrated exactly
        kw = {"n_samples": 1_000_000, "res_theta": 64, "res_phi": 128}
    else:
        # Rejection draws are the costly ones: the grid of model_checks.CHI2_DEFAULTS (half the
        # samples on a quarter of the cells, the same power against a density error even over
        # a cell; see there)
        kw = CHI2_DEFAULTS
    r = chi2_test(sample, pdf, n_tests=N_TABLE, **kw)
    assert r.passed, f"{method} at theta_o={theta_o_deg}: {r.message}"
    assert r.pdf_integral <= 1 + 1e-3
    return r


# 45 deg adds little to normal and grazing incidence and costs its own compilations (each
# outgoing bucket is a new program): it runs with -m slow
@pytest.mark.parametrize("theta_o", [0, pytest.param(45, marks=pytest.mark.slow), 85])
def test_inversion_chi2(glossy, theta_o):
    _chi2(glossy, theta_o, "inversion")


@pytest.mark.parametrize("theta_o", [30, 85])
def test_alias_chi2(glossy, theta_o):
    _chi2(glossy, theta_o, "alias")


def test_rejection_chi2_cosine(rough):
    _chi2(rough, 40, "rejection", proposal="cosine")


@pytest.mark.slow
@pytest.mark.parametrize("theta_o", [0, 85])
def test_rejection_chi2_cosine_slow(rough, theta_o):
    _chi2(rough, theta_o, "rejection", proposal="cosine")


@pytest.mark.parametrize("theta_o", [0, pytest.param(45, marks=pytest.mark.slow), 85])
def test_rejection_chi2_majorant(glossy, theta_o):
    """The default proposal: exact sampling of g cos on the glossy table."""
    _chi2(glossy, theta_o, "rejection", proposal="majorant")


def test_majorant_bounds_g_cos_and_acceptance(glossy):
    """The per-cell bound of the majorant proposal is never exceeded by ``g cos`` for outgoing
    directions anywhere in a bucket, and it is tight enough to accept often."""
    from gonio.brdf.sampling.table_buckets import bucket_ranges
    from gonio.brdf.sampling.table_buckets import cell_of as _cell_of

    smp = glossy._sampler().rejection
    geo = smp.geo_major
    rng = np.random.default_rng(7)
    cos_asc = jnp.asarray(smp.cos_desc_major[::-1].copy())
    worst = 0.0
    for b in (0, geo.n_to // 2, geo.n_to - 2, geo.n_to - 1):
        maj = smp._majorant(b)
        t0, t1, _, _ = bucket_ranges(smp.geo, b)
        n = 200_000
        th_o = rng.uniform(t0, t1, n)
        wo = np.asarray(frames.spherical_to_direction(th_o, rng.uniform(0, 2 * math.pi, n)))
        z = rng.uniform(0, 1, n)
        phi = rng.uniform(0, 2 * math.pi, n)
        r = np.sqrt(1 - z * z)
        wi = np.stack([r * np.cos(phi), r * np.sin(phi), z], -1)
        # half of them within a few degrees of the mirror direction, where the lobe peaks and
        # (at grazing angles) the half-vector bounds are hardest
        k = n // 2
        mirror = wo[:k] * np.array([-1.0, -1.0, 1.0])
        near = mirror + rng.normal(0, math.radians(2.0), (k, 3))
        near[:, 2] = np.abs(near[:, 2])
        wi[:k] = near / np.linalg.norm(near, axis=-1, keepdims=True)
        row, col = _cell_of(geo, jnp.asarray(wi), jnp.asarray(wo), cos_asc)
        cell = np.asarray(row) * geo.n_p + np.asarray(col)
        g = np.maximum(np.asarray(glossy.f(wi, wo)).mean(-1), 0) * wi[:, 2]
        worst = max(worst, float(np.max(g / maj["bound"][cell])))
    assert worst <= 1.0, f"g cos exceeds the majorant by {worst:.4f}x"
    wo = np.asarray(frames.spherical_to_direction(math.radians(45), 0.0))
    glossy.sample(wo, np.random.default_rng(3).random((20_000, 2)), method="rejection")
    acceptance = smp.stats["rejection_samples"] / smp.stats["rejection_proposals"]
    assert acceptance > 0.3, f"majorant acceptance {acceptance:.3f}"


# the bucket lookup is shared by both proposals; the cosine one runs with -m slow
@pytest.mark.parametrize("proposal", ["majorant", pytest.param("cosine", marks=pytest.mark.slow)])
def test_rejection_on_a_bucket_edge(proposal):
    """Proposals run in float32: a float64 direction on a bucket edge (45 degrees is the edge
    between buckets 7 and 8 of 16) rounds into the lower bucket there. Its structures must be
    built and used, whatever other buckets are already built."""

    def table():
        model = _GGXLike(kd=0.2, ks=0.7, alpha=0.3)
        return TabulatedBRDF.from_model(model, axes=_axes(16), sampling_res=(16, 32, 64))

    wo = np.asarray(frames.spherical_to_direction(math.radians(45), 0.0))
    u = np.random.default_rng(4).random((2000, 2))
    fresh = table().sample(wo, u, method="rejection", proposal=proposal)
    t = table()
    t.sample(np.array([0.0, 0.0, 1.0]), u[:4], method="rejection", proposal=proposal)
    after = t.sample(wo, u, method="rejection", proposal=proposal)
    np.testing.assert_array_equal(np.asarray(after.wi), np.asarray(fresh.wi))


@pytest.mark.parametrize("proposal", ["majorant", "cosine"])
def test_rejection_of_a_black_table_fails_at_once(proposal):
    """g = 0 everywhere: each query fails (pdf and weight 0) after one proposal, not after
    max_rounds rejected ones."""
    t = TabulatedBRDF(
        np.zeros((12, 12, 12, 3), np.float32), axes=_axes(12), sampling_res=(4, 8, 16)
    )
    wo = np.asarray(frames.spherical_to_direction(np.radians([10.0, 50.0, 80.0]), 0.4))
    u = np.random.default_rng(2).random((3, 2))
    s = t.sample(wo, u, method="rejection", proposal=proposal)
    assert np.all(np.asarray(s.pdf) == 0) and np.all(np.asarray(s.weight) == 0)
    stats = t._sampler().stats
    assert stats["rejection_proposals"] == stats["rejection_samples"] == 3


def test_rejection_refuses_an_analytic_proposal():
    """Exact rejection needs a rigorous bound of g cos / q: an analytic model's density gives
    none, so a model is refused as a proposal with a one-line error (sample by the model)."""
    t = TabulatedBRDF.from_model(_GGXLike(), axes=_axes(12), sampling_res=(4, 16, 32))
    msg = "proposal must be 'majorant' or 'cosine'"
    with pytest.raises(ParameterError, match=msg):
        t.sample([0, 0, 1.0], [0.5, 0.5], method="rejection", proposal=_GGXLike())
    with pytest.raises(ParameterError, match=msg):
        t.pdf([0, 0, 1.0], [0, 0, 1.0], method="rejection", proposal=_GGXLike())


@pytest.mark.slow
def test_anisotropic_table_samplers():
    axes = (
        Axis("theta_h", 24, 0.0, HALF, "sqrt"),
        Axis("phi_h", 24, 0.0, 2 * math.pi, periodic=True),
        Axis("theta_d", 24, 0.0, HALF),
        Axis("phi_d", 48, 0.0, 2 * math.pi, periodic=True),
    )
    t = TabulatedBRDF.from_model(
        _GGXLike(alpha=0.45),
        axes=axes,
        parameterization="half_diff_aniso",
        sampling_res=(8, 32, 64),
    )
    wo = np.asarray(frames.spherical_to_direction(math.radians(50), 0.0))
    for method in ("inversion", "alias", "rejection"):

        def sample(u, method=method):
            s = t.sample(wo, u, method=method)
            return np.asarray(s.wi), np.asarray(s.pdf)

        r = chi2_test(
            sample,
            lambda wi, method=method: np.asarray(t.pdf(wi, wo, method=method)),
            n_samples=1_000_000,
            n_tests=N_TABLE,
            res_theta=32,
            res_phi=64,
        )
        assert r.passed, f"anisotropic {method}: {r.message}"
    assert t.sampling_buckets("inversion") == [int(50 / 90 * 8) * 16 + 0]


@pytest.fixture(scope="module")
def rough24():
    """A rough table with six theta_o buckets, and 3000 queries over all of them."""
    table = TabulatedBRDF.from_model(
        _GGXLike(kd=0.2, ks=0.7, alpha=0.5), axes=_axes(24), sampling_res=(6, 32, 64)
    )
    rng = np.random.default_rng(11)
    n = 3000
    th = rng.uniform(0, math.radians(85), n)
    wo = np.asarray(frames.spherical_to_direction(th, rng.uniform(0, 2 * math.pi, n)))
    return table, wo, rng.random((n, 2))


def _check_weight_and_pdf(table, wo, u, method, proposal, dtype):
    """``pdf`` equals ``table.pdf`` at the sample and ``weight`` equals ``f cos / pdf``, in the
    input's precision (float32 in, float32 out; rejection then reuses the f its acceptance test
    looked up). ``pdf`` and ``f`` are evaluated at every sample and compared where it succeeded:
    one input shape per call, not one compile per count of successful samples."""
    wo, u = wo.astype(dtype), u.astype(dtype)
    s = table.sample(wo, u, method=method, proposal=proposal)
    assert s.wi.dtype == dtype and s.pdf.dtype == dtype
    ok = np.asarray(s.pdf) > 0
    assert ok.mean() > 0.99
    pdf = np.asarray(table.pdf(s.wi, wo, method=method))[ok]
    f = np.asarray(table.f(s.wi, wo))[ok]
    wi, got = np.asarray(s.wi)[ok], np.asarray(s.pdf)[ok]
    np.testing.assert_allclose(pdf, got, rtol=1e-5)
    np.testing.assert_allclose(np.asarray(s.weight)[ok], f * wi[:, 2:3] / got[:, None], rtol=1e-5)


SAMPLERS = [
    ("inversion", "majorant"),
    ("alias", "majorant"),
    ("rejection", "majorant"),
    ("rejection", "cosine"),
]


def test_sample_weight_and_pdf_consistency(rough24):
    """Every sampler in float64, and rejection (the default proposal) in float32; the other
    samplers in float32 are in the slow test (each sampler and precision is a compile of its
    own, ~8 s for rejection on this suite's machine)."""
    table, wo, u = rough24
    for method, proposal in SAMPLERS:
        _check_weight_and_pdf(table, wo, u, method, proposal, np.float64)
    _check_weight_and_pdf(table, wo[:500], u[:500], "rejection", "majorant", np.float32)


@pytest.mark.slow
@pytest.mark.parametrize(("method", "proposal"), SAMPLERS[:2] + SAMPLERS[3:])
def test_sample_weight_and_pdf_consistency_float32(rough24, method, proposal):
    table, wo, u = rough24
    _check_weight_and_pdf(table, wo[:500], u[:500], method, proposal, np.float32)


def test_laziness_and_cache():
    t = TabulatedBRDF.from_model(_GGXLike(), axes=_axes(20), sampling_res=(16, 32, 64))
    assert t.sampling_cache_size() == 0
    wo = np.asarray(frames.spherical_to_direction(math.radians(30), 1.0))
    wi = np.asarray(frames.spherical_to_direction(math.radians(20), 2.0))
    t.f(wi, wo)  # evaluation never builds sampling structures
    assert t.sampling_cache_size() == 0
    t.pdf(wi, wo, method="inversion")
    assert t.sampling_buckets("inversion") == [int(30 / 90 * 16)]
    assert t.sampling_cache_size("alias") == 0 and t.sampling_cache_size("rejection") == 0
    # many directions in the same bucket, and in one more
    wos = np.asarray(frames.spherical_to_direction(np.radians([30.5, 31.0, 31.9, 80.0]), 0.3))
    t.sample(wos, np.full((4, 2), 0.5), method="inversion")
    assert t.sampling_buckets("inversion") == [int(30 / 90 * 16), int(80 / 90 * 16)]
    t.sample(wos[:1], np.full((1, 2), 0.5), method="alias")
    assert t.sampling_cache_size("alias") == 1
    # a pytree round trip shares the cache
    leaves, tree = jax.tree_util.tree_flatten(t)
    t2 = jax.tree_util.tree_unflatten(tree, leaves)
    assert t2.sampling_cache_size("inversion") == 2


def test_sampling_under_jit_builds_every_bucket():
    t = TabulatedBRDF.from_model(_GGXLike(), axes=_axes(12), sampling_res=(4, 16, 32))
    wo = jnp.asarray(frames.spherical_to_direction(0.4, 0.2))
    u = jnp.asarray(np.random.default_rng(0).random((64, 2)))
    for method in ("inversion", "alias"):
        eager = t.sample(wo, u, method=method)
        jitted = jax.jit(lambda w, uu, m=method: t.sample(w, uu, method=m))(wo, u)
        np.testing.assert_allclose(np.asarray(jitted.wi), np.asarray(eager.wi), rtol=1e-12)
        np.testing.assert_allclose(np.asarray(jitted.pdf), np.asarray(eager.pdf), rtol=1e-12)
        # the table is looked up at the sampled wi by a different path under jit
        np.testing.assert_allclose(np.asarray(jitted.weight), np.asarray(eager.weight), rtol=1e-12)
        assert t.sampling_cache_size(method) == 4


# float32 (the renderer's precision, where rounding differs most) by default; float64 with -m slow
@pytest.mark.parametrize("dtype", [np.float32, pytest.param(np.float64, marks=pytest.mark.slow)])
def test_rejection_under_jit_matches_eager(dtype):
    """Traced or eager, rejection runs the same compacting while loop
    (:func:`rejection_sample_traced`): the same proposals (same counters), so the same samples
    up to float rounding (XLA fuses the two programs differently)."""
    t = TabulatedBRDF.from_model(_GGXLike(alpha=0.3), axes=_axes(12), sampling_res=(4, 16, 32))
    rng = np.random.default_rng(3)
    wo = np.asarray(frames.spherical_to_direction(rng.uniform(0, 1.4, 500), 0.3), dtype)
    u = rng.random((500, 2)).astype(dtype)
    eager = t.sample(wo, u, method="rejection")
    jitted = jax.jit(lambda w, uu: t.sample(w, uu, method="rejection"))(wo, u)
    np.testing.assert_allclose(np.asarray(jitted.wi), np.asarray(eager.wi), atol=1e-6)
    np.testing.assert_allclose(np.asarray(jitted.pdf), np.asarray(eager.pdf), rtol=1e-5)
    np.testing.assert_allclose(np.asarray(jitted.weight), np.asarray(eager.weight), rtol=1e-5)


def test_rejection_randomness():
    t = TabulatedBRDF.from_model(_GGXLike(alpha=0.5), axes=_axes(12), sampling_res=(4, 16, 32))
    wo = np.asarray(frames.spherical_to_direction(0.7, 0.0))
    u = np.random.default_rng(1).random((2000, 2))
    a = t.sample(wo, u, method="rejection")
    b = t.sample(wo, u, method="rejection")
    np.testing.assert_array_equal(np.asarray(a.wi), np.asarray(b.wi))  # default: derived from u
    c = t.sample(wo, u, method="rejection", rng=np.random.default_rng(5))
    d = t.sample(wo, u, method="rejection", rng=5)
    np.testing.assert_array_equal(np.asarray(c.wi), np.asarray(d.wi))
    assert not np.array_equal(np.asarray(a.wi), np.asarray(c.wi))
    assert np.all(np.asarray(a.pdf) > 0)


def test_horizon_and_bad_arguments():
    t = TabulatedBRDF.from_model(_GGXLike(), axes=_axes(12), sampling_res=(4, 16, 32))
    below = np.array([0.6, 0.0, -0.8])
    for method in ("inversion", "alias", "rejection"):
        s = t.sample(below, [0.3, 0.3], method=method)
        assert float(s.pdf) == 0 and np.all(np.asarray(s.weight) == 0)
        assert float(t.pdf([0, 0, 1.0], below, method=method)) == 0
        assert float(t.pdf(below, [0, 0, 1.0], method=method)) == 0
    with pytest.raises(ParameterError, match="method"):
        t.sample([0, 0, 1.0], [0.5, 0.5], method="metropolis")
    with pytest.raises(ParameterError, match="proposal"):
        t.sample([0, 0, 1.0], [0.5, 0.5], method="rejection", proposal="uniform")
    with pytest.raises(ParameterError, match="rng"):
        t.sample([0, 0, 1.0], [0.5, 0.5], method="rejection", rng="seed")
    with pytest.raises(ParameterError, match="sampling_res"):
        TabulatedBRDF.from_model(_GGXLike(), axes=_axes(12), sampling_res=(4, 0, 32))
