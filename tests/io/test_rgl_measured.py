"""RGL tensor files loaded exactly: f against Mitsuba 3 and the reference readers, sampling through
the file's own warps (chi-square, weights, albedo), negative values, rendering and fitting."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gonio import io
from gonio.brdf.chi2 import chi2_test
from gonio.io import rgl
from gonio.io.rgl_measured import RGLMeasured, load_rgl
from tests.conftest import shared_file
from tests.io.test_rgl import FILES, _SlowReference

COS_85 = math.cos(math.radians(85.0))


def _hemi(rng: np.random.Generator, n: int, cos_min: float) -> np.ndarray:
    u = rng.random((n, 2))
    z = cos_min + (1 - cos_min) * u[:, 0]
    r = np.sqrt(1 - z * z)
    p = 2 * math.pi * u[:, 1]
    return np.stack([r * np.cos(p), r * np.sin(p), z], -1)


def _pairs(n: int, seed: int, cos_min: float = COS_85) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return _hemi(rng, n, cos_min), _hemi(rng, n, cos_min)


def _rel(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    # relative to the reference, with a floor at 1e-4 of the sample's largest channel (values
    # within float32 round-off of 0 have no meaningful relative error)
    scale = np.maximum(np.abs(b), 1e-4 * np.abs(b).max(axis=-1, keepdims=True))
    scale = np.maximum(scale, 1e-12)
    return np.abs(a - b) / scale


def test_load_returns_the_exact_bsdf_quickly():
    path = shared_file("rgl", "acrylic_felt_green_rgb.bsdf")
    m = io.load(path)
    assert isinstance(m, RGLMeasured)
    assert m.channels == 3 and m.channel_info.names == ("R", "G", "B")
    assert m.isotropic and "felt" in m.description.lower()


@pytest.mark.parametrize("name", FILES)
def test_f_equals_mitsuba_measured_eval_with_explicit_argument_order(name):
    """gonio ``f(wi, wo)`` (wi toward the light) equals Mitsuba's
    ``eval(si.wi = wo, wo = wi) / cos(theta_i)``: Mitsuba conditions on ``si.wi``, the
    direction toward the camera. Directions up to 85 degrees."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    path = shared_file("rgl", name)
    m = load_rgl(path)
    bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
    wi, wo = _pairs(400, seed=11)
    ours = np.asarray(m.f(wi, wo))
    ctx = mi.BSDFContext()
    ref = np.zeros_like(ours)
    for k in range(len(wi)):
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*wo[k])  # the camera side: the file's conditioning direction
        v = bsdf.eval(ctx, si, mi.Vector3f(*wi[k]))  # toward the light; value = f cos(theta_i)
        ref[k] = np.array([v[0], v[1], v[2]]) / wi[k, 2]
    rel = _rel(ours, ref)
    assert np.median(rel) <= 1e-4 and np.percentile(rel, 99) <= 1e-3, (
        np.median(rel),
        np.percentile(rel, 99),
    )
    # the swapped order is a different function for measured (non-reciprocal) data
    swapped = np.asarray(m.f(wo, wi)) * wo[:, 2:3] / wi[:, 2:3]
    assert np.median(_rel(swapped, ref)) > 1e-3


@pytest.mark.parametrize("name", FILES)
def test_pdf_equals_mitsuba_measured_pdf(name):
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    path = shared_file("rgl", name)
    m = load_rgl(path)
    bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
    wi, wo = _pairs(200, seed=12)
    ours = np.asarray(m.pdf(wi, wo))
    ctx = mi.BSDFContext()
    ref = np.zeros_like(ours)
    for k in range(len(wi)):
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*wo[k])
        ref[k] = bsdf.pdf(ctx, si, mi.Vector3f(*wi[k]))
    rel = np.abs(ours - ref) / np.maximum(ref, 1e-4 * ref.max())
    assert np.median(rel) <= 1e-4 and np.percentile(rel, 99) <= 1e-3


@pytest.mark.parametrize("name", FILES)
def test_f_equals_the_reference_reader(name):
    """Against the scalar pure-Python reference of the test suite on every file, which always
    runs (Mitsuba's reader is compared above where it is installed)."""
    path = shared_file("rgl", name)
    m = load_rgl(path)
    wi, wo = _pairs(60, seed=3)
    ours = np.asarray(m.f(wi, wo))
    ref = _SlowReference(rgl.read_rgl(path).fields)
    slow = np.array([ref(wo[j], wi[j]) for j in range(len(wi))])  # ref(w_c, w_s) = F / cos(w_s)
    rel = _rel(ours, slow)
    assert np.median(rel) <= 1e-6 and rel.max() <= 1e-4


def test_float32_evaluation_matches_float64():
    m = load_rgl(shared_file("rgl", "cc_ibiza_sunset_rgb.bsdf"))
    wi, wo = _pairs(2000, seed=4)
    a = np.asarray(m.f(wi.astype(np.float32), wo.astype(np.float32)))
    assert a.dtype == np.float32
    rel = _rel(a.astype(np.float64), np.asarray(m.f(wi, wo)))
    assert np.median(rel) < 1e-5 and np.percentile(rel, 99) < 1e-3


# -- sampling --------------------------------------------------------------------------------
# Two diffuse files (paper; the felt, a textile), the sharpest database file at hand (the vinyl
# film's clear coat: a lobe about 10 deg wide at half maximum) and, since ../shared/data/rgl has
# no near-mirror file, one written by gonio's RGL writer from GGX at alpha 0.05 (the writer
# tests' sharpest model; at 30 deg incidence its lobe is 7 deg wide at half maximum and peaks at
# 38 / sr, the vinyl's at 4.8 / sr); its chi-square histogram is a 25 deg cap around the mirror
# direction (plus one cell for the rest of the sphere) so that the lobe spans many cells.
NEAR_MIRROR = "ggx-0.05-written"
SAMPLED = [
    "paper_white_rgb.bsdf",
    "acrylic_felt_green_rgb.bsdf",
    "vch_golden_yellow_rgb.bsdf",
    NEAR_MIRROR,
]
WO_DEG = [0.0, 30.0, 60.0, 80.0]
N_CHI2 = len(SAMPLED) * len(WO_DEG)
# the default run keeps normal and grazing incidence; the middle angles run with -m slow
WO_PARAMS = [d if d in (0.0, 80.0) else pytest.param(d, marks=pytest.mark.slow) for d in WO_DEG]


@pytest.fixture(scope="module")
def near_mirror_file(tmp_path_factory):
    from gonio.brdf import models

    ggx = models.TorranceSparrow(
        alpha=0.05, distribution="ggx", shadowing="smith", fresnel=models.Schlick(f0=0.9)
    )
    path = tmp_path_factory.mktemp("near-mirror") / "ggx-0.05.bsdf"
    io.save(ggx, path)
    return path


def _sampled(name: str, request: pytest.FixtureRequest) -> RGLMeasured:
    if name == NEAR_MIRROR:
        return load_rgl(request.getfixturevalue("near_mirror_file"))
    return load_rgl(shared_file("rgl", name))


def test_the_near_mirror_file_is_sharper_than_the_database_files(request):
    """What makes the written file the near-mirror case: its peak is 8 times the vinyl's."""

    def peak(m):
        wo = _wo(30.0, 0.0)
        a = np.radians(np.linspace(10.0, 50.0, 401))
        wi = np.stack([-np.sin(a), 0 * a, np.cos(a)], -1)
        return float(np.asarray(m.f(wi, np.broadcast_to(wo, wi.shape))).mean(-1).max())

    sharp = peak(_sampled(NEAR_MIRROR, request))
    assert sharp > 6 * peak(_sampled("vch_golden_yellow_rgb.bsdf", request)), sharp


def _wo(deg: float, phi: float = 0.7) -> np.ndarray:
    t = math.radians(deg)
    return np.array([math.sin(t) * math.cos(phi), math.sin(t) * math.sin(phi), math.cos(t)])


@pytest.mark.parametrize("name", SAMPLED)
@pytest.mark.parametrize("deg", WO_PARAMS)
def test_sampling_passes_chi_square(name, deg, request):
    m = _sampled(name, request)
    wo = _wo(deg)

    def sample(u):
        s = m.sample(wo, u)
        return np.asarray(s.wi), np.asarray(s.pdf)

    def pdf(wi):
        return np.asarray(m.pdf(wi, wo))

    cap = {}
    if name == NEAR_MIRROR:
        # 12 Gauss-Legendre nodes per cell: at 80 deg the cap's cells that the horizon cuts
        # hold samples within a sliver that 6 nodes miss (expected count 0)
        mirror = wo * np.array([-1.0, -1.0, 1.0])
        cap = {"axis": mirror, "theta_max": math.radians(25.0), "order": 12}
    r = chi2_test(sample, pdf, n_samples=400_000, res_theta=45, res_phi=90, seed=1,
                  significance=0.01, n_tests=N_CHI2, **cap)  # fmt: skip
    assert r.passed, r.message


@pytest.mark.parametrize("name", SAMPLED)
def test_sample_weight_is_f_cos_over_pdf_and_pdf_is_consistent(name, request):
    m = _sampled(name, request)
    rng = np.random.default_rng(2)
    wo = _hemi(rng, 2000, math.cos(math.radians(80)))  # the shape of other tests: one compile
    s = m.sample(wo, rng.random((2000, 2)))
    ok = np.asarray(s.pdf) > 0
    assert ok.mean() > 0.9
    wi = np.asarray(s.wi)[ok]
    p = np.asarray(m.pdf(wi, wo[ok]))
    np.testing.assert_allclose(np.asarray(s.pdf)[ok], p, rtol=1e-5)
    expect = np.asarray(m.f(wi, wo[ok])) * wi[:, 2:3] / p[:, None]
    np.testing.assert_allclose(np.asarray(s.weight)[ok], expect, rtol=1e-5, atol=1e-9)
    assert np.all(np.asarray(s.weight)[~ok] == 0)


def _albedo_quadrature(m: RGLMeasured, wo: np.ndarray, n: int = 512) -> np.ndarray:
    """Midpoint rule in (cos theta_i, phi_i), an n x 4n grid."""
    c = (np.arange(n) + 0.5) / n
    p = (np.arange(4 * n) + 0.5) * (2 * math.pi / (4 * n))
    cc, pp = np.meshgrid(c, p, indexing="ij")
    s = np.sqrt(1 - cc**2)
    wi = np.stack([s * np.cos(pp), s * np.sin(pp), cc], -1).reshape(-1, 3)
    val = np.asarray(m.f(wi, wo)) * wi[:, 2:3]
    return val.sum(axis=0) * (2 * math.pi / (4 * n * n))


@pytest.mark.parametrize("name", SAMPLED)
@pytest.mark.parametrize("deg", [10.0, pytest.param(45.0, marks=pytest.mark.slow), 75.0])
def test_mean_weight_matches_quadrature_albedo(name, deg, request):
    m = _sampled(name, request)
    wo = _wo(deg)
    rng = np.random.default_rng(9)
    s = m.sample(wo, rng.random((400_000, 2)))
    mc = np.asarray(s.weight).mean(axis=0)
    quad = _albedo_quadrature(m, wo)
    np.testing.assert_allclose(mc, quad, rtol=0.01)


# -- negative values -------------------------------------------------------------------------
def test_negative_values_are_kept_by_default_and_clamped_on_request():
    path = shared_file("rgl", "vch_golden_yellow_rgb.bsdf")
    keep = load_rgl(path)
    clamp = load_rgl(path, negative="clamp")
    assert (rgl.read_rgl(path).fields["rgb"] < 0).mean() > 0.01
    wi, wo = _pairs(2000, seed=5)
    fk = np.asarray(keep.f(wi, wo))
    fc = np.asarray(clamp.f(wi, wo))
    assert (fk < 0).any() and (fc >= 0).all()
    # clamping raises table entries and interpolation weights are >= 0: f can only grow,
    # and stays the same wherever the interpolation touches no negative entry (most places)
    assert np.all(fc >= fk - 1e-12)
    assert np.mean(np.isclose(fc, fk, rtol=1e-12, atol=0)) > 0.8
    # sampling does not depend on the colour table: same directions and pdf
    u = np.random.default_rng(0).random((2000, 2))
    a, b = keep.sample(wo, u), clamp.sample(wo, u)
    np.testing.assert_array_equal(np.asarray(a.wi), np.asarray(b.wi))
    np.testing.assert_array_equal(np.asarray(a.pdf), np.asarray(b.pdf))
    assert (np.asarray(b.weight) >= 0).all()


def test_bad_options_are_refused():
    from gonio.errors import ParameterError

    path = shared_file("rgl", "paper_white_rgb.bsdf")
    with pytest.raises(ParameterError):
        load_rgl(path, negative="zero")
    with pytest.raises(ParameterError):
        load_rgl(path, color="xyz")


def test_spectral_files_keep_wavelengths_and_convert_to_rgb(tmp_path):
    from gonio.io.spectral import spectrum_to_linear_srgb

    fields = rgl.parse_tensor_file(shared_file("rgl", "paper_white_rgb.bsdf").read_bytes())
    spec = dict(fields)
    rgb = spec.pop("rgb")
    spec["spectra"] = np.concatenate([rgb, rgb[:, :, :1]], axis=2)
    spec["wavelengths"] = np.array([450.0, 520.0, 600.0, 680.0], dtype=np.float32)
    p = tmp_path / "spectral.bsdf"
    p.write_bytes(rgl.tensor_file_bytes(spec))
    keep = io.load(p)
    assert keep.channels == 4
    np.testing.assert_allclose(keep.channel_info.wavelengths_nm, spec["wavelengths"])
    wi, wo = _pairs(50, seed=6)
    fs = np.asarray(keep.f(wi, wo))
    as_rgb = io.load(p, color="rgb")
    assert as_rgb.channels == 3
    expect = spectrum_to_linear_srgb(fs, spec["wavelengths"])
    np.testing.assert_allclose(np.asarray(as_rgb.f(wi, wo)), expect, rtol=1e-9, atol=1e-12)


# -- consumers -------------------------------------------------------------------------------
def test_renderer_consumes_it_directly_and_negative_values_stay_finite():
    from gonio.render.integrator import render_sphere
    from gonio.render.lights import Directional

    m = load_rgl(shared_file("rgl", "vch_golden_yellow_rgb.bsdf"))
    light = Directional(direction=[0.3, 0.2, 1.0], irradiance=1.0)
    img = render_sphere(m, [light], resolution=24, spp=1)
    assert img.shape == (24, 24, 3) and np.all(np.isfinite(img)) and img.max() > 0
    g = render_sphere(m, [light], resolution=24, spp=1, channels=[1])
    np.testing.assert_allclose(g[..., 0], img[..., 1], rtol=1e-5, atol=1e-7)
    env = render_sphere(m, None, resolution=16, spp=8)
    assert np.all(np.isfinite(env)) and env.mean() > 0
    clamped = load_rgl(shared_file("rgl", "vch_golden_yellow_rgb.bsdf"), negative="clamp")
    assert render_sphere(clamped, None, resolution=16, spp=8).min() >= 0


def test_outgoing_direction_with_size_one_axes_gives_the_broadcast_result():
    """The renderer passes its per-pixel ``wo`` as ``(P, 1, 3)`` against ``(P, S, 3)``
    (``broadcasts_outgoing``): f, pdf and sample must equal the fully broadcast call, including
    where ``wo`` or ``wi`` is below the horizon."""
    m = load_rgl(shared_file("rgl", "cc_ibiza_sunset_rgb.bsdf"))
    assert m.broadcasts_outgoing
    rng = np.random.default_rng(5)
    wo = _hemi(rng, 12, COS_85).astype(np.float32)
    wo[0, 2] = -wo[0, 2]  # one outgoing direction below the horizon
    wi = _hemi(rng, 12 * 7, COS_85).astype(np.float32).reshape(12, 7, 3)
    wi[3, 2, 2] = -wi[3, 2, 2]
    u = rng.random((12, 7, 2)).astype(np.float32)
    wo1, wo_b = wo[:, None, :], np.broadcast_to(wo[:, None, :], wi.shape)
    np.testing.assert_allclose(np.asarray(m.f(wi, wo1)), np.asarray(m.f(wi, wo_b)), rtol=1e-6)
    np.testing.assert_allclose(np.asarray(m.pdf(wi, wo1)), np.asarray(m.pdf(wi, wo_b)), rtol=1e-6)
    a, b = m.sample(wo1, u), m.sample(wo_b, u)
    assert a.wi.shape == b.wi.shape == (12, 7, 3) and a.weight.shape == (12, 7, 3)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-5, atol=1e-7)
    assert np.all(np.asarray(a.pdf)[0] == 0) and np.all(np.asarray(m.f(wi, wo1))[0] == 0)


def test_fitter_consumes_the_file_nodes():
    from gonio.fit.data import prepare

    m = load_rgl(shared_file("rgl", "acrylic_felt_green_rgb.bsdf"))
    d = prepare(m)
    assert d.n > 2000 and d.channels == 3 and d.source["kind"] == "RGLMeasured"
    np.testing.assert_allclose(d.values, np.asarray(m.f(d.wi, d.wo)), rtol=1e-12)
    # the weights are a quadrature of the direction-pair space: constant f integrates to the
    # measure of the pairs used (< the full (2 pi)^2 sr^2 of two hemispheres)
    total = d.weights.sum()
    assert 0.3 * (2 * math.pi) ** 2 < total < 1.1 * (2 * math.pi) ** 2


def test_to_table_is_the_explicit_resampling():
    from gonio.brdf.tabulated import Axis, TabulatedBRDF

    m = load_rgl(shared_file("rgl", "paper_white_rgb.bsdf"))
    axes = (
        Axis("theta_h", 8, 0, math.pi / 2, "sqrt"),
        Axis("theta_d", 8, 0, math.pi / 2),
        Axis("phi_d", 8, 0, math.pi, periodic=True),
    )
    t = m.to_table(axes=axes)
    assert isinstance(t, TabulatedBRDF)
    wi, wo = (w.reshape(-1, 3) for w in t.node_directions())
    ok = t.mask.reshape(-1)
    np.testing.assert_allclose(t.values.reshape(-1, 3)[ok], np.asarray(m.f(wi, wo))[ok], rtol=1e-5)


def test_cli_render_takes_a_bsdf_file(tmp_path, capsys):
    import json

    from gonio.cli import main

    path = shared_file("rgl", "paper_white_rgb.bsdf")
    out = tmp_path / "paper.png"
    rc = main(["render", "--measured", str(path), "--light", "dir:25,60", "--resolution", "16",
               "--out", str(out), "--json"])  # fmt: skip
    assert rc == 0 and out.stat().st_size > 100
    assert "measured" in json.loads(capsys.readouterr().out)["images"]


@pytest.mark.parametrize(
    ("phi_lo", "phi_hi", "n_phi"),
    [
        pytest.param(-math.pi, math.pi, 6, id="full", marks=pytest.mark.slow),
        pytest.param(-math.pi, 0.0, 5, id="mirror-2", marks=pytest.mark.slow),
        pytest.param(-math.pi, -math.pi / 2, 3, id="mirror-4"),
    ],
)
def test_anisotropic_files_with_symmetry_folds_match_mitsuba(tmp_path, phi_lo, phi_hi, n_phi):
    """Synthetic anisotropic files (random positive tables) with no, two- and four-fold
    symmetry: the folding into the tabulated wedge and the absolute half-vector azimuth are
    the reference's (f and pdf)."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    rng = np.random.default_rng(8)
    nt, n = 5, 16
    fields = {
        "description": np.frombuffer(b"synthetic anisotropic", np.uint8).copy(),
        "jacobian": np.array([1], np.uint8),
        "theta_i": np.linspace(0, math.pi / 2, nt).astype(np.float32),
        "phi_i": np.linspace(phi_lo, phi_hi, n_phi).astype(np.float32),
        "ndf": rng.uniform(0.5, 2.0, (8, 32)).astype(np.float32),
        "sigma": rng.uniform(0.5, 2.0, (8, 32)).astype(np.float32),
        "vndf": rng.uniform(0.1, 1.0, (n_phi, nt, 24, 24)).astype(np.float32),
        "luminance": rng.uniform(0.1, 1.0, (n_phi, nt, n, n)).astype(np.float32),
        "rgb": rng.uniform(0.0, 1.0, (n_phi, nt, 3, n, n)).astype(np.float32),
    }
    path = tmp_path / "aniso.bsdf"
    path.write_bytes(rgl.tensor_file_bytes(fields))
    m = load_rgl(path)
    assert not m.isotropic
    bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
    wi, wo = _pairs(150, seed=13)
    ours_f = np.asarray(m.f(wi, wo))
    ours_p = np.asarray(m.pdf(wi, wo))
    ref_f = np.zeros_like(ours_f)
    ref_p = np.zeros_like(ours_p)
    ctx = mi.BSDFContext()
    for k in range(len(wi)):
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*wo[k])
        v = bsdf.eval(ctx, si, mi.Vector3f(*wi[k]))
        ref_f[k] = np.array([v[0], v[1], v[2]]) / wi[k, 2]
        ref_p[k] = bsdf.pdf(ctx, si, mi.Vector3f(*wi[k]))
    rel = _rel(ours_f, ref_f)
    assert np.median(rel) <= 1e-4 and np.percentile(rel, 99) <= 1e-3
    relp = np.abs(ours_p - ref_p) / np.maximum(ref_p, 1e-6)
    assert np.median(relp) <= 1e-4 and np.percentile(relp, 99) <= 1e-3
    # sampling stays consistent with the pdf through the folds
    s = m.sample(wo, np.random.default_rng(1).random((150, 2)))
    ok = np.asarray(s.pdf) > 0
    np.testing.assert_allclose(
        np.asarray(s.pdf)[ok], np.asarray(m.pdf(np.asarray(s.wi)[ok], wo[ok])), rtol=1e-5
    )
