"""Closed-form rigid alignment of 3D correspondences and robust estimation around it.

- :func:`umeyama` — weighted least-squares rigid (or similarity) transform, Umeyama's SVD
  solution; :func:`kabsch` is the same after refusing collinear points.
- :func:`consistent_subset` — prune outliers with the pairwise-distance consistency of rigid
  motions (a rigid transform preserves every distance), by growing cliques of the
  compatibility graph from its best-connected vertices.
- :func:`ransac_rigid` — 3-point RANSAC with batched (vectorised) hypotheses, MSAC scoring,
  adaptive stopping by confidence and a final least-squares fit on all inliers.
- :func:`guided_fit` — guided matching around a prior and least squares with a shrinking
  inlier radius (the prior-driven alternative to RANSAC).
- :func:`windowed_fit` — RANSAC bounded by a rough prior (:class:`Window`): putative matches
  where the prior could put them, hypotheses only inside its window.

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
from flexreg.stages.keypoints import Features
from flexreg.stages.matching import match_guided, match_window

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


def _weights(weights: ArrayLike | None, n: int) -> NDArray[np.float64]:
    """One finite non-negative weight per correspondence (all 1 when None), at least 3 > 0."""
    w = np.ones(n) if weights is None else np.asarray(weights, dtype=np.float64).reshape(-1)
    if len(w) != n or (w < 0).any() or not np.isfinite(w).all():
        raise InputError("weights", "need one finite non-negative weight per correspondence")
    if np.count_nonzero(w) < 3:
        raise DegenerateGeometryError(
            f"rigid alignment needs at least 3 weighted correspondences, got {np.count_nonzero(w)}"
        )
    return w


def _umeyama(
    Q: NDArray[np.float64],
    P: NDArray[np.float64],
    w: NDArray[np.float64],
    *,
    with_scale: bool,
    unit_weights: bool,
) -> tuple[NDArray[np.float64], float, NDArray[np.float64]]:
    """Umeyama's closed form on checked arrays: ``(T_target_source [R | t], s, singular values)``.

    ``unit_weights`` says that ``w`` is all ones; the source variance is then summed without
    the weights (the same value; its rounding is what the TUM evaluation tools give).
    """
    ws = w.sum()
    mp = (w[:, None] * P).sum(0) / ws
    mq = (w[:, None] * Q).sum(0) / ws
    Pc, Qc = P - mp, Q - mq
    H = (w[:, None] * Qc).T @ Pc / ws  # eq. 38: target x source cross-covariance
    U, D, Vt = np.linalg.svd(H)
    S = np.ones(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:  # eq. 39: a rotation, never a reflection
        S[2] = -1.0
    R = (U * S) @ Vt  # eq. 40
    s = 1.0
    if with_scale:
        if unit_weights:
            var_p = float(np.einsum("ij,ij->", Pc, Pc) / len(P))  # eq. 36
        else:
            var_p = float((w * np.einsum("ij,ij->i", Pc, Pc)).sum() / ws)
        if var_p <= 1e-24:
            raise DegenerateGeometryError("scale undetermined: the source points coincide")
        s = float(D @ S / var_p)  # eq. 42
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = mq - s * R @ mp  # eq. 41
    return T, s, D


def umeyama(
    target: ArrayLike,
    source: ArrayLike,
    weights: ArrayLike | None = None,
    *,
    with_scale: bool = False,
) -> tuple[NDArray[np.float64], float]:
    """Least-squares alignment of corresponding points: ``target ~= s R source + t``.

    The closed form of Horn (1987) / Umeyama (1991): the SVD ``U D V^T`` of the (weighted)
    cross-covariance of the centred points (Umeyama eq. 38) gives ``R = U S V^T`` with
    ``S = diag(1, 1, det(U) det(V))`` (eqs. 39-40), ``s = tr(D S) / sigma_source^2`` (eq. 42,
    or 1 without scale) and ``t = mu_target - s R mu_source`` (eq. 41).

    Collinear points are accepted: the residual is the same for every rotation about their
    line (one of them is returned). :func:`kabsch` refuses them, because a registration must
    determine the rotation.

    Parameters
    ----------
    target, source : (N, 3) array_like of float, metres
        Corresponding points (``N >= 3``).
    weights : (N,) array_like of float, optional
        Non-negative weights (default all 1), at least 3 of them positive.
    with_scale : bool
        Also estimate the scale ``s`` (a similarity).

    Returns
    -------
    T_target_source : (4, 4) float64
        The rigid part ``[R | t]``.
    scale : float
        ``s`` (1.0 unless ``with_scale``). The aligned source is ``apply(T, s * source)``.

    Raises
    ------
    InputError
        Arrays of different or wrong shapes, non-finite values, or bad weights.
    DegenerateGeometryError
        Fewer than 3 (weighted) points, or (with scale) a source whose points all coincide.

    Examples
    --------
    >>> src = np.array([[0.0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 3]])
    >>> T, s = umeyama(2.0 * src + [1.0, 2.0, 3.0], src, with_scale=True)
    >>> round(s, 12), np.round(T[:3, 3], 12).tolist()
    (2.0, [1.0, 2.0, 3.0])
    """
    Q, P = _pairs(target, source)
    w = _weights(weights, len(P))
    T, s, D = _umeyama(Q, P, w, with_scale=with_scale, unit_weights=weights is None)
    if np.count_nonzero(D > 1e-12 * max(D[0], 1e-300)) < 2:
        log.debug("alignment of %d points is degenerate (collinear or coincident)", len(P))
    return T, s


def kabsch(
    target: ArrayLike,
    source: ArrayLike,
    weights: ArrayLike | None = None,
    *,
    with_scale: bool = False,
) -> NDArray[np.float64]:
    """Weighted least-squares transform mapping ``source`` onto ``target`` (Kabsch / Umeyama).

    Minimises ``sum_i w_i || target_i - (s R source_i + t) ||^2`` in closed form
    (:func:`umeyama`), after refusing collinear or coincident points.

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
        ``T_target_source`` (with ``s R`` as its 3x3 block when ``with_scale``).

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
    w = _weights(weights, len(P))
    if spread_ratio(P, w) < COLLINEAR_RATIO or spread_ratio(Q, w) < COLLINEAR_RATIO:
        raise DegenerateGeometryError(
            f"the {len(P)} correspondences are collinear or coincident: rotation undetermined"
        )
    T, s, _ = _umeyama(Q, P, w, with_scale=with_scale, unit_weights=False)
    T[:3, :3] *= s
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


@dataclass(frozen=True, eq=False)
class Window:
    """Where a rough prior says the true pose lies: within ``shift_m`` of its translation and
    ``turn_rad`` of its rotation (e.g. two stations' rough positions: a few sigma of both, and
    both headings' error).

    Attributes
    ----------
    T_prior : (4, 4) float64
        The prior ``T_target_source``.
    shift_m : float, metres
    turn_rad : float, radians
    """

    T_prior: NDArray[np.float64]
    shift_m: float
    turn_rad: float

    def contains(self, Ts: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Which of the ``(B, 4, 4)`` transforms lie inside the window.

        >>> w = Window(np.eye(4), 1.0, math.radians(10))
        >>> T = np.stack([np.eye(4)] * 3); T[1, 0, 3] = 1.5
        >>> c, s = math.cos(0.2), math.sin(0.2); T[2, :2, :2] = [[c, -s], [s, c]]
        >>> w.contains(T).tolist()
        [True, False, False]
        """
        Ts = np.asarray(Ts, dtype=np.float64).reshape(-1, 4, 4)
        P = np.asarray(self.T_prior, dtype=np.float64)
        shift = np.linalg.norm(Ts[:, :3, 3] - P[:3, 3], axis=1)
        # angle of R_prior^T R from its trace
        tr = np.einsum("ij,bij->b", P[:3, :3], Ts[:, :3, :3])
        turn = np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0))
        return (shift <= self.shift_m) & (turn <= self.turn_rad)


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
    window: Window | None = None,
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
    window : Window, optional
        Only hypotheses inside it count (a rough prior's bounds); the final fit too must
        end inside it.

    Raises
    ------
    DegenerateGeometryError
        Fewer than 3 correspondences, no valid sample, too few inliers, collinear inliers,
        or (with a window) no hypothesis inside the window.
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
        if window is not None:
            Ts = Ts[window.contains(Ts)]
            if not len(Ts):
                continue
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
    if window is not None and not window.contains(T[None])[0]:
        raise DegenerateGeometryError("the best fit leaves the prior's window")
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


@dataclass(eq=False)
class GuidedFit:
    """Outcome of :func:`guided_fit`.

    Attributes
    ----------
    T_target_source : (4, 4) float64
    pairs : (Q, 2) int64
        ``(target keypoint, source keypoint)`` of the final guided matches.
    inliers : (Q,) bool
        Pairs within ``threshold_m`` under ``T_target_source``.
    """

    T_target_source: NDArray[np.float64]
    pairs: NDArray[np.int64]
    inliers: NDArray[np.bool_]


def _shrinking_fit(
    T: NDArray[np.float64],
    pt: NDArray[np.float64],
    ps: NDArray[np.float64],
    r0: float,
    threshold_m: float,
    radius_per_m: float,
) -> tuple[NDArray[np.float64] | None, NDArray[np.bool_]]:
    """Least squares (:func:`kabsch`) on the pairs within a radius that halves from ``r0``
    down to ``threshold_m`` (the range-proportional part shrinking alike), then two more fits
    at ``threshold_m``; None when the inliers get too few or collinear."""
    thr = threshold_m
    rng_s = np.linalg.norm(ps, axis=1)
    radii = [r0]
    while radii[-1] > thr:
        radii.append(max(radii[-1] / 2, thr))
    for radius in [*radii, thr, thr]:
        extra = radius_per_m * rng_s * (radius / r0) if radius > thr else 0.0
        inl = squared_residuals(T, pt, ps) < (radius + extra) ** 2
        if inl.sum() < 3 or spread_ratio(ps[inl]) < COLLINEAR_RATIO:
            return None, inl
        T = kabsch(pt[inl], ps[inl])
    return T, squared_residuals(T, pt, ps) < thr * thr


def guided_fit(
    target_features: Features,
    source_features: Features,
    target_points: NDArray[np.float64],
    source_points: NDArray[np.float64],
    T_prior: NDArray[np.float64],
    *,
    threshold_m: float,
    radius_m: float = 0.25,
    radius_per_m: float = 0.02,
) -> GuidedFit | None:
    """Guided matching around a prior, then least squares with a shrinking inlier radius.

    The prior is trusted to within the guided search radius (``radius_m`` plus
    ``radius_per_m`` per metre of range, at least ``2 threshold_m``); starting from it,
    correspondences within the current radius are fitted (Kabsch) and the radius halves down to
    ``threshold_m``, so the estimate cannot jump to an unrelated model the way RANSAC on the
    same matches can. A second, tight guided round around the result collects the final
    matches (:func:`flexreg.stages.matching.match_guided`).

    Parameters
    ----------
    target_features, source_features : Features
        Keypoints and descriptors of both images.
    target_points, source_points : (K, 3) float64, metres
        The keypoints lifted to 3D (NaN where they could not be).
    T_prior : (4, 4) float64
        The prior ``T_target_source``.
    threshold_m : float, metres
        Inlier distance.
    radius_m, radius_per_m : float
        Search radius around the prior's prediction: metres plus metres per metre of range.

    Returns
    -------
    GuidedFit or None
        None when too few (or collinear) matches support a fit.
    """
    ft, fs, xt, xs, thr = (
        target_features,
        source_features,
        target_points,
        source_points,
        threshold_m,
    )
    r0 = max(radius_m, 2 * thr)
    pairs = match_guided(ft, fs, xt, xs, T_prior, radius_m=r0, radius_per_m=radius_per_m)
    if len(pairs) < 3:
        return None
    T, _ = _shrinking_fit(T_prior, xt[pairs[:, 0]], xs[pairs[:, 1]], r0, thr, radius_per_m)
    if T is None:
        return None
    pairs = match_guided(ft, fs, xt, xs, T, radius_m=2 * thr, radius_per_m=0.002)
    if len(pairs) < 3:
        return None
    T, inl = _shrinking_fit(T, xt[pairs[:, 0]], xs[pairs[:, 1]], 2 * thr, thr, radius_per_m)
    if T is None:
        return None
    return GuidedFit(T, pairs, inl)


def windowed_fit(
    target_features: Features,
    source_features: Features,
    target_points: NDArray[np.float64],
    source_points: NDArray[np.float64],
    window: Window,
    *,
    threshold_m: float,
    k: int = 3,
    confidence: float = 0.9999,
    max_iterations: int = 50_000,
    rng: RngLike = None,
) -> RansacResult | None:
    """RANSAC bounded by a rough prior: the ``k`` nearest descriptors where the prior's
    window could put each source keypoint (:func:`~flexreg.stages.matching.match_window`),
    then :func:`ransac_rigid` counting only hypotheses inside the window.

    A prior too rough for :func:`guided_fit` (a sketch's position, a heading off by ten
    degrees) still rules out every look-alike pose beyond its window (the next bay of a
    warehouse, a room turned a quarter), which a global search among repeating structure
    cannot; inside the window the matches decide.

    Parameters
    ----------
    target_features, source_features : Features
    target_points, source_points : (K, 3) float64, metres
        The keypoints lifted to 3D (NaN where they could not be).
    window : Window
    threshold_m : float, metres
        Inlier distance.
    k : int
        Candidate partners per source keypoint.
    confidence, max_iterations, rng
        As :func:`ransac_rigid`.

    Returns
    -------
    RansacResult or None
        None when no pose inside the window is supported by at least 3 non-collinear matches.
    """
    pairs = match_window(
        target_features,
        source_features,
        target_points,
        source_points,
        window.T_prior,
        shift_m=window.shift_m,
        turn_rad=window.turn_rad,
        k=k,
    )
    if len(pairs) < 3:
        return None
    try:
        return ransac_rigid(
            target_points[pairs[:, 0]],
            source_points[pairs[:, 1]],
            threshold_m=threshold_m,
            confidence=confidence,
            max_iterations=max_iterations,
            rng=rng,
            window=window,
        )
    except DegenerateGeometryError as e:
        log.debug("windowed fit: %s", e)
        return None
