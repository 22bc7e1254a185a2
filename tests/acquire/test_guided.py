"""Plans chosen by a material prior (``optimal``, ``guided``) on the fast simulated rig: the
candidates the rig reaches, journaled decisions, stopping rules, kill-and-resume, the dry run
and the list plan a run writes of what it chose."""

from __future__ import annotations

import json
import random
import signal
import subprocess
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gonio.acquire.engine import acquire, dry_run
from gonio.acquire.journal import Journal
from gonio.acquire.plans import load_plan, plan_from_spec
from gonio.errors import PlanError
from gonio.rigs.config import load_rig
from tests.acquire.child import acquire_cmd, env, run_until

#: the shipped rig files
RIGS = ("sim", "sim_sample", "xm430_4axis")
#: a coarse candidate grid: few candidates, fast choices
GRID = (
    "theta_deg = { start = 0, stop = 75, step = 15 }\n"
    "dphi_deg = { start = 0, stop = 180, step = 45 }\n"
)


@pytest.fixture(scope="module")
def prior_file(tmp_path_factory) -> Path:
    """A small synthetic prior (a random orthonormal rank-4 basis about a grey Lambertian mean
    on a coarse grid), written once: the choices are the prior's, whatever its materials."""
    from gonio.brdf.grid import Channels
    from gonio.prior import Prior, prior_axes, space

    axes = prior_axes(30, 15, 15)
    mask = space.valid_mask(axes)
    wi, wo = space.grid_directions(axes)
    keep = mask.reshape(-1)
    cc = space.cos_product(wi[keep], wo[keep])
    mean = space.to_mapped(np.full((cc.size, 3), 0.3 / np.pi), cc)
    rng = np.random.default_rng(1)
    basis, _ = np.linalg.qr(rng.normal(size=(mean.size, 4)))
    prior = Prior(
        axes, mask, mean, basis.reshape(cc.size, 3, 4).astype(np.float32),
        np.linspace(4.0, 0.5, 4), np.full(mean.shape, 1e-4), Channels.rgb(),
        meta={"materials": ["a", "b", "c"]},
    )  # fmt: skip
    path = tmp_path_factory.mktemp("prior") / "small.prior.h5"
    prior.write(path)
    return path


def _plan(tmp_path: Path, prior: Path, body: str, name: str = "plan") -> Path:
    p = tmp_path / f"{name}.toml"
    p.write_text(f'prior = "{prior}"\n{body}{GRID}')
    return p


def _configs(run: Path):
    j = Journal(run)
    try:
        return [(c.idx, c.stage, c.wi, c.wo, c.status) for c in j.configs()], j.decisions()
    finally:
        j.close()


@settings(
    max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    rig_name=st.sampled_from(RIGS),
    theta_step=st.sampled_from([10, 15, 20]),
    dphi_step=st.sampled_from([30, 45, 60]),
    count=st.integers(1, 12),
)
def test_optimal_never_proposes_an_unreachable_configuration(
    prior_file, rig_name, theta_step, dphi_step, count
):
    rig = load_rig(rig_name, check_sample_model=False)
    spec = {
        "kind": "optimal",
        "prior": str(prior_file),
        "count": count,
        "theta_deg": {"start": 0, "stop": 90, "step": theta_step},
        "dphi_deg": {"start": 0, "stop": 180, "step": dphi_step},
    }
    plan = plan_from_spec(spec)
    (stage,) = dry_run(rig, plan, time_budget_s=0.5)
    assert not stage.refused, stage.refused[0].reason
    assert len(stage.accepted) == min(count, len(plan.candidates))
    assert np.sum(stage.move_s) <= stage.lexicographic_s + 1e-9  # ordered for travel


#: the guided plan of the reference run and of the kill-and-resume runs
GUIDED = 'kind = "guided"\nbatch = 3\nfirst = 4\nbudget_configurations = 10\n'


@pytest.fixture(scope="module")
def reference(prior_file, tmp_path_factory):
    """An uninterrupted guided run (budget of 10 configurations): its folder and summary."""
    d = tmp_path_factory.mktemp("guided")
    s = acquire(d / "ref", "sim_sample", _plan(d, prior_file, GUIDED), progress=False)
    return d / "ref", s


def test_guided_stops_on_budget_and_target_and_writes_a_list_plan(reference, prior_file, tmp_path):
    run, s = reference
    assert s.complete and s.done == 10
    errs = [b["predicted_error"] for b in s.batches]
    assert [b["batch"] for b in s.batches] == [4, 3, 3, 0]
    assert errs[0] is None and all(e > 0 for e in errs[1:])
    assert "configuration budget" in s.batches[-1]["stop"]
    assert all(b["true_error"] > 0 for b in s.batches[1:])  # the simulator knows its truth
    # the chosen configurations, rerun as a fixed plan, are the same targets
    chosen, spec = load_plan(Path(s.chosen_plan))
    assert chosen.kind == "list" and spec["isotropic"] is True
    cfgs, decisions = _configs(run)
    got = np.array([t.wo for t in chosen.stage(0)])
    want = np.array([c[3] for c in sorted(cfgs)])
    np.testing.assert_allclose(got, want, atol=1e-7)
    assert set(decisions) == {0, 1, 2, 3}
    # a target at the second predicted error stops at the second decision, as chosen before
    body = f'kind = "guided"\nbatch = 3\nfirst = 4\ntarget = {errs[2]!r}\n'
    s2 = acquire(tmp_path / "run2", "sim_sample", _plan(tmp_path, prior_file, body, "t"),
                 progress=False)  # fmt: skip
    assert s2.complete and s2.done == 7 and "target" in s2.batches[-1]["stop"]
    assert [b["predicted_error"] for b in s2.batches] == errs[:3]
    # a rig-time budget: the first batch spends more than 1 rig second
    body = 'kind = "guided"\nbatch = 3\nbudget_s = 1.0\n'
    s3 = acquire(tmp_path / "run3", "sim_sample", _plan(tmp_path, prior_file, body, "r"),
                 progress=False)  # fmt: skip
    assert s3.done == 3 and "rig-time budget" in s3.batches[-1]["stop"]
    assert s3.batches[-1]["rig_s_before"] > 1.0


def test_dry_run_says_what_a_guided_run_will_do(prior_file, tmp_path, capsys):
    from gonio.cli import main

    body = 'kind = "guided"\nbatch = 3\nfirst = 5\ntarget = 0.1\nbudget_s = 900\n'
    plan = _plan(tmp_path, prior_file, body)
    assert main(["plan", "--rig", "sim_sample", "--plan", str(plan), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["accepted"] == 5 and d["refused"] == 0
    assert d["decides"]["batch"] == 3 and d["decides"]["target"] == 0.1
    assert "batches of 3 until predicted error <= 0.1 or 900 rig seconds" in d["note"]
    assert main(["plan", "--rig", "sim_sample", "--plan", str(plan)]) == 0
    assert "first batch 5" in capsys.readouterr().out


def test_bad_prior_plans_are_one_line(prior_file, tmp_path):
    with pytest.raises(PlanError, match="prior: missing"):
        plan_from_spec({"kind": "guided", "batch": 2, "target": 0.1})
    with pytest.raises(PlanError, match="stopping rule"):
        plan_from_spec({"kind": "guided", "prior": str(prior_file)})
    with pytest.raises(PlanError, match="count: missing"):
        plan_from_spec({"kind": "optimal", "prior": str(prior_file)})
    with pytest.raises(PlanError, match="batch: must be a whole number"):
        plan_from_spec({"kind": "guided", "prior": str(prior_file), "batch": 0, "target": 1})
    p = tmp_path / "p.toml"
    p.write_text('kind = "optimal"\ncount = 3\nprior = "nope.prior.h5"\n')
    with pytest.raises(PlanError, match="prior: no such file"):
        load_plan(p)


def _kill_and_resume_guided(reference, prior_file, tmp_path, kills: int, seed: int):
    ref_run, ref = reference
    plan = _plan(tmp_path, prior_file, GUIDED)
    run = tmp_path / "run"
    rng = random.Random(seed)
    for n, point in enumerate(sorted(rng.choices(range(1, ref.done), k=kills))):
        cmd = (
            acquire_cmd("--rig", "sim_sample", "--plan", plan, "--out", run)
            if n == 0
            else acquire_cmd("--resume", run)
        )
        rc = run_until(cmd, run, point, signal.SIGKILL)
        assert rc in (-signal.SIGKILL, 0)
    out = subprocess.run(
        [*acquire_cmd("--resume", run), "--json"], env=env(), capture_output=True, text=True,
        timeout=120,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["complete"]
    assert _configs(run) == _configs(ref_run)  # the same choices, the same decisions
    import h5py

    with h5py.File(run / "table.brdf.h5") as a, h5py.File(ref_run / "table.brdf.h5") as b:
        for key in ("values", "sigma", "wi", "wo", "gridded/values"):
            np.testing.assert_array_equal(a[key][()], b[key][()])
    assert (run / "plan_chosen.toml").read_text() == (ref_run / "plan_chosen.toml").read_text()


def test_guided_run_killed_twice_resumes_to_the_same_choices(reference, prior_file, tmp_path):
    _kill_and_resume_guided(reference, prior_file, tmp_path, kills=2, seed=3)


@pytest.mark.slow
def test_guided_run_killed_ten_times_resumes_to_the_same_choices(reference, prior_file, tmp_path):
    """SIGKILL at ten seeded moments (after a seeded number of samples; a number already
    reached kills the resumed process as it starts; batch boundaries fall between a batch's
    last sample and the next decision)."""
    _kill_and_resume_guided(reference, prior_file, tmp_path, kills=10, seed=11)


def test_model_keys_are_checked(prior_file):
    base = {"kind": "guided", "prior": str(prior_file), "batch": 2}
    with pytest.raises(PlanError, match="model: 'nope' is not a gonio fit model"):
        plan_from_spec({**base, "model": "nope", "target": 1.0})
    with pytest.raises(PlanError, match="target_width: needs model"):
        plan_from_spec({**base, "target_width": 0.1})
    plan = plan_from_spec({**base, "model": "phong", "target_width": 0.5})
    assert plan.describe()["model"] == "phong"


@pytest.mark.slow
def test_guided_stops_when_the_model_parameters_are_known(prior_file, tmp_path):
    """With ``model`` the analytic fit is journaled with each decision; ``target_width`` stops
    the run once the widest 95 % interval is that fraction of its parameter (the sim_sample
    truth is a Phong: 7 samples pin it)."""
    body = 'kind = "guided"\nbatch = 3\nfirst = 4\nmodel = "phong"\ntarget_width = 0.5\n'
    body += "budget_configurations = 16\n"
    s = acquire(tmp_path / "run", "sim_sample", _plan(tmp_path, prior_file, body), progress=False)
    assert s.complete and "phong parameters known" in s.batches[-1]["stop"]
    _, decisions = _configs(tmp_path / "run")
    fit = decisions[max(decisions)]["fit"]
    assert fit["max_relative_width"] <= 0.5
    np.testing.assert_allclose(fit["params"]["n"], 80.0, rtol=0.2)


def test_optimal_run_and_a_changed_prior_is_refused_on_resume(prior_file, tmp_path):
    import shutil

    mine = tmp_path / "mine.prior.h5"
    shutil.copy(prior_file, mine)
    plan = _plan(tmp_path, mine, 'kind = "optimal"\ncount = 3\n')
    s = acquire(tmp_path / "run", "sim_sample", plan, progress=False, write_table=False)
    assert s.complete and s.done == 3 and [b["batch"] for b in s.batches] == [3, 0]
    assert s.batches[-1]["stop"] == "all chosen configurations measured"
    with open(mine, "ab") as fh:
        fh.write(b"\0")
    with pytest.raises(PlanError, match=r"prior .* changed since the run started"):
        acquire(tmp_path / "run", resume=True, progress=False)
