"""End to end on the simulated rig: acquire -> RAW files, EXR frames, table vs ground truth."""

import json
from contextlib import contextmanager

import numpy as np
import pytest

from gonio.acquire.engine import acquire
from gonio.acquire.imaging import measurement
from gonio.acquire.journal import Journal
from gonio.brdf import models
from gonio.io.dng import read_dng
from gonio.io.exr import read_exr
from gonio.io.native import read_native
from gonio.rigs.config import load_rig, parse_rig
from gonio.rigs.kinematics import Kinematics
from gonio.rigs.session import open_rig

# One pair of reciprocal configurations and one on the mirror direction.
PLAN = """kind = "isotropic"
theta_i_deg = [25]
theta_o_deg = [25, 45]
dphi_deg = [180]
reciprocal = true
"""


def small_rig(sample: str | None = None):
    """The sim rig with a smaller image (same field of view) to keep the test fast."""
    text = load_rig("sim").text
    text = text.replace("width = 640", "width = 480").replace("height = 480", "height = 360")
    text = text.replace("focal_px = 2400.0", "focal_px = 1800.0")
    if sample is not None:
        text = text.replace(
            "params = { rho_d = [0.3, 0.25, 0.2], rho_s = 0.4, n = 80.0 }", sample
        ).replace('type = "Phong"', 'type = "Lambert"')
    return parse_rig(text, "sim-small.toml")


@contextmanager
def imaging_camera(rig, run_dir):
    """The imaging chain over the rig's camera and light, opened without the servos."""
    with open_rig(rig, devices=("light", "camera")) as ses:
        yield measurement(ses, run_dir)


def z_and_geometry(run, rig):
    """|measured - truth| / sigma per channel and the camera-direction error (deg)."""
    kin = Kinematics(rig)
    truth = models.Node.from_dict(rig.sim.sample)
    j = Journal(run)
    try:
        rows = j.samples()
    finally:
        j.close()
    zs, geo = [], []
    for r in rows:
        f = np.asarray(truth.f(r.wi, r.wo))
        zs.append((r.value - f) / r.sigma)
        _, wo_true = kin.forward(kin.joints_deg_to_pose(r.joints_deg))
        geo.append(np.degrees(np.arccos(np.clip(wo_true @ r.wo, -1, 1))))
    return np.abs(np.concatenate(zs)), np.array(geo), rows


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    d = tmp_path_factory.mktemp("imaging")
    (d / "plan.toml").write_text(PLAN)
    rig = small_rig()
    s = acquire(d / "run", rig, d / "plan.toml", progress=False)
    return d / "run", rig, s


def test_run_writes_raw_files_exr_frames_and_table(run):
    path, rig, s = run
    assert s.complete and s.done == 3
    raws = sorted((path / "raw").glob("c*.dng"))
    darks = sorted((path / "raw").glob("dark_*.dng"))
    assert len(raws) >= 3 and darks
    fr = read_dng(raws[0])
    assert fr.data.shape == (360, 480) and fr.meta["joints_deg"]
    exrs = sorted((path / "hdr").glob("c*.exr"))
    assert len(exrs) == 3
    img, names = read_exr(exrs[0])
    assert img.shape == (360, 480, 5) and names[:3] == ["R", "G", "B"]
    import OpenEXR

    with OpenEXR.File(str(exrs[0])) as f:  # the header dict lives only while the file is open
        h = {k: v for k, v in f.header().items() if k.startswith("gonio_")}
    assert len(json.loads(h["gonio_exposures_s"])) >= 1
    assert np.asarray(json.loads(h["gonio_pose_R"])).shape == (3, 3)
    assert set(json.loads(h["gonio_joints_deg"])) == {j.name for j in rig.joints}
    # the table: scattered samples with sigma at the root, the gridded table in /gridded
    samples = read_native(path / "table.brdf.h5")
    assert samples.values.shape == (3, 3) and samples.sigma is not None
    grid = read_native(path / "table.brdf.h5", group="gridded")
    assert grid.mask.sum() >= 2 and grid.sigma is not None
    assert int(np.asarray(grid.counts).sum()) == 3
    valid = grid.mask
    assert np.all(np.asarray(grid.sigma)[valid] > 0)
    assert samples.meta["reciprocity"]["pairs"] == 1


@pytest.mark.xfail(
    strict=True,
    reason="the reciprocal pair (light 25 / camera 45 deg and swapped) is compared at directions"
    " up to 0.19 deg apart (servo settle errors), over which the Phong n = 80 flank changes f by"
    " 2-3 %; the pair's z (gonio.acquire.table.reciprocal_pairs) has no term for that, so |z| p95"
    " is 5.8 and 6.8 at [sim] seeds 1 and 2 before the board's lens blur too (1.1 at the shipped"
    " seed 7 was its noise realization; the blur changes the noise stream), 4.7, 8.2, 9.3 at seeds"
    " 7, 1, 2 now; each configuration agrees with the truth at its own directions (|z| <= 2.9)",
)
def test_reciprocal_pair_agrees_within_the_noise_model(run):
    path, _, _ = run
    rec = read_native(path / "table.brdf.h5").meta["reciprocity"]
    # swapped light and camera agree within the noise model (4 sigma, 3 channels)
    assert rec["abs_z_p95"] < 4.0


def test_values_match_the_ground_truth_within_the_noise_model(run):
    path, rig, _ = run
    z, geo, _ = z_and_geometry(path, rig)
    # 9 values: the median of |z| for a normal is 0.67; allow sampling spread (fixed seed)
    assert np.median(z) <= 1.2, z
    assert np.max(z) < 4.0, z
    assert np.max(geo) < 0.05, geo


def test_white_reference_only_run_recovers_rho_over_pi(tmp_path):
    (tmp_path / "plan.toml").write_text(
        'kind = "isotropic"\ntheta_i_deg = [30]\ntheta_o_deg = [40]\ndphi_deg = [150]\n'
    )
    rig = small_rig("params = { albedo = [0.99, 0.99, 0.99] }")
    s = acquire(tmp_path / "run", rig, tmp_path / "plan.toml", progress=False)
    t = read_native(tmp_path / "run" / "table.brdf.h5")
    assert s.done == 1
    np.testing.assert_allclose(np.asarray(t.values), 0.99 / np.pi, rtol=0.01)


@pytest.mark.slow
def test_interrupted_imaging_run_resumes_to_the_same_samples(run, tmp_path):
    path, rig, _ = run
    (tmp_path / "plan.toml").write_text(PLAN)

    def stop_after_one(n, session):
        if n == 1:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        acquire(tmp_path / "r", rig, tmp_path / "plan.toml", progress=False,
                on_sample=stop_after_one)  # fmt: skip
    s = acquire(tmp_path / "r", resume=True, progress=False)
    assert s.complete and s.measured_now == 2
    _, _, want = z_and_geometry(path, rig)
    _, _, got = z_and_geometry(tmp_path / "r", rig)
    for a, b in zip(want, got, strict=True):
        np.testing.assert_array_equal(a.value, b.value)
        np.testing.assert_array_equal(a.sigma, b.sigma)


def test_a_saturating_probe_is_rescued_by_shorter_brackets(tmp_path):
    from gonio.rigs.devices import Geometry

    rig = small_rig()
    kin = Kinematics(rig)
    joints = {"light_arm": 30.0, "camera_arm": -40.0, "tilt": 0.0, "turntable": 0.0}
    wi, wo = kin.forward(kin.joints_deg_to_pose(joints))
    with imaging_camera(rig, tmp_path) as cam:
        cam.settings.exposure_s = 0.5  # ~100x too long: the whole holder saturates
        cap = cam.capture(Geometry(0, joints, wi, wo, wi * 0.6, wo * 0.8))
    assert min(cap.meta["exposures_s"]) < 0.05 < max(cap.meta["exposures_s"])
    truth = np.asarray(models.Node.from_dict(rig.sim.sample).f(cap.meta["wi"], cap.meta["wo"]))
    assert np.all(np.abs(cap.value - truth) < 4 * cap.sigma)


def test_rig_file_sets_the_blooming_guard():
    from gonio.acquire.imaging import settings_from_rig
    from gonio.errors import RigConfigError

    text = load_rig("sim").text
    assert settings_from_rig(parse_rig(text, "sim.toml")).bloom_guard_px == 1
    off = text.replace("spot_radius_m = 0.002", "spot_radius_m = 0.002\nbloom_guard_px = 0")
    assert settings_from_rig(parse_rig(off, "off.toml")).bloom_guard_px == 0
    bad = text.replace("spot_radius_m = 0.002", "spot_radius_m = 0.002\nbloom_guard_px = -1")
    with pytest.raises(RigConfigError, match="bloom_guard_px"):
        parse_rig(bad, "bad.toml")


def test_board_at_a_grazing_view_is_found_though_opencv_checks_reject_it(tmp_path):
    # [sim] seed 8's configuration 110 of the full demo plan (theta_o = 70 deg, the joints the
    # servos reached): 24 markers decode, but OpenCV's CharucoParameters.checkMarkers test drops
    # the board once the longer brackets are merged ("0 corners"), which stopped the whole run
    import re

    from gonio.demo.materials import builtin_material
    from gonio.demo.pipeline import rig_text
    from gonio.rigs.devices import Geometry

    text = re.sub(r"(?m)^seed = \d+", "seed = 8", rig_text(builtin_material()), count=1)
    rig = parse_rig(text, "seed8.toml")
    kin = Kinematics(rig)
    joints = {"light_arm": 31.46484375, "camera_arm": -69.2578125, "tilt": 15.8203125,
              "turntable": 0.0}  # fmt: skip
    wi, wo = kin.forward(kin.joints_deg_to_pose(joints))
    with imaging_camera(rig, tmp_path) as cam:
        cap = cam.capture(Geometry(110, joints, wi, wo, wi * 0.6, wo * 0.8))
    assert cap.meta["pose_corners"] >= 20 and cap.meta["reprojection_px"] < 0.3
    _, wo_true = kin.forward(kin.joints_deg_to_pose(joints))
    assert np.degrees(np.arccos(np.clip(wo_true @ cap.meta["wo"], -1, 1))) < 0.05
    truth = np.asarray(models.Node.from_dict(rig.sim.sample).f(cap.meta["wi"], cap.meta["wo"]))
    assert np.all(np.abs(cap.value - truth) < 4 * cap.sigma)


def test_a_frame_that_cannot_be_measured_is_retaken_then_rejected(tmp_path, monkeypatch):
    from gonio.acquire.imaging import ImagingCamera
    from gonio.errors import FrameError

    (tmp_path / "plan.toml").write_text(PLAN)
    tags = []
    measure = ImagingCamera._measure

    def no_board_at_1(self, geometry, exposure_s, tag, times):
        tags.append(tag)
        if geometry.index == 1:
            raise FrameError("ChArUco board not found: 0 corners detected, need 6")
        return measure(self, geometry, exposure_s, tag, times)

    monkeypatch.setattr(ImagingCamera, "_measure", no_board_at_1)
    s = acquire(tmp_path / "run", small_rig(), tmp_path / "plan.toml", progress=False)
    assert s.complete and s.planned == 3 and s.done == 2 and s.rejected == 1
    assert tags.count("c00001") == 1 and tags.count("c00001_retake") == 1
    assert "1 configuration(s) rejected" in s.table_note and "board not found" in s.table_note
    j = Journal(tmp_path / "run")
    try:
        rej = [c for c in j.configs() if c.status == "rejected"]
        assert [c.idx for c in rej] == [1] and "on a retake" in rej[0].reason
        assert j.counts() == {"planned": 3, "refused": 0, "rejected": 1, "done": 2}
    finally:
        j.close()
    events = [json.loads(x) for x in (tmp_path / "run" / "log.jsonl").read_text().splitlines()]
    assert [e["idx"] for e in events if e["event"] == "rejected"] == [1]
    assert read_native(tmp_path / "run" / "table.brdf.h5").values.shape == (2, 3)
    # a resumed run does not measure it again
    again = acquire(tmp_path / "run", resume=True, progress=False)
    assert again.complete and again.measured_now == 0 and again.rejected == 1
