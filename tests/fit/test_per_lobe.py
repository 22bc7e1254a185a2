"""Models with per-lobe parameters (Lafortune) fit as one model, every lobe at once."""

import numpy as np
import pytest

from gonio import fit
from gonio.brdf import frames, models
from gonio.brdf.measured import MeasuredSamples
from gonio.brdf.tabulated import Channels
from gonio.fit.params import Layout


def _samples(truth, n=3000, seed=1, rel_noise=0.01):
    rng = np.random.default_rng(seed)

    def dirs():
        th = np.arccos(np.sqrt(rng.random(n))) * 0.95
        return np.asarray(frames.spherical_to_direction(th, rng.random(n) * 2 * np.pi))

    wi, wo = dirs(), dirs()
    f = np.asarray(truth.f(wi, wo))
    sig = rel_noise * f + 1e-3
    noisy = f + sig * rng.standard_normal(f.shape)
    return MeasuredSamples(wi=wi, wo=wo, values=noisy, sigma=sig, channels=Channels.rgb())


def test_layout_sizes_per_lobe_parameters_by_the_lobe_count():
    m = models.Lafortune(cx=[-1.0, -0.5], cy=[-1.0, -0.5], cz=[1.0, 0.7], n=[30.0, 3.0],
                         rho_s=[0.5, 0.1], rho_d=0.1)  # fmt: skip
    lay = Layout(m, channels=3)
    shapes = {e.key: e.shape for e in lay.entries}
    assert shapes == {"cx": (2,), "cy": (2,), "cz": (2,), "n": (2,), "rho_s": (2, 3),
                      "rho_d": (3,)}  # fmt: skip
    assert lay.size == 4 * 2 + 6 + 3
    names = lay.flat_names(("R", "G", "B"))
    assert "n[lobe1]" in names and "rho_s[lobe1,B]" in names
    # u -> model -> u round trip keeps every lobe's values where they were
    u = lay.initial()
    np.testing.assert_allclose(np.asarray(lay.to_model(u).n), [30.0, 3.0], rtol=1e-2)


def test_two_lobe_lafortune_recovers_both_exponents_and_round_trips(tmp_path):
    truth = models.Lafortune(cx=[-1.0, -0.6], cy=[-1.0, -0.6], cz=[1.0, 0.7], n=[40.0, 5.0],
                             rho_s=[0.5, 0.15], rho_d=[0.1, 0.15, 0.2])  # fmt: skip
    m, _, _ = fit.presets.build("lafortune-2")
    r = fit.fit(_samples(truth), model=m, uncertainty="laplace")
    np.testing.assert_allclose(r.params["n"], [40.0, 5.0], rtol=0.02)
    np.testing.assert_allclose(np.asarray(r.params["rho_d"]), [0.1, 0.15, 0.2], atol=0.01)
    lo, hi = (np.asarray(x) for x in r.intervals()["n"])
    assert lo.shape == (2,) and np.all(lo < hi)
    path = tmp_path / "laf.json"
    r.save(path)
    back = fit.load_model(path)
    assert isinstance(back, models.Lafortune)
    assert np.asarray(back.rho_s).shape == (2, 3)


def test_bad_per_lobe_shape_is_a_fit_error():
    from gonio.errors import FitError

    m = models.Lafortune(cx=[-1.0, -0.5], cy=[-1.0, -0.5], cz=[1.0, 0.7], n=[30.0, 3.0],
                         rho_s=[[0.5, 0.4], [0.1, 0.1]])  # fmt: skip
    with pytest.raises(FitError, match="rho_s"):
        Layout(m, channels=3)
