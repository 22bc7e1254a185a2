"""The sphere's table encoding (gonio.view.encode): float16 within 2**-11, phi_d folding by the
table's rule, isotropy detection, and the page data JSON-safe."""

from __future__ import annotations

import math

import numpy as np

from gonio.view import encode


def test_float16_encoding_is_within_2_to_the_minus_11_over_eight_decades():
    # float16's normal range is 29 binades (8.7 decades) below the scaled peak; further down
    # values are subnormal and their relative error grows (encoding_error reports it)
    rng = np.random.default_rng(0)
    values = 10.0 ** rng.uniform(-5, 3, (4000, 3))
    k = encode.float16_scale(values)
    enc = (values * 2.0**k).astype("<f2")
    assert np.max(np.abs(values)) * 2.0**k <= 2**15
    assert encode.encoding_error(values, enc, k) <= 2.0**-11


def test_fold_follows_the_phi_d_span():
    from gonio.brdf.grid import Axis

    assert encode.fold_of(Axis("phi_d", 8, 0.0, math.pi / 2)) == 2
    assert encode.fold_of(Axis("phi_d", 8, 0.0, math.pi, "linear", True)) == 1
    assert encode.fold_of(Axis("phi_d", 8, 0.0, 2 * math.pi, "linear", True)) == 0


def test_isotropy_is_detected():
    from gonio.brdf import models

    assert encode.is_isotropic(models.Lambert(albedo=0.5))
    aniso = models.Ward(rho_d=0.1, rho_s=0.2, alpha_x=0.05, alpha_y=0.3)
    assert not encode.is_isotropic(aniso)


def test_small_table_is_shipped_as_it_is():
    from gonio.brdf import models
    from gonio.brdf.grid import Axis
    from gonio.brdf.tabulated import TabulatedBRDF

    half = math.pi / 2
    axes = (
        Axis("theta_h", 6, 0.0, half, "sqrt"),
        Axis("theta_d", 5, 0.0, half),
        Axis("phi_d", 4, 0.0, math.pi, "linear", True),
    )
    t = TabulatedBRDF.from_model(models.Lambert(albedo=[0.2, 0.3, 0.4]), axes=axes)
    s = encode.sphere_table("t", t)
    assert s.shape == (6, 5, 4) and s.channels == 3 and s.fold == 1
    assert s.resampling_error is None and s.mask_b64 is not None  # below-horizon nodes
    assert s.encoding_error <= 2.0**-11
