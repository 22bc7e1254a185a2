"""Planning a stage of a run: inverse kinematics, safety refusals, travel-time ordering.

Shared by the run engine (:mod:`gonio.acquire.engine`) and ``gonio plan``'s dry run. A stage's
targets come from the plan (:meth:`gonio.acquire.plans.Plan.stage`) or, for a plan that chooses
its batches from the measurements (:mod:`gonio.acquire.decide`), from the plan's decision; either
way every configuration passes the rig's reachability and safety checks
(:meth:`gonio.rigs.kinematics.Kinematics.refusal`) before it is journaled.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gonio.acquire.journal import PlannedConfig
from gonio.acquire.ordering import move_times, path_time, plan_route
from gonio.acquire.plans import Plan, Result, Spent, Target
from gonio.errors import PlanError
from gonio.rigs.config import RigConfig
from gonio.rigs.kinematics import Kinematics


@dataclass
class StagePlan:
    """One planned stage: configurations in execution order, refusals, predicted motion."""

    stage: int
    configs: list[PlannedConfig]
    move_s: np.ndarray  # predicted time of each accepted move, in order (rig time, s)
    lexicographic_s: float  # predicted motion time in the plan's own order

    @property
    def accepted(self) -> list[PlannedConfig]:
        return [c for c in self.configs if c.status == "planned"]

    @property
    def refused(self) -> list[PlannedConfig]:
        return [c for c in self.configs if c.status == "refused"]


def _joint_order(kin: Kinematics, rig: RigConfig):
    names = [kin.joint_names[r] for r in kin.ROLES]
    return names, [rig.joint(n) for n in names]


def plan_stage(
    rig: RigConfig,
    plan: Plan,
    stage: int,
    results: list[Result],
    start_deg: dict[str, float],
    first_index: int,
    time_budget_s: float = 10.0,
    targets: list[Target] | None = None,
) -> StagePlan:
    """Inverse kinematics, safety refusals and travel-time ordering for one stage.

    ``start_deg`` is the pose the stage starts from (joint name -> deg). Configuration indices
    are assigned in the plan's own order from ``first_index``; ``seq`` is the execution order.
    ``targets``: the stage's targets when the plan has chosen them already (a decision of a
    dynamic plan); by default ``plan.stage(stage, results)``.
    """
    kin = Kinematics(rig)
    names, joints = _joint_order(kin, rig)
    start = np.array([start_deg[n] for n in names])
    near = kin.joints_deg_to_pose(start_deg)
    targets = list(plan.stage(stage, results)) if targets is None else list(targets)
    cands: list[np.ndarray] = []
    accepted: list[int] = []
    base: list[np.ndarray] = []
    refused: list[tuple[int, str]] = []
    for i, t in enumerate(targets):
        poses = [
            c
            for c in kin.candidates(t.wi, t.wo, t.isotropic, near.rot if t.isotropic else 0.0)
            if kin.refusal(c) is None
        ]
        if not poses:
            _, why = kin.inverse(t.wi, t.wo, t.isotropic, near)
            refused.append((i, why or "no pose"))
            continue
        accepted.append(i)
        best, _ = kin.inverse(t.wi, t.wo, t.isotropic, near)
        base.append(np.degrees(best.as_tuple()))
        cands.append(np.degrees(np.array([c.as_tuple() for c in poses])))
    order, choice = plan_route(start, cands, joints, time_budget_s=time_budget_s)
    if len(cands):
        # keep the plan's own order (with the reference-nearest poses) if the heuristic lost
        base_arr = np.array(base)
        routed = np.array([cands[k][choice[k]] for k in range(len(cands))])
        if path_time(start, base_arr, np.arange(len(base)), joints) < path_time(
            start, routed, order, joints
        ):
            order = np.arange(len(base))
            choice = np.array(
                [
                    int(np.argmin(np.abs(cands[k] - base_arr[k]).sum(axis=1)))
                    for k in range(len(cands))
                ]
            )
    configs: list[PlannedConfig] = []
    seq_of = {int(o): s for s, o in enumerate(order)}
    for k, i in enumerate(accepted):
        t = targets[i]
        pose = cands[k][choice[k]]
        configs.append(
            PlannedConfig(
                idx=first_index + i,
                stage=stage,
                seq=seq_of[k],
                wi=tuple(map(float, t.wi)),
                wo=tuple(map(float, t.wo)),
                isotropic=t.isotropic,
                joints_deg={n: float(v) for n, v in zip(names, pose, strict=True)},
                status="planned",
                reason=None,
            )
        )
    n_acc = len(accepted)
    for j, (i, why) in enumerate(refused):
        t = targets[i]
        configs.append(
            PlannedConfig(
                first_index + i,
                stage,
                n_acc + j,
                tuple(map(float, t.wi)),
                tuple(map(float, t.wo)),
                t.isotropic,
                None,
                "refused",
                why,
            )
        )
    configs.sort(key=lambda c: c.seq)
    if n_acc:
        poses = np.array([cands[k][choice[k]] for k in range(n_acc)])
        mt = move_times(start, poses, order, joints)
        lex = float(np.sum(move_times(start, np.array(base), np.arange(n_acc), joints)))
    else:
        mt, lex = np.zeros(0), 0.0
    return StagePlan(stage, configs, mt, lex)


def dry_run(rig: RigConfig, plan: Plan, time_budget_s: float = 10.0) -> list[StagePlan]:
    """Plan every stage without hardware; later stages see no measurements (the adaptive plan
    then refines around the mirror direction). A dynamic plan: its first batch only."""
    out = []
    start = start_pose(rig)
    if plan.dynamic:  # its later batches depend on the data: the first one only
        plan.for_rig(rig, start)
        d = plan.decide(0, [], Spent())
        return [plan_stage(rig, plan, 0, [], start, 0, time_budget_s, targets=list(d.targets))]
    idx = 0
    for s in range(plan.n_stages):
        sp = plan_stage(rig, plan, s, [], start, idx, time_budget_s)
        out.append(sp)
        idx += len(sp.configs)
        if sp.accepted:
            start = dict(sp.accepted[-1].joints_deg)
    return out


def start_pose(rig: RigConfig) -> dict[str, float]:
    """Joint angles (deg) a run starts planning from: the park pose, zero offsets elsewhere."""
    start = dict(rig.park_deg)
    for j in rig.joints:
        start.setdefault(j.name, j.zero_offset_deg)
    return start


def refuse_if_nothing(sp: StagePlan) -> None:
    if sp.accepted:
        return
    if not sp.refused:
        raise PlanError(f"nothing to measure: stage {sp.stage} of the plan has no configuration")
    c = sp.refused[0]
    raise PlanError(
        f"nothing to measure: all {len(sp.refused)} poses of stage {sp.stage} are refused by the"
        f" rig, first #{c.idx}: {c.reason} ('gonio plan --list-refused N' lists them)"
    )


def refuse_if_any(sp: StagePlan) -> None:
    if sp.refused:
        c = sp.refused[0]
        raise PlanError(
            f"plan refused before any motion: {len(sp.refused)} pose(s) refused in stage"
            f" {sp.stage}, first #{c.idx}: {c.reason}"
        )
