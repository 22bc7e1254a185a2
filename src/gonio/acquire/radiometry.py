"""From an HDR raw frame to BRDF values in 1/sr through a white reference.

For a point light of intensity ``I`` at ``x_l``, the irradiance at a point ``p`` of the holder is
``E(p) = I cos(theta_i(p)) / |x_l - p|^2``. The white reference (Lambertian, reflectance ``rho``)
has radiance ``rho / pi * E(p_r)``; the sample has ``f(wi, wo) E(p_s)``. Both are imaged by the
same camera in the same frame, so the unknown light intensity and camera throughput cancel:

    f = (S / R) * (rho / pi),

where ``S`` and ``R`` are the mean pixel rates over the sample and the reference after each
pixel has been divided by its own irradiance (relative to a common light intensity) and its
``cos^4`` vignetting. Directions are those from the *actual* sample centre to the actual light
and camera positions (finite distances), not the nominal servo angles.

The uncertainty comes from the HDR merge's per-pixel variances (the sensor noise model) and is
propagated in absolute terms, ``var f = (k / R)^2 var S + f^2 (var R / R^2 + ...)`` with
``k = rho / pi``, not as a relative error times ``|f|``: a black or negative ``S`` still has the
sensor's noise floor (read noise and quantization of its longest usable exposure, in DN/s) scaled
into 1/sr by the white reference, while the terms that scale with the signal (reference noise,
exposure-ratio errors) vanish with it as they should.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from gonio.errors import DeviceError, FrameError


@dataclass(frozen=True)
class RegionMeasurement:
    """One BRDF sample measured from a frame.

    Attributes
    ----------
    wi, wo : (3,) unit directions from the sample centre toward the light and the camera, in
        the sample frame.
    f : (C,) BRDF value in 1/sr per colour plane (R, G, B); may be negative for a black sample
        (the noise of a dark-subtracted value is not clipped away).
    sigma : (C,) its standard deviation in 1/sr; positive even where ``f`` is zero.
    n_pixels : (C,) sample pixels used per colour plane.
    """

    wi: np.ndarray
    wo: np.ndarray
    f: np.ndarray
    sigma: np.ndarray
    n_pixels: np.ndarray


def pixel_rays_to_plane(
    shape: tuple[int, int], camera_matrix: np.ndarray, rotation: np.ndarray, translation: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Where each pixel centre's ray meets the holder plane z = 0.

    Returns ``(points (H, W, 3), hit (H, W))`` in the sample frame; ``rotation``/``translation``
    map sample to camera coordinates (``x_cam = R x + t``).
    """
    h, w = shape
    kinv = np.linalg.inv(camera_matrix)
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    d_cam = np.stack([u, v, np.ones_like(u)], -1) @ kinv.T
    d = d_cam @ rotation  # R^T d_cam for each pixel
    origin = -rotation.T @ translation
    with np.errstate(divide="ignore", invalid="ignore"):
        s = -origin[2] / d[..., 2]
    hit = np.isfinite(s) & (s > 0)
    points = origin + np.where(hit, s, 0.0)[..., None] * d
    return points, hit


def measure_brdf(
    rate: np.ndarray,
    variance: np.ndarray,
    plane_index: np.ndarray,
    camera_matrix: np.ndarray,
    rotation: np.ndarray,
    translation: np.ndarray,
    light_pos: np.ndarray,
    sample_center: tuple[float, float],
    sample_radius: float,
    reference_center: tuple[float, float],
    reference_radius: float,
    reference_albedo: float,
    spot_radius: float = 0.001,
    frame_fraction: np.ndarray | None = None,
    log_time_cov: np.ndarray | None = None,
    pose_sigma_points: list[tuple[np.ndarray, np.ndarray]] | None = None,
    fit_order: int = 1,
    direction_uncertainty: bool = False,
    variance_at: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
) -> RegionMeasurement:
    """Measure the sample's BRDF in one merged frame.

    Parameters
    ----------
    rate, variance : (H, W) HDR mosaic (DN/s) and its variance, from the raw merge.
    plane_index : (H, W) 0/1/2 for the R/G/B site of each pixel.
    camera_matrix : 3x3 intrinsics K (pixels).
    rotation, translation : holder pose in the camera (from the ChArUco board).
    light_pos : (3,) light position in the sample frame (metres).
    sample_center, sample_radius, reference_center, reference_radius : holder layout (metres).
    reference_albedo : hemispherical reflectance of the white reference.
    spot_radius : radius (metres) of the measured spot around the sample centre. A BRDF sample
        is assigned the directions of the centre, so a large spot averages ``f`` over a range of
        directions (a bias growing with the spot's area); a small one costs noise. The default,
        1 mm, keeps the averaging bias below the noise for lobes as sharp as Phong n = 40 at
        0.5 m. The white reference uses 80 % of its disk (it is Lambertian; more pixels only
        help).
    frame_fraction, log_time_cov : from :class:`gonio.acquire.hdr.HDRResult`. When given, the
        uncertainty of the exposure-time ratios is propagated: a region's log signal moves by
        ``-sum_k a_k dlog(t_k)`` with ``a_k`` its mean share of frame ``k``, so ``log f`` has the
        extra variance ``(a_R - a_S)^T C (a_R - a_S)``. It vanishes when the sample and the
        reference come from the same exposures.
    pose_sigma_points : from :func:`gonio.acquire.pose.pose_samples`. When given, the pose
        uncertainty is propagated: the pixel at the spot centre is traced through each sigma
        point to find how far the measured spot may really lie from where the pose says
        (covariance ``C_xy`` on the holder), and the spot's own spatial gradient of the signal
        ``g`` (from the plane fit) turns that into ``var(S) += g^T C_xy g``. On a steep specular
        lobe this dominates the sensor noise; on a diffuse sample it vanishes.
    direction_uncertainty : with ``pose_sigma_points``, also propagate the uncertainty of the
        reported outgoing direction (the camera position from the pose) into sigma, so that
        sigma describes f *at the reported directions*: each sigma point's change of ``wo``
        times the lobe's directional slope. The slope is estimated from the spot's spatial
        gradient ``g``: moving on the holder by ``dp`` turns ``wi`` and ``wo`` by
        ``-P_i dp / D_l`` and ``-P_o dp / D_c`` (``P`` projectors, ``D`` distances), so for a
        lobe that varies with ``wi + wo`` (microfacet, Phong-like) ``g = -s M`` with
        ``M = P_o / D_c + P_i / D_l``; ``s`` is taken as the minimum-norm solution.
    fit_order : 1 fits a plane through the spot's pixels, 2 a quadratic surface, whose
        intercept is free of the lobe's curvature averaged over the spot (a bias growing with
        the spot's area on sharp lobes); it needs more pixels per colour plane (>= 12).
    variance_at : ``variance_at(rate (N,), mask (H, W)) -> (N,)``, the merge's variance of the
        masked pixels at other rates (:meth:`gonio.acquire.hdr.HDRResult.variance_at`). When
        given, the spot's pixels are weighted by it at the fitted surface instead of by
        ``variance``, which the noise model evaluated at each pixel's own noisy rate and which
        so favours the pixels that came out low (a bias of ``f`` of about ``-1 / SNR^2`` per
        pixel, relative; on the simulated rig's demo runs 0.01-0.03 sigma per value).
    """
    h, w = rate.shape
    pts, hit = pixel_rays_to_plane((h, w), camera_matrix, rotation, translation)
    cam_pos = -rotation.T @ translation
    light_pos = np.asarray(light_pos, dtype=np.float64)
    to_light = light_pos - pts
    d2 = np.sum(to_light**2, -1)
    cos_i = np.maximum(to_light[..., 2], 0.0) / np.sqrt(d2)
    irr = cos_i / d2  # irradiance per unit light intensity, W/m^2 per W/sr

    # Natural vignetting of the pinhole: cos^4 of the pixel ray's off-axis angle.
    kinv = np.linalg.inv(camera_matrix)
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    d_cam = np.stack([u, v, np.ones_like(u)], -1) @ kinv.T
    cos4 = (1.0 / np.linalg.norm(d_cam, axis=-1)) ** 4

    good = hit & np.isfinite(rate) & (irr > 0)
    scale = np.where(good, 1.0 / np.where(good, irr * cos4, 1.0), 0.0)
    norm_rate = np.where(good, rate, 0.0) * scale
    norm_var = np.where(good, variance, 0.0) * scale**2

    def region(center, radius):
        r2 = (pts[..., 0] - center[0]) ** 2 + (pts[..., 1] - center[1]) ** 2
        return good & (r2 <= radius**2)

    in_s = region(sample_center, min(spot_radius, 0.8 * sample_radius))
    spot_cov = None
    if pose_sigma_points:
        spot_cov = _spot_covariance(
            camera_matrix, rotation, translation, pose_sigma_points, sample_center
        )
    in_r = region(reference_center, 0.8 * reference_radius)
    dir_jac = None
    if pose_sigma_points and direction_uncertainty:
        dir_jac = _direction_jacobian(cam_pos, light_pos, sample_center, pose_sigma_points)
    f = np.zeros(3)
    sig = np.zeros(3)
    n_px = np.zeros(3, dtype=np.int64)
    for c in range(3):
        ms, mr = in_s & (plane_index == c), in_r & (plane_index == c)
        ns, nr = int(ms.sum()), int(mr.sum())
        if ns == 0 or nr == 0:
            raise FrameError(
                f"sample or reference not visible in the frame (plane {c}: {ns} / {nr} pixels)"
            )
        variance_of = None
        if variance_at is not None:
            sc = scale[ms]

            def variance_of(v: np.ndarray, sc: np.ndarray = sc, ms: np.ndarray = ms) -> np.ndarray:
                return variance_at(v / sc, ms) * sc**2

        S, vS, grad = _value_at_centre(
            norm_rate[ms], norm_var[ms], pts[ms], sample_center, fit_order, variance_of
        )
        if spot_cov is not None:
            vS += float(grad @ spot_cov @ grad)
        if dir_jac is not None:
            m_mat, dwo = dir_jac
            slope = np.linalg.pinv(m_mat.T) @ grad  # (3,): dS per unit change of wi + wo
            vS += float(np.mean((dwo @ slope) ** 2))  # unscented, as in _spot_covariance
        R, vR = norm_rate[mr].mean(), norm_var[mr].sum() / nr**2
        if not R > 0:
            raise DeviceError("white reference gives no signal: is the light on?")
        k = reference_albedo / np.pi
        f[c] = S / R * k
        # Absolute for S (so a black sample keeps its noise floor), relative for what scales f.
        rel_var = vR / (R * R)
        if frame_fraction is not None and log_time_cov is not None:
            a = frame_fraction[:, ms].mean(axis=1) - frame_fraction[:, mr].mean(axis=1)
            rel_var += float(a @ log_time_cov @ a)
        sig[c] = np.sqrt((k / R) ** 2 * vS + f[c] ** 2 * rel_var)
        n_px[c] = ns
    p_s = np.array([sample_center[0], sample_center[1], 0.0])
    wi = light_pos - p_s
    wo = cam_pos - p_s
    return RegionMeasurement(wi / np.linalg.norm(wi), wo / np.linalg.norm(wo), f, sig, n_px)


def _value_at_centre(
    values: np.ndarray,
    variances: np.ndarray,
    points: np.ndarray,
    centre: tuple[float, float],
    order: int = 1,
    variance_of: Callable[[np.ndarray], np.ndarray] | None = None,
) -> tuple[float, float, np.ndarray]:
    """Weighted least-squares plane ``a + b dx + c dy`` (``order`` 2: plus ``dx^2, dx dy,
    dy^2``) through pixel values.

    Returns ``(a, var(a), (b, c))``; falls back to a plane below 12 pixels and to the weighted
    mean with a zero gradient below 6, and one order down wherever the surface is not determined
    by the pixels (a foreshortened spot can hold one colour plane's sites on two lines only,
    through which no quadratic is unique).

    ``variance_of`` maps values (N,) to the pixels' variances at those values (the noise model).
    When given, the fit is repeated once with the variances at the first fit's surface instead
    of ``variances``, which the noise model evaluated at each pixel's own noisy value: those
    weights favour the pixels that came out low, a bias of the intercept toward lower values
    (:meth:`gonio.acquire.hdr.HDRResult.variance_at`). What remains is the surface's own
    dependence on each pixel (its leverage), about ``k / N`` of that bias for ``k`` surface terms
    and ``N`` pixels: at 12 electrons per pixel (SNR 3.3) and 32-64 pixels per colour plane,
    600 trials gave a mean pull of -0.02 to -0.15 sigma, against -1.6 to -2.3 before (300).
    """
    dx, dy = points[:, 0] - centre[0], points[:, 1] - centre[1]
    cols = [np.ones_like(values), dx, dy]
    if order >= 2 and values.size >= 12:
        cols += [dx * dx, dx * dy, dy * dy]
    if values.size < 6:
        cols = cols[:1]
    X, coef, cov = _weighted_surface(values, 1.0 / np.maximum(variances, 1e-300), cols)
    if variance_of is not None:
        w = 1.0 / np.maximum(variance_of(X @ coef), 1e-300)
        X, coef, cov = _weighted_surface(values, w, cols)
    gradient = coef[1:3] if coef.size > 1 else np.zeros(2)
    return float(coef[0]), float(cov[0, 0]), gradient


def _weighted_surface(
    values: np.ndarray, w: np.ndarray, cols: list[np.ndarray]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted least squares on the columns ``cols`` (the constant first), dropping to a plane
    and then to the constant wherever the pixels do not determine the surface: ``(X, coef,
    cov)``."""
    while len(cols) > 1:
        X = np.stack(cols, -1)
        # the weighted design with unit columns: a surface the pixels (nearly) do not determine
        # "solves" to an arbitrary intercept with a huge variance, or raises (a well-spread spot
        # has a condition number of 10-100)
        xs = np.sqrt(w)[:, None] * X
        sv = np.linalg.svd(xs / np.maximum(np.linalg.norm(xs, axis=0), 1e-300), compute_uv=False)
        if sv[-1] >= 1e-6 * sv[0]:
            A = X.T @ (w[:, None] * X)
            return X, np.linalg.solve(A, X.T @ (w * values)), np.linalg.inv(A)
        cols = cols[:3] if len(cols) > 3 else cols[:1]
    X = cols[0][:, None]
    return X, np.array([np.sum(w * values) / np.sum(w)]), np.array([[1.0 / np.sum(w)]])


def _direction_jacobian(
    cam_pos: np.ndarray,
    light_pos: np.ndarray,
    centre: tuple[float, float],
    sigma_points: list[tuple[np.ndarray, np.ndarray]],
) -> tuple[np.ndarray, np.ndarray]:
    """``M`` (3, 2): change of ``wi + wo`` per metre moved on the holder (x, y), and the change
    of the reported ``wo`` at each pose sigma point (K, 3)."""
    p = np.array([centre[0], centre[1], 0.0])
    out = []
    for pos in (cam_pos, light_pos):
        d = pos - p
        dist = float(np.linalg.norm(d))
        w = d / dist
        out.append((np.eye(3) - np.outer(w, w)) / dist)
    m_mat = -(out[0] + out[1])[:, :2]
    wo = (cam_pos - p) / np.linalg.norm(cam_pos - p)
    dwo = []
    for R, t in sigma_points:
        c = -R.T @ t
        dwo.append((c - p) / np.linalg.norm(c - p) - wo)
    return m_mat, np.asarray(dwo)


def _spot_covariance(
    camera_matrix: np.ndarray,
    rotation: np.ndarray,
    translation: np.ndarray,
    sigma_points: list[tuple[np.ndarray, np.ndarray]],
    centre: tuple[float, float],
) -> np.ndarray:
    """(2, 2) covariance on the holder of the point the spot-centre pixel really images."""
    p = np.array([centre[0], centre[1], 0.0])
    x = camera_matrix @ (rotation @ p + translation)
    pixel = x[:2] / x[2]
    kinv = np.linalg.inv(camera_matrix)
    ray = kinv @ np.array([pixel[0], pixel[1], 1.0])
    hits = []
    for R, t in sigma_points:
        d = R.T @ ray
        o = -R.T @ t
        s = -o[2] / d[2]
        hits.append((o + s * d)[:2])
    diff = np.asarray(hits) - p[:2]
    # Unscented transform with weights 1/(2n) and the mean at the nominal point.
    return diff.T @ diff / len(hits)
