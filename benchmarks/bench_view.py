"""``gonio view``'s page for a MERL table: size, encoding error, first frame and frame time.

A glossy MERL file (Lambert + GGX Torrance-Sparrow tabulated by ``TabulatedBRDF.merl_like`` and
written as a real ``.binary``) is read through ``gonio.io`` and written as a page by ``gonio
view``'s own code. Measured: the page's size with Plotly's bundle (target <= 20 MB), the float16
encoding's largest relative error over the table's nonzero values (target <= 0.5 %), the time
from navigation to the first sphere frame in headless Chromium (target <= 2 s), the time of one
512 x 512 frame under the directional light (target <= 16 ms; the mean of 10 frames, each
waited for by a 1-pixel readback), all in Chromium's software WebGL2 (SwiftShader) on this
machine's CPU, and the sphere's agreement with ``render_sphere`` (relative RMSE at 128 x 128).
Writes ``benchmarks/results/view.csv`` and its table in benchmarks/README.md.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
sys.path.insert(0, str(HERE.parent / "src"))
sys.path.insert(0, str(HERE.parent))


def measure(folder: Path, frames: int = 10) -> list[dict]:
    from tests.view import browser

    from gonio import io
    from gonio.brdf import models
    from gonio.brdf.tabulated import TabulatedBRDF
    from gonio.render import Directional, render_sphere
    from gonio.view.page import write_page
    from gonio.view.sources import from_path

    m = models.Lambert(albedo=[0.1, 0.08, 0.05]) + models.TorranceSparrow(
        alpha=0.08, distribution="ggx", rho_d=0.0
    )
    merl = folder / "glossy.binary"
    io.save(TabulatedBRDF.merl_like(m), merl)
    t0 = time.perf_counter()
    source = from_path(merl)
    page = write_page([source], folder / "view.html")
    build_s = time.perf_counter() - t0
    size_mb = page.stat().st_size / 1e6

    text = page.read_text(encoding="utf-8")
    data = json.loads(text.split('id="gonio-data">', 1)[1].split("</script>", 1)[0])
    enc = data["spheres"][0]["encoding_error"]
    driver = browser.start(folder / "profile")
    try:
        driver.set_script_timeout(600)
        errors = browser.open_page(driver, page, timeout=300)
        first_ms = driver.execute_script("return gonioView.firstFrameMs")
        frame_ms = driver.execute_script(
            "return gonioView.timeFrames(0, 512, arguments[0])", frames
        )
        light = [0.3, 0.2, 0.93]
        n = 128
        got = np.asarray(
            driver.execute_script("return gonioView.readLinear(0, arguments[0], arguments[1])",
                                  light, n), np.float64
        ).reshape(n, n, 4)[..., :3]  # fmt: skip
        renderer = driver.execute_script(
            "const gl = document.createElement('canvas').getContext('webgl2');"
            "const e = gl.getExtension('WEBGL_debug_renderer_info');"
            "return e ? gl.getParameter(e.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER);"
        )
    finally:
        driver.quit()
    lv = np.asarray(light) / np.linalg.norm(light)
    ref = np.asarray(render_sphere(source.material.material, lights=[Directional(lv)],
                                   resolution=n), np.float64)  # fmt: skip
    rmse = float(np.sqrt(np.mean((got - ref) ** 2)) / np.sqrt(np.mean(ref**2)))
    load = os.getloadavg()[0]
    where = f"headless Chromium, {renderer}, {os.cpu_count()} CPUs, load average {load:.0f}"
    return [
        {"metric": "page size, MERL table + Plotly (MB)", "value": size_mb, "target": 20,
         "note": f"built in {build_s:.1f} s"},
        {"metric": "float16 encoding, max relative error (%)", "value": 100 * enc,
         "target": 0.5, "note": "over the table's nonzero values"},
        {"metric": "first sphere frame after navigation (s)", "value": first_ms / 1000,
         "target": 2, "note": where},
        {"metric": "frame at 512x512, directional light (ms)", "value": frame_ms, "target": 16,
         "note": f"{where}; mean of {frames}"},
        {"metric": "sphere vs render_sphere, relative RMSE (%)", "value": 100 * rmse,
         "target": 1, "note": "128x128, same light"},
        {"metric": "console errors", "value": len(errors), "target": 0, "note": ""},
    ]  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=10, help="frames timed at 512x512")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as d:
        rows = measure(Path(d), args.frames)
    RESULTS.mkdir(exist_ok=True)
    with open(RESULTS / "view.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    for r in rows:
        print(f"{r['metric']}: {r['value']:.4g} (target {r['target']}) {r['note']}")
    write_tables()
    return 0


def write_tables() -> None:
    """Rewrite this benchmark's table in benchmarks/README.md from its CSV."""
    import _tables

    columns = [("measure", "metric"), ("value", "value"), ("target", "target"),
               ("where", "note")]  # fmt: skip
    _tables.write("view", _tables.markdown(_tables.read("view.csv"), columns))


if __name__ == "__main__":
    sys.exit(main())
