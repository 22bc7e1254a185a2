"""Blender runs the exported script and Cycles renders the fit like gonio does.

The exported ``.py`` is executed by ``blender_scene.py`` inside a Python that has ``bpy`` (a
separate process: the ``bpy`` wheels for Python 3.11 pin NumPy < 2, which gonio's JAX cannot
share, so ``make interop`` installs bpy in ``.venv-bpy``; ``GONIO_BPY_PYTHON`` or a ``blender``
on PATH work too). The scene is the DESIGN.md sphere under one sun (angle 0, irradiance 1),
Cycles on the CPU, 64 px, 64 samples, denoiser off, box filter one pixel wide.

Tolerance: 0.5 % relative RMSE over the interior pixels. Measured while writing this test
(alpha 0.05 / 0.2 / 0.5, Schlick and dielectric): 0.20 / 0.034 / 0.030 % at 64 spp and
0.80 / 0.12 / 0.11 % at 16 spp; the error falls as 1 / spp, so it is Cycles' sampling of the
pixel area against gonio's 8 x 8 supersampled centres, not a BSDF difference. Mapping errors
it catches are far larger: roughness = alpha instead of sqrt(alpha) gives > 10 % (checked
below); the Principled BSDF alone (its base layer darkens the diffuse by the specular albedo)
instead of Diffuse + Principled gave 7.0 % (alpha 0.2) and 5.8 % (alpha 0.5). Not caught:
Multiscatter GGX instead of GGX, 0.07 % and 0.20 % for this f0 of 0.04-0.06, below the
tolerance (the script sets GGX explicitly).
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gonio.brdf import models
from gonio.export import to_blender
from tests.export.conftest import LIGHT, SIZE, fit_record, gonio_sphere, rel_rmse

ROOT = Path(__file__).resolve().parents[2]
SCENE = Path(__file__).with_name("blender_scene.py")
SAMPLES = 64
TOLERANCE = 0.005

MODELS = {
    "schlick": models.Lambert(albedo=[0.5, 0.4, 0.3])
    + models.TorranceSparrow(
        alpha=0.2, distribution="ggx", shadowing="smith", fresnel=models.Schlick([0.04, 0.05, 0.06])
    ),
    "dielectric": models.Lambert(albedo=[0.2, 0.3, 0.5])
    + models.TorranceSparrow(
        alpha=0.05, distribution="ggx", shadowing="smith", fresnel=models.Dielectric(1.5)
    ),
    # Metallic BSDF node (Blender >= 4.3): physical conductor, and Beckmann with F82 = Schlick
    "conductor": models.Lambert(albedo=[0.1, 0.1, 0.1])
    + models.TorranceSparrow(
        alpha=0.2,
        distribution="ggx",
        shadowing="smith",
        fresnel=models.Conductor(eta=[0.143, 0.374, 1.442], k=[3.983, 2.385, 1.603]),
    ),
    "beckmann": models.Lambert(albedo=[0.3, 0.2, 0.1])
    + models.TorranceSparrow(
        alpha=0.3,
        distribution="beckmann",
        shadowing="smith",
        fresnel=models.Schlick([0.9, 0.6, 0.3]),
    ),
}


def _has_bpy(python: str) -> bool:
    probe = "import importlib.util, sys; sys.exit(importlib.util.find_spec('bpy') is None)"
    return subprocess.run([python, "-c", probe], capture_output=True, timeout=60).returncode == 0


def bpy_command() -> list[str] | None:
    """How to run a script with bpy here, or None."""
    env = os.environ.get("GONIO_BPY_PYTHON")
    if env:
        return [env]
    local = ROOT / ".venv-bpy" / "bin" / "python"
    if local.exists() and _has_bpy(str(local)):
        return [str(local)]
    if importlib.util.find_spec("bpy") is not None:
        return [sys.executable]
    blender = shutil.which("blender")
    if blender:
        return [blender, "-b", "--factory-startup", "--python-exit-code", "1", "--python"]
    return None


@pytest.fixture(scope="module")
def renders(tmp_path_factory):
    cmd = bpy_command()
    if cmd is None:
        pytest.skip("no bpy: run 'make interop' (bpy in .venv-bpy) or set GONIO_BPY_PYTHON")
    tmp = tmp_path_factory.mktemp("blender")
    args, exports = [], {}
    for key, model in MODELS.items():
        e = to_blender(fit_record(model))
        (script,) = e.write(tmp / f"{key}.py")
        args += [str(script), str(tmp / f"{key}.npy")]
        exports[key] = e
    light = [str(x) for x in LIGHT]
    sep = ["--"] if cmd[-1] == "--python" else []
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    run = subprocess.run(
        [*cmd, str(SCENE), *sep, str(SIZE), str(SAMPLES), *light, *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert run.returncode == 0, run.stderr[-2000:]
    return {k: (exports[k], np.load(tmp / f"{k}.npy").astype(np.float64)) for k in MODELS}


@pytest.mark.parametrize("key", list(MODELS))
def test_cycles_matches_gonio(renders, key):
    e, img = renders[key]
    assert e.mapping == "exact"
    assert rel_rmse(img, gonio_sphere(MODELS[key])) <= TOLERANCE


def test_roughness_is_sqrt_alpha(renders):
    e, img = renders["schlick"]
    assert e.params["Principled BSDF"]["Roughness"] == pytest.approx(np.sqrt(0.2))
    # A renderer given roughness = alpha would render alpha^2: far outside the tolerance.
    spec = MODELS["schlick"].lobes[1]
    wrong = MODELS["schlick"].lobes[0] + spec.replace(alpha=0.2**2)
    assert rel_rmse(img, gonio_sphere(wrong)) > 20 * TOLERANCE
