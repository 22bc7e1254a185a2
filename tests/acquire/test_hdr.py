import numpy as np
import pytest

from gonio.acquire.hdr import Bracket, NoiseModel, merge_brackets, plan_exposures
from gonio.errors import ParameterError
from gonio.rigs.sim.sensor import SensorModel


def _scene(shape=(128, 128), lo=30.0, hi=3e6, seed=0):
    """A rate map (e-/s) spanning five decades, log-uniform."""
    rng = np.random.default_rng(seed)
    return np.exp(rng.uniform(np.log(lo), np.log(hi), shape))


def _capture(sensor, rate, times, seed, dark=False):
    out = []
    for t in times:
        dn, _ = sensor.expose(0.0 * rate if dark else rate, t, seed=seed,
                              key=("dark" if dark else "light") + str(t))  # fmt: skip
        out.append(Bracket(dn, t, float(sensor.black_level), sensor.white_level))
    return out


def test_sensor_statistics_match_the_noise_model():
    s = SensorModel()
    rate = np.full((200, 200), 5e4)
    t = 0.1
    dn, actual = s.expose(rate, t, seed=1, key="flat")
    assert actual == t
    x = dn.astype(float) - s.black_level
    mean_e = (5e4 + s.dark_current) * t
    assert x.mean() == pytest.approx(s.gain * mean_e, rel=2e-3)
    # Sample variance of 40000 values: relative standard error sqrt(2/N) ~ 0.7 %; allow 4 sigma.
    assert x.var() == pytest.approx(float(s.dn_variance(mean_e)) - 0.0, rel=0.03)
    dn2, _ = s.expose(rate, t, seed=1, key="flat")
    assert np.array_equal(dn, dn2), "same (seed, key) must give the same frame"
    dn3, _ = s.expose(rate, t, seed=2, key="flat")
    assert not np.array_equal(dn, dn3)


def test_merge_error_within_noise_model():
    s = SensorModel(shutter_error=0.0)
    noise = NoiseModel(s.gain, s.read_noise)
    rate = _scene()
    times = [1e-4, 1.6e-3, 2.56e-2, 0.4096]
    light = _capture(s, rate, times, seed=5)
    dark = [b.dn for b in _capture(s, rate, times, seed=6, dark=True)]
    res = merge_brackets(light, noise, dark=dark, shutter_precision=0.002)
    truth = s.gain * rate  # DN/s, dark current removed by the dark frames
    z = (res.rate - truth) / res.sigma
    assert np.all(np.isfinite(z))
    rms = float(np.sqrt(np.mean(z**2)))
    assert rms <= 1.2, f"merge error is {rms:.3f} x the noise-model sigma"
    # Exposure ratios estimated from the data carry counting noise that is common to all pixels
    # (here ~0.2 % from the 1e-4 s frame), which shows up as a small shared offset of z.
    assert abs(float(np.mean(z))) < 0.3
    assert res.ratio_source == ["data"] * 4


def test_exposure_ratios_estimated_from_data():
    s = SensorModel(shutter_error=0.03)
    noise = NoiseModel(s.gain, s.read_noise)
    rate = _scene(seed=3)
    times = [1e-4, 1.6e-3, 2.56e-2, 0.4096]
    actual = [s.expose(rate, t, seed=9, key="light" + str(t))[1] for t in times]
    light = _capture(s, rate, times, seed=9)
    # The scene changes by five decades from pixel to pixel, so the blooming guard would drop
    # most long frames and the spread below would measure dim pixels' noise, not the ratios.
    est = merge_brackets(light, noise, estimate_ratios=True, bloom_guard_px=0)
    trust = merge_brackets(light, noise, estimate_ratios=False, bloom_guard_px=0)
    true_ratios = np.array(actual) / actual[0]
    np.testing.assert_allclose(est.exposures_s / est.exposures_s[0], true_ratios, rtol=2e-3)
    # Relative error after normalizing the overall scale (what the white reference does).
    truth = s.gain * (rate + s.dark_current)

    def spread(r):
        q = r.rate / truth
        return float(np.std(q / np.median(q)) / np.median(r.sigma / r.rate))

    assert spread(est) < spread(trust)


def test_plan_uses_one_exposure_when_range_is_small_and_more_when_large():
    kw = dict(gain=0.25, read_noise=3.0, dark_current=2.0, full_well=6e4)
    one = plan_exposures(1e5, 3e4, **kw)
    assert len(one.exposures_s) == 1 and one.reason == "covered"
    many = plan_exposures(1e7, 100.0, snr_target=20, **kw)
    assert len(many.exposures_s) >= 3
    assert many.covered_rate_min <= 100.0
    assert all(a < b for a, b in zip(many.exposures_s, many.exposures_s[1:], strict=False))
    # the brightest rate never saturates in the shortest exposure
    assert 1e7 * many.exposures_s[0] <= 0.8 * 6e4 + 1e-9
    # and a plan that cannot reach the SNR says why
    limited = plan_exposures(1e7, 1e-3, t_max=1.0, **kw)
    assert "t_max" in limited.reason
    with pytest.raises(ParameterError):
        plan_exposures(1.0, 2.0, **kw)


def _dark_subtracted_merge(sensor, rate, times, noise, seed, **kw):
    """Light brackets and their own dark frames (independent noise), merged as the camera does."""
    light = _capture(sensor, rate, times, seed=seed)
    dark = [b.dn for b in _capture(sensor, rate, times, seed=seed + 1000, dark=True)]
    return merge_brackets(light, noise, dark=dark, **kw)


def test_black_pixels_get_the_noise_floor_of_the_longest_exposure():
    # A zero-signal patch seen in long exposures: what is left after dark subtraction is read
    # noise, the 1 DN quantization step and the dark current's shot noise, of the light frame and
    # of its dark frame. 40000 pixels are 40000 independent captures of a black value.
    s = SensorModel(dark_current=2.0)
    noise = NoiseModel(s.gain, s.read_noise, s.dark_current)
    rate = np.zeros((200, 200))
    times = [0.05, 0.5, 2.0]
    res = _dark_subtracted_merge(s, rate, times, noise, seed=11)
    assert np.all(np.isfinite(res.rate)) and np.all(res.sigma > 0)
    assert np.all(res.n_used == len(times))
    # Expected floor, from the sensor's own parameters (not the merge's code): inverse-variance
    # combination of the frames, each with the DN variance of a black light minus a dark frame.
    per_frame = [2 * float(s.dn_variance(s.dark_current * t)) / t**2 for t in times]
    floor_sigma = 1.0 / np.sqrt(sum(1.0 / v for v in per_frame))
    # Sample standard deviation of 40000 values: relative standard error 0.35 %; allow 3 %.
    empirical = float(np.std(res.rate))
    assert empirical == pytest.approx(floor_sigma, rel=0.03)
    # The merge's sigma: the shot-noise term is evaluated at each pixel's own (noisy, clipped at
    # zero) rate, so the half of the black pixels that came out positive claim a little more
    # than the floor (gain * E[max(x, 0)]: about +3.5 % in RMS here), never less.
    assert float(np.median(res.sigma)) == pytest.approx(floor_sigma, rel=0.02)
    assert float(np.min(res.sigma)) >= floor_sigma * (1 - 1e-9)
    assert floor_sigma <= float(np.sqrt(np.mean(res.variance))) <= 1.06 * floor_sigma
    # Unbiased: the mean of 40000 values within 4 standard errors of zero.
    assert abs(float(np.mean(res.rate))) < 4 * empirical / np.sqrt(rate.size)
    # The same merge without the dark current's shot noise claims ~15 % less than the scatter.
    blind = _dark_subtracted_merge(s, rate, times, NoiseModel(s.gain, s.read_noise), seed=11)
    assert float(np.sqrt(np.mean(blind.variance))) < 0.9 * empirical


def test_bright_pixels_are_not_changed_by_the_dark_noise_terms():
    # Shot noise of the signal dominates a bright pixel: adding dark current to the model moves
    # its sigma by a negligible amount, and the merged values themselves do not move.
    s = SensorModel(dark_current=2.0)
    rate = np.full((100, 100), 2e5)
    times = [1e-3, 4e-3, 1.6e-2, 6.4e-2]
    with_dark = _dark_subtracted_merge(s, rate, times, NoiseModel(s.gain, s.read_noise, 2.0), 21)
    without = _dark_subtracted_merge(s, rate, times, NoiseModel(s.gain, s.read_noise), 21)
    np.testing.assert_allclose(with_dark.rate, without.rate, rtol=1e-6)
    np.testing.assert_allclose(with_dark.sigma, without.sigma, rtol=2e-3)
    truth = s.gain * rate
    z = (with_dark.rate - truth) / with_dark.sigma
    assert float(np.std(z)) == pytest.approx(1.0, abs=0.05)


def test_neighbours_of_saturated_pixels_drop_that_frame():
    # A black column beside a column that saturates in the long frame: with the guard the black
    # pixels next to it keep only the short frames (a real sensor blooms into them there), those
    # one column further keep all frames; without the guard every black pixel keeps all frames.
    s = SensorModel(dark_current=2.0)
    noise = NoiseModel(s.gain, s.read_noise, s.dark_current)
    rate = np.zeros((64, 64))
    rate[:, 30:34] = 2e5  # e-/s: saturates at 2 s (4e5 e- > full well), not at 0.05 s
    times = [0.05, 2.0]
    guarded = _dark_subtracted_merge(s, rate, times, noise, seed=31)
    assert np.all(guarded.n_used[:, 29] == 1) and np.all(guarded.n_used[:, 34] == 1)
    assert np.all(guarded.n_used[:, 28] == 2) and np.all(guarded.n_used[:, 35] == 2)
    assert np.all(guarded.n_used[:, 30:34] == 1)
    # Their sigma is the short frame's floor, 40x the long frame's for read-noise-limited pixels.
    short_floor = np.sqrt(2 * float(s.dn_variance(s.dark_current * 0.05))) / 0.05
    assert float(np.median(guarded.sigma[:, 29])) == pytest.approx(short_floor, rel=0.02)
    assert float(np.min(guarded.sigma[:, 29])) >= short_floor * (1 - 1e-9)
    assert np.all(guarded.sigma[:, 28] < 0.1 * short_floor)
    unguarded = _dark_subtracted_merge(s, rate, times, noise, seed=31, bloom_guard_px=0)
    assert np.all(unguarded.n_used[:, 29] == 2)
    with pytest.raises(ParameterError):
        _dark_subtracted_merge(s, rate, times, noise, seed=31, bloom_guard_px=-1)
