"""Closed-form rigid alignment of 3D correspondences and robust estimation around it.

- :func:`kabsch` — weighted least-squares rigid (or similarity) transform, Umeyama's SVD solution.
- :func:`consistent_subset` — prune outliers with the pairwise-distance consistency of rigid
  motions (a rigid transform preserves every distance), by growing cliques of the
  compatibility graph from its best-connected vertices.
- :func:`ransac_rigid` — 3-point RANSAC with batched (vectorised) hypotheses, MSAC scoring,
  adaptive stopping by confidence and a final least-squares fit on all inliers.

All transforms are ``T_target_source``: ``target ~= R @ source + t``.
"""

from __future__ import annotations

import itertools
import logging
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.errors import DegenerateGeometryError, InputError

log = logging.getLogger(__name__)

RngLike = np.random.Generator | int | None

#: smallest ratio of the 2nd to the 1st singular value of the centred points for a
#: non-degenerate (non-collinear) configuration
COLLINEAR_RATIO = 1e-3


def _pairs(target: ArrayLike, source: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    Q = np.asarray(target, dtype=np.float64)
    P = np.asarray(source, dtype=np.float64)
    if Q.shape != P.shape or Q.ndim != 2 or Q.shape[1] != 3:
        raise InputError("correspondences", f"need two (N, 3) arrays, got {Q.shape} and {P.shape}")
    if not (np.isfinite(Q).all() and np.isfinite(P).all()):
        raise InputError("correspondences", "NaN or Inf in the points")
    return Q, P


def spread_ratio(points: NDArray[np.float64], weights: NDArray[np.float64] | None = None) -> float:
    """Ratio of the second to the first principal spread of points (0 for collinear sets)."""
    w = np.ones(len(points)) if weights is None else weights
    c = (w[:, None] * points).sum(0) / w.sum()
    X = (points - c) * np.sqrt(w)[:, None]
    s = np.linalg.svd(X, compute_uv=False)
    return float(s[1] / s[0]) if s[0] > 0 else 0.0


def kabsch(
    target: ArrayLike,
    source: ArrayLike,
    weights: ArrayLike | None = None,
    *,
    with_scale: bool = False,
) -> NDArray[np.float64]:
    """Weighted least-squares transform mapping ``source`` onto ``target`` (Kabsch / Umeyama).

    Minimises ``sum_i w_i || target_i - (s R source_i + t) ||^2`` in closed form via the SVD
    of the weighted cross-covariance, with the reflection fix ``diag(1, 1, det(U V^T))``.

    Parameters
    ----------
    target, source : (N, 3) float, metres
        Corresponding points, ``N >= 3``.
    weights : (N,) float, optional
        Non-negative weights (default all 1).
    with_scale : bool
        Also estimate a uniform scale ``s`` (Umeyama); the result is then a similarity.

    Returns
    -------
    (4, 4) float64
        ``T_target_source``.

    Raises
    ------
    DegenerateGeometryError
        Fewer than 3 weighted points, or collinear/coincident points (the rotation about
        their line is undetermined).

    Examples
    --------
    >>> src = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> T = kabsch(src + [1.0, 2.0, 3.0], src)
    >>> np.round(T[:3, 3], 12).tolist()
    [1.0, 2.0, 3.0]
    """
    Q, P = _pairs(target, source)
    w = np.ones(len(P)) if weights is None else np.asarray(weights, dtype=np.float64).reshape(-1)
    if len(w) != len(P) or (w < 0).any() or not np.isfinite(w).all():
        raise InputError("weights", "need one finite non-negative weight per correspondence")
    if np.count_nonzero(w) < 3:
        raise DegenerateGeometryError(
            f"rigid alignment needs at least 3 weighted correspondences, got {np.count_nonzero(w)}"
        )
    ws = w.sum()
    mp = (w[:, None] * P).sum(0) / ws
    mq = (w[:, None] * Q).sum(0) / ws
    Pc, Qc = P - mp, Q - mq
    if spread_ratio(P, w) < COLLINEAR_RATIO or spread_ratio(Q, w) < COLLINEAR_RATIO:
        raise DegenerateGeometryError(
            f"the {len(P)} correspondences are collinear or coincident: rotation undetermined"
        )
    H = (w[:, None] * Qc).T @ Pc / ws  # cross-covariance, target x source
    U, S, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    R = U @ D @ Vt
    s = 1.0
    if with_scale:
        var_p = (w * np.einsum("ij,ij->i", Pc, Pc)).sum() / ws
        s = float(np.trace(np.diag(S) @ D) / var_p)
    T = np.eye(4)
    T[:3, :3] = s * R
    T[:3, 3] = mq - s * R @ mp
    return T


def _batched_kabsch(Q: NDArray[np.float64], P: NDArray[np.float64]) -> NDArray[np.float64]:
    """Unweighted Kabsch for a batch: Q, P (B, k, 3) -> (B, 4, 4); no degeneracy checks."""
    mq, mp = Q.mean(1, keepdims=True), P.mean(1, keepdims=True)
    H = np.einsum("bki,bkj->bij", Q - mq, P - mp)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(U @ Vt))
    d[d == 0] = 1.0
    U[:, :, 2] *= d[:, None]
    R = U @ Vt
    T = np.tile(np.eye(4), (len(Q), 1, 1))
    T[:, :3, :3] = R
    T[:, :3, 3] = mq[:, 0] - np.einsum("bij,bj->bi", R, mp[:, 0])
    return T


@dataclass(frozen=True)
class RansacResult:
    """Outcome of :func:`ransac_rigid`.

    Attributes
    ----------
    T_target_source : (4, 4) float64
    inliers : (N,) bool
        Correspondences within the threshold of the final fit.
    iterations : int
        Hypotheses evaluated.
    rmse_m : float
        Root-mean-square residual of the inliers, metres.
    """

    T_target_source: NDArray[np.float64]
    inliers: NDArray[np.bool_]
    iterations: int
    rmse_m: float

    @property
    def n_inliers(self) -> int:
        return int(self.inliers.sum())


def _rng(rng: RngLike) -> np.random.Generator:
    return rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)


def ransac_rigid(
    target: ArrayLike,
    source: ArrayLike,
    *,
    threshold_m: float,
    confidence: float = 0.9999,
    max_iterations: int = 50_000,
    min_inliers: int = 3,
    batch: int = 256,
    min_sample_spread_m: float | None = None,
    rng: RngLike = None,
) -> RansacResult:
    """Robust rigid transform from putative 3D correspondences.

    Hypotheses come from 3 random correspondences (Kabsch), generated and scored ``batch`` at a
    time with array operations; when there are at most ``batch`` triplets, every one is tried
    once instead. Scoring is MSAC (truncated quadratic), which separates models
    with equal inlier counts by their fit. The number of iterations adapts to the best inlier
    ratio ``w`` so far: stop after ``log(1 - confidence) / log(1 - w^3)``. The winner is refitted
    by least squares on its inliers, twice (inliers re-selected in between).

    Parameters
    ----------
    target, source : (N, 3) float, metres
    threshold_m : float
        Inlier distance, metres.
    confidence : float
        Probability of having drawn at least one all-inlier sample when stopping.
    max_iterations : int
    min_inliers : int
        Fewer inliers than this raise :class:`DegenerateGeometryError`.
    batch : int
        Hypotheses per vectorised batch.
    min_sample_spread_m : float, optional
        Reject samples whose points are closer than this to each other (default
        ``3 * threshold_m``): near-coincident samples give unstable rotations.
    rng : Generator, int or None
        Source of randomness; same seed, same result.

    Raises
    ------
    DegenerateGeometryError
        Fewer than 3 correspondences, no valid sample, too few inliers, or collinear inliers.
    """
    Q, P = _pairs(target, source)
    n = len(P)
    if not threshold_m > 0:
        raise InputError("threshold_m", f"must be positive, got {threshold_m}")
    if n < 3:
        raise DegenerateGeometryError(f"RANSAC needs at least 3 correspondences, got {n}")
    gen = _rng(rng)
    spread = 3 * threshold_m if min_sample_spread_m is None else min_sample_spread_m
    th2 = threshold_m * threshold_m
    best_score, best_T, best_count = np.inf, None, 0
    needed = max_iterations
    # few correspondences: every triplet once (exhaustive, no sampling)
    exhaustive = math.comb(n, 3) <= batch
    it = 0
    while it < min(needed, max_iterations):
        if exhaustive:
            idx = np.array(list(itertools.combinations(range(n), 3)), dtype=np.int64)
            needed = 0
        else:
            idx = _sample_triplets(gen, n, min(batch, max_iterations - it))
        b = len(idx)
        it += b
        Ps, Qs = P[idx], Q[idx]
        # rigid motions preserve the sample's side lengths: cheap pre-test
        ok = np.ones(b, dtype=bool)
        for a, c in ((0, 1), (1, 2), (0, 2)):
            dp = np.linalg.norm(Ps[:, a] - Ps[:, c], axis=1)
            dq = np.linalg.norm(Qs[:, a] - Qs[:, c], axis=1)
            ok &= (np.abs(dp - dq) < 2 * threshold_m) & (dp > spread)
        if not ok.any():
            continue
        Ts = _batched_kabsch(Qs[ok], Ps[ok])
        res = np.einsum("bij,nj->bni", Ts[:, :3, :3], P) + Ts[:, None, :3, 3] - Q[None]
        d2 = np.einsum("bni,bni->bn", res, res)
        score = np.minimum(d2, th2).sum(1)
        k = int(np.argmin(score))
        if score[k] < best_score:
            best_score, best_T = score[k], Ts[k]
            best_count = int((d2[k] < th2).sum())
            w = best_count / n
            if w >= 1.0:
                needed = 0
            elif w > 0:
                needed = math.ceil(math.log(1 - confidence) / math.log(1 - w**3))
        if exhaustive:
            break
    if best_T is None:
        raise DegenerateGeometryError(
            f"no valid 3-point sample among {n} correspondences (all too close or inconsistent)"
        )
    T = best_T
    inl = squared_residuals(T, Q, P) < th2
    for _ in range(2):
        if inl.sum() < 3:
            break
        T = kabsch(Q[inl], P[inl])
        inl = squared_residuals(T, Q, P) < th2
    if inl.sum() < max(3, min_inliers):
        raise DegenerateGeometryError(
            f"only {int(inl.sum())} inliers of {n} correspondences within {threshold_m:.4g} m "
            f"(need {max(3, min_inliers)})"
        )
    if spread_ratio(P[inl]) < COLLINEAR_RATIO:
        raise DegenerateGeometryError(f"the {int(inl.sum())} inliers are collinear")
    rmse = float(np.sqrt(squared_residuals(T, Q, P)[inl].mean()))
    log.debug("RANSAC: %d hypotheses, %d/%d inliers, rmse %.4g m", it, inl.sum(), n, rmse)
    return RansacResult(T_target_source=T, inliers=inl, iterations=it, rmse_m=rmse)


def _sample_triplets(gen: np.random.Generator, n: int, b: int) -> NDArray[np.int64]:
    """``b`` triplets of distinct indices in ``[0, n)`` (resampling the few collisions)."""
    idx = gen.integers(0, n, size=(b, 3))
    while True:
        bad = (idx[:, 0] == idx[:, 1]) | (idx[:, 1] == idx[:, 2]) | (idx[:, 0] == idx[:, 2])
        if not bad.any():
            return idx
        idx[bad] = gen.integers(0, n, size=(int(bad.sum()), 3))


def squared_residuals(
    T: NDArray[np.float64], Q: NDArray[np.float64], P: NDArray[np.float64]
) -> NDArray[np.float64]:
    r = P @ T[:3, :3].T + T[:3, 3] - Q
    return np.einsum("ij,ij->i", r, r)


def consistent_subset(
    target: ArrayLike,
    source: ArrayLike,
    *,
    threshold_m: float,
    relative: float = 0.0,
    seeds: int = 64,
    max_points: int = 4000,
) -> NDArray[np.int64]:
    """Largest mutually consistent subset of correspondences found by greedy clique growth.

    Two correspondences ``i, j`` are compatible when a rigid motion could map both:
    ``| ||t_i - t_j|| - ||s_i - s_j|| | <= threshold_m + relative * ||s_i - s_j||``. True
    correspondences form a clique of this graph; outliers rarely join it. From each of the
    ``seeds`` best-connected vertices a clique is grown greedily (best-connected compatible
    candidate first); the largest clique found is returned.

    Parameters
    ----------
    target, source : (N, 3) float, metres
    threshold_m : float
        Absolute distance tolerance (about twice the point noise plus keypoint jitter).
    relative : float
        Extra tolerance proportional to the distance (keypoint localisation error grows with
        range).
    seeds : int
        Number of starting vertices.
    max_points : int
        Above this many correspondences an evenly spaced subset of ``max_points`` is used
        (memory is O(N^2)).

    Returns
    -------
    (K,) int64
        Indices of the consistent subset, sorted.
    """
    Q, P = _pairs(target, source)
    n = len(P)
    if n < 3:
        return np.arange(n)
    cand = np.arange(n)
    if n > max_points:
        cand = np.linspace(0, n - 1, max_points).astype(np.int64)
    Qc, Pc = Q[cand], P[cand]
    dq = np.linalg.norm(Qc[:, None] - Qc[None], axis=2)
    dp = np.linalg.norm(Pc[:, None] - Pc[None], axis=2)
    A = np.abs(dq - dp) <= threshold_m + relative * dp
    np.fill_diagonal(A, False)
    deg = A.sum(1)
    best: list[int] = []
    for s in np.argsort(-deg, kind="stable")[:seeds]:
        if deg[s] + 1 <= len(best):
            break
        clique = [int(s)]
        members = A[s].copy()
        while members.any():
            # the best-connected remaining candidate joins next
            c = np.flatnonzero(members)
            k = int(c[np.argmax(deg[c])])
            clique.append(k)
            members &= A[k]
        if len(clique) > len(best):
            best = clique
    return np.sort(cand[np.asarray(best, dtype=np.int64)])
