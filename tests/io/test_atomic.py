"""The one atomic-write helper: outputs get the mode a plain open() gives them under the umask,
a failed write leaves nothing behind, and every kind of output goes through it."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import numpy as np
import pytest

from gonio.errors import FormatError
from gonio.io.atomic import atomic_output


@pytest.fixture
def umask_022():
    old = os.umask(0o022)
    try:
        yield
    finally:
        os.umask(old)


def _mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def test_atomic_output_mode_and_cleanup(tmp_path, umask_022):
    dest = tmp_path / "a.txt"
    with atomic_output(dest) as tmp:
        tmp.write_text("x")
    assert dest.read_text() == "x" and _mode(dest) == 0o644
    with pytest.raises(RuntimeError), atomic_output(dest) as tmp:
        tmp.write_text("half")
        raise RuntimeError("interrupted")
    assert dest.read_text() == "x"  # the old file is left as it was
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt"]  # no temporary left
    with pytest.raises(FormatError, match="does not exist"), atomic_output(tmp_path / "no" / "b"):
        pass
    with atomic_output(tmp_path / "new" / "b.txt", make_parents=True) as tmp:
        tmp.write_text("y")
    assert _mode(tmp_path / "new" / "b.txt") == 0o644


def test_every_output_kind_honours_the_umask(tmp_path, umask_022, monkeypatch):
    """PNG, JSON, EXR, HDF5 and HTML outputs are 0644 under umask 022 (not mkstemp's 0600)."""
    from gonio import io
    from gonio.brdf import models
    from gonio.brdf.tabulated import TabulatedBRDF
    from gonio.demo import report
    from gonio.io.exr import write_exr
    from gonio.io.fit_result import write_json
    from gonio.render.output import write_png

    img = np.random.default_rng(0).random((8, 8, 3)).astype(np.float32)
    outputs = [
        write_png(tmp_path / "sphere.png", img),
        write_json({"a": 1}, tmp_path / "fit.json"),
    ]
    write_exr(tmp_path / "sphere.exr", img, ["R", "G", "B"])
    outputs.append(tmp_path / "sphere.exr")
    t = TabulatedBRDF.from_model(
        models.Lambert(albedo=0.5), axes=TabulatedBRDF.default_axes(n_theta_h=4, n_theta_d=4)
    )
    io.save(t, tmp_path / "t.brdf.h5")
    outputs.append(tmp_path / "t.brdf.h5")
    monkeypatch.setattr(report, "render_html", lambda summary: "<!DOCTYPE html>\n")
    outputs.append(report.write_report(tmp_path / "index.html", None))
    modes = {Path(p).suffix: oct(_mode(Path(p))) for p in outputs}
    assert modes == {s: "0o644" for s in (".png", ".json", ".exr", ".h5", ".html")}
