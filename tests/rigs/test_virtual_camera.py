import numpy as np
import pytest

from gonio.acquire.pose import estimate_pose, to_8bit
from gonio.brdf import models
from gonio.errors import DeviceError
from gonio.io.dng import read_dng
from gonio.rigs.sim.camera import CameraPose, PinholeCamera, VirtualCamera


def _pose(theta_deg, phi=0.4, dist=0.5):
    t = np.radians(theta_deg)
    pos = dist * np.array([np.sin(t) * np.cos(phi), np.sin(t) * np.sin(phi), np.cos(t)])
    return CameraPose.looking_at_origin(pos)


@pytest.fixture(scope="module")
def cam():
    truth = models.Lambert([0.6, 0.5, 0.4])
    return VirtualCamera(truth=truth, camera=PinholeCamera(640, 480, 1600))


def test_radiance_of_the_reference_and_sample_follow_inverse_square(cam):
    pose = _pose(20)
    light = np.array([0.2, -0.1, 0.45])
    L = cam.radiance(pose, light, intensity=[3.0, 3.0, 3.0])
    # Project the centres of the sample and the reference into the image and compare.
    K = cam.camera.matrix
    for centre, albedo in (
        ((0.0, 0.0), np.array([0.6, 0.5, 0.4])),
        (cam.layout.reference_center, cam.layout.reference_albedo),
    ):
        p = np.array([centre[0], centre[1], 0.0])
        xc = pose.rotation @ (p - pose.position)
        u, v = (K @ (xc / xc[2]))[:2]
        d = light - p
        expect = albedo / np.pi * 3.0 * d[2] / np.linalg.norm(d) ** 3
        got = L[int(v), int(u)]
        np.testing.assert_allclose(got, expect, rtol=2e-3)


def test_same_seed_and_key_give_the_same_dng(cam, tmp_path):
    rate = cam.electron_rate(_pose(30), np.array([0.3, 0.0, 0.4]), 2.0)
    a, _ = cam.capture(tmp_path / "a.dng", rate, 1e-3, key="c0-e0", meta={"theta_o": 30})
    b, _ = cam.capture(tmp_path / "b.dng", rate, 1e-3, key="c0-e0")
    c, _ = cam.capture(tmp_path / "c.dng", rate, 1e-3, key="c1-e0")
    fa, fb, fc = read_dng(a), read_dng(b), read_dng(c)
    assert np.array_equal(fa.data, fb.data)
    assert not np.array_equal(fa.data, fc.data)
    assert fa.meta["theta_o"] == 30 and fa.meta["exposure_nominal_s"] == 1e-3


@pytest.mark.parametrize("theta", [25, 45, 65])
def test_pose_from_the_charuco_board(theta):
    cam = VirtualCamera(truth=models.Lambert(0.5))
    pose = _pose(theta)
    rate = cam.electron_rate(pose, np.array([0.3, -0.2, 0.4]), 5.0)
    bp = estimate_pose(to_8bit(rate[..., 1]), cam.layout, cam.camera.matrix)
    c = bp.camera_position
    cos = np.dot(c, pose.position) / (np.linalg.norm(c) * np.linalg.norm(pose.position))
    err_deg = np.degrees(np.arccos(np.clip(cos, -1, 1)))
    assert bp.n_corners >= 20
    assert bp.reprojection_px < 0.5
    assert err_deg < 0.05, f"camera direction error {err_deg:.4f} deg at theta_o = {theta}"


def test_board_missing_is_a_device_error(cam):
    with pytest.raises(DeviceError, match="ChArUco"):
        estimate_pose(np.zeros((480, 640), np.uint8), cam.layout, cam.camera.matrix)
