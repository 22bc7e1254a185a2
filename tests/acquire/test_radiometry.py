"""Imaging chain without the rig: render -> DNG brackets -> merge -> pose -> f in 1/sr."""

import numpy as np
import pytest

from gonio.acquire.hdr import Bracket, NoiseModel, merge_brackets, plan_exposures
from gonio.acquire.pose import estimate_pose, mosaic_to_gray, pose_samples, to_8bit
from gonio.acquire.radiometry import measure_brdf
from gonio.brdf import frames, models
from gonio.io.dng import read_dng
from gonio.rigs.sim.camera import CameraPose, PinholeCamera, VirtualCamera


class Glossy:
    """A test-only ground truth: Lambert + a normalized Phong lobe written out here."""

    def f(self, wi, wo):
        wi, wo = np.asarray(wi), np.asarray(wo)
        r = wo * [-1, -1, 1]
        c = np.clip(np.sum(wi * r, -1), 0, 1)
        spec = 0.3 * (40 + 2) / (2 * np.pi) * c**40
        return np.array([0.10, 0.15, 0.20]) / np.pi + spec[..., None]


def _position(theta_deg, phi_deg, dist):
    return dist * np.asarray(
        frames.spherical_to_direction(np.radians(theta_deg), np.radians(phi_deg))
    )


def _measure(cam, cam_pos, light_pos, tmp_path, key):
    """Capture one configuration the way the run engine does and return the measurement."""
    pose = CameraPose.looking_at_origin(cam_pos)
    rate = cam.electron_rate(pose, light_pos, 4.0)
    s = cam.sensor
    plan = plan_exposures(float(rate.max()), float(np.percentile(rate[rate > 0], 5)),
                          gain=s.gain, read_noise=s.read_noise, dark_current=s.dark_current,
                          full_well=s.full_well, snr_target=30)  # fmt: skip
    brackets = []
    for k, t in enumerate(plan.exposures_s):
        path, _ = cam.capture(tmp_path / f"{key}-{k}.dng", rate, t, key=f"{key}-{k}")
        fr = read_dng(path)
        brackets.append(Bracket(fr.data, fr.exposure_s, fr.black_map(), fr.white_level))
    hdr = merge_brackets(brackets, NoiseModel(s.gain, s.read_noise))
    gray = mosaic_to_gray(hdr.rate, s.cfa)
    bp = estimate_pose(to_8bit(gray), cam.layout, cam.camera.matrix)
    lay = cam.layout
    m = measure_brdf(hdr.rate, hdr.variance, s.plane_index(rate.shape[:2]), cam.camera.matrix,
                     bp.rotation, bp.translation, light_pos, lay.sample_center, lay.sample_radius,
                     lay.reference_center, lay.reference_radius, lay.reference_albedo,
                     frame_fraction=hdr.frame_fraction, log_time_cov=hdr.log_time_cov,
                     pose_sigma_points=pose_samples(bp))  # fmt: skip
    return m, bp, len(plan.exposures_s)


def test_white_reference_material_recovers_rho_over_pi(tmp_path):
    cam = VirtualCamera(truth=models.Lambert(0.99), camera=PinholeCamera(640, 480, 1600), seed=1)
    m, _, _ = _measure(cam, _position(35, 20, 0.5), _position(30, 200, 0.6), tmp_path, "w")
    np.testing.assert_allclose(m.f, 0.99 / np.pi, rtol=0.01)


# Was p95 |z| = 3.9: the "corner bias" was OpenCV's pixel-centre convention (integers) against
# gonio's (i + 0.5), half a pixel on every corner; estimate_pose now shifts K (median 0.77,
# p95 1.85, geometry 0.013 deg).
@pytest.mark.slow
def test_measured_values_match_truth_within_the_noise_model(tmp_path):
    truth = Glossy()
    cam = VirtualCamera(truth=truth, seed=2)
    zs, geo = [], []
    configs = [(to, po, ti, pi_) for to in (25, 45, 60) for ti in (20, 40, 60)
               for po, pi_ in ((0, 180), (30, 150), (0, 90))]  # fmt: skip
    for n, (to, po, ti, pi_) in enumerate(configs):
        cam_pos, light_pos = _position(to, po, 0.5), _position(ti, pi_, 0.6)
        m, _, _ = _measure(cam, cam_pos, light_pos, tmp_path, f"g{n}")
        f_true = truth.f(m.wi, m.wo)
        zs.append((m.f - f_true) / m.sigma)
        wo_true = cam_pos / np.linalg.norm(cam_pos)
        geo.append(np.degrees(np.arccos(np.clip(np.dot(m.wo, wo_true), -1, 1))))
    z = np.abs(np.concatenate(zs))
    print("median |z|", np.median(z), "p95", np.percentile(z, 95), "geometry max deg", max(geo))
    assert np.median(z) <= 1.0
    assert np.percentile(z, 95) <= 2.5
    assert max(geo) < 0.05
