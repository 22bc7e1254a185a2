"""Rig and plan files: every non-finite or unrepresentable number, and every inconsistent safety
setting, is refused at load time with the key and its line named (issue 18, items 1-3)."""

from __future__ import annotations

import math
import re
from importlib import resources

import pytest

from gonio.errors import PlanError, RigConfigError
from gonio.rigs.config import parse_rig


def rig_text(name: str = "sim_sample") -> str:
    return resources.files("gonio.rigs").joinpath(f"{name}.toml").read_text()


_NUMBER = re.compile(r"^(\s*)([A-Za-z_]+)(\s*=\s*)(-?[0-9][0-9_.eE+-]*)(\s*(#.*)?)$")


def numeric_lines(text: str) -> list[tuple[int, str]]:
    """(1-based line, key) of every ``key = number`` line of a rig file."""
    return [
        (i + 1, m.group(2))
        for i, line in enumerate(text.splitlines())
        if (m := _NUMBER.match(line))
    ]


def with_value(text: str, line: int, value: str) -> str:
    lines = text.splitlines()
    m = _NUMBER.match(lines[line - 1])
    lines[line - 1] = f"{m.group(1)}{m.group(2)}{m.group(3)}{value}{m.group(5)}"
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("rig", ["sim_sample", "sim", "xm430_4axis"])
@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
def test_every_number_of_a_rig_file_refuses_non_finite(rig, value):
    text = rig_text(rig)
    lines = numeric_lines(text)
    assert len(lines) > 40
    for line, key in lines:
        with pytest.raises(RigConfigError) as exc:
            parse_rig(with_value(text, line, value), "bad.toml")
        msg = str(exc.value)
        assert msg.startswith(f"bad.toml:{line}: ") and key in msg and "\n" not in msg, msg


@pytest.mark.parametrize(
    ("old", "new", "key", "why"),
    [
        # item 1: the margins and keep-outs that NaN used to switch off
        ("min_light_camera_deg = 8.0", "min_light_camera_deg = nan", "min_light_camera", "finite"),
        ("max_theta_deg = 80.0", "max_theta_deg = nan", "max_theta_deg", "finite"),
        ("min_deg = 165.0\nmax_deg = 170.0", "min_deg = -50.0\nmax_deg = nan", "max_deg", "finite"),
        # item 2: numbers whose tick conversion overflowed or raised after torque was on
        ("settle_tolerance_deg = 0.3", "settle_tolerance_deg = inf", "settle_tolerance", "finite"),
        ("settle_tolerance_deg = 0.3", "settle_tolerance_deg = 400.0", "settle_tolerance", "range"),
        ("profile_velocity_deg_s = 90.0", "profile_velocity_deg_s = nan", "profile_vel", "finite"),
        (
            "profile_velocity_deg_s = 90.0",
            "profile_velocity_deg_s = 1e9",
            "profile_vel",
            "1..32767",
        ),
        (
            "profile_velocity_deg_s = 90.0",
            "profile_velocity_deg_s = 1e-6",
            "profile_vel",
            "1..32767",
        ),
        (
            "profile_acceleration_deg_s2 = 180.0",
            "profile_acceleration_deg_s2 = 1e12",
            "profile_acc",
            "1..32767",
        ),
        ("gear_ratio = 1.0", "gear_ratio = 1e308", "joints[0].min_deg", "servo tick"),
        ("gear_ratio = 1.0", "gear_ratio = nan", "gear_ratio", "finite"),
        ("zero_offset_deg = 0.0", "zero_offset_deg = 1e308", "joints[0].min_deg", "servo tick"),
        ("min_deg = -170.0", "min_deg = -1e308", "joints[0].min_deg", "servo tick"),
        ("max_deg = 170.0", "max_deg = 1e308", "joints[0].max_deg", "servo tick"),
        ("backoff_ms = 1.0", "backoff_ms = 1e308", "bus.backoff_ms", "maximum"),
        ("seed = 7", "seed = 99999999999999999999", "sim.seed", "maximum"),
        # item 3: park and home poses
        ("light_arm = 60.0", "light_arm = 167.0", "park.light_arm", "keep-out"),
        ("camera_arm = -60.0", "camera_arm = 55.0", "park.light_arm", "apart"),
        ("min_deg = 165.0\nmax_deg = 170.0", "min_deg = 170.0\nmax_deg = 165.0", "min_deg", "<"),
    ],
)
def test_bad_safety_numbers_are_refused_naming_the_key(old, new, key, why):
    text = rig_text()
    assert old in text, old
    with pytest.raises(RigConfigError) as exc:
        parse_rig(text.replace(old, new, 1), "bad.toml")
    msg = str(exc.value)
    assert re.match(r"bad\.toml:\d+: ", msg) and key in msg and why in msg, msg


def test_home_angle_of_an_unparked_keepout_joint_is_checked():
    text = rig_text().replace("light_arm = 60.0\n", "", 1)  # light arm home: its centre, 0 deg
    keep = "min_deg = 165.0\nmax_deg = 170.0"
    parse_rig(text, "ok.toml")
    with pytest.raises(RigConfigError, match=r"safety\.keepout\[0\]\.joint: home angle 0\.0"):
        parse_rig(text.replace(keep, "min_deg = -5.0\nmax_deg = 5.0"), "bad.toml")


@pytest.mark.parametrize(
    ("body", "key"),
    [
        ("theta_i_deg = [20, nan]\ntheta_o_deg = [20]\ndphi_deg = [180]", "theta_i_deg[1]"),
        (
            "theta_i_deg = [20]\ntheta_o_deg = { start = 0, stop = inf, step = 10 }\n"
            "dphi_deg = [180]",
            "theta_o_deg.stop",
        ),
        (
            "theta_i_deg = [20]\ntheta_o_deg = { start = 0, stop = 60, step = nan }\n"
            "dphi_deg = [180]",
            "theta_o_deg.step",
        ),
        (
            "theta_i_deg = [20]\ntheta_o_deg = [20]\ndphi_deg = { start = 0, stop = 1e300, "
            "step = 1e-300 }",
            "dphi_deg",
        ),
    ],
)
def test_plan_files_refuse_non_finite_and_huge_ranges_naming_key_and_line(tmp_path, body, key):
    from gonio.acquire.plans import load_plan

    p = tmp_path / "p.toml"
    p.write_text('kind = "isotropic"\n' + body + "\n")
    with pytest.raises(PlanError) as exc:
        load_plan(p)
    msg = str(exc.value)
    name = key.split(".")[0].split("[")[0]
    line = next(i + 1 for i, l in enumerate(p.read_text().splitlines()) if l.startswith(name))
    assert msg.startswith(f"{p}:{line}: ") and key in msg and "\n" not in msg, msg


def test_plan_refine_values_must_be_finite_and_positive(tmp_path):
    from gonio.acquire.plans import load_plan

    p = tmp_path / "a.toml"
    base = 'kind = "adaptive"\ntheta_i_deg = [20]\ntheta_o_deg = [20]\ndphi_deg = [180]\n'
    for bad in ("window_deg = nan", "step_deg = -1.0", "peak_ratio = inf"):
        p.write_text(base + "[refine]\n" + bad + "\n")
        with pytest.raises(PlanError, match=rf"a\.toml:6: refine\.{bad.split()[0]}"):
            load_plan(p)


def test_guard_refuses_nan_even_when_validation_is_bypassed():
    import dataclasses

    from gonio.rigs.config import Keepout, load_rig
    from gonio.rigs.guard import GoalGuard
    from gonio.rigs.kinematics import Kinematics, Pose

    rig = load_rig("sim_sample")
    nan = math.nan
    inside = rig.joint("light_arm").to_ticks(-20.0)
    for bad in (
        dataclasses.replace(rig, safety=dataclasses.replace(rig.safety, min_light_camera_deg=nan)),
        dataclasses.replace(
            rig, safety=dataclasses.replace(rig.safety, keepout=(Keepout("light_arm", -50, nan),))
        ),
    ):
        g = GoalGuard(bad)
        with pytest.raises(PlanError):
            g.check({1: inside, 2: rig.joint("camera_arm").to_ticks(-60.0)})
        pose = Pose(math.radians(-20.0), math.radians(-60.0), 0.0, 0.0)
        assert Kinematics(bad).refusal(pose) is not None
    bad = dataclasses.replace(rig, safety=dataclasses.replace(rig.safety, max_theta_deg=nan))
    assert Kinematics(bad).refusal(Pose(0.3, -0.3, 0.0, 0.0)) is not None
