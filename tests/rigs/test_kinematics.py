"""Forward/inverse kinematics: known poses, round trips (hypothesis), refusals with reasons."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from gonio.errors import PlanError
from gonio.rigs.config import load_rig
from gonio.rigs.kinematics import Kinematics, Pose, direction, forward, spherical

RIG = load_rig("sim")
KIN = Kinematics(RIG)


def test_in_plane_pose_gives_expected_angles():
    # tilt = rot = 0: the normal points at arm angle 0; the light at +30 deg, camera at -45 deg
    wi, wo = forward(math.radians(30), math.radians(-45), 0.0, 0.0)
    ti, pi = spherical(wi)
    to, po = spherical(wo)
    assert math.degrees(ti) == pytest.approx(30)
    assert math.degrees(to) == pytest.approx(45)
    assert abs(math.remainder(po - pi, 2 * math.pi)) == pytest.approx(math.pi)


def test_tilt_lifts_normal_out_of_plane():
    # light at arm angle 0, tilt t: theta_i = |t|
    for t in (-0.4, 0.2, 0.7):
        wi, _ = forward(0.0, 1.0, t, 0.0)
        assert spherical(wi)[0] == pytest.approx(abs(t))


def test_turntable_rotates_azimuth_only():
    a = forward(0.3, -0.5, 0.2, 0.0)
    b = forward(0.3, -0.5, 0.2, 0.4)
    for u, v in zip(a, b, strict=True):
        assert spherical(u)[0] == pytest.approx(spherical(v)[0])
        assert math.remainder(spherical(u)[1] - spherical(v)[1], 2 * math.pi) == pytest.approx(0.4)


# generation is filtered (poses the rig refuses) and the host may be loaded: neither is a failure
SLOW_OK = [HealthCheck.too_slow, HealthCheck.filter_too_much]

angle = st.floats(0.02, math.radians(78))
azim = st.floats(0.0, 2 * math.pi)


@settings(max_examples=200, deadline=None, suppress_health_check=SLOW_OK)
@given(angle, azim, angle, azim)
def test_inverse_then_forward_roundtrip(ti, pi, to, po):
    wi, wo = direction(ti, pi), direction(to, po)
    pose, _ = KIN.inverse(wi, wo)
    assume(pose is not None)  # refusals are tested separately
    a, b = KIN.forward(pose)
    np.testing.assert_allclose(a, wi, atol=1e-9)
    np.testing.assert_allclose(b, wo, atol=1e-9)
    assert KIN.refusal(pose) is None


@settings(max_examples=100, deadline=None, suppress_health_check=SLOW_OK)
@given(angle, angle, st.floats(0.2, math.pi))
def test_isotropic_inverse_keeps_relative_geometry(ti, to, dphi):
    wi, wo = direction(ti, 0.0), direction(to, dphi)
    pose, _ = KIN.inverse(wi, wo, isotropic=True)
    assume(pose is not None)
    assert pose.rot == pytest.approx(0.0)  # the turntable is held
    a, b = KIN.forward(pose)
    assert spherical(a)[0] == pytest.approx(ti, abs=1e-9)
    assert spherical(b)[0] == pytest.approx(to, abs=1e-9)
    assert float(np.dot(a, b)) == pytest.approx(float(np.dot(wi, wo)), abs=1e-9)


@settings(max_examples=100, deadline=None, suppress_health_check=SLOW_OK)
@given(st.floats(-2.9, 2.9), st.floats(-2.9, 2.9), st.floats(-1.4, 1.4), st.floats(-3.1, 3.1))
def test_forward_then_inverse_reaches_same_directions(al, ac, tilt, rot):
    wi, wo = forward(al, ac, tilt, rot)
    assume(wi[2] > 0.2 and wo[2] > 0.2)
    pose, _ = KIN.inverse(wi, wo)
    assume(pose is not None)
    a, b = KIN.forward(pose)
    np.testing.assert_allclose(a, wi, atol=1e-9)
    np.testing.assert_allclose(b, wo, atol=1e-9)


def test_refusals_name_the_reason():
    # light and camera at the same place: occlusion
    pose, why = KIN.inverse(direction(0.5, 0.0), direction(0.5, 0.02))
    assert pose is None and "min_light_camera_deg" in why
    # grazing beyond max_theta_deg
    pose, why = KIN.inverse(direction(math.radians(85), 0.0), direction(0.3, 2.0))
    assert pose is None and "too grazing" in why
    # a keep-out sector of the light arm (165..170 deg)
    p = Pose(math.radians(167), math.radians(100), 0.0, 0.0)
    assert "keep-out" in KIN.refusal(p)
    p = Pose(0.0, 1.0, math.radians(86), 0.0)
    assert "outside its limits" in KIN.refusal(p)
    with pytest.raises(PlanError, match="refused: light and camera"):
        KIN.require(direction(0.5, 0.0), direction(0.5, 0.0))


def test_inverse_prefers_pose_near_reference():
    from gonio.rigs.config import parse_rig

    # arms that may pass each other: both mirror solutions are allowed
    kin = Kinematics(
        parse_rig(RIG.text.replace("[safety]\n", "[safety]\narms_can_pass = true\n"), "x")
    )
    wi, wo = direction(0.6, 0.3), direction(0.9, 2.5)
    cands = [c for c in kin.candidates(wi, wo) if kin.refusal(c) is None]
    assert len(cands) >= 2
    for c in cands:
        pose, _ = kin.inverse(wi, wo, near=c)
        assert pose == c


def test_keepout_sector_may_be_neither_entered_nor_crossed():
    hw = Kinematics(load_rig("xm430_4axis"))  # camera arm keep-out 150..160, park -90
    inside = Pose(math.radians(20), math.radians(155), 0.0, 0.0)
    assert "keep-out sector (camera cable chain" in hw.refusal(inside)
    across = Pose(math.radians(20), math.radians(163), 0.0, 0.0)
    assert "across the keep-out sector" in hw.refusal(across)
    # on the park side the sector does not apply (that pose fails only for being behind the
    # sample)
    assert "keep-out" not in hw.refusal(Pose(math.radians(20), math.radians(149), 0.0, 0.0))


def test_arms_keep_their_park_order():
    # park: light 60 > camera -60 on the sim rig; swapping sides is refused
    p = Pose(math.radians(-30), math.radians(20), 0.0, 0.0)
    assert "pass each other" in KIN.refusal(p)
    # for an isotropic sample the mirrored solution keeps the order and the geometry
    wi, wo = forward(*p.as_tuple())
    pose, why = KIN.inverse(wi, wo, isotropic=True)
    assert why is None and pose.light > pose.camera
    a, b = KIN.forward(pose)
    assert spherical(a)[0] == pytest.approx(spherical(wi)[0])
    assert spherical(b)[0] == pytest.approx(spherical(wo)[0])
    assert float(np.dot(a, b)) == pytest.approx(float(np.dot(wi, wo)))
