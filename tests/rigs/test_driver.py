"""ServoChain over dynamixel-sdk against the emulator: motion, limits, faults."""

from __future__ import annotations

import pytest

from gonio.errors import DeviceError, PlanError
from gonio.rigs import control_table as ct
from gonio.rigs.config import load_rig
from gonio.rigs.dynamixel import HardwareFault
from gonio.rigs.session import open_rig
from gonio.rigs.sim import FaultConfig

RIG = load_rig("sim")
POSE = {"light_arm": 35.0, "camera_arm": -50.0, "tilt": 12.5, "turntable": -30.0}


def within_tol(res, target):
    for j in RIG.joints:
        assert abs(res.reached_deg[j.name] - target[j.name]) <= j.settle_tolerance_deg + 1e-9


def test_initialize_configures_servos_and_move_reads_back():
    with open_rig(RIG) as s:
        emu = s.emulator
        for j in RIG.joints:
            assert emu.register(j.id, ct.TORQUE_ENABLE) == 1
            assert emu.register(j.id, ct.PROFILE_VELOCITY) == ct.deg_s_to_velocity_raw(
                j.profile_velocity_deg_s
            )
        res = s.chain.move(POSE)
        within_tol(res, POSE)
        # the reported angles are the servo's Present Position, not the command
        for j in RIG.joints:
            assert res.reached_deg[j.name] == j.from_ticks(
                emu.register(j.id, ct.PRESENT_POSITION, signed=True)
            )
        assert res.motion_s > 0
        assert [g.ticks for g in emu.goal_log[-4:]] == [
            j.to_ticks(POSE[j.name]) for j in RIG.joints
        ]


@pytest.mark.parametrize(
    "bad",
    [
        {**POSE, "tilt": 86.0},
        {**POSE, "light_arm": -171.0},
        {k: v for k, v in POSE.items() if k != "turntable"},
        {**POSE, "elbow": 0.0},
        {**POSE, "light_arm": 167.0},  # keep-out sector 165..170 of the sim rig
    ],
)
def test_limits_checked_before_anything_is_sent(bad):
    with open_rig(RIG) as s:
        n_before = s.emulator.packets_in
        with pytest.raises(PlanError):
            s.chain.move(bad)
        assert s.emulator.goal_log == []
        assert s.emulator.packets_in == n_before


def test_moves_complete_under_packet_faults():
    faults = FaultConfig(drop=0.04, garble=0.04, crc=0.04, seed=3)
    with open_rig(RIG, faults=faults) as s:
        for k in range(12):
            target = {
                "light_arm": 20.0 + 7 * k,
                "camera_arm": -30.0 - 5 * k,
                "tilt": -20.0 + 3 * k,
                "turntable": 10.0 * k,
            }
            within_tol(s.chain.move(target), target)
        st = s.chain.bus.stats
        assert st.retries > 0
        assert s.emulator.crc_errors_seen > 0


def test_overload_raises_and_nothing_reboots_or_moves_it_again():
    # the old design rebooted the servo and drove it into the same move; an overload means the
    # arm met something (a cable, a hand): the move stops, nothing is rebooted or re-sent
    with open_rig(RIG) as s:
        s.chain.move(POSE)
        n_goals = len(s.emulator.goal_log)
        s.emulator.overload(3)
        with pytest.raises(HardwareFault, match=r"servo 3 \(tilt\): overload") as err:
            s.chain.move({**POSE, "tilt": -10.0})
        assert err.value.joints == ("tilt",) and err.value.faults == {"tilt": ct.HW_OVERLOAD}
        assert err.value.policy.key == "overload"
        assert s.emulator.register(3, ct.HARDWARE_ERROR_STATUS) == ct.HW_OVERLOAD
        assert s.emulator.register(3, ct.TORQUE_ENABLE) == 0
        assert not [r for r in s.emulator.packet_log if r.instruction == 0x08]  # no reboot
        # the failed move's goals went out once (a lost one re-sent), none after the fault
        assert len(s.emulator.goal_log) - n_goals <= 4


def test_overload_of_a_resting_servo_raises_hardware_fault():
    with open_rig(RIG) as s:
        s.emulator.overload(2)
        with pytest.raises(HardwareFault, match=r"camera_arm\): overload"):
            s.chain.move(POSE)


def test_reboot_is_explicit_and_leaves_torque_off():
    with open_rig(RIG, initialize=False) as s:
        s.emulator.hardware_error(2, ct.HW_OVERHEATING)
        assert s.chain.reboot() == {"camera_arm": ct.HW_OVERHEATING}
        assert s.emulator.register(2, ct.HARDWARE_ERROR_STATUS) == 0
        assert s.emulator.register(2, ct.TORQUE_ENABLE) == 0
        assert [r.id for r in s.emulator.packet_log if r.instruction == 0x08] == [2]
        assert s.emulator.goal_log == []


def test_dead_servo_gives_device_error_naming_it():
    with open_rig(RIG) as s:
        s.emulator.kill(4)
        with pytest.raises(DeviceError, match=r"servo 4|\[.*4.*\]"):
            s.chain.move(POSE)


def test_model_mismatch_is_refused():
    text = RIG.text.replace('model = "XM430-W350"', 'model = "XL430-W250"', 1)
    from gonio.rigs.config import parse_rig
    from gonio.rigs.dynamixel import ServoChain
    from gonio.rigs.session import make_emulator

    rig_file = parse_rig(text, "x.toml")
    with make_emulator(RIG) as emu:  # the bus really has XM430s
        chain = ServoChain(rig_file, port=emu.port)
        with chain, pytest.raises(DeviceError, match=r"light_arm.*XM430-W350.*XL430-W250"):
            chain.initialize()


def test_check_reports_models_and_hardware_errors():
    with open_rig(RIG, initialize=False) as s:
        s.emulator.overload(1)
        infos = s.chain.check()
    assert [i.model for i in infos] == ["XM430-W350"] * 4
    assert [i.firmware for i in infos] == [RIG.sim.firmware] * 4
    assert infos[0].hardware_error == ct.HW_OVERLOAD and infos[0].alert and not infos[0].ok
    assert all(i.ok for i in infos[1:])


def test_pyserial_url_ports_open_through_the_sdk():
    from gonio.rigs.dynamixel import DynamixelBus

    # loop:// echoes our own instruction back: the SDK discards it (not a status packet), so
    # the ping times out and is retried, then fails with a one-line DeviceError
    with DynamixelBus("loop://", retries=1, backoff_s=0.0) as bus:
        with pytest.raises(DeviceError, match=r"ping servo 1: no valid reply after 2 attempts"):
            bus.ping(1)
        assert bus.stats.timeouts + bus.stats.corrupt == 2
    with pytest.raises(DeviceError, match="cannot open servo bus"):
        DynamixelBus("socket://127.0.0.1:1").open()


def test_arms_that_would_cross_on_the_way_move_in_two_phases():
    from gonio.rigs.config import parse_rig

    # a slow light arm and a fast camera arm: moving both at once, the camera would overtake
    # the light mid-move although both end poses keep them 15 deg apart
    text = RIG.text.replace(
        "profile_velocity_deg_s = 90.0\nprofile_acceleration_deg_s2 = 180.0",
        "profile_velocity_deg_s = 30.0\nprofile_acceleration_deg_s2 = 60.0",
        1,
    ).replace(
        "profile_velocity_deg_s = 90.0\nprofile_acceleration_deg_s2 = 180.0",
        "profile_velocity_deg_s = 180.0\nprofile_acceleration_deg_s2 = 720.0",
        1,
    )
    rig = parse_rig(text, "slow-light.toml")
    assert rig.joint("light_arm").profile_velocity_deg_s == 30.0
    assert rig.joint("camera_arm").profile_velocity_deg_s == 180.0
    start = {"light_arm": 30.0, "camera_arm": -40.0, "tilt": 0.0, "turntable": 0.0}
    goal = {"light_arm": 60.0, "camera_arm": 45.0, "tilt": 0.0, "turntable": 0.0}
    with open_rig(rig) as s:
        s.chain.move(start)
        assert s.chain.arm_transit_hold(start, goal) == "camera_arm"
        n0 = len(s.emulator.goal_log)
        res = s.chain.move(goal)
        assert s.chain.two_phase_moves == 1
        within_tol(res, goal)
        cam = [g for g in s.emulator.goal_log[n0:] if g.id == 2]
        light = [g for g in s.emulator.goal_log[n0:] if g.id == 1]
        # phase 1: camera held where it was while the light moves; phase 2: camera goes
        assert abs(cam[0].ticks - rig.joint("camera_arm").to_ticks(-40.0)) <= 3
        assert cam[-1].ticks == rig.joint("camera_arm").to_ticks(45.0)
        assert light[0].time <= cam[-1].time
    # the same move with equal profiles is safe together
    with open_rig(RIG) as s:
        assert s.chain.arm_transit_hold(start, goal) is None
