"""Servo faults handled as the policy table says (gonio.rigs.faults.POLICY), proven on the
emulator's packet log: every hardware error bit on every joint mid-move and at open, a blocked
joint, and the run engine's journal, log and one-line message."""

from __future__ import annotations

import json
from contextlib import contextmanager

import pytest

from gonio.acquire import stopping
from gonio.acquire.engine import acquire
from gonio.acquire.journal import Journal
from gonio.cli import main
from gonio.errors import DeviceError
from gonio.interrupts import StopFlag
from gonio.rigs import control_table as ct
from gonio.rigs.config import load_rig, parse_rig
from gonio.rigs.faults import (
    EVERY,
    FAULTED,
    NONE,
    OTHERS,
    HardwareFault,
    LatchedAtOpen,
    MotionTimeout,
    bit_policies,
    policy,
)
from gonio.rigs.protocol import REBOOT
from gonio.rigs.session import open_rig

BASE = load_rig("sim_sample")
#: the sim rig with fast simulated time and a short motion timeout (a stall is found quickly)
RIG = parse_rig(
    BASE.text.replace("time_scale = 60.0", "time_scale = 1000.0").replace(
        "motion_timeout_s = 3.0", "motion_timeout_s = 0.4"
    ),
    "fast.toml",
)
BITS = sorted(ct.HW_ERROR_NAMES)
JOINTS = [j.name for j in RIG.joints]
POSE = {"light_arm": 35.0, "camera_arm": -50.0, "tilt": 12.5, "turntable": -30.0}
POSE2 = {"light_arm": 50.0, "camera_arm": -20.0, "tilt": -15.0, "turntable": 40.0}
#: a plan of 9 configurations
PLAN = (
    'kind = "isotropic"\ntheta_i_deg = [20, 40]\ntheta_o_deg = [30, 50]\ndphi_deg = [0, 90, 180]\n'
)


@pytest.fixture
def plan(tmp_path):
    path = tmp_path / "tiny.toml"
    path.write_text(PLAN)
    return path


def _torque_writes(records, value=None):
    out = [w for r in records for w in r.writes(ct.TORQUE_ENABLE)]
    return out if value is None else [sid for sid, v in out if v == value]


def _check_rest(emu, records, faulted: str, pol) -> None:
    """After bring_to_rest: what each joint got, from the packets sent (``records``)."""
    assert pol.park == OTHERS and pol.torque_off == FAULTED and pol.stops_run
    bad = RIG.joint(faulted).id
    assert bad in _torque_writes(records, 0)  # torque off the faulted servo ...
    assert _torque_writes(records, 1) == []  # ... and nothing is powered again
    goals = [w for r in records for w in r.writes(ct.GOAL_POSITION)]
    assert bad not in {sid for sid, _ in goals}  # no goal for the faulted servo
    for j in RIG.joints:  # every other joint parked
        if j.name != faulted:
            park = j.to_ticks(RIG.park_deg[j.name])
            assert (j.id, park) in goals
            pos = emu.register(j.id, ct.PRESENT_POSITION, signed=True)
            assert abs(pos - park) <= j.tolerance_ticks
    assert emu.register(bad, ct.TORQUE_ENABLE) == 0


def _matrix():
    """Every bit on every joint: one joint per bit in the default run, the rest under slow."""
    out = []
    for k, bit in enumerate(BITS):
        for i, joint in enumerate(JOINTS):
            marks = () if i == k % len(JOINTS) else (pytest.mark.slow,)
            out.append(
                pytest.param(bit, joint, marks=marks, id=f"{ct.HW_ERROR_NAMES[bit]}-{joint}")
            )
    return out


@pytest.mark.parametrize(("bit", "joint"), _matrix())
def test_hardware_error_mid_move_is_handled_as_the_policy_says(bit, joint):
    jid = RIG.joint(joint).id
    with open_rig(RIG) as s:
        emu = s.emulator
        s.chain.move(POSE)
        emu.hardware_error(jid, bit, next_move=True)
        with pytest.raises(HardwareFault) as err:
            s.chain.move(POSE2)
        fault = err.value
        assert fault.joints == (joint,) and fault.faults == {joint: bit}
        assert fault.policy == bit_policies(bit)[0] and fault.policy.key == ct.HW_ERROR_NAMES[bit]
        n0 = len(emu.packet_log)
        parked, phrase = stopping.bring_to_rest(s.chain, StopFlag(), fault)
        assert parked and phrase == f"{joint} torque off, the other joints parked"
        _check_rest(emu, emu.packet_log[n0:], joint, fault.policy)
        assert emu.register(jid, ct.HARDWARE_ERROR_STATUS) == bit  # still latched
        assert not [r for r in emu.packet_log if r.instruction == REBOOT]


@pytest.mark.parametrize(("bit", "joint"), _matrix())
def test_latch_found_at_open_is_refused_with_no_torque_and_no_motion(bit, joint):
    jid = RIG.joint(joint).id
    pol = policy("latch at open")
    assert pol.park == NONE and pol.torque_off == EVERY and pol.stops_run
    with open_rig(RIG, initialize=False) as s:
        emu = s.emulator
        emu.hardware_error(jid, bit)
        with pytest.raises(LatchedAtOpen, match=rf"servo {jid} \({joint}\)") as err:
            s.chain.initialize()
        assert err.value.policy == pol and err.value.faults == {joint: bit}
        notes = " ".join(err.value.__notes__)
        assert "nothing moved, torque off" in notes and "gonio rig reboot" in notes
        log = emu.packet_log
        assert sorted(set(_torque_writes(log, 0))) == [j.id for j in RIG.joints]
        assert _torque_writes(log, 1) == [] and emu.goal_log == []
        assert not [r for r in log if r.instruction == REBOOT]


def test_blocked_joint_times_out_torque_off_and_the_others_park():
    pol = policy("stall")
    with open_rig(RIG) as s:
        emu = s.emulator
        s.chain.move(POSE)
        emu.block(2)  # the camera arm meets an obstacle half-way through its next move
        with pytest.raises(MotionTimeout, match=r"servo 2 \(camera_arm\) stopped at") as err:
            s.chain.move(POSE2)
        assert err.value.joints == ("camera_arm",) and err.value.policy == pol
        stuck = emu.register(2, ct.PRESENT_POSITION, signed=True)
        goal = RIG.joint("camera_arm").to_ticks(POSE2["camera_arm"])
        assert abs(stuck - goal) > 100 and emu.register(2, ct.TORQUE_ENABLE) == 1
        n0 = len(emu.packet_log)
        parked, phrase = stopping.bring_to_rest(s.chain, StopFlag(), err.value)
        assert parked and phrase == "camera_arm torque off, the other joints parked"
        _check_rest(emu, emu.packet_log[n0:], "camera_arm", pol)
        assert emu.register(2, ct.PRESENT_POSITION, signed=True) == stuck


@contextmanager
def _latched_at_open(rig, run_dir, servo_id, bits):
    """open_session, with a latched error on one servo before the driver initializes it."""
    with open_rig(rig, initialize=False, log_dir=run_dir) as ses:
        ses.emulator.hardware_error(servo_id, bits)
        ses.chain.initialize()
        yield ses


def test_run_stops_on_an_overload_journals_it_and_resumes(tmp_path, plan):
    run = tmp_path / "run"

    def hook(n, ses):
        if n == 2:
            ses.emulator.hardware_error(2, ct.HW_OVERLOAD, next_move=True)

    with pytest.raises(HardwareFault) as err:
        acquire(run, RIG, plan, progress=False, on_sample=hook, write_table=False)
    notes = "; ".join(err.value.__notes__)
    assert "camera_arm torque off, the other joints parked" in notes
    assert "next: The joint met a load it should not" in notes
    j = Journal(run)
    (event,) = j.events()
    assert event[1] == "hardware error"
    assert event[2]["joints"] == ["camera_arm"] and event[2]["errors"] == {"camera_arm": "overload"}
    assert "torque off" in event[2]["rig"] and "gonio rig reboot" in event[2]["next"]
    assert json.loads(j.get_meta("last_stop"))["reason"] == "device error"
    done = j.counts()["done"]
    j.close()
    assert done == 2
    faults = [json.loads(x) for x in (run / "log.jsonl").read_text().splitlines()]
    assert [e["fault"] for e in faults if e["event"] == "fault"] == ["hardware error"]
    # a latched error found when resuming is refused, journaled, and moves nothing
    with pytest.raises(LatchedAtOpen):
        acquire(
            run,
            resume=True,
            progress=False,
            write_table=False,
            open_devices=lambda rig, d: _latched_at_open(rig, d, 2, ct.HW_OVERLOAD),
        )
    j = Journal(run)
    assert [e[1] for e in j.events()] == ["hardware error", "latch at open"]
    assert j.counts()["done"] == done
    j.close()
    # the user cleared it: the resumed run completes (a fresh emulator has no latch)
    s = acquire(run, resume=True, progress=False, write_table=False)
    assert s.complete and s.done == s.planned


def test_blocked_joint_from_the_rig_file_stops_the_cli_in_one_line(tmp_path, plan, capsys):
    text = RIG.text.replace("[sim.faults]\n", "[sim.faults]\nblock_servo = 2\nblock_after = 3\n")
    rig = tmp_path / "blocked.toml"
    rig.write_text(text)
    run = tmp_path / "run"
    rc = main(
        ["acquire", "--no-progress", "--rig", str(rig), "--plan", str(plan), "--out", str(run)]
    )
    err = capsys.readouterr().err
    assert rc == DeviceError.exit_code, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("gonio: move did not settle within")
    assert "servo 2 (camera_arm) stopped at" in lines[0]
    assert "camera_arm torque off, the other joints parked" in lines[0]
    assert "next: " in lines[0]
    j = Journal(run)
    (event,) = j.events()
    j.close()
    assert event[1] == "stall" and event[2]["joints"] == ["camera_arm"]


@pytest.mark.slow
@pytest.mark.parametrize("joint", JOINTS)
@pytest.mark.parametrize("bit", BITS, ids=[ct.HW_ERROR_NAMES[b] for b in BITS])
def test_every_bit_on_every_joint_stops_a_run_as_the_policy_says(tmp_path, plan, bit, joint):
    jid = RIG.joint(joint).id
    run = tmp_path / "run"
    packets = []

    def hook(n, ses):
        if n == 2:
            ses.emulator.hardware_error(jid, bit, next_move=True)
            packets.append(ses.emulator)

    with pytest.raises(HardwareFault) as err:
        acquire(run, RIG, plan, progress=False, on_sample=hook, write_table=False)
    assert err.value.faults == {joint: bit}
    assert f"{joint} torque off, the other joints parked" in err.value.__notes__
    emu = packets[0]
    n_fault = max(i for i, r in enumerate(emu.packet_log) if r.instruction == 0x02)  # its read
    _check_rest(emu, emu.packet_log[n_fault:], joint, err.value.policy)
    assert not [r for r in emu.packet_log if r.instruction == REBOOT]
    j = Journal(run)
    (event,) = j.events()
    j.close()
    assert event[1] == "hardware error" and event[2]["bits"] == {joint: bit}
