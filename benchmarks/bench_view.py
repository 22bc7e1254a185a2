"""``gonio view``'s page for a MERL table: size, encoding error, first frame and frame times.

A glossy MERL file (Lambert + GGX Torrance-Sparrow tabulated by ``TabulatedBRDF.merl_like`` and
written as a real ``.binary``) is read through ``gonio.io`` and written as a page by ``gonio
view``'s own code. Measured, in headless Chromium's software WebGL2 (SwiftShader) on this
machine's CPUs, with the load average (1 min) before and after each browser measurement:

* the page's size with Plotly's bundle and the studio map (target <= 20 MB);
* the float16 encoding's largest relative error over the table's nonzero values (<= 0.5 %);
* the time from navigation to the first sphere frame (<= 2 s), and where it goes: the page's
  parse (``domInteractive``), the sphere script's start, the environment map's and the table's
  inflate + texture upload + shader compile (``loaded``), the first draw waited for;
* one 512 x 512 frame under the directional light (<= 16 ms) and one environment frame (1
  sample per pixel, progressive; <= 100 ms), each the median of many frames, each frame
  waited for by a 1-pixel readback, with the CPU time the browser's processes spent per frame
  (user + system, all of them: SwiftShader's threads share the machine's 2 cores, so wall time
  grows with the load while CPU time much less));
* the sphere against ``render_sphere``: point light (relative RMSE at 128 x 128, <= 1 %), and
  the environment: the mean of two sample sequences of 768 frames (768 samples per pixel each)
  against ``render_sphere`` with ``Environment("studio")`` at 1024 samples per pixel (64 x 64),
  with the noise the two sequences measure.

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


def _load() -> float:
    return os.getloadavg()[0]


def _cpu_s(root: int) -> float:
    """CPU time (user + system, s) so far of process ``root`` and all its descendants (Linux
    /proc): what the browser spent, whatever the machine's load."""
    parent: dict[int, int] = {}
    ticks: dict[int, int] = {}
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            fields = (d / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        parent[int(d.name)] = int(fields[1])
        ticks[int(d.name)] = int(fields[11]) + int(fields[12])
    tree, todo = set(), [root]
    while todo:
        p = todo.pop()
        tree.add(p)
        todo += [c for c, pp in parent.items() if pp == p and c not in tree]
    return sum(ticks.get(p, 0) for p in tree) / os.sysconf("SC_CLK_TCK")


def _rel_rmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b**2)))


def measure(folder: Path, frames: int = 50, env_frames: int = 20) -> list[dict]:
    from tests.view import browser

    from gonio import io
    from gonio.brdf import models
    from gonio.brdf.tabulated import TabulatedBRDF
    from gonio.render import Directional, render_sphere
    from gonio.render.lights import Environment
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
    light = [0.3, 0.2, 0.93]
    n, n_env, env_run = 128, 64, 768
    try:
        driver.set_script_timeout(900)
        load0 = _load()
        # the page as a user opens it: both lights, the environment refining in the background
        errors = browser.open_page(driver, page, timeout=300, mode="both")
        first_ms = driver.execute_script("return gonioView.firstFrameMs")
        marks = driver.execute_script("return gonioView.timings()")
        nav = driver.execute_script(
            "const n = performance.getEntriesByType('navigation')[0];"
            "return {parsed: n.domInteractive, read: n.responseEnd};"
        )
        load1 = _load()
        driver.execute_script("gonioView.hold(true)")
        load2 = _load()
        pid = driver.service.process.pid
        c0 = _cpu_s(pid)
        frame_ms = driver.execute_script(
            "return gonioView.timeFrames(0, 512, arguments[0], 'point')", frames
        )
        c1 = _cpu_s(pid)
        env_ms = driver.execute_script(
            "return gonioView.timeFrames(0, 512, arguments[0], 'environment')", env_frames
        )
        c2 = _cpu_s(pid)
        load3 = _load()
        # timeFrames draws 2 untimed frames first
        frame_cpu, env_cpu = 1e3 * (c1 - c0) / (frames + 2), 1e3 * (c2 - c1) / (env_frames + 2)
        got = np.asarray(
            driver.execute_script("return gonioView.readLinear(0, arguments[0], arguments[1])",
                                  light, n), np.float64
        ).reshape(n, n, 4)[..., :3]  # fmt: skip
        env_ab = [
            np.asarray(
                driver.execute_script(
                    "return gonioView.readEnv(0, arguments[0], arguments[1], arguments[2])",
                    n_env, env_run, seed), np.float64
            ).reshape(n_env, n_env, 4)[..., :3]
            for seed in (1, 2)
        ]  # fmt: skip
        renderer = driver.execute_script(
            "const gl = document.createElement('canvas').getContext('webgl2');"
            "const e = gl.getExtension('WEBGL_debug_renderer_info');"
            "return e ? gl.getParameter(e.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER);"
        )
    finally:
        driver.quit()
    material = source.material.material
    lv = np.asarray(light) / np.linalg.norm(light)
    ref = np.asarray(render_sphere(material, lights=[Directional(lv)], resolution=n), np.float64)
    ref_env = np.asarray(
        render_sphere(material, lights=[Environment("studio")], resolution=n_env, spp=1024),
        np.float64,
    )
    noise = _rel_rmse(env_ab[0], env_ab[1]) / np.sqrt(2)
    sw = "SwiftShader" if "SwiftShader" in renderer else renderer
    where = f"headless Chromium, {sw}, {os.cpu_count()} CPUs"
    breakdown = (
        f"file read {nav['read']:.0f} ms, page parsed {nav['parsed']:.0f} ms, sphere script "
        f"{marks['start']:.0f} ms, map inflated {marks['env-inflated']:.0f} ms, tables "
        f"uploaded + shaders compiled {marks['loaded']:.0f} ms, first frame "
        f"{marks['first-frame']:.0f} ms, Plotly run {marks['plotly-loaded']:.0f} ms, plots "
        f"{marks['plots']:.0f} ms (all since navigation)"
    )
    return [
        {"metric": "page size, MERL table + Plotly + studio map (MB)", "value": size_mb,
         "target": 20, "note": f"built in {build_s:.1f} s"},
        {"metric": "float16 encoding, max relative error (%)", "value": 100 * enc,
         "target": 0.5, "note": "over the table's nonzero values"},
        {"metric": "first sphere frame after navigation (s)", "value": first_ms / 1000,
         "target": 2, "note": f"{where}, load {load0:.1f} -> {load1:.1f}; {breakdown}"},
        {"metric": "frame at 512x512, point light (ms)", "value": frame_ms, "target": 16,
         "note": f"{where}, load {load2:.1f} -> {load3:.1f}; median of {frames}; browser CPU "
         f"time {frame_cpu:.0f} ms per frame"},
        {"metric": "frame at 512x512, environment, 1 sample/px (ms)", "value": env_ms,
         "target": 100, "note": f"{where}, load {load2:.1f} -> {load3:.1f}; median of "
         f"{env_frames}; progressive; browser CPU time {env_cpu:.0f} ms per frame"},
        {"metric": "sphere vs render_sphere, point light, relative RMSE (%)",
         "value": 100 * _rel_rmse(got, ref), "target": 1, "note": f"{n}x{n}, same light"},
        {"metric": "sphere vs render_sphere, environment, relative RMSE (%)",
         "value": 100 * _rel_rmse((env_ab[0] + env_ab[1]) / 2, ref_env),
         "target": f"{100 * (0.005 + 2 * noise / np.sqrt(2)):.2g}",
         "note": f"{n_env}x{n_env}; the mean of two sample sequences of {env_run} samples/px "
         f"against 1024 spp; noise of one sequence {100 * noise:.2f} % (RMSE(A - B) / sqrt 2), "
         "target 0.5 % + 2 noise / sqrt 2 as in the browser test"},
        {"metric": "console errors", "value": len(errors), "target": 0, "note": ""},
    ]  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=50, help="point-light frames timed")
    ap.add_argument("--env-frames", type=int, default=20, help="environment frames timed")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as d:
        rows = measure(Path(d), args.frames, args.env_frames)
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
