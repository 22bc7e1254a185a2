"""Pearson chi-square test that a direction sampler draws from the density it reports.

This follows the approach of Mitsuba 3's ``chi2.py``: histogram many samples over a grid of
solid-angle cells, integrate the claimed pdf over the same cells, pool cells whose expected count
is below 5, and compare with Pearson's statistic. A Šidák correction keeps the family-wise error
at ``significance`` when ``n_tests`` tests are run together.

Two further checks catch what a histogram cannot:

* the pdf a sampler returns with each sample must equal ``pdf(wi)`` evaluated separately;
* the pdf must integrate to at most 1 over the hemisphere (mass below the horizon is lost).

Cells are uniform in ``theta`` over [0, pi/2] and in ``phi`` over [0, 2pi); samples with a
non-zero pdf below the horizon fail the test outright.

For very sharp lobes (a microfacet lobe of roughness 0.02 seen at grazing incidence is a tenth
of a degree wide) that grid is too coarse to integrate the pdf accurately. ``chi2_test(...,
axis=w, theta_max=t)`` then histograms in a frame whose pole is ``w`` (usually the lobe's mirror
direction): cells uniform in the angle to ``w`` over [0, t], plus one cell for everything
farther than ``t`` from the axis.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import stats

SampleFn = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
PdfFn = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Chi2Result:
    """Outcome of :func:`chi2_test`; ``passed`` is the verdict, ``message`` says why."""

    passed: bool
    statistic: float
    dof: int
    p_value: float
    threshold: float
    n_samples: int
    n_valid: int
    pdf_integral: float
    max_pdf_mismatch: float
    message: str


def lobe_frame(axis: np.ndarray) -> np.ndarray:
    """Orthonormal frame ``(3, 3)`` (rows: tangent, bitangent, axis) with ``axis`` as its pole."""
    n = np.asarray(axis, dtype=np.float64).reshape(3)
    n = n / np.linalg.norm(n)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t = helper - np.dot(helper, n) * n
    t /= np.linalg.norm(t)
    return np.stack([t, np.cross(n, t), n])


def integrate_pdf_cells(
    pdf: PdfFn,
    res_theta: int,
    res_phi: int,
    order: int = 6,
    chunk: int = 1 << 20,
    theta_range: tuple[float, float] = (0.0, np.pi / 2),
    frame: np.ndarray | None = None,
) -> np.ndarray:
    """Integral of ``pdf`` over each (theta, phi) cell, ``(res_theta, res_phi)``.

    Gauss-Legendre with ``order`` nodes per cell and dimension, the ``sin(theta)`` Jacobian
    included, so the result is a probability per cell. Cells are uniform in ``theta`` over
    ``theta_range`` (radians) and in ``phi`` over [0, 2pi), measured in ``frame`` (rows: tangent,
    bitangent, pole; default the local frame itself).
    """
    x, w = np.polynomial.legendre.leggauss(order)
    x = 0.5 * (x + 1.0)
    w = 0.5 * w
    th0, th1 = theta_range
    dth = (th1 - th0) / res_theta
    dph = (2 * np.pi) / res_phi
    th = (th0 + (np.arange(res_theta)[:, None] + x[None, :]) * dth).ravel()
    ph = ((np.arange(res_phi)[:, None] + x[None, :]) * dph).ravel()
    wt = np.tile(w, res_theta) * dth * np.sin(th)
    wp = np.tile(w, res_phi) * dph
    st, ct = np.sin(th), np.cos(th)
    dirs_t = np.stack([st, ct], -1)
    out = np.empty((res_theta * order, res_phi * order))
    rows_per_chunk = max(1, chunk // ph.size)
    for r0 in range(0, th.size, rows_per_chunk):
        r1 = min(th.size, r0 + rows_per_chunk)
        s = dirs_t[r0:r1, 0][:, None]
        c = dirs_t[r0:r1, 1][:, None]
        d = np.stack(
            np.broadcast_arrays(s * np.cos(ph)[None], s * np.sin(ph)[None], c), axis=-1
        ).reshape(-1, 3)
        if frame is not None:
            d = d @ frame
        out[r0:r1] = np.asarray(pdf(d), dtype=np.float64).reshape(r1 - r0, ph.size)
    out *= wt[:, None] * wp[None, :]
    return out.reshape(res_theta, order, res_phi, order).sum(axis=(1, 3))


def histogram_directions(
    wi: np.ndarray,
    res_theta: int,
    res_phi: int,
    theta_max: float = np.pi / 2,
    frame: np.ndarray | None = None,
) -> np.ndarray:
    """Counts of directions ``(N, 3)`` per (theta, phi) cell, ``(res_theta, res_phi)``.

    ``theta`` is uniform over [0, ``theta_max``]; with ``frame`` (rows: tangent, bitangent, pole)
    angles are measured in that frame and directions beyond ``theta_max`` are not counted.
    Without it, every direction is counted (the default grid covers the upper hemisphere).
    """
    if frame is not None:
        wi = wi @ frame.T
    theta = np.arctan2(np.hypot(wi[:, 0], wi[:, 1]), wi[:, 2])
    phi = np.mod(np.arctan2(wi[:, 1], wi[:, 0]), 2 * np.pi)
    if frame is not None:
        keep = theta < theta_max
        theta, phi = theta[keep], phi[keep]
    it = np.clip((theta / theta_max * res_theta).astype(np.int64), 0, res_theta - 1)
    ip = np.clip((phi / (2 * np.pi) * res_phi).astype(np.int64), 0, res_phi - 1)
    return np.bincount(it * res_phi + ip, minlength=res_theta * res_phi).reshape(res_theta, res_phi)


def pearson_pooled(observed: np.ndarray, expected: np.ndarray, min_expected: float = 5.0):
    """Pearson statistic with cells of expected count < ``min_expected`` pooled together.

    Returns ``(statistic, dof, zero_expected_hits)``: ``zero_expected_hits`` counts samples that
    landed where the expected count is exactly 0 (an immediate failure).
    """
    observed = observed.ravel().astype(np.float64)
    expected = expected.ravel().astype(np.float64)
    zero_hits = float(observed[expected <= 0].sum())
    order = np.argsort(expected)
    o, e = observed[order], expected[order]
    small = e < min_expected
    pooled_o, pooled_e = o[small].sum(), e[small].sum()
    o, e = o[~small], e[~small]
    if pooled_e > 0:
        if pooled_e >= min_expected or o.size == 0:
            o = np.append(o, pooled_o)
            e = np.append(e, pooled_e)
        else:  # fold the remainder into the smallest kept cell
            o[0] += pooled_o
            e[0] += pooled_e
    stat = float(np.sum((o - e) ** 2 / e))
    return stat, int(o.size - 1), zero_hits


def chi2_test(
    sample: SampleFn,
    pdf: PdfFn,
    n_samples: int = 1_000_000,
    res_theta: int = 90,
    res_phi: int = 180,
    seed: int = 0,
    significance: float = 0.01,
    n_tests: int = 1,
    order: int = 6,
    pdf_rtol: float = 1e-3,
    axis: np.ndarray | None = None,
    theta_max: float | None = None,
) -> Chi2Result:
    """Test that ``sample`` draws directions with density ``pdf``.

    Parameters
    ----------
    sample : ``u (N, 2) -> (wi (N, 3), pdf (N,))``; a pdf of 0 marks a failed sample.
    pdf : ``wi (M, 3) -> (M,)`` density per unit solid angle the sampler claims.
    n_samples : number of uniform pairs drawn (fixed ``seed``).
    res_theta, res_phi : histogram resolution over the upper hemisphere.
    significance : family-wise level; with ``n_tests`` tests each one uses the Šidák level
        ``1 - (1 - significance) ** (1 / n_tests)``.
    order : Gauss-Legendre nodes per cell and dimension for the expected counts.
    pdf_rtol : allowed relative difference between the pdf returned with a sample and ``pdf(wi)``.
    axis : optional unit vector (3,): histogram in a frame with this pole (e.g. the mirror
        direction of a sharp lobe) instead of the surface normal; cells then cover angles
        [0, ``theta_max``] from the axis (default pi: the whole sphere) and one extra cell
        collects everything beyond.
    theta_max : angular radius in radians of the gridded cap around ``axis``.
    """
    rng = np.random.default_rng(seed)
    u = rng.random((n_samples, 2))
    wi, spdf = sample(u)
    wi = np.asarray(wi, dtype=np.float64)
    spdf = np.asarray(spdf, dtype=np.float64)
    valid = spdf > 0
    if not np.all(np.isfinite(wi[valid])) or not np.all(np.isfinite(spdf)):
        return _fail("sampler returned NaN or Inf", n_samples)
    below = valid & (wi[:, 2] <= 0)
    if below.any():
        return _fail(f"{int(below.sum())} samples below the horizon have pdf > 0", n_samples)
    wv = wi[valid]
    claimed = spdf[valid]
    evaluated = np.asarray(pdf(wv), dtype=np.float64)
    mismatch = float(
        np.max(np.abs(claimed - evaluated) / np.maximum(np.abs(evaluated), 1e-30), initial=0.0)
    )

    if axis is None:
        observed = histogram_directions(wv, res_theta, res_phi)
        prob = integrate_pdf_cells(pdf, res_theta, res_phi, order=order)
        obs_cells, exp_cells = observed.ravel(), prob.ravel() * n_samples
        integral = float(prob.sum())
    else:
        frame = lobe_frame(axis)
        cap = float(np.pi if theta_max is None else min(theta_max, np.pi))
        observed = histogram_directions(wv, res_theta, res_phi, theta_max=cap, frame=frame)
        prob = integrate_pdf_cells(
            pdf, res_theta, res_phi, order=order, theta_range=(0.0, cap), frame=frame
        )
        rest = 0.0
        if cap < np.pi:  # the rest of the sphere, as one cell
            rest = float(
                integrate_pdf_cells(
                    pdf, res_theta, res_phi, order=order, theta_range=(cap, np.pi), frame=frame
                ).sum()
            )
        obs_cells = np.append(observed.ravel(), wv.shape[0] - observed.sum())
        exp_cells = np.append(prob.ravel(), rest) * n_samples
        integral = float(prob.sum()) + rest
    # The multinomial's last outcome: samples that failed (pdf 0), expected where mass is lost.
    obs_all = np.append(obs_cells, n_samples - wv.shape[0])
    exp_all = np.append(exp_cells, max(0.0, n_samples * (1.0 - integral)))
    stat, dof, zero_hits = pearson_pooled(obs_all, exp_all)
    threshold = 1.0 - (1.0 - significance) ** (1.0 / n_tests)
    p_value = float(stats.chi2.sf(stat, dof)) if dof > 0 else 1.0

    problems = []
    if mismatch > pdf_rtol:
        problems.append(f"returned pdf differs from pdf(wi) by up to {mismatch:.3g} (relative)")
    if integral > 1.0 + 1e-3:
        problems.append(f"pdf integrates to {integral:.5f} > 1")
    if zero_hits > 0:
        problems.append(f"{zero_hits:.0f} samples fell where the pdf integrates to 0")
    if p_value < threshold:
        problems.append(f"p = {p_value:.3g} < {threshold:.3g}")
    message = "; ".join(problems) or (
        f"chi2 = {stat:.1f} on {dof} dof, p = {p_value:.3g} >= {threshold:.3g}"
    )
    return Chi2Result(
        passed=not problems,
        statistic=stat,
        dof=dof,
        p_value=p_value,
        threshold=threshold,
        n_samples=n_samples,
        n_valid=int(wv.shape[0]),
        pdf_integral=integral,
        max_pdf_mismatch=mismatch,
        message=message,
    )


def _fail(message: str, n: int) -> Chi2Result:
    return Chi2Result(False, np.inf, 0, 0.0, 0.0, n, 0, np.nan, np.inf, message)


def model_sampler(model, wo: np.ndarray) -> tuple[SampleFn, PdfFn]:
    """Adapt a gonio model (or table) with ``sample``/``pdf`` for :func:`chi2_test` at ``wo``."""
    wo = np.asarray(wo, dtype=np.float64)

    def sample(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        s = model.sample(wo, u)
        return np.asarray(s.wi), np.asarray(s.pdf)

    def pdf(wi: np.ndarray) -> np.ndarray:
        return np.asarray(model.pdf(wi, wo))

    return sample, pdf
