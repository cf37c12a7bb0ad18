"""Point sampling: even samples by surface area, thinning, point spacing, Open3D clouds.

A scanner samples the surfaces near it far more densely than distant ones. The area sample
(:func:`area_sample`, one point per occupied cell of a voxel grid sized by :func:`area_cell`)
weights every part of a scene by its surface area instead; the dense checks
(:mod:`flexreg.stages.verification`) and the refinements (:mod:`flexreg.stages.refinement`)
work on it. :func:`thin` and :func:`thin_random` cut very large clouds down before voxel
downsampling, :func:`median_spacing` gives the scan resolution every default size derives
from, :func:`to_open3d` builds the Open3D cloud.
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from flexreg.errors import RegistrationError


def area_sample(points: NDArray[np.floating], samples: int) -> NDArray[np.float64]:
    """About ``samples`` points spread evenly over the surfaces of a cloud.

    One point (the first in input order) per occupied cell of the voxel grid of
    :func:`area_cell`; deterministic.

    Parameters
    ----------
    points : (N, 3) float32 or float64
        Metres.
    samples : int
        Wanted number of points (the result has about 0.7 to 1.4 times that, or all N points
        when N is smaller).

    Returns
    -------
    (M, 3) float64
        A subset of ``points`` in input order.
    """
    return area_sample_cell(points, samples)[1]


def area_sample_cell(
    points: NDArray[np.floating], samples: int
) -> tuple[float, NDArray[np.float64]]:
    """:func:`area_cell` and :func:`area_sample` at once (float32 points are read as they
    are: only the sample becomes float64)."""
    p = _float_points(points)
    cell, first = _area_cells(p, samples)
    return cell, np.asarray(p if len(p) <= samples else p[first], dtype=np.float64)


def area_sample_image(
    xyz: NDArray[np.floating], valid: NDArray[np.bool_], samples: int
) -> NDArray[np.float64]:
    """:func:`area_sample` of an image's valid points, ``xyz[valid]`` (row by row), without
    making that (N, 3) copy: only the thinned points the cells are found on are gathered.
    Exactly ``area_sample(xyz[valid], samples)``.

    Parameters
    ----------
    xyz : (H, W, 3) float32 or float64, metres
    valid : (H, W) bool
    samples : int

    Returns
    -------
    (M, 3) float64
    """
    v = np.ascontiguousarray(valid, dtype=np.bool_)
    n = int(np.count_nonzero(v))
    if n <= samples:
        return np.asarray(xyz[v], dtype=np.float64)
    step = max(1, n // (20 * samples))
    x = np.ascontiguousarray(xyz)
    q = _valid_every(x.reshape(-1, 3), v.reshape(-1), step, -(-n // step))
    _, first = _thinned_cells(q, samples)
    return q[first]


@numba.njit(cache=True, nogil=True)
def _valid_every(xyz, valid, step, m):  # pragma: no cover - compiled
    """(m, 3) float64: every ``step``-th of the points ``xyz[valid]`` (in order), from the
    first."""
    out = np.empty((m, 3), dtype=np.float64)
    k = 0
    j = 0
    for i in range(valid.shape[0]):
        if valid[i]:
            if k % step == 0:
                for c in range(3):
                    out[j, c] = xyz[i, c]
                j += 1
            k += 1
    return out[:j]


def area_cell(points: NDArray[np.floating], samples: int) -> float:
    """Voxel size at which about ``samples`` voxels of a cloud's surfaces are occupied, metres.

    Downsampling with it weights every part of a scene by its surface area rather than by its
    number of points (a scanner samples the surfaces near it far more densely).

    Parameters
    ----------
    points : (N, 3) float64
        Metres.
    samples : int
        Wanted number of occupied voxels.
    """
    return _area_cells(_float_points(points), samples)[0]


def _float_points(points: NDArray[np.generic]) -> NDArray[np.floating]:
    """(N, 3) points as float32 when they are, else float64 (no float64 copy of a float32
    cloud)."""
    p = np.asarray(points)
    return p if p.dtype in (np.float32, np.float64) else p.astype(np.float64)


def _area_cells(p: NDArray[np.floating], samples: int) -> tuple[float, NDArray[np.int64]]:
    """Cell size and the index of the first point in each occupied cell, ascending (of a
    thinned copy of ``p`` when it is large: indices then refer to ``p`` itself)."""
    step = max(1, len(p) // (20 * samples))  # enough points to fill the cells
    cell, first = _thinned_cells(np.ascontiguousarray(p[::step], dtype=np.float64), samples)
    return cell, first * step


def _thinned_cells(q: NDArray[np.float64], samples: int) -> tuple[float, NDArray[np.int64]]:
    """:func:`_area_cells` on the thinned points ``q`` themselves (indices into ``q``)."""
    if len(q) == 0:
        return 1e-9, np.zeros(0, dtype=np.int64)
    lo, hi = _bounds(q)
    span = float(np.max(hi - lo))
    cell = max(span, 1e-9) / math.sqrt(samples)  # surfaces: cells grow with 1 / cell^2
    first = np.arange(len(q))
    table = np.empty(1 << max(4, int(2 * len(q) - 1).bit_length()), dtype=np.int64)
    for _ in range(8):
        first = _first_in_cells(q, lo, cell, table)
        ratio = len(first) / samples
        if 0.7 < ratio < 1.4:
            break
        cell *= math.sqrt(ratio)
    return cell, first


@numba.njit(cache=True, nogil=True)
def _bounds(q):  # pragma: no cover - compiled
    """Per-axis minimum and maximum of (N, 3) points (N >= 1)."""
    lo = q[0].copy()
    hi = q[0].copy()
    for i in range(1, q.shape[0]):
        for c in range(3):
            x = q[i, c]
            if x < lo[c]:
                lo[c] = x
            elif x > hi[c]:
                hi[c] = x
    return lo, hi


@numba.njit(cache=True, nogil=True, inline="always")
def _slot(kx, ky, kz, mask):  # pragma: no cover - compiled
    """The first slot of the integer cell ``(kx, ky, kz)`` in an open-addressing table of
    ``mask + 1`` slots (a power of two)."""
    return ((kx * 73856093) ^ (ky * 19349663) ^ (kz * 83492791)) & mask


@numba.njit(cache=True, nogil=True, inline="always")
def _nearer(qx, qy, qz, P, j, best):  # pragma: no cover - compiled
    """The smaller of ``best`` and the squared distance from ``(qx, qy, qz)`` to ``P[j]``."""
    dx = qx - P[j, 0]
    dy = qy - P[j, 1]
    dz = qz - P[j, 2]
    d = dx * dx + dy * dy + dz * dz
    return d if d < best else best


@numba.njit(cache=True, nogil=True, inline="always")
def _in_cell(q, j, lo, cell, kx, ky, kz):  # pragma: no cover - compiled
    """Whether point ``j`` of ``q`` lies in the cell ``(kx, ky, kz)``."""
    return (
        np.int64(np.floor((q[j, 0] - lo[0]) / cell)) == kx
        and np.int64(np.floor((q[j, 1] - lo[1]) / cell)) == ky
        and np.int64(np.floor((q[j, 2] - lo[2]) / cell)) == kz
    )


@numba.njit(cache=True, nogil=True)
def _first_in_cells(q, lo, cell, table):  # pragma: no cover - compiled
    """Indices (ascending) of the first point of each occupied cell of side ``cell`` anchored
    at ``lo``: an open-addressing hash set of the integer cell coordinates; ``table`` is
    scratch space of a power-of-two size at least twice the number of points."""
    mask = table.shape[0] - 1
    table[:] = -1
    out = np.empty(q.shape[0], dtype=np.int64)
    n = 0
    for i in range(q.shape[0]):
        kx = np.int64(np.floor((q[i, 0] - lo[0]) / cell))
        ky = np.int64(np.floor((q[i, 1] - lo[1]) / cell))
        kz = np.int64(np.floor((q[i, 2] - lo[2]) / cell))
        slot = _slot(kx, ky, kz, mask)
        while True:
            j = table[slot]
            if j < 0:
                table[slot] = i
                out[n] = i
                n += 1
                break
            if _in_cell(q, j, lo, cell, kx, ky, kz):
                break
            slot = (slot + 1) & mask
    return out[:n]


def median_spacing(
    points: NDArray[np.floating],
    *,
    sample: int = 5000,
    seed: int = 0,
    tree_points: int | None = None,
) -> float:
    """Median nearest-neighbour distance of a point cloud (metres), from a fixed subsample.

    With ``tree_points``, the neighbours are searched among at most that many points (a
    fixed random subset), which overestimates the spacing of larger clouds but is fast.

    The nearest neighbours are found exactly in a grid of cells that holds only the points'
    indices (:func:`_nearest_other`), which gives bit for bit the distances a k-d tree gives
    (the same float64 sum of squared differences) without building the tree over every point.
    Points repeated exactly (a cloud that holds each point twice) count once when the
    median would otherwise be 0.
    """
    P = _float_points(points)
    if len(P) < 2:
        raise RegistrationError("cannot estimate point spacing from fewer than 2 points")
    spacing = _median_spacing(P, sample, seed, tree_points)
    if spacing == 0.0:  # a cloud written with every point twice: the spacing of distinct ones
        U = np.unique(np.asarray(P, dtype=np.float64), axis=0)
        if 2 <= len(U) < len(P):
            return median_spacing(U, sample=sample, seed=seed, tree_points=tree_points)
    return spacing


def _median_spacing(
    P: NDArray[np.floating], sample: int, seed: int, tree_points: int | None
) -> float:
    if tree_points is not None and len(P) > tree_points:
        P = P[np.random.default_rng(seed).choice(len(P), tree_points, replace=False)]
    P = np.ascontiguousarray(P, dtype=np.float64)
    idx = np.random.default_rng(seed).choice(len(P), min(sample, len(P)), replace=False)
    lo, hi = _bounds(P) if np.isfinite(P).all() else (None, None)
    if lo is None or not np.isfinite(hi - lo).all():
        from scipy.spatial import cKDTree  # heavy (0.1 s): the CLI imports this module early

        d, _ = cKDTree(P).query(P[idx], k=2)
        return float(np.median(d[:, 1]))
    span = float(np.max(hi - lo))
    # an eighth of the side of a box's share per point: a few points per cell on the surfaces
    # of a scene (the fastest on the test rooms, halls and courtyards)
    extent = np.maximum(hi - lo, span * 1e-3)
    cell = max(float(np.prod(extent) / len(P)) ** (1 / 3) / 8, span * 1e-6, 1e-12)
    return float(np.median(_nearest_other(P, np.asarray(idx, dtype=np.int64), lo, cell)))


#: rings of cells :func:`_nearest_other` searches around a point before it compares the point
#: with every other one (a point far from all others)
_MAX_RINGS = 6


@numba.njit(cache=True, nogil=True)
def _nearest_other(P, idx, lo, cell):  # pragma: no cover - compiled
    """(len(idx),) float64: the distance from each point ``P[idx[k]]`` to its nearest other
    point of ``P`` (0 for a duplicate), exactly: the points are binned into cells of side
    ``cell`` (a hash table of the occupied cells, each holding its points' indices), and each
    query searches rings of cells around its own until the best distance found is no larger
    than the ring's reach (any point farther out is farther away); beyond :data:`_MAX_RINGS`
    rings, with every other point."""
    n = P.shape[0]
    keys = np.empty((n, 3), dtype=np.int64)
    for i in range(n):
        for c in range(3):
            keys[i, c] = np.int64(np.floor((P[i, c] - lo[c]) / cell))
    size = 1 << 4
    while size < 2 * n:
        size *= 2
    mask = size - 1
    table = np.full(size, -1, dtype=np.int64)  # slot -> cell number
    cell_key = np.empty((n, 3), dtype=np.int64)
    count = np.zeros(n + 1, dtype=np.int64)
    of = np.empty(n, dtype=np.int64)  # point -> cell number
    m = 0
    for i in range(n):
        kx, ky, kz = keys[i, 0], keys[i, 1], keys[i, 2]
        slot = _slot(kx, ky, kz, mask)
        while True:
            v = table[slot]
            if v < 0:
                v = m
                table[slot] = v
                cell_key[v, 0], cell_key[v, 1], cell_key[v, 2] = kx, ky, kz
                m += 1
                break
            if cell_key[v, 0] == kx and cell_key[v, 1] == ky and cell_key[v, 2] == kz:
                break
            slot = (slot + 1) & mask
        of[i] = v
        count[v + 1] += 1
    for v in range(m):
        count[v + 1] += count[v]
    members = np.empty(n, dtype=np.int64)
    fill = count[:m].copy()
    for i in range(n):
        members[fill[of[i]]] = i
        fill[of[i]] += 1
    # the farthest ring that can be needed: the whole box
    reach = 1
    for c in range(3):
        r = int(keys[:, c].max() - keys[:, c].min()) + 1
        if r > reach:
            reach = r
    out = np.empty(idx.shape[0], dtype=np.float64)
    for k in range(idx.shape[0]):
        i = idx[k]
        qx, qy, qz = P[i, 0], P[i, 1], P[i, 2]
        best = np.inf
        for r in range(reach + 1):
            if r > _MAX_RINGS:  # an isolated point: every other point, one by one
                for j in range(n):
                    if j != i:
                        best = _nearer(qx, qy, qz, P, j, best)
                break
            # the cells at Chebyshev distance r from the query's cell
            for ax in range(-r, r + 1):
                for ay in range(-r, r + 1):
                    edge = abs(ax) == r or abs(ay) == r
                    az = -r
                    while az <= r:
                        kx, ky, kz = keys[i, 0] + ax, keys[i, 1] + ay, keys[i, 2] + az
                        slot = _slot(kx, ky, kz, mask)
                        while True:
                            v = table[slot]
                            if v < 0:
                                break
                            if (
                                cell_key[v, 0] == kx
                                and cell_key[v, 1] == ky
                                and cell_key[v, 2] == kz
                            ):
                                for t in range(count[v], count[v + 1]):
                                    j = members[t]
                                    if j != i:
                                        best = _nearer(qx, qy, qz, P, j, best)
                                break
                            slot = (slot + 1) & mask
                        # inside the ring's faces only its two z layers are new cells
                        az = az + 1 if edge or az == r else r
            # every point not yet seen lies beyond r whole cells of the query
            if best < np.inf and math.sqrt(best) <= r * cell * (1.0 - 1e-9):
                break
        out[k] = math.sqrt(best)
    return out


@numba.njit(cache=True, nogil=True)
def _voxel_sums(q, lo, cell, size):  # pragma: no cover - compiled
    """Per occupied cell of side ``cell`` anchored at ``lo`` (in the order of their first
    points): the sum of its points and their number. An open-addressing hash set of the
    integer cell coordinates, each stored with its cell, of ``size`` slots (a power of two) to
    start with, four times larger whenever half full: a table sized by the occupied cells
    rather than by the points stays in the cache. Neither the table's size nor its growth
    changes the cells, their order or their sums (each point is added in input order)."""
    mask = size - 1
    table = np.full(size, -1, dtype=np.int64)
    keys = np.empty((1024, 3), dtype=np.int64)
    sums = np.zeros((1024, 3), dtype=np.float64)
    counts = np.zeros(1024, dtype=np.int64)
    m = 0
    for i in range(q.shape[0]):
        kx = np.int64(np.floor((q[i, 0] - lo[0]) / cell))
        ky = np.int64(np.floor((q[i, 1] - lo[1]) / cell))
        kz = np.int64(np.floor((q[i, 2] - lo[2]) / cell))
        slot = _slot(kx, ky, kz, mask)
        while True:
            v = table[slot]
            if v < 0:
                if m == keys.shape[0]:  # grow the per-cell arrays
                    keys = np.concatenate((keys, np.empty((m, 3), dtype=np.int64)))
                    sums = np.concatenate((sums, np.zeros((m, 3), dtype=np.float64)))
                    counts = np.concatenate((counts, np.zeros(m, dtype=np.int64)))
                v = m
                keys[v, 0] = kx
                keys[v, 1] = ky
                keys[v, 2] = kz
                m += 1
                if 2 * m > size:  # half full: a larger table, every cell placed again
                    size *= 4
                    mask = size - 1
                    table = np.full(size, -1, dtype=np.int64)
                    for u in range(m):
                        s = _slot(keys[u, 0], keys[u, 1], keys[u, 2], mask)
                        while table[s] >= 0:
                            s = (s + 1) & mask
                        table[s] = u
                else:
                    table[slot] = v
                break
            if keys[v, 0] == kx and keys[v, 1] == ky and keys[v, 2] == kz:
                break
            slot = (slot + 1) & mask
        for c in range(3):
            sums[v, c] += q[i, c]
        counts[v] += 1
    return sums[:m], counts[:m]


def _voxels(
    points: NDArray[np.floating], voxel_m: float
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Sums and counts of the points per occupied voxel, the voxels as Open3D's
    ``voxel_down_sample`` bins them: ``floor((p - origin) / voxel_m)`` from the cloud's
    minimum less half a voxel. Float32 points are read as they are (sums in float64)."""
    p = np.ascontiguousarray(_float_points(points))
    if len(p) == 0:
        return np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
    lo = _bounds(p)[0].astype(np.float64)
    size = max(1 << 12, 1 << (len(p) // 4).bit_length())  # grown as cells appear
    return _voxel_sums(p, lo - voxel_m / 2, float(voxel_m), size)


def voxel_count(points: NDArray[np.floating], voxel_m: float) -> int:
    """Occupied voxels of a cloud (as :func:`voxel_centroids` bins it)."""
    return len(_voxels(points, voxel_m)[1])


def voxel_centroids(points: NDArray[np.floating], voxel_m: float) -> NDArray[np.float64]:
    """One point per occupied voxel, the centroid of its points: what Open3D's
    ``voxel_down_sample`` gives (the same voxels and centroids, in another order) without
    copying the cloud into Open3D or loading it. Compiled, one pass over the points.

    Parameters
    ----------
    points : (N, 3) float32 or float64, metres
    voxel_m : float, metres

    Returns
    -------
    (M, 3) float64, metres
        In the order of each voxel's first point.

    Examples
    --------
    >>> voxel_centroids(np.array([[1.0, 0, 0], [0.0, 0, 0], [0.2, 0, 0]]), 0.5)
    array([[1. , 0. , 0. ],
           [0.1, 0. , 0. ]])
    """
    sums, counts = _voxels(points, voxel_m)
    return sums / np.maximum(counts, 1)[:, None]


def thin(points: NDArray[Any], max_points: int) -> NDArray[Any]:
    """Every k-th point so that at most about ``max_points`` remain (deterministic). Voxels of
    the sizes the baselines use hold many points of a large scan, so the voxel grid of the
    thinned cloud hardly differs and downsampling gets much cheaper."""
    if len(points) <= max_points:
        return points
    return points[:: math.ceil(len(points) / max_points)]


def thin_random(
    points: NDArray[np.float64], max_points: int = 1_000_000, *, seed: int = 0
) -> NDArray[np.float64]:
    """At most about ``max_points`` of the points, a fixed-seed uniform random subset (voxels
    of the sizes ICP uses hold many points, so the voxel grid hardly changes)."""
    if len(points) <= max_points:
        return points
    keep = np.random.default_rng(seed).random(len(points)) < max_points / len(points)
    return points[keep]


def to_open3d(points: NDArray[np.float64]) -> Any:
    """An Open3D point cloud of (N, 3) float64 points."""
    import open3d as o3d  # heavy: only the Open3D paths need it

    p = np.ascontiguousarray(points, dtype=np.float64)
    if not p.flags.writeable:  # Open3D takes writeable arrays only (a kept, shared cloud)
        p = p.copy()
    pc = o3d.geometry.PointCloud()
    pc.points = o3d.utility.Vector3dVector(p)
    return pc


__all__ = [
    "area_cell",
    "area_sample",
    "area_sample_cell",
    "area_sample_image",
    "median_spacing",
    "thin",
    "thin_random",
    "to_open3d",
    "voxel_centroids",
    "voxel_count",
]
