"""Station placement with guaranteed overlap, and one-line synthetic station pairs.

Overlap between two stations is measured by visibility, on a coarse version of the scanner
grid: the share of station A's returns that station B also sees (line of sight free, inside
B's range, field of view and incidence limit), and vice versa. :func:`station_overlap` returns
the smaller of the two shares, so "overlap 0.5" means each station sees at least half of what
the other one measured.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from flexreg.core.scan import Scan
from flexreg.core.transforms import as_transform, invert, rotation_about_axis
from flexreg.errors import ConfigError, DegenerateGeometryError
from flexreg.synth.config import TLSConfig
from flexreg.synth.scene import Scene
from flexreg.synth.scenes import make_scene
from flexreg.synth.seeding import as_rng
from flexreg.synth.sensors import scan_tls

#: coarse grid used to measure overlap (2 degree steps)
OVERLAP_GRID = (180, 90)


@dataclass(eq=False)
class FreeMap:
    """Where a tripod can stand: a floor grid from downward ray casts.

    Attributes
    ----------
    x0, y0 : float, metres
        World position of cell ``[0, 0]``'s centre.
    cell_m : float, metres
    free : (ny, nx) bool
        Bare floor (upward surface near ``floor_z``, nothing above it up to the probe height,
        not inside a solid), eroded by the tripod radius.
    ground_z : (ny, nx) float64, metres
        Height of the surface hit by the downward ray (NaN where nothing was hit).
    """

    x0: float
    y0: float
    cell_m: float
    free: NDArray[np.bool_]
    ground_z: NDArray[np.float64]

    def lookup(self, xy: NDArray[np.float64]) -> tuple[NDArray[np.bool_], NDArray[np.float64]]:
        """``(free, ground_z)`` at (N, 2) world positions (outside the grid: not free)."""
        j = np.rint((xy[:, 0] - self.x0) / self.cell_m).astype(np.int64)
        i = np.rint((xy[:, 1] - self.y0) / self.cell_m).astype(np.int64)
        ny, nx = self.free.shape
        inside = (i >= 0) & (i < ny) & (j >= 0) & (j < nx)
        ic, jc = np.clip(i, 0, ny - 1), np.clip(j, 0, nx - 1)
        return inside & self.free[ic, jc], np.where(inside, self.ground_z[ic, jc], np.nan)


def free_map(
    scene: Scene,
    *,
    cell_m: float = 0.1,
    probe_height_m: float = 2.0,
    tripod_radius_m: float = 0.35,
    region: tuple[float, float, float, float] | None = None,
) -> FreeMap:
    """Compute (and cache on the scene) the :class:`FreeMap` of its placement region (or of
    ``region``, ``(xmin, ymin, xmax, ymax)`` in metres, when given)."""
    key = f"free_map:{cell_m}:{probe_height_m}:{tripod_radius_m}"
    if region is not None:
        key += ":" + ",".join(repr(float(v)) for v in region)
    if key in scene._cache:
        return scene._cache[key]
    x0, y0, x1, y1 = scene.region if region is None else region
    if not (x1 > x0 and y1 > y0):
        raise DegenerateGeometryError(f"scene region is empty: {(x0, y0, x1, y1)}")
    xs = np.arange(x0, x1 + 1e-9, cell_m)
    ys = np.arange(y0, y1 + 1e-9, cell_m)
    X, Y = np.meshgrid(xs, ys)
    zp = scene.floor_z + probe_height_m
    origins = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, zp)])
    hits = scene.cast(origins, np.broadcast_to(np.array([0.0, 0.0, -1.0]), origins.shape))
    gz = (zp - hits.t).reshape(X.shape)
    ok = hits.hit.reshape(X.shape) & (hits.normal[:, 2].reshape(X.shape) > 0.9)
    ok &= np.abs(gz - scene.floor_z) < 0.4
    # a probe inside a solid (wall, machine) sees a back face above it; its downward ray may
    # report the floor's top face, which is coplanar with the solid's bottom face
    up = scene.cast(origins, np.broadcast_to(np.array([0.0, 0.0, 1.0]), origins.shape))
    ok &= ~(up.hit & (up.normal[:, 2] > 0)).reshape(X.shape)
    r = max(1, math.ceil(tripod_radius_m / cell_m))
    yy, xx = np.mgrid[-r : r + 1, -r : r + 1]
    disk = xx * xx + yy * yy <= r * r
    free = ndimage.binary_erosion(ok, structure=disk, border_value=0)
    fm = FreeMap(float(xs[0]), float(ys[0]), cell_m, free, np.where(np.isfinite(gz), gz, np.nan))
    scene._cache[key] = fm
    return fm


def coarse_config(config: TLSConfig) -> TLSConfig:
    w, h = OVERLAP_GRID
    return config.replace(
        width=w,
        height=h,
        range_noise_m=0.0,
        range_noise_per_m=0.0,
        dropout_rate=0.0,
        mixed_pixel_prob=0.0,
        intensity_speckle=0.0,
        colors=False,
    )


def _coarse_hits(
    scene: Scene, T: NDArray[np.float64], config: TLSConfig
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """World points and normals a station sees on the coarse overlap grid."""
    cfg = coarse_config(config)
    key = ("coarse", T.tobytes(), cfg)
    cache = scene._cache.setdefault("coarse_hits", {})
    if key in cache:
        return cache[key]
    pw, n = coarse_points(scene, T, cfg)
    if len(cache) > 32:  # ~0.8 MB per entry
        cache.clear()
    cache[key] = (pw, n)
    return pw, n


def coarse_points(
    scene: Scene, T: NDArray[np.float64], cfg: TLSConfig
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """World points and normals of a station on the coarse grid ``cfg`` (uncached)."""
    s = scan_tls(scene, T, config=cfg, rng=0)
    pw = s.points_world()
    # normals of what was seen, by re-casting the valid rays (cheap at this size)
    d = pw - T[:3, 3]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    n = scene.cast(T[:3, 3], d).normal.astype(np.float64)
    return pw, n


def visible_fraction(
    scene: Scene,
    T_world_from: ArrayLike,
    T_world_to: ArrayLike,
    *,
    config: TLSConfig | None = None,
) -> float:
    """Share of the coarse returns of station ``to`` that station ``from`` can also see.

    A point is seen from a station if it lies within the station's range and polar field of
    view (outside the tripod cone), its incidence angle is within the limit, and the ray from
    the station reaches it unobstructed (within 2 cm + 0.5 % of the distance).

    Returns
    -------
    float in [0, 1]; 0 if station ``to`` sees nothing.
    """
    cfg = config or TLSConfig()
    Ta = as_transform(T_world_from, name="T_world_from")
    Tb = as_transform(T_world_to, name="T_world_to")
    pts, normals = _coarse_hits(scene, Tb, cfg)
    return seen_share(scene, Ta, pts, normals, cfg)


def seen_share(
    scene: Scene,
    Ta: NDArray[np.float64],
    pts: NDArray[np.float64],
    normals: NDArray[np.float64],
    cfg: TLSConfig,
) -> float:
    """Share of the world points ``pts`` (with their surface ``normals``) that a station at
    ``Ta`` sees (the test of :func:`visible_fraction`)."""
    if len(pts) == 0:
        return 0.0
    ok, d, dist = seen_rays(Ta, pts, normals, cfg)
    idx = np.flatnonzero(ok)
    if len(idx):
        t = scene.cast(Ta[:3, 3], d[idx]).t
        ok[idx] = unblocked(t, dist[idx])
    return float(np.count_nonzero(ok)) / len(pts)


def unblocked(t: NDArray[np.float64], dist: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Whether rays that first hit at ``t`` reach points at ``dist`` (2 cm + 0.5 %)."""
    return t >= dist - (0.02 + 0.005 * dist)


def seen_rays(
    Ta: NDArray[np.float64],
    pts: NDArray[np.float64],
    normals: NDArray[np.float64],
    cfg: TLSConfig,
) -> tuple[NDArray[np.bool_], NDArray[np.float64], NDArray[np.float64]]:
    """The tests of :func:`seen_share` before the line of sight: ``(ok, directions,
    distances)`` of every point from the station at ``Ta``."""
    o = Ta[:3, 3]
    v = pts - o
    dist = np.linalg.norm(v, axis=1)
    d = v / np.maximum(dist, 1e-12)[:, None]
    local = d @ Ta[:3, :3]
    theta = np.arccos(np.clip(local[:, 2], -1.0, 1.0))
    ok = (dist >= cfg.min_range_m) & (dist <= cfg.max_range_m)
    ok &= (theta >= cfg.theta_min) & (theta <= cfg.theta_max)
    if cfg.tripod_cone_rad > 0:
        ok &= theta <= math.pi - cfg.tripod_cone_rad
    ok &= np.abs(np.einsum("ij,ij->i", normals, d)) >= math.cos(cfg.max_incidence_rad)
    return ok, d, dist


def station_overlap(
    scene: Scene, T_world_a: ArrayLike, T_world_b: ArrayLike, *, config: TLSConfig | None = None
) -> float:
    """Mutual overlap of two stations: ``min`` of the two :func:`visible_fraction` shares."""
    return min(
        visible_fraction(scene, T_world_a, T_world_b, config=config),
        visible_fraction(scene, T_world_b, T_world_a, config=config),
    )


def random_rotation(rng: np.random.Generator, max_tilt_rad: float) -> NDArray[np.float64]:
    """Any yaw, and a tilt of up to ``max_tilt_rad`` about a random horizontal axis."""
    yaw = rng.uniform(-math.pi, math.pi)
    axis_angle = rng.uniform(0.0, 2.0 * math.pi)
    tilt = rng.uniform(0.0, max_tilt_rad)
    Rz = rotation_about_axis([0.0, 0.0, 1.0], yaw)
    Rt = rotation_about_axis([math.cos(axis_angle), math.sin(axis_angle), 0.0], tilt)
    return Rt @ Rz


def check_positions(scene: Scene, P: NDArray[np.float64], clearance_m: float) -> NDArray[np.bool_]:
    """Clearance from every surface, and not inside a closed object (back faces all around)."""
    ok = scene.distance(P) >= clearance_m
    dirs = np.array(
        [
            [1, 0, 0],
            [-1, 0, 0],
            [0, 1, 0],
            [0, -1, 0],
            [0, 0, 1],
            [0, 0, -1],
            [1, 1, 1],
            [-1, -1, 1],
            [1, -1, -1],
            [-1, 1, -1],
        ],
        dtype=np.float64,
    )
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    Og = np.repeat(P, len(dirs), axis=0)
    D = np.tile(dirs, (len(P), 1))
    h = scene.cast(Og, D)
    back = (np.einsum("ij,ij->i", h.normal.astype(np.float64), D) > 0) & h.hit
    ok &= back.reshape(len(P), len(dirs)).mean(axis=1) <= 0.3
    return ok


def place_stations(
    scene: Scene,
    n: int,
    *,
    min_overlap: float = 0.5,
    distance_range_m: tuple[float, float] = (2.0, 10.0),
    max_tilt_rad: float = math.radians(3.0),
    height_range_m: tuple[float, float] = (1.3, 1.8),
    clearance_m: float = 0.3,
    config: TLSConfig | None = None,
    rng: np.random.Generator | int | None = 0,
    max_tries: int = 3000,
) -> list[NDArray[np.float64]]:
    """Place ``n`` scanner stations on free floor, each linked to an earlier one.

    Station 0 stands anywhere free. Every later station ``k`` is placed at a distance within
    ``distance_range_m`` of a *parent* (station ``k - 1``, or any earlier station if that
    fails), with :func:`station_overlap` of at least ``min_overlap`` with it, at least half the
    minimum distance away from every other station. Candidate positions must lie on bare floor
    (:func:`free_map`), keep ``clearance_m`` from every surface and not be inside a closed
    object. Each station gets a uniformly random yaw and a tilt of up to ``max_tilt_rad`` about a
    random horizontal axis.

    Parameters
    ----------
    scene : Scene
    n : int
        Number of stations, >= 1.
    min_overlap : float
        Required mutual overlap (0..1) between a station and its parent.
    distance_range_m : (float, float), metres
        Allowed distance between a station and its parent (scanner centres, 3D).
    max_tilt_rad : float, radians
    height_range_m : (float, float), metres
        Scanner centre above the ground.
    clearance_m : float, metres
    config : TLSConfig, optional
        Sensor model used for the overlap (range, field of view, tripod cone).
    rng : numpy Generator, int or None
    max_tries : int
        Candidate positions tried per station before giving up.

    Returns
    -------
    list of (4, 4) float64
        ``T_world_scanner`` of each station.

    Raises
    ------
    ConfigError
        Invalid arguments.
    DegenerateGeometryError
        If a station cannot be placed (scene too small or cluttered for the distance range,
        overlap too demanding).
    """
    gen, _ = as_rng(rng)
    cfg = config or TLSConfig()
    dmin, dmax = (float(v) for v in distance_range_m)
    if int(n) != n or n < 1:
        raise ConfigError(f"number of stations must be a positive integer, got {n}")
    if not (0 < dmin <= dmax):
        raise ConfigError(f"distance range must satisfy 0 < min <= max, got {distance_range_m}")
    if not 0 <= min_overlap <= 1:
        raise ConfigError(f"min_overlap must be in [0, 1], got {min_overlap}")
    if not 0 <= max_tilt_rad <= math.radians(30):
        raise ConfigError(
            f"max_tilt_rad must be in [0, 30 deg], got {math.degrees(max_tilt_rad):.1f} deg"
        )
    h0, h1 = (float(v) for v in height_range_m)
    if not 0 < h0 <= h1:
        raise ConfigError(f"height range must satisfy 0 < min <= max, got {height_range_m}")
    fm = free_map(scene)
    fy, fx = np.nonzero(fm.free)
    if len(fx) == 0:
        raise DegenerateGeometryError(
            f"{scene.name or 'scene'}: no free floor to place a scanner on"
        )
    poses: list[NDArray[np.float64]] = []
    batch = 64
    for k in range(int(n)):
        placed = None
        tries = 0
        while placed is None and tries < max_tries:
            # candidate positions: anywhere free for the first station, else around a parent
            if k == 0:
                pick = gen.integers(0, len(fx), size=batch)
                xy = np.column_stack([fm.x0 + fx[pick] * fm.cell_m, fm.y0 + fy[pick] * fm.cell_m])
                xy += gen.uniform(-0.5, 0.5, size=(batch, 2)) * fm.cell_m
                parents = np.full(batch, -1)
            else:
                use_last = tries < max_tries // 2
                parents = np.full(batch, k - 1) if use_last else gen.integers(0, k, size=batch)
                dist = gen.uniform(dmin, dmax, size=batch)
                ang = gen.uniform(-math.pi, math.pi, size=batch)
                base = np.array([poses[p][:2, 3] for p in parents])
                xy = base + dist[:, None] * np.column_stack([np.cos(ang), np.sin(ang)])
            heights = gen.uniform(h0, h1, size=batch)
            rots = [random_rotation(gen, max_tilt_rad) for _ in range(batch)]
            tries += batch
            free, gz = fm.lookup(xy)
            P = np.column_stack([xy, gz + heights])
            ok = free.copy()
            for i in np.flatnonzero(ok):
                others = [T[:3, 3] for T in poses]
                if others and np.min(np.linalg.norm(np.array(others) - P[i], axis=1)) < 0.5 * dmin:
                    ok[i] = False
                elif parents[i] >= 0:
                    d3 = float(np.linalg.norm(poses[parents[i]][:3, 3] - P[i]))
                    ok[i] = dmin <= d3 <= dmax
            idx = np.flatnonzero(ok)
            if len(idx):
                ok[idx] = check_positions(scene, P[idx], clearance_m)
            for i in np.flatnonzero(ok):
                T = np.eye(4)
                T[:3, :3] = rots[i]
                T[:3, 3] = P[i]
                if parents[i] >= 0 and min_overlap > 0:
                    if station_overlap(scene, poses[parents[i]], T, config=cfg) < min_overlap:
                        continue
                placed = T
                break
        if placed is None:
            raise DegenerateGeometryError(
                f"{scene.name or 'scene'}: could not place station {k} after {tries} candidates "
                f"(distance {dmin:g}-{dmax:g} m, overlap >= {min_overlap:g}); try a wider distance "
                "range, a lower overlap or another seed"
            )
        poses.append(placed)
    return poses


@dataclass(eq=False)
class StationPair:
    """Two simulated stations and their exact relative pose.

    Unpacks as ``target, source, T_target_source``.

    Attributes
    ----------
    target, source : Scan
        Points in each scanner's frame, with ``T_world_scanner`` set to the true pose.
    T_target_source : (4, 4) float64
        ``inv(T_world_target) @ T_world_source``: maps source-frame points onto the target.
    scene : Scene
    overlap : float
        Mutual visibility overlap (see :func:`station_overlap`).
    distance_m : float
        Distance between the scanner centres.
    """

    target: Scan
    source: Scan
    T_target_source: NDArray[np.float64]
    scene: Scene
    overlap: float
    distance_m: float

    def __iter__(self) -> Any:
        return iter((self.target, self.source, self.T_target_source))

    def __repr__(self) -> str:
        return (
            f"StationPair({self.scene.kind}, {len(self.target)} + {len(self.source)} points, "
            f"distance {self.distance_m:.2f} m, overlap {self.overlap:.2f})"
        )


def stream(seed: int, index: int) -> np.random.Generator:
    """Independent random stream ``index`` of a seed (placement 0, stations 100 + i, ...).

    The scene itself uses ``np.random.default_rng(seed)``, so it equals ``make_scene(kind, seed)``.
    """
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(index,)))


def station_pair(
    scene: Scene | str = "room",
    *,
    seed: np.random.Generator | int = 0,
    resolution: tuple[int, int] = (1024, 512),
    noise_m: float = 0.003,
    distance_range_m: tuple[float, float] = (2.0, 10.0),
    min_overlap: float = 0.5,
    max_tilt_rad: float = math.radians(5.0),
    config: TLSConfig | None = None,
    poses: tuple[ArrayLike, ArrayLike] | None = None,
) -> StationPair:
    """Two TLS stations of a scene with their exact ``T_target_source``, in one call.

    >>> target, source, T = station_pair("room", seed=3, resolution=(256, 128))  # doctest: +SKIP

    Parameters
    ----------
    scene : Scene or {"room", "courtyard", "hall"}
        A scene, or a kind generated with ``make_scene(kind, seed)``.
    seed : int or numpy Generator
        Seeds the scene (if generated), the placement and both stations' noise.
    resolution : (int, int)
        Grid ``(width, height)``; ignored when ``config`` is given.
    noise_m : float, metres
        Constant range noise sigma; ignored when ``config`` is given.
    distance_range_m, min_overlap, max_tilt_rad
        See :func:`place_stations`.
    config : TLSConfig, optional
        Full sensor model.
    poses : two (4, 4) float64, optional
        ``T_world_scanner`` of the target and the source (metres) instead of placing them:
        the same views on every CPU (seeded placement depends on ray-cast ties between
        coplanar faces, see docs/determinism.md); ``seed`` still seeds the scene and noise.
    """
    if isinstance(seed, np.random.Generator):
        seed = int(seed.integers(0, 2**63 - 1))
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ConfigError(f"seed must be a non-negative int or a numpy Generator, got {seed!r}")
    seed = int(seed)
    sc = make_scene(scene, seed) if isinstance(scene, str) else scene
    cfg = config or TLSConfig(
        width=int(resolution[0]), height=int(resolution[1]), range_noise_m=noise_m
    )
    if poses is not None:
        Ta, Tb = (as_transform(T) for T in poses)
    else:
        Ta, Tb = place_stations(
            sc,
            2,
            min_overlap=min_overlap,
            distance_range_m=distance_range_m,
            max_tilt_rad=max_tilt_rad,
            config=cfg,
            rng=stream(seed, 0),
        )
    target = scan_tls(sc, Ta, config=cfg, rng=stream(seed, 100), name="station_00")
    source = scan_tls(sc, Tb, config=cfg, rng=stream(seed, 101), name="station_01")
    return StationPair(
        target,
        source,
        invert(Ta) @ Tb,
        sc,
        station_overlap(sc, Ta, Tb, config=cfg),
        float(np.linalg.norm(Tb[:3, 3] - Ta[:3, 3])),
    )


def in_line_of_sight(
    scene: Scene,
    origin: NDArray[np.float64],
    points_world: NDArray[np.float64],
    dist: NDArray[np.float64],
    *,
    tol_m: float,
    max_incidence_rad: float,
) -> NDArray[np.bool_]:
    """Whether a sensor at ``origin`` sees each of ``points_world`` (at distances ``dist``,
    metres): the scene's first hit towards the point lies no nearer than ``dist - tol_m`` and
    meets its surface within ``max_incidence_rad`` of the normal. (N,) bool."""
    dirs = (points_world - origin) / dist[:, None]
    hits = scene.cast(origin, dirs)
    cos_inc = np.abs(np.einsum("ij,ij->i", hits.normal.astype(np.float64), dirs))
    return (hits.t >= dist - tol_m) & (cos_inc >= math.cos(max_incidence_rad))


def neighbour_pairs(
    names: list[str],
    poses: list[NDArray[np.float64]],
    overlap: Callable[[int, int], float],
) -> list[dict[str, Any]]:
    """Each item of a sequence (views, lidar frames) with the next, for ``gt.json``: their
    ``T_target_source = inv(T_world_target) @ T_world_source``, the distance between them
    (metres) and ``overlap(i, i + 1)``.

    >>> import numpy as np
    >>> T = [np.eye(4), np.eye(4)]
    >>> T[1][0, 3] = 2.0
    >>> neighbour_pairs(["a", "b"], T, lambda i, j: 0.5)[0]["distance_m"]
    2.0
    """
    return [
        {
            "target": names[i],
            "source": names[i + 1],
            "T_target_source": invert(poses[i]) @ poses[i + 1],
            "distance_m": float(np.linalg.norm(poses[i + 1][:3, 3] - poses[i][:3, 3])),
            "overlap": overlap(i, i + 1),
        }
        for i in range(len(names) - 1)
    ]
