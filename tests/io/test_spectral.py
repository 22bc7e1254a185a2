"""CIE 1931 -> XYZ -> linear sRGB, checked against published colorimetric constants."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.errors import ParameterError
from gonio.io import spectral


def test_d65_white_point_chromaticity():
    # CIE: D65 with the 2-degree observer has (x, y) = (0.31271, 0.32902)
    xyz = spectral.spectrum_to_xyz(np.ones(95), spectral.WAVELENGTHS_NM, "D65")
    x, y = xyz[0] / xyz.sum(), xyz[1] / xyz.sum()
    assert x == pytest.approx(0.31271, abs=2e-4) and y == pytest.approx(0.32902, abs=2e-4)


def test_equal_energy_white_is_one_third():
    xyz = spectral.spectrum_to_xyz(np.ones(95), spectral.WAVELENGTHS_NM, "E")
    np.testing.assert_allclose(xyz / xyz.sum(), 1 / 3, atol=5e-4)


def test_cmf_published_values():
    # CIE 1931 2-degree table: ybar(555) = 1.0000, xbar(600) = 1.0622, zbar(450) = 1.7721
    c = spectral.cmf(np.array([555.0, 600.0, 450.0]))
    assert c[0, 1] == pytest.approx(1.0, abs=2e-3)
    assert c[1, 0] == pytest.approx(1.0622, abs=1e-3)
    assert c[2, 2] == pytest.approx(1.7721, abs=1e-3)


def test_flat_spectrum_is_neutral_srgb_under_d65_on_cornell_sampling():
    wl = np.arange(400.0, 701.0, 10.0)  # Cornell's 31 wavelengths
    rgb = spectral.spectrum_to_linear_srgb(np.full((2, 31), 0.5), wl, "D65")
    np.testing.assert_allclose(rgb, 0.5, rtol=0.01)


def test_monochromatic_lights_land_in_the_right_channel():
    wl = np.arange(400.0, 701.0, 10.0)
    for peak, ch in ((450.0, 2), (530.0, 1), (620.0, 0)):
        s = np.exp(-0.5 * ((wl - peak) / 15) ** 2)
        rgb = spectral.spectrum_to_linear_srgb(s, wl, "E")
        assert np.argmax(rgb) == ch, (peak, rgb)


def test_linearity_and_bad_input():
    wl = np.arange(400.0, 701.0, 10.0)
    rng = np.random.default_rng(0)
    a, b = rng.random(31), rng.random(31)
    np.testing.assert_allclose(
        spectral.spectrum_to_linear_srgb(2 * a + b, wl),
        2 * spectral.spectrum_to_linear_srgb(a, wl) + spectral.spectrum_to_linear_srgb(b, wl),
    )
    with pytest.raises(ParameterError):
        spectral.spectrum_to_xyz(a, wl, "A")
    with pytest.raises(ParameterError):
        spectral.spectrum_to_xyz(a, wl[::-1])
    with pytest.raises(ParameterError):
        spectral.spectrum_to_xyz(np.ones(2), np.array([1000.0, 1100.0]))


def test_one_spectral_to_rgb_matrix_for_renderer_exporter_and_rgl_reader():
    """The matrix is the documented XYZ weights times the sRGB matrix, and a flat spectrum
    maps to (c, c, c) under D65 (the renderer's, exporter's and RGL reader's conversion)."""
    wl = np.arange(400.0, 701.0, 10.0)
    m = spectral.spectral_to_rgb_matrix(wl)
    expected = spectral.spectral_weights(wl, "D65") @ spectral.XYZ_TO_LINEAR_SRGB.T
    np.testing.assert_array_equal(m, expected)
    np.testing.assert_allclose(np.full(wl.size, 0.4) @ m, [0.4, 0.4, 0.4], atol=3e-3)
    e = spectral.spectral_weights(wl, "E") @ spectral.XYZ_TO_LINEAR_SRGB.T
    np.testing.assert_array_equal(spectral.spectral_to_rgb_matrix(list(wl), "E"), e)


@pytest.mark.parametrize(
    ("names", "expected"),
    [
        (["450nm", "550nm", "650nm"], [450.0, 550.0, 650.0]),
        ([" 400 nm", "532.5nm"], [400.0, 532.5]),
        (["450nm"], None),  # one wavelength is not a spectrum
        (["R", "G", "B"], None),
        (["450nm", "G"], None),
        (["550nm", "450nm"], None),  # not increasing
        (None, None),
        ((), None),
    ],
)
def test_wavelengths_from_channel_names(names, expected):
    wl = spectral.wavelengths_from_names(names)
    if expected is None:
        assert wl is None
    else:
        np.testing.assert_array_equal(wl, expected)
