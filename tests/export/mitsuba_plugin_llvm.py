"""The plugin's checks in Mitsuba's vectorized ``llvm_ad_rgb`` variant, run as a child process
by ``test_mitsuba_plugin_llvm.py`` (an LLVM older than 16 aborts the process, which must not be
pytest's). Prints one JSON object:

``eval_rel``: the largest relative difference of ``BSDF.eval`` from gonio's ``f cos`` over 4096
random direction pairs, per family; ``chi2``: Mitsuba's own chi-square test
(``mitsuba.chi2.ChiSquareTest`` with ``BSDFAdapter``) per model and view angle, its p-value and
verdict; ``render``: relative RMSE (interior pixels) of ``mi.render`` (``direct`` integrator, one
directional light, orthographic camera, 64 x 64 pixels, 1024 stratified samples, box filter) of
each shared-data fit against gonio's render of it (32 x 32 pixel centres per pixel), per light
angle, and ``noise_floor``: the same render with another seed against the first. 1024 samples
per pixel: the chrome fit's sharpest lobe (GTR alpha 0.003) is narrower than a pixel, and at 64
samples two seeds of Mitsuba's render differ by 20 %.

Usage: ``python -m tests.export.mitsuba_plugin_llvm`` with ``DRJIT_LIBLLVM_PATH`` naming
libLLVM >= 16 where the system's is older.
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np


def main() -> int:
    import drjit as dr
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    from gonio.brdf import models
    from gonio.export import mitsuba_plugin
    from tests.export.conftest import mitsuba_scene, rel_rmse
    from tests.export.test_mitsuba_plugin import (
        FAMILIES,
        FITS,
        MATERIALS,
        family_model,
        hemisphere,
        light_at,
        rgb3,
    )

    mitsuba_plugin.register()
    out: dict = {"eval_rel": {}, "chi2": {}, "render": {}, "noise_floor": {}, "render_s": {}}

    ctx = mi.BSDFContext()
    light, view = hemisphere(4096, 11), hemisphere(4096, 12)
    for name in FAMILIES:
        model = family_model(name)
        bsdf = mi.load_dict({"type": "gonio", "model": json.dumps(model.to_dict())})
        si = dr.zeros(mi.SurfaceInteraction3f, len(view))
        si.wi = mi.Vector3f(view.T.astype(np.float32))
        got = np.array(bsdf.eval(ctx, si, mi.Vector3f(light.T.astype(np.float32))), np.float64).T
        want = rgb3(np.asarray(model.f(light, view))) * light[:, 2:3]
        out["eval_rel"][name] = float(np.max(np.abs(got - want) / np.abs(want)))

    from mitsuba.chi2 import BSDFAdapter, ChiSquareTest, SphericalDomain

    chi2_models = {
        "lambert+gtr": models.Lambert(albedo=[0.3, 0.3, 0.3]) + models.GTR(0.6, 0.35, 2.0),
        "lambert+retro+gtr": family_model("lambert+retro+gtr"),
        "ward": models.Ward(rho_d=0.0, rho_s=0.5, alpha_x=0.15, alpha_y=0.15),
    }
    for name, model in chi2_models.items():
        for deg in (10, 60):
            spec = {"type": "gonio", "model": json.dumps(model.to_dict())}
            w = light_at(deg).tolist()
            sample, pdf = BSDFAdapter("gonio", spec, wi=w)
            test = ChiSquareTest(SphericalDomain(), sample, pdf, sample_dim=3, res=101, ires=8)
            ok = bool(test.run(0.01))
            out["chi2"][f"{name}@{deg}"] = {"passed": ok, "p_value": float(test.p_value)}

    from gonio.io.fit_result import load_model
    from gonio.render import Directional, render_sphere

    size, ss, spp = 64, 32, 1024
    for name in MATERIALS:
        model = load_model(FITS / f"{name}.json")
        bsdf = {"type": "gonio", "filename": str(FITS / f"{name}.json")}
        for deg in (0, 30, 60):
            ld = light_at(deg)
            case = f"{name}@{deg}"
            img = []
            for seed in (0, 1):
                scene = mi.load_dict(mitsuba_scene(mi, bsdf, ld, size, spp, seed))
                t = time.perf_counter()
                img.append(np.array(mi.render(scene, seed=seed), np.float64))
                out["render_s"][case] = time.perf_counter() - t
            ref = render_sphere(model, [Directional(ld, 1.0)], resolution=size * ss)
            ref = rgb3(ref.reshape(size, ss, size, ss, -1).astype(np.float64).mean(axis=(1, 3)))
            out["render"][case] = rel_rmse(img[0], ref)
            out["noise_floor"][case] = rel_rmse(img[1], img[0])
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
