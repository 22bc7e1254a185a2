"""The next stage of a run, for fixed plans and for plans that decide from the measurements.

A fixed plan's stage ``k`` is generated from the earlier stages' samples
(:meth:`gonio.acquire.plans.Plan.stage`). A *dynamic* plan (``plan.dynamic``: ``optimal``,
``guided``) decides each batch with :meth:`~gonio.acquire.plans.Plan.decide` from every journaled
sample — the per-channel values with their sigma — and from what the run has spent; the
decision (its summary, the predicted error, or why the run stops) is journaled in the same
transaction as the batch's configurations (:meth:`gonio.acquire.journal.Journal.plan_stage`).
Every input of a decision comes from the journal, so a resumed or killed run makes exactly the
decision it would have made; the batch passes the rig's reachability and safety checks like any
other stage (:func:`gonio.acquire.planning.plan_stage`).

Rig time
--------
A batch's *rig time* is its predicted motion (the servos' profiles at time scale 1, what the
moves take on the hardware) plus, per accepted configuration, the capture, settling and
bookkeeping costs that ``gonio plan`` uses (:func:`gonio.acquire.timing.default_costs`; the
exposure time for a real camera never measured). It is journaled with each decision
(``batch_rig_s``) and a guided plan's ``budget_s`` counts it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gonio.acquire.journal import Journal
from gonio.acquire.planning import StagePlan, plan_stage, start_pose
from gonio.acquire.plans import Plan, Result, Spent, list_spec
from gonio.rigs.config import RigConfig


@dataclass
class NextStage:
    """A planned stage and, for a dynamic plan, the decision journaled with it (``stop`` in
    the decision: the run ends here, ``plan.configs`` is empty)."""

    plan: StagePlan
    decision: dict | None = None

    @property
    def stops(self) -> bool:
        return self.decision is not None and self.decision.get("stop") is not None


def results_of(journal: Journal) -> list[Result]:
    """Every journaled sample as a :class:`Result` (per-channel values and sigma, 1/sr), in
    configuration order."""
    return [
        Result(
            tuple(map(float, s.wi)),
            tuple(map(float, s.wo)),
            float(np.mean(s.value)),
            tuple(map(float, s.value)),
            tuple(map(float, s.sigma)),
        )
        for s in journal.samples()
    ]


def per_config_rig_s(rig: RigConfig) -> float:
    """Rig seconds per configuration besides the motion (see the module docstring)."""
    from gonio.acquire.timing import default_costs

    c = default_costs(rig)
    capture = c.capture_s if c.capture_s is not None else float(rig.camera.get("exposure_s", 0.0))
    return float(capture + c.move_overhead_s + c.book_s)


def batch_rig_s(sp: StagePlan, per_config_s: float) -> float:
    """Predicted rig seconds of a planned stage: motion plus per-configuration costs."""
    return float(np.sum(sp.move_s)) + len(sp.accepted) * per_config_s


def spent_of(journal: Journal) -> Spent:
    """Configurations measured or rejected so far, and the rig seconds of the journaled
    batches (``batch_rig_s`` of each decision)."""
    counts = journal.counts()
    decisions = tuple(journal.decisions().values())
    rig_s = sum(float(d.get("batch_rig_s", 0.0)) for d in decisions)
    return Spent(counts["done"] + counts["rejected"], rig_s, decisions)


def next_stage(
    rig: RigConfig,
    plan: Plan,
    stage: int,
    results: Sequence[Result],
    spent: Spent,
    start_deg: dict[str, float],
    first_index: int,
    time_budget_s: float = 10.0,
) -> NextStage:
    """Plan stage ``stage``: the plan's own targets, or a dynamic plan's decision."""
    if not plan.dynamic:
        return NextStage(
            plan_stage(rig, plan, stage, list(results), start_deg, first_index, time_budget_s)
        )
    plan.for_rig(rig, start_pose(rig))
    d = plan.decide(stage, results, spent)
    detail = {
        "stage": stage,
        "spent_configurations": spent.configurations,
        "spent_rig_s": round(spent.rig_s, 6),
        **(d.summary or {}),
        "stop": d.stop,
    }
    targets = [] if d.stop is not None else list(d.targets)
    sp = plan_stage(
        rig, plan, stage, list(results), start_deg, first_index, time_budget_s, targets=targets
    )
    if d.stop is None and not sp.accepted:
        first = sp.refused[0] if sp.refused else None
        why = f": first #{first.idx}: {first.reason}" if first else ""
        detail["stop"] = f"the rig refused every configuration of the batch{why}"
    detail["targets"] = len(targets)
    detail["batch_rig_s"] = round(batch_rig_s(sp, per_config_rig_s(rig)), 6)
    return NextStage(sp, detail)


#: the list plan a dynamic run writes of the configurations it chose (``kind = "list"``)
CHOSEN_PLAN = "plan_chosen.toml"


def write_chosen_plan(journal: Journal, run_dir: Path, plan: Plan) -> Path:
    """Write ``RUN/plan_chosen.toml``: the configurations a dynamic plan chose (every accepted
    target, in configuration order) as a ``kind = "list"`` plan, so that anyone can rerun them
    as a fixed plan (``gonio acquire --plan RUN/plan_chosen.toml``)."""
    import tomli_w

    from gonio.io.atomic import atomic_output

    cfgs = sorted(
        (c for c in journal.configs() if c.status in ("planned", "rejected")), key=lambda c: c.idx
    )
    spec = list_spec(
        np.array([c.wi for c in cfgs]).reshape(-1, 3),
        np.array([c.wo for c in cfgs]).reshape(-1, 3),
        all(c.isotropic for c in cfgs),
        f"{plan.name}-chosen",
    )
    rows = spec.pop("configurations")
    text = (
        f"# the {len(cfgs)} configurations plan {plan.name!r} ({plan.kind}) chose in this run,"
        " [theta_i, phi_i, theta_o, phi_o] in degrees\n"
        + tomli_w.dumps(spec)
        + "configurations = [\n"
        + "".join(f"  [{', '.join(repr(float(v)) for v in r)}],\n" for r in rows)
        + "]\n"
    )
    path = Path(run_dir) / CHOSEN_PLAN
    with atomic_output(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path


def batches(journal: Journal) -> list[dict]:
    """One row per decision of a dynamic run: the stage, the configurations measured before it,
    its predicted error (None before any sample), the batch size, the rig seconds spent before
    it, and why the run stopped there (None: it went on)."""
    return [
        {
            "stage": k,
            "measured_before": d.get("spent_configurations", 0),
            "predicted_error": d.get("predicted_error"),
            "batch": 0 if d.get("stop") is not None else d.get("targets", 0),
            "rig_s_before": d.get("spent_rig_s", 0.0),
            "stop": d.get("stop"),
        }
        for k, d in sorted(journal.decisions().items())
    ]
