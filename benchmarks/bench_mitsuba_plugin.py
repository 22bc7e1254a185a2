"""Render time of gonio's Mitsuba BSDF plugin against Mitsuba's stock BSDFs, same scene.

The material is one both express exactly: Lambert + Torrance-Sparrow (GGX, Smith, a gold-like
conductor Fresnel), exported by ``gonio export --to mitsuba`` (a ``blendbsdf`` of ``diffuse`` and
``roughconductor``) and by ``--plugin`` (BSDF ``gonio``, which calls gonio's JAX model). Scenes,
both 64 x 64 on the unit sphere: ``direct`` (one directional light, ``direct`` integrator,
orthographic camera: the plugin's ``eval`` once per sample) and ``path`` (perspective camera,
constant environment, path tracer of depth 3: ``sample``, ``eval`` and ``pdf``). Each variant
runs in its own child process: ``scalar_rgb`` (the plugin is called once per ray) and
``llvm_ad_rgb`` (once per wavefront; needs ``DRJIT_LIBLLVM_PATH`` naming libLLVM >= 16 where the
system's is older, else it is skipped). A time is the fastest of ``--repeats`` renders after a
warm-up render (JIT compilation excluded). The relative RMSE column compares the plugin's image
with the stock one (same seed; Mitsuba's separable Smith term against gonio's height-correlated
one, plus sampling noise in the path scene). Writes ``results/mitsuba_plugin.csv`` and its table.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT))
#: Samples per pixel per variant and scene: scalar_rgb is slow with the plugin, keep it short.
SPP = {"scalar_rgb": {"direct": 4, "path": 4}, "llvm_ad_rgb": {"direct": 64, "path": 64}}


def scenes(mi, bsdf: dict, spp: dict) -> dict:
    from tests.export.conftest import LIGHT, mitsuba_scene, path_scene

    return {
        "direct": mitsuba_scene(mi, bsdf, LIGHT, 64, spp["direct"]),
        "path": path_scene(mi, bsdf, 64, spp["path"], 3),
    }


def child(variant: str, repeats: int) -> list[dict]:
    """Time both BSDFs on both scenes in ``variant`` (run in a child process)."""
    import mitsuba as mi

    mi.set_variant(variant)
    from tests.export.conftest import fit_record

    from gonio.brdf import models
    from gonio.export import mitsuba_plugin, to_mitsuba

    mitsuba_plugin.register()
    model = models.Lambert(albedo=[0.5, 0.35, 0.2]) + models.TorranceSparrow(
        alpha=0.2,
        distribution="ggx",
        shadowing="smith",
        fresnel=models.Conductor(eta=[0.143, 0.374, 1.442], k=[3.983, 2.385, 1.603]),
    )
    record = fit_record(model)
    stock = to_mitsuba(record)
    assert stock.mapping == "exact"
    bsdfs = {"stock": stock.data, "plugin": mitsuba_plugin.export(record).data}
    rows, images = [], {}
    for kind, bsdf in bsdfs.items():
        for scene_name, scene_dict in scenes(mi, bsdf, SPP[variant]).items():
            scene = mi.load_dict(scene_dict)
            img = np.array(mi.render(scene, seed=0), np.float64)  # warm-up
            times = []
            for _ in range(repeats):
                t = time.perf_counter()
                mi.render(scene, seed=0)
                times.append(time.perf_counter() - t)
            images[kind, scene_name] = img
            rows.append({"variant": variant, "scene": scene_name, "bsdf": kind,
                         "spp": SPP[variant][scene_name], "seconds": min(times)})  # fmt: skip
    for r in rows:
        a, b = images["plugin", r["scene"]], images["stock", r["scene"]]
        r["rel_rmse_vs_stock"] = float(np.sqrt(np.mean((a - b) ** 2) / np.mean(b**2)))
        r["load"] = os.getloadavg()[0]
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3, help="timed renders per case")
    ap.add_argument("--child", metavar="VARIANT", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.child, args.repeats)))
        return 0
    rows = []
    for variant in SPP:
        if variant.startswith("llvm") and not os.environ.get("DRJIT_LIBLLVM_PATH"):
            print(f"{variant}: skipped (set DRJIT_LIBLLVM_PATH to libLLVM >= 16)")
            continue
        run = subprocess.run(
            [sys.executable, __file__, "--child", variant, "--repeats", str(args.repeats)],
            capture_output=True,
            text=True,
            check=True,
        )
        rows += json.loads(run.stdout.strip().splitlines()[-1])
    stock = {(r["variant"], r["scene"]): r["seconds"] for r in rows if r["bsdf"] == "stock"}
    for r in rows:
        r["x_stock"] = r["seconds"] / stock[r["variant"], r["scene"]]
    import _tables

    _tables.write_csv(rows, "mitsuba_plugin.csv")
    for r in rows:
        print(r)
    write_tables()
    return 0


def write_tables() -> None:
    """Rewrite this benchmark's table in benchmarks/README.md from its CSV."""
    import _tables

    columns = [("variant", "variant"), ("scene", "scene"), ("BSDF", "bsdf"), ("spp", "spp"),
               ("render (s)", "seconds"), ("x stock", "x_stock"),
               ("rel. RMSE vs stock", "rel_rmse_vs_stock"), ("load", "load")]  # fmt: skip
    rows = _tables.read("mitsuba_plugin.csv")
    _tables.write("mitsuba_plugin", _tables.markdown(rows, columns))


if __name__ == "__main__":
    sys.exit(main())
