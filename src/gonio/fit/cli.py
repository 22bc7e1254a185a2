"""``gonio fit``: fit analytic models to measured BRDF files (one file, or a batch)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from gonio.errors import FitError, ParameterError
from gonio.io.strict_json import dumps_json

#: Names of :data:`gonio.fit.losses.LOSSES` (written out so that building the parser does not
#: import JAX; a test checks that the two agree).
LOSS_NAMES = ("cube-root", "low-e1", "low-e2", "ngan", "sqrt-cos", "wls")


def register(subparsers: Any) -> None:
    """Add the ``fit`` subcommand."""
    p = subparsers.add_parser(
        "fit",
        help="fit analytic BRDF models (with uncertainty) to measured files",
        description=(
            "Fit one or more analytic BRDF models to a measured BRDF (native .brdf.h5, MERL "
            ".binary, RGL .bsdf, Cornell .brdf, ALTA). One JSON per model, plots and a "
            "comparison are written to --out. Several files, a folder or a glob pattern run "
            "as a resumable batch: OUT/<material>/ per file, skipped when already done. Data "
            "with a measured sigma (gonio's own runs) get chi2/dof and BIC; data without (MERL, "
            "RGL, Cornell, ALTA, NBRDF) are ranked by the measured loss, with no chi-square."
        ),
    )
    p.add_argument(
        "inputs",
        nargs="*",
        metavar="FILE_DIR_OR_GLOB",
        help="measurement file(s), folder(s) of files, or quoted glob patterns",
    )
    p.add_argument(
        "--model",
        "-m",
        action="append",
        dest="models",
        metavar="NAME",
        help="model to fit (repeatable): a lobe name or lobes joined by '+', e.g. "
        "lambert+ward; 'gonio fit --list-models' lists them. Default: fit lambert, "
        "lambert+gtr, lambert+gtr+gtr and lambert+retro+gtr (gtr: microfacet lobe with a "
        "long, fitted tail; retro: lobe about the light direction) on 8192 cells stratified "
        "along theta_h (all but a held-out fifth of smaller data) with the sqrt-cos loss (wls "
        "with sigma), and recommend the one with the lowest loss on 8192 held-out cells, or "
        "one with fewer parameters within 1%%: real highlights have long tails that Ward and "
        "Beckmann lobes turn into a bright diffuse floor, and held-out cells, not a BIC that "
        "assumes a sigma nobody measured, say whether a lobe is worth its parameters",
    )
    p.add_argument(
        "--list-models", action="store_true", help="print the valid model names and exit"
    )
    p.add_argument(
        "--loss",
        default="auto",
        choices=["auto", *LOSS_NAMES],
        help="metric to minimize. Default auto: wls (chi-square) when the data has sigma; "
        "without sigma sqrt-cos for the default fit (errors weighted by the brightness f "
        "cos_i a lit sphere shows), and with --model (published tables: MERL, RGL, Cornell, "
        "ALTA) low-e1, Low et al.'s log "
        "metric ln(1 + f cos_i), because their errors are closer to relative than absolute and "
        "an unweighted fit lets the specular peak decide everything (diffuse albedos end on "
        "their bounds). Others: ngan (cosine-weighted L2), low-e2 (log metric without the "
        "cosine), sqrt-cos, cube-root",
    )
    p.add_argument(
        "--score",
        nargs="*",
        metavar="MODEL_FILE",
        help="print Ngan's cosine-weighted L2 and Low's log metric E2 on the data's own cells "
        "(theta <= --theta-max, exact cell solid angles) and the appearance score: the "
        "measured and the model's spheres (96 px, light at 0, 30 and 60 deg from the view, and "
        "a generated studio environment) compared by HDR-FLIP and relative L1 "
        "(docs/guide/fitting.md). Without files: of the fitted models (also in the table and "
        "the JSON; with several inputs, in OUT/fits.csv and the table across materials). "
        "With files, score those instead of fitting: fit results (.json) or published "
        "fits (any .fit file of Ngan et al., Low et al. or Bagher et al., for the input's "
        "material; or FILE.fit::MATERIAL); with several files, one without the material is "
        "skipped with a note",
    )
    p.add_argument(
        "--uncertainty",
        default="none",
        choices=("none", "laplace", "mcmc"),
        help="parameter intervals: Laplace (Gauss-Newton at the optimum) or MCMC (emcee; "
        "the likelihood is the fitted loss, so the optimum lies inside its intervals; walkers "
        "start over the prior box); default none. Intervals spanning the search box are "
        "reported as unconstrained",
    )
    p.add_argument(
        "--theta-max",
        type=float,
        default=80.0,
        metavar="DEG",
        help="discard samples with incident or outgoing polar angle above DEG degrees (default 80)",
    )
    p.add_argument(
        "--channels",
        default="shared",
        choices=("shared", "separate"),
        help="shared lobe shapes with per-channel albedos (default), or each "
        "channel fitted on its own",
    )
    p.add_argument(
        "--optimizer",
        default="lm",
        choices=("lm", "lbfgs", "slsqp"),
        help="local method: Levenberg-Marquardt on the JAX Jacobian (default) or "
        "nlopt L-BFGS / SLSQP with JAX gradients",
    )
    p.add_argument(
        "--global",
        dest="global_method",
        default="none",
        choices=("none", "crs2", "mlsl", "direct"),
        help="nlopt global search on a subsample before the local stage (default none; "
        "multi-start is always on)",
    )
    p.add_argument(
        "--starts", type=int, default=8, metavar="N", help="multi-start points (default 8)"
    )
    p.add_argument("--seed", type=int, default=0, help="seed of subsamples and starts (default 0)")
    p.add_argument(
        "--refine",
        type=int,
        default=65536,
        metavar="N",
        help="on data of more than 2N samples, refine the best start on a stratified subset "
        "of N samples before the polish on every sample, whose steps then use the subset's "
        "curvature (default 65536; 0: every polish step on every sample, the slower path)",
    )
    p.add_argument(
        "--fix",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="hold a parameter fixed, e.g. --fix ward.rho_d=0 (repeatable)",
    )
    p.add_argument(
        "--mcmc-steps",
        type=int,
        default=2000,
        metavar="N",
        help="MCMC steps per walker (default 2000)",
    )
    p.add_argument(
        "--out",
        "-o",
        default="fit-results",
        metavar="DIR",
        help="output folder (default ./fit-results). It holds one run: a rerun replaces the "
        "previous run as a whole (and says so); an interrupted one leaves it intact. A batch "
        "keeps one run per material in DIR/<material>/ and writes DIR/fits.csv",
    )
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument(
        "--jobs",
        "-j",
        type=int,
        default=2,
        metavar="N",
        help="worker processes for a batch (default 2; 1 = in this process)",
    )
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run a batch on a Dask cluster, e.g. tcp://10.0.0.5:8786",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help="print a machine-readable summary on stdout instead of tables",
    )
    from gonio import compile_cache

    compile_cache.add_argument(p)
    p.set_defaults(func=run)


def _default_models() -> list[str]:
    from gonio.fit.selection import DEFAULT_FAMILIES

    return list(DEFAULT_FAMILIES)


def _parse_fix(items: list[str]) -> dict[str, float]:
    out = {}
    for item in items:
        key, eq, val = item.partition("=")
        try:
            if not eq:
                raise ValueError
            out[key.strip()] = float(val)
        except ValueError:
            raise FitError(f"--fix expects KEY=NUMBER, got {item!r}") from None
    return out


def run(args: argparse.Namespace) -> int:
    """Entry point of ``gonio fit``."""
    from gonio.fit.presets import available, build

    if args.list_models:
        print("\n".join(available()))
        return 0
    if not args.inputs:
        raise ParameterError("give at least one measurement file, folder or glob pattern")
    if Path(args.out).exists() and not Path(args.out).is_dir():
        raise ParameterError(f"--out {args.out}: exists and is not a folder")
    models = args.models or _default_models()
    for m in models:
        build(m)  # unknown names fail here, before any work
    if args.theta_max <= 0 or args.theta_max > 90:
        raise FitError(f"--theta-max must be in (0, 90] degrees, got {args.theta_max:g}")
    if args.starts < 1 or args.mcmc_steps < 10 or args.jobs < 1 or args.refine < 0:
        raise FitError("--starts and --jobs must be >= 1, --mcmc-steps >= 10 and --refine >= 0")
    if args.seed < 0:
        raise FitError(f"--seed must be >= 0, got {args.seed}")
    from gonio.fit.batch import expand_inputs

    paths = expand_inputs(args.inputs)
    if args.score:
        return _run_score(paths, args)
    fit_opts: dict[str, Any] = {
        "loss": args.loss,
        "uncertainty": None if args.uncertainty == "none" else args.uncertainty,
        "theta_max_deg": args.theta_max,
        "channels": args.channels,
        "optimizer": args.optimizer,
        "global_method": None if args.global_method == "none" else args.global_method,
        "n_starts": args.starts,
        "seed": args.seed,
        "mcmc_steps": args.mcmc_steps,
        "fixed": _parse_fix(args.fix) or None,
    }
    if args.refine != 65536:  # recorded only when set, so earlier batch folders stay done
        fit_opts["refine"] = args.refine
    # no --model: the default choice among the default families on held-out cells
    select = not args.models and args.channels == "shared"
    options = {"models": models, "fit": fit_opts, "plots": not args.no_plots,
               "score": args.score is not None, "select": select}  # fmt: skip
    out = Path(args.out)
    single = len(paths) == 1 and not Path(args.inputs[0]).is_dir() and len(args.inputs) == 1
    if single:
        from gonio.fit.run_folder import check_target

        check_target(out)
        return _run_single(paths[0], out, options, args.json)
    return _run_batch(paths, out, options, args)


def _run_single(path: Path, out: Path, options: dict[str, Any], as_json: bool) -> int:
    from rich.console import Console
    from rich.markup import escape
    from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    from gonio.fit import run_folder
    from gonio.fit.batch import safe_stem
    from gonio.fit.data import prepare
    from gonio.fit.selection import fit_models
    from gonio.io.strict_json import write_json

    console = Console(stderr=True)
    opts = dict(options["fit"])
    results = []
    clock = {"start": time.perf_counter()}
    with Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        TimeElapsedColumn(),
        console=console,
        transient=True,
        disable=as_json,
    ) as bar:
        task = bar.add_task(f"reading {path.name}")
        data = prepare(path, opts["theta_max_deg"])
        clock["read"] = time.perf_counter()
        if data.source.get("sigma_ignored") and not as_json:
            console.print(f"{path.name}: {data.source['sigma_ignored']}")
        if opts.get("loss") == "auto" and data.sigma is None and not as_json:
            from gonio.fit.api import AUTO_LOSS_WITHOUT_SIGMA
            from gonio.fit.selection import DEFAULT_LOSS

            loss = DEFAULT_LOSS if options.get("select") else AUTO_LOSS_WITHOUT_SIGMA
            console.print(
                f"{path.name} has no sigma: fitting with {loss} (see --help of --loss), not an "
                "unweighted chi-square"
            )
        say = {"progress": lambda s: bar.update(task, description=s)}
        chosen = None if options.get("select") else options["models"]

        def score(fits: list[Any]) -> None:
            bar.update(task, description="appearance score")
            _score_appearance(path, fits, console, as_json)

        results, comp, shown = fit_models(
            data, chosen, {**opts, **say}, score if options.get("score") else None
        )
        clock["fit"] = time.perf_counter()
        plotting = 0.0
        # One run per folder: written into a hidden sibling, then swapped in as a whole
        # (gonio.fit.run_folder), so a rerun leaves nothing stale and an interrupted one leaves
        # the previous run as it was.
        skipped: list[str] = []
        log: list[str] = []
        with run_folder.staging(out) as staging:
            files = []
            for r in results:
                stem = safe_stem(r.name if r.channel is None else f"{r.name}.{r.channel}")
                bar.update(task, description=f"writing {stem}")
                files.append(str(out / r.save(staging / f"{stem}.json").name))
                # the default choice plots its recommended family only
                if options["plots"] and (r.name == comp.recommended or not options.get("select")):
                    from gonio.fit.plots import plot_result

                    t0 = time.perf_counter()
                    drawn = plot_result(r, shown, staging, stem, skipped=skipped, log=log)
                    plotting += time.perf_counter() - t0
                    files += [str(out / p.name) for p in drawn]
            done = time.perf_counter()
            summary = {
                "material": data.source.get("name"),
                "path": str(path),
                "files": files,
                **comp.to_json(),
                # wall seconds of this command's stages (the fits' own are in their JSON)
                "timings_s": {
                    "read": clock["read"] - clock["start"],
                    "fit": clock["fit"] - clock["read"],
                    "plots": plotting,
                    "write": done - clock["fit"] - plotting,
                },
            }
            write_json(summary, staging / "summary.json")
            replaced = run_folder.publish(staging, out, log)
    notes = ([replaced] if replaced else []) + skipped
    if log:
        notes.append(f"{len(log)} plotting library message(s) written to {out / run_folder.LOG}")
    if as_json:
        sys.stdout.write(dumps_json(summary, indent=2))
        sys.stdout.write("\n")
    else:
        for line in notes:
            console.print(escape(line), highlight=False, soft_wrap=True)
        out_console = Console()
        _print_table(out_console, summary, data.source.get("name") or path.name, results)
        if options.get("score"):
            for r in results:
                _print_score(out_console, r.name, r.metrics, data, r.appearance)
            line = appearance_beside_next(results, summary["recommended"])
            if line:
                out_console.print(line, highlight=False, markup=False, soft_wrap=True)
    return 0


def appearance_beside_next(results: list[Any], recommended: str | None) -> str:
    """One line: the recommended fit's appearance score beside that of the best other family
    by HDR-FLIP (e.g. a retro-reflective tape's ``lambert+retro+gtr`` beside the best family
    without the retro lobe); empty when fewer than two fits carry a score."""
    scored = [r for r in results if r.channel is None and r.appearance]
    chosen = next((r for r in scored if r.name == recommended), None)
    others = sorted((r for r in scored if r.name != recommended),
                    key=lambda r: r.appearance["hdr_flip"])  # fmt: skip
    if chosen is None or not others:
        return ""
    a, b = chosen.appearance, others[0].appearance
    return (
        f"appearance: recommended {chosen.name} HDR-FLIP {a['hdr_flip']:.3f}, rel. L1 "
        f"{a['rel_l1']:.3f}; best other family by HDR-FLIP {others[0].name} HDR-FLIP "
        f"{b['hdr_flip']:.3f}, rel. L1 {b['rel_l1']:.3f}"
    )


def _score_appearance(path: Path, results: list[Any], console: Any, quiet: bool) -> None:
    """Set each result's appearance score (per-channel fits have none: the score compares
    whole-colour images)."""
    from gonio.fit.score import score_results

    why = score_results(path, results)
    if why is not None and not quiet:
        console.print(f"appearance score skipped: {why}", highlight=False, markup=False)


def _print_score(
    console: Any,
    label: str,
    metrics: dict[str, float],
    data: Any,
    appearance: dict[str, float] | None = None,
) -> None:
    th = data.source.get("theta_max_deg", 80.0)
    console.print(
        f"score {label}: ngan {metrics['ngan']:.5g} 1/sr, low-e2 {metrics['low-e2']:.5g} "
        f"({data.n} cells, theta <= {th:g} deg)",
        highlight=False,
        markup=False,
    )
    if appearance:
        from gonio.appearance import IMAGES

        console.print(
            f"  appearance ({appearance['resolution_px']:.0f} px spheres; light at 0, 30, 60 "
            "deg, studio):",
            highlight=False,
            markup=False,
        )
        for m, name in (("hdr_flip", "HDR-FLIP"), ("rel_l1", "rel. L1 ")):
            each = " ".join(f"{appearance[f'{m}_{i}']:.3f}" for i in IMAGES)
            console.print(
                f"    {name} {appearance[m]:.3f}  ({each})", highlight=False, markup=False
            )


def _run_score(paths: list[Path], args: argparse.Namespace) -> int:
    """``gonio fit FILE --score MODEL_FILE...``: score given models, fit nothing."""
    from rich.console import Console

    from gonio.errors import GonioError
    from gonio.fit.data import prepare
    from gonio.fit.score import appearance_reference, appearance_score, load_scored_model, score

    rows = []
    console = Console()  # COLUMNS when set, else the terminal's width, 80 when piped
    notes = Console(stderr=True)
    for path in paths:
        data = prepare(path, args.theta_max)
        ref, why = appearance_reference(path)
        if ref is None and not args.json:
            notes.print(f"appearance score skipped: {why}", highlight=False, markup=False)
        for spec in args.score:
            try:
                label, model = load_scored_model(spec, data.source.get("name"))
            except GonioError as exc:
                if len(args.score) == 1:
                    raise
                if not args.json:
                    notes.print(f"skipped {spec}: {exc}", highlight=False, markup=False)
                continue
            s = score(model, data)
            app = None if ref is None else appearance_score(ref, model)
            rows.append({"file": str(path), "model": spec, "label": label, **s, "appearance": app})
            if not args.json:
                _print_score(console, f"{label} ({Path(spec).name})", s, data, app)
    if args.json:
        sys.stdout.write(dumps_json(rows, indent=2))
        sys.stdout.write("\n")
    return 0


def _print_table(console: Any, summary: dict[str, Any], title: str, results: list[Any]) -> None:
    from rich.markup import escape

    from gonio.fit.table_text import fit_table_lines

    # plain text at the console's width (COLUMNS when set, 80 when piped): no name is cut
    console.print(escape(f"{title}: {summary['table'][0]['metric']} fit"), highlight=False)
    for line in fit_table_lines(summary["table"], console.width):
        console.print(escape(line), highlight=False, soft_wrap=True)
    for r in results:
        _print_params(console, r)
        if r.warnings:
            console.print(f"[yellow]{escape(r.name)}:[/yellow] " + escape("; ".join(r.warnings)))
    console.print(
        f"recommended: [bold]{escape(str(summary['recommended']))}[/bold]"
        f" ({escape(str(summary['reason']))})"
    )


def _print_params(console: Any, r: Any) -> None:
    """One fit's parameters with their 95 % intervals and units (a rich table)."""
    from rich import box
    from rich.table import Table

    from gonio.fit.table_text import PARAM_HEADERS, param_rows

    method = "" if r.uncertainty is None else f", 95 % intervals ({r.uncertainty.method})"
    label = r.name if r.channel is None else f"{r.name}[{r.channel}]"
    table = Table(title=f"{label}: fitted parameters{method}", box=box.SIMPLE_HEAD,
                  title_justify="left", pad_edge=False)  # fmt: skip
    rows = param_rows(r)
    for i, head in enumerate(PARAM_HEADERS):
        if i >= 2 and not any(row[i] for row in rows):
            continue  # no intervals (no --uncertainty), no bounds
        table.add_column(head, justify="right" if head == "value" else "left", overflow="fold")
    keep = [i for i in range(len(PARAM_HEADERS)) if i < 2 or any(row[i] for row in rows)]
    for row in rows:
        table.add_row(*(row[i] for i in keep))
    console.print(table)


def _run_batch(paths: list[Path], out: Path, options: dict[str, Any], args: Any) -> int:
    from rich.console import Console
    from rich.markup import escape
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    from gonio.fit.batch import batch_rows, pending, run_batch, write_batch_csv

    console = Console(stderr=True)
    separate = options["fit"].get("channels") == "separate"
    todo, done = pending(paths, out, () if separate else options["models"], options)
    if done and not args.json:
        console.print(f"{len(done)} of {len(paths)} materials already done in {out}; resuming")
    failures = []
    with Progress(
        *Progress.get_default_columns()[:1],
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
        console=console,
        disable=args.json,
    ) as bar:
        task = bar.add_task("fitting", total=len(todo))

        def on_done(s: dict[str, Any]) -> None:
            bar.advance(task)
            if s["status"] != "ok":
                failures.append(s)
                if not args.json:
                    console.print(f"[red]{s['material']}[/red]: {s['error']}")

        summaries = run_batch(
            todo, out, options, jobs=args.jobs, scheduler=args.scheduler, on_done=on_done
        )
    if args.json:
        sys.stdout.write(
            dumps_json(
                {"out": str(out), "done_before": [str(p) for p in done], "results": summaries},
                indent=2,
            )
        )
        sys.stdout.write("\n")
    else:
        for s in summaries:
            for line in s.get("skipped") or []:
                console.print(escape(f"{s['material']}: {line}"), highlight=False)
        replaced = [s["material"] for s in summaries if s.get("replaced")]
        if replaced:
            console.print(escape(f"replaced the previous runs of {len(replaced)} material(s) in "
                                 f"{out}: {', '.join(replaced)}"), highlight=False)  # fmt: skip
    rows = batch_rows(paths, out)
    if rows:
        csv_path = write_batch_csv(rows, out / "fits.csv")
        if not args.json:
            _print_batch_table(Console(), rows, csv_path)
    if not args.json:
        ok = len(summaries) - len(failures)
        console.print(f"{ok} fitted, {len(failures)} failed, {len(done)} skipped; results in {out}")
    return 1 if failures else 0


def _print_batch_table(console: Any, rows: list[dict[str, Any]], csv_path: Path) -> None:
    """The table across materials: the recommended fit of each (every model is in the CSV)."""
    from rich import box
    from rich.table import Table

    from gonio.fit.table_text import params_compact

    best = [r for r in rows if r["recommended"]]
    appearance = any("hdr_flip" in r["metrics"] for r in best)
    scores = (("hdr_flip", "HDR-FLIP"), ("rel_l1", "rel. L1")) if appearance else ()
    table = Table(title=f"recommended fit per material (every model: {csv_path})",
                  box=box.SIMPLE_HEAD, title_justify="left", pad_edge=False)  # fmt: skip
    numeric = ("loss", *(head for _, head in scores))
    for head in ("material", "family", *numeric, "parameters", "flags"):
        table.add_column(head, overflow="fold", justify="right" if head in numeric else "left")
    for r in best:
        cells = [str(r["material"]), str(r["model"]), f"{r['metric']} {r['loss']:.4g}"]
        for key, _ in scores:
            v = r["metrics"].get(key)
            cells.append("" if v is None else f"{v:.4g}")
        cells += [params_compact(r["params"]), ", ".join(r["flags"]) or "-"]
        table.add_row(*cells)
    console.print(table)
