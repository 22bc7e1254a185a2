"""EXR images and half/diff table slices."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gonio.brdf.tabulated import Axis, Channels, TabulatedBRDF
from gonio.errors import FormatError, ParameterError
from gonio.io import exr, save


def _table(channels=None):
    axes = (
        Axis("theta_h", 9, 0, math.pi / 2, "sqrt"),
        Axis("theta_d", 7, 0, math.pi / 2),
        Axis("phi_d", 5, 0, math.pi, periodic=True),
    )
    rng = np.random.default_rng(0)
    c = 3 if channels is None else len(channels)
    return TabulatedBRDF(
        values=rng.random((9, 7, 5, c)),
        axes=axes,
        mask=rng.random((9, 7, 5)) > 0.3,
        channels=channels,
    )


def test_image_round_trip(tmp_path):
    img = np.random.default_rng(1).random((6, 8, 3)).astype(np.float32)
    exr.write_exr(tmp_path / "i.exr", img)
    back, names = exr.read_exr(tmp_path / "i.exr")
    assert names == ["R", "G", "B"]
    np.testing.assert_array_equal(back, img)


@pytest.mark.parametrize("channels", [None, Channels.spectral([450.0, 550.0, 650.0, 700.0])])
def test_table_slices_round_trip(tmp_path, channels):
    t = _table(channels)
    p = tmp_path / "t.exr"
    save(t, p)
    d = exr.read_table_slices(p)
    assert d["values"].shape == t.values.shape
    assert np.array_equal(d["mask"], t.mask)
    np.testing.assert_array_equal(d["values"][t.mask], t.values[t.mask])
    np.testing.assert_allclose(d["phi_d"], t.axes[2].nodes(), rtol=1e-8)
    assert exr.write_table_slices(t, tmp_path / "e.exr", every=2) == 3


def test_exr_errors(tmp_path):
    with pytest.raises(ParameterError):
        exr.write_exr(tmp_path / "x.exr", np.zeros(5))
    p = tmp_path / "bad.exr"
    p.write_bytes(b"\x76\x2f\x31\x01" + b"\0" * 40)
    with pytest.raises(FormatError):
        exr.read_exr(p)
    exr.write_exr(tmp_path / "plain.exr", np.zeros((2, 2, 3)))
    with pytest.raises(FormatError, match="not a gonio table slice"):
        exr.read_table_slices(tmp_path / "plain.exr")
