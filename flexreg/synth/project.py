"""Station placement of multi-station projects, and their overlap graph.

A surveyor covers a building, a warehouse or a street by walking it: every new station is set
up a few metres on from one already scanned, where it sees enough of it to be registered,
until the whole site is covered. :func:`place_project` does the same on the free floor of each
group's placement zones (``Scene.zones``): a depth-first walk that puts each station at a
*spacing* from every earlier one (sqrt(zone area per station), 2-8 m, so the stations
cover the site like a grid) and within reach of a *parent* it overlaps, or failing that on a
doorway the scene marks (``Scene.stand_points``) at half the spacing, as a surveyor links a
room; when no spot around the last station works it steps back to earlier ones. The walk
starts on the scene's first stand point (a building's entrance), or anywhere free. Stations
therefore see their neighbours, not the whole site, and the walk order is the file order.

:func:`overlap_matrix` then measures what every station sees of every other one (the
visibility overlap of :func:`~flexreg.synth.placement.station_overlap`), which gives the true
overlap graph, its connected components and, for disconnected groups, the proof that no two
groups share a view.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.sparse.csgraph import connected_components

from flexreg.errors import ConfigError, DegenerateGeometryError
from flexreg.synth.config import TLSConfig
from flexreg.synth.placement import (
    FreeMap,
    check_positions,
    coarse_config,
    coarse_points,
    free_map,
    random_rotation,
    seen_rays,
    seen_share,
    station_overlap,
    unblocked,
)
from flexreg.synth.scene import Scene
from flexreg.synth.scenes import group_sizes
from flexreg.synth.seeding import as_rng

__all__ = [
    "ProjectPlacement",
    "overlap_components",
    "overlap_matrix",
    "place_project",
    "zone_free_map",
]

#: candidate positions drawn for the first station per attempt
_BATCH = 96
#: candidate positions drawn around a parent per attempt (most fail cheap tests: a doorway
#: seen from a room is a narrow cone)
_AROUND = 512
#: candidates (best first) whose overlap with the parent is measured per attempt
_OVERLAP_TRIES = 10
#: grid of the quick overlap estimate (6 degrees), and the share of the minimal overlap below
#: which an estimate rejects a candidate without the full 2 degree test
_QUICK_GRID = (60, 30)
_QUICK_MARGIN = 0.6
#: factor applied to the spacing when no station fits anywhere
_SHRINK = 0.85


@dataclass(eq=False)
class ProjectPlacement:
    """Stations of a project.

    Attributes
    ----------
    poses : list of (4, 4) float64
        ``T_world_scanner`` of each station, in walk (file) order, group after group.
    groups : list of int
        Group (disconnected site) of each station.
    parents : list of int
        Index of the station each one was set up from (-1 for the first of a group); the
        parent links form a spanning tree of each group whose every link has at least the
        minimal overlap.
    spacing_m : list of float
        Smallest minimal distance between stations the walk used, per group (metres).
    """

    poses: list[NDArray[np.float64]]
    groups: list[int]
    parents: list[int]
    spacing_m: list[float] = field(default_factory=list)


def zone_free_map(scene: Scene, group: int = 0) -> FreeMap:
    """The :func:`~flexreg.synth.placement.free_map` of one group's placement zones.

    Computed over the bounding box of the group's zone rectangles (``Scene.zones``) and
    cleared outside them; a scene without zones has one group (0) over its ``region``.
    """
    rects = [z[:4] for z in scene.zones if z[4] == group] if scene.zones else [scene.region]
    if not rects:
        raise ConfigError(f"{scene.name or 'scene'} has no placement zone of group {group}")
    R = np.array(rects, dtype=np.float64)
    box = (float(R[:, 0].min()), float(R[:, 1].min()), float(R[:, 2].max()), float(R[:, 3].max()))
    fm = free_map(scene, region=box)
    ny, nx = fm.free.shape
    X = fm.x0 + np.arange(nx) * fm.cell_m
    Y = fm.y0 + np.arange(ny) * fm.cell_m
    inside = np.zeros((ny, nx), dtype=bool)
    for x0, y0, x1, y1 in rects:
        inside |= ((Y >= y0) & (Y <= y1))[:, None] & ((X >= x0) & (X <= x1))[None, :]
    return replace(fm, free=fm.free & inside)


def place_project(
    scene: Scene,
    stations: int,
    *,
    min_overlap: float = 0.15,
    distance_range_m: tuple[float, float] = (2.0, 10.0),
    max_tilt_rad: float = math.radians(3.0),
    height_range_m: tuple[float, float] = (1.3, 1.8),
    clearance_m: float = 0.3,
    config: TLSConfig | None = None,
    rng: np.random.Generator | int | None = 0,
) -> ProjectPlacement:
    """Place the stations of a project as a surveyor walks it (see the module docstring).

    Parameters
    ----------
    scene : Scene
        A project scene (:func:`~flexreg.synth.scenes.make_project_scene`); its zones' groups
        share the stations as :func:`~flexreg.synth.scenes.group_sizes` says. A scene
        without zones is one group over its ``region``.
    stations : int
        Number of stations, at least 2 per group.
    min_overlap : float
        Minimal :func:`~flexreg.synth.placement.station_overlap` of a station with its parent.
    distance_range_m : (float, float), metres
        Allowed distance between a station and its parent; the minimum is also the smallest
        spacing the walk may shrink to.
    max_tilt_rad : float, radians
        Tilt of each station about a random horizontal axis, up to this (any yaw).
    height_range_m : (float, float), metres
        Scanner centre above the ground.
    clearance_m : float, metres
        Free space around the scanner centre.
    config : TLSConfig, optional
        Sensor model of the overlap (range, field of view, tripod cone).
    rng : numpy Generator, int or None

    Returns
    -------
    ProjectPlacement

    Raises
    ------
    ConfigError
        Invalid arguments.
    DegenerateGeometryError
        If a group's zones cannot hold its stations even at the smallest spacing.
    """
    gen, _ = as_rng(rng)
    cfg = config or TLSConfig()
    dmin, dmax = (float(v) for v in distance_range_m)
    ids = sorted({z[4] for z in scene.zones}) if scene.zones else [0]
    if isinstance(stations, bool) or int(stations) != stations or stations < 2 * len(ids):
        raise ConfigError(f"a project needs at least 2 stations per group, got {stations}")
    if not 0 < dmin <= dmax:
        raise ConfigError(f"distance range must satisfy 0 < min <= max, got {distance_range_m}")
    if not 0 <= min_overlap <= 1:
        raise ConfigError(f"min_overlap must be in [0, 1], got {min_overlap}")
    if not 0 <= max_tilt_rad <= math.radians(30):
        raise ConfigError(f"max_tilt_rad must be in [0, 30 deg], got {max_tilt_rad}")
    out = ProjectPlacement([], [], [])
    for g, n in zip(ids, group_sizes(int(stations), len(ids)), strict=True):
        fm = zone_free_map(scene, g)
        rects = [z[:4] for z in scene.zones if z[4] == g] if scene.zones else [scene.region]
        area = sum((x1 - x0) * (y1 - y0) for x0, y0, x1, y1 in rects)  # floor, not free floor
        spacing = float(np.clip(1.25 * math.sqrt(area / n), dmin, min(8.0, 0.8 * dmax)))
        walk = _Walk(scene, fm, cfg, gen, dmin, dmax, min_overlap, max_tilt_rad, height_range_m)
        walk.clearance_m = clearance_m
        walk.stand = np.array([(x, y) for x, y, k in scene.stand_points if k == g]).reshape(-1, 2)
        offset = len(out.poses)
        poses, parents, spacing = walk.run(n, spacing, f"{scene.name or 'scene'} group {g}")
        out.poses += poses
        out.groups += [g] * n
        out.parents += [p + offset if p >= 0 else -1 for p in parents]
        out.spacing_m.append(spacing)
    return out


@dataclass(eq=False)
class _Walk:
    """The state of one group's walk."""

    scene: Scene
    fm: FreeMap
    cfg: TLSConfig
    gen: np.random.Generator
    dmin: float
    dmax: float
    min_overlap: float
    max_tilt_rad: float
    height_range_m: tuple[float, float]
    clearance_m: float = 0.3
    stand: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 2)))
    quick: dict[int, tuple[NDArray[np.float64], NDArray[np.float64]]] = field(default_factory=dict)
    poses: list[NDArray[np.float64]] = field(default_factory=list)

    def _pose(self, p: NDArray[np.float64]) -> NDArray[np.float64]:
        T = np.eye(4)
        T[:3, :3] = random_rotation(self.gen, self.max_tilt_rad)
        T[:3, 3] = p
        return T

    def _candidates(self, xy: NDArray[np.float64]) -> NDArray[np.float64]:
        """(N, 3) scanner centres over ``xy`` (NaN where the floor is not free)."""
        h0, h1 = self.height_range_m
        free, gz = self.fm.lookup(xy)
        z = np.where(free, gz, np.nan) + self.gen.uniform(h0, h1, size=len(xy))
        return np.column_stack([xy, z])

    def _first(self, label: str) -> NDArray[np.float64]:
        fy, fx = np.nonzero(self.fm.free)
        if len(fx) == 0:
            raise DegenerateGeometryError(f"{label}: no free floor to place a scanner on")
        fm = self.fm
        if len(self.stand):  # the scene's first stand point (an entrance) and around it
            xy = self.stand[0] + self.gen.uniform(-0.5, 0.5, size=(_BATCH, 2))
            xy[0] = self.stand[0]
            P = self._candidates(xy)
            idx = np.flatnonzero(np.isfinite(P[:, 2]))
            idx = idx[check_positions(self.scene, P[idx], self.clearance_m)]
            if len(idx):
                return self._pose(P[idx[0]])
        for _ in range(40):
            pick = self.gen.integers(0, len(fx), size=_BATCH)
            xy = np.column_stack([fm.x0 + fx[pick] * fm.cell_m, fm.y0 + fy[pick] * fm.cell_m])
            xy += self.gen.uniform(-0.5, 0.5, size=(_BATCH, 2)) * fm.cell_m
            P = self._candidates(xy)
            idx = np.flatnonzero(np.isfinite(P[:, 2]))
            idx = idx[check_positions(self.scene, P[idx], self.clearance_m)]
            if len(idx):
                return self._pose(P[idx[0]])
        raise DegenerateGeometryError(f"{label}: found no clear spot for the first station")

    def _from(self, parent: int, spacing: float) -> NDArray[np.float64] | None:
        """A new station around ``parent``: free, clear, ``spacing`` from all others, and
        overlapping the parent; ``None`` if this attempt finds none."""
        Pp = self.poses[parent][:3, 3]
        r = self.gen.uniform(spacing, max(spacing, self.dmax), size=_AROUND)
        a = self.gen.uniform(-math.pi, math.pi, size=_AROUND)
        P = self._candidates(Pp[:2] + r[:, None] * np.column_stack([np.cos(a), np.sin(a)]))
        return self._pick(parent, P, spacing, hug=True)

    def _from_stand_points(self, parent: int, spacing: float) -> NDArray[np.float64] | None:
        """A new station on one of the scene's stand points (a doorway) seen from ``parent``,
        at half the spacing from all others; the nearest first."""
        if len(self.stand) == 0:
            return None
        xy = np.repeat(self.stand, 4, axis=0)
        xy += self.gen.uniform(-0.3, 0.3, size=xy.shape)
        return self._pick(parent, self._candidates(xy), 0.5 * spacing, hug=False)

    def _pick(
        self, parent: int, P: NDArray[np.float64], spacing: float, *, hug: bool
    ) -> NDArray[np.float64] | None:
        """The first candidate of ``P`` (N, 3) that passes every test, in order of distance to
        the placed stations (``hug``) or to the parent."""
        Pp = self.poses[parent][:3, 3]
        placed = np.array([T[:3, 3] for T in self.poses])
        with np.errstate(invalid="ignore"):
            diff = P[:, None, :] - placed[None, :, :]
            d_all = np.sqrt(np.einsum("ijk,ijk->ij", diff, diff).min(axis=1))
            d_par = np.linalg.norm(P - Pp, axis=1)
            ok = (d_all >= spacing) & (d_par >= self.dmin) & (d_par <= self.dmax)
        idx = np.flatnonzero(ok)
        if len(idx):  # the parent's scanner must see the candidate's (through a door, say)
            v = P[idx] - Pp
            dist = np.linalg.norm(v, axis=1)
            idx = idx[self.scene.cast(Pp, v / dist[:, None]).t >= dist - 0.05]
        if len(idx):
            idx = idx[check_positions(self.scene, P[idx], self.clearance_m)]
        # hug the stations already placed: the walk fills the site without leaving holes
        key = d_all if hug else d_par
        for i in idx[np.argsort(key[idx], kind="stable")][:_OVERLAP_TRIES]:
            T = self._pose(P[i])
            if self._quick_overlap(parent, T) < _QUICK_MARGIN * self.min_overlap:
                continue  # clearly too little: skip the full test
            if station_overlap(self.scene, self.poses[parent], T, config=self.cfg) >= (
                self.min_overlap
            ):
                return T
        return None

    def _quick_overlap(self, parent: int, T: NDArray[np.float64]) -> float:
        """The overlap of ``parent`` and a candidate on a 6 degree grid (a cheap estimate)."""
        cfg = coarse_config(self.cfg).replace(width=_QUICK_GRID[0], height=_QUICK_GRID[1])
        if parent not in self.quick:
            self.quick[parent] = coarse_points(self.scene, self.poses[parent], cfg)
        pts, nrm = coarse_points(self.scene, T, cfg)
        Tp = self.poses[parent]
        return min(
            seen_share(self.scene, Tp, pts, nrm, self.cfg),
            seen_share(self.scene, T, *self.quick[parent], self.cfg),
        )

    def run(
        self, n: int, spacing: float, label: str
    ) -> tuple[list[NDArray[np.float64]], list[int], float]:
        """Place ``n`` stations; returns poses, parent indices and the smallest spacing used
        (it shrinks while the site seems full at it, e.g. to pass a doorway, and grows back
        to ``spacing`` as stations are placed)."""
        self.poses = [self._first(label)]
        parents = [-1]
        exhausted: set[int] = set()
        s0, smallest = spacing, spacing
        while len(self.poses) < n:
            last = len(self.poses) - 1
            T = None
            for parent in [last, *range(last - 1, -1, -1)]:  # the last station, then back
                if parent in exhausted:
                    continue
                T = self._from(parent, spacing)
                if T is None:  # a second batch, then the doorways, before giving up on it
                    T = self._from(parent, spacing)
                if T is None:
                    T = self._from_stand_points(parent, spacing)
                if T is not None:
                    self.poses.append(T)
                    parents.append(parent)
                    if spacing < s0:
                        spacing = min(s0, spacing / _SHRINK)
                        exhausted.clear()
                    break
                exhausted.add(parent)
            if T is None:  # the site is full at this spacing
                spacing *= _SHRINK
                smallest = min(smallest, spacing)
                exhausted.clear()
                if spacing < max(1.0, 0.5 * self.dmin):
                    raise DegenerateGeometryError(
                        f"{label}: could place only {len(self.poses)} of {n} stations (spacing "
                        f"down to {spacing / _SHRINK:.1f} m, overlap >= {self.min_overlap:g}); "
                        "use fewer stations, a lower overlap or another seed"
                    )
        return self.poses, parents, smallest


def overlap_matrix(
    scene: Scene, poses: Sequence[ArrayLike], *, config: TLSConfig | None = None
) -> NDArray[np.float64]:
    """What every station sees of every other one.

    Parameters
    ----------
    scene : Scene
    poses : list of (4, 4) float
        ``T_world_scanner`` of each station.
    config : TLSConfig, optional
        Sensor model (range, field of view, incidence limit, tripod cone).

    Returns
    -------
    (N, N) float64
        ``S[i, j]``: share of station ``j``'s coarse returns that station ``i`` also sees
        (:func:`~flexreg.synth.placement.visible_fraction`); the mutual overlap of a pair is
        ``min(S[i, j], S[j, i])``, exactly :func:`~flexreg.synth.placement.station_overlap`
        (the same tests, with one ray cast per station for all the others). Stations more
        than twice the maximal range apart share nothing and are not cast. The diagonal is 1.
    """
    cfg = config or TLSConfig()
    Ts = [np.asarray(T, dtype=np.float64) for T in poses]
    coarse = coarse_config(cfg)
    hits = [coarse_points(scene, T, coarse) for T in Ts]
    n = len(Ts)
    S = np.eye(n)
    C = np.array([T[:3, 3] for T in Ts]).reshape(n, 3)
    for i in range(n):
        # the tests of station_overlap, point by point, with one ray cast for all stations j
        js = [j for j in range(n) if j != i and np.linalg.norm(C[i] - C[j]) <= 2 * cfg.max_range_m]
        tests = [seen_rays(Ts[i], hits[j][0], hits[j][1], cfg) for j in js]
        sel = [np.flatnonzero(ok) for ok, _d, _dist in tests]
        if not any(len(k) for k in sel):
            continue
        t = scene.cast(
            C[i], np.vstack([d[k] for (_ok, d, _dist), k in zip(tests, sel, strict=True)])
        ).t
        start = 0
        for j, (ok, _d, dist), k in zip(js, tests, sel, strict=True):
            ok[k] = unblocked(t[start : start + len(k)], dist[k])
            start += len(k)
            S[i, j] = float(np.count_nonzero(ok)) / len(ok) if len(ok) else 0.0
    return S


def overlap_components(overlap: NDArray[np.float64], min_overlap: float) -> NDArray[np.int64]:
    """Connected components of the graph of pairs with mutual overlap >= ``min_overlap``
    (> 0 when ``min_overlap`` is 0).

    Parameters
    ----------
    overlap : (N, N) float
        :func:`overlap_matrix`.

    Returns
    -------
    (N,) int64 component label of each station, numbered in order of first appearance.

    Examples
    --------
    >>> S = np.array([[1, .4, 0], [.5, 1, 0], [0, 0, 1]])
    >>> overlap_components(S, 0.3).tolist()
    [0, 0, 1]
    """
    M = np.minimum(overlap, np.asarray(overlap).T)
    adj = (M >= min_overlap) if min_overlap > 0 else (M > 0)
    _, labels = connected_components(adj, directed=False)
    _, first = np.unique(labels, return_index=True)
    order = np.argsort(first)
    remap = np.empty_like(order)
    remap[order] = np.arange(len(order))
    return remap[labels].astype(np.int64)


def project_ground_truth(
    placement: ProjectPlacement,
    overlap: NDArray[np.float64],
    names: list[str],
    min_overlap: float,
) -> dict[str, Any]:
    """The project part of ``gt.json``: groups, the overlap graph, the walk.

    Returns
    -------
    dict
        ``"groups"``: station names of each group; ``"components"``: connected components of
        the overlap graph at ``min_overlap`` (station names); ``"overlaps"``: every pair that
        shares any view (``target``, ``source`` in file order, ``overlap`` = the mutual
        overlap, ``seen_by_target`` / ``seen_by_source`` = the two shares, ``distance_m``);
        ``"spacing_m"`` per group.
    """
    n = len(names)
    C = np.array([T[:3, 3] for T in placement.poses]).reshape(n, 3)
    pairs = []
    for i in range(n):
        for j in range(i + 1, n):
            m = min(overlap[i, j], overlap[j, i])
            if m > 0:
                pairs.append(
                    {
                        "target": names[i],
                        "source": names[j],
                        "overlap": round(float(m), 6),
                        "seen_by_target": round(float(overlap[i, j]), 6),
                        "seen_by_source": round(float(overlap[j, i]), 6),
                        "distance_m": round(float(np.linalg.norm(C[j] - C[i])), 6),
                    }
                )
    ids = sorted(set(placement.groups))
    labels = overlap_components(overlap, min_overlap)
    return {
        "groups": [
            [nm for nm, g in zip(names, placement.groups, strict=True) if g == k] for k in ids
        ],
        "components": [
            [nm for nm, c in zip(names, labels, strict=True) if c == k]
            for k in range(int(labels.max()) + 1 if n else 0)
        ],
        "min_overlap": min_overlap,
        "spacing_m": [round(s, 6) for s in placement.spacing_m],
        "overlaps": pairs,
    }
