"""``gonio info`` reports what a file means: RGL BRDF values in 1/sr, Cornell's description."""

import json
import subprocess
import sys

from tests.conftest import shared_file


def info(path):
    out = subprocess.run(
        [sys.executable, "-m", "gonio", "info", str(path), "--json"],
        capture_output=True,
        text=True,
    )
    assert out.returncode == 0 and "Traceback" not in out.stderr, out.stderr
    return json.loads(out.stdout)


def test_rgl_values_are_the_brdf_not_the_stored_tensor():
    s = info(shared_file("rgl", "paper_white_rgb.bsdf"))
    # White paper is close to Lambertian with albedo ~0.85: f ~ 0.27 1/sr. The stored tensor's
    # mean (0.85) is not a BRDF value and is kept apart, labelled.
    assert 0.2 < s["value_range"]["mean"] < 0.35
    assert s["stored_range"]["mean"] > 0.5
    assert "not 1/sr" in s["value_range_note"]


def test_cornell_description_is_the_header_not_the_section_labels():
    s = info(shared_file("cornell", "garnet_red.brdf"))
    d = s["provenance"]["source"]["description"]
    assert d == "Cornell University, Program of Computer Graphics / Garnet Red / Medium-gloss Paint"


def test_info_on_a_native_table_imports_no_heavy_library(tmp_path):
    import numpy as np

    from gonio import io
    from gonio.brdf.measured import MeasuredSamples

    w = np.tile([[0.0, 0.6, 0.8]], (4, 1))
    io.save(MeasuredSamples(w, w, np.full((4, 3), 0.2)), tmp_path / "t.brdf.h5")
    code = (
        "import sys\nfrom gonio.cli import main\n"
        f"main(['info', {str(tmp_path / 't.brdf.h5')!r}])\n"
        "print(sorted(m for m in ('jax', 'scipy', 'matplotlib') if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == "[]", out.stdout
    assert "0.2" in out.stdout  # the values are still reported
