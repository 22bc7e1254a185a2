"""The plugin in Mitsuba's ``llvm_ad_rgb`` variant (slow: one child process, about a minute).

Mitsuba's LLVM backend aborts the process on an LLVM older than 16 (Debian 12 has 14 and 15), so
the checks run in a child (:mod:`tests.export.mitsuba_plugin_llvm`) and only where
``DRJIT_LIBLLVM_PATH`` names a library (e.g. Debian's ``libllvm19`` unpacked with
``apt-get download libllvm19 && dpkg -x libllvm19_*.deb DIR``): gonio never downloads it.
Tolerances: ``BSDF.eval`` within 1e-5 relative of gonio's ``f cos``; Mitsuba's chi-square test
at level 0.01; a Mitsuba render of each shared-data fit within 2 % relative RMSE of gonio's (the
difference is the pixel integration of highlights: Mitsuba averages 1024 stratified samples per
pixel, gonio 32 x 32 pixel centres; the child also reports the noise floor, two seeds of
Mitsuba's render against each other).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def results():
    pytest.importorskip("mitsuba", reason="mitsuba not installed (pip install -e '.[interop]')")
    lib = os.environ.get("DRJIT_LIBLLVM_PATH")
    if not lib or not Path(lib).is_file():
        pytest.skip(
            "llvm_ad_rgb needs LLVM >= 16: set DRJIT_LIBLLVM_PATH to its libLLVM.so (the "
            "system's older LLVM aborts Mitsuba's LLVM backend)"
        )
    env = dict(os.environ, PYTHONPATH=f"{ROOT / 'src'}{os.pathsep}{ROOT}")
    run = subprocess.run(
        [sys.executable, "-m", "tests.export.mitsuba_plugin_llvm"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    return json.loads(run.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_llvm_eval_is_f_cos(results):
    for name, err in results["eval_rel"].items():
        assert err <= 1e-5, (name, err)


@pytest.mark.slow
def test_llvm_mitsuba_chi2(results):
    for case, r in results["chi2"].items():
        assert r["passed"], (case, r)


@pytest.mark.slow
def test_llvm_render_matches_gonio(results):
    for case, err in results["render"].items():
        assert err <= 0.02, (case, err)
