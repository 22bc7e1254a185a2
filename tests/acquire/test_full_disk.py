"""Issue 44, full disk: an acquisition whose filesystem fills mid-run keeps every committed
sample, parks and stops in one line naming the filesystem; once space is freed, ``--resume``
completes with nothing lost or duplicated and a table bit-identical to an uninterrupted run.
The simulated bus writes its logs into the run folder and survives the full disk. A run folder
removed under a running acquisition stops it, parked."""

from __future__ import annotations

import json
import shutil
import subprocess
from importlib import resources
from pathlib import Path

import h5py
import numpy as np
import pytest

from gonio.acquire.engine import acquire
from gonio.acquire.journal import Journal
from gonio.errors import StorageError
from gonio.rigs import control_table as ct
from gonio.rigs.config import parse_rig
from gonio.rigs.sim.bus import read_packet_log
from tests.acquire.child import acquire_cmd, env
from tests.small_fs import file_size_limit, fill, small_tmpfs, under_file_size_limit

# 12 configurations, none of them the park pose (see tests/acquire/test_engine.py)
PLAN = """kind = "isotropic"
theta_i_deg = [20, 40]
theta_o_deg = [20, 40]
dphi_deg = [30, 90, 150, 170]
"""
RIG_TEXT = (
    resources.files("gonio.rigs")
    .joinpath("sim_sample.toml")
    .read_text()
    .replace("[sim]\n", "[sim]\npacket_log = true\n", 1)
)
RIG = parse_rig(RIG_TEXT, "sim_sample+packets")


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("full_disk")
    (d / "plan.toml").write_text(PLAN)
    (d / "rig.toml").write_text(RIG_TEXT)
    return d


@pytest.fixture(scope="module")
def reference(files):
    """An uninterrupted run of PLAN."""
    s = acquire(files / "ref", RIG, files / "plan.toml", progress=False)
    assert s.complete and s.done == s.planned == 12
    return files / "ref"


def samples(run: Path) -> dict:
    j = Journal(run)
    try:
        return {s.idx: s for s in j.samples()}
    finally:
        j.close()


def assert_same_run(run: Path, ref: Path) -> None:
    """Nothing lost or duplicated, every sample bit-identical, and the table's datasets and
    attributes (but its creation time, run folder and rig file) bit-identical to the
    uninterrupted run's."""
    got, want = samples(run), samples(ref)
    assert sorted(got) == sorted(want)
    for i, r in want.items():
        for key in ("value", "sigma", "wi", "wo"):
            assert getattr(got[i], key).tobytes() == getattr(r, key).tobytes(), (i, key)
        assert got[i].joints_deg == r.joints_deg
    with h5py.File(run / "table.brdf.h5") as a, h5py.File(ref / "table.brdf.h5") as b:
        names: list[str] = []
        b.visit(names.append)
        seen: list[str] = []
        a.visit(seen.append)
        assert seen == names
        for obj_a, obj_b in [(a, b)] + [(a[n], b[n]) for n in names]:
            attrs = set(obj_b.attrs) - {"created_utc"}
            assert set(obj_a.attrs) - {"created_utc"} == attrs
            for k in attrs:
                va, vb = obj_a.attrs[k], obj_b.attrs[k]
                if k == "metadata":  # names the run folder and the rig file, which differ
                    va, vb = (json.loads(v) for v in (va, vb))
                    for m in (va, vb):
                        m["run"] = m["rig"]["source"] = None
                    assert va == vb
                else:
                    assert np.array_equal(va, vb), (obj_b.name, k)
            if isinstance(obj_b, h5py.Dataset):
                assert obj_a[()].tobytes() == obj_b[()].tobytes(), obj_b.name


def pad(path: Path) -> None:
    """Append empty lines to ``path`` until the filesystem refuses (a file's last page has
    room that a full filesystem still lets it fill)."""
    with open(path, "ab", buffering=0) as fh:
        try:
            while True:
                fh.write(b"\n")
        except OSError:
            pass


def whole_json_lines(path: Path) -> list[dict]:
    text = path.read_text()
    assert text == "" or text.endswith("\n"), f"{path.name} ends in a cut line"
    return [json.loads(x) for x in text.splitlines() if x.strip()]


def test_filesystem_filling_mid_run_keeps_samples_and_resumes_identically(
    tmp_path, files, reference
):
    with small_tmpfs(tmp_path / "mnt", "6m") as mnt:
        run = mnt / "run"
        filler: list[Path] = []
        emulators = []

        def fill_up(n, ses):
            if n == 5:  # the filesystem fills under the running acquisition
                filler.append(fill(mnt))
                emulators.append(ses.emulator)
                for log in ("sim_goals.jsonl", "sim_packets.jsonl"):
                    pad(run / log)  # no room left in their last page either

        with pytest.raises(StorageError) as info:
            acquire(run, RIG, files / "plan.toml", progress=False, on_sample=fill_up)
        msg = "; ".join([str(info.value), *info.value.__notes__])
        assert "no space left on device" in msg and f"the filesystem at {mnt} (tmpfs" in msg
        assert "rig parked" in msg and f"gonio acquire --resume {run}" in msg
        kept = samples(run)
        assert len(kept) >= 5 and f"{len(kept)} samples kept" in msg
        # the simulated bus lived through the full disk and parked the rig (its packet log in
        # memory); its file logs stopped at their last whole line, and the error says so
        park = {j.id: j.to_ticks(RIG.park_deg[j.name]) for j in RIG.joints}
        (emu,) = emulators
        assert dict(emu.writes(ct.GOAL_POSITION)[-4:]) == park
        assert emu.file_log_error is not None and "the simulator's log stopped at" in msg
        whole_json_lines(run / "sim_goals.jsonl")
        whole_json_lines(run / "log.jsonl")
        assert len(read_packet_log(run / "sim_packets.jsonl")) < len(emu.packet_log)
        # resumed once space is freed: complete, nothing lost or duplicated, the same table;
        # a PID file left by a killed holder is taken over
        filler[0].unlink()
        dead = _dead_pid()
        (run / ".lock.pid").write_text(f"{dead}\n")
        s = acquire(run, resume=True, progress=False)
        events = [e for e in whole_json_lines(run / "log.jsonl") if e["event"] == "lock_taken_over"]
        assert [e["stale_pid"] for e in events] == [dead]
        assert s.complete and s.done == 12 and s.measured_now == 12 - len(kept)
        assert_same_run(run, reference)
        last = {}
        for rec in read_packet_log(run / "sim_packets.jsonl"):
            for sid, ticks in rec.writes(ct.GOAL_POSITION):
                last[sid] = ticks
        assert last == park  # the resumed run ended parked, as logged by its own bus
        shutil.rmtree(run)


def test_file_size_limit_keeps_samples_and_resume_completes(tmp_path, files, reference):
    """Where no tmpfs can be mounted too: files limited to 60 kB (the journal's write-ahead
    log reaches that mid-run), EFBIG; resumed without the limit, bit-identical."""
    run = tmp_path / "run"
    with file_size_limit(60_000), pytest.raises(StorageError) as info:
        acquire(run, RIG, files / "plan.toml", progress=False)
    msg = "; ".join([str(info.value), *info.value.__notes__])
    assert "file too large" in msg and "ulimit -f" in msg and "rig parked" in msg
    kept = samples(run)
    assert 0 < len(kept) < 12 and f"{len(kept)} samples kept" in msg
    s = acquire(run, resume=True, progress=False)
    assert s.complete and s.measured_now == 12 - len(kept)
    assert_same_run(run, reference)


@pytest.mark.slow
def test_console_full_disk_is_one_line_and_resume_completes(tmp_path, files, reference):
    """``gonio acquire`` whose files may not exceed 60 kB: one line, exit status 5, parked;
    ``gonio acquire --resume`` without the limit completes bit-identically."""
    run = tmp_path / "run"
    cmd = acquire_cmd("--rig", files / "rig.toml", "--plan", files / "plan.toml", "--out", run)
    r = subprocess.run(
        under_file_size_limit(60_000, cmd), env=env(), capture_output=True, text=True, timeout=300
    )
    assert r.returncode == 5, r.stderr
    err = r.stderr
    assert "Traceback" not in err and err.startswith("gonio: ") and err.count("\n") == 1, err
    assert "file too large" in err and "rig parked" in err and "--resume" in err, err
    assert 0 < len(samples(run)) < 12
    r = subprocess.run(
        acquire_cmd("--resume", run), env=env(), capture_output=True, text=True, timeout=300
    )
    assert r.returncode == 0, r.stderr
    assert_same_run(run, reference)


def _dead_pid() -> int:
    """The PID of a process that has ended."""
    p = subprocess.Popen(["true"])
    p.wait()
    return p.pid


def test_a_start_on_a_full_filesystem_creates_no_run(tmp_path, files):
    with small_tmpfs(tmp_path / "mnt", "256k") as mnt:
        fill(mnt)
        with pytest.raises(StorageError) as info:
            acquire(mnt / "run", RIG, files / "plan.toml", progress=False)
        assert str(info.value).startswith(f"{mnt / 'run' / 'journal.sqlite'}: no space left")
        assert info.value.__notes__ == ["no run was created: make room, then start it again"]
        assert [p.name for p in mnt.iterdir()] == ["filler"]


def test_run_folder_removed_under_a_run_stops_it_parked(tmp_path, files):
    run = tmp_path / "run"

    def remove(n, ses):
        if n == 3:
            shutil.rmtree(run)

    with pytest.raises(StorageError, match="run folder was removed or replaced") as info:
        acquire(run, RIG, files / "plan.toml", progress=False, on_sample=remove)
    assert "rig parked" in info.value.__notes__
    assert not run.exists()
