"""RGL tensor files of issue #45 (scaled angles, an anisotropic-looking ``phi_i``, thousands of
wavelengths, an NDF or ``sigma`` that scale the values beyond any reflectance): the console
script refuses each in one line naming the field and writes nothing; the writer refuses the same
fields; what ``convert`` writes, ``info`` reads."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.errors import FormatError
from gonio.io import rgl
from gonio.io.rgl_write import write_rgl
from tests.conftest import shared_file
from tests.console_script import assert_clean, run


def _fields() -> dict[str, np.ndarray]:
    return rgl.parse_tensor_file(shared_file("rgl", "paper_white_rgb.bsdf").read_bytes())


def _scaled(name: str, factor: float):
    def edit(f):
        f[name] = f[name] * np.float32(factor)

    return edit


def _three_azimuths(f):
    """``phi_i`` of 3 entries over [0, 2] rad and every table repeated to match."""
    f["phi_i"] = np.array([0.0, 1.0, 2.0], np.float32)
    for name in ("vndf", "luminance", "rgb"):
        f[name] = np.ascontiguousarray(np.concatenate([f[name]] * 3))


def _many_wavelengths(f, n: int = 2000):
    """A spectral file of ``n`` wavelengths over 360-1000 nm (flat spectra of the green
    channel), on a 4 x 4 colour grid."""
    green = f.pop("rgb")[:, :, 1:2, :4, :4]
    f["spectra"] = np.ascontiguousarray(np.repeat(green, n, axis=2))
    f["luminance"] = np.ascontiguousarray(f["luminance"][:, :, :4, :4])
    f["wavelengths"] = np.linspace(360.0, 1000.0, n).astype(np.float32)


def _sigma(value: float):
    def edit(f):
        f["sigma"] = np.full_like(f["sigma"], value)

    return edit


CASES = {
    "theta_i x 1e-30": (_scaled("theta_i", 1e-30), "theta_i"),
    "phi_i of 3 entries": (_three_azimuths, "phi_i"),
    "2000 wavelengths": (_many_wavelengths, "wavelengths"),
    "sigma 1e-38": (_sigma(1e-38), "sigma"),
    "sigma 1e-45": (_sigma(1e-45), "sigma"),
}


def _write(tmp_path, edit) -> tuple:
    fields = _fields()
    edit(fields)
    src = tmp_path / "bad.bsdf"
    src.write_bytes(rgl.tensor_file_bytes(fields))
    return src, fields


def _refused_in_one_line(proc, field: str) -> None:
    assert "Traceback" not in proc.stderr, proc.stderr
    assert proc.returncode != 0, proc.stdout
    err = proc.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("gonio: ") and repr(field) in err[0], err


@pytest.mark.parametrize("case", list(CASES))
def test_console_script_refuses_the_file_in_one_line_and_writes_nothing(case, tmp_path):
    edit, field = CASES[case]
    src, _ = _write(tmp_path, edit)
    _refused_in_one_line(run("info", src, timeout=60), field)
    out = tmp_path / "out.brdf.h5"
    _refused_in_one_line(run("convert", src, out, "--quiet", timeout=60), field)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.bsdf"]


@pytest.mark.parametrize("case", list(CASES))
def test_writer_refuses_the_same_fields(case, tmp_path):
    edit, field = CASES[case]
    fields = _fields()
    edit(fields)
    out = tmp_path / "out.bsdf"
    with pytest.raises(FormatError, match=repr(field)):
        write_rgl(rgl.RGLFile(fields=fields), out)
    assert not out.exists()


def test_convert_refuses_a_table_its_reader_would_refuse(tmp_path):
    """An NDF of 1.7e9 over ten columns passes the load bound (colour x ndf / (4 sigma) below
    1e10) but tabulates beyond 1e10 1/sr near the horizon: convert refused to write what
    ``gonio info`` refuses to read."""

    def edit(f):
        f["ndf"] = f["ndf"].copy()
        f["ndf"][:, 60:70] = 1.7e9

    src, _ = _write(tmp_path, edit)
    assert_clean(run("info", src, timeout=120))
    out = tmp_path / "out.brdf.h5"
    proc = run("convert", src, out, "--quiet", timeout=300)
    assert "Traceback" not in proc.stderr and proc.returncode != 0, proc.stderr
    err = proc.stderr.strip().splitlines()
    assert len(err) == 1 and "tabulated f_r" in err[0] and "beyond any reflectance" in err[0], err
    assert not out.exists()


def test_real_files_still_convert_and_read_back(tmp_path):
    """The bounds leave a database file alone: converted, the table reads back."""
    out = tmp_path / "paper.brdf.h5"
    assert_clean(run("convert", shared_file("rgl", "paper_white_rgb.bsdf"), out, "--quiet"))
    assert_clean(run("info", out))
