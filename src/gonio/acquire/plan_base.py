"""The plan protocol: what a plan yields (:class:`Target`), what it is told of the measurements
(:class:`Result`, :class:`Spent`), what a dynamic plan decides (:class:`Decision`), the
:class:`Plan` base class, and the checks of a plan file's angle keys. The kinds are in
:mod:`gonio.acquire.plans` (fixed plans) and :mod:`gonio.acquire.guided` (plans chosen by a
material prior). Directions are unit vectors in the sample frame; radians in code.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from gonio.errors import PlanError

#: Most values one plan axis may have, and most configurations one plan may ask for (10,000
#: configurations are days of acquisition; the dry run orders them with an n x n cost matrix).
MAX_AXIS_VALUES = 3600
MAX_TARGETS = 10_000


@dataclass(frozen=True)
class Target:
    """A requested configuration: directions in the sample frame (unit 3-vectors)."""

    wi: tuple[float, float, float]
    wo: tuple[float, float, float]
    isotropic: bool = False
    stage: int = 0


@dataclass(frozen=True)
class Result:
    """A measured configuration handed to later stages: directions (read back from the rig),
    the mean over channels ``value`` (1/sr), and per channel ``values`` and their 1-sigma
    ``sigma`` (1/sr; empty when not known)."""

    wi: tuple[float, float, float]
    wo: tuple[float, float, float]
    value: float
    values: tuple[float, ...] = ()
    sigma: tuple[float, ...] = ()


@dataclass(frozen=True)
class Spent:
    """What a run has spent before a decision: configurations measured or rejected, and rig
    seconds (predicted motion of the journaled batches plus their per-configuration costs,
    :func:`gonio.acquire.decide.batch_rig_s`), and the earlier decisions."""

    configurations: int = 0
    rig_s: float = 0.0
    decisions: tuple[dict, ...] = ()  # the earlier decisions, as journaled, in stage order


@dataclass(frozen=True)
class Decision:
    """A dynamic plan's choice before batch ``k``.

    Attributes
    ----------
    targets : the batch (empty when the plan stops).
    stop : why the run stops here (None: measure ``targets``).
    summary : JSON-able record of the decision (the reconstruction's state, the predicted error,
        the budget spent), journaled with the batch.
    """

    targets: tuple[Target, ...]
    stop: str | None = None
    summary: dict | None = None


def direction_of(theta: float, phi: float) -> tuple[float, float, float]:
    st = math.sin(theta)
    return (st * math.cos(phi), st * math.sin(phi), math.cos(theta))


def plan_key_error(key: str | tuple, msg: str) -> PlanError:
    """PlanError ``plan key KEY: msg`` that remembers the key (``load_plan`` adds the line)."""
    path = (key,) if isinstance(key, str) else tuple(key)
    dotted = ".".join(f"[{k}]" if isinstance(k, int) else str(k) for k in path).replace(".[", "[")
    err = PlanError(f"plan key {dotted}: {msg}")
    err.key_path = path
    err.detail = msg
    return err


def plan_angles(spec, key: str) -> np.ndarray:
    """Degrees list or {start, stop, step} (inclusive) -> radians array."""
    if isinstance(spec, dict):
        extra = sorted(set(spec) - {"start", "stop", "step"})
        if extra:  # a misspelt "stop" must not leave the range silently as written elsewhere
            raise plan_key_error((key, extra[0]), "unknown in a range (start, stop, step)")
        try:
            if any(isinstance(spec[k], bool) for k in ("start", "stop", "step")):
                raise TypeError("a boolean is not a number of degrees")
            start, stop, step = float(spec["start"]), float(spec["stop"]), float(spec["step"])
        except (KeyError, TypeError, ValueError):
            raise plan_key_error(key, "a range needs numeric start, stop, step") from None
        # written so that NaN refuses
        if not all(math.isfinite(v) for v in (start, stop, step)):
            raise plan_key_error(key, "start, stop and step must be finite")
        if not (step > 0 and stop >= start):
            raise plan_key_error(key, "need step > 0 and stop >= start")
        count = (stop - start) / step
        if not count < MAX_AXIS_VALUES:
            raise plan_key_error(
                key, f"the range has {count + 1:.3g} values, more than {MAX_AXIS_VALUES}"
            )
        n = math.floor(count + 1e-9) + 1
        vals = start + step * np.arange(n)
    elif isinstance(spec, (list, tuple)) and spec:
        if len(spec) > MAX_AXIS_VALUES:
            raise plan_key_error(key, f"{len(spec)} values, more than {MAX_AXIS_VALUES}")
        try:
            if any(isinstance(v, bool) for v in spec):
                raise TypeError("a boolean is not a number of degrees")
            vals = np.array([float(v) for v in spec])
        except (TypeError, ValueError):
            raise plan_key_error(key, "values must be numbers (degrees)") from None
    else:
        raise plan_key_error(key, "give a list of degrees or {start, stop, step}")
    bad = np.flatnonzero(~np.isfinite(vals))
    if bad.size:
        raise plan_key_error((key, int(bad[0])), f"{vals[bad[0]]} is not a finite number")
    return np.radians(vals)


class Plan:
    """Base class: ``n_stages`` stages, stage ``k`` generated by :meth:`stage`.

    A *dynamic* plan (``dynamic = True``) has no fixed number of stages: before each batch the
    engine asks :meth:`decide` with every measurement so far (values with their sigma) and what
    was spent, journals the :class:`Decision` with the batch, and stops when the decision says
    so. ``decide`` must be a function of its arguments only, so that a resumed run makes exactly
    the choices the interrupted one would have made.
    """

    kind = "plan"
    isotropic = False
    n_stages = 1
    dynamic = False

    def __init__(self, name: str = "") -> None:
        self.name = name or self.kind

    def stage(self, k: int, results: Sequence[Result] = ()) -> Iterator[Target]:
        raise NotImplementedError

    def decide(self, k: int, results: Sequence[Result], spent: Spent) -> Decision:
        """The batch before stage ``k`` of a dynamic plan (see the class docstring)."""
        raise NotImplementedError

    def true_errors(
        self, results: Sequence[Result], decisions: dict[int, dict], rig
    ) -> dict[int, float]:
        """On a simulated rig, stage -> the true error of each decision's reconstruction
        against the simulator's truth (a dynamic plan with a reconstruction); {} otherwise."""
        return {}

    def for_rig(self, rig, start_deg: dict[str, float]) -> None:
        """Bind a dynamic plan to the rig it runs on, starting from ``start_deg`` (joint name
        -> deg), before its first decision (its candidates are the configurations that rig
        reaches); nothing for a fixed plan."""

    def describe(self) -> dict:
        return {"name": self.name, "kind": self.kind}
