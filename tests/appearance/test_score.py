"""The appearance score on materials with a known answer (small images, few samples)."""

from __future__ import annotations

import numpy as np
import pytest

from gonio import appearance
from gonio.brdf import models
from gonio.errors import ParameterError

RES, SAMPLES = 24, 7  # small and fast; the rules do not depend on the size


@pytest.fixture(scope="module")
def lambert_ref():
    return appearance.Reference.of(models.Lambert([0.5, 0.4, 0.3]), RES, SAMPLES)


def test_identical_material_scores_zero(lambert_ref):
    s = appearance.score(lambert_ref, models.Lambert([0.5, 0.4, 0.3]))
    for key in appearance.KEYS[:-2]:
        assert s[key] == 0.0, key
    assert s["resolution_px"] == RES and s["env_samples"] == SAMPLES


def test_scaled_lambert_relative_l1_is_the_scale_difference(lambert_ref):
    s = appearance.score(lambert_ref, models.Lambert([0.5 * 1.3, 0.4 * 1.3, 0.3 * 1.3]))
    for i in appearance.IMAGES:
        # the studio image is linear in f with the same samples, so it scales exactly too
        assert s[f"rel_l1_{i}"] == pytest.approx(0.3, rel=1e-5), i
        assert 0.0 < s[f"hdr_flip_{i}"] < 1.0, i


def test_point_light_images_are_exact(lambert_ref):
    im = lambert_ref.images
    px = im.pixels
    for a in appearance.LIGHT_ANGLES_DEG:
        light = np.array([np.sin(np.radians(a)), 0.0, np.cos(np.radians(a))])
        cos = np.maximum(px.normal @ light, 0.0)
        want = np.array([0.5, 0.4, 0.3]) / np.pi * cos[:, None]
        got = im.images[f"{a:g}"].reshape(-1, 3)[px.index]
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-7)
    assert not im.images["0"][~px.mask].any()


@pytest.mark.slow
def test_studio_estimate_of_a_lambertian_sphere_converges():
    # f = a / pi: the pixel is a / pi * integral L cos over the hemisphere, estimated with 70
    # and 700 samples per pixel and different seeds; the sums over the sphere agree within 3 %
    # (measured: 0.5 %; a biased stratification gave 12 %)
    lam = models.Lambert(0.5)
    lo = appearance.render_images(lam, RES, 10 * SAMPLES).images["env"]
    hi = appearance.render_images(lam, RES, 100 * SAMPLES, seed=1).images["env"]
    assert lo.sum() == pytest.approx(hi.sum(), rel=0.03)


def test_bad_arguments_are_one_line_errors():
    with pytest.raises(ParameterError, match="multiple of 7"):
        appearance.render_images(models.Lambert(0.5), RES, 10)
    with pytest.raises(ParameterError, match="resolution"):
        appearance.render_images(models.Lambert(0.5), 4, SAMPLES)
