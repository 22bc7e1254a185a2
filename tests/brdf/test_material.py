"""The material interface (gonio.brdf.material): every material answers the same members, and a
material bound to a sampling method is a pytree whose sample/pdf are the plain interface."""

import jax
import numpy as np
import pytest

from gonio.brdf import models
from gonio.brdf.grid import Channels
from gonio.brdf.gridding import render_axes
from gonio.brdf.material import GENERIC_METHODS, Material
from gonio.brdf.sampled import CosineSampled, LobeSampled, TableSampled
from gonio.brdf.tabulated import TabulatedBRDF
from gonio.errors import ParameterError


@pytest.fixture(scope="module")
def table():
    # sampling structures for 8 outgoing buckets of 32 x 64 cells (the default is 32 of 64 x 128):
    # the tests compare a bound material with the table it binds, whatever the resolution, and
    # each bucket the 64 random directions fall into is built for every sampling method
    axes = render_axes(32, 16, 16)
    return TabulatedBRDF.from_model(models.Lambert([0.2, 0.4, 0.6]) + models.Phong(0.0, 0.5, 20.0),
                                    axes=axes, sampling_res=(8, 32, 64))  # fmt: skip


def _dirs(n, seed):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2]) + 0.1
    return (v / np.linalg.norm(v, axis=1, keepdims=True)).astype(np.float32)


def test_every_material_answers_the_same_members(table):
    mirror = models.Lambert(0.3) + models.SpecularReflection()
    cases = [
        (models.Lambert(0.5), 1, "mono", False, ("native",)),
        (models.Lambert([0.1, 0.2, 0.3]), 3, "rgb", False, ("native",)),
        (mirror, 1, "mono", True, ("native",)),
        (models.Scaled(models.Phong(0.0, 0.5, 10.0), [1.0, 2.0, 3.0]), 3, "rgb", False,
         ("native",)),
        (table, 3, "rgb", False, ("inversion", "alias", "rejection")),
    ]  # fmt: skip
    for m, c, kind, delta, methods in cases:
        assert isinstance(m, Material)
        assert isinstance(m.n_channels, int) and m.n_channels == c
        assert isinstance(m.channel_info, Channels) and m.channel_info.kind == kind
        assert m.has_delta is delta
        assert tuple(m.sampling_methods) == methods
        assert m.broadcasts_outgoing is False
    spectral = models.Lambert(np.linspace(0.1, 0.5, 5))
    assert spectral.n_channels == 5 and spectral.channel_info is None
    assert set(GENERIC_METHODS) == {"cosine", "lobe"}


def test_select_channels(table):
    m = models.Lambert([0.1, 0.2, 0.3]) + models.Phong(0.0, 0.5, 10.0)
    wi, wo = _dirs(16, 1), _dirs(16, 2)
    cut = m.select_channels(np.array([2]))
    assert cut.n_channels == 1
    np.testing.assert_allclose(cut.f(wi, wo)[..., 0], m.f(wi, wo)[..., 2], rtol=1e-6)
    one = table.select_channels(np.array([1]))
    assert one.n_channels == 1 and one.channel_info.names == ("G",)
    assert table.select_channels(np.array([0, 1, 2])) is table
    assert table.select_channels(np.array([0, 2])) is None  # no description for two of RGB


def test_a_model_is_its_own_bound_material():
    m = models.Lambert(0.5)
    assert m.with_sampling() is m and m.with_sampling("native") is m
    with pytest.raises(ParameterError, match="inversion"):
        m.with_sampling("inversion")
    with pytest.raises(ParameterError):
        m.with_sampling("native", proposal=models.Lambert(0.2))


@pytest.mark.parametrize("method", ["inversion", "alias", "rejection"])
def test_bound_table_is_the_table_sampled_by_that_method(table, method):
    wo, u = _dirs(64, 3), np.random.default_rng(4).random((64, 2)).astype(np.float32)
    bound = table.with_sampling(method, wo=wo)
    assert isinstance(bound, TableSampled) and bound.n_channels == 3
    eager = table.sample(wo, u, method=method)
    s = jax.jit(lambda b, w, uu: b.sample(w, uu))(bound, wo, u)
    # jitted and eager code may round differently in the last bit
    np.testing.assert_allclose(np.asarray(s.wi), np.asarray(eager.wi), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(np.asarray(s.pdf), np.asarray(eager.pdf), rtol=1e-5)
    p = jax.jit(lambda b, wi, w: b.pdf(wi, w))(bound, eager.wi, wo)
    np.testing.assert_allclose(np.asarray(p), np.asarray(eager.pdf), rtol=1e-5)
    np.testing.assert_array_equal(np.asarray(bound.f(eager.wi, wo)),
                                  np.asarray(table.f(eager.wi, wo)))  # fmt: skip


def test_generic_wrappers_sample_any_material(table):
    wo, u = _dirs(256, 5), np.random.default_rng(6).random((256, 2)).astype(np.float32)
    lobe = models.Phong(0.0, 0.5, 20.0)
    for material in (models.Lambert([0.2, 0.4, 0.6]), table):
        cos = material.with_sampling("cosine")
        assert isinstance(cos, CosineSampled)
        s = cos.sample(wo, u)
        np.testing.assert_allclose(np.asarray(cos.pdf(s.wi, wo)), np.asarray(s.pdf), rtol=1e-6)
        np.testing.assert_allclose(np.asarray(s.pdf), np.asarray(s.wi[..., 2]) / np.pi,
                                   rtol=1e-5)  # fmt: skip
        by_lobe = material.with_sampling("lobe", proposal=lobe)
        assert isinstance(by_lobe, LobeSampled)
        s = jax.jit(lambda b, w, uu: b.sample(w, uu))(by_lobe, wo, u)
        ok = np.asarray(s.pdf) > 0
        np.testing.assert_allclose(np.asarray(by_lobe.pdf(s.wi, wo))[ok], np.asarray(s.pdf)[ok],
                                   rtol=1e-5)  # fmt: skip
        f = np.asarray(material.f(s.wi, wo))
        cos_i = np.maximum(np.asarray(s.wi)[..., 2], 0.0)
        w = f * (cos_i / np.where(ok, np.asarray(s.pdf), 1.0))[..., None]
        np.testing.assert_allclose(np.asarray(s.weight)[ok], w[ok], rtol=1e-5, atol=1e-7)


def test_generic_wrappers_refuse_what_they_cannot_sample(table):
    mirror = models.Lambert(0.3) + models.SpecularReflection()
    with pytest.raises(ParameterError, match="delta"):
        mirror.with_sampling("cosine")
    with pytest.raises(ParameterError, match="proposal"):
        table.with_sampling("lobe")
    with pytest.raises(ParameterError, match="delta"):
        table.with_sampling("lobe", proposal=mirror)
    with pytest.raises(ParameterError, match="metropolis"):
        table.with_sampling("metropolis")


def test_bound_material_is_a_pytree_that_round_trips(table):
    wo = _dirs(8, 7)
    by_lobe = models.Lambert(0.4).with_sampling("lobe", proposal=models.Lambert(0.1))
    for bound in (table.with_sampling("alias", wo=wo), table.with_sampling("cosine"), by_lobe):
        leaves, tree = jax.tree_util.tree_flatten(bound)
        again = jax.tree_util.tree_unflatten(tree, leaves)
        assert type(again) is type(bound)
        np.testing.assert_array_equal(np.asarray(again.f(wo, wo)), np.asarray(bound.f(wo, wo)))


def test_scattered_samples_are_their_documented_interpolant(table):
    from gonio.brdf.gridding import filled_interpolant
    from gonio.brdf.measured import MeasuredSamples

    lambert = TabulatedBRDF.from_model(models.Lambert([0.2, 0.4, 0.6]), axes=render_axes(12, 8, 8))
    samples = MeasuredSamples.from_table(lambert)
    assert isinstance(samples, Material)
    assert samples.n_channels == 3 and samples.channel_info.kind == "rgb"
    assert not samples.has_delta and samples.sampling_methods == table.sampling_methods
    interp, covered = filled_interpolant(samples)
    assert samples.interpolant() is samples.interpolant()  # built once
    assert samples.interpolant_coverage() == pytest.approx(covered)
    wi, wo = _dirs(64, 5), _dirs(64, 6)
    np.testing.assert_array_equal(np.asarray(samples.f(wi, wo)), np.asarray(interp.f(wi, wo)))
    # a Lambertian material stays Lambertian through the interpolant
    expected = np.tile([0.2, 0.4, 0.6], (64, 1)) / np.pi
    np.testing.assert_allclose(np.asarray(samples.f(wi, wo)), expected, rtol=1e-5)
    u = np.random.default_rng(7).random((64, 2)).astype(np.float32)
    s, r = samples.sample(wo, u), interp.sample(wo, u)
    np.testing.assert_array_equal(np.asarray(s.wi), np.asarray(r.wi))
    np.testing.assert_array_equal(np.asarray(samples.pdf(s.wi, wo)), np.asarray(r.pdf))
    bound = samples.with_sampling("alias", wo=wo)
    assert isinstance(bound, TableSampled)
    assert samples.select_channels([1]).n_channels == 1
