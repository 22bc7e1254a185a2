"""Fitting many materials: one output folder per material, streamed to disk, resumable.

Layout of ``out_dir``::

    <material>/<model>.json         one fit result per model (written atomically)
    <material>/<model>-*.png        plots (unless disabled)
    <material>/summary.json         the comparison; written last, it marks the material done
    <material>/log.txt              what the plotting libraries said (when they said anything)
    batch.jsonl                     one line per finished (or failed) material, appended
    fits.csv                        one row per material and model: the table across materials

Each material folder holds one run (:mod:`gonio.fit.run_folder`): written into a hidden sibling
and swapped in whole, so a material fitted again leaves nothing of its earlier run behind.

A rerun skips every material whose ``summary.json`` exists and records the same fit options
(loss, theta_max, ...) and models, so an interrupted batch resumes where it stopped; a material
fitted earlier with other options is redone, and one asked for a new model is refitted with its
earlier models too, so that ``summary.json`` always compares every model of the folder. Work
runs in a local process pool (``spawn`` start method: JAX is multithreaded and must not be
forked) or on a Dask cluster (``scheduler="tcp://host:8786"``); each task reads its
file, fits, writes its folder and returns a small summary, so results never travel back in bulk.
"""

from __future__ import annotations

import glob
import json
import os
import traceback
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from multiprocessing import get_context
from pathlib import Path
from typing import Any

from gonio.errors import FitError, GonioError, ParameterError
from gonio.io.strict_json import dumps_json

#: File name endings considered measurement files when a folder is given.
DATA_SUFFIXES = (".h5", ".hdf5", ".binary", ".bsdf", ".brdf", ".alta", ".dat", ".csv")


def material_name(path: Path) -> str:
    """``acryl_blue`` for ``acryl_blue.brdf``, ``x`` for ``x.brdf.h5``, ``gold-paint`` for an
    archive member ``merl_nbrdf.zip::gold-paint`` (:mod:`gonio.io.nbrdf`)."""
    archive, sep, member = str(path).rpartition("::")
    if sep and archive and member:
        return member
    return path.name.split(".")[0] or path.name


def _is_data_file(q: Path) -> bool:
    return q.is_file() and not q.name.startswith(".") and q.name.lower().endswith(DATA_SUFFIXES)


def expand_inputs(inputs: Sequence[str | Path]) -> list[Path]:
    """Files named by paths, folders (their data files) and glob patterns, deduplicated.

    Raises
    ------
    FitError
        When an input matches nothing.
    """
    out: list[Path] = []
    for item in inputs:
        s = str(item)
        p = Path(s)
        if p.is_dir():
            found = sorted(
                q
                for q in p.iterdir()
                if q.is_file()
                and not q.name.startswith(".")
                and q.name.lower().endswith(DATA_SUFFIXES)
            )
        elif any(ch in s for ch in "*?["):
            found = sorted(Path(q) for q in glob.glob(s) if Path(q).is_file())
        elif p.is_file():
            found = [p]
        elif "::" in s and Path(s.rpartition("::")[0]).is_file():
            found = [p]  # ARCHIVE.zip::NAME (gonio.io.nbrdf)
        else:
            raise ParameterError(f"{s}: no such file or directory")
        if not found:
            raise FitError(f"{s}: no measurement files found")
        out.extend(found)
    seen: set[Path] = set()
    unique = []
    for p in out:
        r = p.resolve()
        if r not in seen:
            seen.add(r)
            unique.append(p)
    return unique


def safe_stem(name: str) -> str:
    """A file-name-safe version of a model name (``lambert+ts`` -> ``lambert+ts``)."""
    return "".join(ch if ch.isalnum() or ch in "+-_." else "_" for ch in name)


def fit_options_key(options: dict[str, Any]) -> Any:
    """The fit options (``options["fit"]``) as recorded in a material's ``summary.json``:
    JSON-normalized so that a rerun can tell whether a material was fitted the same way."""
    key = dict(options.get("fit", {}))
    if options.get("score"):  # a scored run is not done by an earlier unscored one
        key["score"] = True
    return json.loads(dumps_json(key, sort_keys=True, default=str))


def _summary(folder: Path) -> dict[str, Any]:
    """A material folder's ``summary.json`` as written by an earlier run ({} when it is absent
    or unreadable: the material is then fitted again)."""
    try:
        prev = json.loads((folder / "summary.json").read_text())
    except (OSError, ValueError):
        return {}
    return prev if isinstance(prev, dict) else {}


def _previous_models(folder: Path, key: Any) -> list[str]:
    """Models of an earlier run on this material with the same fit options (none otherwise)."""
    prev = _summary(folder)
    if prev.get("fit_options") != key:
        return []
    return [m for m in prev.get("models", []) if isinstance(m, str)]


def fit_material(path: str, out_dir: str, options: dict[str, Any]) -> dict[str, Any]:
    """Fit every model of ``options["models"]`` to one file and write its folder.

    Returns a small summary (``material``, ``status`` "ok"/"error", ``recommended``,
    ``error``). Runs in worker processes: imports happen here.
    """
    import gonio.brdf  # noqa: F401  (float64)
    from gonio.fit.data import prepare
    from gonio.fit.run_folder import check_target, publish, staging
    from gonio.io.strict_json import write_json

    src = Path(path)
    name = options.get("material") or material_name(src)
    folder = Path(out_dir) / name
    opts = dict(options.get("fit", {}))
    key = fit_options_key(options)
    # A rerun that adds a model refits the earlier ones too (same options), so that the
    # comparison in summary.json covers every model of the folder, not only the new one.
    models = list(options["models"])
    plain = [m for m in models if isinstance(m, str)]
    models = [m for m in _previous_models(folder, key) if m not in plain] + models
    try:
        from gonio.fit.selection import fit_models

        check_target(folder)  # never replace a folder of other files
        data = prepare(src, opts.get("theta_max_deg", 80.0), name=name)
        chosen = None if options.get("select") else models
        skipped: list[str] = []

        def score(fits: list[Any]) -> None:  # gonio fit --score: the appearance score
            from gonio.fit.score import score_results

            why = score_results(src, fits)
            if why is not None:
                skipped.append(f"appearance score skipped: {why}")

        results, comp, shown = fit_models(
            data, chosen, opts, score if options.get("score") else None
        )
        log: list[str] = []
        with staging(folder) as tmp:  # one run per folder, swapped in whole (run_folder)
            files = []
            for r in results:
                stem = safe_stem(r.name if r.channel is None else f"{r.name}.{r.channel}")
                r.save(tmp / f"{stem}.json")
                files.append(str(folder / f"{stem}.json"))
                if options.get("plots", True) and (
                    r.name == comp.recommended or not options.get("select")
                ):
                    from gonio.fit.plots import plot_result

                    plot_result(r, shown, tmp, stem, skipped=skipped, log=log)
            summary = {
                "material": name,
                "path": str(src),
                "status": "ok",
                "files": files,
                "models": [m for m in models if isinstance(m, str)],
                "fit_options": key,
                **comp.to_json(),
            }
            write_json(summary, tmp / "summary.json")
            replaced = publish(tmp, folder, log)
        return {
            "material": name,
            "status": "ok",
            "recommended": comp.recommended,
            "table": comp.to_json()["table"],
            "replaced": replaced,
            "skipped": skipped,
        }
    except GonioError as exc:
        return {"material": name, "status": "error", "error": str(exc)}
    except Exception as exc:  # a bug in one material must not stop the batch; keep its trace
        return {
            "material": name,
            "status": "error",
            "error": f"{type(exc).__name__}: {exc}",
            "trace": traceback.format_exc(),
        }


def pending(
    paths: Iterable[Path],
    out_dir: Path,
    models: Sequence[str] = (),
    options: dict[str, Any] | None = None,
) -> tuple[list[Path], list[Path]]:
    """Split ``paths`` into (to do, already done): done means ``summary.json`` exists, so does
    the result of every model in ``models`` (a rerun asking for a new model redoes the
    material), and, when ``options`` are given, the summary records the same fit options (a
    rerun with another ``--loss`` or ``--theta-max`` redoes it; so does a summary that records
    none)."""
    key = None if options is None else fit_options_key(options)
    todo, done = [], []
    for p in paths:
        folder = out_dir / material_name(p)
        ok = (folder / "summary.json").exists()
        ok = ok and all((folder / f"{safe_stem(m)}.json").exists() for m in models)
        if ok and key is not None:
            ok = _summary(folder).get("fit_options") == key
        (done if ok else todo).append(p)
    return todo, done


def _journal(out_dir: Path, record: dict[str, Any]) -> None:
    line = dumps_json({k: v for k, v in record.items() if k != "table"}) + "\n"
    with open(out_dir / "batch.jsonl", "a") as fh:
        fh.write(line)
        fh.flush()
        os.fsync(fh.fileno())


def run_batch(
    paths: Sequence[Path],
    out_dir: str | Path,
    options: dict[str, Any],
    jobs: int = 2,
    scheduler: str | None = None,
    on_done: Callable[[dict[str, Any]], None] | None = None,
) -> list[dict[str, Any]]:
    """Fit every file not yet done; returns the summaries of this run (done ones skipped).

    Parameters
    ----------
    paths : measurement files.
    out_dir : output folder (created).
    options : ``{"models": [...], "fit": {fit() keyword arguments}, "plots": bool}``.
    jobs : worker processes of the local pool (1 runs in this process).
    scheduler : address of a Dask scheduler; when given, tasks run on that cluster.
    on_done : called with each summary as it arrives (progress display); an exception raised
        there (e.g. KeyboardInterrupt) stops the batch, leaving finished materials on disk.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    names = [material_name(p) for p in paths]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise FitError(f"several inputs share the material name(s) {', '.join(sorted(dup))}")
    plain = [m for m in options.get("models", ()) if isinstance(m, str)]
    separate = options.get("fit", {}).get("channels") == "separate"
    todo, _ = pending(paths, out, () if separate else plain, options)
    summaries: list[dict[str, Any]] = []

    def finish(s: dict[str, Any]) -> None:
        _journal(out, s)
        summaries.append(s)
        if on_done is not None:
            on_done(s)

    if not todo:
        return summaries
    if scheduler:
        _run_dask(todo, out, options, scheduler, finish)
    elif jobs <= 1:
        for p in todo:
            finish(fit_material(str(p), str(out), options))
    else:
        ctx = get_context("spawn")
        with ProcessPoolExecutor(max_workers=jobs, mp_context=ctx) as pool:
            futures = {pool.submit(fit_material, str(p), str(out), options) for p in todo}
            try:
                while futures:
                    done, futures = wait(futures, return_when=FIRST_COMPLETED)
                    for fut in done:
                        finish(fut.result())
            except BaseException:
                for fut in futures:
                    fut.cancel()
                raise
    return summaries


def _run_dask(
    todo: list[Path],
    out: Path,
    options: dict[str, Any],
    scheduler: str,
    finish: Callable[[dict[str, Any]], None],
) -> None:
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise FitError(
            "--scheduler needs dask.distributed (pip install 'dask[distributed]')"
        ) from None
    try:
        client = Client(scheduler, timeout="10s")
    except (OSError, TimeoutError) as exc:
        raise FitError(f"cannot reach the Dask scheduler at {scheduler} ({exc})") from None
    try:
        futures = [
            client.submit(fit_material, str(p.resolve()), str(out.resolve()), options, pure=False)
            for p in todo
        ]
        for fut in as_completed(futures):
            finish(fut.result())
    finally:
        client.close()


def batch_rows(paths: Sequence[Path], out_dir: Path) -> list[dict[str, Any]]:
    """One record per fitted (material, model) of ``out_dir`` for ``paths``, in order:
    ``material``, ``model``, ``recommended``, ``n_params``, ``metric``, ``loss``, every metric
    (``hdr_flip`` and ``rel_l1``, the appearance score, when the fits carry it), ``flags`` and
    ``params`` (the fit's parameter values by key). Materials without a finished run are left
    out."""
    rows = []
    for p in paths:
        folder = out_dir / material_name(p)
        summary = _summary(folder)
        for r in summary.get("table") or []:
            if not isinstance(r, dict):
                continue
            try:
                rec = json.loads((folder / f"{safe_stem(str(r['model']))}.json").read_text())
            except (OSError, ValueError, KeyError):
                rec = {}
            rows.append({
                "material": summary.get("material", material_name(p)),
                "model": r.get("model"),
                "recommended": r.get("model") == summary.get("recommended"),
                "n_params": r.get("n_params"),
                "metric": r.get("metric"),
                "loss": r.get("loss"),
                "metrics": {**(r.get("metrics") or {}), **_appearance_metrics(r)},
                "flags": r.get("flags") or [],
                "params": rec.get("params") or {},
            })  # fmt: skip
    return rows


def _appearance_metrics(row: dict[str, Any]) -> dict[str, float]:
    """The appearance score of a summary row (``gonio fit --score``) as batch metrics:
    ``hdr_flip`` and ``rel_l1``, the means over the sphere images; empty without one."""
    a = row.get("appearance")
    if not isinstance(a, dict):
        return {}
    return {k: float(a[k]) for k in ("hdr_flip", "rel_l1") if isinstance(a.get(k), (int, float))}


def write_batch_csv(rows: Sequence[dict[str, Any]], path: Path) -> Path:
    """``rows`` of :func:`batch_rows` as one CSV: fixed columns, one per metric, then one per
    scalar parameter value (``param:lambert.albedo[1]``; empty where a family has none)."""
    import csv
    import io

    import numpy as np

    from gonio.io.atomic import atomic_output

    metrics = sorted({k for r in rows for k in r["metrics"]})
    flat_rows, params = [], []
    for r in rows:
        flat = {}
        for key, value in r["params"].items():
            vals = np.ravel(np.asarray(value, dtype=float))
            for i, v in enumerate(vals):
                col = f"param:{key}" if vals.size == 1 else f"param:{key}[{i}]"
                flat[col] = float(v)
                if col not in params:
                    params.append(col)
        flat_rows.append(flat)
    head = ["material", "model", "recommended", "n_params", "metric", "loss", *metrics, "flags"]
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(head + params)
    for r, flat in zip(rows, flat_rows, strict=True):
        w.writerow([r["material"], r["model"], int(bool(r["recommended"])), r["n_params"],
                    r["metric"], r["loss"], *(r["metrics"].get(m, "") for m in metrics),
                    "; ".join(r["flags"]), *(flat.get(c, "") for c in params)])  # fmt: skip
    with atomic_output(path, ".csv") as tmp:
        tmp.write_text(buf.getvalue(), encoding="utf-8")
    return path
