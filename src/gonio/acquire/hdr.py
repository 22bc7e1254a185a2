"""HDR from exposure brackets on raw Bayer data, and exposure planning.

Merging works on the raw mosaic, before any demosaicking, so that every pixel keeps the simple
noise model of its sensor (see :class:`NoiseModel`). For a pixel seen in frames ``k`` with exposure
``t_k`` and dark-subtracted signal ``x_k`` (DN), each frame gives the rate estimate ``x_k / t_k``
with variance ``var_k / t_k^2``; the minimum-variance unbiased combination weights them by
``t_k^2 / var_k`` (Robertson et al. 2003; Hasinoff et al. 2010 "Noise-optimal capture"). ``var_k``
comes from the noise model at a first-pass estimate of the rate, not from the observed value, so
that the weights are not correlated with the noise.

The variance never vanishes: a pixel with no signal (or a negative one after dark subtraction)
still carries the read noise, the ADC's quantization step and the shot noise of the dark current
it collected, in its own frame and in the dark frame subtracted from it. So the merged rate of a
black pixel has the standard deviation of its longest usable exposure's noise floor divided by
that exposure time (DN/s), and that is what propagates through the white reference.

Saturated pixels are excluded, and so are their neighbours (``bloom_guard_px``): a real sensor
spills the charge of an over-full pixel into the pixels around it (blooming, electrical and
optical crosstalk), which would corrupt a dark pixel beside a highlight in exactly the long frames
that would otherwise give it a tiny variance. The longest usable exposure of such a pixel is the
longest one in which its whole neighbourhood is unsaturated.

Exposure-time *ratios* are estimated from the data (pixels well exposed in two frames), since
real shutters differ from their nominal times by a few percent; only the overall scale is taken
from the metadata, and the white reference calibrates that scale away anyway.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from gonio.errors import ParameterError


@dataclass(frozen=True)
class NoiseModel:
    """Per-pixel noise of a linear sensor in DN (EMVA 1288).

    A raw value (DN) whose mean is ``black + signal_DN + dark_DN`` has the variance

        ``gain * (signal_DN + dark_DN) + gain^2 * read_noise^2 + 1/12``  (DN^2):

    shot noise of the collected electrons (signal and dark current), read noise, and the
    quantization noise of a 1 DN step (uniform; valid while the read noise is a fair fraction of
    a DN, as on any sensor whose gain is matched to its ADC).

    Attributes
    ----------
    gain : conversion gain, DN per electron.
    read_noise : read noise, electrons RMS.
    dark_current : dark current, electrons per second per pixel (0: not modelled).
    """

    gain: float
    read_noise: float
    dark_current: float = 0.0

    def dark_dn(self, exposure_s: float) -> float:
        """Mean dark-current signal (DN) collected in ``exposure_s`` seconds."""
        return self.gain * self.dark_current * float(exposure_s)

    def variance(self, signal_dn: np.ndarray, dark_dn: float = 0.0) -> np.ndarray:
        """Predicted variance (DN^2) of one raw value, at least ``gain^2 read_noise^2 + 1/12``.

        Parameters
        ----------
        signal_dn : mean signal (DN) above what is subtracted from the raw value; a negative
            value (a noisy estimate of a black pixel) counts as zero signal.
        dark_dn : mean dark signal (DN) the raw value carries besides ``signal_dn`` (see
            :meth:`dark_dn`): its shot noise remains when a dark frame removes its mean. Leave
            it 0 when ``signal_dn`` already includes the dark current (black level subtracted).
        """
        shot = self.gain * (np.maximum(signal_dn, 0.0) + max(float(dark_dn), 0.0))
        return shot + (self.gain * self.read_noise) ** 2 + 1 / 12

    def dark_frame_variance(self, exposure_s: float) -> float:
        """Variance (DN^2) of one pixel of a dark frame exposed for ``exposure_s`` seconds."""
        return float(self.variance(np.float64(0.0), self.dark_dn(exposure_s)))


@dataclass
class Bracket:
    """One raw exposure: ``dn`` (H, W) raw values, nominal ``exposure_s``, its ``black`` map."""

    dn: np.ndarray
    exposure_s: float
    black: np.ndarray | float
    white_level: int


@dataclass
class HDRResult:
    """A merged frame.

    Attributes
    ----------
    rate : (H, W) signal rate in DN/s (dark-subtracted), NaN where no frame was usable.
    variance : (H, W) variance of ``rate`` in (DN/s)^2 from the noise model; it includes the
        read, quantization and dark-current noise of every frame used (and of its dark frame),
        so it is positive for black pixels too.
    n_used : (H, W) number of frames that contributed (unsaturated, neighbourhood included).
    exposures_s : effective exposure times used (ratios from the data, scale from metadata).
    ratio_source : per frame, "data" or "metadata" (when too few pixels overlapped).
    log_time_cov : (K, K) covariance of the errors of ``log(exposures_s)``; an error common to
        all frames is left out (it scales every pixel alike and the white reference removes it).
    frame_fraction : (K, H, W) float32 share of each frame in each pixel's estimate (weights
        normalized per pixel), so a region's sensitivity to each exposure error can be computed.
    noise_terms : what ``variance`` was computed from (the noise model and each frame's dark
        terms), for :meth:`variance_at`.
    """

    rate: np.ndarray
    variance: np.ndarray
    n_used: np.ndarray
    exposures_s: np.ndarray
    ratio_source: list[str] = field(default_factory=list)
    log_time_cov: np.ndarray | None = None
    frame_fraction: np.ndarray | None = None
    noise_terms: MergeNoise | None = None

    @property
    def sigma(self) -> np.ndarray:
        """Standard deviation of ``rate``, DN/s (NaN where ``rate`` is NaN)."""
        return np.sqrt(self.variance)

    def variance_at(self, rate: np.ndarray, where: np.ndarray) -> np.ndarray:
        """Variance (DN/s)^2 that the merge would give the pixels ``where`` if their rates were
        ``rate`` (DN/s), through the same frames.

        ``variance`` is the noise model at each pixel's own measured rate, so it is correlated
        with that pixel's noise: a pixel that came out low claims a smaller variance. A fit that
        weights pixels by it leans toward the low ones (a harmonic-mean bias of about
        ``1 / SNR^2`` per pixel); weights from this method at a smooth estimate of the rate (a
        fitted surface) are free of it.

        Parameters
        ----------
        rate : (N,) assumed rates, DN/s.
        where : boolean mask (H, W) selecting N pixels, or an index into the (H, W) frame.
        """
        if self.noise_terms is None or self.frame_fraction is None:
            raise ParameterError("this merge result carries no noise model to re-evaluate")
        usable = self.frame_fraction[:, where] > 0  # a frame's weight is > 0 exactly where used
        rate = np.asarray(rate, dtype=np.float64)
        den = np.zeros(rate.shape)
        for k, t in enumerate(self.exposures_s):
            v = self.noise_terms.frame_variance(k, rate * t)
            den += np.where(usable[k], t * t / v, 0.0)
        with np.errstate(divide="ignore"):
            return np.where(den > 0, 1.0 / den, np.nan)


@dataclass(frozen=True)
class MergeNoise:
    """The noise terms of a merge: the sensor's model and, per frame, the mean dark signal
    (DN) whose shot noise stays in the frame and the variance (DN^2) its dark frame adds."""

    noise: NoiseModel
    dark_dn: tuple[float, ...]
    dark_var: tuple[float, ...]

    def frame_variance(self, k: int, signal_dn: np.ndarray) -> np.ndarray:
        """Variance (DN^2) of frame ``k``'s dark-subtracted value at mean ``signal_dn``."""
        return self.noise.variance(signal_dn, self.dark_dn[k]) + self.dark_var[k]


def saturation_threshold(white_level: int, noise: NoiseModel) -> float:
    """DN at and above which a raw value is treated as saturated.

    Clipping happens at ``white_level``, but read noise spreads clipped pixels a few DN below it,
    so the threshold keeps a margin of five read-noise sigmas (at least 2 DN).
    """
    return float(white_level) - max(2.0, 5.0 * noise.gain * noise.read_noise)


def estimate_exposure_ratios(
    signals: Sequence[np.ndarray],
    saturation_signal: Sequence[float],
    nominal_s: Sequence[float],
    noise: NoiseModel,
    min_pixels: int = 200,
    min_snr: float = 50.0,
    max_fill: float = 0.8,
    shutter_precision: float = 0.01,
) -> tuple[np.ndarray, list[str], np.ndarray]:
    """Effective exposure times from the data.

    For each pair of frames adjacent in nominal time (``a`` shorter, ``b`` longer), the ratio of
    their exposures is the ratio of summed signals over pixels exposed well in both (a ratio of
    sums is unbiased to first order and robust to single outliers). Ratios are chained, and the
    overall scale is fixed so that the geometric mean equals that of the nominal times.

    Selecting pixels on a noisy value biases that value, so each cut uses the frame whose noise
    does not enter the sum it could bias: the lower cut (SNR > ``min_snr``) is made on ``b``, where
    the SNR is high enough that the cut moves the sum negligibly, and the upper cut (no
    saturation in ``b``) on ``a`` scaled by the nominal ratio, with ``max_fill`` headroom.

    The data ratio has a counting-statistics uncertainty (the sums' noise-model variances); it is
    combined with the nominal ratio, trusted to ``shutter_precision`` (relative, per frame), by
    inverse-variance weighting in log space. So a pair that overlaps in only a few photons leans on
    the metadata, and a well-overlapping pair corrects it.

    Parameters
    ----------
    signals : per frame, (H, W) dark-subtracted signal in DN.
    saturation_signal : per frame, the signal (DN above black) at which it saturates.
    nominal_s : nominal exposure times, seconds.
    shutter_precision : relative standard deviation of a real exposure around its nominal time.

    Returns ``(times_s, source, log_cov)``: ``source[k]`` is "data", or "metadata" when fewer
    than ``min_pixels`` pixels qualified between frame ``k`` and its shorter neighbour;
    ``log_cov`` (K, K) is the covariance of the errors of ``log(times_s)`` relative to the
    shortest frame (errors accumulate along the chain of pairs).
    """
    nominal = np.asarray(nominal_s, dtype=np.float64)
    order = np.argsort(nominal)
    rel = np.ones(len(nominal))
    source = ["metadata"] * len(nominal)
    source[order[0]] = "data"
    var_prior = 2.0 * shutter_precision**2
    chain_var = np.zeros(len(nominal))  # variance of log t_k relative to the shortest frame
    for a, b in itertools.pairwise(order):
        sa, sb = signals[a], signals[b]
        snr_b = sb / np.sqrt(noise.variance(sb))
        sel = (snr_b > min_snr) & (sa * (nominal[b] / nominal[a]) < max_fill * saturation_signal[b])
        sel &= sa < saturation_signal[a]
        if sel.sum() >= min_pixels:
            sum_a, sum_b = float(sa[sel].sum()), float(sb[sel].sum())
            var_log = (
                float(noise.variance(sa[sel]).sum()) / sum_a**2
                + float(noise.variance(sb[sel]).sum()) / sum_b**2
            )
            w = var_prior / (var_prior + var_log) if var_prior > 0 else 0.0
            log_ratio = w * np.log(sum_b / sum_a) + (1 - w) * np.log(nominal[b] / nominal[a])
            rel[b] = rel[a] * float(np.exp(log_ratio))
            source[b] = "data"
            pair_var = w * var_log  # posterior variance of the fused log ratio
        else:
            rel[b] = rel[a] * nominal[b] / nominal[a]
            pair_var = var_prior
        chain_var[b] = chain_var[a] + pair_var
    scale = np.exp(np.mean(np.log(nominal)) - np.mean(np.log(rel)))
    # Frames share the chain up to the shorter of the two: cov = var at the earlier position.
    rank = np.empty(len(nominal), dtype=np.int64)
    rank[order] = np.arange(len(nominal))
    earlier = np.where(rank[:, None] <= rank[None, :], np.arange(len(nominal))[:, None],
                       np.arange(len(nominal))[None, :])  # fmt: skip
    log_cov = chain_var[earlier]
    return rel * scale, source, log_cov


def merge_brackets(
    brackets: Sequence[Bracket],
    noise: NoiseModel,
    dark: Sequence[np.ndarray] | None = None,
    estimate_ratios: bool = True,
    shutter_precision: float = 0.01,
    bloom_guard_px: int = 1,
) -> HDRResult:
    """Merge raw brackets into one rate image with noise-optimal weights.

    Parameters
    ----------
    brackets : frames of one scene, any order.
    noise : the sensor's noise model.
    dark : optional dark frames (raw DN, same exposures, shutter closed), one per bracket; when
        given they replace the black level and remove dark current and fixed pattern (their
        noise, and the dark current's shot noise, stay in the variance).
    estimate_ratios : estimate exposure ratios from the data (default) or trust the metadata.
    shutter_precision : relative accuracy of the nominal exposure times (see
        :func:`estimate_exposure_ratios`).
    bloom_guard_px : a frame is not used for a pixel when any pixel within this Chebyshev
        distance is saturated in it (blooming and crosstalk, see the module docstring); 0 uses
        every unsaturated pixel.

    Returns an :class:`HDRResult`: ``rate`` in DN/s, ``variance`` in (DN/s)^2, finite and
    positive wherever ``rate`` is finite, whatever the signal (zero and negative included).
    """
    if not brackets:
        raise ParameterError("HDR merge needs at least one bracket")
    shape = brackets[0].dn.shape
    if any(b.dn.shape != shape for b in brackets):
        raise ParameterError("HDR brackets differ in size")
    if dark is not None and len(dark) != len(brackets):
        raise ParameterError("HDR merge needs one dark frame per bracket")
    if bloom_guard_px < 0:
        raise ParameterError(f"bloom_guard_px must be >= 0, got {bloom_guard_px}")

    signals, usable, sat_signal = [], [], []
    for k, b in enumerate(brackets):
        dn = b.dn.astype(np.float64)
        base = dark[k].astype(np.float64) if dark is not None else b.black
        threshold = saturation_threshold(b.white_level, noise)
        signals.append(dn - base)
        saturated = dn >= threshold
        if bloom_guard_px > 0 and saturated.any():
            size = 2 * bloom_guard_px + 1
            saturated = ndimage.maximum_filter(saturated, size=size, mode="nearest")
        usable.append(~saturated)
        sat_signal.append(threshold - float(np.median(base)))
    nominal = np.array([b.exposure_s for b in brackets], dtype=np.float64)
    if estimate_ratios and len(brackets) > 1:
        times, source, log_cov = estimate_exposure_ratios(
            signals, sat_signal, nominal, noise, shutter_precision=shutter_precision
        )
    else:
        times, source = nominal, ["metadata"] * len(brackets)
        log_cov = 2.0 * shutter_precision**2 * np.eye(len(brackets))

    # With dark frames the signal has the dark current's mean removed but not its shot noise, and
    # the subtracted dark frame adds its own read, quantization and dark shot noise. With only a
    # black level the signal still holds the dark current, whose shot noise the model then counts.
    if dark is not None:
        dark_dn = [noise.dark_dn(t) for t in times]
        dark_var = [noise.dark_frame_variance(t) for t in times]
    else:
        dark_dn = dark_var = [0.0] * len(times)
    terms = MergeNoise(noise, tuple(map(float, dark_dn)), tuple(map(float, dark_var)))
    # Pass 1: weights from the observed signal; pass 2: from the model at the pass-1 rate.
    first = [terms.frame_variance(k, s) for k, s in enumerate(signals)]
    rate = _weighted(signals, usable, times, first)[0]
    rate0 = np.where(np.isfinite(rate), rate, 0.0)
    variances = [terms.frame_variance(k, rate0 * t) for k, t in enumerate(times)]
    rate, var, n_used = _weighted(signals, usable, times, variances)
    weights = np.stack(
        [np.where(ok, t * t / v, 0.0) for ok, t, v in zip(usable, times, variances, strict=True)]
    )
    total = weights.sum(0)
    fraction = np.where(total > 0, weights / np.where(total > 0, total, 1.0), 0.0)
    return HDRResult(rate, var, n_used, times, source, log_cov, fraction.astype(np.float32), terms)


def _weighted(signals, usable, times, variances):
    num = np.zeros(signals[0].shape)
    den = np.zeros(signals[0].shape)
    n = np.zeros(signals[0].shape, dtype=np.int32)
    for s, ok, t, v in zip(signals, usable, times, variances, strict=True):
        w = np.where(ok, t * t / v, 0.0)  # weight of the estimate s / t
        num += w * s / t
        den += w
        n += ok
    with np.errstate(invalid="ignore", divide="ignore"):
        rate = np.where(den > 0, num / den, np.nan)
        var = np.where(den > 0, 1.0 / den, np.nan)
    return rate, var, n


@dataclass(frozen=True)
class ExposurePlan:
    """Exposure times chosen for one configuration, shortest first, and why."""

    exposures_s: tuple[float, ...]
    covered_rate_min: float
    reason: str


def plan_exposures(
    rate_max: float,
    rate_min: float,
    *,
    gain: float,
    read_noise: float,
    dark_current: float,
    full_well: float,
    t_min: float = 1e-5,
    t_max: float = 30.0,
    snr_target: float = 50.0,
    headroom: float = 0.8,
) -> ExposurePlan:
    """The fewest exposures that keep everything between two rates unsaturated and above an SNR.

    Parameters
    ----------
    rate_max, rate_min : brightest and darkest pixel of interest (sample and white reference),
        electrons per second, e.g. predicted from the previous configuration's frame.
    gain, read_noise, dark_current, full_well : sensor parameters (DN/e-, e-, e-/s, e-).
    t_min, t_max : exposure limits of the camera, seconds.
    snr_target : required signal-to-noise ratio of every pixel of interest in at least one frame.
    headroom : fraction of the full well the brightest pixel may fill.

    Each exposure covers the rates from ``headroom * full_well / t`` down to the rate whose SNR
    at ``t`` equals the target; greedily starting with the brightest rate gives the minimum number
    of intervals that cover [rate_min, rate_max] (interval covering).
    """
    if not (rate_max > 0 and rate_min > 0 and rate_max >= rate_min):
        raise ParameterError(f"need 0 < rate_min <= rate_max, got {rate_min}, {rate_max}")
    sat = headroom * full_well

    def lowest_rate_ok(t: float) -> float:
        # Solve r t / sqrt(r t + dark t + read^2) = snr for r (a quadratic in r t).
        s2 = snr_target**2
        c = dark_current * t + read_noise**2
        rt = 0.5 * (s2 + np.sqrt(s2 * s2 + 4 * s2 * c))
        return rt / t

    times: list[float] = []
    r_hi = rate_max
    reason = "covered"
    while True:
        t = float(np.clip(sat / r_hi, t_min, t_max))
        times.append(t)
        r_lo = lowest_rate_ok(t)
        if r_lo <= rate_min:
            break
        if t >= t_max:
            reason = f"darkest rate needs more than t_max = {t_max} s for SNR {snr_target}"
            break
        if len(times) > 32:
            reason = "gave up after 32 exposures"
            break
        r_hi = r_lo
    return ExposurePlan(tuple(times), float(lowest_rate_ok(times[-1])), reason)
