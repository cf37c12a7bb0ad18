"""Cloud-to-cloud fit of two placed stations: the measurement of the survey's final joint
alignment (:mod:`flexreg.survey.adjust`) and the per-link figures surveyors judge a
registration by.

Each station is reduced once to an *adjustment cloud*: its points voxel-averaged at
``refine_voxel_m`` with normals (:func:`adjustment_cloud`, cached beside the prepared
station). A pair is then aligned by robust point-to-plane ICP (Gauss-Newton, Tukey kernel) started
from the relative pose the graph holds (written here, so that the same inputs give the same
bits on every run), and measured at the result (:func:`fit_pair`):

* ``T_target_source`` and its 6 x 6 information matrix, ordered (rx, ry, rz, tx, ty, tz) for a
  perturbation of the source frame (``T_target_source @ exp(xi)``), as a GTSAM
  ``BetweenFactorPose3(target, source)`` expects. Each correspondence contributes
  ``J = [p x n', n']`` (``p`` the source point, ``n'`` the target normal turned into the
  source frame) weighted by the Tukey weight of its residual over the residual variance.
  Neighbouring points share their errors (mixed pixels, incidence, the voxel's own bias), so
  every cell of :data:`CORRELATION_M` counts as one observation: the information of a cell
  is the mean of its points' (not their sum), which keeps a million points from claiming
  micrometres. The residuals themselves add the cluster-robust (sandwich) covariance of the
  same cells (:func:`cluster_covariance`): errors a cell's points share (a surface's bias,
  noise growing with range) enlarge it where the noise model alone would not; the pair's
  covariance is the sum of the two;
* the cloud-to-cloud figures (:func:`cloud_figures`), over the overlapping points (a target
  point within ICP's final correspondence distance): the point-to-plane RMS of those within
  the Tukey width (:data:`TUKEY_C` residual sigmas; mm), the share of them within 6 mm and
  within 1 cm, the overlap (overlapping over all of the source's adjustment points) and the
  balance (smallest over largest eigenvalue of the overlapping normals' scatter
  ``sum n n^T``: 0 when every surface faces one way and a translation along them is free,
  1 when the normals spread evenly; the geometric strength surveyors' tools show as
  "balance").
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.core.transforms import rotation_error_deg, translation_error_m
from flexreg.stages.normals import grid_normals, masked_xyz
from flexreg.survey.stations import (
    PREPARED_SUFFIX,
    CacheEntryError,
    load_prepared,
    read_entry,
    write_entry,
)

log = logging.getLogger(__name__)

#: Tukey's constant for 95 % efficiency under Gaussian residuals (times the residual sigma)
TUKEY_C = 4.685
#: side of the cell that keeps one source point, in voxels (ICP's cost grows with the moved
#: side's points, its accuracy with the target's density)
CELL_VOXELS = 10
#: side of the cell whose points count as one independent observation, metres: a scan's
#: systematic errors (mixed pixels, incidence, range bias of one surface) are shared over
#: metres of surface; the points of one cell average their noise but not these (2 m: the
#: stations' true errors on the tuning projects were within 3 sigma, 1 m left 10 % outside)
CORRELATION_M = 2.0
#: residual limits of the per-link figures, metres (ReCap's 6 mm; the 1 cm outer limit)
WITHIN_M = (0.006, 0.010)
#: reach of the first (capture) stage of :func:`fit_pair`, in voxels
CAPTURE_VOXELS = 8
#: most Gauss-Newton steps of one ICP stage
ICP_ITERATIONS = 30
#: a capture stage of :func:`fit_pair` (its wide kernels) stops once a step moves the points
#: by less than this share of its kernel: its pose is only a start for the narrower stage
#: after it, whose reach is several times that
CAPTURE_STOP = 0.01
#: the last stage of :func:`fit_pair` stops once a step moves the points by less than this
#: share of the residuals' robust sigma (a turn at the source's median range)
FINAL_STOP = 0.001
#: MAD to sigma for Gaussian residuals
MAD_SIGMA = 1.4826


@dataclass(frozen=True)
class CloudFigures:
    """The cloud-to-cloud figures of one pair at one relative pose.

    Attributes
    ----------
    rms_mm : float or None
        Point-to-plane RMS of the overlapping points within the inlier distance, mm (None:
        no point overlaps).
    within_6mm, within_1cm : float
        Shares (0..1) of the overlapping points whose point-to-plane distance is under 6 mm
        and 1 cm.
    overlap : float
        Overlapping points over the source's adjustment points (0..1).
    balance : float
        Smallest over largest eigenvalue of ``sum n n^T`` of the overlapping target normals
        (0..1).
    points : int
        Overlapping points (the denominator of ``within_*``).
    source_points : int
        Source adjustment points (the denominator of ``overlap``).
    """

    rms_mm: float | None
    within_6mm: float
    within_1cm: float
    overlap: float
    balance: float
    points: int
    source_points: int

    def to_dict(self) -> dict[str, Any]:
        return {
            "rms_mm": None if self.rms_mm is None else round(self.rms_mm, 3),
            "within_6mm": round(self.within_6mm, 4),
            "within_1cm": round(self.within_1cm, 4),
            "overlap": round(self.overlap, 4),
            "balance": round(self.balance, 4),
            "points": self.points,
            "source_points": self.source_points,
        }


@dataclass(frozen=True)
class PairFit:
    """One pair aligned on its overlapping points.

    Attributes
    ----------
    T_target_source : (4, 4) float64
    information : (6, 6) float64
        (rx, ry, rz, tx, ty, tz), source-frame perturbation, 1 / (rad^2, m^2).
    sigma_m : float
        Robust sigma of the point-to-plane residuals (metres).
    figures : CloudFigures
    """

    T_target_source: NDArray[np.float64]
    information: NDArray[np.float64]
    sigma_m: float
    figures: CloudFigures


def cloud_path(cache_file: str, voxel_m: float) -> str:
    """Where the adjustment cloud of a prepared station is kept (beside it, named after its
    content key and the voxel in tenths of a millimetre)."""
    base = cache_file.removesuffix(PREPARED_SUFFIX)
    return f"{base}.adjust-{round(voxel_m * 1e4):d}.npz"


def _usable(path: str) -> bool:
    """Whether a kept adjustment cloud is whole (else it is made again): the arrays, shapes
    and types it was written with, read without pickles."""
    try:
        with np.load(path, allow_pickle=False) as z:
            p, n, k, r = z["points"], z["normals"], z["sparse"], z["median_range_m"]
            return bool(
                p.ndim == 2
                and p.shape[1] == 3
                and n.shape == p.shape
                and p.dtype == n.dtype == np.float32
                and k.ndim == 1
                and k.dtype == np.int64
                and (len(k) == 0 or (int(k.min()) >= 0 and int(k.max()) < len(p)))
                and r.shape == ()
                and np.isfinite(r)
                and np.isfinite(p).all()
                and np.isfinite(n).all()
            )
    except (OSError, ValueError, KeyError, EOFError):
        return False


def adjustment_cloud(cache_file: str, voxel_m: float) -> str:
    """Write (once) the adjustment cloud of a prepared station; returns its path (a task).

    The station's valid points with their grid normals (:func:`flexreg.stages.normals.
    grid_normals`: from the scan's own rows and columns, so far and sparse surfaces get
    them as well as near ones; none across depth jumps), averaged per ``voxel_m`` voxel
    (points whose normals disagree within a voxel, an edge, are dropped), and the median
    range of the points (metres). Kept
    as float32 in the scanner frame, so the file is about 1/50 of the station at 2 cm.
    """
    out = cloud_path(cache_file, voxel_m)
    if os.path.isfile(out):
        if _usable(out):
            return out
        log.warning("%s: unusable cache entry; making the adjustment cloud again", out)
    import open3d as o3d

    image = load_prepared(cache_file).image
    nrm = grid_normals(image)
    keep = image.valid & np.isfinite(nrm).all(axis=-1)  # no normal across depth jumps
    pts = np.asarray(masked_xyz(image)[keep], dtype=np.float64)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    pcd.normals = o3d.utility.Vector3dVector(np.asarray(nrm[keep], dtype=np.float64))
    del nrm
    pcd = pcd.voxel_down_sample(voxel_m)  # points and normals averaged per voxel
    p = np.asarray(pcd.points, dtype=np.float32)
    n = np.asarray(pcd.normals, dtype=np.float64)
    length = np.linalg.norm(n, axis=1)
    p, n = p[length > 0.5], (n[length > 0.5] / length[length > 0.5, None]).astype(np.float32)
    median_range = float(np.median(np.linalg.norm(pts, axis=1))) if len(pts) else 0.0
    cells = np.floor(p / np.float32(CELL_VOXELS * voxel_m)).astype(np.int64)
    _, first = np.unique(cells, axis=0, return_index=True)  # one point per coarse cell
    tmp = f"{out}.{os.getpid()}.tmp.npz"
    np.savez(
        tmp,
        points=p,
        normals=n,
        sparse=np.sort(first).astype(np.int64),
        median_range_m=np.float64(median_range),
    )
    os.replace(tmp, out)
    return out


def read_cloud(
    path: str, *, sparse: bool = False
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """Points (N, 3), normals (N, 3) float64 and median range (m) of an adjustment cloud;
    ``sparse``: only one point per cell of :data:`CELL_VOXELS` voxels (the side that is
    moved: ICP's cost grows with it, its accuracy with the target's density)."""
    with np.load(path, allow_pickle=False) as z:
        keep = z["sparse"] if sparse else slice(None)
        return (
            z["points"][keep].astype(np.float64),
            z["normals"][keep].astype(np.float64),
            float(z["median_range_m"]),
        )


def median_range(path: str) -> float:
    """The median range of a station's points, metres (its lever arm for rotations)."""
    with np.load(path, allow_pickle=False) as z:
        return float(z["median_range_m"])


def _correspond(
    tgt: NDArray[np.float64],
    tgt_n: NDArray[np.float64],
    src: NDArray[np.float64],
    T: NDArray[np.float64],
    max_m: float,
    tree: Any,
    src_n: NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64]]:
    """Source indices, target indices and signed point-to-plane residuals (m) of the source
    points with a target point within ``max_m`` at ``T``. With the source normals
    ``src_n``, only pairs whose normals face the same side: each scanner's normals point to
    it, so a pair facing apart joins the two faces of a wall (seen from both sides through a
    doorway or a window), never one surface."""
    moved = src @ T[:3, :3].T + T[:3, 3]
    d, j = tree.query(moved, k=1, distance_upper_bound=max_m)
    i = np.flatnonzero(np.isfinite(d))
    j = j[i]
    if src_n is not None:
        same = np.einsum("ij,ij->i", src_n[i] @ T[:3, :3].T, tgt_n[j]) > 0.0
        i, j = i[same], j[same]
    r = np.einsum("ij,ij->i", moved[i] - tgt[j], tgt_n[j])
    return i, j, r


def cloud_figures(
    tgt: NDArray[np.float64],
    tgt_n: NDArray[np.float64],
    src: NDArray[np.float64],
    T_target_source: NDArray[np.float64],
    max_m: float,
    *,
    inlier_m: float | None = None,
    tree: Any = None,
    src_n: NDArray[np.float64] | None = None,
) -> CloudFigures:
    """The cloud-to-cloud figures of ``src`` moved by ``T_target_source`` against ``tgt``.

    Parameters
    ----------
    tgt, tgt_n : (M, 3) float64
        Target points and unit normals, metres.
    src : (N, 3) float64
        Source points, metres.
    T_target_source : (4, 4) float64
    max_m : float
        Correspondence distance: a source point with a target point within it overlaps.
    inlier_m : float, optional
        The RMS is of the overlapping points whose point-to-plane distance is under this
        (default ``max_m``): the inlier RMS, as Open3D's ``inlier_rmse``; the shares within
        6 mm and 1 cm are of every overlapping point.
    tree : scipy.spatial.cKDTree, optional
        Of ``tgt``, when already at hand.
    src_n : (N, 3) float64, optional
        Source unit normals (pointing to the source scanner): a source point overlaps only
        where its normal and its target point's face the same side.

    Examples
    --------
    Two points of a floor 2 mm and 8 mm above a target floor of four points:

    >>> import numpy as np
    >>> tgt = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    >>> n = np.tile([0.0, 0.0, 1.0], (4, 1))
    >>> src = np.array([[0, 0, 0.002], [1, 1, 0.008], [9, 9, 9]], float)
    >>> f = cloud_figures(tgt, n, src, np.eye(4), 0.05)
    >>> round(f.rms_mm, 3), f.within_6mm, f.within_1cm, round(f.overlap, 3), f.points
    (5.831, 0.5, 1.0, 0.667, 2)
    """
    from scipy.spatial import cKDTree

    tree = tree if tree is not None else cKDTree(tgt)
    T = np.asarray(T_target_source, np.float64)
    i, j, r = _correspond(tgt, tgt_n, src, T, max_m, tree, src_n)
    k = len(i)
    if k == 0:
        return CloudFigures(None, 0.0, 0.0, 0.0, 0.0, 0, len(src))
    a = np.abs(r)
    n = tgt_n[j]
    ev = np.linalg.eigvalsh(n.T @ n)
    inl = r[a < (inlier_m if inlier_m is not None else max_m)]
    return CloudFigures(
        rms_mm=float(np.sqrt(np.mean(inl * inl)) * 1e3) if len(inl) else None,
        within_6mm=float(np.mean(a < WITHIN_M[0])),
        within_1cm=float(np.mean(a < WITHIN_M[1])),
        overlap=k / len(src),
        balance=float(max(ev[0], 0.0) / ev[-1]) if ev[-1] > 0 else 0.0,
        points=k,
        source_points=len(src),
    )


def jacobian(p: NDArray[np.float64], n: NDArray[np.float64]) -> NDArray[np.float64]:
    """(K, 6) derivatives of point-to-plane residuals ``n . (T exp(xi) p - q)`` by ``xi`` =
    (rx, ry, rz, tx, ty, tz) at ``xi = 0``: ``[p x n, n]`` (``p`` source points, ``n`` the
    target normals turned into the source frame)."""
    return np.hstack([np.cross(p, n), n])


def information(
    src_pts: NDArray[np.float64],
    normals_src: NDArray[np.float64],
    weights: NDArray[np.float64],
    sigma_m: float,
    cell_m: float,
) -> NDArray[np.float64]:
    """The 6 x 6 information of a point-to-plane fit, (rx, ry, rz, tx, ty, tz) for a
    perturbation of the source frame.

    Parameters
    ----------
    src_pts : (K, 3) float64
        Overlapping source points, source frame, metres.
    normals_src : (K, 3) float64
        Their target normals turned into the source frame.
    weights : (K,) float64
        Robust weights 0..1.
    sigma_m : float
        Residual sigma, metres.
    cell_m : float
        Points within one cell of this side count as one observation (mean, not sum).
    """
    J = jacobian(src_pts, normals_src)
    cells = np.floor(src_pts / cell_m).astype(np.int64)
    _, inv, counts = np.unique(cells, axis=0, return_inverse=True, return_counts=True)
    w = weights / counts[inv.ravel()]
    return (J * w[:, None]).T @ J / (sigma_m * sigma_m)


def cluster_covariance(
    src_pts: NDArray[np.float64],
    normals_src: NDArray[np.float64],
    weights: NDArray[np.float64],
    residuals_m: NDArray[np.float64],
    cell_m: float,
) -> NDArray[np.float64]:
    """The cluster-robust ("sandwich") covariance of a point-to-plane fit, 6 x 6,
    (rx, ry, rz, tx, ty, tz) for a perturbation of the source frame, rad^2 and m^2.

    ``H^-1 S H^-1`` with ``H = sum w J^T J`` and ``S`` the scatter of the cells' scores
    ``g_c = sum_(i in c) w_i r_i J_i`` (times ``C / (C - 1)`` for ``C`` cells): what the
    residuals themselves say, so errors shared within a cell (a surface's bias, noise that
    grows with range) enlarge it where the model of independent noise cannot.

    Examples
    --------
    Residuals of zero leave nothing to add:

    >>> import numpy as np
    >>> p = np.array([[0.5, 0.5, 0.0], [1.5, 0.5, 0.0]]); n = np.tile([0.0, 0, 1], (2, 1))
    >>> float(np.abs(cluster_covariance(p, n, np.ones(2), np.zeros(2), 1.0)).max())
    0.0
    """
    J = jacobian(src_pts, normals_src)
    cells = np.floor(src_pts / cell_m).astype(np.int64)
    _, inv, counts = np.unique(cells, axis=0, return_inverse=True, return_counts=True)
    c = len(counts)
    g = np.zeros((c, 6))
    np.add.at(g, inv.ravel(), J * (weights * residuals_m)[:, None])
    S = g.T @ g * (c / (c - 1) if c > 1 else 1.0)
    H = (J * weights[:, None]).T @ J
    Hi = np.linalg.pinv(H)
    return Hi @ S @ Hi


def _icp(
    tgt: NDArray[np.float64],
    tgt_n: NDArray[np.float64],
    tree: Any,
    src: NDArray[np.float64],
    src_n: NDArray[np.float64],
    T0: NDArray[np.float64],
    max_m: float,
    k_m: float,
    stop: tuple[float, float] = (1e-7, 1e-6),
) -> NDArray[np.float64]:
    """Point-to-plane ICP with Tukey weights (width ``k_m``) on correspondences within
    ``max_m`` whose normals face the same side (:func:`_correspond`): Gauss-Newton steps
    ``T <- T exp(xi)`` until a step is under ``stop`` (rad, m: by default 1e-7 rad / 1 um)
    or :data:`ICP_ITERATIONS` are made. Written here rather than Open3D's so that the same
    inputs give the same bits (its parallel sums do not)."""
    from scipy.spatial.transform import Rotation

    T = np.array(T0, dtype=np.float64)
    for _ in range(ICP_ITERATIONS):
        i, j, r = _correspond(tgt, tgt_n, src, T, max_m, tree, src_n)
        if len(i) < 6:
            break
        u = np.clip(np.abs(r) / k_m, 0.0, 1.0)
        w = (1.0 - u * u) ** 2
        n_s = tgt_n[j] @ T[:3, :3]
        J = jacobian(src[i], n_s)
        Jw = J * w[:, None]
        H = Jw.T @ J
        try:
            xi = -np.linalg.solve(H + np.eye(6) * 1e-12 * max(np.trace(H), 1e-12), Jw.T @ r)
        except np.linalg.LinAlgError:
            break
        step = np.eye(4)
        step[:3, :3] = Rotation.from_rotvec(xi[:3]).as_matrix()
        step[:3, 3] = xi[3:]
        T = T @ step
        if np.linalg.norm(xi[:3]) < stop[0] and np.linalg.norm(xi[3:]) < stop[1]:
            break
    return T


def _shift(A: NDArray[np.float64], B: NDArray[np.float64], reach_m: float) -> float:
    """How far a source point within ``reach_m`` of its origin moves between two poses at
    most: the translation plus the turn times the reach (metres)."""
    return translation_error_m(A, B) + np.radians(rotation_error_deg(A, B)) * reach_m


def _align(
    tgt: NDArray[np.float64],
    tgt_n: NDArray[np.float64],
    tree: Any,
    source: tuple[NDArray[np.float64], NDArray[np.float64]],
    T: NDArray[np.float64],
    scale: tuple[float, float],
) -> tuple[NDArray[np.float64], float]:
    """The stages of :func:`fit_pair` from ``T``: the source points and normals ``source``
    moved onto the target's, ``scale`` the voxel (m) and the source's median range (m).
    Returns the pose and the last stage's kernel width (m)."""
    (src, src_n), (voxel_m, lever_m) = source, scale
    for max_v, k_v in ((CAPTURE_VOXELS, 4), (3, 1.5)):  # capture: stop at a step of 1 %
        step_m = CAPTURE_STOP * k_v * voxel_m  # (a turn: at the median range)
        stop = (step_m / max(lever_m, 1.0), step_m)
        T = _icp(tgt, tgt_n, tree, src, src_n, T, max_v * voxel_m, k_v * voxel_m, stop)
    _, _, r = _correspond(tgt, tgt_n, src, T, 3 * voxel_m, tree, src_n)
    sigma = _robust_sigma(r, voxel_m)
    k = TUKEY_C * sigma
    step_m = FINAL_STOP * sigma
    stop = (step_m / max(lever_m, 1.0), step_m)
    # the last stage moves a point by far less than its reach (3 k): the source points with
    # no target point within twice that reach cannot find one, and are left out of its
    # steps unless a point did move by as much (then it runs again with every point)
    near, _, _ = _correspond(tgt, tgt_n, src, T, 6 * k, tree)
    start = T
    T = _icp(tgt, tgt_n, tree, src[near], src_n[near], T, 3 * k, k, stop)
    if _shift(T, start, float(np.sqrt(np.max(np.einsum("ij,ij->i", src, src))))) >= 3 * k:
        T = _icp(tgt, tgt_n, tree, src, src_n, T, 3 * k, k, stop)
    return T, k


def fit_groups(
    target: Sequence[tuple[str, NDArray[np.float64]]],
    source: Sequence[tuple[str, NDArray[np.float64]]],
    X: NDArray[np.float64],
    voxel_m: float,
) -> NDArray[np.float64]:
    """Align two groups of placed stations as two clouds, by :func:`fit_pair`'s stages.

    Parameters
    ----------
    target, source : sequence of (str, (4, 4) float64)
        Each group's stations: adjustment cloud (:func:`adjustment_cloud`) and pose in the
        group's frame. The target's clouds are used whole, the source's one point per cell
        (:func:`read_cloud`); each point keeps its own scanner's normal, so the normal-side
        rule of :func:`_correspond` still keeps a wall's two faces apart.
    X : (4, 4) float64
        Start: ``T_target_source`` of the groups' frames.
    voxel_m : float
        The clouds' voxel, metres.

    Returns
    -------
    (4, 4) float64
        ``T_target_source`` where all the overlap of the two groups fits.

    Raises
    ------
    ValueError
        Fewer than six points on a side.
    """
    from scipy.spatial import cKDTree

    def union(
        group: Sequence[tuple[str, NDArray[np.float64]]], sparse: bool
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
        ps, ns, lever = [], [], 1.0
        for path, P in group:
            p, n, r = read_cloud(path, sparse=sparse)
            ps.append(p @ P[:3, :3].T + P[:3, 3])
            ns.append(n @ P[:3, :3].T)
            lever = max(lever, r)
        return np.vstack(ps), np.vstack(ns), lever

    tgt, tgt_n, _ = union(target, False)
    src, src_n, lever_m = union(source, True)
    if len(tgt) < 6 or len(src) < 6:
        raise ValueError("too few points to align")
    X = np.asarray(X, dtype=np.float64)
    return _align(tgt, tgt_n, cKDTree(tgt), (src, src_n), X, (voxel_m, lever_m))[0]


def fit_pair(
    target_cloud: str, source_cloud: str, T_init: NDArray[np.float64], voxel_m: float
) -> PairFit:
    """Align two stations' adjustment clouds by robust point-to-plane ICP from ``T_init`` and
    measure the result (a task; see the module).

    Three stages of point-to-plane ICP with a Tukey kernel (:func:`_icp`): correspondences
    within 8 and then 3 voxels (kernel 4 and 1.5 voxels), then within three kernel widths of
    the residuals' own robust sigma (kernel :data:`TUKEY_C` sigma), so the final weights come
    from the scans' noise, not from a set distance. The first two only bring the pose within
    reach of the next and stop once a step moves the points by less than
    :data:`CAPTURE_STOP` of their kernel (a turn at the source's median range); the last stops
    once a step moves them by less than :data:`FINAL_STOP` of the residuals' sigma (4 um at
    4 mm), on the source points with a target point within twice its reach (unless it
    moved a point by as much: then on all).

    Raises
    ------
    ValueError
        Fewer than six points overlap.
    """
    from scipy.spatial import cKDTree

    tgt, tgt_n, _ = read_cloud(target_cloud)
    src, src_n, lever_m = read_cloud(source_cloud, sparse=True)
    T = np.asarray(T_init, dtype=np.float64)
    if len(tgt) < 6 or len(src) < 6:
        raise ValueError("too few points to align")
    tree = cKDTree(tgt)
    T, k = _align(tgt, tgt_n, tree, (src, src_n), T, (voxel_m, lever_m))
    i, j, r = _correspond(tgt, tgt_n, src, T, 3 * k, tree, src_n)
    sigma = _robust_sigma(r, voxel_m)
    k = TUKEY_C * sigma
    u = np.clip(np.abs(r) / k, 0.0, 1.0)
    w = (1.0 - u * u) ** 2
    n_src = tgt_n[j] @ T[:3, :3]  # target normals in the source frame
    model = information(src[i], n_src, w, sigma, CORRELATION_M)
    cov = np.linalg.pinv(model) + cluster_covariance(src[i], n_src, w, r, CORRELATION_M)
    info = np.linalg.pinv(0.5 * (cov + cov.T))
    figures = cloud_figures(tgt, tgt_n, src, T, 3 * k, inlier_m=k, tree=tree, src_n=src_n)
    if len(i) < 6 or figures.rms_mm is None:
        raise ValueError("too few overlapping points to align")
    return PairFit(T, info, sigma, figures)


#: bumped when :func:`fit_pair`'s results change: fits kept by older code are measured again
FIT_FORMAT = 2
#: the cache entry kind of a kept fit
FIT_KIND = "pair-fit"


def fit_cache_path(target_cloud: str, source_cloud: str) -> str:
    """Where a pair's last fit is kept: beside the adjustment clouds, named by both (their
    stations' cache keys and the voxel) and :data:`FIT_FORMAT`."""
    t = os.path.basename(target_cloud).removesuffix(".npz")
    s = os.path.basename(source_cloud).removesuffix(".npz")
    return os.path.join(os.path.dirname(target_cloud), "fits", f"{t}__{s}.v{FIT_FORMAT}.fit.npz")


def save_fit(path: str, start: NDArray[np.float64], fit: PairFit) -> None:
    """Keep a pair's fit and the relative pose it started from (a cache entry,
    :func:`~flexreg.survey.stations.write_entry`: written whole or not at all, its digest
    checked on reading; a cache that cannot be written is only a warning: the next run
    measures the pair again)."""
    f = fit.figures
    figures = [np.nan if f.rms_mm is None else f.rms_mm, f.within_6mm, f.within_1cm, f.overlap,
               f.balance, f.points, f.source_points]  # fmt: skip
    arrays = {
        "start": np.asarray(start, dtype=np.float64),
        "T": np.asarray(fit.T_target_source, dtype=np.float64),
        "information": np.asarray(fit.information, dtype=np.float64),
        "sigma_m": np.asarray(fit.sigma_m, dtype=np.float64),
        "figures": np.asarray(figures, dtype=np.float64),
    }
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        write_entry(Path(path), FIT_KIND, arrays, {"format": FIT_FORMAT})
    except OSError as e:
        log.warning("%s: cannot keep the pair's fit (%s)", path, e.strerror or e)


def load_fit(path: str) -> tuple[NDArray[np.float64], PairFit] | None:
    """A kept fit and the pose it started from (:func:`save_fit`); None when there is none
    or it is damaged (then the pair is measured again)."""
    if not os.path.isfile(path):
        return None
    try:
        _, z = read_entry(path, FIT_KIND)
        start, T, info = z["start"], z["T"], z["information"]
        sigma, fig = float(z["sigma_m"]), z["figures"]
        ok = start.shape == T.shape == (4, 4) and info.shape == (6, 6) and fig.shape == (7,)
        if not ok or not (np.isfinite(start).all() and np.isfinite(T).all() and sigma > 0):
            raise CacheEntryError("unexpected arrays")
    except (CacheEntryError, KeyError, TypeError) as e:
        log.warning("%s: unusable kept fit (%s); measuring the pair again", path, e)
        return None
    rms = None if np.isnan(fig[0]) else float(fig[0])
    figures = CloudFigures(rms, float(fig[1]), float(fig[2]), float(fig[3]), float(fig[4]),
                           int(fig[5]), int(fig[6]))  # fmt: skip
    return start, PairFit(T, info, sigma, figures)


def _robust_sigma(r: NDArray[np.float64], voxel_m: float) -> float:
    """Robust sigma (1.4826 MAD) of residuals, metres; never under a twentieth of a voxel
    (the averaging floor of a voxel's points)."""
    floor = voxel_m / 20
    if len(r) < 6:
        return max(voxel_m, floor)
    return max(float(MAD_SIGMA * np.median(np.abs(r - np.median(r)))), floor)


__all__ = [
    "CAPTURE_VOXELS",
    "CELL_VOXELS",
    "CORRELATION_M",
    "FIT_FORMAT",
    "CloudFigures",
    "PairFit",
    "adjustment_cloud",
    "cloud_figures",
    "cloud_path",
    "cluster_covariance",
    "fit_cache_path",
    "fit_groups",
    "fit_pair",
    "information",
    "jacobian",
    "load_fit",
    "median_range",
    "read_cloud",
    "save_fit",
]
