"""The default fit: candidate families fitted on training cells, chosen on held-out cells.

What ``gonio fit FILE`` does without ``--model`` (and :func:`select` in Python):

1. **Cells.** The data's valid cells are split once (seeded): on a large table (a MERL grid has
   about 9e5 cells inside 80 degrees) :data:`TRAIN_CELLS` cells, one per stratum of equal count
   along theta_h (:meth:`~gonio.fit.data.FitData.stratified_subset`, so the few cells of the
   specular peak are always represented), are the training cells and :data:`TEST_CELLS` others,
   drawn at random from the rest, are held out; smaller data holds out
   :data:`HELD_OUT_FRACTION` of its cells at random. A 10-parameter model does not need more
   cells than this to be determined, and the fit costs a fraction of one over every cell.
2. **Families.** Every family of :data:`DEFAULT_FAMILIES` is fitted to the training cells with
   the default loss: ``wls`` (chi-square) where the data has sigma, else :data:`DEFAULT_LOSS`
   (``sqrt-cos``, :mod:`gonio.fit.losses`: errors weighted by the brightness a lit sphere shows
   them at). The families hold what real highlights have: a Lambert base, a long-tailed
   microfacet lobe (GTR, free tail exponent), a second one, and a retro-reflective lobe.
3. **Choice.** Each fit's loss on the held-out cells (its cross-validated error) ranks them; the
   family with the fewest parameters whose held-out error is within :data:`SIMPLER_WITHIN` of the
   best is chosen (a nested family that fits as well, e.g. Lambert alone for a matte paint, wins
   over a lobe whose parameters run to their bounds). Nothing of it reads a published fit.

The families, the loss and the thresholds were chosen on the tuning half of the NBRDF materials
(``benchmarks/_nbrdf_split.py``); ``benchmarks/README.md`` reports both halves.
"""

from __future__ import annotations

import contextlib
import dataclasses
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gonio.brdf.models import BRDFModel
from gonio.errors import FitError, GonioError
from gonio.fit import presets
from gonio.fit.api import FitOptions, fit
from gonio.fit.compare import Comparison, summarize, with_nested
from gonio.fit.data import FitData, prepare
from gonio.fit.losses import Loss, get_loss
from gonio.fit.objective import Problem
from gonio.fit.params import Layout
from gonio.fit.result import FitResult

#: The families the default fit tries, simplest first.
DEFAULT_FAMILIES: tuple[str, ...] = (
    "lambert",
    "lambert+gtr",
    "lambert+gtr+gtr",
    "lambert+retro+gtr",
)
#: The loss of the default fit on data without sigma.
DEFAULT_LOSS = "sqrt-cos"
#: Training and held-out cells on large data (see the module docstring).
TRAIN_CELLS = TEST_CELLS = 8192
#: Share of the cells held out on data with fewer than ``TRAIN_CELLS + TEST_CELLS`` cells.
HELD_OUT_FRACTION = 0.2
#: Cells the default fit's plots show at most (see :func:`fit_models`).
PLOT_CELLS = 16384
#: A family with fewer parameters is chosen while its held-out error is within this fraction
#: of the best family's.
SIMPLER_WITHIN = 0.01


@dataclass
class Selection:
    """Outcome of :func:`select`.

    Attributes
    ----------
    results : each family's fit on the training cells, in the order tried.
    cv_errors : ``{family: loss on the held-out cells}`` (the loss's reported value).
    chosen : the chosen family's name; ``result`` is its fit.
    reason : one sentence saying why.
    loss : the loss fitted and cross-validated.
    n_train, n_test : cells fitted and held out.
    timings : seconds per stage (``split``, one per family, ``total``).
    """

    results: list[FitResult]
    cv_errors: dict[str, float]
    chosen: str
    reason: str
    loss: str
    n_train: int
    n_test: int
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def result(self) -> FitResult:
        """The chosen family's fit."""
        return next(r for r in self.results if r.name == self.chosen)


def split_cells(data: FitData, seed: int = 0) -> tuple[FitData, FitData]:
    """``(train, held_out)`` cells of ``data`` (see the module docstring), disjoint, seeded."""
    n = data.n
    rng = np.random.default_rng(seed)
    if n >= TRAIN_CELLS + TEST_CELLS:
        picked = data.stratified_indices(TRAIN_CELLS, seed)
        rest = np.setdiff1d(np.arange(n), picked, assume_unique=True)
        test = np.sort(rng.choice(rest, size=TEST_CELLS, replace=False))
        return data.subset(picked), data.subset(test)
    n_test = round(HELD_OUT_FRACTION * n)
    if n_test < 1 or n - n_test < 2:
        raise FitError(f"only {n} samples: too few to hold any out for the model choice")
    perm = rng.permutation(n)
    return data.subset(np.sort(perm[n_test:])), data.subset(np.sort(perm[:n_test]))


def default_loss(data: FitData, options: FitOptions) -> str:
    """The loss of the default fit: the options' unless ``"auto"``; then ``wls`` with sigma,
    :data:`DEFAULT_LOSS` without."""
    if options.loss != "auto":
        return options.loss
    return "wls" if data.sigma is not None else DEFAULT_LOSS


def select(
    data: Any,
    families: Sequence[str] | None = None,
    *,
    options: FitOptions | None = None,
    **overrides: Any,
) -> Selection:
    """Fit every family of ``families`` (default :data:`DEFAULT_FAMILIES`) to the training
    cells of ``data`` and choose one by the held-out cells (see the module docstring).

    ``data``: anything :func:`gonio.fit.fit` takes; ``options``/``overrides``: as there (the
    loss ``"auto"`` means ``wls`` with sigma, :data:`DEFAULT_LOSS` without; ``channels`` must
    be ``"shared"``).

    Raises
    ------
    FitError
        As :func:`gonio.fit.fit`, and for data too small to hold cells out.
    """
    t_start = time.perf_counter()
    opts = dataclasses.replace(options or FitOptions(), **overrides)
    if opts.channels != "shared":
        raise FitError("the default model choice fits shared lobe shapes; pass --model to fit "
                       "channels separately")  # fmt: skip
    fd = data if isinstance(data, FitData) else prepare(data, opts.theta_max_deg, name=opts.name)
    if isinstance(data, FitData) and fd.source.get("theta_max_deg") != float(opts.theta_max_deg):
        fd = prepare(fd, opts.theta_max_deg, name=opts.name)
    loss = default_loss(fd, opts)
    opts = dataclasses.replace(opts, loss=loss)
    names = list(families or DEFAULT_FAMILIES)
    if not names:
        raise FitError("no model family given")
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    train, test = split_cells(fd, opts.seed)
    # the training cells stand for the data: fitted as they are, with no further subsets
    train = dataclasses.replace(train, source={**fd.source, "n_used": train.n,
                                               "cells": "training"})  # fmt: skip
    timings["split"] = time.perf_counter() - t0
    results, cv = [], {}
    with _compiled_ahead(names[1:], train, get_loss(loss), opts.fixed):
        for name in names:
            t0 = time.perf_counter()
            r, cv[name] = _fit_family(name, results, train, test, loss, opts)
            results.append(r)
            timings[name] = time.perf_counter() - t0
    chosen, reason = _choose(results, cv)
    timings["total"] = time.perf_counter() - t_start
    return Selection(results, cv, chosen, reason, loss, train.n, test.n, timings)


def _fit_family(
    name: str, done: list[FitResult], train: FitData, test: FitData, loss: str, opts: FitOptions
) -> tuple[FitResult, float]:
    """One family's fit on the training cells and its loss on the held-out cells."""
    tmpl, fixed = _warm_template(name, done)
    fixed = {**fixed, **(opts.fixed or {})}
    # every stage on the training cells (no random subset of them: one compiled program)
    r = fit(train, model=tmpl, options=dataclasses.replace(opts, fixed=fixed,
                                                           subsample=train.n))  # fmt: skip
    assert isinstance(r, FitResult) and r.u is not None
    r.name = name
    # the held-out loss through the fit's own compiled program (same layout, same shapes)
    held_out = Problem(Layout(tmpl, train.channels, fixed=fixed), get_loss(loss), test)
    cost = held_out.normal(r.u)[0]
    return r, get_loss(loss).value(cost) if np.isfinite(cost) else float("inf")


@contextlib.contextmanager
def _compiled_ahead(
    names: Sequence[str], train: FitData, loss: Loss, extra_fixed: dict[str, Any] | None
) -> Iterator[None]:
    """Compile (or load) the programs the families ``names`` will run on ``train`` (the normal
    equations, also of the held-out cells, which have the same size, and the predictions) on
    a background thread while the body fits the first families: XLA's compiler releases the
    GIL, so on an empty compilation cache a second core compiles the next family while this
    one fits. A family's fit that needs a program first waits for it
    (:meth:`~gonio.fit.programs.Program.prepare`); leaving the body cancels the rest."""
    problems = []
    for name in names:
        try:
            tmpl, fixed, _ = presets.build(name)
            layout = Layout(tmpl, train.channels, fixed={**fixed, **(extra_fixed or {})})
        except GonioError:  # e.g. a --fix key the family lacks: its fit reports it
            continue
        problems.append(Problem(layout, loss, train))
    pool = ThreadPoolExecutor(1, thread_name_prefix="gonio-select-compile")
    jobs = [pool.submit(p.prepare, what) for p in problems for what in ("normal", "predict")]
    try:
        yield
    finally:
        for job in jobs:
            job.cancel()
        pool.shutdown(wait=False)


#: Albedo factors of lobes, and the value an added lobe starts at.
_LOBE_SCALES, _FAINT = ("rho_s", "rho_r"), 0.05


def _warm_template(name: str, done: list[FitResult]) -> tuple[BRDFModel, dict[str, Any]]:
    """The preset ``name``'s template and fixed values, started from the fitted values of the
    largest family already fitted whose lobes are all among its own (``lambert+gtr`` for
    ``lambert+gtr+gtr``): a family then starts where the family it nests ended, so that its
    training loss is never worse than that family's, whatever the random starts find."""
    tmpl, fixed, _ = presets.build(name)
    lobes = name.split("+")
    best = None
    for r in done:
        sub = r.name.split("+")
        if all(sub.count(x) <= lobes.count(x) for x in sub) and (
            best is None or len(sub) > len(best.name.split("+"))
        ):
            best = r
    if best is not None:
        keys = tmpl.param_specs()
        warm = {k: v for k, v in best.model.params().items() if k in keys and k not in fixed}
        # the added lobes start faint (the nested family's optimum, nearly)
        for k in keys:
            if k not in warm and k not in fixed and k.rpartition(".")[2] in _LOBE_SCALES:
                warm[k] = _FAINT
        tmpl = tmpl.replace(**warm)
    return tmpl, fixed


def _choose(results: list[FitResult], cv: dict[str, float]) -> tuple[str, str]:
    """The family with the fewest parameters within :data:`SIMPLER_WITHIN` of the best held-out
    error, and the reason."""
    best = min(results, key=lambda r: cv[r.name])
    if not np.isfinite(cv[best.name]):
        raise FitError("no family gave a finite model on the held-out cells")
    limit = cv[best.name] * (1.0 + SIMPLER_WITHIN)
    near = [r for r in results if cv[r.name] <= limit]
    choice = min(near, key=lambda r: (r.n_params, cv[r.name]))
    if choice is best:
        rest = sorted((cv[r.name], r.name) for r in results if r is not best)
        nxt = f" (next: {rest[0][1]}, {rest[0][0] / cv[best.name] - 1:+.1%})" if rest else ""
        reason = f"{best.name} has the lowest error on the held-out cells{nxt}"
    else:
        reason = (
            f"{choice.name} is within {SIMPLER_WITHIN:.0%} of {best.name} on the held-out cells "
            f"({cv[choice.name] / cv[best.name] - 1:+.1%}) with {choice.n_params} instead of "
            f"{best.n_params} parameters"
        )
    return choice.name, reason


def fit_models(
    data: FitData,
    models: Sequence[str] | None,
    fit_opts: dict[str, Any],
    score: Callable[[list[FitResult]], None] | None = None,
) -> tuple[list[FitResult], Comparison, FitData]:
    """What ``gonio fit`` runs on one material: the ``models`` given (compared by
    :func:`~gonio.fit.compare.summarize`), or with ``models=None`` the default choice
    (:func:`select`), whose held-out errors go into the table (``metrics["cv_loss"]``) and
    whose choice is the recommendation. ``fit_opts``: :class:`~gonio.fit.api.FitOptions`
    fields. Given models are joined by their nested families
    (:func:`~gonio.fit.compare.with_nested`: Lambert alone beside a Lambert + lobe whose lobe ran
    to its bound). ``score``, when given, is called with the results before they are compared
    (``gonio fit --score`` sets their appearance).

    Returns the results, the comparison and the cells to plot them on: the data, or for the
    default choice at most :data:`PLOT_CELLS` of them (stratified along theta_h), as many as
    the fits were made on and held out, which keeps the plots of a MERL table cheap (the
    command line plots the recommended family only)."""
    if models is not None:

        def one(m: str) -> list[FitResult]:
            r = fit(data, model=m, **fit_opts)
            return r if isinstance(r, list) else [r]

        res = fit(data, model=list(models), **fit_opts)
        results = with_nested(res if isinstance(res, list) else [res], one)
        if score is not None:
            score(results)
        return results, summarize(results), data
    sel = select(data, options=FitOptions(**fit_opts))
    for r in sel.results:  # the held-out error ranks them and is shown as the table's "cv"
        if r.name in sel.cv_errors:
            r.metrics["cv_loss"] = sel.cv_errors[r.name]
    if score is not None:
        score(sel.results)
    comp = summarize(sel.results)
    comp.recommended = sel.chosen
    comp.reason = (
        f"{sel.reason} ({sel.loss} loss; fitted on {sel.n_train} cells, {sel.n_test} held out)"
    )
    return sel.results, comp, data.stratified_subset(PLOT_CELLS, fit_opts.get("seed", 0))
