"""The demo's ``index.html``: one self-contained page (no scripts, no network) with the numbers,
linking the run's interactive ``view.html`` (:mod:`gonio.view`).

Every image and link is a relative path inside the demo folder, so the folder can be copied or
served as it is. Text from data (material descriptions, warnings) is HTML-escaped.
"""

from __future__ import annotations

import html
from pathlib import Path
from typing import Any

import numpy as np

from gonio.io.atomic import atomic_output

_CSS = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 70em; color: #222; }
h1 { margin-bottom: 0.2em; }
table { border-collapse: collapse; margin: 1em 0; }
th, td { border: 1px solid #ccc; padding: 0.3em 0.6em; text-align: left; vertical-align: top; }
th { background: #f3f3f3; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
figure { display: inline-block; margin: 0.5em; text-align: center; }
/* plots wider than the page scroll inside their figure: every image at its native size */
figure { max-width: 100%; overflow-x: auto; }
figure img { max-width: none; }
.warn { color: #a40; font-size: 90%; }
.ok { color: #070; }
.bad { color: #a00; }
code { background: #f6f6f6; padding: 0 0.2em; }
"""


def _e(x: Any) -> str:
    return html.escape(str(x), quote=True)


def _num(x: Any, digits: int = 4) -> str:
    if x is None:
        return "&ndash;"
    return f"{float(x):.{digits}g}"


def format_value(v: Any, digits: int = 4) -> str:
    """A scalar as ``0.123``, a per-channel value as ``(0.1, 0.2, 0.3)``."""
    a = np.asarray(v, dtype=float)
    if a.ndim == 0:
        return f"{float(a):.{digits}g}"
    return "(" + ", ".join(f"{x:.{digits}g}" for x in a.ravel()) + ")"


def format_interval(iv: Any, digits: int = 4) -> str:
    """``[lo, hi]`` per value (per channel), or ``-`` when there is no interval."""
    if not iv:
        return "-"
    lo, hi = (np.asarray(x, dtype=float).ravel() for x in iv)
    return ", ".join(f"[{a:.{digits}g}, {b:.{digits}g}]" for a, b in zip(lo, hi, strict=True))


def _img(src: str, alt: str, cls: str = "") -> str:
    c = f' class="{cls}"' if cls else ""
    return f'<img src="{_e(src)}" alt="{_e(alt)}"{c}>'


def _models_table(models: list[Any]) -> str:
    rows = []
    for m in models:
        chk = ""
        tc = m.truth_check
        if tc is not None:
            cls, word = ("ok", "consistent") if tc.consistent else ("bad", "inconsistent")
            chk = (
                f'<span class="{cls}" title="largest |fit - truth| / std over {tc.n_scalars}'
                f' values; family-wise 1 % limit {tc.z_crit:.2f}">'
                f"{word}, max |z| {tc.max_z:.2f}</span>"
            )
        rows.append(
            "<tr>"
            f'<td><a href="{_e(m.files["fit"])}">{_e(m.label)}</a></td>'
            f'<td class="num">{_num(m.reduced_chi2)}</td>'
            f'<td class="num">{_num(m.aic, 6)}</td><td class="num">{_num(m.bic, 6)}</td>'
            f'<td class="num">{_num(m.rmse)}</td><td class="num">{_num(m.rel_mse)}</td>'
            f'<td class="num">{_num(m.ssim, 3)}</td>'
            f'<td class="num">{_num(getattr(m, "hdr_flip", None), 3)}</td>'
            f'<td class="num">{_num(getattr(m, "rel_l1", None), 3)}</td>'
            f'<td class="num">{m.fit_s:.2f}</td>'
            f"<td>{chk or '&ndash;'}</td></tr>"
        )
    head = (
        "<tr><th>model (fit JSON)</th><th>reduced &chi;&sup2;</th><th>AIC</th><th>BIC</th>"
        "<th>render RMSE</th><th>render relMSE</th><th>SSIM</th>"
        '<th title="appearance score: HDR-FLIP, mean over the spheres under a light at 0, 30 and'
        ' 60 degrees and the studio">HDR-FLIP</th>'
        '<th title="appearance score: relative L1 of the same spheres">rel. L1</th>'
        "<th>fit time (s)</th>"
        "<th>ground truth (family-wise 1&nbsp;%)</th></tr>"
    )
    return f"<table>{head}{''.join(rows)}</table>"


def _params_table(m: Any, truth: dict[str, Any]) -> str:
    rows = []
    for key, value in m.params.items():
        true = truth.get(key)
        rows.append(
            f"<tr><td><code>{_e(key)}</code></td><td class='num'>{format_value(value)}</td>"
            f"<td class='num'>{_e(format_interval(m.intervals.get(key)))}</td>"
            f"<td class='num'>{'&ndash;' if true is None else format_value(true)}</td></tr>"
        )
    head = "<tr><th>parameter</th><th>value</th><th>95&nbsp;% interval</th><th>truth</th></tr>"
    return f"<table>{head}{''.join(rows)}</table>"


def _reference_note(material: dict[str, Any], render: dict[str, Any]) -> str:
    if material.get("table"):
        return (
            "The measured sphere renders the material's table itself (the simulated sample's"
            " ground truth); the fitted spheres render the models fitted to what the simulated"
            " rig acquired from it."
        )
    return (
        f"The {render['reference']} sphere renders the built-in material's exact model; the"
        " fitted spheres render the models fitted to what the simulated rig acquired from it."
    )


def render_html(summary: Any) -> str:
    """The report page for a :class:`gonio.demo.pipeline.DemoSummary`."""
    mat, acq, ren = summary.material, summary.acquisition, summary.render
    files = summary.files
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>gonio demo: {_e(mat['name'])}</title><style>{_CSS}</style></head><body>",
        f"<h1>gonio demo: {_e(mat['name'])}</h1>",
        f"<p>{_e(mat['description'])}</p>",
        "<h2>Acquisition</h2>",
        f"<p>{acq['measured']} configurations measured on the simulated 4-axis rig"
        f" ({acq['refused']} refused by its safety checks"
        f"{f', {r} rejected as unmeasurable' if (r := acq.get('rejected')) else ''})"
        f" in {acq['wall_s']:.0f}&nbsp;s;"
        f' {_e(acq["table_note"])}. Rig file: <a href="{_e(files["rig"])}">rig.toml</a>;'
        f' samples and gridded table: <a href="{_e(files["table"])}">table.brdf.h5</a>'
        f' (<a href="run/log.jsonl">run log</a>).</p>',
    ]
    if files.get("view"):
        parts.append(
            f'<p>Interactive view of the run and every fit: <a href="{_e(files["view"])}">'
            f"{_e(files['view'])}</a> (<code>gonio view</code>: spheres under a light you drag"
            " and the studio environment, slices, maps, the run's coverage, the fits'"
            " parameters; one self-contained file).</p>"
        )
    if files.get("camera_view"):
        parts.append(
            "<figure>"
            + _img(files["camera_view"], "first HDR frame of the virtual camera")
            + "<figcaption>What the camera saw (first configuration, tone-mapped HDR): ChArUco"
            " board, the sample disk at its centre and the brighter white-reference disk beside"
            " it.</figcaption></figure>"
        )
    parts += [
        "<h2>Fits</h2>",
        "<p>Weighted least squares on the measured samples (each weighted by its own"
        " uncertainty), 95&nbsp;% intervals from the Laplace approximation. AIC and BIC compare"
        " models fitted to the same data (lower is better). Render errors compare each fitted"
        f" sphere with the {_e(ren['reference'])} sphere. A reduced &chi;&sup2; far above 1 means"
        " the model cannot follow the data within the measurement uncertainty (well below 1&nbsp;%"
        " per sample here): no analytic model is exact for a real material.</p>",
        _models_table(summary.models),
        "<h2>Spheres</h2>",
        f"<p>{ren['resolution']}&times;{ren['resolution']} pixels, {ren['spp']} samples per"
        f" pixel, {_e(ren['lights'])}; PNGs share one exposure; EXRs are linear radiance."
        f" {_e(_reference_note(mat, ren))}</p>",
        '<div class="spheres">',
    ]
    spheres = [("measured", ren["reference"])] + [
        (m.preset.replace("+", "-"), m.label) for m in summary.models
    ]
    for stem, label in spheres:
        im = ren["images"][stem]
        parts.append(
            f"<figure>{_img(im['png'], f'{label} sphere')}<figcaption>{_e(label)}<br>"
            f'<a href="{_e(im["exr"])}">EXR</a></figcaption></figure>'
        )
    parts += [
        "</div>",
        "<figure>" + _img(files["compare"], "measured, fitted and difference per model"),
        f"<figcaption>{_e(ren['reference'])} | fitted | |difference| per model (the"
        " colour scale ends at the 99.5th percentile of the differences; larger ones show at"
        " its top colour)</figcaption></figure>",
        "<h2>Per model</h2>",
    ]
    truth_all = mat.get("truth_params", {})
    for m in summary.models:
        parts.append(f"<h3>{_e(m.label)}</h3>")
        parts.append(_params_table(m, truth_all.get(m.preset, {})))
        for w in m.warnings:
            parts.append(f'<p class="warn">{_e(w)}</p>')
        parts.append('<div class="plots">')
        for p in m.files["plots"]:
            parts.append(f"<figure>{_img(p, Path(p).stem)}</figure>")
        parts.append("</div>")
    parts += _export_section(summary.models)
    t = summary.timings_s
    parts += [
        "<h2>Timings</h2>",
        "<table><tr><th>stage</th><th>seconds</th></tr>"
        + "".join(f"<tr><td>{_e(k)}</td><td class='num'>{v:.1f}</td></tr>" for k, v in t.items())
        + "</table>",
        f'<p>All numbers: <a href="{_e(files["summary"])}">{_e(files["summary"])}</a>.</p>',
        "</body></html>",
    ]
    return "\n".join(parts) + "\n"


def _export_section(models: list[Any]) -> list[str]:
    """The "Export" section: each fit as a material per renderer (gonio.export)."""
    rows = [(m, r) for m in models for r in m.files.get("exports", [])]
    if not rows:
        return []
    out = [
        "<h2>Export</h2>",
        "<p>Every fit as a renderer's material (<code>gonio export FIT --to TARGET</code>)."
        " <em>exact</em>: the renderer has the fitted family and gets the fitted values;"
        " <em>refit</em>: it has not, so its family was fitted to the measurement under the"
        " fit's metric (or, where the measurement was not readable, to the fitted model"
        " sampled densely, whose loss is not comparable with the fit's), with the loss shown"
        " next to the original fit's.</p>",
        "<table><tr><th>model</th><th>target</th><th>mapping</th><th>exported family</th>"
        "<th>loss: refit / original fit</th><th>files</th></tr>",
    ]
    for m, r in rows:
        loss = ""
        if r["refit_loss"] is not None:
            loss = f"{_num(r['refit_loss'])} / {_num(r['original_loss'])} ({_e(r['metric'])})"
            if r.get("refit_data") != "measurement":
                loss += " refit to the sampled model"
        links = " ".join(f'<a href="{_e(f)}">{_e(Path(f).name)}</a>' for f in r["files"])
        out.append(
            f"<tr><td>{_e(m.label)}</td><td>{_e(r['target'])}</td><td>{_e(r['mapping'])}</td>"
            f"<td>{_e(r['family'])}</td><td class='num'>{loss}</td><td>{links}</td></tr>"
        )
    out.append("</table>")
    return out


def write_report(path: str | Path, summary: Any) -> Path:
    """Write ``index.html`` atomically; returns the path."""
    path = Path(path)
    text = render_html(summary)
    with atomic_output(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path
