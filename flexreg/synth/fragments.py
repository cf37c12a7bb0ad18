"""Fused fragments (3DMatch style): depth frames of a hand-held camera fused into clouds.

A camera walks slowly through the scene (:data:`FRAGMENT_WALK_M` per fragment) and turns
steadily one way (:data:`FRAGMENT_PAN_RAD` per fragment) with a gently varying downward
tilt, as someone scanning a room does (:func:`fragment_trajectory`). A fragment is
``frames`` consecutive depth frames (:func:`~flexreg.synth.sensors.render_rgbd`, the
Kinect-like :class:`~flexreg.synth.config.RGBDConfig`) fused into one cloud in the
coordinates of its first frame's camera (x right, y down, z forward) and voxel-downsampled:
each frame's points are first averaged per voxel of a world grid, then the voxel means of
all its frames, weighted by their counts, per voxel of the fragment's grid
(:func:`voxel_downsample`). A fragment has no single viewpoint; ``gt.json`` lists the
camera positions that made it, in its own frame.

Consecutive fragments overlap within a requested range and share no frame: after each
fragment, the next one's first frame is searched along the path from the frame after its last
(coarse steps, then halving) for the first start whose overlap with it falls below a target
drawn uniformly from the range, so overlaps spread over it; the frames skipped in between are
in no fragment. Overlap (:func:`fragment_overlap`): the share of one fragment's points within
:data:`OVERLAP_VOXELS` voxels of the other's, with the true relative pose; the smaller of the
two shares. Noise is drawn per frame (a generator of its own for each), so a fragment does not
depend on which frames the search rendered before it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.core.scan import Scan
from flexreg.core.transforms import invert
from flexreg.errors import DegenerateGeometryError
from flexreg.io import write_scan
from flexreg.synth.config import FragmentConfig, RGBDConfig
from flexreg.synth.objectscan import view_points
from flexreg.synth.paths import smooth_path
from flexreg.synth.scene import Scene
from flexreg.synth.seeding import as_rng
from flexreg.synth.sensors import look_at, render_rgbd

__all__ = [
    "FRAGMENT_PAN_RAD",
    "FRAGMENT_WALK_M",
    "OVERLAP_VOXELS",
    "fragment_overlap",
    "fragment_trajectory",
    "voxel_downsample",
    "write_fragments",
]

#: the camera turns by this much over one fragment's frames, radians
FRAGMENT_PAN_RAD = math.radians(20.0)
#: the camera walks this far over one fragment's frames, metres
FRAGMENT_WALK_M = 0.1
#: overlap radius, voxel sizes (3 cm at the default 1 cm voxels)
OVERLAP_VOXELS = 3.0
#: how far past a fragment the next one's start is searched, fragment lengths
SEARCH_FRAGMENTS = 6
#: points each overlap share is estimated from while searching (every k-th point)
SEARCH_QUERIES = 20000
#: frames of a candidate fragment fused while searching (every k-th frame)
SEARCH_FRAMES = 10
#: depth camera of the fragments: depths beyond this are not fused, metres (as the
#: truncated fusion of 3DMatch-style data keeps the near, less noisy depths)
FRAGMENT_MAX_DEPTH_M = 4.0

Progress = Callable[[int, int], None]


def fragment_trajectory(
    scene: Scene,
    n_frames: int,
    *,
    frames_per_fragment: int,
    rng: np.random.Generator | int | None = 0,
) -> list[NDArray[np.float64]]:
    """Camera poses (x right, y down, z forward) of someone scanning a room: along
    :func:`~flexreg.synth.paths.smooth_path`, :data:`FRAGMENT_WALK_M` and
    :data:`FRAGMENT_PAN_RAD` per ``frames_per_fragment`` frames, turning one way (drawn), the
    view tilted down by 11 +- 6 degrees.

    Returns
    -------
    list of (4, 4) float64
        ``T_world_camera`` of each frame, metres.
    """
    gen, _ = as_rng(rng)
    f = max(1, int(frames_per_fragment))
    P, _heading = smooth_path(scene, n_frames, step_m=FRAGMENT_WALK_M / f, rng=gen)
    yaw0 = gen.uniform(-math.pi, math.pi)
    turn = 1.0 if gen.random() < 0.5 else -1.0
    phase = gen.uniform(0, 2 * math.pi)
    poses = []
    for i in range(n_frames):
        yaw = yaw0 + turn * FRAGMENT_PAN_RAD * i / f
        pitch = -0.2 + 0.1 * math.sin(0.7 * i / f + phase)
        d = [math.cos(yaw) * math.cos(pitch), math.sin(yaw) * math.cos(pitch), math.sin(pitch)]
        poses.append(look_at(P[i], P[i] + d))
    return poses


def voxel_downsample(
    points: ArrayLike, voxel_m: float, weights: ArrayLike | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The (weighted) mean of the points in each occupied voxel of a grid at the origin.

    Parameters
    ----------
    points : (N, 3) float, metres
    voxel_m : float, metres
        Edge of the cubic voxels.
    weights : (N,) float, optional
        Weight of each point (1 each by default: a point that is itself a voxel mean carries
        its count).

    Returns
    -------
    means : (M, 3) float64, metres
        One per occupied voxel, in the order of the voxels' integer coordinates (x, then y,
        then z): the same points give the same array, bit for bit.
    weights : (M,) float64
        The summed weights of each voxel.

    Examples
    --------
    >>> m, w = voxel_downsample([[0.01, 0, 0], [0.03, 0, 0], [0.25, 0, 0]], 0.1)
    >>> m.round(6).tolist(), w.tolist()
    ([[0.02, 0.0, 0.0], [0.25, 0.0, 0.0]], [2.0, 1.0])
    """
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    w = np.ones(len(P)) if weights is None else np.asarray(weights, dtype=np.float64)
    if len(P) == 0:
        return np.zeros((0, 3)), np.zeros(0)
    q = np.floor(P / voxel_m).astype(np.int64)
    q -= q.min(axis=0)
    span = q.max(axis=0) + 1
    key = (q[:, 0] * span[1] + q[:, 1]) * span[2] + q[:, 2]
    _, inverse = np.unique(key, return_inverse=True)
    inverse = inverse.reshape(-1)
    total = np.asarray(np.bincount(inverse, weights=w), dtype=np.float64)
    means = np.column_stack([np.bincount(inverse, weights=w * P[:, k]) for k in range(3)])
    return means / total[:, None], total


def fragment_overlap(
    target: NDArray[np.float64],
    source: NDArray[np.float64],
    T_target_source: NDArray[np.float64],
    *,
    radius_m: float,
    max_queries: int | None = None,
) -> tuple[float, float]:
    """How much two fragments overlap: the share of each one's points within ``radius_m``
    of the other's, with the source mapped by ``T_target_source``.

    Parameters
    ----------
    target, source : (N, 3), (M, 3) float64, metres
        Each in its own frame.
    T_target_source : (4, 4) float64
    radius_m : float, metres
    max_queries : int, optional
        Estimate each share from at most this many points (every k-th one) instead of all.

    Returns
    -------
    seen_by_target, seen_by_source : float
        Share of the source's points near the target's, and of the target's near the
        source's (0 for an empty cloud).

    Examples
    --------
    >>> a = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    >>> fragment_overlap(a, a[:1], np.eye(4), radius_m=0.1)
    (1.0, 0.5)
    """
    from scipy.spatial import cKDTree  # heavy: loaded where it is used

    if len(target) == 0 or len(source) == 0:
        return 0.0, 0.0
    moved = source @ T_target_source[:3, :3].T + T_target_source[:3, 3]

    def share(cloud: NDArray[np.float64], queries: NDArray[np.float64]) -> float:
        k = 1 if max_queries is None else max(1, -(-len(queries) // max_queries))
        tree = cKDTree(cloud, balanced_tree=False, compact_nodes=False)
        d, _ = tree.query(queries[::k], distance_upper_bound=radius_m, workers=-1)
        return float(np.isfinite(d).mean())

    return share(target, moved), share(moved, target)


class _Frames:
    """Each frame's points averaged per voxel of a world grid, rendered once when first
    needed (noise from the frame's own generator) and dropped when no longer needed."""

    def __init__(
        self,
        scene: Scene,
        poses: list[NDArray[np.float64]],
        camera: RGBDConfig,
        voxel_m: float,
        base_seed: int,
    ) -> None:
        self.scene, self.poses, self.camera = scene, poses, camera
        self.voxel_m, self.base_seed = voxel_m, base_seed
        self._cache: dict[int, tuple[NDArray[np.float64], NDArray[np.float64]]] = {}

    def get(self, i: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        if i not in self._cache:
            gen = np.random.default_rng([self.base_seed, i])
            frame = render_rgbd(self.scene, self.poses[i], config=self.camera, rng=gen, image=False)
            T = self.poses[i]
            pts = view_points(frame.depth, self.camera) @ T[:3, :3].T + T[:3, 3]
            self._cache[i] = voxel_downsample(pts, self.voxel_m)
        return self._cache[i]

    def forget_before(self, i: int) -> None:
        for k in [k for k in self._cache if k < i]:
            del self._cache[k]

    def fuse(self, start: int, n: int, stride: int = 1) -> NDArray[np.float64]:
        """Fragment of frames ``start .. start + n - 1`` in the first frame's camera frame
        (with ``stride``: of every stride-th of them, a quick likeness)."""
        T = invert(self.poses[start])
        parts = [self.get(j) for j in range(start, start + n, stride)]
        P = np.vstack([p for p, _ in parts]) @ T[:3, :3].T + T[:3, 3]
        points, _ = voxel_downsample(P, self.voxel_m, np.concatenate([w for _, w in parts]))
        return points


def _next_start(
    frames: _Frames,
    prev_start: int,
    prev: NDArray[np.float64],
    config: FragmentConfig,
    target: float,
    last_start: int,
) -> tuple[int, NDArray[np.float64], tuple[float, float]]:
    """The first start after ``prev_start`` whose fragment overlaps the previous one by at
    most ``target`` (coarse steps, then halving, on overlaps estimated from
    :data:`SEARCH_FRAMES` of its frames and :data:`SEARCH_QUERIES` points), or the one before
    it when only that one is within the range (exact overlaps); its fragment and exact
    overlap shares."""
    f, radius = int(config.frames), OVERLAP_VOXELS * config.voxel_m
    stride = max(1, f // SEARCH_FRAMES)
    memo: dict[int, float] = {}

    def rel(s: int) -> NDArray[np.float64]:
        return invert(frames.poses[prev_start]) @ frames.poses[s]

    def est(s: int) -> float:
        if s not in memo:
            pts = frames.fuse(s, f, stride)
            shares = fragment_overlap(
                prev, pts, rel(s), radius_m=radius, max_queries=SEARCH_QUERIES
            )
            memo[s] = min(shares)
        return memo[s]

    lo, hi = config.overlap
    step = max(1, f // 4)
    first = prev_start + f  # no frame in two fragments
    if first > last_start:
        raise DegenerateGeometryError("fragments: the path is too short")  # pragma: no cover
    above, s = None, first
    while s <= last_start and est(s) > target:
        above, s = s, s + step
    if s > last_start:
        s = last_start
        if est(s) > target:
            raise DegenerateGeometryError(
                f"fragments: no start within {last_start - prev_start} frames of frame "
                f"{prev_start} overlaps its fragment by {lo:g}..{hi:g} (the path turns back "
                "on itself); try another seed or a wider fragment.overlap"
            )
    while above is not None and s - above > 1:  # the first start at or below the target
        mid = (above + s) // 2
        if est(mid) > target:
            above = mid
        else:
            s = mid
    for cand in (s, above):
        if cand is not None:
            pts = frames.fuse(cand, f)
            shares = fragment_overlap(prev, pts, rel(cand), radius_m=radius)
            if lo <= min(shares) <= hi:
                return cand, pts, shares
    before = "" if above is None else f"{est(above):.2f} -> "
    raise DegenerateGeometryError(
        f"fragments: the overlap after frame {prev_start} jumps past {lo:g}..{hi:g} from one "
        f"start to the next ({before}{est(s):.2f}); try another seed, more fragment.frames "
        "or a wider fragment.overlap"
    )


def write_fragments(
    out_dir: str | PathLike[str],
    scene: Scene,
    n: int,
    *,
    config: FragmentConfig,
    camera: RGBDConfig | None = None,
    rng: np.random.Generator | int | None = 0,
    progress: Progress | None = None,
) -> tuple[list[Path], list[dict[str, Any]], list[dict[str, Any]]]:
    """Make ``n`` fragments along one camera path and write ``fragment_NNN.ply``.

    Parameters
    ----------
    out_dir : path-like
        Folder of the fragments (created).
    scene : Scene
        A scene with free floor to walk (a procedural or project kind).
    n : int
        Number of fragments, >= 1.
    config : FragmentConfig
    camera : RGBDConfig, optional
        The depth camera (Kinect-like by default, depths up to
        :data:`FRAGMENT_MAX_DEPTH_M`).
    rng : numpy Generator, int or None
        The path, the overlap targets and (through one seed drawn from it) every frame's
        noise.
    progress : callable, optional
        ``progress(done, total)`` after each fragment.

    Returns
    -------
    files : list of Path
    fragments : list of dict
        Per fragment: ``name``, ``file`` (relative to ``out_dir``'s parent),
        ``T_world_fragment`` (its first frame's camera pose), ``frames`` (first and last
        frame index along the path), ``camera_positions_m`` (every frame's camera centre in
        the fragment's frame), ``points``.
    pairs : list of dict
        Each fragment and the next: ``target``, ``source``, ``T_target_source``,
        ``distance_m`` (between their first cameras), ``overlap`` (the smaller share of
        :func:`fragment_overlap`), ``seen_by_target``, ``seen_by_source``.

    Raises
    ------
    DegenerateGeometryError
        No start along the path gives an overlap within the range.
    """
    gen, _ = as_rng(rng)
    cam = camera or RGBDConfig(max_depth_m=FRAGMENT_MAX_DEPTH_M)
    f = int(config.frames)
    total = f * (1 + (n - 1) * SEARCH_FRAGMENTS)
    poses = fragment_trajectory(scene, total, frames_per_fragment=f, rng=gen)
    frames = _Frames(scene, poses, cam, config.voxel_m, int(gen.integers(2**62)))
    lo, hi = config.overlap
    margin = 0.1 * (hi - lo)
    starts, clouds = [0], [frames.fuse(0, f)]
    shares: list[tuple[float, float]] = []
    if progress is not None:
        progress(1, n)
    for k in range(1, n):
        target = gen.uniform(lo + margin, hi - margin)
        s, pts, share = _next_start(frames, starts[-1], clouds[-1], config, target, total - f)
        frames.forget_before(s)
        starts.append(s)
        clouds.append(pts)
        shares.append(share)
        if progress is not None:
            progress(k + 1, n)
    return _write(Path(out_dir), poses, starts, clouds, shares, f)


def _write(
    out: Path,
    poses: list[NDArray[np.float64]],
    starts: list[int],
    clouds: list[NDArray[np.float64]],
    shares: list[tuple[float, float]],
    f: int,
) -> tuple[list[Path], list[dict[str, Any]], list[dict[str, Any]]]:
    out.mkdir(parents=True, exist_ok=True)
    digits = max(3, len(str(len(starts) - 1)))
    files: list[Path] = []
    entries: list[dict[str, Any]] = []
    for k, (s, pts) in enumerate(zip(starts, clouds, strict=True)):
        name = f"fragment_{k:0{digits}d}"
        T0 = invert(poses[s])
        centres = np.array([T0[:3, :3] @ poses[j][:3, 3] + T0[:3, 3] for j in range(s, s + f)])
        files.append(write_scan(out / f"{name}.ply", Scan(points=pts, name=name)))
        entries.append(
            {
                "name": name,
                "file": f"{out.name}/{name}.ply",
                "T_world_fragment": poses[s].tolist(),
                "frames": [s, s + f - 1],
                "camera_positions_m": centres.tolist(),
                "points": len(pts),
            }
        )
    pairs = []
    for k, (seen_by_target, seen_by_source) in enumerate(shares):
        Ta, Tb = poses[starts[k]], poses[starts[k + 1]]
        pairs.append(
            {
                "target": entries[k]["name"],
                "source": entries[k + 1]["name"],
                "T_target_source": invert(Ta) @ Tb,
                "distance_m": float(np.linalg.norm(Tb[:3, 3] - Ta[:3, 3])),
                "overlap": min(seen_by_target, seen_by_source),
                "seen_by_target": seen_by_target,
                "seen_by_source": seen_by_source,
            }
        )
    return files, entries, pairs
