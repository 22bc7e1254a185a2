"""A malformed RGL tensor file is refused in one line naming the file and the field; nothing is
written."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.cli import main
from gonio.errors import FormatError
from gonio.io import load, rgl
from tests.conftest import shared_file


def _fields():
    return rgl.parse_tensor_file(shared_file("rgl", "paper_white_rgb.bsdf").read_bytes())


def _nan(name):
    def edit(f):
        a = f[name].copy()
        a.reshape(-1)[a.size // 2] = np.nan
        f[name] = a

    return edit


def _drop(name):
    def edit(f):
        del f[name]

    return edit


def _negative_luminance(f):
    a = f["luminance"].copy()
    a[0, 3, 10, 10] = -0.5
    f["luminance"] = a


def _shape(name, cut):
    def edit(f):
        f[name] = np.ascontiguousarray(f[name][cut])

    return edit


CASES = {
    "missing luminance": (_drop("luminance"), "luminance"),
    "missing vndf": (_drop("vndf"), "vndf"),
    "missing theta_i": (_drop("theta_i"), "theta_i"),
    "NaN in rgb": (_nan("rgb"), "rgb"),
    "NaN in sigma": (_nan("sigma"), "sigma"),
    "negative luminance": (_negative_luminance, "luminance"),
    "vndf theta count": (_shape("vndf", np.s_[:, :5]), "vndf"),
    "luminance grid": (_shape("luminance", np.s_[:, :, :16, :16]), "luminance"),
    "rgb channels": (_shape("rgb", np.s_[:, :, :2]), "rgb"),
    "theta_i length": (_shape("theta_i", np.s_[:6]), "theta_i"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_bad_field_is_one_line_naming_file_and_field(case, tmp_path, capsys):
    edit, field = CASES[case]
    fields = _fields()
    edit(fields)
    src = tmp_path / "bad.bsdf"
    src.write_bytes(rgl.tensor_file_bytes(fields))
    with pytest.raises(FormatError) as exc:
        load(src)
    msg = str(exc.value)
    assert "\n" not in msg and str(src) in msg and repr(field) in msg, msg
    for out in (tmp_path / "out.brdf.h5", tmp_path / "out.binary"):
        assert main(["convert", str(src), str(out), "--quiet"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("gonio: ") and repr(field) in err[0], err
        assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.bsdf"]
