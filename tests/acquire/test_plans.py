"""Plans (pure generators) and travel-time ordering."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gonio.acquire.engine import dry_run
from gonio.acquire.ordering import order_poses, path_time, plan_route
from gonio.acquire.plans import (
    Adaptive,
    Isotropic3D,
    Result,
    builtin_plans,
    load_plan,
    plan_from_spec,
)
from gonio.errors import PlanError
from gonio.rigs.config import load_rig
from gonio.rigs.kinematics import spherical

RIG = load_rig("sim")


def test_isotropic_uses_reciprocity_and_mirror_symmetry():
    th = np.radians([10, 30, 50, 70])
    dp = np.radians([0, 60, 120, 180, 240])
    plan = Isotropic3D(th, th, dp)
    t = list(plan.stage(0))
    # pairs with theta_i <= theta_o: 4*5/2 = 10; dphi 240 == 120 by mirror symmetry -> 4 values
    assert len(t) == 10 * 4
    for x in t:
        assert spherical(np.array(x.wi))[0] <= spherical(np.array(x.wo))[0] + 1e-12
        assert x.isotropic


def test_grid4d_count_and_directions():
    plan, _ = load_plan("grid4d-small")
    t = list(plan.stage(0))
    assert len(t) == 2 * 2 * 3 * 6
    assert all(abs(np.linalg.norm(x.wi) - 1) < 1e-12 for x in t)


def test_halfdiff_targets_above_horizon_and_match_angles():
    from gonio.brdf.frames import half_diff

    plan, _ = load_plan("halfdiff-small")
    t = list(plan.stage(0))
    assert t and all(x.wi[2] > 0 and x.wo[2] > 0 for x in t)
    th, _, td, _ = half_diff(np.array([x.wi for x in t]), np.array([x.wo for x in t]))
    assert set(np.round(np.degrees(np.asarray(th)), 6)) <= {0, 2, 5, 10, 20, 40}
    assert set(np.round(np.degrees(np.asarray(td)), 6)) <= {0, 15, 30, 45, 60}


def test_adaptive_refines_around_measured_peak():
    coarse = Isotropic3D(np.radians([30]), np.radians([0, 20, 40, 60]), np.radians([0, 90, 180]))
    plan = Adaptive(coarse, window=math.radians(4), step=math.radians(2))
    # a synthetic peak at theta_o = 40, dphi = 90 (not the mirror direction)
    results = []
    for x in plan.stage(0):
        to = spherical(np.array(x.wo))[0]
        dp = abs(math.remainder(math.atan2(x.wo[1], x.wo[0]), 2 * math.pi))
        peak = abs(to - math.radians(40)) < 1e-6 and abs(dp - math.pi / 2) < 1e-6
        results.append(Result(x.wi, x.wo, 10.0 if peak else 1.0))
    fine = list(plan.stage(1, results))
    assert len(fine) == 5 * 5 - 1  # the patch minus the already measured centre
    for x in fine:
        a, b = spherical(np.array(x.wi))[0], spherical(np.array(x.wo))[0]
        to = b if abs(a - math.radians(30)) < 1e-9 else a
        assert abs(math.degrees(to) - 40) <= 4 + 1e-9
    # no clear peak (flat data): refine around the mirror direction instead
    flat = [Result(r.wi, r.wo, 1.0) for r in results]
    assert plan.peaks(flat)[math.radians(30)] == (math.radians(30), math.pi)


@pytest.mark.parametrize(
    ("spec", "match"),
    [
        ({"kind": "nope"}, "kind"),
        ({"kind": "isotropic", "theta_i_deg": [10]}, "theta_o_deg: missing"),
        (
            {"kind": "isotropic", "theta_i_deg": [10], "theta_o_deg": [95], "dphi_deg": [0]},
            "[0, 90]",
        ),
        (
            {"kind": "isotropic", "theta_i_deg": {"start": 0}, "theta_o_deg": [1], "dphi_deg": [0]},
            "start, stop, step",
        ),
        ({"kind": "grid4d", "theta_i_deg": [1], "bogus": 1}, "bogus"),
        (
            {
                "kind": "isotropic",
                "theta_i_deg": [10],
                "theta_o_deg": [20],
                "dphi_deg": {"start": 0, "stop": 180, "step": 90, "stpo": 90},
            },
            r"dphi_deg\.stpo: unknown in a range",
        ),
    ],
)
def test_bad_plan_specs(spec, match):
    with pytest.raises(PlanError, match=match):
        plan_from_spec(spec)


def test_plan_file(tmp_path):
    p = tmp_path / "mine.toml"
    p.write_text(
        'kind = "isotropic"\ntheta_i_deg = [20]\ntheta_o_deg = [40, 60]\ndphi_deg = [180]\n'
    )
    plan, _ = load_plan(p)
    assert plan.name == "mine" and len(list(plan.stage(0))) == 2
    with pytest.raises(PlanError, match="unknown plan"):
        load_plan(tmp_path / "missing.toml")


def test_ordering_beats_plan_order_and_is_a_permutation():
    joints = list(RIG.joints)
    rng = np.random.default_rng(1)
    poses = rng.uniform(-120, 120, size=(150, 4))
    start = np.zeros(4)
    order = order_poses(start, poses, joints)
    assert sorted(order.tolist()) == list(range(150))
    ident = path_time(start, poses, np.arange(150), joints)
    assert path_time(start, poses, order, joints) < 0.5 * ident


def test_route_candidate_choice_is_optimal_for_small_case():
    import itertools

    joints = list(RIG.joints)
    rng = np.random.default_rng(2)
    cands = [rng.uniform(-90, 90, size=(2, 4)) for _ in range(5)]
    start = np.zeros(4)
    order, choice = plan_route(start, cands, joints)
    got = path_time(start, np.array([cands[i][choice[i]] for i in range(5)]), order, joints)
    best = min(
        path_time(start, np.array([cands[i][c[i]] for i in range(5)]), np.array(perm), joints)
        for perm in itertools.permutations(range(5))
        for c in itertools.product((0, 1), repeat=5)
    )
    assert got <= best * 1.05


@pytest.mark.parametrize(
    "name",
    [n for n in builtin_plans() if n != "adaptive"]
    + [pytest.param("adaptive", marks=pytest.mark.slow)],
)
def test_dry_run_counts_and_refusals(name):
    plan, _ = load_plan(name)
    stages = dry_run(RIG, plan, time_budget_s=2.0)
    n_targets = sum(len(list(plan.stage(s, []))) for s in range(plan.n_stages))
    assert sum(len(s.configs) for s in stages) == n_targets
    for s in stages:
        assert all(c.reason for c in s.refused)
        assert np.sum(s.move_s) <= s.lexicographic_s + 1e-9


def test_published_example_plan_loads_and_plans():
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "data-schema" / "examples" / "plan_adaptive.toml"
    plan, spec = load_plan(path)
    assert plan.kind == "adaptive" and spec["name"] == "example-adaptive"
    stages = dry_run(RIG, plan, time_budget_s=1.0)
    assert len(stages) == 2 and stages[1].accepted


def test_list_plan_parses_orders_and_refuses_bad_rows(tmp_path):
    p = tmp_path / "chosen.toml"
    p.write_text(
        'kind = "list"\nisotropic = true\nconfigurations = [\n'
        "  [20, 0, 40, 180],\n  [45, 0, 45, 90],\n  [10, 0, 70, 150],\n]\n"
    )
    plan, _ = load_plan(p)
    assert plan.kind == "list" and plan.name == "chosen"
    targets = list(plan.stage(0))
    assert len(targets) == 3 and all(t.isotropic for t in targets)
    np.testing.assert_allclose(spherical(np.array(targets[0].wi))[0], math.radians(20), atol=1e-12)
    stages = dry_run(RIG, plan, time_budget_s=1.0)
    assert len(stages) == 1 and len(stages[0].accepted) == 3
    assert np.sum(stages[0].move_s) <= stages[0].lexicographic_s + 1e-9
    # a written list spec round-trips to the same directions
    from gonio.acquire.plans import list_spec

    wi = np.array([t.wi for t in targets])
    wo = np.array([t.wo for t in targets])
    again = list(plan_from_spec(list_spec(wi, wo, True, "x")).stage(0))
    np.testing.assert_allclose([t.wo for t in again], wo, atol=1e-7)
    p.write_text('kind = "list"\nconfigurations = [\n  [20, 0, 40, 180],\n  [20, 0, 95, 0],\n]\n')
    with pytest.raises(PlanError, match=r"chosen.toml:\d+: configurations\[1\]: polar angles"):
        load_plan(p)


@pytest.mark.parametrize(
    "spec, match",
    [
        ({"kind": "list"}, "configurations: missing"),
        ({"kind": "list", "configurations": []}, "non-empty list"),
        ({"kind": "list", "configurations": [[1, 2, 3]]}, r"configurations\[0\]: give"),
        ({"kind": "list", "configurations": [[1, 2, 3, "x"]]}, "must be numbers"),
        ({"kind": "list", "configurations": [[1, 2, 3, True]]}, "must be numbers"),
        ({"kind": "list", "configurations": [[1, 2, 3, 400]]}, "azimuths"),
        ({"kind": "list", "configurations": [[1, 2, 3, 4]], "theta_i_deg": [1]}, "unknown"),
        ({"kind": "list", "configurations": [[1, 2, 3, 4]], "isotropic": 1}, "true or false"),
    ],
)
def test_bad_list_plans(spec, match):
    with pytest.raises(PlanError, match=match):
        plan_from_spec(spec)


def test_published_example_list_plan_loads_and_plans():
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "data-schema" / "examples" / "plan_list.toml"
    plan, spec = load_plan(path)
    assert plan.kind == "list" and spec["name"] == "example-list"
    (stage,) = dry_run(RIG, plan, time_budget_s=1.0)
    assert len(stage.accepted) == 4 and not stage.refused
