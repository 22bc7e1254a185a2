"""The run engine on the simulated rig: complete runs, faults, refusals, kill-and-resume, Ctrl-C."""

from __future__ import annotations

import json
import random
import signal
import subprocess
from pathlib import Path

import numpy as np
import pytest

from gonio.acquire.engine import acquire
from gonio.acquire.journal import Journal
from gonio.errors import PlanError
from gonio.rigs.config import load_rig
from gonio.rigs.session import open_rig
from gonio.rigs.sim import FaultConfig
from gonio.rigs.sim.sample import SimulatedSampleCamera
from tests.acquire.child import acquire_cmd, done_samples, env, run_until

RIG = load_rig("sim")

# No configuration of this plan is the park pose (theta 60/60, dphi 180 on the sim rig): a servo
# already resting at its goal stays put when that goal's Sync Write is lost (correctly: it is
# within tolerance), so under packet faults its read-back could differ from a run where it moved
# there, and the runs below compare samples bit for bit.
PLAN = """kind = "isotropic"
theta_i_deg = [20, 40, 55]
theta_o_deg = [20, 40, 55]
dphi_deg = [30, 90, 150, 180]
"""


@pytest.fixture
def plan_file(tmp_path):
    p = tmp_path / "plan.toml"
    p.write_text(PLAN)
    return p


def samples_of(run: Path):
    j = Journal(run)
    try:
        return {s.idx: s for s in j.samples()}, j.counts()
    finally:
        j.close()


def goals_within_limits(run: Path) -> int:
    by_id = {j.id: j for j in RIG.joints}
    n = 0
    for line in (run / "sim_goals.jsonl").read_text().splitlines():
        g = json.loads(line)
        j = by_id[g["id"]]
        a = j.from_ticks(g["ticks"])
        assert j.min_deg - 1e-9 <= a <= j.max_deg + 1e-9, g
        n += 1
    return n


@pytest.fixture(scope="module")
def reference_run(tmp_path_factory):
    """An uninterrupted, fault-free run of PLAN: its summary and run directory (read only)."""
    d = tmp_path_factory.mktemp("ref")
    (d / "plan.toml").write_text(PLAN)
    s = acquire(d / "run", "sim_sample", d / "plan.toml", progress=False)
    assert s.complete
    return s, d / "run"


@pytest.fixture(scope="module")
def reference(reference_run):
    """The samples and journal counts of :func:`reference_run`."""
    return samples_of(reference_run[1])


def test_complete_run_measures_truth_within_noise(reference, tmp_path):
    samples, counts = reference
    assert counts["done"] == counts["planned"] == len(samples) > 15
    cam = SimulatedSampleCamera(RIG)
    z = []
    for s in samples.values():
        truth = cam.truth(s.wi, s.wo)
        z.extend((s.value - truth) / s.sigma)
        assert np.linalg.norm(s.wi) == pytest.approx(1) and s.wi[2] > 0 and s.wo[2] > 0
    z = np.array(z)
    # chi-square of the standardized residuals: 3N dof, accept at the 0.1% level both sides
    from scipy.stats import chi2

    n = z.size
    assert chi2.ppf(0.0005, n) < np.sum(z**2) < chi2.ppf(0.9995, n)


def test_read_back_directions_match_targets(reference_run):
    _, run = reference_run
    j = Journal(run)
    cfg = {c.idx: c for c in j.configs()}
    for s in j.samples():
        c = cfg[s.idx]
        # isotropic targets may be rotated about the normal: compare polar angles and the angle
        # between light and camera (all within the joints' settle tolerance, 0.3 deg each)
        tol = np.radians(3 * 0.3)
        assert abs(np.arccos(s.wi[2]) - np.arccos(c.wi[2])) < tol
        assert abs(np.arccos(s.wo[2]) - np.arccos(c.wo[2])) < tol
        assert abs(np.arccos(np.dot(s.wi, s.wo)) - np.arccos(np.dot(c.wi, c.wo))) < tol
        # and the journaled joints are what the servos reported, not the plan
        assert s.joints_deg != c.joints_deg
    j.close()
    events = [json.loads(x)["event"] for x in (run / "log.jsonl").read_text().splitlines()]
    assert events[0] == "start" and events[-1] == "end" and "parked" in events
    assert goals_within_limits(run) > 0


def test_faulty_bus_still_gives_every_sample_identically(reference, tmp_path, plan_file):
    ref, _ = reference
    faults = FaultConfig(drop=0.03, garble=0.03, crc=0.03, seed=11)
    s = acquire(
        tmp_path / "run",
        "sim_sample",
        plan_file,
        progress=False,
        open_devices=lambda rig, d: open_rig(rig, faults=faults, log_dir=d),
    )
    assert s.complete and s.bus["retries"] > 0
    got, counts = samples_of(tmp_path / "run")
    assert set(got) == set(ref) and counts["done"] == len(ref)
    for i, r in ref.items():
        np.testing.assert_array_equal(got[i].value, r.value)
        assert got[i].joints_deg == r.joints_deg


def test_out_of_limit_plan_refused_before_any_motion(tmp_path):
    plan = tmp_path / "grazing.toml"
    plan.write_text(
        'kind = "isotropic"\ntheta_i_deg = [30, 85]\ntheta_o_deg = [45]\ndphi_deg = [180]\n'
    )
    run = tmp_path / "run"
    with pytest.raises(PlanError, match=r"before any motion.*too grazing"):
        acquire(run, "sim_sample", plan, progress=False, strict=True)
    assert not run.exists()  # nothing created, the bus never opened
    # without --strict the pose is skipped, journaled with its reason, and never commanded
    s = acquire(run, "sim_sample", plan, progress=False)
    assert s.complete and s.refused == 1 and s.done == 1
    j = Journal(run)
    (ref,) = [c for c in j.configs() if c.status == "refused"]
    assert "theta" in ref.reason and ref.joints_deg is None
    j.close()
    goals_within_limits(run)


def test_plan_with_nothing_reachable_is_refused_before_any_motion(tmp_path):
    # every pose refused: the run measured nothing, exited 0 and parked the servos (motion)
    plan = tmp_path / "grazing.toml"
    plan.write_text('kind = "isotropic"\ntheta_i_deg = [85]\ntheta_o_deg = [45, 60]\n'
                    'dphi_deg = [180]\n')  # fmt: skip
    run = tmp_path / "run"
    with pytest.raises(PlanError, match=r"nothing to measure: all 2 poses .* too grazing"):
        acquire(run, "sim_sample", plan, progress=False)
    assert not run.exists()


def _kill_and_resume(reference, tmp_path, plan_file, kills: int, seed: int, extra=()):
    ref, _ = reference
    run = tmp_path / "run"
    rng = random.Random(seed)
    points = sorted(rng.sample(range(1, len(ref) - 1), kills))
    first = True
    for n in points:
        cmd = (
            acquire_cmd("--rig", "sim_sample", "--plan", plan_file, "--out", run, *extra)
            if first
            else (acquire_cmd("--resume", run, *extra))
        )
        rc = run_until(cmd, run, n, signal.SIGKILL)
        first = False
        assert rc == -signal.SIGKILL or rc == 0
    out = subprocess.run(
        [*acquire_cmd("--resume", run, *extra), "--json"],
        env=env(),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    summary = json.loads(out.stdout)
    assert summary["complete"] and summary["done"] == len(ref)
    got, counts = samples_of(run)
    assert set(got) == set(ref) and counts["done"] == len(ref)
    for i, r in ref.items():
        np.testing.assert_array_equal(got[i].value, r.value)
        np.testing.assert_array_equal(got[i].wi, r.wi)
    goals_within_limits(run)


def test_sigkill_and_resume_gives_the_uninterrupted_samples(reference, tmp_path, plan_file):
    _kill_and_resume(reference, tmp_path, plan_file, kills=2, seed=5)


@pytest.mark.slow
def test_sigkill_many_times_on_a_faulty_bus(reference, tmp_path, plan_file):
    faults = ("--sim-faults", "drop=0.03,garble=0.03,crc=0.03,seed=4")
    _kill_and_resume(reference, tmp_path, plan_file, kills=6, seed=9, extra=faults)


def test_ctrl_c_parks_the_rig_then_resume_completes(reference, tmp_path, plan_file):
    ref, _ = reference
    run = tmp_path / "run"
    rc = run_until(
        acquire_cmd("--rig", "sim_sample", "--plan", plan_file, "--out", run),
        run,
        5,
        signal.SIGINT,
    )
    assert rc == 130
    events = [json.loads(x) for x in (run / "log.jsonl").read_text().splitlines()]
    names = [e["event"] for e in events]
    assert "interrupted" in names and names.index("parked") > names.index("interrupted")
    # the last goal every servo received is its park angle
    last = {}
    for line in (run / "sim_goals.jsonl").read_text().splitlines():
        g = json.loads(line)
        last[g["id"]] = g["ticks"]
    for j in RIG.joints:
        assert last[j.id] == j.to_ticks(RIG.park_deg[j.name])
    done = done_samples(run)
    assert 5 <= done < len(ref)
    s = acquire(run, resume=True, progress=False)
    assert s.complete and s.measured_now == len(ref) - done


def test_servo_silent_briefly_is_ridden_out(reference, tmp_path, plan_file):
    ref, _ = reference

    def hook(n, ses):
        if n == 4:
            ses.emulator.kill(2, 0.05)  # silent for 50 ms: retries with backoff cover it

    s = acquire(tmp_path / "run", "sim_sample", plan_file, progress=False, on_sample=hook)
    assert s.complete and s.done == len(ref) and s.bus["timeouts"] > 0


def test_dead_servo_stops_run_cleanly_and_resume_finishes(reference, tmp_path, plan_file):
    from gonio.errors import DeviceError

    ref, _ = reference

    def hook(n, ses):
        if n == 6:
            ses.emulator.kill(3)  # the tilt servo never answers again

    run = tmp_path / "run"
    with pytest.raises(DeviceError, match=r"servo 3 gave no valid reply"):
        acquire(run, "sim_sample", plan_file, progress=False, on_sample=hook)
    got, counts = samples_of(run)
    assert counts["done"] == 6
    events = [json.loads(x)["event"] for x in (run / "log.jsonl").read_text().splitlines()]
    assert "device_error" in events
    s = acquire(run, resume=True, progress=False)  # the servo was replaced: a fresh bus
    assert s.complete and s.measured_now == len(ref) - 6
    got, _ = samples_of(run)
    for i, r in ref.items():
        np.testing.assert_array_equal(got[i].value, r.value)


def test_complete_run_writes_table_through_gonio_io(reference_run, capsys):
    from gonio import io as gio

    s, run = reference_run
    assert s.table == str(run / "table.brdf.h5")
    t = gio.load(run / "table.brdf.h5")
    assert t.wi.shape == (s.done, 3)
    got, _ = samples_of(run)
    want = np.array([got[i].value for i in sorted(got)])
    np.testing.assert_allclose(np.asarray(t.values), want, rtol=1e-6)  # stored as float32
    np.testing.assert_allclose(np.asarray(t.sigma), [got[i].sigma for i in sorted(got)], rtol=1e-6)
    # and `gonio info RUN/table.brdf.h5 --json` reports the sample count
    from gonio.cli import main

    capsys.readouterr()
    assert main(["info", str(run / "table.brdf.h5"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["samples"] == s.done


def test_adaptive_plan_refines_around_the_measured_specular_peak(tmp_path):
    import math

    from gonio.acquire.plans import load_plan
    from gonio.rigs.kinematics import spherical

    plan = tmp_path / "adaptive.toml"
    plan.write_text(
        'kind = "adaptive"\ntheta_i_deg = [25, 45]\n'
        "theta_o_deg = { start = 5, stop = 65, step = 10 }\ndphi_deg = [0, 90, 180]\n"
        "[refine]\nwindow_deg = 4.0\nstep_deg = 2.0\n"
    )
    run = tmp_path / "run"
    s = acquire(run, "sim_sample", plan, progress=False)
    assert s.complete
    j = Journal(run)
    coarse = j.samples(stage=0)
    fine = [c for c in j.configs(stage=1) if c.status == "planned"]
    j.close()
    from gonio.acquire.plans import Result

    adaptive, _ = load_plan(plan)
    peaks = adaptive.peaks(
        [Result(tuple(c.wi), tuple(c.wo), float(np.mean(c.value))) for c in coarse]
    )
    # the sim sample is glossy (Phong n=80): the coarse data peak at the mirror direction, which
    # the coarse grid (theta_o = 5, 15, ... 65) only approximates to the nearest 10 deg
    for ti, (to, dp) in peaks.items():
        assert abs(math.degrees(to) - math.degrees(ti)) <= 5.0 + 1e-9
        assert dp == pytest.approx(math.pi)
    assert len(fine) > 0
    # every refined target lies in a 4-deg patch around one of those peaks
    for c in fine:
        a = spherical(np.array(c.wi))[0]
        b = spherical(np.array(c.wo))[0]
        dphi = abs(
            math.remainder(math.atan2(c.wo[1], c.wo[0]) - math.atan2(c.wi[1], c.wi[0]), 2 * math.pi)
        )
        assert math.degrees(abs(dphi - math.pi)) <= 4 + 1e-6
        assert any(
            (abs(a - ti) < 1e-6 and abs(b - to) <= math.radians(4) + 1e-9)
            or (abs(b - ti) < 1e-6 and abs(a - to) <= math.radians(4) + 1e-9)
            for ti, (to, _) in peaks.items()
        )


def test_a_stop_asked_for_while_the_camera_opens_powers_no_servo(tmp_path, monkeypatch):
    from gonio import interrupts
    from gonio.acquire.engine import open_session
    from gonio.errors import Interrupted
    from gonio.rigs.sim.bus import ServoChainEmulator

    started = []
    monkeypatch.setattr(ServoChainEmulator, "start", lambda self: started.append(self))
    with interrupts.installed() as flag:
        flag.count, flag.signum = 1, signal.SIGINT  # recorded while the run was shielded
        with pytest.raises(Interrupted):
            with open_session(load_rig("sim_sample"), tmp_path):
                pytest.fail("the session opened")
    assert not started
