"""``gonio acquire`` killed or interrupted at random moments, through the real console entry.

* SIGKILL (issue 18, item 6): every kill leaves either no run directory (start again with
  ``--out``) or one that ``--resume`` continues; at the end the samples are exactly those of an
  uninterrupted run: none lost, none duplicated, bit for bit.
* SIGINT / SIGTERM (item 8): never a traceback; one line on stderr; exit status 128 + signal
  (or 0 when the run had finished); when the servos had been powered the rig is parked: the
  last goal every servo received is its park angle, and the journal records it.

The seeded random moments cover the interpreter's start-up, the imports, the creation of the
run directory (including 0-30 ms after ``journal.sqlite`` appears), planning, motion and the
writing of the table. The full counts (30 kills, 20 of each signal) run in the slow suite; a
few of each run by default.

For SIGINT and SIGTERM the clock starts when gonio's first line has run: before that the
interpreter is still starting (site, the environment's .pth files, runpy: 20-100 ms here) and
the signal is Python's to handle (a KeyboardInterrupt traceback from site.py, or death by
SIGTERM) with nothing of gonio's created or moved; no Python program can change that.
"""

from __future__ import annotations

import json
import random
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from gonio.acquire.engine import acquire
from gonio.acquire.journal import Journal
from gonio.rigs.config import load_rig
from tests.acquire.child import acquire_cmd, done_samples, env

RIG = load_rig("sim_sample")
PLAN = """kind = "isotropic"
theta_i_deg = [20, 40, 55]
theta_o_deg = [20, 40, 55]
dphi_deg = [30, 90, 150, 180]
"""


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    d = tmp_path_factory.mktemp("ref")
    (d / "plan.toml").write_text(PLAN)
    s = acquire(d / "run", "sim_sample", d / "plan.toml", progress=False, write_table=False)
    assert s.complete
    j = Journal(d / "run")
    try:
        return {r.idx: r for r in j.samples()}, d / "plan.toml"
    finally:
        j.close()


def _catches_sigterm(pid: int) -> bool:
    """Whether process ``pid`` has a SIGTERM handler yet (``gonio/__main__.py`` installs one
    first thing; before that the interpreter is still starting: site, .pth files, runpy)."""
    try:
        with open(f"/proc/{pid}/status") as fh:
            for line in fh:
                if line.startswith("SigCgt:"):
                    return bool(int(line.split()[1], 16) & (1 << (signal.SIGTERM - 1)))
    except OSError:
        pass
    return False


def _signal_at(cmd, moment, sig, run: Path, timeout: float = 120.0, from_gonio=False):
    """Start ``cmd``, send ``sig`` at ``moment`` and return (returncode, stderr).

    ``moment``: ("t", seconds after the start), ("journal", seconds after journal.sqlite
    appears) or ("samples", n: once n samples are journaled). With ``from_gonio`` the clock
    starts when gonio's first line has run (see :func:`_catches_sigterm`), not at the exec.
    """
    proc = subprocess.Popen(cmd, env=env(), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    t0 = time.monotonic()
    kind, value = moment
    try:
        while from_gonio and proc.poll() is None and not _catches_sigterm(proc.pid):
            time.sleep(0.0005)
        if kind == "t":
            time.sleep(value)
        else:
            while proc.poll() is None and time.monotonic() - t0 < timeout:
                if kind == "journal" and (run / "journal.sqlite").exists():
                    time.sleep(value)
                    break
                if kind == "samples" and done_samples(run) >= value:
                    break
                time.sleep(0.001 if kind == "journal" else 0.005)
        if proc.poll() is None:
            proc.send_signal(sig)
        _, err = proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    return proc.returncode, err.decode("utf-8", "replace")


def _is_resumable(run: Path) -> bool:
    """A run directory whose journal names its rig and plan (what ``--resume`` needs)."""
    j = Journal(run)  # raises FormatError on a journal without its schema version
    try:
        return j.get_meta("rig_text") is not None and j.get_meta("plan_spec") is not None
    finally:
        j.close()


def _moments(rng: random.Random, n: int, n_samples: int) -> list[tuple[str, float]]:
    """``n`` seeded moments: a quarter in the first 50 ms, a quarter 0-30 ms after the
    journal appears, the rest at random times of the start-up and at random sample counts."""
    out: list[tuple[str, float]] = []
    for i in range(n):
        r = i % 4
        if r == 0:
            out.append(("t", rng.uniform(0.0, 0.05)))
        elif r == 1:
            out.append(("journal", rng.uniform(0.0, 0.03)))
        elif r == 2:
            out.append(("t", rng.uniform(0.05, 4.0)))
        else:
            out.append(("samples", rng.randrange(1, n_samples)))
    rng.shuffle(out)
    return out


def _kill_many(reference, tmp_path, kills: int, seed: int) -> dict:
    ref, plan = reference
    run = tmp_path / "run"
    rng = random.Random(seed)
    stats = {"kills": 0, "unrecoverable": 0, "fresh_starts": 0, "resumes": 0, "finished": 0}
    for moment in _moments(rng, kills, len(ref)):
        if run.exists():
            assert _is_resumable(run), f"unrecoverable run after a kill at {moment}"
            cmd = acquire_cmd("--resume", run)
            stats["resumes"] += 1
        else:
            cmd = acquire_cmd("--rig", "sim_sample", "--plan", plan, "--out", run)
            stats["fresh_starts"] += 1
        rc, err = _signal_at(cmd, moment, signal.SIGKILL, run)
        if rc == 0:
            stats["finished"] += 1
        elif rc == -signal.SIGKILL:
            stats["kills"] += 1
        else:
            stats["unrecoverable"] += 1
            pytest.fail(f"kill at {moment}: exit {rc}: {err}")
    final = (
        acquire_cmd("--resume", run)
        if run.exists()
        else acquire_cmd("--rig", "sim_sample", "--plan", plan, "--out", run)
    )
    out = subprocess.run([*final, "--json"], env=env(), capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["complete"]
    j = Journal(run)
    try:
        got = {r.idx: r for r in j.samples()}
        n_rows = j.counts()["done"]
    finally:
        j.close()
    lost = set(ref) - set(got)
    duplicated = n_rows - len(got)
    assert not lost and duplicated == 0 and set(got) == set(ref)
    for i, r in ref.items():
        np.testing.assert_array_equal(got[i].value, r.value)
        np.testing.assert_array_equal(got[i].wi, r.wi)
    stats.update(lost=len(lost), duplicated=duplicated)
    return stats


def test_sigkill_at_random_moments_a_few(reference, tmp_path):
    stats = _kill_many(reference, tmp_path, kills=4, seed=18)
    assert stats["unrecoverable"] == 0


@pytest.mark.slow
def test_sigkill_at_30_random_moments_loses_and_duplicates_nothing(reference, tmp_path):
    stats = _kill_many(reference, tmp_path, kills=30, seed=1806)
    print("sigkill:", stats)
    assert stats["unrecoverable"] == stats["lost"] == stats["duplicated"] == 0
    assert stats["kills"] >= 25


def _last_goals(run: Path) -> dict[int, int]:
    last = {}
    for line in (run / "sim_goals.jsonl").read_text().splitlines():
        g = json.loads(line)
        last[g["id"]] = g["ticks"]
    return last


def _check_interrupted(run: Path, sig: int, rc: int, err: str, moment) -> str:
    """The outcome of one interrupted run (see the module docstring); returns its kind."""
    where = f"{signal.Signals(sig).name} at {moment}: exit {rc}, stderr {err!r}"
    assert "Traceback" not in err and "Exception ignored" not in err, where
    if rc == 0:
        assert err == "", where
        kind = "finished"
    else:
        assert rc == 128 + sig, where
        assert err.count("\n") == 1 and err.startswith("gonio: interrupted ("), where
        kind = "interrupted"
    if not run.exists():
        assert rc != 0, where
        return "before the run directory"
    assert _is_resumable(run), where
    events = [json.loads(x) for x in (run / "log.jsonl").read_text().splitlines()]
    stops = [e for e in events if e["event"] == "stopped"]
    if not (run / "sim_goals.jsonl").exists() or not stops:
        # stopped before the servos were powered: nothing was sent
        assert not stops and not (run / "sim_goals.jsonl").exists(), where
        return "before the servos"
    assert stops[-1]["parked"], where
    assert rc == 0 or err.rstrip().endswith("; rig parked"), where
    last = _last_goals(run)
    for j in RIG.joints:
        assert last[j.id] == j.to_ticks(RIG.park_deg[j.name]), where
    return kind


def _interrupt_many(reference, tmp_path, sig: int, n: int, seed: int) -> dict[str, int]:
    _, plan = reference
    rng = random.Random(seed)
    kinds: dict[str, int] = {}
    for k, moment in enumerate(_moments(rng, n, 20)):
        run = tmp_path / f"run{k}"
        cmd = acquire_cmd("--rig", "sim_sample", "--plan", plan, "--out", run)
        rc, err = _signal_at(cmd, moment, sig, run, from_gonio=True)
        kind = _check_interrupted(run, sig, rc, err, moment)
        kinds[kind] = kinds.get(kind, 0) + 1
    return kinds


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_interrupt_at_random_moments_a_few(reference, tmp_path, sig):
    kinds = _interrupt_many(reference, tmp_path, sig, n=2, seed=8 + sig)
    assert sum(kinds.values()) == 2


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_interrupt_at_20_random_moments_no_traceback_rig_parked(reference, tmp_path, sig):
    kinds = _interrupt_many(reference, tmp_path, sig, n=20, seed=1800 + sig)
    print(signal.Signals(sig).name, kinds)
    assert kinds.get("interrupted", 0) >= 5
