"""From an HDR raw frame to BRDF values in 1/sr through a white reference.

For a point light of intensity ``I`` at ``x_l``, the irradiance at a point ``p`` of the holder is
``E(p) = I cos(theta_i(p)) / |x_l - p|^2``. The white reference (Lambertian, reflectance ``rho``)
has radiance ``rho / pi * E(p_r)``; the sample has ``f(wi, wo) E(p_s)``. Both are imaged by the
same camera in the same frame, so the unknown light intensity and camera throughput cancel:

    f = (S / R) * (rho / pi),

where ``S`` and ``R`` are the mean pixel rates over the sample and the reference after each
pixel has been divided by its own irradiance (relative to a common light intensity) and its
``cos^4`` vignetting. Directions are those from the *actual* sample centre to the actual light
and camera positions (finite distances), not the nominal servo angles. The uncertainty comes from
the HDR merge's per-pixel variances (the sensor noise model).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gonio.errors import DeviceError


@dataclass(frozen=True)
class RegionMeasurement:
    """One BRDF sample measured from a frame.

    Attributes
    ----------
    wi, wo : (3,) unit directions from the sample centre toward the light and the camera, in
        the sample frame.
    f : (C,) BRDF value in 1/sr per colour plane (R, G, B).
    sigma : (C,) its standard deviation from the sensor noise model.
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
    in_r = region(reference_center, 0.8 * reference_radius)
    f = np.zeros(3)
    sig = np.zeros(3)
    n_px = np.zeros(3, dtype=np.int64)
    for c in range(3):
        ms, mr = in_s & (plane_index == c), in_r & (plane_index == c)
        ns, nr = int(ms.sum()), int(mr.sum())
        if ns == 0 or nr == 0:
            raise DeviceError(
                f"sample or reference not visible in the frame (plane {c}: {ns} / {nr} pixels)"
            )
        S, R = norm_rate[ms].mean(), norm_rate[mr].mean()
        vS, vR = norm_var[ms].sum() / ns**2, norm_var[mr].sum() / nr**2
        if not R > 0:
            raise DeviceError("white reference gives no signal: is the light on?")
        f[c] = S / R * reference_albedo / np.pi
        rel_var = vS / max(S * S, 1e-300) + vR / (R * R)
        if frame_fraction is not None and log_time_cov is not None:
            a = frame_fraction[:, ms].mean(axis=1) - frame_fraction[:, mr].mean(axis=1)
            rel_var += float(a @ log_time_cov @ a)
        sig[c] = abs(f[c]) * np.sqrt(rel_var)
        n_px[c] = ns
    p_s = np.array([sample_center[0], sample_center[1], 0.0])
    wi = light_pos - p_s
    wo = cam_pos - p_s
    return RegionMeasurement(wi / np.linalg.norm(wi), wo / np.linalg.norm(wo), f, sig, n_px)
