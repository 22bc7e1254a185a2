"""The simulated sample's ground truth from a table file (``[sim.sample] file = ...``)."""

from __future__ import annotations

import math
from importlib import resources

import numpy as np
import pytest

from gonio import io
from gonio.brdf import frames, models
from gonio.brdf.tabulated import Axis, TabulatedBRDF
from gonio.errors import FormatError, RigConfigError
from gonio.rigs.config import parse_rig
from gonio.rigs.sim.truth import ClampedTable, load_truth, truth_file
from tests.conftest import shared_file


def _rig_with_sample(sample_lines: str) -> str:
    text = resources.files("gonio.rigs").joinpath("sim_sample.toml").read_text()
    head, _, tail = text.partition("[sim.sample]\n")
    rest = tail.split("\n\n", 1)[1] if "\n\n" in tail else ""
    return f"{head}[sim.sample]\n{sample_lines}\n\n{rest}"


def _small_table(values_sign: float = 1.0) -> TabulatedBRDF:
    axes = (
        Axis("theta_h", 8, 0.0, math.pi / 2, "sqrt", False, 0.5),
        Axis("theta_d", 8, 0.0, math.pi / 2, "linear", False, 0.5),
        Axis("phi_d", 6, 0.0, math.pi, "linear", True, 0.5),
    )
    t = TabulatedBRDF.from_model(models.Lambert(albedo=[0.6, 0.3, 0.1]), axes)
    values = np.asarray(t.values).copy()
    if values_sign < 0:
        # a slightly negative channel, as in spectral->RGB conversions (the native reader
        # refuses values below -1 % of the peak: those cannot be noise)
        values[..., 2] *= -0.05
    return TabulatedBRDF(values=values, axes=axes, parameterization="half_diff_iso", mask=t.mask)


def test_relative_file_resolves_against_rig_file(tmp_path):
    io.save(_small_table(), tmp_path / "m.brdf.h5")
    rig_path = tmp_path / "rig.toml"
    rig_path.write_text(_rig_with_sample('file = "m.brdf.h5"'))
    from gonio.rigs.config import load_rig

    rig = load_rig(rig_path)
    assert truth_file(rig.sim.sample, rig.source) == tmp_path / "m.brdf.h5"
    truth = load_truth(rig.sim.sample, rig.source)
    assert isinstance(truth, ClampedTable)


def test_missing_file_is_a_line_numbered_rig_error(tmp_path):
    text = _rig_with_sample('file = "nope.brdf.h5"')
    with pytest.raises(RigConfigError, match=r"rig.toml:\d+: .*no such file"):
        parse_rig(text, str(tmp_path / "rig.toml"))


def test_file_beside_model_keys_is_refused(tmp_path):
    text = _rig_with_sample('file = "m.brdf.h5"\ntype = "Lambert"')
    with pytest.raises(RigConfigError, match=r"type.*not allowed beside 'file'"):
        parse_rig(text, str(tmp_path / "rig.toml"))


def test_scattered_samples_cannot_be_a_ground_truth():
    path = shared_file("cornell", "acryl_blue.brdf")
    with pytest.raises(FormatError, match="scattered samples"):
        load_truth({"file": str(path)}, "rig.toml")


def test_truth_clamps_negative_values_and_matches_the_table(tmp_path):
    t = _small_table(values_sign=-1.0)
    io.save(t, tmp_path / "neg.brdf.h5")
    truth = load_truth({"file": str(tmp_path / "neg.brdf.h5")}, "x")
    rng = np.random.default_rng(3)
    wi = frames.spherical_to_direction(rng.uniform(0, 1.4, 64), rng.uniform(0, 6.28, 64))
    wo = frames.spherical_to_direction(rng.uniform(0, 1.4, 64), rng.uniform(0, 6.28, 64))
    f = np.asarray(truth.f(wi, wo))
    raw = np.asarray(t.f(wi, wo))
    assert np.all(raw[:, 2] < 0)
    np.testing.assert_array_equal(f[:, 2], 0.0)
    np.testing.assert_allclose(f[:, :2], raw[:, :2], rtol=1e-6)


def test_sim_sample_camera_reads_a_table_truth(tmp_path):
    from gonio.rigs.devices import Geometry
    from gonio.rigs.sim.sample import SimulatedSampleCamera

    io.save(_small_table(), tmp_path / "m.brdf.h5")
    rig = parse_rig(_rig_with_sample('file = "m.brdf.h5"'), str(tmp_path / "rig.toml"))
    cam = SimulatedSampleCamera(rig)
    assert cam.channels == ("R", "G", "B")
    wi = np.asarray(frames.spherical_to_direction(0.4, 0.0))
    wo = np.asarray(frames.spherical_to_direction(0.6, math.pi))
    cap = cam.capture(Geometry(index=0, joints_deg={}, wi=wi, wo=wo))
    expected = np.array([0.6, 0.3, 0.1]) / math.pi
    # Gaussian noise of sigma = noise_rel * f + noise_abs (1 % here): within 5 sigma
    assert np.all(np.abs(cap.value - expected) < 5 * cap.sigma)


def test_rgl_truth_has_no_ramp_on_the_plane_of_incidence():
    # The felt is ~5 % non-reciprocal; a table folded from one half of phi_d joins f(pi-) to
    # f(0) within one cell, so in-plane geometries (phi_d = 0) sat on a one-sided ramp. The
    # reciprocal (averaged) truth is mirror-symmetric there like the data: f(-d) = f(+d).
    truth = load_truth({"file": str(shared_file("rgl", "acrylic_felt_green_rgb.bsdf"))}, "t")
    th, td = np.meshgrid(np.radians([5.0, 12.5, 25.0, 40.0]), np.radians([10.0, 30.0, 57.5]))
    th, td = th.ravel(), td.ravel()
    f = {}
    for d in (-0.2, 0.2):
        wi, wo = frames.half_diff_to_directions(th, 0.0, td, np.full_like(th, math.radians(d)))
        f[d] = np.asarray(truth.f(np.asarray(wi), np.asarray(wo)))
    np.testing.assert_allclose(f[-0.2], f[0.2], rtol=2e-3)


def test_nbrdf_member_is_a_truth_relative_to_the_rig_file(tmp_path):
    """``[sim.sample] file = "ARCHIVE.zip::NAME"``: any material of a shared archive is a truth,
    the archive resolved against the rig file, the member checked when the table is read."""
    archive = shared_file("nbrdf", "merl_nbrdf.zip")
    from gonio.io.nbrdf import list_materials

    name = list_materials(archive)[0]
    (tmp_path / "merl.zip").symlink_to(archive)
    rig_path = tmp_path / "rig.toml"
    rig_path.write_text(_rig_with_sample(f'file = "merl.zip::{name}"'))
    from gonio.rigs.config import load_rig

    rig = load_rig(rig_path)
    assert str(truth_file(rig.sim.sample, rig.source)) == f"{tmp_path / 'merl.zip'}::{name}"
    truth = load_truth(rig.sim.sample, rig.source)
    ref = io.load(f"{archive}::{name}")
    wi = frames.spherical_to_direction(np.array([0.3, 0.7]), np.array([0.0, 1.0]))
    wo = frames.spherical_to_direction(np.array([0.5, 0.2]), np.array([3.0, 2.0]))
    np.testing.assert_allclose(
        np.asarray(truth.f(wi, wo)), np.maximum(np.asarray(ref.f(wi, wo)), 0.0), rtol=1e-6
    )
    with pytest.raises(RigConfigError, match=r"rig.toml:\d+: .*no such file: .*nope.zip"):
        parse_rig(_rig_with_sample('file = "nope.zip::x"'), str(rig_path))
    with pytest.raises(FormatError):
        load_truth({"file": f"{archive}::no-such-material"}, "rig.toml")
