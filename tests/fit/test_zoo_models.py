"""The models beyond the core set fit through the same generic path (no per-model code)."""

import numpy as np

from gonio import fit
from gonio.brdf import frames, models
from gonio.brdf.measured import MeasuredSamples
from gonio.brdf.tabulated import Channels


def test_htsg_recovers_roughness_and_autocorrelation_length():
    rng = np.random.default_rng(2)
    alu = models.Conductor(eta=[1.2, 0.96, 0.62], k=[7.3, 6.7, 5.4])
    truth = models.HTSG(sigma0=0.3, tau=3.0, fresnel=alu)
    n = 1500

    def dirs():
        th = np.arccos(np.sqrt(rng.random(n))) * 0.95
        return np.asarray(frames.spherical_to_direction(th, rng.random(n) * 2 * np.pi))

    wi, wo = dirs(), dirs()
    f = np.asarray(truth.f(wi, wo))
    sig = 0.02 * f + 1e-4
    data = MeasuredSamples(wi=wi, wo=wo, values=f + sig * rng.standard_normal(f.shape),
                           sigma=sig, channels=Channels.rgb())  # fmt: skip
    fixed = {"fresnel.eta": [1.2, 0.96, 0.62], "fresnel.k": [7.3, 6.7, 5.4]}
    r = fit.fit(data, model=models.HTSG(sigma0=0.2, tau=2.0, fresnel=alu), fixed=fixed,
                n_starts=2)  # fmt: skip
    assert abs(r.params["sigma0"] - 0.3) < 0.01
    assert abs(r.params["tau"] - 3.0) < 0.05
