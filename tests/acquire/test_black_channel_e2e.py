"""End-to-end: a real material with a black colour channel, acquired on the simulated rig.

RGL's ``vch_golden_yellow`` has (after the ground truth clamps the spectral-to-RGB conversion's
negative values) no blue at all at the specular peak, where red and green are ~30 times the
white reference. The blue pixels there sit between red and green pixels that saturate in every
exposure but the shortest; their value must carry the noise floor of the exposures in which they
are really usable, or that single black value outweighs the rest of the blue channel in the fit.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import shared_file


@pytest.mark.slow
def test_black_blue_at_the_specular_peak_keeps_a_real_sigma_and_does_not_steer_the_fit(tmp_path):
    from gonio import io
    from gonio.acquire.engine import acquire
    from gonio.demo.materials import table_material
    from gonio.demo.pipeline import rig_text
    from gonio.fit import fit
    from gonio.fit.data import prepare

    material = table_material(shared_file("rgl", "vch_golden_yellow_rgb.bsdf"))
    rig = tmp_path / "rig.toml"
    rig.write_text(rig_text(material))
    summary = acquire(tmp_path / "run", rig, "demo-quick", progress=False)
    assert summary.complete, summary.table_note
    samples = io.load(tmp_path / "run" / "table.brdf.h5")
    values, sigma = np.asarray(samples.values), np.asarray(samples.sigma)
    assert np.all(np.isfinite(sigma) & (sigma > 0))

    peak = int(np.argmax(values[:, 0]))
    assert values[peak, 0] > 1.0 and abs(values[peak, 2]) < 1e-3  # bright red, black blue
    # Red there is ~4e7 DN/s, so only frames up to ~0.4 ms leave the blue pixels' neighbours
    # unsaturated: a floor of ~1 DN / 0.4 ms per pixel, 7e-4 1/sr against the reference's
    # ~1.3e6 DN/s, ~2e-4 over the spot. Taking the 2 s frame's floor instead gave 6e-8.
    assert sigma[peak, 2] > 5e-5, sigma[peak]

    r = fit(prepare(samples, name=material.name), model="lambert+ts", seed=0)
    blue_albedo = float(np.asarray(r.params["lambert.albedo"])[2])
    # The diffuse blue level of the other configurations (median value times pi) sets the blue
    # albedo, within a factor of two; the black peak used to pin it at its lower bound (2e-5).
    diffuse = np.pi * float(np.median(values[:, 2]))
    assert 0.5 * diffuse < blue_albedo < 2.0 * diffuse, (blue_albedo, diffuse)
    assert 0.05 < float(r.params["torrancesparrow.alpha"]) < 0.9
