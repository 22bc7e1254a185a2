import numpy as np
import pytest

from gonio.errors import FormatError
from gonio.io.dng import read_dng, write_dng


def test_round_trip_is_bit_exact(tmp_path):
    rng = np.random.default_rng(7)
    data = rng.integers(0, 16383, size=(48, 64), dtype=np.uint16)
    meta = {"joints_deg": [10.0, -20.5, 0.0, 45.0], "seed": 3}
    p = write_dng(tmp_path / "f.dng", data, exposure_s=1 / 250, black_level=512,
                  white_level=16383, meta=meta)  # fmt: skip
    frame = read_dng(p)
    assert frame.data.dtype == np.uint16
    assert np.array_equal(frame.data, data)
    assert frame.cfa == (("R", "G"), ("G", "B"))
    assert np.all(frame.black_level == 512)
    assert frame.white_level == 16383
    assert frame.exposure_s == pytest.approx(1 / 250, rel=1e-9)
    assert frame.meta == meta
    masks = frame.channel_masks()
    assert masks["R"][0, 0] and masks["G"][0, 1] and masks["G"][1, 0] and masks["B"][1, 1]
    assert masks["G"].sum() == data.size // 2


@pytest.mark.parametrize("cfa", ["GBRG", "BGGR", "GRBG"])
def test_other_bayer_layouts(tmp_path, cfa):
    data = np.arange(32 * 48, dtype=np.uint16).reshape(32, 48)
    frame = read_dng(write_dng(tmp_path / "x.dng", data, exposure_s=0.5, black_level=0,
                               white_level=4095, cfa=cfa))  # fmt: skip
    assert "".join(frame.cfa[0] + frame.cfa[1]) == cfa
    assert np.array_equal(frame.data, data)


def test_bad_inputs_write_nothing(tmp_path):
    with pytest.raises(FormatError, match="uint16"):
        write_dng(tmp_path / "a.dng", np.zeros((4, 4)), exposure_s=1, black_level=0, white_level=9)
    with pytest.raises(FormatError, match="even"):
        write_dng(tmp_path / "a.dng", np.zeros((3, 4), np.uint16), exposure_s=1, black_level=0,
                  white_level=9)  # fmt: skip
    assert list(tmp_path.iterdir()) == []


def test_corrupt_and_missing_files(tmp_path):
    with pytest.raises(FormatError, match="not a file"):
        read_dng(tmp_path)
    data = np.ones((32, 32), np.uint16)
    p = write_dng(tmp_path / "c.dng", data, exposure_s=0.01, black_level=0, white_level=4095)
    raw = p.read_bytes()
    (tmp_path / "t.dng").write_bytes(raw[:100])
    with pytest.raises(FormatError):
        read_dng(tmp_path / "t.dng")
    (tmp_path / "z.dng").write_bytes(b"not a raw file at all" * 10)
    with pytest.raises(FormatError):
        read_dng(tmp_path / "z.dng")
