"""Tests of gonio.brdf.tabulated: grids, lookup, masks, symmetry, conversions, bad input."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.interpolate import RegularGridInterpolator

from gonio.brdf import frames, models
from gonio.brdf.measured import MeasuredSamples
from gonio.brdf.tabulated import Axis, Channels, TabulatedBRDF, merl_axes
from gonio.errors import FormatError, ParameterError
from tests.brdf.model_checks import random_upper

HALF = math.pi / 2


def small_iso_axes() -> tuple[Axis, Axis, Axis]:
    return (
        Axis("theta_h", 7, 0.0, HALF, "sqrt", False, 0.0),
        Axis("theta_d", 6, 0.0, HALF, "linear", False, 0.5),
        Axis("phi_d", 10, 0.0, math.pi, "linear", True, 0.0),
    )


def small_aniso_axes() -> tuple[Axis, ...]:
    return (
        Axis("theta_h", 6, 0.0, HALF, "sqrt", False, 0.0),
        Axis("phi_h", 8, 0.0, 2 * math.pi, "linear", True, 0.5),
        Axis("theta_d", 5, 0.0, HALF, "linear", False, 0.0),
        Axis("phi_d", 9, 0.0, 2 * math.pi, "linear", True, 0.0),
    )


def random_table(axes, param="half_diff_iso", C=3, seed=0, mask=None, **kw) -> TabulatedBRDF:
    rng = np.random.default_rng(seed)
    vals = rng.uniform(0.1, 2.0, (*[a.size for a in axes], C)).astype(np.float32)
    return TabulatedBRDF(vals, axes, param, mask=mask, **kw)


# -- axes -----------------------------------------------------------------------------------------
def test_merl_axes_nodes_and_round_trip():
    th, td, pd = merl_axes()
    i = np.arange(90)
    np.testing.assert_allclose(th.nodes(), (i / 90) ** 2 * HALF, rtol=0, atol=1e-15)
    np.testing.assert_allclose(td.nodes(), i / 90 * HALF, atol=1e-15)
    np.testing.assert_allclose(pd.nodes(), np.arange(180) / 180 * math.pi, atol=1e-15)
    assert pd.periodic and not th.periodic and th.warp == "sqrt"
    for ax in (th, td, pd):
        n = np.arange(ax.size)
        nodes = jnp.asarray(ax.nodes())
        np.testing.assert_allclose(np.asarray(ax.continuous_index(nodes)), n, atol=1e-9)
        np.testing.assert_array_equal(np.asarray(ax.nearest_index(nodes)), n)
        # MERL's reference binning: the cell whose lower edge is at or below the angle
        mid = jnp.asarray(ax.angle_of(n + 0.5))
        np.testing.assert_array_equal(np.asarray(ax.cell_index(mid)), n)
    # MERL's own formula for theta_h bins, written independently
    ang = np.random.default_rng(0).uniform(0, HALF, 1000)
    ref = np.clip((np.sqrt(ang / HALF) * 90).astype(int), 0, 89)
    np.testing.assert_array_equal(np.asarray(th.cell_index(jnp.asarray(ang))), ref)
    # periodic wrap: phi_d = pi maps back to node 0
    assert int(pd.nearest_index(jnp.asarray(math.pi))) == 0


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"size": 0}, "size"),
        ({"lo": 1.0, "hi": 0.5}, "lo < hi"),
        ({"warp": "log"}, "warp"),
        ({"node_offset": 1.0}, "node_offset"),
        ({"warp": "sqrt", "periodic": True}, "periodic"),
    ],
)
def test_bad_axis(kwargs, match):
    base = {"name": "theta_h", "size": 4, "lo": 0.0, "hi": 1.0}
    base.update(kwargs)
    with pytest.raises(ParameterError, match=match):
        Axis(**base)


def test_axis_and_channels_dicts_round_trip():
    for ax in merl_axes():
        assert Axis.from_dict(ax.to_dict()) == ax
    for ch in (Channels.rgb(), Channels.mono(), Channels.spectral([400, 500, 600.5])):
        assert Channels.from_dict(ch.to_dict()) == ch
    assert len(Channels.spectral(np.arange(400, 701, 10))) == 31
    with pytest.raises(FormatError):
        Axis.from_dict({"name": "theta_h"})
    with pytest.raises(ParameterError, match="increasing"):
        Channels.spectral([500, 400])


# -- lookup ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("param", ["half_diff_iso", "half_diff_aniso"])
@pytest.mark.parametrize("interp", ["linear", "nearest"])
def test_exact_at_nodes(param, interp):
    axes = small_iso_axes() if param == "half_diff_iso" else small_aniso_axes()
    t = random_table(axes, param, interpolation=interp)
    mesh = np.meshgrid(*[a.nodes() for a in axes], indexing="ij")
    got = np.asarray(t.f_at(*mesh))
    np.testing.assert_allclose(got, t.values, rtol=1e-6)


def test_f_at_node_directions():
    axes = small_iso_axes()
    t = random_table(axes)
    wi, wo = t.node_directions()
    up = (wi[:, 2] > 1e-6) & (wo[:, 2] > 1e-6)
    got = np.asarray(t.f(wi[up], wo[up]))
    np.testing.assert_allclose(got, t.values.reshape(-1, 3)[up], rtol=1e-5)


def _index_coords(axes, angles):
    """Continuous node indices computed independently of the library."""
    out = []
    for ax, a in zip(axes, angles, strict=True):
        x = (a - ax.lo) / (ax.hi - ax.lo)
        if ax.warp == "sqrt":
            x = np.sqrt(x)
        t = x * ax.size - ax.node_offset
        out.append(np.mod(t, ax.size) if ax.periodic else np.clip(t, 0, ax.size - 1))
    return out


@pytest.mark.parametrize("param", ["half_diff_iso", "half_diff_aniso"])
def test_multilinear_matches_scipy(param):
    axes = small_iso_axes() if param == "half_diff_iso" else small_aniso_axes()
    t = random_table(axes, param, seed=3)
    rng = np.random.default_rng(1)
    n = 4000
    angles = [rng.uniform(ax.lo, ax.hi, n) for ax in axes]
    got = np.asarray(t.f_at(*angles))
    # reference: RegularGridInterpolator over index space; periodic axes get a wrapped copy
    vals = np.asarray(t.values, np.float64)
    grids = []
    for k, ax in enumerate(axes):
        if ax.periodic:
            vals = np.concatenate([vals, np.take(vals, [0], axis=k)], axis=k)
            grids.append(np.arange(ax.size + 1.0))
        else:
            grids.append(np.arange(float(ax.size)))
    ref = RegularGridInterpolator(grids, vals)(np.stack(_index_coords(axes, angles), -1))
    np.testing.assert_allclose(got, ref, rtol=2e-6, atol=1e-6)


def test_nearest_matches_rounding():
    axes = small_iso_axes()
    t = random_table(axes, interpolation="nearest", seed=5)
    rng = np.random.default_rng(2)
    angles = [rng.uniform(ax.lo, ax.hi, 3000) for ax in axes]
    idx = [
        np.round(c).astype(int) % ax.size
        for c, ax in zip(_index_coords(axes, angles), axes, strict=True)
    ]
    np.testing.assert_allclose(np.asarray(t.f_at(*angles)), t.values[tuple(idx)], rtol=1e-6)


def _one_node_axes() -> tuple[Axis, ...]:
    """Anisotropic axes with a one-node phi_h (isotropic data on a 4-D grid)."""
    th, _, td, pd = small_aniso_axes()
    return (th, Axis("phi_h", 1, 0.0, 2 * math.pi, "linear", True, 0.0), td, pd)


@pytest.mark.parametrize(
    "param,axes_of",
    [
        ("half_diff_iso", small_iso_axes),
        ("half_diff_aniso", small_aniso_axes),
        ("half_diff_aniso", _one_node_axes),
    ],
)
@pytest.mark.parametrize("interp", ["linear", "nearest"])
def test_mask_never_leaks(interp, param, axes_of):
    axes = axes_of()
    rng = np.random.default_rng(7)
    mask = rng.random([a.size for a in axes]) > 0.4
    base = rng.uniform(0.1, 1.0, (*mask.shape, 2)).astype(np.float32)
    garbage1 = np.where(mask[..., None], base, np.nan).astype(np.float32)
    garbage2 = np.where(mask[..., None], base, 1e30).astype(np.float32)
    ch = Channels.spectral([500, 600])
    t1 = TabulatedBRDF(garbage1, axes, param, mask=mask, channels=ch, interpolation=interp)
    t2 = t1.replace(values=garbage2)
    wi, wo = random_upper(5000, 1), random_upper(5000, 2)
    a, b = np.asarray(t1.f(wi, wo)), np.asarray(t2.f(wi, wo))
    assert np.all(np.isfinite(a))
    np.testing.assert_array_equal(a, b)
    assert a.max() <= base[mask].max() + 1e-6  # a convex combination of valid nodes only
    # independent reference, from each corner's own mask entry: multilinear weights
    # renormalized over the valid corners, or the valid corner of largest weight
    th, ph, td, pd = (np.asarray(x, np.float64) for x in frames.half_diff(wi, wo))
    if param == "half_diff_iso":
        angles = [th, td, np.where(pd >= math.pi, pd - math.pi, pd)]
    else:
        angles = [th, ph, td, pd]
    coords = _index_coords(axes, angles)
    num = np.zeros((len(wi), 2))
    den = np.zeros(len(wi))
    best = np.full(len(wi), -1.0)
    nearest = np.zeros((len(wi), 2))
    for bits in np.ndindex(*(2,) * len(axes)):
        idx, w = [], np.ones(len(wi))
        for c, ax, bit in zip(coords, axes, bits, strict=True):
            if ax.size == 1:
                i0, f = np.zeros(len(wi), int), np.zeros(len(wi))
            else:
                i0 = np.minimum(np.floor(c).astype(int), ax.size - (1 if ax.periodic else 2))
                f = c - i0
            idx.append((i0 + bit) % ax.size)
            w = w * (f if bit else 1 - f)
        m = mask[tuple(idx)]
        v = np.where(m[:, None], base[tuple(idx)], 0)
        num += (w * m)[:, None] * v
        den += w * m
        score = np.where(m, w + 1e-6, -1.0)
        take = score > best + 1e-5  # ties (equal weights) are left out of the comparison below
        tie = np.abs(score - best) <= 1e-5
        nearest = np.where(take[:, None], v, nearest)
        best = np.where(take, score, best)
        if bits != (0,) * len(axes):
            nearest = np.where(tie[:, None] & m[:, None], np.nan, nearest)
    if interp == "linear":
        ref = np.where(den[:, None] > 0, num / np.where(den > 0, den, 1)[:, None], 0)
        np.testing.assert_allclose(a, ref, rtol=1e-4, atol=1e-6)
    else:
        clear = np.isfinite(nearest).all(axis=1)
        assert clear.mean() > 0.95
        np.testing.assert_array_equal(a[clear], nearest[clear].astype(np.float32))


def test_corner_bits_are_each_corners_mask():
    """The per-cell corner validity the lookup gathers once is the mask at every corner."""
    from gonio.brdf.lookup import corner_bits as _corner_bits

    for axes in (small_iso_axes(), small_aniso_axes(), _one_node_axes()):
        rng = np.random.default_rng(len(axes))
        mask = rng.random([a.size for a in axes]) > 0.3
        bits = _corner_bits(mask, axes)
        assert bits.shape == mask.shape and bits.dtype.itemsize * 8 >= 2 ** len(axes)
        for node in np.ndindex(*mask.shape):
            last = [
                a.size > 1 and i == a.size - 1 and not a.periodic
                for i, a in zip(node, axes, strict=True)
            ]
            if any(last):
                continue  # never the first corner of a cell
            for j, corner in enumerate(np.ndindex(*(2,) * len(axes))):
                at = tuple((i + c) % a.size for i, c, a in zip(node, corner, axes, strict=True))
                assert (int(bits[node]) >> j) & 1 == mask[at], (node, corner)


def test_no_valid_neighbour_gives_zero():
    axes = small_iso_axes()
    mask = np.zeros([a.size for a in axes], bool)
    mask[0, 0, 0] = True
    t = random_table(axes, mask=mask)
    wo = np.asarray(frames.spherical_to_direction(1.2, 0.0))
    wi = np.asarray(frames.spherical_to_direction(1.2, math.pi / 2))  # far from theta_h = 0
    assert np.all(np.asarray(t.f(wi, wo)) == 0)
    assert np.all(np.asarray(t.f([0, 0, 1.0], [0, 0, 1.0])) > 0)


def test_below_horizon_is_zero_and_dtypes():
    t = random_table(small_iso_axes())
    wi, wo = random_upper(100, 3), random_upper(100, 4)
    below = wi * [1, 1, -1]
    assert np.all(np.asarray(t.f(below, wo)) == 0) and np.all(np.asarray(t.f(wi, below)) == 0)
    assert t.f(wi.astype(np.float32), wo.astype(np.float32)).dtype == jnp.float32
    assert t.f(wi, wo).dtype == jnp.float64
    np.testing.assert_allclose(
        np.asarray(t.f(wi.astype(np.float32), wo.astype(np.float32))),
        np.asarray(t.f(wi, wo)),
        rtol=2e-4,
    )


def test_reciprocity_and_isotropy_of_iso_table():
    t = random_table(small_iso_axes(), seed=11)
    wi, wo = random_upper(3000, 5), random_upper(3000, 6)
    a = np.asarray(t.f(wi, wo))
    np.testing.assert_allclose(np.asarray(t.f(wo, wi)), a, rtol=1e-6, atol=1e-7)
    ang = np.random.default_rng(0).uniform(0, 2 * np.pi, (3000, 1))
    c, s = np.cos(ang), np.sin(ang)

    def rot(w):
        return np.concatenate(
            [c * w[:, :1] - s * w[:, 1:2], s * w[:, :1] + c * w[:, 1:2], w[:, 2:]], 1
        )

    np.testing.assert_allclose(np.asarray(t.f(rot(wi), rot(wo))), a, rtol=1e-6, atol=1e-7)


def test_jit_closure_and_pytree_argument():
    t = random_table(small_iso_axes())
    wi, wo = random_upper(50, 1), random_upper(50, 2)
    ref = np.asarray(t.f(wi, wo))
    np.testing.assert_allclose(np.asarray(jax.jit(lambda a, b: t.f(a, b))(wi, wo)), ref)
    np.testing.assert_allclose(np.asarray(jax.jit(lambda tab, a, b: tab.f(a, b))(t, wi, wo)), ref)
    leaves = jax.tree_util.tree_leaves(t)
    assert len(leaves) == 1


class _GGXLike:
    """Lambert + a moderately rough isotropic microfacet lobe (GGX D, Smith-like G, no Fresnel),
    written here independently of the library's models."""

    def __init__(self, kd=0.3, ks=0.6, alpha=0.35):
        self.kd, self.ks, self.a2 = kd, ks, alpha * alpha

    def f(self, wi, wo):
        wi, wo = jnp.asarray(wi), jnp.asarray(wo)
        h = wi + wo
        h = h / jnp.linalg.norm(h, axis=-1, keepdims=True)
        ci, co, ch = wi[..., 2], wo[..., 2], h[..., 2]
        d = self.a2 / (math.pi * (ch * ch * (self.a2 - 1) + 1) ** 2)

        def g1(c):
            return 2 * c / (c + jnp.sqrt(self.a2 + (1 - self.a2) * c * c))

        spec = self.ks * d * g1(ci) * g1(co) / (4 * ci * co)
        val = self.kd / math.pi + spec
        ok = (ci > 0) & (co > 0)
        return jnp.where(ok, val, 0.0)[..., None] * jnp.array([1.0, 0.8, 0.6])


def test_dense_table_matches_analytic_model_within_one_percent():
    model = _GGXLike()
    t = TabulatedBRDF.merl_like(model)
    rng = np.random.default_rng(0)
    n = 20000

    # directions uniform in solid angle, both below 80 degrees from the normal
    def dirs():
        z = rng.uniform(math.cos(math.radians(80)), 1.0, n)
        ph = rng.uniform(0, 2 * math.pi, n)
        r = np.sqrt(1 - z * z)
        return np.stack([r * np.cos(ph), r * np.sin(ph), z], -1)

    wi, wo = dirs(), dirs()
    ref = np.asarray(model.f(wi, wo))
    got = np.asarray(t.f(wi, wo))
    rel_rms = np.sqrt(np.mean((got - ref) ** 2) / np.mean(ref**2))
    assert rel_rms < 0.01, f"relative RMS error {rel_rms:.4f}"
    # and the same through float32
    got32 = np.asarray(t.f(wi.astype(np.float32), wo.astype(np.float32)))
    assert np.sqrt(np.mean((got32 - ref) ** 2) / np.mean(ref**2)) < 0.01


def test_from_model_lambert_is_exact_and_masks_horizon():
    m = models.Lambert([0.5, 0.4, 0.3])
    t = TabulatedBRDF.from_model(m, axes=small_iso_axes())
    wi, wo = t.node_directions()
    below = (wi[:, 2] <= 0) | (wo[:, 2] <= 0)
    np.testing.assert_array_equal(~t.mask.reshape(-1), below)
    wi, wo = random_upper(500, 8), random_upper(500, 9)
    np.testing.assert_allclose(np.asarray(t.f(wi, wo)), np.asarray(m.f(wi, wo)), rtol=1e-6)
    assert t.meta["model"]["type"] == "Lambert"


def test_to_samples_and_cell_measure():
    # the cells tile {theta_h, theta_d in [0, pi/2]} x all azimuths: measure 8 pi^2 exactly
    for axes in (merl_axes(), small_iso_axes()):
        m = random_table(axes).cell_measure()
        assert m.sum() == pytest.approx(8 * math.pi**2, rel=1e-9)
    for axes, param in (
        (small_iso_axes(), "half_diff_iso"),
        (small_aniso_axes(), "half_diff_aniso"),
    ):
        t = random_table(axes, param)
        m = t.cell_measure()
        assert m.sum() == pytest.approx(8 * math.pi**2, rel=1e-9)
        s = MeasuredSamples.from_table(t)
        assert isinstance(s, MeasuredSamples)
        assert np.all(s.wi[:, 2] > 0) and np.all(s.wo[:, 2] > 0)
        # theta_d = 0 nodes share one direction pair for every phi_d (and theta_h = 0 nodes of an
        # anisotropic table for every phi_h): skip those
        th, _, td, _ = (np.asarray(x) for x in frames.half_diff(s.wi, s.wo))
        ok = (td > 1e-6) & ((th > 1e-6) | (param == "half_diff_iso"))
        np.testing.assert_allclose(np.asarray(t.f(s.wi, s.wo))[ok], s.values[ok], rtol=1e-4)
    assert s.weights.shape == (len(s),) and np.all(s.weights >= 0)


# -- bad input ------------------------------------------------------------------------------------
def test_constructor_errors():
    axes = small_iso_axes()
    grid = tuple(a.size for a in axes)
    good = np.ones((*grid, 3), np.float32)
    with pytest.raises(FormatError, match="shape"):
        TabulatedBRDF(good[:-1], axes)
    with pytest.raises(ParameterError, match="parameterization"):
        TabulatedBRDF(good, axes, "polar")
    with pytest.raises(ParameterError, match="needs axes"):
        TabulatedBRDF(good, axes[::-1])
    with pytest.raises(ParameterError, match="interpolation"):
        TabulatedBRDF(good, axes, interpolation="cubic")
    bad = good.copy()
    bad[1, 2, 3, 0] = np.nan
    with pytest.raises(FormatError, match="NaN"):
        TabulatedBRDF(bad, axes)
    mask = np.ones(grid, bool)
    mask[1, 2, 3] = False
    TabulatedBRDF(bad, axes, mask=mask)  # NaN in an invalid node is fine
    with pytest.raises(FormatError, match="mask"):
        TabulatedBRDF(good, axes, mask=mask[:-1])
    with pytest.raises(FormatError, match="numeric"):
        TabulatedBRDF(np.full((*grid, 3), "a"), axes)
    with pytest.raises(FormatError, match="channels"):
        TabulatedBRDF(good, axes, channels=Channels.mono())
    with pytest.raises(ParameterError, match="channels"):
        TabulatedBRDF(np.ones((*grid, 5)), axes)
    with pytest.raises(FormatError, match="sigma"):
        TabulatedBRDF(good, axes, sigma=-good)
    with pytest.raises(FormatError, match="counts"):
        TabulatedBRDF(good, axes, counts=np.full(grid, 0.5))


def test_measured_samples_validation():
    wi, wo = random_upper(10, 1), random_upper(10, 2)
    v = np.ones((10, 3))
    s = MeasuredSamples(wi, wo, v, sigma=0.1 * v, weights=np.ones(10))
    assert len(s) == 10 and s.channels == Channels.rgb()
    bad = v.copy()
    bad[3, 1] = np.nan
    with pytest.raises(FormatError, match="NaN"):
        MeasuredSamples(wi, wo, bad)
    keep = np.ones(10, bool)
    keep[3] = False
    assert len(MeasuredSamples(wi, wo, bad, mask=keep)) == 9
    with pytest.raises(FormatError, match="unit"):
        MeasuredSamples(2 * wi, wo, v)
    with pytest.raises(FormatError, match=r"\(N, 3\)"):
        MeasuredSamples(wi[:, :2], wo, v)
    with pytest.raises(FormatError, match="values"):
        MeasuredSamples(wi, wo, v[:5])
    with pytest.raises(FormatError, match="sigma"):
        MeasuredSamples(wi, wo, v, sigma=-v)
