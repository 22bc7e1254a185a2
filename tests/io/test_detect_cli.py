"""Format detection by content, and the `gonio info` / `gonio convert` commands."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gonio.cli import main
from gonio.io import detect_format, load, merl
from tests.conftest import shared_file

ROOT = Path(__file__).resolve().parents[2]
GRIDDED = ROOT / "data-schema" / "examples" / "tiny-gridded.brdf.h5"


def test_content_wins_over_extension(tmp_path):
    for src, fmt in (
        (shared_file("rgl", "paper_white_rgb.bsdf"), "rgl"),
        (shared_file("cornell", "cayman.brdf"), "cornell"),
        (shared_file("alta", "pink-felt-1d.alta"), "alta"),
        (GRIDDED, "native"),
    ):
        q = tmp_path / f"renamed_{fmt}.binary"
        shutil.copy(src, q)
        assert detect_format(q) == fmt
    m = tmp_path / "table.txt"
    m.write_bytes(merl.merl_bytes(np.ones((90, 90, 180, 3))))
    assert detect_format(m) == "merl"


def test_info_json(capsys):
    assert main(["info", str(GRIDDED), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["kind"] == "gridded" and s["format"] == "native"
    t = load(GRIDDED)
    assert s["valid_fraction"] == pytest.approx(float(t.mask.mean()))
    assert s["value_range"]["max"] == pytest.approx(float(t.values[t.mask].max()))
    assert s["grid"]["shape"] == list(t.values.shape[:-1])
    assert s["provenance"]["rig"]["name"] == "example-rig"
    assert s["size_bytes"] == GRIDDED.stat().st_size and s["compression_ratio"] > 0
    assert main(["info", str(shared_file("cornell", "cayman.brdf"))]) == 0
    assert "1439" in capsys.readouterr().out


def test_convert_cornell_to_native_rgb_and_lossy(tmp_path, capsys):
    src = shared_file("cornell", "garnet_red.brdf")
    out = tmp_path / "g.brdf.h5"
    assert main(["convert", str(src), str(out), "--color", "rgb", "--quiet"]) == 0
    s = load(out)
    assert s.channels.kind == "rgb" and len(s) == 1439
    # lossy applies to gridded tables: a scattered input is refused, nothing written
    bad = tmp_path / "l.brdf.h5"
    assert main(["convert", str(src), str(bad), "--lossy", "0.5%", "--quiet"]) == 2
    assert not bad.exists()
    assert main(["convert", str(src), str(tmp_path / "g.binary"), "--quiet"]) == 2
    assert not (tmp_path / "g.binary").exists()
    tab = tmp_path / "t.brdf.h5"
    assert main(["convert", str(GRIDDED), str(tab), "--lossy", "0.5%", "--quiet"]) == 0
    assert load(tab).values.shape == load(GRIDDED).values.shape


@pytest.mark.slow
def test_convert_rgl_to_merl(tmp_path):
    src = shared_file("rgl", "acrylic_felt_green_rgb.bsdf")
    out = tmp_path / "felt.binary"
    assert main(["convert", str(src), str(out), "--quiet"]) == 0
    t = load(out)
    from gonio.io.rgl_measured import load_rgl

    b = load_rgl(src)
    wi, wo = t.node_directions()
    idx = np.flatnonzero(t.mask.reshape(-1))[::9973]
    direct = np.asarray(b.f(wi.reshape(-1, 3)[idx], wo.reshape(-1, 3)[idx]))
    np.testing.assert_allclose(t.values.reshape(-1, 3)[idx], direct, rtol=1e-5)


@pytest.mark.parametrize(
    "make",
    [
        lambda d: d,  # a directory
        lambda d: (d / "trunc.bsdf", (d / "trunc.bsdf").write_bytes(b"tensor_file\x00\x01"))[0],
        lambda d: (d / "x.binary", (d / "x.binary").write_bytes(b"\x01\x00"))[0],
        lambda d: (
            d / "nan.alta",
            (d / "nan.alta").write_text(
                "#DIM 1 3\n#PARAM_IN COS_TH\n#PARAM_OUT RGB_COLOR\n0.5 nan 1 1\n"
            ),
        )[0],
        lambda d: d / "missing.brdf.h5",
    ],
)
def test_cli_bad_input_exits_2_without_traceback_or_output(tmp_path, make, capsys):
    src = make(tmp_path)
    out = tmp_path / "out.brdf.h5"
    for cmd in (["info", str(src)], ["convert", str(src), str(out)]):
        assert main(cmd) == 2
        err = capsys.readouterr().err
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("gonio: "), err
        assert str(src) in lines[0]
    assert not out.exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".out")] == []


def test_console_script_reports_a_directory_in_one_line(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "gonio", "info", str(tmp_path)],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.strip() == f"gonio: {tmp_path}: is a directory, expected a file"
