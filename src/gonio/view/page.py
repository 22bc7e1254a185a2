"""The one self-contained page of ``gonio view``: spheres (WebGL2), plots (Plotly), fit panels.

Everything the page needs is inside it: Plotly's offline bundle (from the ``plotly`` Python
package, gzip + base64, run once the spheres have drawn their first frame), the sphere script
(``sphere.js``, package data), gonio's studio environment map and the data as JSON. Its Content
Security Policy forbids every network request, so opening it fetches nothing.
"""

from __future__ import annotations

import functools
import html
import math
from importlib import resources
from pathlib import Path
from typing import Any

from gonio.io.strict_json import dumps_json
from gonio.view.encode import environment_map, pack, sphere_table
from gonio.view.figures import (
    coverage_figure,
    map_range,
    maps_figure,
    polar_figure,
    slices_figure,
)
from gonio.view.sources import Source

CSP = (
    "default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; "
    "img-src data: blob:; font-src data:; connect-src data: blob:"
)

STYLE = """
body { font-family: system-ui, sans-serif; margin: 1.5em; color: #222; }
h1 { font-size: 1.4em; } h2 { font-size: 1.15em; margin-top: 1.6em; }
#spheres { display: flex; flex-wrap: wrap; gap: 1em; }
#spheres figure { margin: 0; text-align: center; }
canvas.sphere { width: 384px; height: 384px; background: #000; cursor: crosshair;
  touch-action: none; }
.controls label { margin-right: 1.2em; }
.plot { width: 100%; max-width: 1100px; height: 520px; }
table.params { border-collapse: collapse; margin: 0.5em 0 1em; }
table.params td, table.params th { border: 1px solid #ccc; padding: 0.2em 0.6em;
  text-align: right; }
.note { color: #555; font-size: 0.9em; }
"""

BOOT = """
(function () {
  const data = JSON.parse(document.getElementById("gonio-data").textContent);
  const config = { displaylogo: false, responsive: true };
  // the spheres first (their first frame is not held up by the plots), then the plots
  gonioSphere.start(data.spheres, data.environment).catch((e) => {
    document.getElementById("sphere-status").textContent = "sphere: " + e.message;
    window.gonioView = { webgl2: false, error: String(e) };
  }).then(() => {
    // Plotly's bundle (gzip, base64) is inflated and run only now: it does not hold up the
    // spheres' first frame
    return gonioSphere.inflate(document.getElementById("plotly-src").textContent.trim());
  }).then((bytes) => {
    const lib = document.createElement("script");
    lib.textContent = new TextDecoder().decode(bytes);
    document.head.append(lib);
    performance.mark("gonio:plotly-loaded");
    for (const [id, fig] of Object.entries(data.figures)) {
      Plotly.newPlot(id, fig.data, fig.layout, config);
    }
    performance.mark("gonio:plots");
    window.gonioView.ready = true;
  });
})();
"""


@functools.cache
def plotly_packed() -> str:
    """Plotly's offline bundle (from the ``plotly`` package), gzip-compressed and base64-encoded
    (a third of its size); the page inflates it with the browser's ``DecompressionStream``."""
    import plotly.offline

    return pack(plotly.offline.get_plotlyjs().encode("utf-8"))


def _json_script(obj: Any) -> str:
    """JSON safe inside a <script> element (no ``</`` to close it early)."""
    text = dumps_json(obj, nonfinite="refuse", source="the page's data", separators=(",", ":"))
    return text.replace("</", "<\\/")


def _fmt(v: Any) -> str:
    if v is None:
        return "—"
    if isinstance(v, list):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    if isinstance(v, float):
        return f"{v:.4g}" if math.isfinite(v) else str(v)
    return html.escape(str(v))


def params_panel(source: Source) -> str:
    """HTML of a fit's values and 95 % intervals, loss, metric and scores."""
    rec = source.record or {}
    rows = []
    intervals = rec.get("intervals") or {}
    for key, value in (rec.get("params") or {}).items():
        lo_hi = intervals.get(key)
        iv = f"{_fmt(lo_hi[0])} … {_fmt(lo_hi[1])}" if lo_hi else "fixed / —"
        rows.append(f"<tr><th>{html.escape(key)}</th><td>{_fmt(value)}</td><td>{iv}</td></tr>")
    facts = [
        ("model", rec.get("model")),
        ("loss", rec.get("loss")),
        ("metric", rec.get("metric")),
        ("reduced χ²", rec.get("reduced_chi2")),
    ]
    facts += sorted((rec.get("metrics") or {}).items())
    fact_html = "".join(
        f"<tr><th>{html.escape(str(k))}</th><td colspan=2>{_fmt(v)}</td></tr>"
        for k, v in facts
        if v is not None
    )
    return (
        f"<h3>{html.escape(source.label)}</h3><table class=params><tr><th>parameter</th>"
        f"<th>value</th><th>95 % interval</th></tr>{''.join(rows)}{fact_html}</table>"
    )


def page_data(sources: list[Source]) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """``(figures by element id, sphere tables)`` of the page."""
    figures: dict[str, Any] = {
        "slices": slices_figure(sources),
        "polar": polar_figure(sources),
    }
    lo, hi = map_range(sources)
    for k, s in enumerate(sources):
        figures[f"map-{k}"] = maps_figure(s, lo, hi)
        cov = coverage_figure(s)
        if cov is not None:
            figures[f"coverage-{k}"] = cov
    spheres = [sphere_table(s.label, s.material).to_json() for s in sources]
    return figures, spheres


def build_page(sources: list[Source]) -> str:
    """The page's HTML text (see the module docstring)."""
    figures, spheres = page_data(sources)
    environment = environment_map()
    env_note = environment["description"]
    labels = ", ".join(s.label for s in sources)
    notes = []
    for s, t in zip(sources, spheres, strict=True):
        err = t["resampling_error"]
        line = (
            f"{s.label}: sphere from {t['resampling']}"
            + ("" if err is None else f" (resampling error {err:.2%} relative RMSE)")
            + f"; float16 encoding error ≤ {t['encoding_error']:.3%}"
        )
        notes += [line, *(f"{s.label}: {n}" for n in s.notes)]
    note_html = "".join(f"<li>{html.escape(n)}</li>" for n in notes)
    fits = "".join(params_panel(s) for s in sources if s.record is not None)
    maps = "".join(f'<div id="map-{k}" class="plot"></div>' for k in range(len(sources)))
    covs = "".join(f'<div id="{k}" class="plot"></div>' for k in figures if k.startswith("cov"))
    sphere_js = resources.files("gonio.view").joinpath("sphere.js").read_text("utf-8")
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta http-equiv="Content-Security-Policy" content="{CSP}">
<title>gonio view: {html.escape(labels)}</title>
<style>{STYLE}</style></head>
<body>
<h1>gonio view: {html.escape(labels)}</h1>
<h2>Spheres</h2>
<p class=note>Unit spheres seen from above (orthographic), lit by a directional light of
irradiance 1 (pixel = f · cos θi in linear units) and/or by {html.escape(env_note)}; the sum,
times 2<sup>exposure</sup>, shown in sRGB. Drag on a sphere to move the light. The environment
is refined progressively (the sample count is shown) and converges to the sphere that
<code>gonio render</code> draws under the same map.</p>
<div class=controls>
<label><input type="radio" name="light-mode" value="point"> point light</label>
<label><input type="radio" name="light-mode" value="environment"> environment</label>
<label><input type="radio" name="light-mode" value="both" checked> both</label>
<span id="env-label"></span>
</div>
<div class=controls>
<label>light θ <input id="light-theta" type="range" min="0" max="89" step="0.5" value="0"></label>
<label>φ <input id="light-phi" type="range" min="-180" max="180" step="1" value="0"></label>
<span id="light-label"></span>
<label>exposure <input id="exposure" type="range" min="-10" max="10" step="0.1" value="0"></label>
<span id="exposure-label">exposure: 0.0 EV</span>
<label>environment <input id="env-ev" type="range" min="-8" max="4" step="0.1" value="0"></label>
<span id="env-ev-label">environment: 0.0 EV</span>
</div>
<p id="sphere-status" class=note></p>
<div id="spheres"></div>
<ul class=note>{note_html}</ul>
{"<h2>Fits</h2>" + fits if fits else ""}
<h2>Slices</h2>
<div id="slices" class="plot"></div>
<div id="polar" class="plot"></div>
<h2>θh–θd maps</h2>
{maps}
{"<h2>Coverage</h2>" + covs if covs else ""}
<script type="application/json" id="gonio-data">{
        _json_script({"figures": figures, "spheres": spheres, "environment": environment})
    }</script>
<script>{sphere_js}</script>
<script type="text/plain" id="plotly-src">{plotly_packed()}</script>
<script>{BOOT}</script>
</body></html>
"""


def write_page(sources: list[Source], out: str | Path) -> Path:
    """Build the page first, then write it atomically: a failure leaves no file."""
    from gonio.io.atomic import atomic_output

    text = build_page(sources)
    out = Path(out)
    with atomic_output(out, ".html") as tmp:
        tmp.write_text(text, encoding="utf-8")
    return out
