"""Descriptor matching: k-NN with Lowe's ratio test and a mutual (cross) check."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.stages.keypoints import Features


def match(
    target: Features,
    source: Features,
    *,
    ratio: float = 0.8,
    mutual: bool = True,
) -> NDArray[np.int64]:
    """Match source features to target features.

    A pair ``(i, j)`` is kept when target ``i`` is source ``j``'s nearest neighbour, the
    nearest is clearly better than the second (``d1 < ratio * d2``, Lowe's ratio test), and,
    with ``mutual``, source ``j`` is also target ``i``'s nearest neighbour. Distances use the
    L2 norm for float descriptors and the Hamming norm for binary ones (ORB, AKAZE, BRISK).

    Parameters
    ----------
    target, source : Features
    ratio : float
        Ratio-test threshold in (0, 1]; 1 disables it.
    mutual : bool
        Keep only mutual nearest neighbours.

    Returns
    -------
    (Q, 2) int64
        ``[target index, source index]`` per match, sorted by source index.
    """
    import cv2

    if len(target) < 2 or len(source) < 1:
        return np.zeros((0, 2), dtype=np.int64)
    norm = cv2.NORM_HAMMING if source.binary else cv2.NORM_L2
    bf = cv2.BFMatcher(norm, crossCheck=False)
    fwd = bf.knnMatch(source.descriptors, target.descriptors, k=2)
    pairs = []
    for m in fwd:
        if len(m) == 2 and m[0].distance < ratio * m[1].distance:
            pairs.append((m[0].trainIdx, m[0].queryIdx))
        elif len(m) == 1:
            pairs.append((m[0].trainIdx, m[0].queryIdx))
    if not pairs:
        return np.zeros((0, 2), dtype=np.int64)
    out = np.asarray(pairs, dtype=np.int64)
    if mutual:
        # nearest source of each target that has a match (the others cannot be mutual)
        ts = np.unique(out[:, 0])
        back: Any = bf.match(np.ascontiguousarray(target.descriptors[ts]), source.descriptors)
        nn = np.full(len(target), -1, dtype=np.int64)
        for b in back:
            nn[ts[b.queryIdx]] = b.trainIdx
        out = out[nn[out[:, 0]] == out[:, 1]]
    return out[np.argsort(out[:, 1], kind="stable")]


def descriptor_distances(
    target: Features, source: Features, ti: NDArray[np.int64], si: NDArray[np.int64]
) -> NDArray[np.float64]:
    """Descriptor distance of the pairs ``(target[ti[k]], source[si[k]])``: L2 for float
    descriptors, Hamming (bits) for binary ones."""
    out = np.empty(len(ti), dtype=np.float64)
    step = 65536
    for a in range(0, len(ti), step):
        dt = target.descriptors[ti[a : a + step]]
        ds = source.descriptors[si[a : a + step]]
        if source.binary:
            out[a : a + step] = np.unpackbits(np.bitwise_xor(dt, ds), axis=1).sum(axis=1)
        else:
            d = dt.astype(np.float32) - ds.astype(np.float32)
            out[a : a + step] = np.sqrt(np.einsum("ij,ij->i", d, d))
    return out


def _near_prediction(
    target: Features,
    source: Features,
    target_xyz: NDArray[np.float64],
    source_xyz: NDArray[np.float64],
    T_target_source: NDArray[np.float64],
    radius: Callable[[NDArray[np.float64], NDArray[np.float64]], NDArray[np.float64]],
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]] | None:
    """Every (source keypoint, target keypoint within ``radius(q, p)`` of its prediction
    ``q``; ``p`` the source point) pair with its descriptor distance, sorted by source index
    then nearest descriptor (ties: lower target index); None when there is none."""
    okt = np.flatnonzero(np.isfinite(target_xyz).all(axis=1))
    oks = np.flatnonzero(np.isfinite(source_xyz).all(axis=1))
    if len(okt) == 0 or len(oks) == 0:
        return None
    T = np.asarray(T_target_source, dtype=np.float64)
    q = source_xyz[oks] @ T[:3, :3].T + T[:3, 3]
    from scipy.spatial import cKDTree  # heavy (0.1 s): the CLI imports this module at start-up

    cand = cKDTree(target_xyz[okt]).query_ball_point(q, radius(q, source_xyz[oks]))
    lens = np.fromiter((len(c) for c in cand), dtype=np.int64, count=len(cand))
    if lens.sum() == 0:
        return None
    si = np.repeat(oks, lens)
    ti = okt[np.fromiter((j for c in cand for j in c), dtype=np.int64, count=int(lens.sum()))]
    d = descriptor_distances(target, source, ti, si)
    order = np.lexsort((ti, d, si))
    return si[order], ti[order], d[order]


def match_guided(
    target: Features,
    source: Features,
    target_xyz: NDArray[np.float64],
    source_xyz: NDArray[np.float64],
    T_target_source: NDArray[np.float64],
    *,
    radius_m: float = 0.2,
    radius_per_m: float = 0.0,
    ratio: float = 0.9,
) -> NDArray[np.int64]:
    """Match features near where a transform predicts them (guided matching).

    Each source keypoint's 3D point is mapped into the target frame by ``T_target_source``;
    the candidates are the target keypoints within ``radius_m + radius_per_m * range`` of that
    prediction, and the one with the nearest descriptor wins if it passes the ratio test
    against the second-nearest candidate (a single candidate passes). Geometry does the
    pruning that the ratio test over all keypoints cannot do among repetitive structure, so
    far more true matches survive than with :func:`match`.

    Parameters
    ----------
    target, source : Features
    target_xyz, source_xyz : (Kt, 3), (Ks, 3) float64, metres
        The keypoints' 3D points in their scan frames (NaN: not liftable, never matched).
    T_target_source : (4, 4) float64
        Prior transform.
    radius_m : float, metres
        Search radius around each prediction.
    radius_per_m : float
        Extra radius per metre of predicted range (angular uncertainty of the prior).
    ratio : float
        Ratio test among the candidates; 1 disables it.

    Returns
    -------
    (Q, 2) int64
        ``[target index, source index]`` per match, sorted by source index; each target
        keypoint used at most once (the pair with the best descriptor distance keeps it).
    """
    found = _near_prediction(
        target,
        source,
        target_xyz,
        source_xyz,
        T_target_source,
        lambda q, _: radius_m + radius_per_m * np.linalg.norm(q, axis=1),
    )
    if found is None:
        return np.zeros((0, 2), dtype=np.int64)
    si, ti, d = found
    first = np.r_[True, si[1:] != si[:-1]]
    starts = np.flatnonzero(first)
    counts = np.diff(np.r_[starts, len(si)])
    best_t, best_s, best_d = ti[starts], si[starts], d[starts]
    second = np.where(counts > 1, d[np.minimum(starts + 1, len(d) - 1)], np.inf)
    keep = best_d < ratio * second if ratio < 1 else np.ones(len(starts), dtype=bool)
    best_t, best_s, best_d = best_t[keep], best_s[keep], best_d[keep]
    if len(best_t) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    # one source per target keypoint: the nearest descriptor keeps it
    o = np.lexsort((best_s, best_d, best_t))
    uniq = np.r_[True, best_t[o][1:] != best_t[o][:-1]]
    o = o[uniq]
    out = np.column_stack([best_t[o], best_s[o]]).astype(np.int64)
    return out[np.argsort(out[:, 1], kind="stable")]


def match_window(
    target: Features,
    source: Features,
    target_xyz: NDArray[np.float64],
    source_xyz: NDArray[np.float64],
    T_target_source: NDArray[np.float64],
    *,
    shift_m: float,
    turn_rad: float,
    k: int = 3,
) -> NDArray[np.int64]:
    """Putative matches under a rough prior: each source keypoint with the ``k`` target
    keypoints of nearest descriptor among those where the prior could have put it.

    A pose within ``shift_m`` of the prior's translation and ``turn_rad`` of its rotation
    moves a source point at range ``r`` (from the source's origin) at most
    ``shift_m + 2 sin(turn_rad / 2) r`` from where the prior maps it; the candidates are the
    target keypoints within that distance. No ratio test: among look-alike structure the
    right partner is rarely the clear best, so the ``k`` best all go to a robust fit that
    only accepts poses inside the window (:func:`flexreg.stages.alignment.windowed_fit`).

    Parameters
    ----------
    target, source : Features
    target_xyz, source_xyz : (Kt, 3), (Ks, 3) float64, metres
        The keypoints' 3D points in their scan frames (NaN: never matched).
    T_target_source : (4, 4) float64
        The rough prior.
    shift_m : float, metres
    turn_rad : float, radians
        How far the true pose may be from the prior: translation and rotation angle.
    k : int
        Candidates kept per source keypoint.

    Returns
    -------
    (Q, 2) int64
        ``[target index, source index]``, sorted by source index then descriptor distance.
    """
    arc = 2.0 * math.sin(min(turn_rad, math.pi) / 2.0)
    found = _near_prediction(
        target,
        source,
        target_xyz,
        source_xyz,
        T_target_source,
        lambda _, p: shift_m + arc * np.linalg.norm(p, axis=1),
    )
    if found is None or k < 1:
        return np.zeros((0, 2), dtype=np.int64)
    si, ti, _ = found
    starts = np.flatnonzero(np.r_[True, si[1:] != si[:-1]])
    rank = np.arange(len(si)) - np.repeat(starts, np.diff(np.r_[starts, len(si)]))
    keep = rank < k
    return np.column_stack([ti[keep], si[keep]]).astype(np.int64)
