"""Geometric hypotheses: FPFH descriptors of two clouds, matched, pruned to a mutually
consistent set (a maximum-clique search) and solved by RANSAC, several distinct times.

This is the route of the geometric registration methods (FPFH, Rusu et al. ICRA 2009; the
consistency graph of TEASER++, Yang et al. T-RO 2020, and KISS-Matcher, Lim et al. 2024) for
clouds the feature images do not suit: objects scanned from outside, narrow-field lidar
frames, fused fragments. It only proposes: every hypothesis is judged afterwards by the same
dense check and verdict as the Flexion route's (:mod:`flexreg.registration`), so an alias
that FPFH + RANSAC would return without a warning ends uncertain or refused.

Open3D computes the normals and FPFH descriptors; the matching, the consistency pruning
(:func:`flexreg.stages.alignment.consistent_subset`) and the seeded RANSAC
(:func:`flexreg.stages.alignment.ransac_rigid`) are ours, so the same seed gives the same
hypotheses.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from flexreg.core.transforms import rotation_error_deg, translation_error_m
from flexreg.errors import DegenerateGeometryError, InputError
from flexreg.stages.alignment import RngLike, consistent_subset, ransac_rigid, squared_residuals
from flexreg.stages.sampling import median_spacing

log = logging.getLogger(__name__)

#: points each cloud keeps for its descriptors (the voxel size is chosen for about this many:
#: FPFH costs grow with it, and a few thousand surface points describe a scene or an object)
DESCRIBED_POINTS = 5000

#: normals from neighbours within this many voxels, FPFH from neighbours within this many
#: (the radii of Open3D's and the FPFH paper's examples: 2 and 5 voxels)
NORMAL_RADIUS_VOXELS, FEATURE_RADIUS_VOXELS = 2.0, 5.0

#: a hypothesis is a runner-up only when it differs from every better one by this much
DISTINCT_DEG, DISTINCT_VOXELS = 5.0, 5.0

#: fewest correspondences a hypothesis must explain (3 determine a pose; a few more make it
#: more than a chance triple)
MIN_SUPPORT = 6


@dataclass(frozen=True, eq=False)
class Described:
    """A cloud's descriptor points.

    Attributes
    ----------
    points : (N, 3) float64, metres
        The voxel-grid centroids of the cloud.
    features : (N, 33) float32
        Their FPFH descriptors.
    voxel_m : float, metres
    """

    points: NDArray[np.float64]
    features: NDArray[np.float32]
    voxel_m: float


@dataclass(frozen=True, eq=False)
class Hypothesis:
    """One pose the descriptors support.

    Attributes
    ----------
    T_target_source : (4, 4) float64
    support : int
        Correspondences within the inlier distance.
    target_points, source_points : (K, 3) float64, metres
        Those correspondences.
    """

    T_target_source: NDArray[np.float64]
    support: int
    target_points: NDArray[np.float64]
    source_points: NDArray[np.float64]


def descriptor_voxel(points: ArrayLike, *, keep: int = DESCRIBED_POINTS) -> float:
    """The voxel size (metres) that leaves about ``keep`` of a cloud's points: a surface of
    area ``A`` keeps about ``A / v^2`` of them, so two down-samplings correct a first guess
    (the bounding box's diagonal over ``sqrt(keep)``) by the square root of the ratio.

    Parameters
    ----------
    points : (N, 3) float, metres
    keep : int

    Returns
    -------
    float, metres

    >>> import numpy as np
    >>> g = np.stack(np.meshgrid(np.arange(200), np.arange(200), [0.0]), -1).reshape(-1, 3)
    >>> 2.5 < descriptor_voxel(g * 0.01, keep=1000) / 0.01 < 8.0
    True
    """
    P = np.asarray(points, dtype=np.float64)
    if len(P) <= keep:
        return median_spacing(P)
    lo, hi = P.min(axis=0), P.max(axis=0)
    v = float(np.linalg.norm(hi - lo)) / math.sqrt(keep)
    for _ in range(2):
        n = len(np.unique(np.floor((P - lo) / v).astype(np.int64), axis=0))
        v *= math.sqrt(max(n, 1) / keep)
    return max(v, median_spacing(P))


def describe(
    points: ArrayLike,
    *,
    voxel_m: float,
    viewpoint: ArrayLike | None = (0.0, 0.0, 0.0),
) -> Described:
    """FPFH descriptors of a cloud's voxel-grid centroids.

    Normals from the neighbours within ``NORMAL_RADIUS_VOXELS`` voxels, turned towards the
    ``viewpoint`` (the scanner, where the cloud has one: the descriptors of two clouds only
    compare when their normals point the same way off the surface); FPFH over
    ``FEATURE_RADIUS_VOXELS`` voxels.

    Parameters
    ----------
    points : (N, 3) float, metres
    voxel_m : float, metres
    viewpoint : (3,) float or None, metres
        None: normals oriented by Open3D's tangent-plane propagation instead.

    Returns
    -------
    Described

    Raises
    ------
    InputError
        Not positive ``voxel_m``.
    DegenerateGeometryError
        Fewer than 3 points left after the down-sampling.
    """
    import open3d as o3d

    if not (math.isfinite(voxel_m) and voxel_m > 0):
        raise InputError("voxel_m", f"must be positive, got {voxel_m}")
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, dtype=np.float64)))
    pc = pc.voxel_down_sample(voxel_m)
    if len(pc.points) < 3:
        raise DegenerateGeometryError(f"{len(pc.points)} points left at a {voxel_m:.3g} m voxel")
    search = o3d.geometry.KDTreeSearchParamHybrid
    pc.estimate_normals(search(radius=NORMAL_RADIUS_VOXELS * voxel_m, max_nn=30))
    if viewpoint is not None:
        pc.orient_normals_towards_camera_location(np.asarray(viewpoint, dtype=np.float64))
    else:
        pc.orient_normals_consistent_tangent_plane(10)
    reg: Any = o3d.pipelines.registration  # its stubs lack compute_fpfh_feature's defaults
    f = reg.compute_fpfh_feature(pc, search(radius=FEATURE_RADIUS_VOXELS * voxel_m, max_nn=100))
    return Described(
        np.asarray(pc.points, dtype=np.float64),
        np.ascontiguousarray(np.asarray(f.data, dtype=np.float32).T),
        float(voxel_m),
    )


def feature_matches(target: Described, source: Described) -> NDArray[np.int64]:
    """(Q, 2) index pairs (target, source) of nearest descriptors: the mutual ones, or every
    source point's nearest when fewer than ``8 * MIN_SUPPORT`` are mutual (two clouds of
    little overlap).

    >>> import numpy as np
    >>> f = np.eye(33, dtype=np.float32)[:8]
    >>> a = Described(np.zeros((8, 3)), f, 1.0)
    >>> b = Described(np.zeros((8, 3)), f[::-1].copy(), 1.0)
    >>> feature_matches(a, b)[:3].tolist()
    [[7, 0], [6, 1], [5, 2]]
    """
    if len(target.features) == 0 or len(source.features) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    _, ts = cKDTree(target.features).query(source.features, k=1)
    _, st = cKDTree(source.features).query(target.features, k=1)
    src = np.arange(len(source.features))
    mutual = st[ts] == src
    keep = mutual if mutual.sum() >= 8 * MIN_SUPPORT else np.ones_like(mutual)
    return np.stack([ts[keep], src[keep]], axis=1).astype(np.int64)


def _distinct(T: NDArray[np.float64], others: list[Hypothesis], far_m: float) -> bool:
    return all(
        rotation_error_deg(T, h.T_target_source) > DISTINCT_DEG
        or translation_error_m(T, h.T_target_source) > far_m
        for h in others
    )


def hypotheses_from_matches(
    target_points: ArrayLike,
    source_points: ArrayLike,
    *,
    threshold_m: float,
    count: int = 3,
    confidence: float = 0.9999,
    max_iterations: int = 50_000,
    rng: RngLike = None,
) -> list[Hypothesis]:
    """Up to ``count`` distinct poses that putative correspondences support, in the order
    found: each from the largest consistent set the earlier ones left.

    The largest mutually consistent subset (:func:`~flexreg.stages.alignment.
    consistent_subset`, pairwise distances kept within twice ``threshold_m``) is solved by
    RANSAC (:func:`~flexreg.stages.alignment.ransac_rigid`); the correspondences the pose
    explains are then set aside and the search runs again on the rest, so a look-alike's
    support gives the runner-up. A pose that explains fewer than ``MIN_SUPPORT`` of them, or
    lies within ``DISTINCT_DEG`` and ``DISTINCT_VOXELS`` inlier distances of a better one, is
    not kept.

    Parameters
    ----------
    target_points, source_points : (Q, 3) float, metres
    threshold_m : float, metres
        Inlier distance.
    count : int
    confidence, max_iterations : as :func:`~flexreg.stages.alignment.ransac_rigid`
    rng : Generator, int or None

    Returns
    -------
    list of Hypothesis
    """
    pt = np.asarray(target_points, dtype=np.float64)
    ps = np.asarray(source_points, dtype=np.float64)
    gen = np.random.default_rng(rng)
    left = np.arange(len(pt))
    out: list[Hypothesis] = []
    for _ in range(3 * count):
        if len(out) >= count or len(left) < MIN_SUPPORT:
            break
        idx = left[consistent_subset(pt[left], ps[left], threshold_m=2 * threshold_m)]
        if len(idx) < MIN_SUPPORT:
            break
        try:
            rr = ransac_rigid(
                pt[idx],
                ps[idx],
                threshold_m=threshold_m,
                confidence=confidence,
                max_iterations=max_iterations,
                min_inliers=3,
                rng=gen,
            )
        except DegenerateGeometryError:
            left = np.setdiff1d(left, idx)
            continue
        T = rr.T_target_source
        near = squared_residuals(T, pt[left], ps[left]) < (2 * threshold_m) ** 2
        inl = squared_residuals(T, pt, ps) < threshold_m**2
        support = int(inl.sum())
        if support >= MIN_SUPPORT and _distinct(T, out, DISTINCT_VOXELS * threshold_m):
            out.append(Hypothesis(T, support, pt[inl], ps[inl]))
        left = left[~near] if near.any() else np.setdiff1d(left, idx)
    log.info(
        "geometric hypotheses: %s", ", ".join(f"{h.support} supporting" for h in out) or "none"
    )
    return out


def geometric_hypotheses(
    target: ArrayLike,
    source: ArrayLike,
    *,
    voxel_m: float | None = None,
    count: int = 3,
    viewpoints: tuple[ArrayLike | None, ArrayLike | None] = ((0, 0, 0), (0, 0, 0)),
    rng: RngLike = None,
) -> tuple[list[Hypothesis], Described, Described]:
    """Distinct ``T_target_source`` hypotheses of two clouds from their FPFH descriptors.

    Parameters
    ----------
    target, source : (N, 3) float, metres
        Each in its own frame.
    voxel_m : float or None, metres
        Descriptor voxel; None: the larger of both clouds' :func:`descriptor_voxel`.
    count : int
        Most hypotheses.
    viewpoints : two (3,) float or None
        Each cloud's scanner position in its frame (None: no single viewpoint).
    rng : Generator, int or None

    Returns
    -------
    hypotheses : list of Hypothesis
        In the order found (:func:`hypotheses_from_matches`); the inlier distance is 1.5
        voxels. Every one is judged, so the order only breaks exact ties.
    target_described, source_described : Described
    """
    if voxel_m is None:
        voxel_m = max(descriptor_voxel(target), descriptor_voxel(source))
    dt = describe(target, voxel_m=voxel_m, viewpoint=viewpoints[0])
    ds = describe(source, voxel_m=voxel_m, viewpoint=viewpoints[1])
    pairs = feature_matches(dt, ds)
    log.info(
        "FPFH at a %.3g m voxel: %d / %d points, %d matches",
        voxel_m,
        len(dt.points),
        len(ds.points),
        len(pairs),
    )
    if len(pairs) < MIN_SUPPORT:
        return [], dt, ds
    hyps = hypotheses_from_matches(
        dt.points[pairs[:, 0]],
        ds.points[pairs[:, 1]],
        threshold_m=1.5 * voxel_m,
        count=count,
        rng=rng,
    )
    return hyps, dt, ds


__all__ = [
    "DESCRIBED_POINTS",
    "Described",
    "Hypothesis",
    "describe",
    "descriptor_voxel",
    "feature_matches",
    "geometric_hypotheses",
    "hypotheses_from_matches",
]
