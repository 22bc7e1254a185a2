"""Issue 18, one test per item, against the built-in emulator and its packet log.

The rig is driven as hardware: the emulator is started here and the rig file's ``bus.port``
names its pseudo-terminal, so the packet log records every instruction the driver sent.
"""

from __future__ import annotations

import dataclasses
import json
import math
import signal
from contextlib import contextmanager
from importlib import resources

import pytest

from gonio.acquire.engine import acquire
from gonio.acquire.journal import Journal
from gonio.errors import DeviceError, Interrupted, PlanError, RigConfigError
from gonio.rigs import control_table as ct
from gonio.rigs.config import Keepout, parse_rig
from gonio.rigs.sim import ServoChainEmulator, ServoSpec

SIM_SAMPLE = resources.files("gonio.rigs").joinpath("sim_sample.toml").read_text()
PLAN = """kind = "isotropic"
theta_i_deg = [20, 40]
theta_o_deg = [20, 40]
dphi_deg = [90, 180]
"""


@contextmanager
def emulated(text: str = SIM_SAMPLE, models: dict[int, str] | None = None):
    """(emulator, rig on the emulator's port) for rig-file ``text``."""
    rig = parse_rig(text, "sim_sample.toml")
    specs = [
        ServoSpec(
            j.id,
            (models or {}).get(j.id, j.model),
            rig.sim.firmware,
            j.to_ticks(rig.park_deg.get(j.name, j.zero_offset_deg)),
        )
        for j in rig.joints
    ]
    emu = ServoChainEmulator(
        specs, time_scale=rig.sim.time_scale, settle_ticks=rig.sim.settle_ticks, seed=rig.sim.seed
    )
    port = emu.start()
    try:
        yield emu, parse_rig(text.replace('port = "sim"', f'port = "{port}"'), "hw.toml")
    finally:
        emu.stop()


@pytest.fixture
def plan_file(tmp_path):
    p = tmp_path / "plan.toml"
    p.write_text(PLAN)
    return p


def goals(emu) -> list[tuple[int, int]]:
    return emu.writes(ct.GOAL_POSITION)


def assert_goals_safe(emu, rig) -> int:
    """Every Goal Position on the wire within its joint's limits and outside every keep-out."""
    by_id = {j.id: j for j in rig.joints}
    sent = goals(emu)
    for sid, ticks in sent:
        j = by_id[sid]
        a = j.from_ticks(ticks)
        half = 180 / 4096 / j.gear_ratio
        assert j.min_deg - half <= a <= j.max_deg + half, (j.name, a)
        for k in rig.safety.keepout:
            if k.joint == j.name:
                assert a < k.min_deg + half or a > k.max_deg - half, (j.name, a, k)
    return len(sent)


def assert_parked(emu, rig) -> None:
    """The last goal of every servo is its park angle, and it rests there."""
    last = dict(goals(emu))
    for j in rig.joints:
        want = j.to_ticks(rig.park_deg[j.name])
        assert last[j.id] == want, j.name
        assert abs(emu.register(j.id, ct.PRESENT_POSITION, signed=True) - want) <= 3


def last_stop(run) -> dict:
    j = Journal(run)
    try:
        return json.loads(j.get_meta("last_stop"))
    finally:
        j.close()


# --- 1. NaN margins and keep-outs cannot switch the checks off -------------------------------


@pytest.mark.parametrize("case", ["min_sep", "keepout", "max_theta"])
def test_1_nan_safety_numbers_move_nothing_unsafe(tmp_path, plan_file, case):
    nan = math.nan
    with emulated() as (emu, rig):
        # validation refuses these at load time (tests/rigs/test_config_safety.py); here the
        # RigConfig is built around it, to show that the checks downstream refuse NaN too
        s = rig.safety
        bad = {
            "min_sep": dataclasses.replace(s, min_light_camera_deg=nan),
            "keepout": dataclasses.replace(s, keepout=(Keepout("light_arm", -50.0, nan),)),
            "max_theta": dataclasses.replace(s, max_theta_deg=nan),
        }[case]
        rig = dataclasses.replace(rig, safety=bad)
        run = tmp_path / "run"
        # every pose refused: the run is refused before the bus opens (nothing to measure)
        with pytest.raises(PlanError, match="nothing to measure"):
            acquire(run, rig, plan_file, progress=False, write_table=False)
        assert goals(emu) == [] and not run.exists()
        # the chain's own checks refuse the NaN too: with min_sep and keepout even the park
        # pose is refused, and parking falls back to torque off; max_theta leaves it allowed
        from gonio.acquire.stopping import bring_to_rest
        from gonio.interrupts import StopFlag
        from gonio.rigs.dynamixel import ServoChain

        with ServoChain(rig) as chain:
            chain.initialize()
            parked, phrase = bring_to_rest(chain, StopFlag())
        if case == "max_theta":
            assert parked, phrase
            assert_parked(emu, rig)
        else:
            assert not parked and "torque off" in phrase, phrase
            assert goals(emu) == []
            assert emu.writes(ct.TORQUE_ENABLE)[-4:] == [(j.id, 0) for j in rig.joints]


def test_1_last_moment_guard_refuses_goals_that_bypass_the_pose_checks():
    from gonio.errors import PlanError
    from gonio.rigs.dynamixel import ServoChain

    with emulated() as (emu, rig):
        chain = ServoChain(rig)
        with chain:
            chain.initialize()
            n0 = len(emu.packet_log)
            light = rig.joint("light_arm")
            for ticks in (light.to_ticks(167.0), light.to_ticks(171.0) + 20, 5000, -1):
                with pytest.raises(PlanError):
                    chain.bus.sync_write(ct.GOAL_POSITION, {light.id: ticks})
                with pytest.raises(PlanError):
                    chain.bus.write(light.id, ct.GOAL_POSITION, ticks)
            for angle in (math.nan, math.inf, 167.0):
                pose = {"light_arm": angle, "camera_arm": -60.0, "tilt": 0.0, "turntable": 0.0}
                with pytest.raises(PlanError):
                    chain.move(pose)
            assert len(emu.packet_log) == n0  # not one packet more
            # arms closer than the margin (both joints within their limits)
            with pytest.raises(PlanError, match="apart"):
                chain.guard.check(
                    {1: light.to_ticks(10.0), 2: rig.joint("camera_arm").to_ticks(5.0)},
                    {"light_arm": 60.0, "camera_arm": -60.0},
                )


# --- 2. numbers that overflowed tick conversions or failed after torque-on ------------------


@pytest.mark.parametrize(
    ("old", "new"),
    [
        ("settle_tolerance_deg = 0.3", "settle_tolerance_deg = inf"),
        ("profile_velocity_deg_s = 120.0", "profile_velocity_deg_s = nan"),
        ("gear_ratio = 1.0", "gear_ratio = 1e308"),
        ("zero_offset_deg = 0.0", "zero_offset_deg = 1e308"),
    ],
)
def test_2_bad_numbers_are_refused_before_the_bus_is_opened(tmp_path, plan_file, old, new):
    with emulated() as (emu, rig):
        bad = tmp_path / "bad.toml"
        bad.write_text(rig.text.replace(old, new, 1))
        with pytest.raises(RigConfigError, match=r"bad\.toml:\d+: joints\["):
            acquire(tmp_path / "run", str(bad), plan_file, progress=False)
        assert emu.packet_log == [] and not (tmp_path / "run").exists()


# --- 3. a park angle in a keep-out ---------------------------------------------------------


def test_3_park_in_a_keepout_is_refused_before_any_motion(tmp_path, plan_file):
    with emulated() as (emu, rig):
        bad = tmp_path / "bad.toml"
        bad.write_text(rig.text.replace("light_arm = 60.0", "light_arm = 167.0", 1))
        with pytest.raises(RigConfigError, match=r"park\.light_arm: home angle 167\.0"):
            acquire(tmp_path / "run", str(bad), plan_file, progress=False)
        assert emu.packet_log == [] and not (tmp_path / "run").exists()


# --- 4. a DeviceError parks the rig, or turns torque off when it cannot ----------------------


def test_4_device_error_parks_the_rig_and_journals_it(tmp_path, plan_file):
    def camera_fails(n, ses):
        if n == 3:
            raise DeviceError("camera: no frame within 30 s")

    with emulated() as (emu, rig):
        run = tmp_path / "run"
        with pytest.raises(DeviceError, match="no frame") as exc:
            acquire(run, rig, plan_file, progress=False, on_sample=camera_fails)
        assert exc.value.__notes__ == ["rig parked"]
        assert_parked(emu, rig)
        assert assert_goals_safe(emu, rig) > 4
    stop = last_stop(run)
    assert stop["parked"] and stop["reason"] == "device error"
    events = [json.loads(x)["event"] for x in (run / "log.jsonl").read_text().splitlines()]
    assert events[-3:] == ["device_error", "stopped", "parked"]


def test_4_dead_servo_turns_torque_off_and_says_so(tmp_path, plan_file):
    emus = []

    def tilt_dies(n, ses):
        if n == 2:
            emus.append(ses.emulator)
            ses.emulator.kill(3)

    rig = parse_rig(SIM_SAMPLE, "sim_sample.toml")
    run = tmp_path / "run"
    with pytest.raises(DeviceError, match="servo 3 gave no valid reply") as exc:
        acquire(run, rig, plan_file, progress=False, on_sample=tilt_dies)
    (note,) = exc.value.__notes__
    assert note.startswith("rig not parked (") and note.endswith(
        "torque off sent (servo 3 did not confirm)"
    )
    emu = emus[0]
    syncs = [
        r.writes(ct.TORQUE_ENABLE)
        for r in emu.packet_log
        if r.instruction == 0x83 and r.writes(ct.TORQUE_ENABLE)
    ]
    assert syncs[-1] == [(1, 0), (2, 0), (3, 0), (4, 0)]  # one Sync Write, torque off for all
    for j in rig.joints:
        if j.id != 3:
            assert emu.register(j.id, ct.TORQUE_ENABLE) == 0
    stop = last_stop(run)
    assert not stop["parked"] and "torque off" in stop["rig"]


# --- 5. a wrong servo model: no torque-on anywhere, no run directory --------------------------


def test_5_wrong_model_refused_before_any_torque_on(tmp_path, plan_file):
    with emulated(models={3: "XL430-W250"}) as (emu, rig):
        run = tmp_path / "run"
        with pytest.raises(DeviceError, match="servo 3 is XL430-W250, rig file says XM430"):
            acquire(run, rig, plan_file, progress=False)
        # servos 1 and 2 answered, servo 3 is the wrong model: three pings and nothing else
        assert [(r.id, r.instruction) for r in emu.packet_log] == [(1, 1), (2, 1), (3, 1)]
        assert emu.writes(ct.TORQUE_ENABLE) == [] and goals(emu) == []
        assert not run.exists() and list(tmp_path.iterdir()) == [plan_file]


# --- 6. a run directory is valid from its first byte ------------------------------------------


def test_6_journal_schema_and_metadata_are_one_transaction(tmp_path):
    import sqlite3

    j = Journal(tmp_path, create=True, meta={"rig_text": "x", "plan_spec": "{}"})
    j.close()
    # nothing but the committed state on disk: both or neither
    con = sqlite3.connect(tmp_path / "journal.sqlite")
    meta = dict(con.execute("SELECT key, value FROM meta"))
    con.close()
    assert meta == {"schema_version": "1", "rig_text": "x", "plan_spec": "{}"}


def test_6_failed_start_leaves_nothing_and_killed_start_is_cleaned_up(tmp_path, plan_file):
    run = tmp_path / "run"
    # a start killed before its rename leaves only a hidden temporary directory
    stale = tmp_path / ".run.start-abc123"
    stale.mkdir()
    (stale / "journal.sqlite").write_bytes(b"")
    with pytest.raises(DeviceError, match="cannot open servo bus /dev/ttyUSB0"):
        acquire(run, "xm430_4axis", plan_file, progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plan.toml"]
    run.mkdir()  # an empty directory given as --out stays, empty
    with pytest.raises(DeviceError):
        acquire(run, "xm430_4axis", plan_file, progress=False)
    assert run.is_dir() and list(run.iterdir()) == []
    s = acquire(run, "sim_sample", plan_file, progress=False)
    assert s.complete


# --- 7. the serial port disappearing ---------------------------------------------------------


def test_7_serial_port_lost_mid_run_is_a_device_error_saying_the_rig_state(tmp_path, plan_file):
    def unplug(n, ses):
        if n == 3:
            ses.emulator.stop()

    run = tmp_path / "run"
    with pytest.raises(DeviceError, match=r"servo bus /dev/pts/\d+ lost") as exc:
        acquire(run, "sim_sample", plan_file, progress=False, on_sample=unplug)
    assert exc.value.__notes__ == [
        "rig not parked (servo bus lost) and torque off failed (servo bus lost):"
        " torque state unknown"
    ]
    assert not last_stop(run)["parked"]
    s = acquire(run, resume=True, progress=False)  # the adapter plugged back in
    assert s.complete and s.measured_now == s.done - 3


# --- 8. signals: the flag is checked, whatever happens to the exception -----------------------


def test_8_second_interrupt_swallowed_by_a_callback_still_stops_at_once(tmp_path, plan_file):
    from gonio import interrupts

    def ctrl_c_twice(n, ses):
        if n == 2:
            interrupts.FLAG.handler(signal.SIGINT, None)  # first: finish this configuration
            try:
                interrupts.FLAG.handler(signal.SIGINT, None)  # second: raises ...
            except KeyboardInterrupt:
                pass  # ... and is swallowed, as JAX's gc callback does

    with emulated() as (emu, rig):
        run = tmp_path / "run"
        with pytest.raises(Interrupted) as exc:
            acquire(run, rig, plan_file, progress=False, on_sample=ctrl_c_twice)
        assert exc.value.__notes__ == ["rig parked"]
        assert_parked(emu, rig)
    j = Journal(run)
    assert j.counts()["done"] == 2  # stopped at once: no third configuration
    j.close()
    assert last_stop(run)["reason"] == "interrupted"
    assert not interrupts.FLAG.installed and interrupts.FLAG.count == 0  # library use: restored
