"""The indoor room scene, built in steps that draw from one ``rng`` in a fixed order."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flexreg.errors import ConfigError
from flexreg.synth import objects as ob
from flexreg.synth.mesh import (
    Material,
    MeshBuilder,
    box,
    cylinder,
    rot_z,
    wall_boxes,
)
from flexreg.synth.scene import Scene
from flexreg.synth.scenes._plan import (
    Floorplan,
    Walls,
    door,
    exterior,
    finish,
    intervals,
    put,
    window,
)
from flexreg.synth.seeding import as_rng


@dataclass
class _Room:
    """What the steps of :func:`room` build on: the mesh ``b``, its walls and floor plan, the
    floor size ``Lx`` x ``Ly``, ceiling height ``H`` and wall thickness ``wt`` (metres)."""

    rng: np.random.Generator
    b: MeshBuilder
    walls: Walls
    plan: Floorplan
    Lx: float
    Ly: float
    H: float
    wt: float
    wall_mat: Material


def room(
    rng: np.random.Generator | int | None = None, *, size_m: tuple[float, float] | None = None
) -> Scene:
    """Indoor room of 10-20 m x 8-14 m (or ``size_m``), 3.0-4.2 m high.

    Walls with door and window openings (frames, sills, mullions, open door leaves, radiators
    under windows), skirting boards, an optional partition wall, pillars, ceiling beams and
    lamps, a stair to a landing, tables with chairs and desk items, shelves full of books,
    cabinets, sofas, office chairs, plants and floor clutter. Through the openings the scanner
    sees an exterior ground and neighbouring blocks.
    """
    rng, seed = as_rng(rng)
    site = _shell(rng, size_m)
    wall_openings = _openings(site)
    _partition(site)
    _stairs(site)
    _structure(site)
    _wall_items(site, wall_openings)
    _suspended_ceiling(site)
    _table_groups(site)
    _furniture_by_walls(site)
    _clutter(site)
    exterior(site.b, rng, -site.wt, -site.wt, site.Lx + site.wt, site.Ly + site.wt)
    return finish(site.b, "room", seed, site.Lx, site.Ly, margin_m=0.3)


def _shell(rng: np.random.Generator, size_m: tuple[float, float] | None) -> _Room:
    """Floor size, height and wall thickness; floor and ceiling slabs."""
    if size_m is None:
        Lx, Ly = rng.uniform(10.0, 20.0), rng.uniform(8.0, 14.0)
    else:
        Lx, Ly = (float(v) for v in size_m)
        if Lx < 4 or Ly < 4:
            raise ConfigError(f"room size must be at least 4 x 4 m, got {Lx} x {Ly}")
    H = rng.uniform(3.0, 4.2)
    wt = rng.uniform(0.2, 0.35)
    b = MeshBuilder()
    floor_mat = (ob.PARQUET if rng.random() < 0.5 else ob.SCREED).jitter(rng)
    wall_mat = ob.PLASTER.jitter(rng, 0.05)
    b.box([-wt, -wt, -0.25], [Lx + wt, Ly + wt, 0.0], floor_mat)
    b.box([-wt, -wt, H], [Lx + wt, Ly + wt, H + 0.25], ob.CEILING)
    walls = Walls([(0, 0), (Lx, 0), (Lx, Ly), (0, Ly)])
    plan = Floorplan(0.05, 0.05, Lx - 0.05, Ly - 0.05)
    return _Room(rng, b, walls, plan, Lx, Ly, H, wt, wall_mat)


def _openings(site: _Room) -> list[list[tuple[float, float]]]:
    """One to three doors and two to seven windows spread over the walls, with
    skirting boards and radiators; returns each wall's opening spans ``(x0, x1)``."""
    rng, b, walls, plan, H, wt = site.rng, site.b, site.walls, site.plan, site.H, site.wt
    wall_mat = site.wall_mat
    n_doors, n_windows = int(rng.integers(1, 4)), int(rng.integers(2, 8))
    door_walls = rng.integers(0, 4, size=n_doors)
    win_walls = rng.integers(0, 4, size=n_windows)
    sill = rng.uniform(0.8, 1.0)
    win_top = min(H - 0.35, rng.uniform(2.2, 2.6))
    skirt_mat = ob.WHITE_PAINT.jitter(rng, 0.05)
    wall_openings: list[list[tuple[float, float]]] = []
    for k in range(4):
        L = walls.length(k)
        dw = [rng.uniform(0.9, 1.3) for _ in range(int(np.sum(door_walls == k)))]
        ww = [rng.uniform(0.8, 2.2) for _ in range(int(np.sum(win_walls == k)))]
        spans = intervals(rng, L, dw + ww, margin=0.6, gap=0.5)
        doors: list[tuple[float, float]] = []
        wins: list[tuple[float, float]] = []
        for x0, x1 in spans:
            (doors if any(abs((x1 - x0) - w) < 1e-12 for w in dw) else wins).append((x0, x1))
        openings = [(x0, x1, 0.0, rng.uniform(2.05, 2.25)) for x0, x1 in doors]
        openings += [(x0, x1, sill, win_top) for x0, x1 in wins]
        wall_openings.append([(o[0], o[1]) for o in openings])
        walls.build(b, k, H, wt, openings, wall_mat)
        # skirting board between doors
        edges = [0.0] + [v for d in doors for v in d] + [L]
        for a, c in zip(edges[0::2], edges[1::2], strict=True):
            if c - a > 0.05:
                walls.add_local(b, k, box([a, 0, 0], [c, 0.015, 0.08]), skirt_mat)
        for x0, x1, _z0, z1 in openings[: len(doors)]:
            door(b, walls, k, x0, x1, z1, wt, rng)
            p = walls.to_world(k, np.array([[x0 - 0.1, 0, 0], [x1 + 0.1, x1 - x0 + 0.4, 0]]))
            plan.mark(p.min(axis=0)[:2], p.max(axis=0)[:2])
        for x0, x1 in wins:
            window(b, walls, k, x0, x1, sill, win_top, wt, rng)
            if sill > 0.5 and rng.random() < 0.75:
                rad = ob.radiator(rng, min(x1 - x0, rng.uniform(0.6, 1.6)), sill - 0.35)
                walls.extend_local(b, k, rad, t=[(x0 + x1) / 2, 0.04, 0])
                p = walls.to_world(k, np.array([[x0, 0, 0], [x1, 0.2, 0]]))
                plan.mark(p.min(axis=0)[:2], p.max(axis=0)[:2])
    return wall_openings


def _partition(site: _Room) -> None:
    """A partition wall with a doorway (60 % of rooms)."""
    rng, b, plan, Lx, Ly, H = site.rng, site.b, site.plan, site.Lx, site.Ly, site.H
    wall_mat = site.wall_mat
    if rng.random() < 0.6:
        along_x = rng.random() < 0.5
        span = Lx if along_x else Ly
        other = Ly if along_x else Lx
        pos = rng.uniform(0.35, 0.65) * other
        length = rng.uniform(0.35, 0.65) * span
        from_start = rng.random() < 0.5
        t = 0.12
        a = 0.0 if from_start else span - length
        dx0 = rng.uniform(0.5, max(0.6, length - 1.5))
        openings = [(dx0, dx0 + 1.0, 0.0, 2.1)] if length > 2.5 else []
        for lo, hi in wall_boxes(length, H, t, openings):
            if along_x:
                b.box([a + lo[0], pos + lo[1], lo[2]], [a + hi[0], pos + hi[1], hi[2]], wall_mat)
            else:
                b.box([pos + lo[1], a + lo[0], lo[2]], [pos + hi[1], a + hi[0], hi[2]], wall_mat)
        b.count("partition wall")
        if along_x:
            plan.mark([a - 0.3, pos - 0.3], [a + length + 0.3, pos + t + 0.3])
        else:
            plan.mark([pos - 0.3, a - 0.3], [pos + t + 0.3, a + length + 0.3])


def _stairs(site: _Room) -> None:
    """A stair to a landing, along a wall."""
    rng, b, walls, plan, H = site.rng, site.b, site.walls, site.plan, site.H
    rise = rng.uniform(0.6, min(2.0, H - 2.1))
    if rng.random() < 0.8 and rise > 0.5:
        sw = rng.uniform(0.9, 1.3)
        st, run_len = ob.stairs(rng, sw, rise)
        for _ in range(30):
            k = int(rng.integers(4))
            L = walls.length(k)
            if L < run_len + 1.0:
                continue
            s0 = rng.uniform(0.3, L - run_len - 0.3)
            foot = walls.to_world(k, np.array([[s0, 0, 0], [s0 + run_len, sw + 0.05, 0]]))
            lo, hi = foot.min(axis=0)[:2], foot.max(axis=0)[:2]
            if plan.is_free(
                np.maximum(lo - 0.2, [plan.x0, plan.y0]), np.minimum(hi + 0.2, [plan.x1, plan.y1])
            ):
                walls.extend_local(b, k, st, yaw=-np.pi / 2, t=[s0, sw / 2 + 0.02, 0])
                plan.mark(lo - 0.2, hi + 0.6)
                break


def _structure(site: _Room) -> None:
    """Pillars, ceiling beams, a duct on hangers and pendant lamps."""
    rng, b, plan, Lx, Ly, H = site.rng, site.b, site.plan, site.Lx, site.Ly, site.H
    for _ in range(int(rng.integers(0, 4))):
        s = rng.uniform(0.3, 0.5)
        spot = plan.place(rng, s, s, margin=1.0)
        if spot is None:
            continue
        cx, cy, _ = spot
        mat = ob.CONCRETE.jitter(rng)
        if rng.random() < 0.5:
            b.box([cx - s / 2, cy - s / 2, 0], [cx + s / 2, cy + s / 2, H], mat)
            b.box(
                [cx - s / 2 - 0.05, cy - s / 2 - 0.05, H - 0.15],
                [cx + s / 2 + 0.05, cy + s / 2 + 0.05, H],
                mat,
            )
        else:
            b.add(cylinder([cx, cy, 0], [cx, cy, H], s / 2, segments=24), mat)
            b.add(cylinder([cx, cy, 0], [cx, cy, 0.1], s / 2 + 0.04, segments=24), mat)
        b.count("pillar")
    for _ in range(int(rng.integers(0, 4))):
        bw, bh = rng.uniform(0.2, 0.4), rng.uniform(0.25, 0.5)
        if rng.random() < 0.5:
            y = rng.uniform(1.0, Ly - 1.0)
            b.box([0, y - bw / 2, H - bh], [Lx, y + bw / 2, H], ob.CONCRETE)
        else:
            x = rng.uniform(1.0, Lx - 1.0)
            b.box([x - bw / 2, 0, H - bh], [x + bw / 2, Ly, H], ob.CONCRETE)
        b.count("ceiling beam")
    if rng.random() < 0.5:  # a duct along one wall, on hangers
        r = rng.uniform(0.12, 0.25)
        y = rng.uniform(0.5, 1.2)
        b.add(cylinder([0.0, y, H - 0.35 - r], [Lx, y, H - 0.35 - r], r, segments=20), ob.METAL)
        for x in np.arange(1.0, Lx, rng.uniform(1.5, 2.5)):
            b.add(cylinder([x, y, H - 0.35], [x, y, H], 0.01, segments=4), ob.DARK_METAL)
        b.count("duct")
    n_l = int(rng.integers(4, 11))
    for _ in range(n_l):
        lamp = ob.pendant_lamp(rng, rng.uniform(0.05, max(0.1, min(0.9, H - 2.45))))
        put(
            b,
            lamp,
            rng.uniform(1.0, Lx - 1.0),
            rng.uniform(1.0, Ly - 1.0),
            rng.uniform(0, np.pi),
            H,
        )


def _wall_items(site: _Room, wall_openings: list[list[tuple[float, float]]]) -> None:
    """Things on the walls, placed before furniture (which may stand below them)."""
    rng, b, walls = site.rng, site.b, site.walls
    for k in range(4):
        L = walls.length(k)
        used = list(wall_openings[k])
        for _ in range(int(rng.integers(2, 7))):
            item, w, _z0, _z1 = ob.wall_item(rng)
            for _ in range(10):
                x = rng.uniform(0.3 + w / 2, max(0.3 + w / 2, L - 0.3 - w / 2))
                if all(x + w / 2 + 0.15 < a or x - w / 2 - 0.15 > c for a, c in used):
                    walls.extend_local(b, k, item, t=[x, 0.0, 0.0])
                    used.append((x - w / 2, x + w / 2))
                    break


def _suspended_ceiling(site: _Room) -> None:
    """A suspended ceiling grid (T-bars) with light panels (40 % of rooms)."""
    rng, b, Lx, Ly, H = site.rng, site.b, site.Lx, site.Ly, site.H
    if rng.random() < 0.4:  # suspended ceiling grid (T-bars) with light panels
        hc = H - rng.uniform(0.2, 0.4)
        pitch = 0.6
        for x in np.arange(pitch, Lx, pitch):
            b.box([x - 0.012, 0, hc - 0.03], [x + 0.012, Ly, hc], ob.WHITE_PAINT)
        for y in np.arange(pitch, Ly, pitch):
            b.box([0, y - 0.012, hc - 0.03], [Lx, y + 0.012, hc], ob.WHITE_PAINT)
        b.box([0, 0, hc], [Lx, Ly, hc + 0.02], ob.CEILING)
        b.count("suspended ceiling")


def _table_groups(site: _Room) -> None:
    """Tables with chairs and desk items."""
    rng, b, plan = site.rng, site.b, site.plan
    for _ in range(int(rng.integers(2, 6))):  # table groups
        w, d = rng.uniform(1.2, 2.4), rng.uniform(0.7, 1.1)
        spot = plan.place(rng, w + 1.2, d + 1.2, margin=0.4, tries=80)
        if spot is None:
            continue
        cx, cy, yaw = spot
        grp = MeshBuilder()
        tb = ob.table(rng, w, d)
        grp.extend(tb)
        ob.desk_items(rng, grp, w, d, 0.74)
        n_ch = int(rng.integers(1, 7))
        seats = [(x, -d / 2 - 0.3, 0.0) for x in np.linspace(-w / 3, w / 3, 2)]
        seats += [(x, d / 2 + 0.3, np.pi) for x in np.linspace(-w / 3, w / 3, 2)]
        seats += [(-w / 2 - 0.3, 0.0, -np.pi / 2), (w / 2 + 0.3, 0.0, np.pi / 2)]
        for i in rng.permutation(len(seats))[:n_ch]:
            x, y, a = seats[i]
            ch = ob.chair(rng) if rng.random() < 0.7 else ob.office_chair(rng)
            grp.extend(
                ch,
                R=rot_z(a + rng.normal(0, 0.25)),
                t=[x + rng.normal(0, 0.05), y + rng.normal(0, 0.05), 0],
            )
        put(b, grp, cx, cy, yaw)


def _furniture_by_walls(site: _Room) -> None:
    """Desks (chair space in front), shelves, cabinets and sofas with a low table."""
    rng, b, plan, H = site.rng, site.b, site.plan, site.H
    for _ in range(int(rng.integers(1, 6))):  # desks against walls, chair in front
        w, d = rng.uniform(1.2, 1.8), rng.uniform(0.7, 0.85)
        spot = plan.place(rng, w, d + 0.9, against_wall=True, tries=80)
        if spot is not None:
            cx, cy, yaw = spot
            off = rot_z(yaw) @ [0, -0.45, 0]
            put(b, ob.desk(rng, w, d), cx + off[0], cy + off[1], yaw)
    for _ in range(int(rng.integers(3, 10))):  # shelves and cabinets against walls
        w, d = rng.uniform(0.8, 2.0), rng.uniform(0.3, 0.45)
        spot = plan.place(rng, w, d, against_wall=True, tries=80)
        if spot is None:
            continue
        cx, cy, yaw = spot
        h = rng.uniform(1.6, min(2.4, H - 0.3))
        obj = (
            ob.shelf(rng, w, d, h)
            if rng.random() < 0.65
            else ob.cabinet(rng, w, d, rng.uniform(0.8, h))
        )
        put(b, obj, cx, cy, yaw)
    for _ in range(int(rng.integers(0, 3))):  # sofas with a low table
        w = rng.uniform(1.6, 2.6)
        spot = plan.place(rng, w, 0.95, against_wall=rng.random() < 0.6, tries=80)
        if spot is not None:
            put(b, ob.sofa(rng, w), *spot)
            cx, cy, yaw = spot
            off = rot_z(yaw) @ [0, 1.0, 0]
            lt = ob.table(rng, w * 0.5, 0.5, rng.uniform(0.35, 0.45))
            if plan.is_free(
                [cx + off[0] - 0.5, cy + off[1] - 0.5], [cx + off[0] + 0.5, cy + off[1] + 0.5]
            ):
                put(b, lt, cx + off[0], cy + off[1], yaw)


def _clutter(site: _Room) -> None:
    """Clutter, plants and lone chairs."""
    rng, b, plan = site.rng, site.b, site.plan
    for _ in range(int(rng.integers(8, 24))):  # clutter, plants, lone chairs
        u = rng.random()
        obj = ob.plant(rng) if u < 0.25 else (ob.office_chair(rng) if u < 0.35 else ob.clutter(rng))
        spot = plan.place(rng, 0.7, 0.7, margin=0.15, free_yaw=True)
        if spot is not None:
            put(b, obj, *spot)
