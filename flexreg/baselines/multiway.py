"""Open3D's multiway registration of N stations: pairwise FPFH + RANSAC + ICP, then a pose graph.

The pipeline of Open3D's documentation (``pipelines/multiway_registration`` with the pairwise
step of ``pipelines/global_registration``, as its reconstruction system registers fragments),
every size from one voxel ``v`` (default from the first station's resolution,
:func:`~flexreg.baselines._common.default_voxel`; the same ``v`` for every station):

1. **Per station, once**: voxel downsampling at ``v``, normals and FPFH features
   (:func:`flexreg.baselines.fpfh.fpfh_features`: the 1:2:5 voxel:normal:FPFH rule), and the
   cloud downsampled at ``v / 4`` that the ICP works on. Only these downsampled clouds are
   kept (float32); a station given as a path is read, reduced and released before the next.
2. **Per pair** (every pair ``i < j`` by default, or the pairs given): RANSAC on mutual FPFH
   matches (:func:`flexreg.baselines.fpfh.ransac_on_features`, the tutorial's checkers and
   criteria), then coarse-to-fine point-to-plane ICP (:func:`flexreg.baselines.open3d_icp.
   run_levels`, voxels ``v, v/2, v/4``), then
   :func:`open3d.pipelines.registration.get_information_matrix_from_point_clouds` at the last
   ICP distance. As in the tutorial the station with the smaller index is the source.
3. **Pose graph**: node ``k`` holds ``T_first_k``; edges between consecutive stations are
   *odometry* edges (``uncertain=False``), all others *loop closures* (``uncertain=True``).
   The initial node poses chain the odometry edges as the tutorial does; where a consecutive
   pair failed (RANSAC found no consistent set) a station is reached through its
   strongest successful link instead, and a station no successful link reaches is left
   unplaced (the tutorial has no such case: it assumes every pair registers).
4. :func:`open3d.pipelines.registration.global_optimization` with
   ``GlobalOptimizationLevenbergMarquardt``, the default convergence criteria and the
   tutorial's options: ``max_correspondence_distance`` = the ICP's fine distance,
   ``edge_prune_threshold=0.25``, ``reference_node=0``. Loop-closure edges whose line-process
   weight falls below the threshold are pruned by Open3D; odometry edges are never pruned
   (that is how the documented pipeline fuses stations that share no surface when a
   consecutive pair registers wrongly).

Stations connected to the first one by the edges that survive optimisation form group 0 and
are *placed*; the other connected components are further groups (their poses are in the same
optimised graph, but no kept edge ties them to the first station).

Seeds and threads: every link draws its RANSAC seed from ``(seed, i, j)``
(:func:`link_seed`), so a link's result does not depend on the order or the subset of pairs.
RANSAC runs on one thread by default (``ransac_threads=1``): with more threads Open3D draws its
hypotheses in thread order and results change from run to run even with a fixed seed (see
:mod:`flexreg.baselines.fpfh`). The ICP runs on one thread; features and the pose-graph
optimisation use Open3D's default threads (per-point features are the same on any thread count;
see ``docs/determinism.md`` for what was measured on the optimisation).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from os import PathLike
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from flexreg.baselines._common import DEFAULT_MAX_POINTS, BaselineConfig, resolve_voxel
from flexreg.baselines.fpfh import (
    RANSAC_CONFIDENCE,
    RANSAC_DISTANCE_VOXELS,
    RANSAC_MAX_ITERATIONS,
    fpfh_features,
    ransac_on_features,
)
from flexreg.baselines.open3d_icp import ICP_LEVELS, THIN_POINTS, run_levels
from flexreg.core.scan import as_points
from flexreg.core.transforms import invert
from flexreg.errors import ConfigError, InputError, RegistrationError
from flexreg.io import read_scan
from flexreg.stages.sampling import thin, to_open3d

log = logging.getLogger(__name__)

#: the option values of Open3D's multiway-registration tutorial
EDGE_PRUNE_THRESHOLD = 0.25
REFERENCE_NODE = 0
#: fewer RANSAC inliers than this: the pair failed (no edge)
MIN_RANSAC_INLIERS = 3

PairSpec = Literal["all", "sequential"] | Sequence[tuple[int, int]]
#: ``progress(stage, done, total)`` with stage ``"stations"`` or ``"pairs"``
Progress = Callable[[str, int, int], None]


@dataclass(frozen=True)
class Station:
    """What the pipeline keeps of one station (float32, scanner frame, metres).

    Attributes
    ----------
    name : str
    coarse : (M, 3) float32
        Points downsampled at ``v`` (FPFH and RANSAC).
    fpfh : (33, M) float32
        Their FPFH histograms.
    fine : (K, 3) float32
        Points downsampled at ``v / 4`` (ICP).
    points : int
        Points of the station as read.
    """

    name: str
    coarse: NDArray[np.float32]
    fpfh: NDArray[np.float32]
    fine: NDArray[np.float32]
    points: int


@dataclass(frozen=True)
class MultiwayLink:
    """One pairwise registration of the pose graph.

    Attributes
    ----------
    target, source : int
        Station indices; ``T_target_source`` maps source points into the target frame.
    kind : {"odometry", "loop"}
        Consecutive stations (certain edge) or any other pair (uncertain edge).
    status : {"accepted", "rejected", "failed"}
        Kept by the optimisation, pruned by its line process (the words of a survey's
        ``poses.json``), or no result (no edge).
    T_target_source : (4, 4) float64 or None
        After ICP.
    T_coarse : (4, 4) float64 or None
        RANSAC's transform.
    information : (6, 6) float64 or None
        Open3D's information matrix of the pair at the final ICP distance.
    ransac_inliers : int
    fitness : float
        Share of the ``v / 4`` source points with a target point within the final ICP distance.
    inlier_rmse_m : float, metres
    seed : int
        The RANSAC seed of this link.
    seconds : float
        Wall time of RANSAC, ICP and information matrix.
    distance_m : float, metres
        The last ICP level's correspondence distance (that of the information matrix).
    error : str or None
        Why the pair failed.
    """

    target: int
    source: int
    kind: str
    status: str
    T_target_source: NDArray[np.float64] | None
    T_coarse: NDArray[np.float64] | None
    information: NDArray[np.float64] | None
    ransac_inliers: int
    fitness: float
    inlier_rmse_m: float
    seed: int
    seconds: float
    distance_m: float = float("nan")
    error: str | None = None

    def to_dict(self, names: Sequence[str]) -> dict[str, Any]:
        """JSON-ready, with station names."""
        return {
            "target": names[self.target],
            "source": names[self.source],
            "kind": self.kind,
            "status": self.status,
            "T_target_source": self.T_target_source,
            "T_coarse": self.T_coarse,
            "information": self.information,
            "ransac_inliers": self.ransac_inliers,
            "fitness": self.fitness,
            "inlier_rmse_m": self.inlier_rmse_m,
            "seed": self.seed,
            "seconds": self.seconds,
            "distance_m": self.distance_m,
            "error": self.error,
        }


@dataclass(frozen=True)
class MultiwayResult:
    """Poses of every station in the first station's frame, the links and the timings.

    Attributes
    ----------
    names : list of str
        Station names (file stems for paths).
    poses : list of (4, 4) float64 or None
        ``T_first_station`` per station (None: no successful link reaches it).
    groups : (N,) int
        Connected component of the kept edges (0: the first station's); -1 for a station
        without pose.
    links : list of MultiwayLink
    timings_s : dict of str to float, seconds
        ``stations`` (reading, downsampling, features), ``ransac``, ``icp``, ``information``,
        ``optimisation``, ``total``.
    config : BaselineConfig
    """

    names: list[str]
    poses: list[NDArray[np.float64] | None]
    groups: NDArray[np.int64]
    links: list[MultiwayLink]
    timings_s: dict[str, float]
    config: BaselineConfig
    station_points: list[int] = field(default_factory=list)

    @property
    def placed(self) -> NDArray[np.bool_]:
        """(N,) bool: tied to the first station by kept edges (group 0)."""
        return self.groups == 0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, in the layout of a survey's ``poses.json`` (the fields this method has):
        ``reference`` (the first station), ``stations`` ({name: ``T_reference_station``
        (None outside group 0), ``placed``, ``group`` (None: no pose), ``group_reference``,
        ``T_group_station``, ``points``}), ``groups``, ``links``, plus ``method``, ``config``
        and ``timings_s``."""
        first = {int(g): k for k in reversed(range(len(self.names))) if (g := self.groups[k]) >= 0}
        stations: dict[str, Any] = {}
        for k, name in enumerate(self.names):
            g, pose = int(self.groups[k]), self.poses[k]
            ref = first.get(g)
            stations[name] = {
                "points": self.station_points[k] if self.station_points else None,
                "placed": g == 0,
                "T_reference_station": pose if g == 0 else None,
                "group": g if g >= 0 else None,
                "group_reference": None if ref is None else self.names[ref],
                "T_group_station": (
                    None if pose is None or ref is None else invert(_pose(self, ref)) @ pose
                ),
            }
        return {
            "method": "open3d-multiway",
            "reference": self.names[REFERENCE_NODE],
            "stations": stations,
            "groups": [
                {
                    "id": g,
                    "reference": self.names[ref],
                    "stations": [
                        n for n, gg in zip(self.names, self.groups, strict=True) if gg == g
                    ],
                    "placed": g == 0,
                }
                for g, ref in sorted(first.items())
            ],
            "links": [link.to_dict(self.names) for link in self.links],
            "config": self.config.to_dict(),
            "timings_s": dict(self.timings_s),
        }


def _pose(result: MultiwayResult, k: int) -> NDArray[np.float64]:
    pose = result.poses[k]
    assert pose is not None
    return pose


def link_seed(seed: int, target: int, source: int) -> int:
    """The RANSAC seed of one link: a function of ``(seed, target, source)`` only (< 2**31)."""
    state = np.random.SeedSequence([int(seed), int(target), int(source)]).generate_state(1)
    return int(state[0] % (2**31 - 1))


def pair_list(n: int, pairs: PairSpec) -> list[tuple[int, int]]:
    """``(target, source)`` index pairs: ``"all"`` = every ``(j, i)`` with ``i < j`` (the
    tutorial's order: the smaller index is the source), ``"sequential"`` = ``(i + 1, i)``, or
    the given pairs (validated, duplicates and self-pairs refused).

    >>> pair_list(3, "all")
    [(1, 0), (2, 0), (2, 1)]
    """
    if isinstance(pairs, str):
        if pairs == "all":
            return [(j, i) for i in range(n) for j in range(i + 1, n)]
        if pairs == "sequential":
            return [(i + 1, i) for i in range(n - 1)]
        raise ConfigError(f"pairs must be 'all', 'sequential' or (target, source) pairs: {pairs!r}")
    out: list[tuple[int, int]] = []
    seen: set[frozenset[int]] = set()
    for t, s in pairs:
        if not (0 <= t < n and 0 <= s < n) or t == s:
            raise ConfigError(f"pair ({t}, {s}): indices must differ and lie in 0..{n - 1}")
        key = frozenset((int(t), int(s)))
        if key in seen:
            raise ConfigError(f"pair ({t}, {s}) given twice")
        seen.add(key)
        out.append((int(t), int(s)))
    return out


def prepare_station(data: Any, v: float, name: str) -> Station:
    """Read (if a path) and reduce one station: ``v`` and ``v / 4`` downsampling, FPFH.

    Parameters
    ----------
    data : Scan, RangeImage, (N, 3) float array or path-like
    v : float, metres
    name : str
    """
    return reduce_station(_points(data, name), v, name)


def reduce_station(pts: NDArray[np.float64], v: float, name: str) -> Station:
    """:func:`prepare_station` of (N, 3) float64 points (metres)."""
    full = to_open3d(thin(pts, THIN_POINTS))
    coarse = full.voxel_down_sample(v)
    feature = fpfh_features(coarse, v)
    fine = full.voxel_down_sample(min(f for f, _, _ in ICP_LEVELS) * v)
    return Station(
        name=name,
        coarse=np.asarray(coarse.points, dtype=np.float32),
        fpfh=np.asarray(feature.data, dtype=np.float32),
        fine=np.asarray(fine.points, dtype=np.float32),
        points=len(pts),
    )


def _points(data: Any, name: str) -> NDArray[np.float64]:
    if isinstance(data, (str, PathLike)):
        return as_points(read_scan(data), name=str(data))
    return as_points(data, name=name)


def register_link(
    target: Station,
    source: Station,
    v: float,
    *,
    seed: int,
    ransac_threads: int | None = 1,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], dict[str, Any]]:
    """RANSAC on the stations' FPFH, point-to-plane ICP and the information matrix.

    Returns
    -------
    T_target_source, T_coarse : (4, 4) float64
    information : (6, 6) float64
    stats : dict
        ``ransac_inliers``, ``fitness``, ``inlier_rmse_m``, ``timings`` (seconds per step).

    Raises
    ------
    RegistrationError
        RANSAC found fewer than 3 consistent correspondences, or ICP no overlap.
    """
    import open3d as o3d

    reg: Any = o3d.pipelines.registration
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    tgt, src = _cloud(target.coarse), _cloud(source.coarse)
    coarse = ransac_on_features(
        tgt,
        src,
        _feature(target.fpfh),
        _feature(source.fpfh),
        RANSAC_DISTANCE_VOXELS * v,
        seed,
        ransac_threads,
    )
    timings["ransac"] = time.perf_counter() - t0
    n_inl = len(coarse.correspondence_set)
    if n_inl < MIN_RANSAC_INLIERS:
        raise RegistrationError(f"FPFH + RANSAC found {n_inl} consistent correspondences")
    T_coarse = np.array(coarse.transformation, dtype=np.float64)
    T, res, levels, (tl, sl) = run_levels(
        _cloud(target.fine), _cloud(source.fine), T_coarse, v, "point-to-plane", timings
    )
    t1 = time.perf_counter()
    info = np.asarray(reg.get_information_matrix_from_point_clouds(sl, tl, levels[-1], T))
    timings["information"] = time.perf_counter() - t1
    stats = {
        "ransac_inliers": n_inl,
        "fitness": float(res.fitness),
        "inlier_rmse_m": float(res.inlier_rmse),
        "distance_m": levels[-1],
        "timings": timings,
    }
    return T, T_coarse, np.array(info, dtype=np.float64), stats


def _cloud(points: NDArray[np.float32]) -> Any:
    return to_open3d(points.astype(np.float64))


def _feature(data: NDArray[np.float32]) -> Any:
    import open3d as o3d

    f = o3d.pipelines.registration.Feature()
    f.data = data.astype(np.float64)
    return f


def multiway(
    stations: Sequence[Any],
    *,
    names: Sequence[str] | None = None,
    pairs: PairSpec = "all",
    voxel_m: float | None = None,
    max_points: int = DEFAULT_MAX_POINTS,
    seed: int = 0,
    ransac_threads: int | None = 1,
    progress: Progress | None = None,
) -> MultiwayResult:
    """Register N stations with Open3D's documented multiway pipeline (see the module notes).

    Parameters
    ----------
    stations : sequence of Scan, RangeImage, (N, 3) float array or path-like
        At least two; points in each scanner's frame, metres. Paths are read one at a time.
    names : sequence of str, optional
        Station names (default: file stems for paths, ``station_k`` otherwise).
    pairs : "all", "sequential" or sequence of (target, source) int pairs
        The pairs to register (default every pair, as the tutorial does).
    voxel_m : float, optional, metres
        The scale ``v``; default from the first station's resolution.
    max_points : int
        Point budget of the default voxel.
    seed : int
        Seed of every link's RANSAC (see :func:`link_seed`).
    ransac_threads : int or None
        Threads of the RANSAC (1: results depend on ``seed`` alone).
    progress : callable, optional
        ``progress(stage, done, total)`` after each station and each pair.

    Returns
    -------
    MultiwayResult

    Raises
    ------
    InputError
        Fewer than two stations, or a station that cannot be read.
    ConfigError
        Invalid pairs, names or voxel.
    RegistrationError
        No pair registered at all.
    """
    n = len(stations)
    if n < 2:
        raise InputError("stations", f"multiway registration needs at least 2 stations, got {n}")
    names = _names(stations, names)
    todo = pair_list(n, pairs)
    t_start = time.perf_counter()
    timings = {"stations": 0.0, "ransac": 0.0, "icp": 0.0, "information": 0.0}
    prepared: list[Station] = []
    v, how = 0.0, ""
    for k, data in enumerate(stations):
        t0 = time.perf_counter()
        pts = _points(data, names[k])
        if k == 0:
            v, how = resolve_voxel(voxel_m, pts, max_points)
        prepared.append(reduce_station(pts, v, names[k]))
        del pts  # one full station in memory at a time
        timings["stations"] += time.perf_counter() - t0
        if progress is not None:
            progress("stations", k + 1, n)
    links = _register_pairs(prepared, todo, v, seed, ransac_threads, timings, progress)
    if not any(link.status != "failed" for link in links):
        raise RegistrationError(f"none of the {len(links)} station pairs registered")
    t0 = time.perf_counter()
    fine = max(lk.distance_m for lk in links if lk.status != "failed")
    poses, links, groups = optimise(links, n, fine_distance_m=fine)
    timings["optimisation"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_start
    return MultiwayResult(
        names=list(names),
        poses=poses,
        groups=groups,
        links=links,
        timings_s=timings,
        config=_settings(v, how, seed, ransac_threads, pairs),
        station_points=[s.points for s in prepared],
    )


def _names(stations: Sequence[Any], names: Sequence[str] | None) -> list[str]:
    if names is None:
        return [
            Path(s).stem if isinstance(s, (str, PathLike)) else f"station_{k}"
            for k, s in enumerate(stations)
        ]
    if len(names) != len(stations) or len(set(names)) != len(names):
        raise ConfigError("names must be unique, one per station")
    return list(names)


def _register_pairs(
    prepared: Sequence[Station],
    todo: Sequence[tuple[int, int]],
    v: float,
    seed: int,
    ransac_threads: int | None,
    timings: dict[str, float],
    progress: Progress | None,
) -> list[MultiwayLink]:
    """Every pair of ``todo``; a failed pair becomes a ``failed`` link."""
    links: list[MultiwayLink] = []
    for done, (t, s) in enumerate(todo, start=1):
        kind = "odometry" if abs(t - s) == 1 else "loop"
        ls = link_seed(seed, t, s)
        t0 = time.perf_counter()
        T: NDArray[np.float64] | None
        T_coarse: NDArray[np.float64] | None
        info: NDArray[np.float64] | None
        try:
            T, T_coarse, info, stats = register_link(
                prepared[t], prepared[s], v, seed=ls, ransac_threads=ransac_threads
            )
        except RegistrationError as exc:
            log.info("pair %s <- %s failed: %s", prepared[t].name, prepared[s].name, exc)
            T = T_coarse = info = None
            stats = {"ransac_inliers": 0, "fitness": 0.0, "inlier_rmse_m": float("nan")}
            error: str | None = str(exc)
        else:
            for key, secs in stats["timings"].items():
                bucket = "icp" if key in ("icp", "normals", "downsampling") else key
                timings[bucket] = timings.get(bucket, 0.0) + secs
            error = None
        links.append(
            MultiwayLink(
                target=t,
                source=s,
                kind=kind,
                status="failed" if error else "accepted",
                T_target_source=T,
                T_coarse=T_coarse,
                information=info,
                ransac_inliers=stats["ransac_inliers"],
                fitness=stats["fitness"],
                inlier_rmse_m=stats["inlier_rmse_m"],
                seed=ls,
                seconds=time.perf_counter() - t0,
                distance_m=stats.get("distance_m", float("nan")),
                error=error,
            )
        )
        if progress is not None:
            progress("pairs", done, len(todo))
    return links


def initial_poses(links: Sequence[MultiwayLink], n: int) -> list[NDArray[np.float64] | None]:
    """``T_first_k`` to start the optimisation from: the tutorial's chained odometry
    (``pose[k+1] = pose[k] @ inv(T_{k+1,k})``); a station the chain cannot reach (its
    odometry pair failed) is reached through its successful link of highest fitness to a
    station already posed, repeatedly; None for a station no successful link reaches."""
    ok = [lk for lk in links if lk.T_target_source is not None]
    poses: list[NDArray[np.float64] | None] = [None] * n
    poses[REFERENCE_NODE] = np.eye(4)
    odo = {(lk.target, lk.source): lk for lk in ok if lk.kind == "odometry"}
    for k in range(n - 1):
        base = poses[k]
        if base is None:
            continue
        if (k + 1, k) in odo:
            poses[k + 1] = base @ invert(_T(odo[(k + 1, k)]))
        elif (k, k + 1) in odo:
            poses[k + 1] = base @ _T(odo[(k, k + 1)])
    while True:
        best: tuple[float, int, NDArray[np.float64]] | None = None
        for lk in ok:
            pt, ps = poses[lk.target], poses[lk.source]
            if (pt is None) == (ps is None):
                continue
            if pt is not None:  # source from target
                cand = (lk.fitness, lk.source, pt @ _T(lk))
            else:
                assert ps is not None
                cand = (lk.fitness, lk.target, ps @ invert(_T(lk)))
            if best is None or cand[0] > best[0]:
                best = cand
        if best is None:
            return poses
        poses[best[1]] = best[2]


def _T(link: MultiwayLink) -> NDArray[np.float64]:
    assert link.T_target_source is not None
    return link.T_target_source


def optimise(
    links: Sequence[MultiwayLink], n: int, *, fine_distance_m: float
) -> tuple[list[NDArray[np.float64] | None], list[MultiwayLink], NDArray[np.int64]]:
    """Build the tutorial's PoseGraph and run ``global_optimization`` (Levenberg-Marquardt).

    Parameters
    ----------
    links : sequence of MultiwayLink
        Failed links add no edge.
    n : int
        Stations.
    fine_distance_m : float, metres
        ``max_correspondence_distance`` of the optimisation options.

    Returns
    -------
    poses : list of (4, 4) float64 or None
        ``T_first_k``; None for stations no successful link reaches.
    links : list of MultiwayLink
        The same, with ``status`` "rejected" for edges the optimisation pruned.
    groups : (N,) int
        Connected components of the kept edges (0: the first station's; -1: no pose).
    """
    import open3d as o3d

    reg: Any = o3d.pipelines.registration
    start = initial_poses(links, n)
    nodes = [k for k in range(n) if start[k] is not None]
    index = {k: i for i, k in enumerate(nodes)}
    graph = reg.PoseGraph()
    for k in nodes:
        graph.nodes.append(reg.PoseGraphNode(start[k]))
    edge_links: list[int] = []
    for li, lk in enumerate(links):
        if lk.T_target_source is None or lk.target not in index or lk.source not in index:
            continue
        graph.edges.append(
            reg.PoseGraphEdge(
                index[lk.source],
                index[lk.target],
                lk.T_target_source,
                lk.information,
                uncertain=lk.kind == "loop",
            )
        )
        edge_links.append(li)
    option = reg.GlobalOptimizationOption(
        max_correspondence_distance=fine_distance_m,
        edge_prune_threshold=EDGE_PRUNE_THRESHOLD,
        reference_node=REFERENCE_NODE,
    )
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        reg.global_optimization(
            graph,
            reg.GlobalOptimizationLevenbergMarquardt(),
            reg.GlobalOptimizationConvergenceCriteria(),
            option,
        )
    kept = {(e.source_node_id, e.target_node_id) for e in graph.edges}
    out = list(links)
    for li in edge_links:
        lk = out[li]
        if (index[lk.source], index[lk.target]) not in kept:
            out[li] = replace(lk, status="rejected")
    poses: list[NDArray[np.float64] | None] = [None] * n
    for k in nodes:
        poses[k] = np.array(graph.nodes[index[k]].pose, dtype=np.float64)
    return poses, out, _components(out, n, poses)


def _components(
    links: Sequence[MultiwayLink], n: int, poses: Sequence[NDArray[np.float64] | None]
) -> NDArray[np.int64]:
    """Connected components of the kept links, numbered in station order (the first
    station's is 0); -1 for stations without pose."""
    parent = list(range(n))

    def root(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for lk in links:
        if lk.status == "accepted":
            parent[root(lk.target)] = root(lk.source)
    groups = np.full(n, -1, dtype=np.int64)
    numbers: dict[int, int] = {}
    for k in range(n):
        if poses[k] is not None:
            groups[k] = numbers.setdefault(root(k), len(numbers))
    return groups


def _settings(
    v: float, how: str, seed: int, ransac_threads: int | None, pairs: PairSpec
) -> BaselineConfig:
    """The record of how the pipeline ran: every size from the voxel ``v``."""
    return BaselineConfig(
        method="open3d-multiway",
        voxel_m=v,
        voxel_source=how,
        start="global",
        seed=seed,
        parameters={
            "pairs": pairs if isinstance(pairs, str) else [list(p) for p in pairs],
            "features": "fpfh (see fpfh-ransac): normals 2 v, FPFH 5 v",
            "ransac_distance_m": RANSAC_DISTANCE_VOXELS * v,
            "ransac_max_iterations": RANSAC_MAX_ITERATIONS,
            "ransac_confidence": RANSAC_CONFIDENCE,
            "ransac_threads": "all (Open3D default)" if ransac_threads is None else ransac_threads,
            "link_seed": "SeedSequence([seed, target, source])",
            "icp": {
                "variant": "point-to-plane",
                "levels": [
                    {"voxel_m": f * v, "max_distance_m": d * v, "max_iterations": it}
                    for f, d, it in ICP_LEVELS
                ],
                "threads": 1,
            },
            "pose_graph": {
                "odometry_edges": "consecutive stations, uncertain=False",
                "loop_closure_edges": "all other pairs, uncertain=True",
                "method": "GlobalOptimizationLevenbergMarquardt",
                "criteria": "GlobalOptimizationConvergenceCriteria() defaults",
                "max_correspondence_distance_m": ICP_LEVELS[-1][1] * v,
                "edge_prune_threshold": EDGE_PRUNE_THRESHOLD,
                "reference_node": REFERENCE_NODE,
            },
            "thin_above_points": THIN_POINTS,
        },
    )


__all__ = [
    "EDGE_PRUNE_THRESHOLD",
    "MultiwayLink",
    "MultiwayResult",
    "Station",
    "initial_poses",
    "link_seed",
    "multiway",
    "optimise",
    "pair_list",
    "prepare_station",
    "reduce_station",
    "register_link",
]
