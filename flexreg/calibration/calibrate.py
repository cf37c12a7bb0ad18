"""Camera-lidar extrinsic calibration from 2D-3D correspondences (PnP).

The classic targetless recipe (Scaramuzza et al., the paper's ref. [5]) turns the scan into an
image that shows geometry, pairs points between that image and the photo, and solves a
Perspective-n-Point problem. Here the image is a Flexion image (paper eq. 11-13) and every stage
is a public function:

====================================  =========================================================
stage                                 function
====================================  =========================================================
correspondences from a CSV file       :func:`read_correspondences` (``u,v`` + ``X,Y,Z`` or
                                      ``row,col`` of the scan's range image)
input checks                          :func:`check_correspondences`
PnP (RANSAC + Levenberg-Marquardt)    :func:`solve_pnp`
Flexion image seen from the camera    :func:`render_flexion_view`
automatic proposals                   :func:`propose_correspondences`, :func:`calibrate_auto`
the one call                          :func:`calibrate`
verification / picking aids           :func:`overlay_image`, :func:`picking_views`
====================================  =========================================================

Conventions. ``T_camera_lidar`` is a 4 x 4 float64 rigid transform that maps lidar-frame points
(metres) into the camera frame (OpenCV: x right, y down, z forward):
``p_camera = R p_lidar + t``. Its inverse ``T_lidar_camera`` holds the camera's pose in the
lidar frame. Quaternions are labelled ``xyzw`` (scalar last, SciPy's order) or ``wxyz`` (scalar
first). Pixels follow :mod:`flexreg.core.camera`: integer ``(u, v)`` is the centre of pixel
``[v, u]``, so the image spans ``[-0.5, W - 0.5] x [-0.5, H - 0.5]``. Pixel coordinates are
those of the image as given (distorted); the lens model is OpenCV's (see
:mod:`flexreg.io.intrinsics`).
"""

from __future__ import annotations

import csv
import logging
import math
import time
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.calibration.config import CalibrationConfig
from flexreg.core.transforms import apply, as_transform, invert
from flexreg.errors import ConfigError, InputError, RegistrationError
from flexreg.io.intrinsics import CameraIntrinsics

if TYPE_CHECKING:
    from flexreg.core.camera import PinholeCamera, SphericalCamera
    from flexreg.core.range_image import RangeImage
    from flexreg.core.scan import Scan

log = logging.getLogger(__name__)

__all__ = [
    "MIN_CORRESPONDENCES",
    "CalibrationConfig",
    "CalibrationError",
    "CalibrationResult",
    "Correspondences2D3D",
    "FlexionView",
    "calibrate",
    "calibrate_auto",
    "check_correspondences",
    "edge_score",
    "overlay_image",
    "panorama_camera",
    "panorama_flexion",
    "picking_views",
    "project_points",
    "propose_correspondences",
    "read_correspondences",
    "render_flexion_view",
    "reprojection_errors",
    "scan_range_image",
    "solve_pnp",
]

#: fewest 2D-3D correspondences accepted (PnP needs 4; 6 leave RANSAC something to check)
MIN_CORRESPONDENCES = 6

RngLike = np.random.Generator | int | None


class CalibrationError(RegistrationError):
    """The correspondences do not determine a trustworthy extrinsic."""


# ============================================================================ configuration


# ============================================================================ correspondences


@dataclass(frozen=True, eq=False)
class Correspondences2D3D:
    """Pairs of a camera pixel and a lidar point.

    Attributes
    ----------
    pixels : (N, 2) float64, pixels
        ``(u, v)`` in the camera image (distorted, as the camera took it).
    points : (N, 3) float64, metres
        The same feature's point in the lidar frame.
    lines : (N,) int64
        Line of each pair in its CSV file (1-based); 0 for pairs not read from a file
        (automatic proposals).
    source : str or None
        The CSV file, for messages.
    """

    pixels: NDArray[np.float64]
    points: NDArray[np.float64]
    lines: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    source: str | None = None

    def __post_init__(self) -> None:
        px = np.asarray(self.pixels, dtype=np.float64).reshape(-1, 2)
        pt = np.asarray(self.points, dtype=np.float64).reshape(-1, 3)
        if len(px) != len(pt):
            raise InputError(
                self.source or "correspondences", f"{len(px)} pixels but {len(pt)} points"
            )
        if not (np.isfinite(px).all() and np.isfinite(pt).all()):
            raise InputError(self.source or "correspondences", "NaN or Inf in pixels or points")
        ln = np.asarray(self.lines, dtype=np.int64).reshape(-1)
        if ln.size == 0:
            ln = np.zeros(len(px), dtype=np.int64)
        if len(ln) != len(px):
            raise InputError(self.source or "correspondences", "one line number per pair needed")
        object.__setattr__(self, "pixels", px)
        object.__setattr__(self, "points", pt)
        object.__setattr__(self, "lines", ln)

    def __len__(self) -> int:
        return len(self.pixels)

    def __repr__(self) -> str:
        src = f" from {self.source}" if self.source else ""
        return f"Correspondences2D3D({len(self)} pairs{src})"

    def subset(self, mask: ArrayLike) -> Correspondences2D3D:
        """The pairs selected by a boolean mask or index array."""
        m = np.asarray(mask)
        return Correspondences2D3D(self.pixels[m], self.points[m], self.lines[m], self.source)

    def concat(self, other: Correspondences2D3D) -> Correspondences2D3D:
        """These pairs followed by ``other``'s (source kept from ``self``)."""
        return Correspondences2D3D(
            np.concatenate([self.pixels, other.pixels]),
            np.concatenate([self.points, other.points]),
            np.concatenate([self.lines, other.lines]),
            self.source or other.source,
        )

    def where(self, i: int) -> str:
        """Where pair ``i`` came from: ``"line 12"`` or ``"pair 3"``."""
        return f"line {self.lines[i]}" if self.lines[i] > 0 else f"pair {i + 1}"


def panorama_camera(points: ArrayLike) -> SphericalCamera:
    """Equirectangular camera for an unstructured lidar cloud, one pixel per point spacing.

    A spinning lidar samples azimuth much more finely than elevation (e.g. 0.17 deg between
    firings, 0.4 deg between rings). The azimuth pitch is the median angular distance of each
    point to its nearest neighbour; the polar pitch makes the pixel count match the points
    over the covered directions, as :func:`flexreg.stages.projection.auto_spherical_camera` does
    (whose isotropic pitch this is for a scanner with square sampling). When that function
    recognises evenly spaced rings (one row per ring), its camera is used as it is.
    """
    from scipy.spatial import cKDTree

    from flexreg.core.camera import SphericalCamera
    from flexreg.stages.projection import auto_spherical_camera

    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    base = auto_spherical_camera(P)
    if not math.isclose(base.dphi, base.dtheta, rel_tol=1e-6):
        return base  # evenly spaced rings recognised: one row per ring already
    r = np.linalg.norm(P, axis=1)
    dirs = P[r > 0] / r[r > 0, None]
    if len(dirs) < 100:
        return base
    rng = np.random.default_rng(0)  # deterministic subsample for the spacing statistic
    probe = dirs[rng.choice(len(dirs), min(len(dirs), 20000), replace=False)]
    d, _ = cKDTree(dirs).query(probe, k=2)
    s0 = base.dphi
    a = float(np.clip(np.median(d[:, 1]), s0 / 4, s0))
    b = s0 * s0 / a
    H = max(1, math.floor((base.theta_max - base.theta_min) / b + 0.5))
    th_hi = min(np.pi, base.theta_min + H * b)
    span = base.phi_max - base.phi_min
    W = max(1, math.ceil(span / a - 1e-9))
    return SphericalCamera(W, H, base.phi_min, base.phi_max, base.theta_min, th_hi)


def _nearest_fill(image: RangeImage, max_px: float) -> RangeImage:
    """Give every no-return pixel within ``max_px`` of a return that nearest return (the real
    point, its index and intensity)."""
    from scipy import ndimage

    from flexreg.core.range_image import RangeImage

    v = image.valid
    if v.all() or not v.any():
        return image
    dist, (ri, ci) = ndimage.distance_transform_edt(~v, return_indices=True)
    fill = ~v & (dist <= max_px)
    xyz = image.xyz.copy()
    index = image.index.copy()
    xyz[fill] = image.xyz[ri[fill], ci[fill]]
    index[fill] = image.index[ri[fill], ci[fill]]
    inten = None
    if image.intensity is not None:
        inten = image.intensity.copy()
        inten[fill] = image.intensity[ri[fill], ci[fill]]
    return RangeImage(xyz=xyz, valid=v | fill, index=index, camera=image.camera, intensity=inten)


def scan_range_image(scan: Scan) -> RangeImage:
    """The range image whose ``(row, col)`` a correspondence file refers to.

    A scan with a native grid (PTX, gridded E57, organised PCD, ...) keeps it
    (``flexreg.range_image``) with isolated no-returns filled
    (:func:`flexreg.stages.projection.fill_holes`). An unstructured cloud (KITTI ``.bin``, most
    ``.pcd``) is z-buffered into :func:`panorama_camera`, and each empty pixel within 2 pixels
    of a return shows the nearest return, so every pixel holds a real lidar point. This is the
    grid of the ``panorama.png`` :func:`picking_views` draws.
    """
    from flexreg.stages.projection import fill_holes, project, range_image

    if scan.has_grid:
        return fill_holes(range_image(scan))
    return _nearest_fill(project(scan, panorama_camera(scan.points)), 2.0)


def panorama_flexion(scan: Scan, *, n: int = 3) -> NDArray[np.float32]:
    """Flexion n x n image (paper eq. 11-13) on the grid of :func:`scan_range_image`.

    Native grids are converted directly. For a projected panorama the range is densified
    first (normalised convolution of the returns' ranges, back-projected along each pixel's
    ray with eq. 7-8), so the sparse rows of a spinning lidar give a readable image.
    """
    from flexreg.core.camera import SphericalCamera
    from flexreg.stages import feature_images as images
    from flexreg.stages.projection import fill_holes, project, range_image

    if scan.has_grid:
        return images.flexion(fill_holes(range_image(scan)), n=n)
    cam = panorama_camera(scan.points)
    ri = project(scan, cam)
    r = _normalized_fill(ri.range.astype(np.float64), ri.valid, (1.0, 2.0))
    v, u = np.mgrid[0 : cam.height, 0 : cam.width].astype(np.float64)
    assert isinstance(cam, SphericalCamera)
    return images.flexion(cam.backproject(u, v, r), n=n, wrap=cam.wraps)


def _parse_rows(path: Path) -> tuple[list[str], list[tuple[int, list[str]]]]:
    """Header (lower-case names) and ``(line number, fields)`` of a CSV file."""
    try:
        text = path.read_text(encoding="utf-8-sig", errors="replace")
    except OSError as e:
        raise InputError(path, f"cannot read: {e.strerror or e}") from None
    lines = text.splitlines()
    header: list[str] | None = None
    rows: list[tuple[int, list[str]]] = []
    delimiter = ","
    for lineno, line in enumerate(lines, start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        if header is None:
            if "," not in s:
                delimiter = ";" if ";" in s else ("\t" if "\t" in s else ",")
            header = [h.strip().lower() for h in next(csv.reader([s], delimiter=delimiter))]
            continue
        rows.append((lineno, [f.strip() for f in next(csv.reader([s], delimiter=delimiter))]))
    if header is None:
        raise InputError(
            path, "empty correspondence file: expected a header u,v,X,Y,Z or u,v,row,col"
        )
    return header, rows


def _columns(path: Path, header: list[str]) -> tuple[str, list[int]]:
    """``("xyz" | "grid", column indices)`` from a header."""
    pos = {name: i for i, name in enumerate(header)}
    if len(pos) != len(header):
        raise InputError(path, f"line 1: duplicate column names in header {','.join(header)}")
    if "u" not in pos or "v" not in pos:
        raise InputError(path, f"header must name columns u,v; got {','.join(header)}")
    has_xyz = all(c in pos for c in ("x", "y", "z"))
    has_grid = all(c in pos for c in ("row", "col"))
    if has_xyz and has_grid:
        raise InputError(path, "give either X,Y,Z or row,col columns, not both")
    if has_xyz:
        return "xyz", [pos[c] for c in ("u", "v", "x", "y", "z")]
    if has_grid:
        return "grid", [pos[c] for c in ("u", "v", "row", "col")]
    raise InputError(
        path, f"header must be u,v,X,Y,Z or u,v,row,col (any order); got {','.join(header)}"
    )


def read_correspondences(
    path: str | PathLike[str],
    *,
    scan: Scan | None = None,
    range_image: RangeImage | None = None,
) -> Correspondences2D3D:
    """Read 2D-3D correspondences from a CSV file.

    The first non-comment line is a header naming the columns (case-insensitive, any order,
    extra columns ignored): ``u,v`` (camera pixel) and either ``X,Y,Z`` (lidar frame, metres)
    or ``row,col`` (pixel of the scan's range image, see :func:`scan_range_image`; fractional
    values are interpolated bilinearly). Blank lines and lines starting with ``#`` are skipped.

    Parameters
    ----------
    path : path-like
    scan : Scan, optional
        Needed for ``row,col`` files (lifted on :func:`scan_range_image`).
    range_image : RangeImage, optional
        Lift ``row,col`` on this image instead.

    Returns
    -------
    Correspondences2D3D

    Raises
    ------
    InputError
        Missing file, bad header, or a malformed line (named by its line number): wrong
        number of fields, a value that is not a finite number, a ``row,col`` outside the range
        image or on a pixel without a lidar return.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(p, "no such file")
    header, rows = _parse_rows(p)
    kind, cols = _columns(p, header)
    names = ["u", "v", "X", "Y", "Z"] if kind == "xyz" else ["u", "v", "row", "col"]
    values = np.empty((len(rows), len(cols)), dtype=np.float64)
    lines = np.empty(len(rows), dtype=np.int64)
    for k, (lineno, fields) in enumerate(rows):
        if len(fields) != len(header):
            raise InputError(
                p,
                f"line {lineno}: expected {len(header)} values ({','.join(header)}), "
                f"got {len(fields)}",
            )
        for j, (c, name) in enumerate(zip(cols, names, strict=True)):
            try:
                x = float(fields[c])
            except ValueError:
                raise InputError(
                    p, f"line {lineno}: {name} is not a number: {fields[c]!r}"
                ) from None
            if not math.isfinite(x):
                raise InputError(p, f"line {lineno}: {name} is not finite: {fields[c]!r}")
            values[k, j] = x
        lines[k] = lineno
    pixels = values[:, :2]
    if kind == "xyz":
        return Correspondences2D3D(pixels, values[:, 2:5], lines, str(p))
    if range_image is None:
        if scan is None:
            raise InputError(p, "row,col correspondences need the scan they refer to")
        range_image = scan_range_image(scan)
    points = _lift_grid(range_image, values[:, 2:4], lines, p)
    return Correspondences2D3D(pixels, points, lines, str(p))


def _lift_grid(
    image: RangeImage, rowcol: NDArray[np.float64], lines: NDArray[np.int64], p: Path
) -> NDArray[np.float64]:
    """3D points of ``(row, col)`` range-image pixels; integer ones exactly, others bilinearly."""
    from flexreg.stages.correspondences import lift

    H, W = image.shape
    out = np.empty((len(rowcol), 3))
    for k, (r, c) in enumerate(rowcol):
        if not (-0.5 <= r <= H - 0.5 and -0.5 <= c <= W - 0.5):
            raise InputError(
                p,
                f"line {lines[k]}: row {r:g}, col {c:g} lies outside the scan's {W}x{H} range "
                "image (see --export-views)",
            )
        ri, ci = round(r), round(c)
        if abs(r - ri) < 1e-9 and abs(c - ci) < 1e-9:
            if not image.valid[ri, ci]:
                raise InputError(
                    p, f"line {lines[k]}: range-image pixel row {ri}, col {ci} has no lidar return"
                )
            out[k] = image.xyz[ri, ci]
            continue
        pts, ok = lift(image, np.array([[c, r]]))
        if not ok[0]:
            raise InputError(
                p,
                f"line {lines[k]}: row {r:g}, col {c:g} is not between four lidar returns on one "
                "surface; use whole pixel coordinates",
            )
        out[k] = pts[0]
    return out


# ============================================================================ projection


def _rvec_tvec(T: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    import cv2

    rvec, _ = cv2.Rodrigues(np.ascontiguousarray(T[:3, :3]))
    return np.asarray(rvec, dtype=np.float64).reshape(3), np.array(T[:3, 3], dtype=np.float64)


def _from_rvec_tvec(rvec: ArrayLike, tvec: ArrayLike) -> NDArray[np.float64]:
    import cv2

    R, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.asarray(tvec, dtype=np.float64).reshape(3)
    return T


def project_points(
    points: ArrayLike, intrinsics: CameraIntrinsics, T_camera_lidar: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Project lidar points into the camera image, lens distortion included.

    ``x = K distort(R p + t)`` (paper eq. 1 with OpenCV's distortion model), via
    ``cv2.projectPoints``.

    Parameters
    ----------
    points : (N, 3) float, metres, lidar frame
    intrinsics : CameraIntrinsics
    T_camera_lidar : (4, 4) float

    Returns
    -------
    uv : (N, 2) float64, pixels
        NaN for points not in front of the camera (``z <= 0``).
    z : (N,) float64, metres
        Depth in the camera frame.

    Examples
    --------
    >>> K = [[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]
    >>> uv, z = project_points([[0.1, -0.2, 2.0]], CameraIntrinsics(K, []), np.eye(4))
    >>> uv.round(6).tolist(), z.tolist()
    ([[345.0, 190.0]], [2.0])
    """
    import cv2

    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    T = np.asarray(T_camera_lidar, dtype=np.float64)
    z = P @ T[2, :3] + T[2, 3]
    uv = np.full((len(P), 2), np.nan)
    front = z > 0
    if front.any():
        rvec, tvec = _rvec_tvec(T)
        proj, _ = cv2.projectPoints(
            np.ascontiguousarray(P[front]), rvec, tvec, np.array(intrinsics.K), _dist(intrinsics)
        )
        uv[front] = proj.reshape(-1, 2)
    return uv, z


def _dist(intrinsics: CameraIntrinsics) -> NDArray[np.float64]:
    d = np.array(intrinsics.distortion, dtype=np.float64)
    return d if d.size else np.zeros(5)


def reprojection_errors(
    correspondences: Correspondences2D3D,
    intrinsics: CameraIntrinsics,
    T_camera_lidar: ArrayLike,
) -> NDArray[np.float64]:
    """(N,) float64 distance in pixels between each pixel and its point's projection; ``inf``
    for points behind the camera."""
    uv, z = project_points(correspondences.points, intrinsics, T_camera_lidar)
    err = np.linalg.norm(uv - correspondences.pixels, axis=1)
    err[~(z > 0)] = np.inf
    return err


# ============================================================================ checks


def check_correspondences(
    correspondences: Correspondences2D3D,
    intrinsics: CameraIntrinsics,
    *,
    T_init: ArrayLike | None = None,
) -> None:
    """Reject correspondences PnP cannot use, naming the offending lines.

    Raises
    ------
    InputError
        Fewer than :data:`MIN_CORRESPONDENCES` pairs, a pixel outside the image (intrinsics
        must know the image size), or -- with an initial guess -- a lidar point that lies
        behind the camera under it.
    """
    c = correspondences
    src = c.source or "correspondences"
    if len(c) < MIN_CORRESPONDENCES:
        raise InputError(
            src,
            f"only {len(c)} correspondence(s); camera-lidar calibration needs at least "
            f"{MIN_CORRESPONDENCES}",
        )
    if intrinsics.size is not None:
        W, H = intrinsics.size
        u, v = c.pixels[:, 0], c.pixels[:, 1]
        out = np.flatnonzero((u < -0.5) | (u > W - 0.5) | (v < -0.5) | (v > H - 0.5))
        if out.size:
            i = int(out[0])
            more = f" (and {out.size - 1} more)" if out.size > 1 else ""
            raise InputError(
                src,
                f"{c.where(i)}: pixel ({u[i]:g}, {v[i]:g}) lies outside the {W}x{H} camera "
                f"image{more}",
            )
    if T_init is not None:
        T = as_transform(T_init, name="initial guess")
        z = c.points @ T[2, :3] + T[2, 3]
        behind = np.flatnonzero(z <= 0)
        if behind.size:
            i = int(behind[0])
            more = f" (and {behind.size - 1} more)" if behind.size > 1 else ""
            raise InputError(
                src,
                f"{c.where(i)}: lidar point ({', '.join(f'{x:.3f}' for x in c.points[i])}) lies "
                f"behind the camera of the initial guess (z = {z[i]:.2f} m){more}",
            )


# ============================================================================ result


@dataclass(eq=False)
class CalibrationResult:
    """A camera-lidar extrinsic with the evidence for it.

    Attributes
    ----------
    T_camera_lidar : (4, 4) float64
        Maps lidar points into the camera frame (x right, y down, z forward), metres.
    correspondences : Correspondences2D3D
        Every pair the solver saw (for the automatic mode: the final round's).
    inlier_mask : (N,) bool
        Pairs within ``threshold_px`` of their projection (in front of the camera).
    residuals_px : (N,) float64, pixels
        Reprojection error of every pair under ``T_camera_lidar`` (inf behind the camera).
    threshold_px : float, pixels
    intrinsics : CameraIntrinsics
    method : str
        ``"pairs"`` (given correspondences) or ``"auto"`` (automatic proposals).
    config : CalibrationConfig
    timings_s : dict of str to float
    T_init : (4, 4) float64 or None
        The initial guess, when one was used.
    auto : dict or None
        Automatic mode: per-round matches, inliers, search radius and edge score.
    """

    T_camera_lidar: NDArray[np.float64]
    correspondences: Correspondences2D3D
    inlier_mask: NDArray[np.bool_]
    residuals_px: NDArray[np.float64]
    threshold_px: float
    intrinsics: CameraIntrinsics
    method: str = "pairs"
    config: CalibrationConfig = field(default_factory=CalibrationConfig)
    timings_s: dict[str, float] = field(default_factory=dict)
    T_init: NDArray[np.float64] | None = None
    auto: dict[str, Any] | None = None

    def __repr__(self) -> str:
        t = self.translation_m
        return (
            f"CalibrationResult({self.method}, {self.inliers}/{len(self.correspondences)} "
            f"inliers, RMSE {self.reprojection_rmse_px:.2f} px, "
            f"t = [{t[0]:.3f}, {t[1]:.3f}, {t[2]:.3f}] m)"
        )

    @property
    def T_lidar_camera(self) -> NDArray[np.float64]:
        """(4, 4) float64 inverse: maps camera points into the lidar frame (camera pose)."""
        return invert(self.T_camera_lidar)

    @property
    def translation_m(self) -> NDArray[np.float64]:
        """(3,) float64 ``t`` of ``T_camera_lidar``: the lidar origin in the camera frame."""
        return self.T_camera_lidar[:3, 3].copy()

    @property
    def quaternion_xyzw(self) -> NDArray[np.float64]:
        """(4,) float64 rotation of ``T_camera_lidar`` as a unit quaternion, scalar last."""
        from scipy.spatial.transform import Rotation

        q = np.asarray(Rotation.from_matrix(self.T_camera_lidar[:3, :3]).as_quat())
        return q if q[3] >= 0 else -q

    @property
    def quaternion_wxyz(self) -> NDArray[np.float64]:
        """(4,) float64 the same quaternion, scalar first."""
        return np.roll(self.quaternion_xyzw, 1)

    @property
    def inliers(self) -> int:
        """Number of inlier pairs."""
        return int(np.count_nonzero(self.inlier_mask))

    @property
    def reprojection_rmse_px(self) -> float:
        """Root mean square reprojection error of the inliers, pixels (NaN without inliers)."""
        r = self.residuals_px[self.inlier_mask]
        return float(np.sqrt(np.mean(r * r))) if r.size else float("nan")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict: both transforms, labelled quaternions, RMSE, per-pair residuals."""
        c = self.correspondences
        pairs = [
            {
                "line": int(c.lines[i]) or None,
                "u": float(c.pixels[i, 0]),
                "v": float(c.pixels[i, 1]),
                "X": float(c.points[i, 0]),
                "Y": float(c.points[i, 1]),
                "Z": float(c.points[i, 2]),
                "residual_px": float(self.residuals_px[i])
                if math.isfinite(self.residuals_px[i])
                else None,
                "inlier": bool(self.inlier_mask[i]),
            }
            for i in range(len(c))
        ]
        rvec, _ = _rvec_tvec(self.T_camera_lidar)
        return {
            "T_camera_lidar": self.T_camera_lidar.tolist(),
            "T_lidar_camera": self.T_lidar_camera.tolist(),
            "convention": (
                "T_camera_lidar maps lidar points (metres) into the camera frame "
                "(x right, y down, z forward): p_camera = R p_lidar + t; "
                "T_lidar_camera is its inverse (the camera pose in the lidar frame)"
            ),
            "rotation_camera_lidar": {
                "quaternion_xyzw": self.quaternion_xyzw.tolist(),
                "quaternion_wxyz": self.quaternion_wxyz.tolist(),
                "rotation_vector_rad": rvec.tolist(),
            },
            "translation_camera_lidar_m": self.translation_m.tolist(),
            "camera_position_in_lidar_m": self.T_lidar_camera[:3, 3].tolist(),
            "method": self.method,
            "solver": "cv2.solvePnPRansac (USAC_MAGSAC) + cv2.solvePnPRefineLM on the inliers",
            "reprojection_rmse_px": self.reprojection_rmse_px,
            "inliers": self.inliers,
            "correspondences": len(c),
            "threshold_px": self.threshold_px,
            "intrinsics": self.intrinsics.to_dict(),
            "T_init": None if self.T_init is None else self.T_init.tolist(),
            "auto": self.auto,
            "timings_s": self.timings_s,
            "seed": self.config.seed,
            "config": self.config.to_dict(),
            "pairs": pairs,
        }


# ============================================================================ solver


def solve_pnp(
    correspondences: Correspondences2D3D,
    intrinsics: CameraIntrinsics,
    *,
    config: CalibrationConfig = CalibrationConfig(),
    T_init: ArrayLike | None = None,
    threshold_px: float | None = None,
) -> CalibrationResult:
    """``T_camera_lidar`` from 2D-3D pairs: PnP in MAGSAC++ RANSAC, then Levenberg-Marquardt.

    ``cv2.solvePnPRansac`` with OpenCV's USAC framework (MAGSAC++ scoring, seeded by
    ``config.seed``) finds the pose and its inliers; ``cv2.solvePnPRefineLM`` then minimises the
    reprojection error of the inliers, and the inliers are re-selected under the refined pose
    (until they no longer change, at most 5 times). A pair is an inlier when its point lies in
    front of the camera and reprojects within ``threshold_px``.

    Parameters
    ----------
    correspondences : Correspondences2D3D
    intrinsics : CameraIntrinsics
        Pixels are distorted image coordinates; the distortion is modelled, not removed.
    config : CalibrationConfig
    T_init : (4, 4) float, optional
        Initial guess, used for the checks of :func:`check_correspondences` only.
    threshold_px : float, optional
        Inlier threshold, default ``config.threshold_px``.

    Returns
    -------
    CalibrationResult

    Raises
    ------
    InputError
        See :func:`check_correspondences`.
    CalibrationError
        RANSAC finds no pose with at least :data:`MIN_CORRESPONDENCES` inliers in front of the
        camera.
    """
    import cv2

    t0 = time.perf_counter()
    c = correspondences
    check_correspondences(c, intrinsics, T_init=T_init)
    thr = float(config.threshold_px if threshold_px is None else threshold_px)
    obj = np.ascontiguousarray(c.points)
    img = np.ascontiguousarray(c.pixels)
    params = cv2.UsacParams()
    params.score = cv2.SCORE_METHOD_MAGSAC
    params.sampler = cv2.SAMPLING_UNIFORM
    params.threshold = thr
    params.confidence = config.confidence
    params.maxIterations = config.max_iterations
    params.randomGeneratorState = config.seed
    params.loMethod = cv2.LOCAL_OPTIM_SIGMA
    params.loIterations = 10
    params.loSampleSize = min(14, len(c))
    params.final_polisher = cv2.NONE_POLISHER
    try:
        ok, _, rvec, tvec, inl = cv2.solvePnPRansac(
            obj, img, np.array(intrinsics.K), _dist(intrinsics), params=params
        )
    except cv2.error as e:
        raise CalibrationError(f"PnP failed on {len(c)} correspondences: {e.err}") from None
    if not ok or inl is None or len(inl) < 4:
        raise CalibrationError(
            f"RANSAC found no pose explaining at least 4 of {len(c)} correspondences within "
            f"{thr:g} px"
        )
    T = _from_rvec_tvec(rvec, tvec)
    t_ransac = time.perf_counter() - t0
    mask = _inliers(c, intrinsics, T, thr)
    if config.refine:
        for _ in range(5):
            if np.count_nonzero(mask) < 4:
                break
            rvec, tvec = _rvec_tvec(T)
            rvec, tvec = cv2.solvePnPRefineLM(
                obj[mask],
                img[mask],
                np.array(intrinsics.K),
                _dist(intrinsics),
                rvec.reshape(3, 1),
                tvec.reshape(3, 1),
                (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-12),
            )
            T = _from_rvec_tvec(rvec, tvec)
            new = _inliers(c, intrinsics, T, thr)
            if np.array_equal(new, mask):
                break
            mask = new
    res = reprojection_errors(c, intrinsics, T)
    n_in = int(np.count_nonzero(mask))
    if n_in < MIN_CORRESPONDENCES:
        raise CalibrationError(
            f"only {n_in} of {len(c)} correspondences agree on one pose within {thr:g} px "
            f"(at least {MIN_CORRESPONDENCES} needed)"
        )
    timings = {"ransac": t_ransac, "refine": time.perf_counter() - t0 - t_ransac}
    log.info(
        "PnP: %d/%d inliers, RMSE %.3f px", n_in, len(c), float(np.sqrt(np.mean(res[mask] ** 2)))
    )
    return CalibrationResult(
        T_camera_lidar=T,
        correspondences=c,
        inlier_mask=mask,
        residuals_px=res,
        threshold_px=thr,
        intrinsics=intrinsics,
        method="pairs",
        config=config,
        timings_s=timings,
        T_init=None if T_init is None else as_transform(T_init, name="initial guess"),
    )


def _inliers(
    c: Correspondences2D3D, intrinsics: CameraIntrinsics, T: NDArray[np.float64], thr: float
) -> NDArray[np.bool_]:
    err = reprojection_errors(c, intrinsics, T)
    return np.asarray(err <= thr)


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
    from flexreg.core.camera import PinholeCamera

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
    from flexreg.stages.projection import auto_spherical_camera

    step = auto_spherical_camera(scan.points).dphi
    f = math.sqrt(intrinsics.fx * intrinsics.fy)
    return float(np.clip(1.75 / (f * step), 0.05, 1.0))


def _normalized_fill(
    values: NDArray[np.float64], mask: NDArray[np.bool_], sigmas: tuple[float, ...]
) -> NDArray[np.float64]:
    """Fill an image from its valid samples by normalised convolution, coarse scales only where
    the fine ones found too little support (Knutsson & Westin's normalised averaging)."""
    import cv2

    out = np.full(values.shape, np.nan)
    v = np.where(mask, values, 0.0)
    m = mask.astype(np.float64)
    for s in sigmas:
        num = cv2.GaussianBlur(v, (0, 0), s)
        den = cv2.GaussianBlur(m, (0, 0), s)
        with np.errstate(invalid="ignore", divide="ignore"):
            r = num / den
        fill = np.isnan(out) & (den > 0.1)
        out[fill] = r[fill]
    return out


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
    sparse
    depth is densified by normalised convolution (Gaussian sigma 1, 2, 4 px), back-projected
    (paper eq. 2) and converted to Flexion n x n (eq. 11-13). A lidar is much sparser than a
    camera, so the working scale is chosen (:func:`auto_scale`) to make its points about 1.75
    pixels apart.

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
    from flexreg.core.scan import Scan as ScanT
    from flexreg.stages import feature_images as images
    from flexreg.stages.projection import project

    T = as_transform(T_camera_lidar, name="T_camera_lidar")
    s = auto_scale(scan, intrinsics) if scale is None else float(scale)
    if not 0 < s <= 1:
        raise ConfigError(f"scale must be in (0, 1], got {scale!r}")
    cam, s = _working_camera(intrinsics, s)
    ri = project(ScanT(points=apply(T, scan.points)), cam)
    z = _normalized_fill(ri.xyz[..., 2], ri.valid, (1.0, 2.0, 4.0))
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


def _grey(image: NDArray[np.uint8]) -> NDArray[np.uint8]:
    import cv2

    a = np.asarray(image)
    if a.ndim == 2:
        return a.astype(np.uint8)
    if a.ndim == 3 and a.shape[2] == 3:
        return np.asarray(cv2.cvtColor(a.astype(np.uint8), cv2.COLOR_BGR2GRAY))
    if a.ndim == 3 and a.shape[2] == 4:
        return np.asarray(cv2.cvtColor(a.astype(np.uint8), cv2.COLOR_BGRA2GRAY))
    raise InputError("image", f"expected a grey or BGR image, got shape {a.shape}")


def _gradient_magnitude(a: NDArray[Any], sigma: float = 1.0) -> NDArray[np.float32]:
    import cv2

    b = cv2.GaussianBlur(np.asarray(a, dtype=np.float32), (0, 0), sigma)
    gx = cv2.Sobel(b, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(b, cv2.CV_32F, 0, 1, ksize=3)
    return np.asarray(np.sqrt(gx * gx + gy * gy), dtype=np.float32)


def _camera_edges(
    image: NDArray[np.uint8], intrinsics: CameraIntrinsics, view: FlexionView
) -> NDArray[np.float32]:
    """Gradient magnitude of the undistorted, resized camera image (the view's pixel grid)."""
    import cv2

    g: NDArray[Any] = _grey(image)
    if intrinsics.has_distortion:
        g = np.asarray(cv2.undistort(g, np.array(intrinsics.K), _dist(intrinsics)))
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


# ============================================================================ automatic mode


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
    import cv2

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


def _distort_pixels(uv: NDArray[np.float64], intrinsics: CameraIntrinsics) -> NDArray[np.float64]:
    """Undistorted pixel coordinates -> the distorted image's (OpenCV model)."""
    import cv2

    if not intrinsics.has_distortion or len(uv) == 0:
        return uv
    K = intrinsics.K
    y = (uv[:, 1] - K[1, 2]) / K[1, 1]
    x = (uv[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
    rays = np.column_stack([x, y, np.ones_like(x)])
    out, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), np.array(K), _dist(intrinsics))
    return np.asarray(out.reshape(-1, 2), dtype=np.float64)


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
    from scipy.spatial import cKDTree

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
    uv = _distort_pixels(uv, intrinsics)
    W, H = intrinsics.size or (0, 0)
    inside = (uv[:, 0] >= -0.5) & (uv[:, 0] <= W - 0.5) & (uv[:, 1] >= -0.5)
    inside &= uv[:, 1] <= H - 0.5
    return Correspondences2D3D(uv[inside], X[inside]), view


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
    ``pairs``) with :func:`solve_pnp`. The first radius covers the stated uncertainty of the
    guess (``config.init_rotation_deg``, ``config.init_translation_m`` at the median depth); it
    shrinks to 1/2, 1/3, 1/4, 1/6 of that. A round's pose is a candidate only with at least
    ``config.min_inliers`` inliers and within twice the stated uncertainty of the guess.
    The candidate (or the guess itself) whose Flexion view best correlates with the camera
    edges (:func:`edge_score`) wins; matches alone cannot rank poses, since wrong poses
    collect chance inliers among cross-modal matches too. When the matches are reliable the
    rounds agree; if the median rotation between the winner and the later rounds' poses
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
    from flexreg.core.transforms import rotation_error_deg, translation_error_m

    t_start = time.perf_counter()
    T0 = as_transform(T_init, name="initial guess")
    if intrinsics.size is None:
        raise InputError(intrinsics.source, "image size unknown; check against the image first")
    img = np.asarray(image)
    if img.shape[:2] != (intrinsics.height, intrinsics.width):
        raise InputError(
            "image",
            f"image is {img.shape[1]}x{img.shape[0]} px but the intrinsics are for "
            f"{intrinsics.width}x{intrinsics.height}",
        )
    if pairs is not None and len(pairs):
        check_correspondences(pairs, intrinsics, T_init=T0)
    scale = config.auto_scale if config.auto_scale is not None else auto_scale(scan, intrinsics)
    view = render_flexion_view(scan, intrinsics, T0, scale=scale, n=config.flexion_n)
    cam_edges = _camera_edges(img, intrinsics, view)
    init_score = edge_score(view, cam_edges)
    z = view.depth[np.isfinite(view.depth)]
    z_med = float(np.median(z)) if z.size else 10.0
    f = max(intrinsics.fx, intrinsics.fy)
    r0 = 1.25 * f * (math.radians(config.init_rotation_deg) + config.init_translation_m / z_med)
    fractions = (1.0, 1 / 2, 1 / 3, 1 / 4, 1 / 6, 1 / 6, 1 / 8, 1 / 8)
    radii = [r0 * fractions[min(k, len(fractions) - 1)] for k in range(config.auto_rounds)]
    thr = max(config.threshold_px, 2.0 / view.scale)
    max_rot = 2.0 * config.init_rotation_deg
    max_trans = 2.0 * config.init_translation_m
    best_score, best = init_score, None
    rounds: list[dict[str, Any]] = []
    poses: list[NDArray[np.float64]] = []  # accepted poses of rounds 2, 3, ...
    T = T0
    for k, radius in enumerate(radii):
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
    best.method = "auto"
    best.T_init = T0
    best.timings_s = {"total": time.perf_counter() - t_start}
    for r in rounds:  # JSON has no infinities
        if r["edge_score"] is not None and not math.isfinite(r["edge_score"]):
            r["edge_score"] = None
    best.auto = {
        "scale": view.scale,
        "threshold_px": thr,
        "edge_score_init": init_score if math.isfinite(init_score) else None,
        "edge_score_final": best_score,
        "round_spread_deg": spread,
        "rounds": rounds,
    }
    return best


# ============================================================================ the one call


def calibrate(
    image: NDArray[np.uint8] | None,
    scan: Scan | None,
    intrinsics: CameraIntrinsics,
    *,
    pairs: Correspondences2D3D | None = None,
    T_init: ArrayLike | None = None,
    auto: bool = False,
    config: CalibrationConfig = CalibrationConfig(),
) -> CalibrationResult:
    """Camera-lidar extrinsic ``T_camera_lidar``: the one call.

    Parameters
    ----------
    image : (H, W[, 3]) uint8 or None
        Camera image; needed for ``auto`` (otherwise only its size is checked).
    scan : Scan or None
        Lidar scan; needed for ``auto``.
    intrinsics : CameraIntrinsics
    pairs : Correspondences2D3D, optional
        Given correspondences.
    T_init : (4, 4) float, optional
        Initial guess; required for ``auto`` unless ``pairs`` give one.
    auto : bool
        Propose correspondences automatically (:func:`calibrate_auto`); given pairs join
        every round.
    config : CalibrationConfig

    Returns
    -------
    CalibrationResult
    """
    if image is not None:
        h, w = np.asarray(image).shape[:2]
        intrinsics = intrinsics.for_image(w, h)
    if not auto:
        if pairs is None:
            raise InputError("pairs", "give correspondences or use the automatic mode")
        return solve_pnp(pairs, intrinsics, config=config, T_init=T_init)
    if image is None or scan is None:
        raise InputError("auto", "the automatic mode needs the camera image and the scan")
    if T_init is None:
        if pairs is None:
            raise InputError("auto", "the automatic mode needs an initial guess or pairs")
        T_init = solve_pnp(pairs, intrinsics, config=config).T_camera_lidar
    return calibrate_auto(image, scan, intrinsics, T_init, config=config, pairs=pairs)


# ============================================================================ pictures


def _range_colours(r: NDArray[np.float64], max_range_m: float) -> NDArray[np.uint8]:
    """(N, 3) uint8 BGR turbo colours, near red to far blue."""
    import cv2

    q = np.clip(255.0 * (1.0 - r / max_range_m), 0, 255).astype(np.uint8)
    return np.asarray(cv2.applyColorMap(q.reshape(-1, 1), cv2.COLORMAP_TURBO).reshape(-1, 3))


def _as_bgr(image: NDArray[np.uint8]) -> NDArray[np.uint8]:
    import cv2

    a = np.asarray(image)
    if a.dtype != np.uint8:
        raise InputError("image", f"expected an 8-bit image, got {a.dtype}")
    if a.ndim == 2:
        return np.asarray(cv2.cvtColor(a, cv2.COLOR_GRAY2BGR))
    if a.ndim == 3 and a.shape[2] == 4:
        return np.asarray(cv2.cvtColor(a, cv2.COLOR_BGRA2BGR))
    if a.ndim == 3 and a.shape[2] == 3:
        return a.copy()
    raise InputError("image", f"expected a grey or BGR image, got shape {a.shape}")


def overlay_image(
    image: NDArray[np.uint8],
    points: ArrayLike,
    intrinsics: CameraIntrinsics,
    T_camera_lidar: ArrayLike,
    *,
    result: CalibrationResult | None = None,
    max_range_m: float | None = None,
    radius_px: int | None = None,
) -> NDArray[np.uint8]:
    """Lidar points projected into the camera image, coloured by range (verification picture).

    Parameters
    ----------
    image : (H, W[, 3]) uint8
        Camera image (BGR or grey).
    points : (N, 3) float, metres, lidar frame
    intrinsics : CameraIntrinsics
    T_camera_lidar : (4, 4) float
    result : CalibrationResult, optional
        Also draw its correspondences: a line from each pixel to its point's projection, green
        for inliers, magenta for outliers.
    max_range_m : float, optional
        Range of the far end of the colour map (default: 95th percentile of the visible
        points' ranges).
    radius_px : int, optional
        Dot radius (default from the image size).

    Returns
    -------
    (H, W, 3) uint8
        BGR image, with a colour bar (metres) in the lower right corner.
    """
    import cv2

    out = _as_bgr(image)
    H, W = out.shape[:2]
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    uv, z = project_points(P, intrinsics, T_camera_lidar)
    vis = (z > 0) & np.isfinite(uv).all(axis=1)
    vis &= (uv[:, 0] >= -0.5) & (uv[:, 0] < W - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] < H - 0.5)
    r = np.linalg.norm(P, axis=1)
    if max_range_m is None:
        max_range_m = float(np.percentile(r[vis], 95)) if vis.any() else 1.0
    max_range_m = max(float(max_range_m), 1e-3)
    rad = radius_px if radius_px is not None else max(1, round(max(W, H) / 1600))
    idx = np.flatnonzero(vis)
    idx = idx[np.argsort(-r[idx], kind="stable")]  # far first, near on top
    colours = _range_colours(r[idx], max_range_m)
    pts = np.rint(uv[idx]).astype(np.int32)
    for (x, y), c in zip(pts, colours.tolist(), strict=True):
        cv2.circle(out, (int(x), int(y)), rad, c, -1, cv2.LINE_8)
    if result is not None:
        corr = result.correspondences
        proj, _ = project_points(corr.points, intrinsics, T_camera_lidar)
        for i in range(len(corr)):
            colour = (0, 255, 0) if result.inlier_mask[i] else (255, 0, 255)
            a = tuple(int(x) for x in np.rint(corr.pixels[i]))
            cv2.drawMarker(out, a, colour, cv2.MARKER_CROSS, 4 * rad + 6, 1, cv2.LINE_AA)
            if np.isfinite(proj[i]).all():
                b = tuple(int(x) for x in np.rint(proj[i]))
                cv2.line(out, a, b, colour, 1, cv2.LINE_AA)
    _colour_bar(out, max_range_m)
    return out


def _colour_bar(out: NDArray[np.uint8], max_range_m: float) -> None:
    import cv2

    H, W = out.shape[:2]
    bw, bh = min(256, W // 3), max(8, H // 60)
    if bw < 32:
        return
    x0, y0 = W - bw - 10, H - bh - 22
    ramp = _range_colours(np.linspace(0.0, max_range_m, bw), max_range_m)
    out[y0 : y0 + bh, x0 : x0 + bw] = ramp[None, :, :]
    font, fs = cv2.FONT_HERSHEY_SIMPLEX, 0.4
    for text, x in (("0 m", x0), (f"{max_range_m:.0f} m", x0 + bw - 30)):
        cv2.putText(out, text, (x, y0 + bh + 14), font, fs, (0, 0, 0), 3, cv2.LINE_AA)
        cv2.putText(out, text, (x, y0 + bh + 14), font, fs, (255, 255, 255), 1, cv2.LINE_AA)


def _grid(out: NDArray[np.uint8], minor: int, major: int, *, top: str, left: str) -> None:
    """Draw a labelled pixel grid on ``out`` (coordinates = the image's own pixels)."""
    import cv2

    H, W = out.shape[:2]
    overlay = out.copy()
    for x in range(0, W, minor):
        c = (0, 255, 255) if x % major == 0 else (0, 160, 160)
        cv2.line(overlay, (x, 0), (x, H - 1), c, 1)
    for y in range(0, H, minor):
        c = (0, 255, 255) if y % major == 0 else (0, 160, 160)
        cv2.line(overlay, (0, y), (W - 1, y), c, 1)
    cv2.addWeighted(overlay, 0.35, out, 0.65, 0.0, dst=out)
    font, fs = cv2.FONT_HERSHEY_PLAIN, 0.8
    for x in range(major, W, major):
        for text, c, t in ((str(x), (0, 0, 0), 3), (str(x), (0, 255, 255), 1)):
            cv2.putText(out, text, (x + 2, 10), font, fs, c, t, cv2.LINE_AA)
    major_y = major if H > 150 else 2 * minor
    for y in range(major_y, H, major_y):
        for text, c, t in ((str(y), (0, 0, 0), 3), (str(y), (0, 255, 255), 1)):
            cv2.putText(out, text, (2, y - 2), font, fs, c, t, cv2.LINE_AA)
    for text, c, t in ((f"{top} ->", (0, 0, 0), 3), (f"{top} ->", (0, 255, 255), 1)):
        cv2.putText(out, text, (W // 2, 22) if H > 40 else (W // 2, 10), font, fs, c, t)
    if H > 60:
        for text, c, t in ((f"{left} v", (0, 0, 0), 3), (f"{left} v", (0, 255, 255), 1)):
            cv2.putText(out, text, (2, H // 2), font, fs, c, t)


def picking_views(
    image: NDArray[np.uint8],
    scan: Scan,
    *,
    intrinsics: CameraIntrinsics | None = None,
    T_init: ArrayLike | None = None,
    n: int = 3,
) -> dict[str, NDArray[np.uint8]]:
    """Pictures for reading correspondences by hand, each at its own native pixel grid.

    * ``"camera"``: the camera image with a pixel grid (``u`` along the width, ``v`` down);
      an image viewer's cursor position is ``(u, v)`` directly.
    * ``"panorama"``: the Flexion n x n image of the scan's range image
      (:func:`scan_range_image`) with a grid; the cursor position ``(x, y)`` is
      ``(col, row)`` for a ``u,v,row,col`` file.
    * ``"flexion-view"`` (with ``intrinsics`` and ``T_init``): the scan rendered as a Flexion
      image from the initial guess (:func:`render_flexion_view`), resized to the camera image
      and gridded the same way, to find the same structures in both (it holds no lidar
      coordinates; read those from the panorama).

    Returns
    -------
    dict of str to (h, w, 3) uint8 BGR images
    """
    import cv2

    from flexreg.stages import feature_images as images

    cam = _as_bgr(image)
    H, W = cam.shape[:2]
    major = 100 if max(W, H) >= 800 else 50
    _grid(cam, major // 5, major, top="u", left="v")
    views = {"camera": cam}
    F = panorama_flexion(scan, n=n)
    q, _ = images.quantize(F, 8, stretch="percentile", percentiles=(1.0, 99.0))
    pano = _as_bgr(np.asarray(q, dtype=np.uint8))
    _grid(pano, 10, 50, top="col", left="row")
    views["panorama"] = pano
    if intrinsics is not None and T_init is not None:
        intr = intrinsics.for_image(W, H)
        view = render_flexion_view(scan, intr, T_init, n=n)
        q, _ = images.quantize(view.flexion, 8)
        fv = _as_bgr(
            np.asarray(
                cv2.resize(np.asarray(q, np.uint8), (W, H), interpolation=cv2.INTER_NEAREST),
                dtype=np.uint8,
            )
        )
        _grid(fv, major // 5, major, top="u", left="v")
        views["flexion-view"] = fv
    return views
