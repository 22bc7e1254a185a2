"""Plans chosen by a material prior: ``optimal`` (a fixed count) and ``guided`` (batches until
the material is known).

Both choose among *candidates*: isotropic configurations (theta_i <= theta_o by reciprocity,
delta_phi in [0, 180] deg) on a grid, kept only where the rig can reach them (joint limits,
keep-outs, the light-camera minimum angle, the grazing limit: the rig's own
:meth:`gonio.rigs.kinematics.Kinematics.refusal`, as every planned stage is checked). The prior
(:mod:`gonio.prior`) chooses the configurations that make its reconstruction best determined
(``prior.choose``) and reconstructs the full table from the samples with their sigma
(``prior.reconstruct``).

``optimal``
    One batch of ``count`` configurations chosen before any data; after it the reconstruction's
    predicted error is journaled and the run stops.
``guided``
    Batches of ``batch`` configurations (the first ``first``); after each, the reconstruction
    from every sample so far and its predicted error (mean absolute error in the prior's mapped
    space); the next batch is chosen given what was measured. The run stops when the predicted
    error is at most ``target``, or the next batch would pass ``budget_configurations`` or the
    rig-time ``budget_s`` (rig seconds, :mod:`gonio.acquire.decide`). With ``model`` the
    analytic fit of that model (:func:`gonio.fit.fit`, Laplace intervals) is journaled with each
    decision, and ``target_width`` stops the run once every parameter is known to that
    fraction of its value (the widest 95 % interval).

Plan files (TOML)::

    kind = "guided"                       # or "optimal" with count = 20
    prior = "merl.prior.h5"               # relative to the plan file
    batch = 5
    first = 10                            # default: batch
    target = 0.05                         # predicted table error, mapped space
    model = "lambert+ward"                # also fit this analytic model after each batch ...
    target_width = 0.1                    # ... and stop when its widest 95 % interval is <=
                                          #     this fraction of the parameter's value
    budget_configurations = 80
    budget_s = 1800.0                     # rig seconds
    theta_deg = { start = 0, stop = 80, step = 5 }    # candidate grid (default)
    dphi_deg = { start = 0, stop = 180, step = 15 }

Every decision depends only on the journaled samples and the earlier decisions, and the prior
file's SHA-256 is recorded in the plan at the start (a resumed run refuses a changed prior), so a
resumed or killed run makes exactly the choices the uninterrupted one makes.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from gonio.acquire.plan_base import (
    Decision,
    Plan,
    Result,
    Spent,
    Target,
    direction_of,
    plan_angles,
    plan_key_error,
)
from gonio.errors import PlanError

#: the candidate grid when the plan file names none (degrees)
DEFAULT_THETA = {"start": 0, "stop": 80, "step": 5}
DEFAULT_DPHI = {"start": 0, "stop": 180, "step": 15}
#: most candidates (each is checked against the rig's kinematics before the first decision)
MAX_CANDIDATES = 20_000

_COMMON = {"kind", "name", "prior", "prior_sha256", "theta_deg", "dphi_deg"}
_KEYS = {
    "optimal": _COMMON | {"count"},
    "guided": _COMMON
    | {"batch", "first", "target", "budget_configurations", "budget_s", "model", "target_width"},
}


def load_prior(path: str):
    """The prior file at ``path`` (:meth:`gonio.prior.Prior.read`)."""
    from gonio.prior import Prior

    return Prior.read(path)


def file_sha256(path: str | Path) -> str:
    """SHA-256 (hex) of a file; PlanError when it cannot be read."""
    h = hashlib.sha256()
    try:
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
    except OSError as exc:
        raise PlanError(f"plan key prior: cannot read {path} ({exc.strerror or exc})") from None
    return h.hexdigest()


class PriorPlan(Plan):
    """Base of ``optimal`` and ``guided``: the candidates, the prior, the choice."""

    isotropic = True
    dynamic = True
    n_stages = 1  # the dry run's count; the run goes on until a decision stops it

    def __init__(self, spec: dict, name: str = "") -> None:
        super().__init__(name)
        self.spec = dict(spec)
        self.prior_path = str(spec["prior"])
        self.theta = plan_angles(spec.get("theta_deg", DEFAULT_THETA), "theta_deg")
        self.dphi = plan_angles(spec.get("dphi_deg", DEFAULT_DPHI), "dphi_deg")
        if not np.all((self.theta >= 0) & (self.theta <= math.pi / 2)):
            raise plan_key_error("theta_deg", "polar angles must lie in [0, 90] deg")
        grid = candidate_grid(self.theta, self.dphi)
        if len(grid) > MAX_CANDIDATES:
            raise PlanError(f"the candidate grid has {len(grid)} configurations, more than"
                            f" {MAX_CANDIDATES}: a coarser theta_deg or dphi_deg")  # fmt: skip
        self.grid = grid
        self._prior = None
        self._reachable: tuple[str, list[int]] | None = None

    # --- what the engine calls ---------------------------------------------------------------
    def for_rig(self, rig, start_deg: dict[str, float]) -> None:
        """Keep the candidates the rig can reach, the turntable where ``start_deg`` (joint
        name -> deg) has it (an isotropic pair is turned to suit; cached per rig file)."""
        if self._reachable is not None and self._reachable[0] == rig.text:
            return
        from gonio.rigs.kinematics import Kinematics

        kin = Kinematics(rig)
        rot = kin.joints_deg_to_pose(start_deg).rot
        keep = [
            i
            for i, t in enumerate(self.grid)
            if any(kin.refusal(c) is None for c in kin.candidates(t.wi, t.wo, True, rot))
        ]
        if not keep:
            raise PlanError(f"plan {self.name}: the rig {rig.name!r} reaches no candidate")
        self._reachable = (rig.text, keep)

    @property
    def candidates(self) -> list[int]:
        """Indices into :attr:`grid` of the reachable candidates (after :meth:`for_rig`)."""
        if self._reachable is None:
            raise RuntimeError("for_rig() first")
        return self._reachable[1]

    @property
    def prior(self):
        if self._prior is None:
            self._prior = load_prior(self.prior_path)
        return self._prior

    def stage(self, k: int, results: Sequence[Result] = ()):
        raise PlanError(f"plan kind {self.kind!r} decides its batches from the measurements")

    def describe(self) -> dict:
        out = {"name": self.name, "kind": self.kind, "prior": self.prior_path}
        if self._reachable is not None:
            out["candidates"] = len(self.candidates)
        return out

    # --- helpers -----------------------------------------------------------------------------
    def _choose(self, count: int, chosen: Sequence[int], results: Sequence[Result]) -> list[int]:
        """``count`` new grid indices (never one chosen before), in the prior's order."""
        taken = set(chosen)
        free = [i for i in self.candidates if i not in taken]
        if not free:
            return []
        wi = np.array([self.grid[i].wi for i in free])
        wo = np.array([self.grid[i].wo for i in free])
        usable = np.asarray(self.prior.observe(wi, wo).usable, dtype=bool)  # the prior sees them
        free, wi, wo = [i for i, u in zip(free, usable, strict=True) if u], wi[usable], wo[usable]
        count = min(count, len(free))
        if count <= 0:
            return []
        measured = _measured(results) if results else None
        picks = self.prior.choose(wi, wo, count, measured=measured)
        return [free[int(p)] for p in np.asarray(picks, dtype=int).ravel()[:count]]

    def _targets(self, picks: Sequence[int], k: int) -> tuple[Target, ...]:
        return tuple(
            Target(self.grid[i].wi, self.grid[i].wo, True, k) for i in picks
        )  # fmt: skip

    def _state(self, results: Sequence[Result]) -> dict:
        """The reconstruction from ``results``: its predicted error and coefficients."""
        wi, wo, values, sigma = _arrays(results)
        rec = self.prior.reconstruct(wi, wo, values, sigma)
        out = {"predicted_error": float(rec.predicted_error), "samples": len(results)}
        out["coefficients"] = [float(v) for v in np.asarray(rec.coefficients).ravel()]
        return out

    def true_errors(
        self, results: Sequence[Result], decisions: dict[int, dict], rig
    ) -> dict[int, float]:
        """On a simulated rig: stage -> the mean absolute error, in the prior's mapped space
        over its valid cells and channels, of the reconstruction each decision made (from the
        first ``samples`` of ``results``, in configuration order) against the simulator's truth
        (``[sim.sample]``); {} on hardware."""
        if not rig.is_sim or not rig.sim.sample:
            return {}
        from gonio.prior import space
        from gonio.rigs.sim.truth import load_truth

        truth = load_truth(rig.sim.sample, rig.source)
        wi, wo = self.prior.cell_directions()
        f = np.asarray(truth.f(wi, wo), dtype=float)
        if f.shape[-1] != self.prior.n_channels:  # a grey truth against an RGB prior
            f = np.broadcast_to(f[..., :1], (*f.shape[:-1], self.prior.n_channels))
        want = space.to_mapped(f, space.cos_product(wi, wo), self.prior.epsilon)
        out = {}
        for k, d in sorted(decisions.items()):
            n = d.get("samples")
            if not n:
                continue
            rec = self.prior.reconstruct(*_arrays(results[:n]))
            out[k] = float(np.mean(np.abs(np.asarray(rec.mapped) - want)))
        return out


def candidate_grid(theta: np.ndarray, dphi: np.ndarray) -> list[Target]:
    """Isotropic configurations (radians axes): theta_i <= theta_o (reciprocity), delta_phi
    folded into [0, pi] (mirror symmetry), one configuration where either direction is the
    normal (delta_phi is then meaningless); in a fixed order."""
    seen, out = set(), []
    for ti in theta:
        for to in theta:
            if to < ti:
                continue
            for dp in dphi:
                dp = abs(math.remainder(float(dp), 2 * math.pi))
                if ti < 1e-12 or to < 1e-12:
                    dp = 0.0
                key = (round(float(ti), 9), round(float(to), 9), round(dp, 9))
                if key in seen:
                    continue
                seen.add(key)
                out.append(Target(direction_of(ti, 0.0), direction_of(to, dp), True, 0))
    return out


def _arrays(results: Sequence[Result]):
    wi = np.array([r.wi for r in results], dtype=float).reshape(-1, 3)
    wo = np.array([r.wo for r in results], dtype=float).reshape(-1, 3)
    values = np.array([r.values or (r.value,) for r in results], dtype=float)
    sigma = np.array([r.sigma or (0.0,) * len(r.values or (r.value,)) for r in results], float)
    return wi, wo, values, sigma


def _measured(results: Sequence[Result]):
    """What ``prior.choose`` is given of the samples so far: ``(wi, wo, values, sigma)``."""
    return _arrays(results)


def _chosen(spent: Spent) -> list[int]:
    return [i for d in spent.decisions for i in d.get("chosen", ())]


class Optimal(PriorPlan):
    """``count`` configurations chosen by the prior before any data, then a stop."""

    kind = "optimal"

    def __init__(self, spec: dict, name: str = "") -> None:
        super().__init__(spec, name)
        self.count = _positive_int(spec, "count", None)

    def decide(self, k: int, results: Sequence[Result], spent: Spent) -> Decision:
        if k == 0:
            picks = self._choose(self.count, [], [])
            return Decision(self._targets(picks, 0), None, {"chosen": picks})
        state = self._state(results) if results else {}
        return Decision((), "all chosen configurations measured", state)

    def describe(self) -> dict:
        return {**super().describe(), "count": self.count}


class Guided(PriorPlan):
    """Batches chosen from what was measured until the target or the budget (see module)."""

    kind = "guided"

    def __init__(self, spec: dict, name: str = "") -> None:
        super().__init__(spec, name)
        self.batch = _positive_int(spec, "batch", 5)
        self.first = _positive_int(spec, "first", self.batch)
        self.target = _positive_float(spec, "target", None)
        self.budget_configurations = _positive_int(spec, "budget_configurations", None, False)
        self.budget_s = _positive_float(spec, "budget_s", None)
        self.model = spec.get("model")
        if self.model is not None:
            from gonio.fit.presets import available

            if not isinstance(self.model, str) or self.model not in available():
                raise plan_key_error("model", f"{self.model!r} is not a gonio fit model name")
        self.target_width = _positive_float(spec, "target_width", None)
        if self.target_width is not None and self.model is None:
            raise plan_key_error("target_width", "needs model = NAME (the analytic fit)")
        rules = (self.target, self.budget_configurations, self.budget_s, self.target_width)
        if all(r is None for r in rules):
            raise PlanError(
                "plan kind 'guided' needs a stopping rule: target, target_width,"
                " budget_configurations or budget_s"
            )

    def decide(self, k: int, results: Sequence[Result], spent: Spent) -> Decision:
        chosen = _chosen(spent)
        if k == 0:
            picks = self._choose(self._room(self.first, spent), [], [])
            return Decision(self._targets(picks, 0), None, {"chosen": picks})
        state = self._state(results) if results else {"predicted_error": None}
        err = state.get("predicted_error")
        if self.target is not None and err is not None and err <= self.target:
            return Decision((), f"predicted error {err:.4g} <= target {self.target:g}", state)
        if self.model is not None and results:
            state["fit"] = fit_state(self.model, results)
            width = state["fit"]["max_relative_width"]
            if self.target_width is not None and width is not None and width <= self.target_width:
                return Decision(
                    (),
                    f"{self.model} parameters known: widest 95 % interval {width:.4g} of its"
                    f" value <= target_width {self.target_width:g}",
                    state,
                )
        if self.budget_s is not None and spent.rig_s >= self.budget_s:
            return Decision(
                (), f"rig-time budget spent ({spent.rig_s:.1f} of {self.budget_s:g} s)", state
            )
        count = self._room(self.batch, spent)
        if count <= 0:
            return Decision((), f"configuration budget spent ({self.budget_configurations})", state)
        picks = self._choose(count, chosen, results)
        if not picks:
            return Decision((), "every reachable candidate measured", state)
        return Decision(self._targets(picks, k), None, {**state, "chosen": picks})

    def _room(self, want: int, spent: Spent) -> int:
        if self.budget_configurations is None:
            return want
        return min(want, self.budget_configurations - spent.configurations)

    def describe(self) -> dict:
        return {
            **super().describe(),
            "batch": self.batch,
            "first": self.first,
            "target": self.target,
            "budget_configurations": self.budget_configurations,
            "budget_s": self.budget_s,
            "model": self.model,
            "target_width": self.target_width,
        }


def fit_state(model: str, results: Sequence[Result]) -> dict:
    """The analytic fit ``model`` of the samples with Laplace intervals (:func:`gonio.fit.fit`):
    its parameters and the widest 95 % interval relative to its parameter's value (None while
    the fit fails or a parameter is unconstrained)."""
    from gonio.brdf.measured import MeasuredSamples
    from gonio.errors import GonioError
    from gonio.fit import fit

    wi, wo, values, sigma = _arrays(results)
    try:
        r = fit(MeasuredSamples(wi=wi, wo=wo, values=values, sigma=sigma), model=model,
                uncertainty="laplace")  # fmt: skip
    except GonioError as exc:
        return {"model": model, "error": str(exc), "max_relative_width": None}
    widths = []
    for key, (lo, hi) in r.intervals(95).items():
        v = np.abs(np.asarray(r.params[key], dtype=float))
        w = (np.asarray(hi, dtype=float) - np.asarray(lo, dtype=float)) / np.maximum(v, 1e-12)
        widths.append(np.ravel(w))
    w = np.concatenate(widths) if widths else np.array([np.nan])
    worst = float(np.max(w)) if np.all(np.isfinite(w)) else None
    params = {k: np.asarray(v, dtype=float).tolist() for k, v in r.params.items()}
    return {"model": model, "params": params, "max_relative_width": worst}


def _positive_int(spec: dict, key: str, default: int | None, required: bool = True) -> int | None:
    v = spec.get(key, default)
    if v is None:
        if not required:
            return None
        raise PlanError(f"plan key {key}: missing (kind {spec['kind']!r} needs it)")
    if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 10_000:
        raise plan_key_error(key, "must be a whole number in [1, 10000]")
    return int(v)


def _positive_float(spec: dict, key: str, default: float | None) -> float | None:
    v = spec.get(key, default)
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
        raise plan_key_error(key, "must be a finite number > 0")
    return float(v)


def guided_plan_from_spec(spec: dict, name: str = "") -> PriorPlan:
    """An ``optimal`` or ``guided`` plan from its parsed spec; PlanError naming the key."""
    kind = spec["kind"]
    extra = sorted(set(spec) - _KEYS[kind])
    if extra:
        raise plan_key_error(extra[0], f"unknown for kind {kind!r}")
    if not isinstance(spec.get("prior"), str) or not spec["prior"]:
        raise PlanError(f"plan key prior: missing (kind {kind!r} needs the path of a prior file)")
    name = spec.get("name", name) or kind
    check_prior(spec)
    return Optimal(spec, name) if kind == "optimal" else Guided(spec, name)


def resolve_prior(spec: dict, base: Path | None) -> dict:
    """``spec`` with its prior path made absolute (against ``base``, the plan file's folder)
    and the prior file's SHA-256 recorded, so that a resumed run reads the same prior."""
    p = Path(spec["prior"]).expanduser()
    if not p.is_absolute() and base is not None:
        p = base / p
    p = p.resolve()
    if not p.is_file():
        raise PlanError(f"plan key prior: no such file: {p}")
    return {**spec, "prior": str(p), "prior_sha256": file_sha256(p)}


def check_prior(spec: dict) -> None:
    """PlanError when the prior file is not the one recorded at the start of the run."""
    want = spec.get("prior_sha256")
    if want and file_sha256(spec["prior"]) != want:
        raise PlanError(
            f"the prior {spec['prior']} changed since the run started (SHA-256 differs): a"
            " resumed run must choose as the interrupted one did"
        )
