"""Automatic camera-lidar calibration from an initial guess: the scan rendered as a Flexion image
seen from the camera, its edges matched to the camera image's, robust PnP, coarse to fine."""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.calibration.config import CalibrationConfig
from flexreg.calibration.panorama import normalized_fill
from flexreg.calibration.pnp import solve_pnp
from flexreg.calibration.types import CalibrationResult, DroppedPair, usable_correspondences
from flexreg.core.camera import PinholeCamera
from flexreg.core.correspondences import Correspondences2D3D
from flexreg.core.scan import Scan
from flexreg.core.transforms import apply, as_transform, rotation_error_deg, translation_error_m
from flexreg.errors import CalibrationError, ConfigError, InputError
from flexreg.io.intrinsics import CameraIntrinsics
from flexreg.stages import feature_images as images
from flexreg.stages.camera_pose import (
    MIN_CORRESPONDENCES,
    distort_pixels,
    distortion_coefficients,
)
from flexreg.stages.projection import auto_spherical_camera, project

log = logging.getLogger(__name__)

__all__ = [
    "FlexionView",
    "auto_scale",
    "calibrate_auto",
    "edge_score",
    "propose_correspondences",
    "render_flexion_view",
]


# ============================================================================ Flexion view


@dataclass(eq=False)
class FlexionView:
    """The scan rendered as a Flexion image seen from the camera (at a working scale).

    Attributes
    ----------
    flexion : (h, w) float32
        Flexion n x n (paper eq. 11-13) of the densified depth, NaN where there is no data.
    depth : (h, w) float32, metres
        Densified camera-frame depth ``z`` (NaN where no lidar point is near).
    index : (h, w) int64
        Scan point seen in each pixel by the z-buffer (-1: none).
    camera : PinholeCamera
        The working camera (the undistorted camera scaled by ``scale``).
    scale : float
        Working size / camera image size.
    T_camera_lidar : (4, 4) float64
        Pose the view was rendered from.
    """

    flexion: NDArray[np.float32]
    depth: NDArray[np.float32]
    index: NDArray[np.int64]
    camera: PinholeCamera
    scale: float
    T_camera_lidar: NDArray[np.float64]

    @property
    def valid(self) -> NDArray[np.bool_]:
        """(h, w) bool: pixels with a Flexion value."""
        return np.isfinite(self.flexion)


def _working_camera(intrinsics: CameraIntrinsics, scale: float) -> tuple[PinholeCamera, float]:
    """The distortion-free camera of an image resized by ``scale`` (``cv2.resize`` pixel
    mapping ``u' = (u + 0.5) s - 0.5``)."""
    if intrinsics.size is None:
        raise InputError(intrinsics.source, "image size unknown; check against the image first")
    W, H = intrinsics.size
    w, h = max(8, round(W * scale)), max(8, round(H * scale))
    sx, sy = w / W, h / H
    K = intrinsics.K
    cam = PinholeCamera(
        K[0, 0] * sx,
        K[1, 1] * sy,
        (K[0, 2] + 0.5) * sx - 0.5,
        (K[1, 2] + 0.5) * sy - 0.5,
        w,
        h,
        skew=K[0, 1] * sx,
    )
    return cam, sx


def auto_scale(scan: Scan, intrinsics: CameraIntrinsics) -> float:
    """Working scale at which the lidar's points are about 1.75 pixels apart in the camera.

    The lidar's mean angular point spacing comes from the automatic equirectangular camera
    (:func:`flexreg.stages.projection.auto_spherical_camera`, one pixel per point over the covered
    directions); the camera's angular pixel pitch is ``1 / f``.
    """
    step = auto_spherical_camera(scan.points).dphi
    f = math.sqrt(intrinsics.fx * intrinsics.fy)
    return float(np.clip(1.75 / (f * step), 0.05, 1.0))


def render_flexion_view(
    scan: Scan,
    intrinsics: CameraIntrinsics,
    T_camera_lidar: ArrayLike,
    *,
    scale: float | None = None,
    n: int = 3,
) -> FlexionView:
    """Render the scan as a Flexion image seen from the camera.

    The scan is mapped into the camera frame with ``T_camera_lidar`` and z-buffered into the
    distortion-free camera scaled by ``scale`` (:func:`flexreg.stages.projection.project`); the
    sparse depth is densified by normalised convolution (Gaussian sigma 1, 2, 4 px),
    back-projected (paper eq. 2) and converted to Flexion n x n (eq. 11-13). A lidar is much
    sparser than a camera, so the working scale is chosen (:func:`auto_scale`) to make its
    points about 1.75 pixels apart.

    Parameters
    ----------
    scan : Scan
        Points in the lidar frame.
    intrinsics : CameraIntrinsics
        With the image size known.
    T_camera_lidar : (4, 4) float
    scale : float, optional
        Working size relative to the camera image, in (0, 1].
    n : int
        Flexion grid size.

    Returns
    -------
    FlexionView
    """
    T = as_transform(T_camera_lidar, name="T_camera_lidar")
    s = auto_scale(scan, intrinsics) if scale is None else float(scale)
    if not 0 < s <= 1:
        raise ConfigError(f"scale must be in (0, 1], got {scale!r}")
    cam, s = _working_camera(intrinsics, s)
    ri = project(Scan(points=apply(T, scan.points)), cam)
    z = normalized_fill(np.asarray(ri.xyz[..., 2], dtype=np.float64), ri.valid, (1.0, 2.0, 4.0))
    v, u = np.mgrid[0 : cam.height, 0 : cam.width].astype(np.float64)
    xyz = cam.backproject(u, v, z)
    F = images.flexion(xyz, n=n)
    return FlexionView(
        flexion=F,
        depth=z.astype(np.float32),
        index=ri.index,
        camera=cam,
        scale=s,
        T_camera_lidar=T,
    )


# ============================================================================ edges


def _grey(image: NDArray[np.uint8]) -> NDArray[np.uint8]:
    import cv2  # heavy: OpenCV loads only when calibrating

    a = np.asarray(image)
    if a.ndim == 2:
        return a.astype(np.uint8)
    if a.ndim == 3 and a.shape[2] == 3:
        return np.asarray(cv2.cvtColor(a.astype(np.uint8), cv2.COLOR_BGR2GRAY))
    if a.ndim == 3 and a.shape[2] == 4:
        return np.asarray(cv2.cvtColor(a.astype(np.uint8), cv2.COLOR_BGRA2GRAY))
    raise InputError("image", f"expected a grey or BGR image, got shape {a.shape}")


def _gradient_magnitude(a: NDArray[Any], sigma: float = 1.0) -> NDArray[np.float32]:
    import cv2  # heavy: OpenCV loads only when calibrating

    b = cv2.GaussianBlur(np.asarray(a, dtype=np.float32), (0, 0), sigma)
    gx = cv2.Sobel(b, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(b, cv2.CV_32F, 0, 1, ksize=3)
    return np.asarray(np.sqrt(gx * gx + gy * gy), dtype=np.float32)


def _camera_edges(
    image: NDArray[np.uint8], intrinsics: CameraIntrinsics, view: FlexionView
) -> NDArray[np.float32]:
    """Gradient magnitude of the undistorted, resized camera image (the view's pixel grid)."""
    import cv2  # heavy: OpenCV loads only when calibrating

    g: NDArray[Any] = _grey(image)
    if intrinsics.has_distortion:
        g = np.asarray(
            cv2.undistort(g, np.array(intrinsics.K), distortion_coefficients(intrinsics))
        )
    cam = view.camera
    g = np.asarray(cv2.resize(g, (cam.width, cam.height), interpolation=cv2.INTER_AREA))
    return _gradient_magnitude(g)


def _scan_edges(view: FlexionView) -> NDArray[np.float32]:
    """Edge strength of the Flexion view: ``1 - F`` (low Flexion marks creases and depth
    edges), 0 where there is no data."""
    return np.asarray(np.nan_to_num(1.0 - view.flexion, nan=0.0), dtype=np.float32)


def edge_score(view: FlexionView, camera_edges: NDArray[np.float32]) -> float:
    """Normalised cross-correlation of the Flexion view's edges (``1 - F``) and the camera
    image's gradient magnitude over the view's valid pixels; higher is better aligned."""
    m = view.valid
    if np.count_nonzero(m) < 16:
        return float("-inf")
    a = _scan_edges(view)[m].astype(np.float64)
    b = np.asarray(camera_edges, dtype=np.float64)[m]
    a -= a.mean()
    b -= b.mean()
    d = math.sqrt(float((a * a).sum()) * float((b * b).sum()))
    return float((a * b).sum() / d) if d > 0 else float("-inf")


# ============================================================================ proposals


def _match_patches(
    scan_edges: NDArray[np.float32],
    valid: NDArray[np.bool_],
    camera_edges: NDArray[np.float32],
    radius: int,
    *,
    patch: int,
    max_keypoints: int,
    min_ncc: float,
    uniqueness: float = 0.9,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Patches around the strongest corners of the scan edge image, found again in the camera
    edge image by normalised cross-correlation within ``radius`` pixels.

    Returns ``(scan_xy (K, 2), camera_xy (K, 2), ncc (K,))`` in working pixels; a match is kept
    when its correlation peak reaches ``min_ncc`` and no other peak (3 px away or more) comes
    within ``uniqueness`` of it. The peak is refined to sub-pixel by a parabola fit.
    """
    import cv2  # heavy: OpenCV loads only when calibrating

    H, W = scan_edges.shape
    h = patch // 2
    empty = (np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0))
    if not valid.any():
        return empty
    hi = float(np.percentile(scan_edges[valid], 99)) or 1.0
    e8 = np.clip(scan_edges / hi * 255.0, 0, 255).astype(np.uint8)
    inner = cv2.erode(valid.astype(np.uint8), np.ones((patch, patch), np.uint8), borderValue=0)
    kp = cv2.goodFeaturesToTrack(
        e8, max_keypoints, 0.003, max(3, patch // 4), mask=(inner > 0).astype(np.uint8) * 255
    )
    if kp is None:
        return empty
    pad = radius + patch
    cam = cv2.copyMakeBorder(
        np.asarray(camera_edges, dtype=np.float32), pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=0
    )
    src, dst, score = [], [], []
    for x, y in np.rint(kp.reshape(-1, 2)).astype(int):
        if x - h < 0 or y - h < 0 or x + h >= W or y + h >= H:
            continue
        tpl = scan_edges[y - h : y + h + 1, x - h : x + h + 1]
        if float(tpl.std()) < 1e-6:
            continue
        y0, x0 = y - h - radius + pad, x - h - radius + pad
        win = cam[y0 : y0 + patch + 2 * radius, x0 : x0 + patch + 2 * radius]
        if float(win.std()) < 1e-6:
            continue
        r = cv2.matchTemplate(win, tpl, cv2.TM_CCOEFF_NORMED)
        _, best, _, (j, i) = cv2.minMaxLoc(r)
        if not best >= min_ncc:
            continue
        r2 = r.copy()
        cv2.circle(r2, (j, i), 3, -1.0, -1)
        if r2.max() > uniqueness * best:
            continue
        dx = dy = 0.0
        if 0 < j < r.shape[1] - 1:
            a, b, c = r[i, j - 1], r[i, j], r[i, j + 1]
            den = a - 2 * b + c
            dx = 0.5 * (a - c) / den if den < 0 else 0.0
        if 0 < i < r.shape[0] - 1:
            a, b, c = r[i - 1, j], r[i, j], r[i + 1, j]
            den = a - 2 * b + c
            dy = 0.5 * (a - c) / den if den < 0 else 0.0
        src.append((x, y))
        dst.append((x + j + dx - radius, y + i + dy - radius))
        score.append(best)
    if not src:
        return empty
    return np.asarray(src, float), np.asarray(dst, float), np.asarray(score, float)


def propose_correspondences(
    image: NDArray[np.uint8],
    scan: Scan,
    intrinsics: CameraIntrinsics,
    T_init: ArrayLike,
    *,
    radius_px: float,
    config: CalibrationConfig = CalibrationConfig(),
    view: FlexionView | None = None,
) -> tuple[Correspondences2D3D, FlexionView]:
    """Automatic 2D-3D proposals: Flexion view patches found again in the camera image.

    The scan is rendered as a Flexion image from ``T_init`` (:func:`render_flexion_view`).
    Camera and lidar see different things (colour texture vs. geometry), so the images are
    compared as edge images: ``1 - Flexion`` (creases and depth edges) against the camera's
    gradient magnitude. Patches around the strongest corners of the Flexion edges are searched
    within ``radius_px`` in the camera edge image (normalised cross-correlation, sub-pixel
    peak); each kept match pairs the real lidar point nearest the patch centre with its
    projection under ``T_init`` shifted by the matched offset. Many proposals are wrong; the
    robust solver sorts them out.

    Parameters
    ----------
    image : (H, W, 3) or (H, W) uint8
        Camera image (BGR or grey), the size of the intrinsics.
    scan : Scan
    intrinsics : CameraIntrinsics
    T_init : (4, 4) float
        Initial ``T_camera_lidar``.
    radius_px : float, full-resolution pixels
        Search radius around each predicted position.
    config : CalibrationConfig
    view : FlexionView, optional
        A view rendered from ``T_init`` already.

    Returns
    -------
    proposals : Correspondences2D3D
        Pixels in the (distorted) camera image, points in the lidar frame.
    view : FlexionView
    """
    from scipy.spatial import cKDTree  # heavy: ~0.1 s at import; the CLI imports this package

    T = as_transform(T_init, name="initial guess")
    if view is None:
        view = render_flexion_view(scan, intrinsics, T, scale=config.auto_scale, n=config.flexion_n)
    cam_edges = _camera_edges(image, intrinsics, view)
    radius = max(2, math.ceil(radius_px * view.scale))
    src, dst, _ = _match_patches(
        _scan_edges(view),
        view.valid,
        cam_edges,
        radius,
        patch=config.patch_px,
        max_keypoints=config.max_keypoints,
        min_ncc=config.min_ncc,
    )
    empty = Correspondences2D3D(np.zeros((0, 2)), np.zeros((0, 3)))
    seen = np.argwhere(view.index >= 0)
    if len(src) == 0 or len(seen) == 0:
        return empty, view
    d, k = cKDTree(seen[:, ::-1].astype(np.float64)).query(src, k=1)
    ok = d <= 1.5
    if not ok.any():
        return empty, view
    idx = view.index[seen[k[ok], 0], seen[k[ok], 1]]
    idx, first = np.unique(idx, return_index=True)  # one proposal per lidar point
    flow = (dst - src)[ok][first] / view.scale
    X = scan.points[idx]
    pc = apply(T, X)
    Kf = intrinsics.K
    y = pc[:, 1] / pc[:, 2]
    x = pc[:, 0] / pc[:, 2]
    uv = np.column_stack([Kf[0, 0] * x + Kf[0, 1] * y + Kf[0, 2], Kf[1, 1] * y + Kf[1, 2]]) + flow
    uv = distort_pixels(uv, intrinsics)
    W, H = intrinsics.size or (0, 0)
    inside = (uv[:, 0] >= -0.5) & (uv[:, 0] <= W - 0.5) & (uv[:, 1] >= -0.5)
    inside &= uv[:, 1] <= H - 0.5
    return Correspondences2D3D(uv[inside], X[inside]), view


# ============================================================================ automatic mode


def _checked_image(image: NDArray[np.uint8], intrinsics: CameraIntrinsics) -> NDArray[np.uint8]:
    """The camera image as an array, refused unless the intrinsics know its size."""
    if intrinsics.size is None:
        raise InputError(intrinsics.source, "image size unknown; check against the image first")
    img = np.asarray(image)
    if img.shape[:2] != (intrinsics.height, intrinsics.width):
        raise InputError(
            "image",
            f"image is {img.shape[1]}x{img.shape[0]} px but the intrinsics are for "
            f"{intrinsics.width}x{intrinsics.height}",
        )
    return img


def _search_radii(
    view: FlexionView, intrinsics: CameraIntrinsics, config: CalibrationConfig
) -> list[float]:
    """Search radius of each round, full-resolution pixels: the guess's stated uncertainty at
    the median depth (with a 25 % margin), then 1/2, 1/3, 1/4, 1/6, 1/6, 1/8, ... of it."""
    z = view.depth[np.isfinite(view.depth)]
    z_med = float(np.median(z)) if z.size else 10.0
    f = max(intrinsics.fx, intrinsics.fy)
    r0 = 1.25 * f * (math.radians(config.init_rotation_deg) + config.init_translation_m / z_med)
    fractions = (1.0, 1 / 2, 1 / 3, 1 / 4, 1 / 6, 1 / 6, 1 / 8, 1 / 8)
    return [r0 * fractions[min(k, len(fractions) - 1)] for k in range(config.auto_rounds)]


def _chosen(
    best: CalibrationResult | None,
    poses: list[NDArray[np.float64]],
    rounds: list[dict[str, Any]],
    config: CalibrationConfig,
) -> tuple[CalibrationResult, float]:
    """The best-scoring round's result and the median rotation (degrees) between it and the
    accepted poses of rounds 2, 3, ...; refused when there is none or the rounds disagree."""
    spread = (
        float(np.median([rotation_error_deg(P, best.T_camera_lidar) for P in poses]))
        if best is not None and poses
        else 0.0
    )
    if best is not None and spread > config.max_spread_deg:
        raise CalibrationError(
            f"automatic mode is unstable: its rounds disagree by {spread:.2f} deg (median, "
            f"more than {config.max_spread_deg:g}); the matches are not reliable here, give "
            "correspondences with --pairs"
        )
    if best is None:
        raise CalibrationError(
            "automatic mode found no pose better aligned than the initial guess ("
            + "; ".join(
                f"round {r['round']}: {r['proposals']} proposals, {r['inliers']} inliers"
                for r in rounds
            )
            + "); give correspondences with --pairs"
        )
    return best, spread


def calibrate_auto(
    image: NDArray[np.uint8],
    scan: Scan,
    intrinsics: CameraIntrinsics,
    T_init: ArrayLike,
    *,
    config: CalibrationConfig = CalibrationConfig(),
    pairs: Correspondences2D3D | None = None,
) -> CalibrationResult:
    """Automatic calibration from an initial guess: proposals + robust PnP, coarse to fine.

    Each round renders the Flexion view from the current estimate, proposes correspondences
    (:func:`propose_correspondences`) within a search radius, and solves them (plus any given
    ``pairs``) with :func:`flexreg.calibration.solve_pnp`. The first radius covers the stated
    uncertainty of the guess (``config.init_rotation_deg``, ``config.init_translation_m`` at
    the median depth); it shrinks to 1/2, 1/3, 1/4, 1/6 of that. A round's pose is a candidate
    only with at least ``config.min_inliers`` inliers and within twice the stated uncertainty
    of the guess. The candidate (or the guess itself) whose Flexion view best correlates with
    the camera edges (:func:`edge_score`) wins; matches alone cannot rank poses, since wrong
    poses collect chance inliers among cross-modal matches too. When the matches are reliable
    the rounds agree; if the median rotation between the winner and the later rounds' poses
    exceeds ``config.max_spread_deg``, the mode refuses rather than return a guess.

    Returns
    -------
    CalibrationResult
        ``method="auto"``; ``auto`` holds the per-round record and the edge scores.

    Raises
    ------
    CalibrationError
        No round produced a pose that beats the initial guess, or the rounds disagree.
    """
    t_start = time.perf_counter()
    T0 = as_transform(T_init, name="initial guess")
    img = _checked_image(image, intrinsics)
    given: tuple[DroppedPair, ...] = ()  # given pairs left out (outside, behind the guess)
    if pairs is not None and len(pairs):
        pairs, given = usable_correspondences(pairs, intrinsics, T_camera_lidar=T0)
    scale = config.auto_scale if config.auto_scale is not None else auto_scale(scan, intrinsics)
    view = render_flexion_view(scan, intrinsics, T0, scale=scale, n=config.flexion_n)
    cam_edges = _camera_edges(img, intrinsics, view)
    init_score = edge_score(view, cam_edges)
    thr = max(config.threshold_px, 2.0 / view.scale)
    max_rot = 2.0 * config.init_rotation_deg
    max_trans = 2.0 * config.init_translation_m
    best_score, best = init_score, None
    rounds: list[dict[str, Any]] = []
    poses: list[NDArray[np.float64]] = []  # accepted poses of rounds 2, 3, ...
    T = T0
    for k, radius in enumerate(_search_radii(view, intrinsics, config)):
        proposals, view = propose_correspondences(
            img, scan, intrinsics, T, radius_px=radius, config=config, view=view
        )
        if pairs is not None and len(pairs):
            proposals = pairs.concat(proposals)
        rec: dict[str, Any] = {
            "round": k + 1,
            "radius_px": radius,
            "proposals": len(proposals),
            "inliers": 0,
            "edge_score": None,
            "accepted": False,
        }
        rounds.append(rec)
        if len(proposals) < MIN_CORRESPONDENCES:
            log.info("auto round %d: %d proposals, stopping", k + 1, len(proposals))
            break
        try:
            res = solve_pnp(proposals, intrinsics, config=config, threshold_px=thr)
        except CalibrationError as e:
            log.info("auto round %d: %s", k + 1, e)
            break
        rec["inliers"] = res.inliers
        Tn = res.T_camera_lidar
        plausible = (
            rotation_error_deg(Tn, T0) <= max_rot and translation_error_m(Tn, T0) <= max_trans
        )
        if res.inliers < config.min_inliers or not plausible:
            log.info(
                "auto round %d: %d inliers, %s; keeping the previous estimate",
                k + 1,
                res.inliers,
                "plausible" if plausible else "too far from the initial guess",
            )
            continue
        view = render_flexion_view(scan, intrinsics, Tn, scale=scale, n=config.flexion_n)
        score = edge_score(view, cam_edges)
        rec["edge_score"] = score
        rec["accepted"] = True
        T = Tn
        if k > 0:
            poses.append(Tn)
        if score > best_score:
            best_score, best = score, res
    chosen, spread = _chosen(best, poses, rounds, config)
    chosen.method = "auto"
    chosen.dropped = given + tuple(d for d in chosen.dropped if d.line > 0)
    chosen.T_init = T0
    chosen.timings_s = {"total": time.perf_counter() - t_start}
    for r in rounds:  # JSON has no infinities
        if r["edge_score"] is not None and not math.isfinite(r["edge_score"]):
            r["edge_score"] = None
    chosen.auto = {
        "scale": view.scale,
        "threshold_px": thr,
        "edge_score_init": init_score if math.isfinite(init_score) else None,
        "edge_score_final": best_score,
        "round_spread_deg": spread,
        "rounds": rounds,
    }
    return chosen
