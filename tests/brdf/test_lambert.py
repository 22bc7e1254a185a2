import numpy as np
import pytest

from gonio.brdf import models
from gonio.errors import ParameterError
from tests.brdf import model_checks as mc


def test_value_and_channels():
    m = models.Lambert(albedo=[0.5, 0.4, 0.3])
    v = np.asarray(m.f([0, 0, 1.0], [0.6, 0, 0.8]))
    np.testing.assert_allclose(v, np.array([0.5, 0.4, 0.3]) / np.pi)
    assert m.channels == 3


@pytest.mark.parametrize("albedo", [0.0, 0.5, 1.0, [0.9, 0.2, 0.05]])
def test_properties(albedo):
    m = models.Lambert(albedo)
    mc.check_properties(m)


def test_albedo_is_exact():
    a = mc.check_albedo_at_most_one(models.Lambert([1.0, 0.5]))
    np.testing.assert_allclose(a, np.tile([1.0, 0.5], (4, 1)), rtol=1e-4)


def test_chi2():
    mc.check_chi2(models.Lambert(0.7), theta_o_deg=(0, 45, 85), n_tests=3)


def test_chi2_detects_a_wrong_pdf():
    class Wrong(models.Lambert):
        def _pdf(self, wi, wo):  # claims uniform sampling while drawing cosine-weighted
            return 0.0 * wi[..., 2] + 1.0 / (2 * np.pi)

    with pytest.raises(AssertionError, match=r"differs|p ="):
        mc.check_chi2(Wrong(0.7), theta_o_deg=(30,), n_tests=1, n_samples=200_000)


@pytest.mark.parametrize("bad", [-0.1, 1.5, float("nan"), [[0.1]], "abc"])
def test_bad_parameters_raise(bad):
    with pytest.raises(ParameterError, match="albedo"):
        models.Lambert(albedo=bad)


def test_sum_of_lobes_and_serialization():
    m = models.Lambert([0.2, 0.3, 0.4]) + models.Lambert(0.1)
    assert isinstance(m, models.Sum)
    assert set(m.params()) == {"lambert.albedo", "lambert2.albedo"}
    np.testing.assert_allclose(
        np.asarray(m.f([0, 0, 1.0], [0, 0, 1.0])), (np.array([0.2, 0.3, 0.4]) + 0.1) / np.pi
    )
    again = models.Node.from_dict(m.to_dict())
    assert repr(again) == repr(m)
    mc.check_sample_weight_consistent(m)
    mc.check_chi2(m, theta_o_deg=(60,), n_tests=1)
    with pytest.raises(ParameterError):
        models.Lambert([0.1, 0.2]) + models.Lambert([0.1, 0.2, 0.3])
