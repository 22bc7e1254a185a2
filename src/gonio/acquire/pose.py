"""Sample-holder pose from a ChArUco board (OpenCV 5's ``CharucoDetector`` and ``solvePnP``).

Frames: OpenCV's camera frame (x right, y down, z forward) and gonio's sample frame (z = holder
normal). The board's own object frame (origin top-left, y down, z into the board) is mapped to
the sample frame by :meth:`gonio.rigs.sim.camera.HolderLayout.board_to_holder`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from gonio.errors import FrameError


@dataclass(frozen=True)
class BoardPose:
    """Pose of the sample frame seen by the camera.

    Attributes
    ----------
    rotation : (3, 3) world(sample)-to-camera rotation ``R``.
    translation : (3,) ``t`` with ``x_cam = R x_sample + t`` (metres).
    n_corners : ChArUco corners used (after outlier rejection).
    reprojection_px : RMS reprojection error of the corners used, pixels.
    covariance : (6, 6) covariance of (rvec, tvec) (radians, metres) from the Gauss-Newton
        approximation ``s^2 (J^T J)^-1`` at the solution, ``s`` the reprojection RMS.
    """

    rotation: np.ndarray
    translation: np.ndarray
    n_corners: int
    reprojection_px: float
    covariance: np.ndarray | None = None

    @property
    def camera_position(self) -> np.ndarray:
        """Camera centre in the sample frame (metres)."""
        return -self.rotation.T @ self.translation


def to_8bit(image: np.ndarray, lo_pct: float = 1.0, hi_pct: float = 99.5) -> np.ndarray:
    """Linear HDR image -> 8-bit for detection, logarithmically.

    Light falls off across the holder (inverse square, cosine), so a linear mapping leaves the
    far side of the board too dark to decode. In log space the board's black/white step is the
    same everywhere; percentiles of the positive values set the range.
    """
    img = np.nan_to_num(np.asarray(image, dtype=np.float64))
    pos = img[img > 0]
    if pos.size == 0:
        return np.zeros(img.shape, dtype=np.uint8)
    lo, hi = np.log(np.percentile(pos, [lo_pct, hi_pct]))
    x = (np.log(np.maximum(img, np.exp(lo))) - lo) / max(hi - lo, 1e-12)
    return (np.clip(x, 0.0, 1.0) * 255 + 0.5).astype(np.uint8)


def mosaic_to_gray(rate: np.ndarray, cfa: str = "RGGB") -> np.ndarray:
    """Bayer mosaic (H, W) -> grey (H, W) by OpenCV's bilinear demosaicking (float32)."""
    import cv2

    codes = {"RGGB": cv2.COLOR_BayerRG2GRAY, "BGGR": cv2.COLOR_BayerBG2GRAY,
             "GRBG": cv2.COLOR_BayerGR2GRAY, "GBRG": cv2.COLOR_BayerGB2GRAY}  # fmt: skip
    img = np.nan_to_num(np.asarray(rate, dtype=np.float64))
    scale = max(float(img.max()), 1e-30)
    # OpenCV demosaics 8- and 16-bit images; 16 bits keep 1/65535 of the range.
    img16 = np.clip(img / scale * 65535, 0, 65535).astype(np.uint16)
    return cv2.cvtColor(img16, codes[cfa]).astype(np.float32) * (scale / 65535)


def opencv_camera_matrix(camera_matrix: np.ndarray) -> np.ndarray:
    """K in OpenCV's pixel convention from K in gonio's.

    gonio's intrinsics (:class:`gonio.rigs.sim.camera.PinholeCamera`, and the pixel rays of
    :mod:`gonio.acquire.radiometry`) put pixel ``i`` on ``[i, i + 1)``, its centre at ``i + 0.5``;
    OpenCV's detectors report coordinates with pixel centres at integers. Feeding PnP the
    unshifted K biases every corner by half a pixel, which tilts and shifts the recovered pose.
    """
    k = np.array(camera_matrix, dtype=np.float64, copy=True)
    k[0, 2] -= 0.5
    k[1, 2] -= 0.5
    return k


def refine_corners(gray: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Chessboard corners (N, 2), OpenCV pixel convention, refined by ``cv2.cornerSubPix``.

    The corners ``CharucoDetector`` returns on a blurred image (any real lens; the simulator's
    :attr:`~gonio.rigs.sim.camera.HolderLayout.blur_m`) are off by 0.2-0.3 px RMS on noise-free
    renders; refining them in a window that stays inside the squares' marker margins brings that
    to ~0.02 px. The half-window is a sixth of the smallest corner spacing in the image (the
    margin is an eighth of a square), between 2 and 4 px, so foreshortened views keep the
    markers' edges out of it.
    """
    import cv2

    pts = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    if len(pts) < 2:
        return pts
    d = np.linalg.norm(pts[:, None, :] - pts[None, :, :], axis=-1)
    np.fill_diagonal(d, np.inf)
    half = int(np.clip(round(float(np.median(d.min(axis=1))) / 6.0), 2, 4))
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
    img = np.asarray(gray, dtype=np.float32)
    out = cv2.cornerSubPix(img, pts.astype(np.float32).reshape(-1, 1, 2), (half, half),
                           (-1, -1), criteria)  # fmt: skip
    return out.reshape(-1, 2).astype(np.float64)


#: Largest reprojection RMS (pixels) a pose found without OpenCV's board check may have: the
#: check is replaced by this one (a marker decoded with a wrong id puts its corners many pixels
#: off any single pose; sound detections reproject to 0.03-0.3 px).
UNCHECKED_MAX_REPROJECTION_PX = 1.0


def estimate_pose(
    gray8: np.ndarray,
    layout: Any,
    camera_matrix: np.ndarray,
    min_corners: int = 6,
    check_board: bool = True,
) -> BoardPose:
    """Detect the board in an 8-bit grey image and solve for the holder pose.

    ``camera_matrix`` is K in gonio's pixel convention (pixel ``i`` spans ``[i, i + 1)``, as in
    :class:`gonio.rigs.sim.camera.PinholeCamera` and :mod:`gonio.acquire.radiometry`); it is
    shifted to OpenCV's (:func:`opencv_camera_matrix`) for detection and PnP, so the pose is
    consistent with gonio's pixel rays.

    ``check_board`` keeps OpenCV's own test of the detection (``CharucoParameters.checkMarkers``:
    each chessboard corner must lie nearer to the corners of its two markers than to any other
    marker's centre, in the image). That test is not perspective-invariant: on a board seen at
    70 deg from its normal, a corner interpolated 2 px off can fail it although every marker is
    decoded right, and the whole board is then dropped ("0 corners"). With ``check_board=False``
    the detection is checked by the solved pose instead: after outlier rejection the corners
    must reproject within :data:`UNCHECKED_MAX_REPROJECTION_PX` RMS.

    Raises FrameError (a DeviceError) when fewer than ``min_corners`` corners are found (a
    problem of this frame that retaking it may fix, not bad user input), or when an unchecked
    detection does not fit one pose.
    """
    import cv2

    camera_matrix = opencv_camera_matrix(camera_matrix)

    params = cv2.aruco.CharucoParameters()
    params.checkMarkers = bool(check_board)
    detector = cv2.aruco.CharucoDetector(layout.board, params)
    corners, ids, _, marker_ids = detector.detectBoard(gray8)
    n = 0 if ids is None else len(ids)
    if n < min_corners:
        m = 0 if marker_ids is None else len(marker_ids)
        raise FrameError(
            f"ChArUco board not found: {n} corners detected, need {min_corners}"
            f" ({m} markers decoded{'' if check_board else ', board check off'})"
        )
    obj, img = layout.board.matchImagePoints(corners, ids)
    obj = layout.board_to_holder(obj)
    img = refine_corners(gray8, np.asarray(img, dtype=np.float64).reshape(-1, 2))
    dist = np.zeros(5)
    ok, rvec, tvec = cv2.solvePnP(obj, img, camera_matrix, dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        raise FrameError("solvePnP failed on the detected ChArUco corners")
    # Corners seen at grazing angles or next to the bright sample are sometimes refined to the
    # wrong sub-pixel position; drop those far off the first solution and solve again.
    keep = np.ones(len(obj), dtype=bool)
    for _ in range(3):
        rvec, tvec = cv2.solvePnPRefineLM(obj[keep], img[keep], camera_matrix, dist, rvec, tvec)
        proj, _ = cv2.projectPoints(obj, rvec, tvec, camera_matrix, dist)
        err = np.linalg.norm(proj.reshape(-1, 2) - img, axis=-1)
        new_keep = err <= max(3.0 * float(np.median(err[keep])), 0.25)
        if new_keep.sum() < min_corners or np.array_equal(new_keep, keep):
            break
        keep = new_keep
    R, _ = cv2.Rodrigues(rvec)
    rms = float(np.sqrt(np.mean(err[keep] ** 2)))
    if not check_board and rms > UNCHECKED_MAX_REPROJECTION_PX:
        raise FrameError(
            f"ChArUco detection does not fit one board pose: reprojection RMS {rms:.2f} px over"
            f" {int(keep.sum())} corners (board check off; at most"
            f" {UNCHECKED_MAX_REPROJECTION_PX} px)"
        )
    _, jac = cv2.projectPoints(obj[keep], rvec, tvec, camera_matrix, dist)
    J = jac[:, :6]
    dof = max(2 * int(keep.sum()) - 6, 1)
    s2 = float(np.sum(err[keep] ** 2)) / dof
    cov = s2 * np.linalg.pinv(J.T @ J)
    return BoardPose(R, tvec.ravel(), int(keep.sum()), rms, cov)


def pose_samples(pose: BoardPose) -> list[tuple[np.ndarray, np.ndarray]]:
    """Sigma points of the pose distribution: 12 (R, t) pairs at +-1 sigma along each
    principal axis of ``pose.covariance`` (unscented transform), for propagating the pose
    uncertainty through non-linear geometry."""
    import cv2

    if pose.covariance is None:
        return []
    rvec, _ = cv2.Rodrigues(pose.rotation)
    x0 = np.concatenate([rvec.ravel(), pose.translation])
    vals, vecs = np.linalg.eigh(pose.covariance)
    out = []
    for k in range(6):
        step = np.sqrt(max(vals[k], 0.0)) * vecs[:, k] * np.sqrt(6.0)
        for sgn in (1.0, -1.0):
            x = x0 + sgn * step
            R, _ = cv2.Rodrigues(x[:3])
            out.append((R, x[3:]))
    return out
