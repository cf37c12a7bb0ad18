"""A multi-room office building for multi-station projects: rooms off corridors, doorways.

The floor is a set of *strips* stacked along y, each a corridor along x with a row of rooms on
either side, joined by a cross corridor along the west wall. Rooms open to their corridor by a
door (some by two) and some to their neighbour; their outer walls have windows onto an exterior
ground with neighbouring blocks and trees. Every room is furnished on its own (office, meeting
room, store or lounge), so no two rooms look alike. A station in a room sees a corridor station
only through a doorway: those links have a low overlap, as in a real building survey.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from flexreg.errors import ConfigError
from flexreg.synth import objects as ob
from flexreg.synth.mesh import Material, MeshBuilder, box, rot_z, wall_boxes
from flexreg.synth.scene import Scene
from flexreg.synth.scenes._plan import Floorplan, Walls, door, exterior, finish, put, window
from flexreg.synth.seeding import as_rng

#: floor area per station the layout is sized for, m^2 (a station or two per room)
BUILDING_AREA_PER_STATION_M2 = 22.0

#: room kinds and their furniture counts (shelves, table groups, desks, sofas, clutter)
_ROOM_KINDS = {
    "office": (1, 0, 3, 0, 4),
    "meeting": (1, 2, 0, 0, 3),
    "store": (5, 0, 0, 0, 8),
    "lounge": (2, 1, 0, 2, 5),
}


@dataclass
class _Room:
    """A room ``[x0, x1] x [y0, y1]`` (wall centre lines, metres) and its door spans
    ``(wall, a, b)``: wall ``"s"``, ``"n"``, ``"w"`` or ``"e"`` and the span along it."""

    x0: float
    y0: float
    x1: float
    y1: float
    kind: str
    doors: list[tuple[str, float, float]] = field(default_factory=list)


@dataclass
class _Site:
    """The building's mesh, size ``Lx`` x ``Ly``, storey height ``H``, outer and inner wall
    thickness ``wt`` / ``it``, corridor width ``cw``, rooms and corridor rectangles."""

    rng: np.random.Generator
    b: MeshBuilder
    Lx: float
    Ly: float
    H: float
    wt: float
    it: float
    cw: float
    wall_mat: Material
    rooms: list[_Room] = field(default_factory=list)
    corridors: list[tuple[float, float, float, float]] = field(default_factory=list)
    strips: list[tuple[float, float, float]] = field(default_factory=list)
    entrance_y: float = 0.0


def building(
    rng: np.random.Generator | int | None = None,
    *,
    stations: int = 12,
    size_m: tuple[float, float] | None = None,
) -> Scene:
    """Office building with rooms on both sides of corridors, sized for ``stations`` stations.

    Parameters
    ----------
    rng : numpy Generator, int or None
    stations : int
        Number of stations the floor should hold (about
        :data:`BUILDING_AREA_PER_STATION_M2` of floor each); sets the number of corridor strips
        (the floor about 1.5 times as long as deep) and the building's length.
    size_m : (float, float), optional
        Footprint ``(x, y)`` in metres instead (at least 12 x 12 m).

    Returns
    -------
    Scene
        Kind ``"building"``; ``layout`` counts rooms, doors and strips; one placement zone over
        the whole floor.
    """
    rng, seed = as_rng(rng)
    site = _layout(rng, stations, size_m)
    _shell(site)
    _inner_walls(site)
    for r in site.rooms:
        _furnish(site, r)
    _corridor_items(site)
    exterior(site.b, rng, -site.wt, -site.wt, site.Lx + site.wt, site.Ly + site.wt)
    m = 0.25
    layout = {
        "rooms": len(site.rooms),
        "strips": len(site.strips),
        "doors": sum(len(r.doors) for r in site.rooms),
        "corridor_width_m": round(site.cw, 3),
        "room_kinds": {k: sum(r.kind == k for r in site.rooms) for k in _ROOM_KINDS},
    }
    zone = (m, m, site.Lx - m, site.Ly - m, 0)
    return finish(
        site.b,
        "building",
        seed,
        site.Lx,
        site.Ly,
        margin_m=m,
        zones=(zone,),
        layout=layout,
        stand_points=_door_stand_points(site),
    )


def _door_stand_points(site: _Site) -> tuple[tuple[float, float, int], ...]:
    """Where a surveyor sets up to link two spaces: inside the main entrance (first: the walk
    starts there), at each corridor junction, and in and 1 m either side of every doorway."""
    pts: list[tuple[float, float, int]] = [(site.cw / 2, site.entrance_y, 0)]
    for _y0, yc0, yc1 in site.strips:
        pts += [(site.cw / 2, (yc0 + yc1) / 2, 0), (site.cw + 1.5, (yc0 + yc1) / 2, 0)]
    doorways: list[tuple[float, float, int]] = []
    for r in site.rooms:
        for side, a, c in r.doors:
            m = (a + c) / 2
            if side in ("n", "s"):
                y = r.y1 if side == "n" else r.y0
                doorways += [(m, y + dy, 0) for dy in (-1.0, 0.0, 1.0)]
            elif side == "e":  # "w" doors are the same doorways seen from the other room
                doorways += [(r.x1 + dx, m, 0) for dx in (-1.0, 0.0, 1.0)]
    return tuple(pts + sorted(set(doorways)))


def _layout(rng: np.random.Generator, stations: int, size_m: tuple[float, float] | None) -> _Site:
    """Strips, corridors and rooms (no geometry yet)."""
    H = float(rng.uniform(3.0, 3.6))
    wt, it = float(rng.uniform(0.25, 0.35)), float(rng.uniform(0.12, 0.16))
    cw = float(rng.uniform(2.2, 3.0))
    # strips of ~15 m: about 1.5 times as long as deep
    n_strips = max(1, round(math.sqrt(max(stations, 1) * BUILDING_AREA_PER_STATION_M2 / 360.0)))
    depths = [(float(rng.uniform(5.0, 7.5)), float(rng.uniform(5.0, 7.5))) for _ in range(n_strips)]
    Ly = sum(ds + cw + dn for ds, dn in depths)
    if size_m is None:
        Lx = max(14.0, stations * BUILDING_AREA_PER_STATION_M2 / Ly)
    else:
        Lx, Ly_req = (float(v) for v in size_m)
        if Lx < 12 or Ly_req < 12:
            raise ConfigError(f"building size must be at least 12 x 12 m, got {Lx} x {Ly_req}")
        scale = Ly_req / Ly
        depths = [(ds * scale, dn * scale) for ds, dn in depths]
        Ly = Ly_req
    site = _Site(rng, MeshBuilder(), Lx, Ly, H, wt, it, cw, ob.PLASTER.jitter(rng, 0.05))
    site.corridors.append((0.0, 0.0, cw, Ly))  # the cross corridor along the west wall
    y = 0.0
    kinds = list(_ROOM_KINDS)
    for ds, dn in depths:
        yc0, yc1 = y + ds, y + ds + cw
        site.strips.append((y, yc0, yc1))
        site.corridors.append((cw, yc0, Lx, yc1))
        for ya, yb, side in ((y, yc0, "n"), (yc1, yc1 + dn, "s")):
            for xa, xb in _room_spans(rng, cw, Lx):
                kind = kinds[int(rng.choice(len(kinds), p=[0.45, 0.2, 0.15, 0.2]))]
                r = _Room(xa, ya, xb, yb, kind)
                w = rng.uniform(0.9, 1.2)  # door to the corridor (wall "side" of the room)
                a = rng.uniform(xa + 0.5, max(xa + 0.5, xb - 0.5 - w))
                r.doors.append((side, a, a + w))
                if xb - xa > 7.5 and rng.random() < 0.5:  # a second door at the other end
                    lo, hi = max(a + w + 0.8, xb - 2.0 - w), xb - 0.5 - w
                    if hi > lo:
                        a2 = float(rng.uniform(lo, hi))
                        r.doors.append((side, a2, a2 + w))
                site.rooms.append(r)
        y = yc1 + dn
    return site


def _room_spans(rng: np.random.Generator, x0: float, x1: float) -> list[tuple[float, float]]:
    """Room boundaries along a corridor: widths of 5.5-9.5 m, the last one taking the rest."""
    xs = [x0]
    while x1 - xs[-1] > 9.5 + 5.5:
        xs.append(xs[-1] + float(rng.uniform(5.5, 9.5)))
    if x1 - xs[-1] > 9.5:
        xs.append(xs[-1] + (x1 - xs[-1]) / 2)
    xs.append(x1)
    return list(itertools.pairwise(xs))


def _wall(
    site: _Site,
    a: float,
    c: float,
    line: float,
    along_x: bool,
    openings: list[tuple[float, float, float, float]],
) -> None:
    """Inner wall centred on ``y = line`` (``along_x``) or ``x = line`` from ``a`` to ``c``,
    with openings ``(s0, s1, z0, z1)`` measured from ``a``; extended into the walls it meets."""
    t, e = site.it, site.it / 2
    for lo, hi in wall_boxes(
        c - a + 2 * e, site.H, t, [(s0 + e, s1 + e, z0, z1) for s0, s1, z0, z1 in openings]
    ):
        if along_x:
            site.b.box(
                [a - e + lo[0], line - t / 2, lo[2]],
                [a - e + hi[0], line + t / 2, hi[2]],
                site.wall_mat,
            )
        else:
            site.b.box(
                [line - t / 2, a - e + lo[0], lo[2]],
                [line + t / 2, a - e + hi[0], hi[2]],
                site.wall_mat,
            )
    site.b.count("wall")


def _door_at(
    site: _Site, along_x: bool, line: float, s0: float, s1: float, h: float, *, up: bool = True
) -> None:
    """Casing and an open leaf for a doorway ``[s0, s1]`` in the wall on ``line``; a leaf in a
    wall along x opens towards +y (``up``) or -y."""
    t = site.it
    if along_x and up:
        walls = Walls([(s0 - 1.0, line + t / 2), (s1 + 1.0, line + t / 2)])
    elif along_x:
        walls = Walls([(s1 + 1.0, line - t / 2), (s0 - 1.0, line - t / 2)])
    else:
        walls = Walls([(line - t / 2, s0 - 1.0), (line - t / 2, s1 + 1.0)])
    door(site.b, walls, 0, 1.0, 1.0 + s1 - s0, h, t, site.rng)


def _shell(site: _Site) -> None:
    """Floor and ceiling slabs; outer walls with windows for the rooms behind them, a main
    entrance into the cross corridor and a window at each corridor's east end."""
    rng, b, Lx, Ly, H, wt = site.rng, site.b, site.Lx, site.Ly, site.H, site.wt
    floor_mat = (ob.PARQUET if rng.random() < 0.4 else ob.SCREED).jitter(rng)
    b.box([-wt, -wt, -0.25], [Lx + wt, Ly + wt, 0.0], floor_mat)
    b.box([-wt, -wt, H], [Lx + wt, Ly + wt, H + 0.25], ob.CEILING)
    walls = Walls([(0, 0), (Lx, 0), (Lx, Ly), (0, Ly)])
    sill, top = float(rng.uniform(0.8, 1.0)), min(H - 0.35, float(rng.uniform(2.2, 2.5)))
    spans: list[list[tuple[float, float]]] = [[], [], [], []]  # outer windows per wall (local x)
    for r in site.rooms:
        if r.y0 <= 1e-9:
            spans[0] += _window_spans(rng, r.x0, r.x1)
        if r.y1 >= Ly - 1e-9:
            spans[2] += [(Lx - s1, Lx - s0) for s0, s1 in _window_spans(rng, r.x0, r.x1)]
        if r.x1 >= Lx - 1e-9:
            spans[1] += _window_spans(rng, r.y0, r.y1)
    for _y0, yc0, yc1 in site.strips:
        spans[1].append((yc0 + 0.4, yc1 - 0.4))
    entrance = float(rng.uniform(0.2, 0.8)) * (Ly - 3.0) + 1.0
    site.entrance_y = entrance + 0.9
    for k in range(4):
        openings = [(s0, s1, sill, top) for s0, s1 in sorted(spans[k])]
        if k == 3:
            openings.append((Ly - entrance - 1.8, Ly - entrance, 0.0, 2.3))
        walls.build(b, k, H, wt, openings, site.wall_mat)
        for s0, s1, z0, z1 in openings:
            if z0 > 0:
                window(b, walls, k, s0, s1, z0, z1, wt, rng)
            else:  # the entrance: a frame, the leaves open outwards
                for a, c in ((s0 - 0.08, s0), (s1, s1 + 0.08)):
                    walls.add_local(b, k, box([a, 0, 0], [c, 0.03, z1 + 0.08]), ob.DARK_METAL)
                walls.add_local(b, k, box([s0, 0, z1], [s1, 0.03, z1 + 0.08]), ob.DARK_METAL)
                b.count("entrance")


def _window_spans(rng: np.random.Generator, a: float, c: float) -> list[tuple[float, float]]:
    """One or two windows in the outer wall of a room spanning ``[a, c]``."""
    n = 1 if c - a < 6.5 else int(rng.integers(1, 3))
    out = []
    for i in range(n):
        lo, hi = a + (c - a) * i / n, a + (c - a) * (i + 1) / n
        w = min(hi - lo - 1.0, float(rng.uniform(1.0, 2.2)))
        m = (lo + hi) / 2 + rng.uniform(-0.3, 0.3) * max(0.0, hi - lo - w - 1.0)
        out.append((m - w / 2, m + w / 2))
    return out


def _inner_walls(site: _Site) -> None:
    """Corridor walls with the rooms' doors, walls between rooms (a third with a door to the
    neighbour), the walls between strips and the cross corridor's wall."""
    rng, cw, Lx = site.rng, site.cw, site.Lx
    for si, (_y0, yc0, yc1) in enumerate(site.strips):
        for line, side in ((yc0, "n"), (yc1, "s")):
            rooms = [
                r
                for r in site.rooms
                if side in [d[0] for d in r.doors] and (r.y1 == line or r.y0 == line)
            ]
            spans = sorted((a, c) for r in rooms for s, a, c in r.doors if s == side)
            hs = [float(rng.uniform(2.05, 2.2)) for _ in spans]
            _wall(
                site,
                cw,
                Lx,
                line,
                True,
                [(a - cw, c - cw, 0.0, h) for (a, c), h in zip(spans, hs, strict=True)],
            )
            for (a, c), h in zip(spans, hs, strict=True):  # leaves open into the rooms
                _door_at(site, True, line, a, c, h, up=side == "s")
        y_end = site.strips[si + 1][0] if si + 1 < len(site.strips) else None
        if y_end is not None:  # wall between this strip's north rooms and the next strip
            _wall(site, cw, Lx, y_end, True, [])
    for r in site.rooms:
        if r.x1 < Lx - 1e-9:  # wall to the east neighbour, sometimes with a door
            openings = []
            if rng.random() < 0.35:
                a = float(rng.uniform(r.y0 + 0.6, r.y1 - 1.6))
                openings.append((a - r.y0, a - r.y0 + 0.95, 0.0, 2.05))
                r.doors.append(("e", a, a + 0.95))
                for nb in site.rooms:
                    if nb.y0 == r.y0 and abs(nb.x0 - r.x1) < 1e-9:
                        nb.doors.append(("w", a, a + 0.95))
            _wall(site, r.y0, r.y1, r.x1, False, openings)
            for s0, s1, _z0, z1 in openings:
                _door_at(site, False, r.x1, r.y0 + s0, r.y0 + s1, z1)
    corridor_openings = [(yc0, yc1, 0.0, site.H - 0.3) for _y0, yc0, yc1 in site.strips]
    _wall(site, 0.0, site.Ly, cw, False, corridor_openings)


def _furnish(site: _Site, r: _Room) -> None:
    """Furniture of one room by its kind: shelves and cabinets, table groups with chairs,
    desks, sofas, clutter and plants, pendant lamps; door swings kept clear."""
    rng, b, H = site.rng, site.b, site.H
    g = site.it / 2 + 0.03
    plan = Floorplan(r.x0 + g, r.y0 + g, r.x1 - g, r.y1 - g)
    for side, a, c in r.doors:
        if side in ("n", "s"):
            y = r.y1 if side == "n" else r.y0
            plan.mark([a - 0.4, y - 1.5], [c + 0.4, y + 1.5])
        else:
            x = r.x1 if side == "e" else r.x0
            plan.mark([x - 1.5, a - 0.4], [x + 1.5, c + 0.4])
    n_shelf, n_tables, n_desks, n_sofas, n_clutter = _ROOM_KINDS[r.kind]
    for _ in range(n_shelf + int(rng.integers(0, 2))):
        w, d = rng.uniform(0.8, 2.0), rng.uniform(0.3, 0.45)
        spot = plan.place(rng, w, d, against_wall=True, tries=60)
        if spot is not None:
            h = rng.uniform(1.6, min(2.4, H - 0.3))
            obj = ob.shelf(rng, w, d, h) if rng.random() < 0.65 else ob.cabinet(rng, w, d, h * 0.6)
            put(b, obj, *spot)
    for _ in range(n_tables):
        w, d = rng.uniform(1.2, 2.6), rng.uniform(0.7, 1.1)
        spot = plan.place(rng, w + 1.2, d + 1.2, margin=0.5, tries=60)
        if spot is not None:
            grp = ob.table(rng, w, d)
            ob.desk_items(rng, grp, w, d, 0.74)
            for i in range(int(rng.integers(2, 7))):
                x = (i // 2 - 1) * w / 3 + rng.normal(0, 0.05)
                y = (d / 2 + 0.35) * (1 if i % 2 else -1)
                grp.extend(
                    ob.chair(rng),
                    R=rot_z((np.pi if i % 2 else 0.0) + rng.normal(0, 0.3)),
                    t=[x, y, 0],
                )
            put(b, grp, *spot)
    for _ in range(n_desks + int(rng.integers(0, 2))):
        w, d = rng.uniform(1.2, 1.8), rng.uniform(0.7, 0.85)
        spot = plan.place(rng, w, d + 0.9, against_wall=True, tries=60)
        if spot is not None:
            cx, cy, yaw = spot
            off = rot_z(yaw) @ [0, -0.45, 0]
            put(b, ob.desk(rng, w, d), cx + off[0], cy + off[1], yaw)
    for _ in range(n_sofas):
        spot = plan.place(rng, rng.uniform(1.6, 2.4), 0.95, against_wall=True, tries=60)
        if spot is not None:
            put(b, ob.sofa(rng, rng.uniform(1.6, 2.2)), *spot)
    for _ in range(n_clutter + int(rng.integers(0, 3))):
        u = rng.random()
        obj = ob.plant(rng) if u < 0.3 else (ob.office_chair(rng) if u < 0.4 else ob.clutter(rng))
        spot = plan.place(rng, 0.7, 0.7, margin=0.2, free_yaw=True)
        if spot is not None:
            put(b, obj, *spot)
    for _ in range(int(rng.integers(1, 4))):
        lamp = ob.pendant_lamp(rng, rng.uniform(0.05, max(0.1, min(0.7, H - 2.45))))
        put(b, lamp, rng.uniform(r.x0 + 1, r.x1 - 1), rng.uniform(r.y0 + 1, r.y1 - 1), 0.0, H)
    b.count(f"{r.kind} room")


def _corridor_items(site: _Site) -> None:
    """Lamps every 3-5 m along the corridors; a few plants, bins and cabinets at the walls."""
    rng, b, H = site.rng, site.b, site.H
    for x0, y0, x1, y1 in site.corridors:
        along_x = x1 - x0 >= y1 - y0
        length = (x1 - x0) if along_x else (y1 - y0)
        for s in np.arange(rng.uniform(1.0, 3.0), length - 0.5, rng.uniform(3.0, 5.0)):
            cx, cy = (x0 + s, (y0 + y1) / 2) if along_x else ((x0 + x1) / 2, y0 + s)
            put(b, ob.pendant_lamp(rng, 0.05), cx, cy, 0.0 if along_x else np.pi / 2, H)
        for _ in range(int(rng.integers(0, 1 + int(length // 12)))):
            s = float(rng.uniform(1.0, length - 1.0))
            u = rng.random()
            obj = ob.plant(rng, 0.8) if u < 0.5 else ob.bin_(rng)
            off = (y1 - y0 if along_x else x1 - x0) / 2 - 0.35
            side = 1 if rng.random() < 0.5 else -1
            cx, cy = (
                (x0 + s, (y0 + y1) / 2 + side * off)
                if along_x
                else ((x0 + x1) / 2 + side * off, y0 + s)
            )
            put(b, obj, cx, cy, float(rng.uniform(0, 2 * np.pi)))
