"""``gonio demo``: the whole pipeline on the simulated rig, from servo motion to a report.

Stages, each with its own progress display:

1. **Rig.** Write ``rig.toml``: the shipped ``sim`` rig (Dynamixel bus emulator on a
   pseudo-terminal, virtual RAW camera, LED light) whose ``[sim.sample]`` is the demo material.
2. **Acquire.** Run the demo plan through the run engine (journal, HDR brackets as DNG, ChArUco
   pose, white-reference calibration) into ``run/``; ``run/table.brdf.h5`` holds the samples.
3. **Fit.** Fit Lambert, Oren-Nayar, Lambert + Ward and Lambert + Torrance-Sparrow by weighted
   least squares with Laplace (or MCMC) intervals; ``fits/<model>.json`` and plots.
4. **Render.** Render the measured material (the ground-truth table, or the built-in model) and
   every fit as spheres in the studio environment; EXR + PNG per sphere and ``compare.png``.
5. **Report.** ``index.html`` (see :mod:`gonio.demo.report`), ``view.html`` (the run and every
   fit as one interactive ``gonio view`` page, linked from the report) and
   ``demo-summary.json``.

Images of the acquisition (raw brackets and merged HDR frames, about 4 MB per configuration) are
pruned to the first :data:`KEPT_FRAMES` configurations unless ``keep_images`` is set: the table
built from all of them is what the rest of the pipeline uses.
"""

from __future__ import annotations

import re
import shutil
import time
from dataclasses import asdict, dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from gonio.demo.materials import DemoMaterial
from gonio.errors import ParameterError

#: Fit presets of the demo, with the label shown for each.
MODELS: tuple[tuple[str, str], ...] = (
    ("lambert", "Lambert"),
    ("oren-nayar", "Oren-Nayar"),
    ("lambert+ward", "Lambert + Ward"),
    ("lambert+ts", "Lambert + Torrance-Sparrow"),
)

#: Configurations whose raw and HDR images are kept when pruning.
KEPT_FRAMES = 3

#: Marker file that identifies a demo output folder (and lets ``--force`` replace it safely).
SUMMARY = "demo-summary.json"


@dataclass(frozen=True)
class DemoSettings:
    """Sizes of a demo run.

    ``plan`` is a built-in plan name (``gonio plan --plan NAME`` shows it); ``resolution`` and
    ``spp`` are the sphere renders' size (pixels) and samples per pixel.
    """

    plan: str = "demo"
    resolution: int = 256
    spp: int = 64
    uncertainty: str = "laplace"
    keep_images: bool = False
    seed: int = 0

    @classmethod
    def quick(cls, **kw: Any) -> DemoSettings:
        """A reduced demo: fewer configurations, small renders (its wall time per stage:
        ``benchmarks/bench_demo.py``)."""
        return cls(**{"plan": "demo-quick", "resolution": 96, "spp": 16, **kw})


@dataclass
class ModelSummary:
    """One fitted model's numbers as the summary table and the report show them."""

    preset: str
    label: str
    params: dict[str, Any]
    intervals: dict[str, Any]
    reduced_chi2: float
    aic: float
    bic: float
    fit_s: float
    warnings: list[str]
    rmse: float | None = None
    rel_mse: float | None = None
    ssim: float | None = None
    #: the appearance score (:mod:`gonio.appearance`) against the reference: HDR-FLIP and
    #: relative L1, means over its four sphere images
    hdr_flip: float | None = None
    rel_l1: float | None = None
    truth_check: TruthCheck | None = None
    files: dict[str, Any] = field(default_factory=dict)


@dataclass
class DemoSummary:
    """Everything a demo run produced (written as ``demo-summary.json``)."""

    out: str
    material: dict[str, Any]
    settings: dict[str, Any]
    acquisition: dict[str, Any]
    models: list[ModelSummary]
    render: dict[str, Any]
    timings_s: dict[str, float]
    files: dict[str, Any]

    def to_json(self) -> dict[str, Any]:
        from gonio.io.fit_result import to_jsonable

        d = asdict(self)
        for m, md in zip(self.models, d["models"], strict=True):
            md["truth_check"] = None if m.truth_check is None else m.truth_check.to_json()
        return to_jsonable(d)


# -- stage 1: the rig file --------------------------------------------------------------------
def rig_text(material: DemoMaterial) -> str:
    """The shipped ``sim`` rig file with ``[sim.sample]`` set to the demo material."""
    import tomli_w

    text = resources.files("gonio.rigs").joinpath("sim.toml").read_text(encoding="utf-8")
    # The sample table is the last key group before [sim.faults]; replace it (header, its keys
    # and the comment above it) by the material, written as TOML by a TOML writer.
    pattern = re.compile(r"(?:#[^\n]*\n)*\[sim\.sample\]\n(?:[^\[\n][^\n]*\n|\n)*")
    sample = tomli_w.dumps({"sim": {"sample": material.sample}})
    new, n = pattern.subn(f"# demo material: {material.description}\n{sample}\n", text)
    if n != 1:  # the shipped file changed shape: fail loudly rather than run the wrong sample
        raise RuntimeError("the shipped sim rig file has no single [sim.sample] table")
    header = (
        "# Written by 'gonio demo': the shipped 'sim' rig measuring the demo material.\n"
        "# Rerun the acquisition alone with: gonio acquire --rig rig.toml --plan PLAN --out RUN\n"
    )
    return header + new


def check_out(out: Path, force: bool) -> None:
    """Refuse an output folder that the demo may not use (a file, or a non-empty folder that is
    not an earlier demo's, or one that is without ``force``); touches nothing."""
    if out.exists() and not out.is_dir():
        raise ParameterError(f"{out} exists and is not a folder")
    if out.is_dir() and any(out.iterdir()):
        if not force:
            raise ParameterError(f"{out} is not empty (use --force to replace an earlier demo)")
        if not (out / SUMMARY).is_file() and not (out / "run" / "journal.sqlite").is_file():
            raise ParameterError(
                f"{out} is not empty and holds no earlier demo; refusing to delete it"
            )


def prepare_out(out: Path, force: bool) -> None:
    """Create the output folder; refuse a non-empty one unless it is an earlier demo's."""
    check_out(out, force)
    if out.is_dir() and any(out.iterdir()):
        shutil.rmtree(out)
    out.mkdir(parents=True, exist_ok=True)


# -- stage 2: acquisition -----------------------------------------------------------------------
def prune_images(run_dir: Path, keep: int = KEPT_FRAMES) -> dict[str, int]:
    """Delete raw brackets and HDR frames beyond the first ``keep`` configurations."""
    removed = kept = 0
    freed = 0

    def config_of(p: Path) -> str:  # c00012_t0.01.dng, c00012.exr -> c00012
        return p.name.split("_")[0].split(".")[0]

    for sub in ("raw", "hdr"):
        folder = run_dir / sub
        if not folder.is_dir():
            continue
        keep_set = set(sorted({config_of(p) for p in folder.iterdir()})[:keep])
        for p in folder.iterdir():
            if config_of(p) in keep_set:
                kept += 1
            else:
                freed += p.stat().st_size
                p.unlink()
                removed += 1
    return {"removed": removed, "kept": kept, "freed_bytes": freed}


def camera_view_png(run_dir: Path, path: Path) -> Path | None:
    """Tone-map the first merged HDR frame (what the camera saw) to a PNG, if there is one."""
    from gonio.render.output import read_exr, write_png

    frames = sorted((run_dir / "hdr").glob("*.exr")) if (run_dir / "hdr").is_dir() else []
    if not frames:
        return None
    return write_png(path, read_exr(frames[0]))


# -- stage 3: fits ------------------------------------------------------------------------------
@dataclass
class TruthCheck:
    """How far a fit's parameters lie from the simulated sample's ground truth.

    Attributes
    ----------
    z : per parameter key, the largest ``|fit - truth| / std`` over its channels (std from
        the fit's uncertainty).
    n_scalars : number of scalars compared (channels counted separately).
    z_crit : the two-sided critical ``|z|`` at a family-wise level of 1 % over ``n_scalars``
        (Sidak): checking each scalar at 95 % would report a miss in about every third run
        of seven scalars by chance alone.
    """

    z: dict[str, float]
    n_scalars: int
    z_crit: float

    @property
    def max_z(self) -> float:
        """The largest ``|fit - truth| / std`` over every compared scalar."""
        return max(self.z.values(), default=0.0)

    @property
    def consistent(self) -> bool:
        """Every scalar within ``z_crit``: the truth is consistent with the fit."""
        return self.max_z < self.z_crit

    def to_json(self) -> dict[str, Any]:
        return {
            "max_abs_z": self.z,
            "n_scalars": self.n_scalars,
            "z_crit": self.z_crit,
            "level": "family-wise 1 % (Sidak)",
            "consistent": self.consistent,
        }


def truth_check(result: Any, truth: dict[str, Any], level: float = 0.01) -> TruthCheck | None:
    """Compare the fitted parameters with the ground truth (free parameters only); None when
    the fit has no uncertainty or no parameter of the truth is free in it."""
    from scipy import stats

    std = result.standard_deviations()
    free = {k: v for k, v in truth.items() if k in std and k not in result.fixed}
    if not free:
        return None
    z: dict[str, float] = {}
    n = 0
    for key, value in free.items():
        fit = np.asarray(result.params[key], dtype=float)
        sd = np.asarray(std[key], dtype=float)
        d = np.abs(fit - np.broadcast_to(np.asarray(value, dtype=float), fit.shape))
        z[key] = float(np.max(np.where(sd > 0, d / np.where(sd > 0, sd, 1.0), np.inf)))
        n += int(np.size(fit))
    z_crit = float(stats.norm.ppf(1 - (1 - (1 - level) ** (1 / n)) / 2))
    return TruthCheck(z, n, z_crit)


# -- the whole run ------------------------------------------------------------------------------
def run_demo(
    out: str | Path,
    material: DemoMaterial,
    settings: DemoSettings | None = None,
    *,
    force: bool = False,
    progress: bool = True,
    console: Any = None,
) -> DemoSummary:
    """Run every stage (see the module docstring) into ``out``; returns the summary.

    Parameters
    ----------
    out : output folder (created; must be empty, or an earlier demo's when ``force``).
    material : the simulated sample (:func:`gonio.demo.materials.find_material`).
    settings : sizes of the run (default :class:`DemoSettings`).
    force : replace an earlier demo's folder.
    progress : show progress bars (rich) on the console.
    console : a ``rich.console.Console`` for the stage headers (default: stderr).
    """
    from rich.console import Console

    settings = settings or DemoSettings()
    console = console or Console(stderr=True, quiet=not progress)
    out = Path(out)
    prepare_out(out, force)
    timings: dict[str, float] = {}
    t0 = time.monotonic()

    console.rule(f"[bold]1/5 rig[/]: simulated 4-axis rig measuring {material.name}")
    rig_path = out / "rig.toml"
    rig_path.write_text(rig_text(material), encoding="utf-8")
    console.print(f"material: {material.description}")

    console.rule(f"[bold]2/5 acquire[/]: plan '{settings.plan}' on the simulated rig")
    acquisition = _acquire(out, rig_path, settings, progress, console)
    timings["acquire"] = time.monotonic() - t0

    console.rule("[bold]3/5 fit[/]: " + ", ".join(label for _, label in MODELS))
    t = time.monotonic()
    results, models_summary = _fit_all(out, material, settings, progress)
    timings["fit"] = time.monotonic() - t

    from gonio.export import registry

    titles = registry.listing([m.TITLE for m in registry.targets().values()], "and")
    console.rule(f"[bold]export[/]: every fit for {titles}")
    t = time.monotonic()
    from gonio.demo.exports import export_fits

    export_fits(out, models_summary)
    timings["export"] = time.monotonic() - t

    console.rule(f"[bold]4/5 render[/]: {settings.resolution}^2 px, {settings.spp} spp, studio")
    t = time.monotonic()
    render = _render_all(out, material, results, models_summary, settings, progress)
    timings["render"] = time.monotonic() - t

    console.rule("[bold]5/5 report[/]: index.html, and view.html (gonio view of the run and fits)")
    t = time.monotonic()
    view = _view_page(out, models_summary)
    timings["view"] = time.monotonic() - t
    files = {
        "rig": "rig.toml",
        "table": "run/table.brdf.h5",
        "compare": render.pop("compare"),
        "camera_view": acquisition.pop("camera_view", None),
        "report": "index.html",
        "view": view,
        "summary": SUMMARY,
    }
    summary = DemoSummary(
        out=str(out),
        material={
            "name": material.name,
            "description": material.description,
            "table": None if material.table_path is None else str(material.table_path),
            "truth_params": material.truth_params,
        },
        settings=asdict(settings),
        acquisition=acquisition,
        models=models_summary,
        render=render,
        timings_s=timings,
        files=files,
    )
    from gonio.demo.report import write_report
    from gonio.io.strict_json import write_json

    # writing the report takes milliseconds: the total is taken just before it
    timings["total"] = time.monotonic() - t0
    write_report(out / "index.html", summary)
    write_json(summary.to_json(), out / SUMMARY)
    return summary


def _view_page(out: Path, summaries: list[ModelSummary]) -> str:
    """``view.html`` beside the report: the run and every fit as one ``gonio view`` page (one
    self-contained file); returns its path relative to ``out``."""
    from gonio.view import build

    fits = [out / s.files["fit"] for s in summaries]
    build(out / "run", *fits).save(out / "view.html")
    return "view.html"


def _acquire(
    out: Path, rig_path: Path, settings: DemoSettings, progress: bool, console: Any
) -> dict[str, Any]:
    from gonio.acquire.engine import acquire

    run_dir = out / "run"
    s = acquire(run_dir, rig_path, settings.plan, progress=progress)
    if not s.complete or s.table is None:
        raise ParameterError(f"the demo acquisition did not complete: {s.table_note}")
    view = camera_view_png(run_dir, out / "camera-view.png")
    pruned = (
        {"removed": 0, "kept": 0, "freed_bytes": 0}
        if settings.keep_images
        else prune_images(run_dir)
    )
    console.print(
        f"{s.done} configurations measured ({s.refused} refused by the safety checks"
        f"{f', {s.rejected} rejected as unmeasurable' if s.rejected else ''}) in"
        f" {s.wall_s:.0f} s; {s.table_note}"
    )
    return {
        "planned": s.planned,
        "refused": s.refused,
        "rejected": s.rejected,
        "measured": s.done,
        "wall_s": s.wall_s,
        "table_note": s.table_note,
        "bus": s.bus,
        "images_pruned": pruned,
        "camera_view": None if view is None else view.name,
    }


def _fit_all(
    out: Path, material: DemoMaterial, settings: DemoSettings, progress: bool
) -> tuple[list[Any], list[ModelSummary]]:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from gonio.fit import fit
    from gonio.fit.data import prepare
    from gonio.fit.plots import plot_result

    # prepared from the path, so that each fit records its measurement (gonio export refits
    # a renderer's family to it)
    data = prepare((out / "run" / "table.brdf.h5").resolve(), name=material.name)
    fits_dir = out / "fits"
    fits_dir.mkdir(exist_ok=True)
    results, summaries = [], []
    columns = (
        TextColumn("{task.description:<48}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
    )
    with Progress(*columns, disable=not progress, transient=False) as bar:
        task = bar.add_task("fitting", total=len(MODELS))
        for preset, label in MODELS:
            stem = preset.replace("+", "-")

            def stage(text: str, label: str = label) -> None:
                bar.update(task, description=f"{label}: {text}")

            t = time.monotonic()
            r = fit(
                data,
                model=preset,
                uncertainty=settings.uncertainty,
                seed=settings.seed,
                name=material.name,
                progress=stage,
            )
            fit_s = time.monotonic() - t
            stage("plots")
            r.save(fits_dir / f"{stem}.json")
            # the corner plot marks the truth where the sample's model is this preset
            plots = plot_result(r, data, fits_dir, stem, truth=material.truth_params.get(preset))
            shown = {k: v for k, v in r.params.items() if k not in r.fixed}
            summaries.append(
                ModelSummary(
                    preset=preset,
                    label=label,
                    params=shown,
                    intervals={k: v for k, v in r.intervals(95).items() if k in shown},
                    reduced_chi2=float(r.reduced_chi2),
                    aic=float(r.aic),
                    bic=float(r.bic),
                    fit_s=fit_s,
                    warnings=list(r.warnings),
                    truth_check=truth_check(r, material.truth_params.get(preset, {})),
                    files={
                        "fit": f"fits/{stem}.json",
                        "plots": [f"fits/{p.name}" for p in plots],
                    },
                )
            )
            results.append(r)
            bar.update(task, advance=1, description=f"{label}: done in {fit_s:.1f} s")
    return results, summaries


def _render_all(
    out: Path,
    material: DemoMaterial,
    results: list[Any],
    summaries: list[ModelSummary],
    settings: DemoSettings,
    progress: bool,
) -> dict[str, Any]:
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    from gonio import appearance
    from gonio.render.compare import compare_images, comparison_figure
    from gonio.render.integrator import render_sphere
    from gonio.render.lights import Environment
    from gonio.render.output import write_exr, write_png
    from gonio.rigs.sim.truth import load_truth

    truth = load_truth(material.sample, "demo")
    measured = getattr(truth, "table", truth)
    ref_label = "measured" if material.is_measured else "ground truth"
    items = [("measured", ref_label, measured)]
    for s, r in zip(summaries, results, strict=True):
        items.append((s.preset.replace("+", "-"), s.label, r.model))
    lights = [Environment("studio")]
    renders_dir = out / "renders"
    renders_dir.mkdir(exist_ok=True)
    images: dict[str, np.ndarray] = {}
    seconds: dict[str, float] = {}
    columns = (TextColumn("{task.description:<40}"), BarColumn(), TimeRemainingColumn())
    with Progress(*columns, disable=not progress) as bar:
        for stem, label, mat in items:
            task = bar.add_task(f"sphere: {label}", total=1)

            def tick(done: int, total: int, task: Any = task) -> None:
                bar.update(task, total=total, completed=done)

            t = time.monotonic()
            images[stem] = render_sphere(
                mat,
                lights=lights,
                resolution=settings.resolution,
                spp=settings.spp,
                seed=settings.seed,
                progress=tick,
            )
            seconds[stem] = time.monotonic() - t
    reference = images["measured"]
    exposure, comps = compare_images(
        reference, [(label, images[stem]) for stem, label, _ in items[1:]]
    )
    files: dict[str, Any] = {}
    for stem, _, _ in items:
        write_exr(renders_dir / f"{stem}.exr", images[stem])
        write_png(renders_dir / f"{stem}.png", images[stem], exposure)
        files[stem] = {"exr": f"renders/{stem}.exr", "png": f"renders/{stem}.png"}
    # the appearance score, as gonio fit --score gives it, against the same reference
    ref = appearance.Reference.of(measured)
    for s, c, r in zip(summaries, comps, results, strict=True):
        s.rmse, s.rel_mse, s.ssim = c.errors.rmse, c.errors.rel_mse, c.errors.ssim
        s.files["render"] = files[s.preset.replace("+", "-")]
        score = appearance.score(ref, r.model)
        s.hdr_flip, s.rel_l1 = score["hdr_flip"], score["rel_l1"]
    comparison_figure(
        out / "compare.png",
        reference,
        comps,
        exposure,
        title=f"{material.name}: fits against the {ref_label}",
        reference_label=ref_label,
    )
    return {
        "reference": ref_label,
        "resolution": settings.resolution,
        "spp": settings.spp,
        "lights": "studio environment",
        "exposure": exposure,
        "seconds": seconds,
        "images": files,
        "compare": "compare.png",
    }
