"""Acquisition plans: generators of target direction pairs that never touch hardware.

A plan is a sequence of *stages*; stage ``k`` is a generator of :class:`Target` that may look at
the measurements of earlier stages (bluesky style: plans describe, the run engine executes).
Directions are unit vectors in the sample frame (``wi`` toward the light, ``wo`` toward the
camera; radians everywhere in code).

Kinds
-----
``grid4d``
    Full 4-D grid: every (theta_i, phi_i, theta_o, phi_o) combination.
``isotropic``
    3-D (theta_i, theta_o, delta_phi) for isotropic samples; reciprocity halves it
    (only theta_i <= theta_o is measured) and mirror symmetry limits delta_phi to [0, 180].
``halfdiff``
    Rusinkiewicz-aligned (theta_h, theta_d, phi_d) with phi_h = 0 (isotropic), theta_h sampled
    densely near the specular peak when ``theta_h_deg`` is given as a ``sqrt`` range.
``adaptive``
    An isotropic coarse pass, then for every incident angle a fine (theta_o, delta_phi) patch
    around the peak found in the coarse data (or the mirror direction when the coarse data
    show no clear peak, and in dry runs).
``optimal``, ``guided``
    Configurations chosen by a material prior, before any data or batch by batch from the
    measurements (:mod:`gonio.acquire.guided`).
``list``
    An explicit list of configurations, each ``[theta_i, phi_i, theta_o, phi_o]`` in degrees
    (the form a guided or optimal run writes as ``RUN/plan_chosen.toml``, so that it can be
    rerun as a fixed plan). ``isotropic = true`` lets the rig turn the sample about its normal
    (only ``phi_o - phi_i`` matters).

Plan files (TOML)
-----------------
::

    kind = "isotropic"                              # grid4d | isotropic | halfdiff | adaptive
    theta_i_deg = [10, 30, 50]                      # a list ...
    theta_o_deg = { start = 0, stop = 70, step = 10 }   # ... or an inclusive range
    dphi_deg = { start = 0, stop = 180, step = 30 }
    reciprocal = false       # isotropic: also measure (theta_o, theta_i) to check reciprocity
    # grid4d: theta_i_deg, phi_i_deg, theta_o_deg, phi_o_deg
    # halfdiff: theta_h_deg, theta_d_deg, phi_d_deg
    # adaptive: the isotropic keys for the coarse pass, plus
    [refine]
    window_deg = 10.0        # half-width of the patch around the peak (theta_o and delta_phi)
    step_deg = 2.5           # spacing inside the patch
    peak_ratio = 1.5         # peak / median of the coarse row needed to trust the data

    # list: [theta_i, phi_i, theta_o, phi_o] in degrees, one row per configuration
    kind = "list"
    isotropic = true
    configurations = [[20, 0, 40, 180], [45, 0, 45, 90]]

Built-in plans are listed by :func:`builtin_plans`.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from gonio._bounded import loads_toml
from gonio.acquire.plan_base import MAX_AXIS_VALUES as MAX_AXIS_VALUES  # re-exported
from gonio.acquire.plan_base import (
    MAX_TARGETS,
    Plan,
    Target,
    direction_of,
    plan_angles,
    plan_key_error,
)
from gonio.acquire.plan_base import Decision as Decision
from gonio.acquire.plan_base import Result as Result
from gonio.acquire.plan_base import Spent as Spent
from gonio.errors import PlanError


class Grid4D(Plan):
    """Every (theta_i, phi_i, theta_o, phi_o) combination (radians arrays)."""

    kind = "grid4d"

    def __init__(self, theta_i, phi_i, theta_o, phi_o, name: str = "") -> None:
        super().__init__(name)
        self.axes = [np.asarray(a, dtype=float) for a in (theta_i, phi_i, theta_o, phi_o)]

    def stage(self, k: int = 0, results: Sequence[Result] = ()) -> Iterator[Target]:
        for ti, pi, to, po in itertools.product(*self.axes):
            yield Target(direction_of(ti, pi), direction_of(to, po), False, k)


class Isotropic3D(Plan):
    """(theta_i, theta_o, delta_phi) with reciprocity (theta_i <= theta_o) and dphi in [0, pi]."""

    kind = "isotropic"
    isotropic = True

    def __init__(self, theta_i, theta_o, dphi, name: str = "", reciprocal: bool = False) -> None:
        super().__init__(name)
        self.theta_i = np.asarray(theta_i, dtype=float)
        self.theta_o = np.asarray(theta_o, dtype=float)
        self.dphi = np.asarray(dphi, dtype=float)
        # also measure the swapped pair (theta_o, theta_i) to check reciprocity
        self.reciprocal = bool(reciprocal)

    def stage(self, k: int = 0, results: Sequence[Result] = ()) -> Iterator[Target]:
        seen = set()
        for ti, to, dp in itertools.product(self.theta_i, self.theta_o, self.dphi):
            # reciprocity: (ti, to) and (to, ti) are one configuration; measure it as
            # theta_i <= theta_o (duplicates are removed below)
            ti, to = (ti, to) if ti <= to else (to, ti)
            dp = abs(math.remainder(dp, 2 * math.pi))  # mirror symmetry: dphi and -dphi agree
            if ti < 1e-12 or to < 1e-12:
                dp = 0.0 if ti < 1e-12 and to < 1e-12 else dp
            key = (round(ti, 9), round(to, 9), round(dp, 9))
            if key in seen:
                continue
            seen.add(key)
            yield Target(direction_of(ti, 0.0), direction_of(to, dp), True, k)
            if self.reciprocal and to - ti > 1e-9:
                yield Target(direction_of(to, 0.0), direction_of(ti, dp), True, k)


class HalfDiff(Plan):
    """Rusinkiewicz (theta_h, theta_d, phi_d) with phi_h = 0, for isotropic samples."""

    kind = "halfdiff"
    isotropic = True

    def __init__(self, theta_h, theta_d, phi_d, name: str = "") -> None:
        super().__init__(name)
        self.axes = [np.asarray(a, dtype=float) for a in (theta_h, theta_d, phi_d)]

    def stage(self, k: int = 0, results: Sequence[Result] = ()) -> Iterator[Target]:
        from gonio.brdf.frames import half_diff_to_directions

        th, td, pd = np.meshgrid(*self.axes, indexing="ij")
        wi, wo = half_diff_to_directions(th.ravel(), np.zeros(th.size), td.ravel(), pd.ravel())
        wi, wo = np.asarray(wi, dtype=float), np.asarray(wo, dtype=float)
        for a, b in zip(wi, wo, strict=True):
            if a[2] <= 1e-9 or b[2] <= 1e-9:
                continue  # below the horizon: not a measurable configuration
            yield Target(tuple(a), tuple(b), True, k)


class Adaptive(Plan):
    """Coarse isotropic pass, then a fine patch around each incident angle's peak."""

    kind = "adaptive"
    isotropic = True
    n_stages = 2

    def __init__(
        self,
        coarse: Isotropic3D,
        window: float = math.radians(10.0),
        step: float = math.radians(2.5),
        peak_ratio: float = 1.5,
        max_theta: float = math.radians(89.0),
        name: str = "",
    ) -> None:
        super().__init__(name)
        for key, v in (("step_deg", step), ("window_deg", window), ("peak_ratio", peak_ratio)):
            if not (math.isfinite(v) and v > 0):  # NaN refuses
                raise plan_key_error(("refine", key), "must be a finite number > 0")
        self.coarse = coarse
        self.window = window
        self.step = step
        self.peak_ratio = peak_ratio
        self.max_theta = max_theta

    def peaks(self, results: Sequence[Result]) -> dict[float, tuple[float, float]]:
        """Per coarse theta_i: the (theta_o, dphi) to refine around."""
        rows: dict[float, list[tuple[float, float, float]]] = {}
        for r in results:
            ti = math.acos(max(-1.0, min(1.0, r.wi[2])))
            to = math.acos(max(-1.0, min(1.0, r.wo[2])))
            dp = abs(
                math.remainder(
                    math.atan2(r.wo[1], r.wo[0]) - math.atan2(r.wi[1], r.wi[0]), 2 * math.pi
                )
            )
            # reciprocity: (ti, to) and (to, ti) are the same configuration; keep both rows
            rows.setdefault(round(ti, 6), []).append((to, dp, r.value))
            rows.setdefault(round(to, 6), []).append((ti, dp, r.value))
        out = {}
        for ti in self.coarse.theta_i:
            mirror = (float(ti), math.pi)
            row = rows.get(round(float(ti), 6), [])
            if row:
                vals = np.array([v for *_, v in row])
                i = int(np.argmax(vals))
                med = float(np.median(vals))
                if med > 0 and vals[i] >= self.peak_ratio * med:
                    out[float(ti)] = (row[i][0], row[i][1])
                    continue
            out[float(ti)] = mirror
        return out

    def stage(self, k: int = 0, results: Sequence[Result] = ()) -> Iterator[Target]:
        if k == 0:
            for t in self.coarse.stage(0):
                yield t
            return
        coarse = {
            (round(t.wi[2], 9), round(t.wo[2], 9), round(t.wo[1], 9), round(t.wo[0], 9))
            for t in self.coarse.stage(0)
        }
        n = math.floor(self.window / self.step + 1e-9)
        offs = self.step * np.arange(-n, n + 1)
        seen = set()
        for ti, (to0, dp0) in self.peaks(results).items():
            for dto, ddp in itertools.product(offs, offs):
                to = to0 + dto
                dp = abs(math.remainder(dp0 + ddp, 2 * math.pi))
                if not 0.0 <= to <= self.max_theta:
                    continue
                a, b = (ti, to) if ti <= to else (to, ti)  # reciprocity
                key = (round(a, 9), round(b, 9), round(dp, 9))
                if key in seen:
                    continue
                seen.add(key)
                t = Target(direction_of(a, 0.0), direction_of(b, dp), True, k)
                ck = (round(t.wi[2], 9), round(t.wo[2], 9), round(t.wo[1], 9), round(t.wo[0], 9))
                if ck in coarse:
                    continue
                yield t

    def describe(self) -> dict:
        return {"name": self.name, "kind": self.kind, "stages": self.n_stages}


class ConfigList(Plan):
    """An explicit list of configurations: ``angles`` (N, 4) radians, rows
    (theta_i, phi_i, theta_o, phi_o)."""

    kind = "list"

    def __init__(self, angles, isotropic: bool = False, name: str = "") -> None:
        super().__init__(name)
        self.angles = np.asarray(angles, dtype=float).reshape(-1, 4)
        self.isotropic = bool(isotropic)

    def stage(self, k: int = 0, results: Sequence[Result] = ()) -> Iterator[Target]:
        for ti, pi, to, po in self.angles:
            yield Target(direction_of(ti, pi), direction_of(to, po), self.isotropic, k)


def _config_rows(rows) -> np.ndarray:
    """``configurations`` of a list plan (degrees) -> (N, 4) radians; PlanError naming the row."""
    key = "configurations"
    if not isinstance(rows, (list, tuple)) or not rows:
        raise plan_key_error(key, "give a non-empty list of [theta_i, phi_i, theta_o, phi_o] (deg)")
    if len(rows) > MAX_TARGETS:
        raise plan_key_error(key, f"{len(rows)} configurations, more than {MAX_TARGETS}")
    out = np.empty((len(rows), 4))
    for n, row in enumerate(rows):
        if not isinstance(row, (list, tuple)) or len(row) != 4:
            raise plan_key_error((key, n), "give [theta_i, phi_i, theta_o, phi_o] (deg)")
        if any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in row):
            raise plan_key_error((key, n), "angles must be numbers (degrees)")
        vals = [float(v) for v in row]
        if not all(math.isfinite(v) for v in vals):
            raise plan_key_error((key, n), "angles must be finite")
        if not (0.0 <= vals[0] <= 90.0 and 0.0 <= vals[2] <= 90.0):
            raise plan_key_error((key, n), "polar angles must lie in [0, 90] deg")
        if not (abs(vals[1]) <= 360.0 and abs(vals[3]) <= 360.0):
            raise plan_key_error((key, n), "azimuths must lie in [-360, 360] deg")
        out[n] = vals
    return np.radians(out)


def list_spec(wi: np.ndarray, wo: np.ndarray, isotropic: bool, name: str) -> dict:
    """A ``kind = "list"`` plan spec of directions ``wi``, ``wo`` (N, 3), degrees rounded to
    1e-6 (what a guided or optimal run writes of the configurations it chose)."""
    from gonio.rigs.kinematics import spherical

    ti, pi = np.degrees(spherical(np.asarray(wi, dtype=float).reshape(-1, 3)))
    to, po = np.degrees(spherical(np.asarray(wo, dtype=float).reshape(-1, 3)))
    ti, to = np.clip(ti, 0.0, 90.0), np.clip(to, 0.0, 90.0)
    rows = [[round(float(v), 6) for v in row] for row in zip(ti, pi, to, po, strict=True)]
    return {"kind": "list", "name": name, "isotropic": bool(isotropic), "configurations": rows}


# --- specs, files and built-ins -------------------------------------------------------------

_KEYS = {
    "grid4d": ("theta_i_deg", "phi_i_deg", "theta_o_deg", "phi_o_deg"),
    "isotropic": ("theta_i_deg", "theta_o_deg", "dphi_deg"),
    "halfdiff": ("theta_h_deg", "theta_d_deg", "phi_d_deg"),
    "adaptive": ("theta_i_deg", "theta_o_deg", "dphi_deg"),
    "list": ("configurations",),
}

#: kinds built by :mod:`gonio.acquire.guided` from the same spec (they need a material prior)
_EXTERNAL_KINDS: tuple[str, ...] = ("optimal", "guided")

BUILTIN: dict[str, dict] = {
    "iso-tiny": {
        "kind": "isotropic",
        "theta_i_deg": [20, 50],
        "theta_o_deg": [20, 50],
        "dphi_deg": [90, 180],
    },
    "iso-reciprocal": {
        # small, and with every theta_i != theta_o pair also measured swapped (reciprocity check)
        "kind": "isotropic",
        "theta_i_deg": [20, 45],
        "theta_o_deg": [20, 45, 60],
        "dphi_deg": [90, 180],
        "reciprocal": True,
    },
    "iso-small": {
        "kind": "isotropic",
        "theta_i_deg": {"start": 10, "stop": 70, "step": 20},
        "theta_o_deg": {"start": 0, "stop": 70, "step": 10},
        "dphi_deg": {"start": 0, "stop": 180, "step": 30},
    },
    "grid4d-small": {
        "kind": "grid4d",
        "theta_i_deg": [15, 45],
        "phi_i_deg": [0, 90],
        "theta_o_deg": [0, 30, 60],
        "phi_o_deg": {"start": 0, "stop": 300, "step": 60},
    },
    "halfdiff-small": {
        "kind": "halfdiff",
        "theta_h_deg": [0, 2, 5, 10, 20, 40],
        "theta_d_deg": {"start": 0, "stop": 60, "step": 15},
        "phi_d_deg": [45, 90, 135],
    },
    "adaptive-small": {
        "kind": "adaptive",
        "theta_i_deg": [20, 40, 60],
        "theta_o_deg": {"start": 0, "stop": 70, "step": 10},
        "dphi_deg": {"start": 0, "stop": 180, "step": 45},
        "refine": {"window_deg": 6.0, "step_deg": 3.0},
    },
    # `gonio demo`: a coarse isotropic sweep, refined around the specular peak
    "demo": {
        "kind": "adaptive",
        "theta_i_deg": [15, 35, 55],
        "theta_o_deg": {"start": 0, "stop": 70, "step": 10},
        "dphi_deg": {"start": 0, "stop": 180, "step": 30},
        "refine": {"window_deg": 6.0, "step_deg": 2.0},
    },
    # `gonio demo --quick` (and the end-to-end test): the same sweep, coarser, no refinement
    "demo-quick": {
        "kind": "isotropic",
        "theta_i_deg": [20, 45],
        "theta_o_deg": {"start": 0, "stop": 70, "step": 10},
        "dphi_deg": [0, 60, 120, 180],
    },
    "adaptive": {
        "kind": "adaptive",
        "theta_i_deg": {"start": 10, "stop": 70, "step": 10},
        "theta_o_deg": {"start": 0, "stop": 75, "step": 5},
        "dphi_deg": {"start": 0, "stop": 180, "step": 20},
        "refine": {"window_deg": 8.0, "step_deg": 2.0},
    },
}


def builtin_plans() -> list[str]:
    """Names accepted by :func:`load_plan` without a file."""
    return sorted(BUILTIN)


def plan_from_spec(spec: dict, name: str = "") -> Plan:
    """Build a plan from a parsed plan file (see the module docstring); raise PlanError."""
    if not isinstance(spec, dict):
        raise PlanError("a plan must be a table")
    kind = spec.get("kind")
    if isinstance(kind, str) and kind in _EXTERNAL_KINDS:
        from gonio.acquire.guided import guided_plan_from_spec

        return guided_plan_from_spec(spec, name)
    if not isinstance(kind, str) or kind not in _KEYS:
        raise plan_key_error("kind", f"{kind!r} is not one of {sorted([*_KEYS, *_EXTERNAL_KINDS])}")
    if kind == "list":
        extra = sorted(set(spec) - {"kind", "name", "isotropic", "configurations"})
        if extra:
            raise plan_key_error(extra[0], "unknown for kind 'list'")
        if not isinstance(spec.get("isotropic", False), bool):
            raise plan_key_error("isotropic", "must be true or false")
        if "configurations" not in spec:
            raise PlanError("plan key configurations: missing (kind 'list' needs configurations)")
        rows = _config_rows(spec["configurations"])
        return ConfigList(rows, spec.get("isotropic", False), name=spec.get("name", name) or "list")
    allowed = {"kind", "name", *_KEYS[kind]} | ({"refine"} if kind == "adaptive" else set())
    allowed |= {"reciprocal"} if kind == "isotropic" else set()
    if not isinstance(spec.get("reciprocal", False), bool):
        raise plan_key_error("reciprocal", "must be true or false")
    extra = sorted(set(spec) - allowed)
    if extra:
        raise plan_key_error(extra[0], f"unknown for kind {kind!r}")
    missing = [k for k in _KEYS[kind] if k not in spec]
    if missing:
        raise PlanError(
            f"plan key {missing[0]}: missing (kind {kind!r} needs {', '.join(_KEYS[kind])})"
        )
    axes = [plan_angles(spec[k], k) for k in _KEYS[kind]]
    n_targets = math.prod(len(a) for a in axes)
    if n_targets > MAX_TARGETS:
        raise PlanError(f"plan asks for {n_targets} configurations, more than {MAX_TARGETS}")
    for k, a in zip(_KEYS[kind], axes, strict=True):
        if k.startswith("theta") and not np.all((a >= 0) & (a <= math.pi / 2)):
            raise plan_key_error(k, "polar angles must lie in [0, 90] deg")
    name = spec.get("name", name) or kind
    if kind == "grid4d":
        return Grid4D(*axes, name=name)
    if kind == "isotropic":
        return Isotropic3D(*axes, name=name, reciprocal=spec.get("reciprocal", False))
    if kind == "halfdiff":
        return HalfDiff(*axes, name=name)
    ref = spec.get("refine", {})
    if not isinstance(ref, dict) or set(ref) - {"window_deg", "step_deg", "peak_ratio"}:
        raise PlanError("plan key refine: allowed keys are window_deg, step_deg, peak_ratio")
    try:
        window = float(ref.get("window_deg", 10.0))
        step = float(ref.get("step_deg", 2.5))
        peak_ratio = float(ref.get("peak_ratio", 1.5))
    except (TypeError, ValueError):
        raise PlanError("plan key refine: values must be numbers") from None
    if not all(map(math.isfinite, (window, step, peak_ratio))):
        raise PlanError("plan key refine: values must be finite")
    # the refinement patch has about (2 window / step + 1)^2 targets per incident angle
    if step > 0 and not (2 * window / step + 1) ** 2 * len(axes[0]) <= MAX_TARGETS:
        raise PlanError(
            f"plan key refine: window_deg / step_deg asks for more than {MAX_TARGETS} targets"
        )
    return Adaptive(
        Isotropic3D(*axes),
        window=math.radians(window),
        step=math.radians(step),
        peak_ratio=peak_ratio,
        name=name,
    )


def load_plan(name_or_path: str | Path) -> tuple[Plan, dict]:
    """A built-in plan by name, or a plan TOML file; returns (plan, spec)."""
    s = str(name_or_path)
    if s in BUILTIN:
        return plan_from_spec(BUILTIN[s], s), dict(BUILTIN[s], name=s)
    p = Path(s)
    if not p.is_file():
        raise PlanError(
            f"unknown plan {s!r}: not a file, and built-ins are {', '.join(builtin_plans())}"
        )
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise PlanError(f"{p}: cannot read ({exc.strerror or exc})") from None
    spec = loads_toml(data, str(p), PlanError)  # size, UTF-8 and depth bounds
    text = data.decode("utf-8")  # loads_toml has checked that it decodes
    from gonio.rigs.toml_lines import non_finite, where

    for path, value in non_finite(spec):
        raise PlanError(f"{where(str(p), text, path)}: {value} is not a finite number")
    spec.setdefault("name", p.stem)
    try:
        if spec.get("kind") in _EXTERNAL_KINDS and isinstance(spec.get("prior"), str):
            from gonio.acquire.guided import resolve_prior

            spec = resolve_prior(spec, p.parent)  # the run records the absolute path and hash
        return plan_from_spec(spec, p.stem), spec
    except PlanError as exc:
        path = getattr(exc, "key_path", None)
        if path is None:
            raise PlanError(f"{p}: {exc}") from None
        raise PlanError(f"{where(str(p), text, path)}: {exc.detail}") from None
