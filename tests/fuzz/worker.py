"""The fuzz worker: a long-lived process that loads one mutated file per request and judges it.

Protocol (one JSON object per line): the parent writes ``{"kind": ..., "path": ...}`` on the
worker's stdin and reads ``{"outcome": "error" | "load" | "fail", "detail": ...}`` from its
stdout. Library output that would go to stdout is sent to stderr so that it cannot break the
protocol. The worker imports JAX and gonio once and runs every check on a clean corpus file at
start, so that compilation and import time are not charged to the first case.

A case passes when it gives

* ``error``: a :class:`gonio.errors.GonioError` whose message is one line and names the file; or
* ``load``: an object that passes its kind's check below (finite values, non-negative where the
  format promises it, directions in the upper hemisphere, a sane shape), after evaluating it
  where the format is an evaluator (RGL: f, pdf and sample; neural BRDFs: f; fit results: the
  model's ``f``; rig files: a dry-run plan; plan files: a dry run on the simulated rig).

Anything else (another exception type, a multi-line or anonymous message, a silent load of data
that cannot be right) is a ``fail`` whose detail names the problem and the innermost frames.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import sys
import traceback
from pathlib import Path
from typing import Any

import numpy as np

#: Largest |BRDF| a check accepts, 1/sr (the readers' documented bound, gonio._bounded).
MAX_BRDF = 1e10
NEGATIVE_TOLERANCE = 0.01
#: Plans with more first-stage targets are loaded and checked but not dry-run.
DRY_RUN_TARGETS = 1000
#: Largest table a check accepts (cells x channels), far above any real measurement.
MAX_VALUES = 1 << 27
#: An RGL colour table may dip this far below 0 (fraction of its peak; gonio.io.rgl documents
#: -1.4 % in the database's files): ``f`` itself is kept as signed as the file is.
RGL_COLOUR_TOLERANCE = 0.1


class Lie(Exception):
    """A load that returned data which cannot be right."""


def _dirs(n: int = 24, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)

    def one() -> np.ndarray:
        th = np.arccos(np.sqrt(rng.random(n))) * 0.98
        ph = 2 * math.pi * rng.random(n)
        return np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)

    return one(), one()


def _check_values(
    what: str, v: Any, valid: Any = None, nonneg: bool = True, tol: float = NEGATIVE_TOLERANCE
) -> None:
    v = np.asarray(v)
    if v.dtype.kind not in "fiu":
        raise Lie(f"{what} has dtype {v.dtype}")
    if v.size > MAX_VALUES:
        raise Lie(f"{what} has {v.size} values")
    if valid is not None:
        valid = np.asarray(valid, bool)
        valid = valid.reshape(valid.shape + (1,) * (v.ndim - valid.ndim))
        v = v[np.broadcast_to(valid, v.shape)]
    if not np.all(np.isfinite(v)):
        raise Lie(f"{what}: {int(np.count_nonzero(~np.isfinite(v)))} non-finite values")
    if v.size and np.max(np.abs(v)) > MAX_BRDF:
        raise Lie(f"{what}: absurd value {float(np.max(np.abs(v))):.3g}")
    # "non-negative" as gonio.io._sanity documents it: noise and out-of-gamut colour
    # conversion dip below zero by at most NEGATIVE_TOLERANCE of the peak
    if nonneg and v.size and np.min(v) < -tol * np.max(np.abs(v)):
        raise Lie(f"{what}: negative value {float(np.min(v)):.3g}")


def _check_dirs(what: str, d: Any) -> None:
    d = np.asarray(d, dtype=np.float64)
    if d.ndim != 2 or d.shape[1] != 3 or len(d) == 0:
        raise Lie(f"{what} has shape {d.shape}")
    if not np.all(np.isfinite(d)):
        raise Lie(f"{what}: non-finite directions")
    if np.max(np.abs(np.linalg.norm(d, axis=1) - 1)) > 1e-3:
        raise Lie(f"{what}: not unit vectors")
    if np.min(d[:, 2]) < -1e-6:
        raise Lie(f"{what}: a direction below the horizon (z = {float(np.min(d[:, 2])):.3g})")


_DOMAIN = {"theta_h": math.pi / 2, "theta_d": math.pi / 2, "phi_d": 2 * math.pi,
           "phi_h": 2 * math.pi}  # fmt: skip


def check_table(obj: Any, nonneg: bool = True) -> str:
    """A TabulatedBRDF or MeasuredSamples: finite, in range, sane shape; evaluate a table."""
    if hasattr(obj, "axes"):
        for a in obj.axes:
            top = _DOMAIN.get(a.name)
            if top is None:
                raise Lie(f"unknown axis {a.name!r}")
            if a.lo < -1e-6 or a.hi > top + 1e-6:
                raise Lie(f"axis {a.name} range [{a.lo}, {a.hi}] outside [0, {top:.4g}]")
        mask = np.ones(np.shape(obj.values)[:-1], bool) if obj.mask is None else obj.mask
        if not np.any(mask):
            raise Lie("table has no valid cell")
        _check_values("values", obj.values, mask, nonneg)
        if obj.sigma is not None:
            _check_values("sigma", obj.sigma, mask, True)
        wi, wo = _dirs()
        _check_values("f(wi, wo)", np.asarray(obj.f(wi, wo)), None, nonneg)
        return f"table {np.shape(obj.values)}"
    if hasattr(obj, "wi"):
        _check_dirs("wi", obj.wi)
        _check_dirs("wo", obj.wo)
        _check_values("values", obj.values, None, nonneg)
        if getattr(obj, "sigma", None) is not None:
            _check_values("sigma", obj.sigma, None, True)
        return f"samples {np.shape(obj.values)}"
    raise Lie(f"load returned a {type(obj).__name__}")


def _load(path: str) -> Any:
    from gonio import io

    return io.load(path)


def c_native(path: str) -> str:
    obj = _load(path)
    out = check_table(obj)
    from gonio.io.native import read_native

    try:  # a run file keeps its gridded table in a group
        out += "; group " + check_table(read_native(path, group="gridded"))
    except Exception as exc:
        from gonio.errors import GonioError

        if not isinstance(exc, GonioError):
            raise
    return f"{out}; {round_trip(obj, path)}"


def _load_checked(path: str) -> str:
    obj = _load(path)
    return f"{check_table(obj)}; {round_trip(obj, path)}"


c_merl = c_cornell = c_alta = _load_checked


#: Tables up to this many values go through every writer that takes them in each case's round
#: trip; larger ones (a MERL grid: 4.4 M values) through the writer of their own format only.
ROUND_TRIP_VALUES = 1 << 18


def _writers(obj: Any) -> list[tuple[str, dict]]:
    """The ``io.save`` targets (``gonio convert``'s) of a case's round trip, as
    ``(suffix, keyword arguments)``: every target for small objects (a refusal on write is
    allowed and cheap for what a format cannot hold), the cell-for-cell MERL writer for a
    table on MERL's grid. Resampling writers (MERL from another grid, RGL tensor files from
    a table: seconds each) are exercised on the corpus by ``test_round_trip_resampling``."""
    from gonio.brdf.tabulated import TabulatedBRDF
    from gonio.io.merl import MERL_DIMS

    small = int(np.size(obj.values)) <= ROUND_TRIP_VALUES
    out = [(".brdf.h5", {}), (".brdf.h5", {"lossy": 0.01}), (".exr", {})] if small else []
    if isinstance(obj, TabulatedBRDF) and obj.shape[:3] == MERL_DIMS and len(obj.axes) == 3:
        out.append((".binary", {}))
    return out


def read_back(out: Path) -> Any:
    """What gonio reads from a file it wrote: ``io.load``, or the EXR slice reader."""
    from gonio import io
    from gonio.io.exr import read_table_slices

    return read_table_slices(out) if out.suffix == ".exr" else io.load(out)


def round_trip(obj: Any, path: str, writers: list[tuple[str, dict]] | None = None) -> str:
    """The round-trip oracle: ``obj`` (what a case loaded) through each writer of
    :func:`_writers`, then back through its reader. A writer may refuse (a typed, one-line
    error: the format cannot hold the object, or the reader's own checks say no); it may not
    write a file its reader refuses, nor one whose content fails the case's check."""
    from gonio import io
    from gonio.errors import GonioError

    counts = {"written": 0, "refused": 0}
    stem = Path(path).name.split(".")[0]
    for suffix, kw in _writers(obj) if writers is None else writers:
        out = Path(path).with_name(f"{stem}-trip{'-lossy' if kw else ''}{suffix}")
        try:
            try:
                io.save(obj, out, **kw)
            except GonioError as exc:
                if "\n" in str(exc):
                    raise Lie(
                        f"multi-line refusal writing {out.name}: {str(exc)[:200]!r}"
                    ) from None
                counts["refused"] += 1
                continue
            try:
                back = read_back(out)
            except GonioError as exc:
                raise Lie(
                    f"{out.name}, as gonio wrote it, is refused by its reader: {exc}"
                ) from None
            if isinstance(back, dict):
                _check_values("slices read back", back["values"], back["mask"], True)
            elif hasattr(back, "to_table"):  # an RGL file: an evaluator, signed like its colour
                _check_values("RGL f read back", np.asarray(back.f(*_dirs(16, 1))), None, False)
            else:
                check_table(back)
            counts["written"] += 1
        finally:
            out.unlink(missing_ok=True)
    return f"round trip: {counts['written']} written and read back, {counts['refused']} refused"


#: Fixed outgoing directions and unit-square points for the RGL evaluator's ``sample``.
_U = np.array([[0.5, 0.5], [0.1, 0.9], [0.99, 0.01], [0.3, 0.7], [0.0, 0.0], [0.999, 0.999]])


def c_rgl(path: str) -> str:
    """An RGL ``.bsdf`` through :func:`gonio.io.load` (an exact evaluator, RGLMeasured): the
    colour table not clearly negative (slightly negative values are kept, as the reference reader
    keeps them: :mod:`gonio.io.rgl_measured`); ``f`` finite and bounded; ``pdf`` finite and >= 0;
    ``sample`` with finite pdf and weights and unit ``wi`` where the sample succeeded (pdf > 0);
    an isotropic file tabulated, written and read back (:func:`_rgl_round_trip`)."""
    b = _load(path)
    if type(b).__name__ != "RGLMeasured":
        raise Lie(f"load returned a {type(b).__name__}")
    from gonio.io.rgl import read_rgl

    fields = read_rgl(path).fields
    colour = fields["spectra"] if "spectra" in fields else fields["rgb"]
    _check_values("RGL colour table", colour, None, nonneg=True, tol=RGL_COLOUR_TOLERANCE)
    wi, wo = _dirs(16, 1)
    _check_values("RGL f", np.asarray(b.f(wi, wo)), None, nonneg=False)
    pdf = np.asarray(b.pdf(wi, wo))
    _check_values("RGL pdf", pdf, None, nonneg=True)
    if np.min(pdf) < 0:
        raise Lie(f"RGL pdf: negative density {float(np.min(pdf)):.3g}")
    wo6 = wo[: len(_U)]
    s = b.sample(wo6, _U)
    spdf, w, swi = np.asarray(s.pdf), np.asarray(s.weight), np.asarray(s.wi)
    _check_values("RGL sample pdf", spdf, None, nonneg=True)
    if np.min(spdf) < 0:
        raise Lie(f"RGL sample pdf: negative density {float(np.min(spdf)):.3g}")
    _check_values("RGL sample weight", w, None, nonneg=False)
    ok = spdf > 0
    if np.any(ok):
        _check_dirs("RGL sampled wi", swi[ok])
    trip = _rgl_round_trip(b, path) if b.isotropic else "anisotropic: no round trip"
    return (
        f"RGL BSDF, {b.n_channels} channels, {int(np.count_nonzero(ok))}/{len(ok)} samples, {trip}"
    )


def _rgl_round_trip(b: Any, path: str) -> str:
    """What ``gonio convert`` writes, the native reader reads: a coarse tabulation (batches of
    16, the size ``f`` was just compiled for), saved as ``.brdf.h5`` and loaded back. The
    tabulation may refuse (a typed error, as convert's); the reader may not
    (:func:`round_trip`: native, lossy native and EXR slices)."""
    from gonio.io.merl import merl_axes

    table = b.to_table(axes=merl_axes((6, 6, 12)), chunk=16)
    return round_trip(table, path)


#: A network's ``f`` may dip below 0 in dark cells (nothing is clamped, gonio.io.nbrdf);
#: this fraction of its peak over the checked directions is the most a check accepts.
NBRDF_NEGATIVE_TOLERANCE = 0.1


def c_nbrdf(path: str) -> str:
    """A neural-BRDF archive: each material it names (and those the corpus put in it, see
    :data:`tests.fuzz.nbrdf.NAMES`, so that a removed member is noticed) through
    ``gonio.io.nbrdf.read_nbrdf("ARCHIVE.zip::NAME")``, ``f`` on fixed directions finite,
    bounded and non-negative, and the network on a small MERL-like grid (the code path of
    ``io.load``, which evaluates MERL's full grid) likewise."""
    import zipfile

    from gonio.io.nbrdf import list_materials, read_nbrdf
    from tests.fuzz.nbrdf import NAMES

    listed = list_materials(path)
    with zipfile.ZipFile(path) as zf:
        stems = {n.rsplit("/", 1)[-1].rpartition(".")[0] for n in zf.namelist()}
    names = sorted(set(listed[:3]) | (set(NAMES) & stems))
    wi, wo = _dirs(16, 3)
    for name in names:
        net = read_nbrdf(f"{path}::{name}")
        _check_values(f"{name} f", net.f(wi, wo), None, True, NBRDF_NEGATIVE_TOLERANCE)
        t = net.to_table((4, 4, 8))
        _check_values(f"{name} table", t.values, t.mask, True, NBRDF_NEGATIVE_TOLERANCE)
        trip = round_trip(t, path)
    return f"nbrdf archive: {len(listed)} materials, read {names}" + (f"; {trip}" if names else "")


def c_prior(path: str) -> str:
    """A material prior (``*.prior.h5``) through ``gonio.prior.Prior.read``; a reconstruction
    from a few samples must be finite and within the readers' bounds, the chosen
    configurations distinct, and the file must survive a write and a read."""
    import tempfile

    from gonio.prior import Prior

    prior = Prior.read(path)
    wi, wo = _dirs(8, 5)
    with np.errstate(all="ignore"):
        r = prior.reconstruct(wi, wo, np.full((8, prior.n_channels), 0.3))
    if not (np.isfinite(r.mapped).all() and np.isfinite(r.predicted_error)):
        raise Lie("a reconstruction from a valid prior is not finite")
    _check_values("reconstruction", r.table.values, r.table.mask, True, 0.0)
    idx = prior.choose(wi, wo, 3)
    if len(set(idx.tolist())) != 3:
        raise Lie(f"choose() repeated a configuration: {idx}")
    with tempfile.TemporaryDirectory() as tmp:
        back = Prior.read(_write_prior(prior, Path(tmp) / "p.prior.h5"))
    if back.rank != prior.rank or not np.array_equal(back.basis, prior.basis):
        raise Lie("a prior changed through write and read")
    return f"prior: rank {prior.rank}, {prior.n_valid} cells, error {r.predicted_error:.3g}"


def _write_prior(prior: Any, path: Path) -> Path:
    prior.write(path)
    return path


def c_exr(path: str) -> str:
    from gonio.io.exr import read_exr

    img, names = read_exr(path)
    if img.ndim != 3 or img.shape[2] != len(names) or img.size > MAX_VALUES:
        raise Lie(f"image of shape {img.shape} with channels {names}")
    return f"image {img.shape}"


def c_exr_slices(path: str) -> str:
    from gonio.io.exr import read_table_slices

    d = read_table_slices(path)
    v, m = d["values"], d["mask"]
    if v.ndim != 4 or m.shape != v.shape[:3] or len(d["phi_d"]) != v.shape[2]:
        raise Lie(f"slices of shape {v.shape}, mask {m.shape}")
    _check_values("slice values", v, m, True)
    if not np.all(np.isfinite(d["phi_d"])):
        raise Lie("non-finite phi_d")
    return f"slices {v.shape}"


def _walk_numbers(obj: Any, where: str = "") -> None:
    if dataclasses.is_dataclass(obj):
        for f in dataclasses.fields(obj):
            _walk_numbers(getattr(obj, f.name), f"{where}.{f.name}")
    elif isinstance(obj, dict):
        for k, v in obj.items():
            _walk_numbers(v, f"{where}.{k}")
    elif isinstance(obj, list | tuple):
        for i, v in enumerate(obj):
            _walk_numbers(v, f"{where}[{i}]")
    elif isinstance(obj, float) and not math.isfinite(obj):
        raise Lie(f"rig field {where} = {obj}")


def c_rig(path: str) -> str:
    from gonio.acquire.engine import dry_run
    from gonio.acquire.plans import load_plan
    from gonio.rigs.config import load_rig

    rig = load_rig(path)
    _walk_numbers(rig)
    plan, _ = load_plan("iso-tiny")
    stages = dry_run(rig, plan, time_budget_s=2.0)
    return f"rig {rig.name}: {sum(len(s.accepted) for s in stages)} accepted"


def c_plan(path: str) -> str:
    from gonio.acquire.engine import dry_run
    from gonio.acquire.plans import load_plan
    from gonio.rigs.config import load_rig

    plan, _ = load_plan(path)
    targets = list(plan.stage(0))
    _check_dirs("plan wi", [t.wi for t in targets])
    _check_dirs("plan wo", [t.wo for t in targets])
    if len(targets) > DRY_RUN_TARGETS:
        # a valid big plan: its dry run is legitimate work (seconds per thousand targets)
        return f"plan {plan.name}: {len(targets)} targets (no dry run)"
    stages = dry_run(load_rig("sim"), plan, time_budget_s=2.0)
    return f"plan {plan.name}: {sum(len(s.configs) for s in stages)} configurations"


def _spec_params(spec: Any) -> set[str]:
    """Parameter names a model_spec states, with their nesting (``child.param``)."""
    out: set[str] = set()
    if not isinstance(spec, dict):
        return out
    for k, v in (spec.get("params") or {}).items():
        if v is not None:
            out.add(k)
    for i, lobe in enumerate(spec.get("lobes") or []):
        out |= {f"lobes[{i}].{p}" for p in _spec_params(lobe)}
    for name, child in (spec.get("children") or {}).items():
        kids = child if isinstance(child, list) else [child]
        for i, c in enumerate(kids):
            out |= {f"{name}[{i}].{p}" for p in _spec_params(c)}
    return out


def c_fit(path: str) -> str:
    from gonio.io.fit_result import load_model, read_result

    obj = read_result(path)
    model = load_model(path)
    stated = _spec_params(obj["model_spec"])
    built = _spec_params(model.to_dict())
    missing = sorted(built - stated)
    if missing:
        raise Lie(f"parameters {missing} missing or null in the file, loaded with defaults")
    wi, wo = _dirs(16, 2)
    _check_values("model f", np.asarray(model.f(wi, wo)), None, nonneg=True)
    return f"model {type(model).__name__}; {_fit_round_trip(obj, path)}"


def _fit_round_trip(obj: dict, path: str) -> str:
    """The fit-result writer (``FitResult.save``'s :func:`write_result`) on what the reader
    accepted: it may not refuse it, and the reader must read back the same record."""
    from gonio.errors import GonioError
    from gonio.io.fit_result import read_result, write_result

    out = Path(path).with_name(Path(path).name.split(".")[0] + "-trip.fit.json")
    try:
        try:
            write_result(obj, out)
        except GonioError as exc:
            raise Lie(f"the fit writer refuses a record its reader accepted: {exc}") from None
        try:
            back = read_result(out)
        except GonioError as exc:
            raise Lie(f"{out.name}, as gonio wrote it, is refused by its reader: {exc}") from None
    finally:
        out.unlink(missing_ok=True)
    if back != obj:
        raise Lie("the fit result read back differs from the one written")
    return "round trip through write_result"


def c_selftest_hang(path: str) -> str:
    """Harness self-test: a case that never answers (and ignores SIGINT, as libhdf5 does)."""
    import signal
    import time

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    while True:
        time.sleep(1)


def c_selftest_spin(path: str) -> str:
    """Harness self-test: a case that computes forever (and ignores SIGINT)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    x = 0
    while True:
        x = (x * 1103515245 + 12345) % (1 << 31)


def c_selftest_memory(path: str) -> str:
    """Harness self-test: a case that keeps allocating (touching every page) until killed."""
    import time

    blocks = []
    while True:
        blocks.append(np.ones(1 << 24))  # 128 MiB, resident
        time.sleep(0.05)


CHECKS = {
    "native": c_native,
    "merl": c_merl,
    "rgl": c_rgl,
    "nbrdf": c_nbrdf,
    "cornell": c_cornell,
    "alta": c_alta,
    "exr": c_exr,
    "exr_slices": c_exr_slices,
    "rig": c_rig,
    "plan": c_plan,
    "fit": c_fit,
    "prior": c_prior,
    "selftest-hang": c_selftest_hang,
    "selftest-spin": c_selftest_spin,
    "selftest-memory": c_selftest_memory,
}


def judge(kind: str, path: str) -> dict[str, str]:
    """Run the check of ``kind`` on ``path``; the verdict as a JSON-ready dict."""
    from gonio.errors import GonioError

    try:
        detail = CHECKS[kind](path)
    except GonioError as exc:
        msg = str(exc)
        if "\n" in msg:
            return {"outcome": "fail", "detail": f"multi-line {type(exc).__name__}: {msg[:300]!r}"}
        if Path(path).name not in msg:
            return {"outcome": "fail", "detail": f"error does not name the file: {msg[:300]!r}"}
        return {"outcome": "error", "detail": f"{type(exc).__name__}: {msg[:300]}"}
    except Lie as exc:
        return {"outcome": "fail", "detail": f"silent load of bad data: {exc}"}
    except BaseException as exc:
        if isinstance(exc, KeyboardInterrupt | SystemExit):
            raise
        frames = traceback.extract_tb(exc.__traceback__)
        where = " <- ".join(f"{Path(f.filename).name}:{f.lineno}" for f in reversed(frames[-4:]))
        return {
            "outcome": "fail",
            "detail": f"uncaught {type(exc).__name__}: {str(exc)[:200]} at {where}",
        }
    return {"outcome": "load", "detail": detail}


def main() -> None:
    proto = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)  # anything printed by libraries goes to stderr
    sys.stdout = sys.stderr
    warm = json.loads(sys.argv[1]) if len(sys.argv) > 1 else []
    for kind, path in warm:
        judge(kind, path)
    proto.write(json.dumps({"ready": os.getpid()}) + "\n")
    for line in sys.stdin:
        req = json.loads(line)
        proto.write(json.dumps(judge(req["kind"], req["path"])) + "\n")


if __name__ == "__main__":
    main()
