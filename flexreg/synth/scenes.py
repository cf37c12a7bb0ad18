"""Seeded procedural scenes: an indoor room, an outdoor courtyard/street, an industrial hall.

Every generator draws all its randomness from one ``rng`` in a fixed order, so the same seed
gives the same mesh bit for bit, and different seeds give different layouts. Geometry spans
the scales a surveyor sees: walls and facades (metres), furniture, cars and machines
(decimetres), radiator fins, book spines, railings, kerbs and ladder rungs (centimetres).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from itertools import pairwise
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.errors import ConfigError, InputError
from flexreg.synth import objects as ob
from flexreg.synth.mesh import (
    Material,
    MeshBuilder,
    box,
    cylinder,
    ellipsoid,
    rot_z,
    tube,
    wall_boxes,
)
from flexreg.synth.scene import Scene

SCENE_KINDS = ("room", "courtyard", "hall")


def as_rng(rng: np.random.Generator | int | None) -> tuple[np.random.Generator, int | None]:
    """Return ``(generator, seed or None)`` for an ``rng`` argument (Generator, int or None)."""
    if isinstance(rng, np.random.Generator):
        return rng, None
    if rng is None:
        return np.random.default_rng(), None
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool) and int(rng) >= 0:
        return np.random.default_rng(int(rng)), int(rng)
    raise ConfigError(
        f"rng must be a numpy Generator, a non-negative int seed or None, got {rng!r}"
    )


class _Floorplan:
    """Occupancy grid of the floor (10 cm cells) to keep objects from overlapping."""

    def __init__(self, x0: float, y0: float, x1: float, y1: float, cell: float = 0.1) -> None:
        self.x0, self.y0, self.x1, self.y1, self.cell = x0, y0, x1, y1, cell
        self.occ = np.zeros((math.ceil((y1 - y0) / cell), math.ceil((x1 - x0) / cell)), dtype=bool)

    def _slices(self, lo: NDArray[np.float64], hi: NDArray[np.float64]) -> tuple[slice, slice]:
        i0 = max(0, math.floor((lo[1] - self.y0) / self.cell))
        i1 = min(self.occ.shape[0], math.ceil((hi[1] - self.y0) / self.cell))
        j0 = max(0, math.floor((lo[0] - self.x0) / self.cell))
        j1 = min(self.occ.shape[1], math.ceil((hi[0] - self.x0) / self.cell))
        return slice(i0, max(i0, i1)), slice(j0, max(j0, j1))

    def is_free(self, lo: Any, hi: Any) -> bool:
        lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
        if lo[0] < self.x0 or lo[1] < self.y0 or hi[0] > self.x1 or hi[1] > self.y1:
            return False
        return not bool(self.occ[self._slices(lo, hi)].any())

    def mark(self, lo: Any, hi: Any) -> None:
        self.occ[self._slices(np.asarray(lo, dtype=float), np.asarray(hi, dtype=float))] = True

    def place(
        self,
        rng: np.random.Generator,
        w: float,
        d: float,
        *,
        margin: float = 0.3,
        against_wall: bool = False,
        wall_gap: float = 0.02,
        free_yaw: bool = False,
        tries: int = 60,
    ) -> tuple[float, float, float] | None:
        """Find a free spot for a ``w x d`` footprint; return ``(cx, cy, yaw)`` and mark it.

        ``against_wall`` puts the object's back (-y) against one of the four region sides.
        """
        for _ in range(tries):
            if against_wall:
                side = int(rng.integers(4))
                yaw = (0.0, np.pi / 2, np.pi, -np.pi / 2)[side]
                if side in (0, 2):
                    cx = rng.uniform(self.x0 + w / 2, max(self.x0 + w / 2, self.x1 - w / 2))
                    cy = self.y0 + wall_gap + d / 2 if side == 0 else self.y1 - wall_gap - d / 2
                else:
                    cy = rng.uniform(self.y0 + w / 2, max(self.y0 + w / 2, self.y1 - w / 2))
                    cx = self.x1 - wall_gap - d / 2 if side == 1 else self.x0 + wall_gap + d / 2
            else:
                yaw = (
                    rng.uniform(-np.pi, np.pi)
                    if free_yaw
                    else (rng.integers(4) * np.pi / 2 + rng.normal(0.0, 0.08))
                )
                cx = rng.uniform(self.x0, self.x1)
                cy = rng.uniform(self.y0, self.y1)
            c, s = abs(math.cos(yaw)), abs(math.sin(yaw))
            hx, hy = c * w / 2 + s * d / 2, s * w / 2 + c * d / 2
            lo, hi = np.array([cx - hx, cy - hy]), np.array([cx + hx, cy + hy])
            chk_lo, chk_hi = lo - margin, hi + margin
            if against_wall:  # the wall side may touch the region edge
                chk_lo = np.maximum(chk_lo, [self.x0, self.y0])
                chk_hi = np.minimum(chk_hi, [self.x1, self.y1])
            if (
                lo[0] >= self.x0 - 1e-9
                and lo[1] >= self.y0 - 1e-9
                and hi[0] <= self.x1 + 1e-9
                and hi[1] <= self.y1 + 1e-9
                and self.is_free(chk_lo, chk_hi)
            ):
                self.mark(lo, hi)
                return float(cx), float(cy), float(yaw)
        return None


def _put(
    b: MeshBuilder, obj: MeshBuilder, cx: float, cy: float, yaw: float, z: float = 0.0
) -> None:
    b.extend(obj, R=rot_z(yaw), t=[cx, cy, z])


def _intervals(
    rng: np.random.Generator,
    length: float,
    widths: list[float],
    *,
    margin: float = 0.4,
    gap: float = 0.4,
) -> list[tuple[float, float]]:
    """Place 1D intervals of the given widths on ``[margin, length - margin]`` without overlap."""
    out: list[tuple[float, float]] = []
    for w in widths:
        for _ in range(30):
            x0 = rng.uniform(margin, length - margin - w) if length - 2 * margin > w else -1.0
            if x0 < 0:
                break
            if all(x0 + w + gap <= a or x0 >= b_ + gap for a, b_ in out):
                out.append((x0, x0 + w))
                break
    return sorted(out)


class _Walls:
    """Walls along a counter-clockwise polygon; wall ``k`` runs from corner ``k`` to ``k+1`` with
    its local frame: x along the wall, +y into the enclosed space, z up."""

    def __init__(self, corners: list[tuple[float, float]], z0: float = 0.0) -> None:
        self.c = np.asarray(corners, dtype=np.float64)
        self.z0 = z0

    def __len__(self) -> int:
        return len(self.c)

    def length(self, k: int) -> float:
        return float(np.linalg.norm(self.c[(k + 1) % len(self.c)] - self.c[k]))

    def pose(self, k: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        d = self.c[(k + 1) % len(self.c)] - self.c[k]
        return rot_z(math.atan2(d[1], d[0])), np.array([self.c[k][0], self.c[k][1], self.z0])

    def add_local(
        self,
        b: MeshBuilder,
        k: int,
        mesh: Any,
        mat: Material,
        R: NDArray[np.float64] | None = None,
        t: Any = (0.0, 0.0, 0.0),
    ) -> None:
        Rw, tw = self.pose(k)
        Rl = np.eye(3) if R is None else R
        b.add(mesh, mat, R=Rw @ Rl, t=Rw @ np.asarray(t, dtype=np.float64) + tw)

    def extend_local(
        self, b: MeshBuilder, k: int, obj: MeshBuilder, yaw: float = 0.0, t: Any = (0.0, 0.0, 0.0)
    ) -> None:
        Rw, tw = self.pose(k)
        b.extend(obj, R=Rw @ rot_z(yaw), t=Rw @ np.asarray(t, dtype=np.float64) + tw)

    def to_world(self, k: int, p: Any) -> NDArray[np.float64]:
        Rw, tw = self.pose(k)
        return np.asarray(p, dtype=np.float64) @ Rw.T + tw

    def build(
        self,
        b: MeshBuilder,
        k: int,
        height: float,
        thickness: float,
        openings: list[tuple[float, float, float, float]],
        mat: Material,
    ) -> None:
        """Solid wall ``k`` (extended by ``thickness`` past both corners) with openings."""
        L = self.length(k)
        shifted = [(x0 + thickness, x1 + thickness, z0, z1) for x0, x1, z0, z1 in openings]
        for lo, hi in wall_boxes(L + 2 * thickness, height, thickness, shifted):
            self.add_local(
                b, k, box(lo - [thickness, thickness, 0], hi - [thickness, thickness, 0]), mat
            )
        b.count("wall")


# ==================================================================================== room
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
    walls = _Walls([(0, 0), (Lx, 0), (Lx, Ly), (0, Ly)])
    plan = _Floorplan(0.05, 0.05, Lx - 0.05, Ly - 0.05)

    # ---- openings: one to three doors, two to seven windows, spread over the walls
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
        spans = _intervals(rng, L, dw + ww, margin=0.6, gap=0.5)
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
            _door(b, walls, k, x0, x1, z1, wt, rng)
            p = walls.to_world(k, np.array([[x0 - 0.1, 0, 0], [x1 + 0.1, x1 - x0 + 0.4, 0]]))
            plan.mark(p.min(axis=0)[:2], p.max(axis=0)[:2])
        for x0, x1 in wins:
            _window(b, walls, k, x0, x1, sill, win_top, wt, rng)
            if sill > 0.5 and rng.random() < 0.75:
                rad = ob.radiator(rng, min(x1 - x0, rng.uniform(0.6, 1.6)), sill - 0.35)
                walls.extend_local(b, k, rad, t=[(x0 + x1) / 2, 0.04, 0])
                p = walls.to_world(k, np.array([[x0, 0, 0], [x1, 0.2, 0]]))
                plan.mark(p.min(axis=0)[:2], p.max(axis=0)[:2])

    # ---- partition wall with a doorway
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

    # ---- stairs to a landing, along a wall
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

    # ---- pillars and ceiling structure
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
        _put(
            b,
            lamp,
            rng.uniform(1.0, Lx - 1.0),
            rng.uniform(1.0, Ly - 1.0),
            rng.uniform(0, np.pi),
            H,
        )

    # ---- things on the walls (placed before furniture; furniture may stand below them)
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
    if rng.random() < 0.4:  # suspended ceiling grid (T-bars) with light panels
        hc = H - rng.uniform(0.2, 0.4)
        pitch = 0.6
        for x in np.arange(pitch, Lx, pitch):
            b.box([x - 0.012, 0, hc - 0.03], [x + 0.012, Ly, hc], ob.WHITE_PAINT)
        for y in np.arange(pitch, Ly, pitch):
            b.box([0, y - 0.012, hc - 0.03], [Lx, y + 0.012, hc], ob.WHITE_PAINT)
        b.box([0, 0, hc], [Lx, Ly, hc + 0.02], ob.CEILING)
        b.count("suspended ceiling")

    # ---- furniture
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
        _put(b, grp, cx, cy, yaw)
    for _ in range(int(rng.integers(1, 6))):  # desks against walls, chair in front
        w, d = rng.uniform(1.2, 1.8), rng.uniform(0.7, 0.85)
        spot = plan.place(rng, w, d + 0.9, against_wall=True, tries=80)
        if spot is not None:
            cx, cy, yaw = spot
            off = rot_z(yaw) @ [0, -0.45, 0]
            _put(b, ob.desk(rng, w, d), cx + off[0], cy + off[1], yaw)
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
        _put(b, obj, cx, cy, yaw)
    for _ in range(int(rng.integers(0, 3))):  # sofas with a low table
        w = rng.uniform(1.6, 2.6)
        spot = plan.place(rng, w, 0.95, against_wall=rng.random() < 0.6, tries=80)
        if spot is not None:
            _put(b, ob.sofa(rng, w), *spot)
            cx, cy, yaw = spot
            off = rot_z(yaw) @ [0, 1.0, 0]
            lt = ob.table(rng, w * 0.5, 0.5, rng.uniform(0.35, 0.45))
            if plan.is_free(
                [cx + off[0] - 0.5, cy + off[1] - 0.5], [cx + off[0] + 0.5, cy + off[1] + 0.5]
            ):
                _put(b, lt, cx + off[0], cy + off[1], yaw)
    for _ in range(int(rng.integers(8, 24))):  # clutter, plants, lone chairs
        u = rng.random()
        obj = ob.plant(rng) if u < 0.25 else (ob.office_chair(rng) if u < 0.35 else ob.clutter(rng))
        spot = plan.place(rng, 0.7, 0.7, margin=0.15, free_yaw=True)
        if spot is not None:
            _put(b, obj, *spot)

    _exterior(b, rng, -wt, -wt, Lx + wt, Ly + wt)
    return _finish(b, "room", seed, Lx, Ly, margin_m=0.3)


def _door(
    b: MeshBuilder,
    walls: _Walls,
    k: int,
    x0: float,
    x1: float,
    h: float,
    wt: float,
    rng: np.random.Generator,
) -> None:
    """Door casing on the inner face and a door leaf opened into the room."""
    frame = ob.WHITE_PAINT.jitter(rng, 0.05)
    cw = rng.uniform(0.05, 0.09)
    walls.add_local(b, k, box([x0 - cw, 0, 0], [x0, 0.02, h + cw]), frame)
    walls.add_local(b, k, box([x1, 0, 0], [x1 + cw, 0.02, h + cw]), frame)
    walls.add_local(b, k, box([x0, 0, h], [x1, 0.02, h + cw]), frame)
    if rng.random() < 0.8:
        a = rng.uniform(0.3, 1.9)
        leaf = MeshBuilder()
        w = x1 - x0 - 0.01
        mat = (ob.WOOD if rng.random() < 0.5 else ob.WHITE_PAINT).jitter(rng)
        leaf.box([0.0, 0.0, 0.01], [w, 0.04, h - 0.01], mat)
        leaf.add(cylinder([w - 0.08, 0.04, 1.0], [w - 0.08, 0.1, 1.0], 0.01, segments=6), ob.CHROME)
        leaf.add(cylinder([w - 0.16, 0.1, 1.0], [w - 0.06, 0.1, 1.0], 0.01, segments=6), ob.CHROME)
        walls.extend_local(b, k, leaf, yaw=a, t=[x0, 0.0, 0.0])
    b.count("door")


def _window(
    b: MeshBuilder,
    walls: _Walls,
    k: int,
    x0: float,
    x1: float,
    z0: float,
    z1: float,
    wt: float,
    rng: np.random.Generator,
) -> None:
    """Sill, frame and mullions inside a window opening (no glass: lasers mostly pass)."""
    frame = (ob.WHITE_PAINT if rng.random() < 0.7 else ob.DARK_METAL).jitter(rng, 0.05)
    walls.add_local(b, k, box([x0 - 0.05, -0.02, z0 - 0.03], [x1 + 0.05, 0.06, z0]), ob.GRANITE)
    yc = -wt * rng.uniform(0.3, 0.7)
    fw = 0.05
    for xa, xb in ((x0, x0 + fw), (x1 - fw, x1)):
        walls.add_local(b, k, box([xa, yc - 0.03, z0], [xb, yc + 0.03, z1]), frame)
    for za, zb in ((z0, z0 + fw), (z1 - fw, z1)):
        walls.add_local(b, k, box([x0, yc - 0.03, za], [x1, yc + 0.03, zb]), frame)
    n = max(1, round((x1 - x0) / rng.uniform(0.6, 1.0)))
    for i in range(1, n):
        x = x0 + i * (x1 - x0) / n
        walls.add_local(b, k, box([x - 0.025, yc - 0.03, z0], [x + 0.025, yc + 0.03, z1]), frame)
    if rng.random() < 0.5:
        zt = z0 + rng.uniform(0.6, 0.8) * (z1 - z0)
        walls.add_local(b, k, box([x0, yc - 0.03, zt - 0.025], [x1, yc + 0.03, zt + 0.025]), frame)
    b.count("window")


def _exterior(
    b: MeshBuilder, rng: np.random.Generator, x0: float, y0: float, x1: float, y1: float
) -> None:
    """Ground and a few neighbouring blocks and trees outside an enclosed building."""
    b.box([x0 - 40, y0 - 40, -0.6], [x1 + 40, y1 + 40, -0.35], ob.PAVING.jitter(rng))
    for _ in range(int(rng.integers(3, 7))):
        a = rng.uniform(-np.pi, np.pi)
        dist = rng.uniform(6, 25)
        cx = (x0 + x1) / 2 + math.cos(a) * ((x1 - x0) / 2 + dist)
        cy = (y0 + y1) / 2 + math.sin(a) * ((y1 - y0) / 2 + dist)
        if rng.random() < 0.5:
            w, d, h = rng.uniform(4, 15), rng.uniform(4, 15), rng.uniform(3, 15)
            b.add(
                box([-w / 2, -d / 2, -0.35], [w / 2, d / 2, h]),
                ob.RENDER.jitter(rng, 0.2),
                R=rot_z(rng.uniform(0, np.pi)),
                t=[cx, cy, 0],
            )
        else:
            _put(b, ob.tree(rng), cx, cy, rng.uniform(0, 2 * np.pi), -0.35)


# ==================================================================================== courtyard
def courtyard(
    rng: np.random.Generator | int | None = None, *, size_m: tuple[float, float] | None = None
) -> Scene:
    """Outdoor street/courtyard of 30-60 m x 22-40 m (or ``size_m``) between building facades.

    A road with kerbs, sidewalks and markings runs along x; buildings of 2-6 floors line both
    sides (window recesses with sills and mullions, shop fronts, doors, balconies with railings,
    cornices at every floor, drainpipes), with alleys between some of them; one end is closed by
    a cross building. Street lamps, trees, benches, parked cars, bollards, signs, bins, bike
    stands, planters and a shelter furnish the street.
    """
    rng, seed = as_rng(rng)
    if size_m is None:
        Lx, Ly = rng.uniform(30.0, 60.0), rng.uniform(22.0, 40.0)
    else:
        Lx, Ly = (float(v) for v in size_m)
        if Lx < 15 or Ly < 14:
            raise ConfigError(f"courtyard size must be at least 15 x 14 m, got {Lx} x {Ly}")
    b = MeshBuilder()
    road_w = rng.uniform(6.0, 8.5)
    yr0 = rng.uniform(0.35, 0.65) * (Ly - road_w)
    yr1 = yr0 + road_w
    kerb = rng.uniform(0.12, 0.16)
    ext = 40.0
    pav = ob.PAVING.jitter(rng)
    b.box([-ext, -ext, -0.5], [Lx + ext, yr0 - 0.15, 0.0], pav)
    b.box([-ext, yr1 + 0.15, -0.5], [Lx + ext, Ly + ext, 0.0], pav)
    b.box([-ext, yr0, -0.5], [Lx + ext, yr1, -kerb], ob.ASPHALT.jitter(rng))
    b.box([-ext, yr0 - 0.15, -0.5], [Lx + ext, yr0, 0.0], ob.GRANITE)  # kerb stones
    b.box([-ext, yr1, -0.5], [Lx + ext, yr1 + 0.15, 0.0], ob.GRANITE)
    b.count("kerb", 2)
    # road markings: centre dashes, edge lines, a crossing
    yc = (yr0 + yr1) / 2
    dash = rng.uniform(2.0, 3.5)
    for x in np.arange(-ext + rng.uniform(0, 3), Lx + ext - dash, dash * 2.2):
        b.box([x, yc - 0.06, -kerb], [x + dash, yc + 0.06, -kerb + 0.004], ob.MARKING)
    xc = rng.uniform(0.2, 0.8) * Lx
    for y in np.arange(yr0 + 0.3, yr1 - 0.4, 0.9):
        b.box([xc - 2.0, y, -kerb], [xc + 2.0, y + 0.5, -kerb + 0.004], ob.MARKING)
    b.count("road marking")
    for _ in range(int(rng.integers(1, 4))):  # manhole covers
        x, y = rng.uniform(0, Lx), rng.uniform(yr0 + 0.8, yr1 - 0.8)
        b.add(
            cylinder([x, y, -kerb - 0.01], [x, y, -kerb + 0.008], 0.32, segments=20), ob.DARK_METAL
        )

    plan = _Floorplan(0.0, 0.0, Lx, Ly)
    plan.mark([0, yr0 - 0.15], [Lx, yr1 + 0.15])  # keep the road free of street furniture
    # ---- buildings: south row faces +y at y = 0, north row faces -y at y = Ly
    for side in (0, 1):
        x = rng.uniform(-15, -2)
        while x < Lx + 10:
            w = rng.uniform(8.0, 22.0)
            depth = rng.uniform(8.0, 14.0)
            if side == 0:
                _building(b, rng, origin=(x, 0.0), yaw=0.0, width=w, depth=depth)
            else:
                _building(b, rng, origin=(x + w, Ly), yaw=np.pi, width=w, depth=depth)
            x += w + (rng.uniform(2.0, 5.0) if rng.random() < 0.35 else 0.0)
    if rng.random() < 0.7:  # cross building closing the east end over the road
        w = Ly + 10.0
        _building(
            b,
            rng,
            origin=(Lx + 0.5, -5.0),
            yaw=np.pi / 2,
            width=w,
            depth=rng.uniform(8, 12),
            gate=(yr0 + 5.0 - 0.5, yr1 + 5.0 + 0.5),
        )

    # ---- street furniture on both sidewalks
    walks = [(0.0, yr0 - 0.15), (yr1 + 0.15, Ly)]

    def sidewalk_spot(
        w: float, d: float, *, kerb_side: bool, face_road: bool
    ) -> tuple[float, float, float] | None:
        for _ in range(40):
            s = int(rng.integers(2))
            a, c = walks[s]
            if c - a < d + 0.6:
                continue
            x = rng.uniform(1.0, Lx - 1.0)
            if kerb_side:
                half = max(w, d) / 2
                y = c - 0.35 - half if s == 0 else a + 0.35 + half
            else:
                y = rng.uniform(a + 1.5 + d / 2, max(a + 1.5 + d / 2, c - 1.2 - d / 2))
            yaw = (0.0 if s == 0 else np.pi) if face_road else rng.uniform(-np.pi, np.pi)
            lo = np.array([x - max(w, d) / 2, y - max(w, d) / 2])
            hi = lo + max(w, d)
            if plan.is_free(lo - 0.3, hi + 0.3):
                plan.mark(lo, hi)
                return x, y, yaw
        return None

    for x in np.arange(rng.uniform(2, 8), Lx, rng.uniform(12, 20)):  # lamps alternate sides
        s = int(rng.integers(2))
        y = walks[s][1] - 0.45 if s == 0 else walks[s][0] + 0.45
        _put(b, ob.street_lamp(rng), x + rng.normal(0, 1.0), y, np.pi if s == 0 else 0.0)
        plan.mark([x - 0.5, y - 0.5], [x + 0.5, y + 0.5])
    for _ in range(int(rng.integers(4, 13))):
        spot = sidewalk_spot(1.0, 1.0, kerb_side=rng.random() < 0.6, face_road=False)
        if spot is not None:
            x, y, yaw = spot
            b.box([x - 0.7, y - 0.7, 0.0], [x + 0.7, y + 0.7, 0.02], ob.DARK_METAL)  # tree grate
            _put(b, ob.tree(rng), x, y, yaw, 0.0)
            plan.mark([x - 1.5, y - 1.5], [x + 1.5, y + 1.5])
    makers: list[tuple[Callable[[np.random.Generator], MeshBuilder], float, int, int, bool]] = [
        (ob.bench, 2.2, 3, 8, False),
        (ob.bollard, 0.3, 6, 20, True),
        (ob.sign_post, 0.8, 2, 6, True),
        (ob.bin_, 0.8, 2, 7, False),
        (ob.bike_stand, 3.0, 0, 4, False),
        (ob.planter, 2.0, 1, 6, False),
        (ob.shelter, 4.5, 0, 2, True),
        (ob.fence, 4.0, 0, 4, False),
        (ob.kiosk, 3.0, 0, 2, False),
    ]
    for make, size, lo_n, hi_n, kerb_side in makers:
        for _ in range(int(rng.integers(lo_n, hi_n + 1))):
            spot = sidewalk_spot(size, size * 0.5, kerb_side=kerb_side, face_road=True)
            if spot is not None:
                _put(b, make(rng), *spot)
    # parked cars along both road edges
    for s in (0, 1):
        x = rng.uniform(-5, 3)
        while x < Lx + 5:
            if rng.random() < 0.6 and abs(x - xc) > 4:
                c = ob.car(rng)
                y = yr0 + 1.1 if s == 0 else yr1 - 1.1
                _put(
                    b,
                    c,
                    x + 2.4,
                    y + rng.normal(0, 0.1),
                    (0.0 if s == 0 else np.pi) + rng.normal(0, 0.03),
                    -kerb,
                )
            x += rng.uniform(5.2, 7.5)

    return _finish(b, "courtyard", seed, Lx, Ly, margin_m=0.5)


def _building(
    b: MeshBuilder,
    rng: np.random.Generator,
    *,
    origin: tuple[float, float],
    yaw: float,
    width: float,
    depth: float,
    gate: tuple[float, float] | None = None,
) -> None:
    """A building whose street facade starts at ``origin`` and runs ``width`` metres along the
    local +x axis (turned by ``yaw``); local +y points into the street, the body extends to
    local -y. ``gate`` is an x-interval left open at street level (an arcade through a cross
    building).
    """
    R = rot_z(yaw)
    t = np.array([origin[0], origin[1], 0.0])
    floors = int(rng.integers(2, 7))
    fh = rng.uniform(2.9, 3.5)
    gh = rng.uniform(3.6, 4.6)
    height = gh + (floors - 1) * fh
    recess = rng.uniform(0.12, 0.3)
    mat = (ob.RENDER if rng.random() < 0.6 else ob.BRICK).jitter(rng, 0.15)
    trim = ob.WHITE_PAINT.jitter(rng, 0.1)
    local = MeshBuilder()
    gx = gate
    # body (behind the facade layer); a gate cuts through the ground floor
    if gx is None:
        local.box([0, -depth, 0], [width, -recess, height], mat)
    else:
        local.box([0, -depth, 0], [gx[0], -recess, height], mat)
        local.box([gx[1], -depth, 0], [width, -recess, height], mat)
        local.box([gx[0], -depth, gh], [gx[1], -recess, height], mat)
    # facade layer with openings
    bay = rng.uniform(2.4, 4.0)
    n_bays = max(1, int(width // bay))
    bay = width / n_bays
    ww = min(bay - 0.7, rng.uniform(1.0, 1.7))
    wh = min(fh - 1.2, rng.uniform(1.4, 1.9))
    sill_h = rng.uniform(0.8, 1.0)
    balcony_cols = (
        {i for i in range(n_bays) if rng.random() < 0.25} if rng.random() < 0.6 else set()
    )
    openings: list[tuple[float, float, float, float]] = []
    if gx is not None:
        openings.append((gx[0], gx[1], 0.0, gh))
    shop = rng.random() < 0.5
    for i in range(n_bays):
        xc = (i + 0.5) * bay + rng.normal(0, 0.03)
        if gx is not None and gx[0] - 0.3 < xc < gx[1] + 0.3:
            continue
        # ground floor: shop window, door, or window
        k = rng.random()
        if shop and k < 0.6:
            sw = min(bay - 0.5, rng.uniform(2.0, 3.5))
            openings.append((xc - sw / 2, xc + sw / 2, rng.uniform(0.3, 0.6), gh - 0.6))
            if rng.random() < 0.4:
                local.extend(ob.awning(rng, sw + 0.3), t=[xc, 0.0, gh - 0.45])
        elif k < 0.8:
            dw = rng.uniform(1.0, 2.0)
            z_door = 0.0
            if rng.random() < 0.5:
                st, _, z_door = ob.entrance_steps(rng, dw + 0.6)
                local.extend(st, t=[xc, 0.0, 0.0])
            openings.append((xc - dw / 2, xc + dw / 2, z_door, z_door + rng.uniform(2.2, 2.8)))
        else:
            openings.append((xc - ww / 2, xc + ww / 2, sill_h, sill_h + wh))
        for f in range(1, floors):
            if rng.random() < 0.07:
                continue
            zf = gh + (f - 1) * fh
            if i in balcony_cols:
                openings.append((xc - 0.5, xc + 0.5, zf + 0.02, zf + 2.3))
            else:
                openings.append((xc - ww / 2, xc + ww / 2, zf + sill_h, zf + sill_h + wh))
                if rng.random() < 0.08:
                    local.extend(ob.ac_unit(rng), t=[xc + rng.uniform(-0.3, 0.3), 0.0, zf + 0.15])
    for lo, hi in wall_boxes(width, height, recess, openings):
        local.box(lo - [0, recess, 0], hi - [0, recess, 0], mat)
    # window furniture: sills, frames with a mullion, inside each recess
    for x0, x1, z0, z1 in openings:
        if z0 > 0.25:
            local.box([x0 - 0.06, -0.02, z0 - 0.06], [x1 + 0.06, 0.05, z0], trim)
        fd = -recess - 0.0
        local.box([x0, fd, z0], [x1, fd + 0.06, z0 + 0.05], trim)
        local.box([x0, fd, z1 - 0.05], [x1, fd + 0.06, z1], trim)
        local.box([x0, fd, z0], [x0 + 0.05, fd + 0.06, z1], trim)
        local.box([x1 - 0.05, fd, z0], [x1, fd + 0.06, z1], trim)
        if x1 - x0 > 0.9:
            xm = (x0 + x1) / 2
            local.box([xm - 0.03, fd, z0], [xm + 0.03, fd + 0.06, z1], trim)
        local.count("window")
    # cornices: a band at every floor, a big one on top
    cp = rng.uniform(0.04, 0.12)
    for f in range(1, floors):
        zf = gh + (f - 1) * fh
        local.box([0, -0.01, zf - 0.12], [width, cp, zf + 0.08], trim)
    top = rng.uniform(0.25, 0.6)
    local.box([-0.1, -0.01, height - 0.35], [width + 0.1, top, height], trim)
    local.box([-0.1, -0.01, height - 0.5], [width + 0.1, top * 0.5, height - 0.35], trim)
    local.box([0, -depth, height], [width, -recess, height + rng.uniform(0.5, 1.1)], mat)  # parapet
    local.count("cornice", floors)
    # balconies
    for i in sorted(balcony_cols):
        xc = (i + 0.5) * bay
        bw = rng.uniform(1.8, min(bay - 0.2, 3.0)) if bay > 2.1 else bay - 0.2
        bd = rng.uniform(0.9, 1.5)
        railing_solid = rng.random() < 0.4
        rail = ob.DARK_METAL if rng.random() < 0.6 else ob.METAL
        for f in range(1, floors):
            zf = gh + (f - 1) * fh
            local.box([xc - bw / 2, 0, zf - 0.15], [xc + bw / 2, bd, zf + 0.02], ob.CONCRETE)
            if railing_solid:
                local.box([xc - bw / 2, bd - 0.05, zf + 0.02], [xc + bw / 2, bd, zf + 1.0], mat)
                for sx in (-1, 1):
                    xs = xc + sx * bw / 2
                    local.box([xs - 0.025, 0, zf + 0.02], [xs + 0.025, bd, zf + 1.0], mat)
            else:
                local.box([xc - bw / 2, bd - 0.05, zf + 0.98], [xc + bw / 2, bd, zf + 1.02], rail)
                for x in np.arange(xc - bw / 2 + 0.02, xc + bw / 2, 0.12):
                    local.box(
                        [x - 0.01, bd - 0.04, zf + 0.02], [x + 0.01, bd - 0.02, zf + 0.98], rail
                    )
                for sx in (-1, 1):
                    xs = xc + sx * (bw / 2 - 0.025)
                    local.box([xs - 0.01, 0.02, zf + 0.98], [xs + 0.01, bd, zf + 1.02], rail)
                    for y in np.arange(0.1, bd - 0.05, 0.12):
                        local.box(
                            [xs - 0.01, y - 0.01, zf + 0.02], [xs + 0.01, y + 0.01, zf + 0.98], rail
                        )
            local.count("balcony")
    # plinth along the ground floor (interrupted by doors and low openings)
    ph = rng.uniform(0.4, 0.9)
    cuts = sorted((o[0], o[1]) for o in openings if o[2] < ph)
    edges = [0.0] + [v for c in cuts for v in c] + [width]
    pm = (ob.GRANITE if rng.random() < 0.5 else mat).jitter(rng, 0.1)
    for a, c in zip(edges[0::2], edges[1::2], strict=True):
        if c - a > 0.05:
            local.box([a, -0.01, 0.0], [c, rng.uniform(0.02, 0.05), ph], pm)
    # drainpipes at the ends
    for x in (0.15, width - 0.15):
        if rng.random() < 0.7:
            local.add(cylinder([x, 0.1, 0.0], [x, 0.1, height - 0.3], 0.05, segments=10), ob.METAL)
            local.add(
                tube(
                    [
                        [x, 0.1, height - 0.3],
                        [x, 0.1, height - 0.15],
                        [x, top - 0.1, height - 0.05],
                    ],
                    0.05,
                    segments=10,
                ),
                ob.METAL,
            )
            local.count("drainpipe")
    if shop and rng.random() < 0.6:  # shop sign
        local.box(
            [0.5, 0, gh - 0.5],
            [width - 0.5, 0.12, gh - 0.15],
            Material.random(rng, 0.7, 30, 230),
        )
    local.count("building")
    b.extend(local, R=R, t=t)


# ==================================================================================== hall
def hall(
    rng: np.random.Generator | int | None = None, *, size_m: tuple[float, float] | None = None
) -> Scene:
    """Industrial hall of 30-50 m x 18-30 m (or ``size_m``), 8-12 m high.

    Steel I-section columns and roof trusses with purlins, a crane runway with its bridge, gates
    with half-open roller doors and high ribbon windows, pipe runs with bends, flanges and
    hangers, vertical tanks with ladders and nozzles, a horizontal tank on saddles, pallet racks
    with varied loads, machines, conveyors, a mezzanine with stairs, floor markings and clutter.
    """
    rng, seed = as_rng(rng)
    if size_m is None:
        Lx, Ly = rng.uniform(30.0, 50.0), rng.uniform(20.0, 32.0)
    else:
        Lx, Ly = (float(v) for v in size_m)
        if Lx < 12 or Ly < 10:
            raise ConfigError(f"hall size must be at least 12 x 10 m, got {Lx} x {Ly}")
    H = rng.uniform(8.0, 12.0)
    wt = 0.3
    b = MeshBuilder()
    b.box([-wt, -wt, -0.3], [Lx + wt, Ly + wt, 0.0], ob.SCREED.jitter(rng))
    b.box([-wt, -wt, H], [Lx + wt, Ly + wt, H + 0.3], ob.METAL.jitter(rng))
    walls = _Walls([(0, 0), (Lx, 0), (Lx, Ly), (0, Ly)])
    wall_mat = ob.Material(0.55, (190, 192, 186)).jitter(rng, 0.1)
    plan = _Floorplan(0.4, 0.4, Lx - 0.4, Ly - 0.4)
    # ---- walls: gates with roller doors, a personnel door, ribbon windows
    band0 = rng.uniform(4.5, 6.0)
    band1 = min(H - 1.0, band0 + rng.uniform(1.0, 2.0))
    for k in range(4):
        L = walls.length(k)
        n_gates = int(rng.integers(0, 3)) if k % 2 == 0 else int(rng.integers(0, 2))
        widths = [rng.uniform(3.5, 5.0) for _ in range(n_gates)] + [1.0]
        spans = _intervals(rng, L, widths, margin=1.0, gap=1.0)
        openings = []
        for x0, x1 in spans:
            gh = rng.uniform(4.0, 4.5) if x1 - x0 > 2 else 2.1
            openings.append((x0, x1, 0.0, gh))
            if x1 - x0 > 2:  # roller door partly open, its box above
                z_open = rng.uniform(1.0, gh - 0.3)
                walls.add_local(b, k, box([x0, -wt * 0.5, z_open], [x1, -wt * 0.4, gh]), ob.METAL)
                walls.add_local(
                    b, k, box([x0 - 0.1, 0.0, gh], [x1 + 0.1, 0.5, gh + 0.6]), ob.DARK_METAL
                )
                for xg in (x0 - 0.12, x1 + 0.02):
                    walls.add_local(b, k, box([xg, 0, 0], [xg + 0.1, 0.15, gh]), ob.SAFETY_YELLOW)
                b.count("gate")
            p = walls.to_world(k, np.array([[x0 - 0.5, 0, 0], [x1 + 0.5, 3.0, 0]]))
            plan.mark(p.min(axis=0)[:2], p.max(axis=0)[:2])
        # ribbon window: a band of openings between mullions
        n_w = max(1, int(L // rng.uniform(1.2, 1.8)))
        pitch = L / n_w
        for i in range(n_w):
            xa = i * pitch + 0.08
            xb = (i + 1) * pitch - 0.08
            if any(not (xb < o[0] or xa > o[1]) and o[3] > band0 - 0.2 for o in openings):
                continue
            openings.append((xa, xb, band0, band1))
        walls.build(b, k, H, wt, openings, wall_mat)
    # ---- columns (I-sections) along both long walls, trusses across, purlins along
    bay = rng.uniform(5.5, 7.5)
    n_bays = max(2, round(Lx / bay))
    xs = np.linspace(0.0, Lx, n_bays + 1)
    xs[0], xs[-1] = 0.25, Lx - 0.25
    steel = ob.STEEL_BLUE.jitter(rng, 0.15) if rng.random() < 0.5 else ob.METAL.jitter(rng, 0.15)
    cd, cw = rng.uniform(0.3, 0.5), rng.uniform(0.2, 0.3)
    truss_h = rng.uniform(1.0, 1.6)
    crane = rng.random() < 0.6
    crane_z = rng.uniform(5.5, H - truss_h - 1.2) if H - truss_h - 1.2 > 5.5 else None
    for x in xs:
        for y in (0.3, Ly - 0.3):
            i_beam_z(b, x, y, H, cd, cw, steel)
            plan.mark([x - 0.5, y - 0.5], [x + 0.5, y + 0.5])
        zb = H - truss_h
        ob.i_beam([x, 0.2, zb], [x, Ly - 0.2, zb], 0.2, 0.15, b, steel)  # bottom chord
        ob.i_beam([x, 0.2, H - 0.12], [x, Ly - 0.2, H - 0.12], 0.2, 0.15, b, steel)
        n_d = max(2, int(Ly // 1.5))
        ys = np.linspace(0.3, Ly - 0.3, n_d + 1)
        for j, (ya, yb) in enumerate(pairwise(ys)):
            za, zc = (zb + 0.1, H - 0.22) if j % 2 == 0 else (H - 0.22, zb + 0.1)
            b.add(cylinder([x, ya, za], [x, yb, zc], 0.035, segments=6), steel)
        b.count("truss")
        if crane and crane_z is not None:  # runway brackets
            b.box([x - 0.1, 0.3, crane_z - 0.5], [x + 0.1, 0.9, crane_z - 0.3], steel)
            b.box([x - 0.1, Ly - 0.9, crane_z - 0.5], [x + 0.1, Ly - 0.3, crane_z - 0.3], steel)
    for y in np.arange(1.0, Ly - 0.5, rng.uniform(1.8, 2.6)):
        b.box([0, y - 0.05, H - 0.17], [Lx, y + 0.05, H], steel)
    b.count("purlin", len(np.arange(1.0, Ly - 0.5, 2.2)))
    if crane and crane_z is not None:
        for y in (0.6, Ly - 0.6):
            ob.i_beam([0.0, y, crane_z - 0.05], [Lx, y, crane_z - 0.05], 0.5, 0.3, b, steel)
        xb = rng.uniform(3.0, Lx - 3.0)
        yel = ob.SAFETY_YELLOW
        for dx in (-0.6, 0.6):
            b.box(
                [xb + dx - 0.25, 0.4, crane_z + 0.2], [xb + dx + 0.25, Ly - 0.4, crane_z + 1.0], yel
            )
        yh = rng.uniform(3.0, Ly - 3.0)
        b.box([xb - 1.0, yh - 0.6, crane_z + 1.0], [xb + 1.0, yh + 0.6, crane_z + 1.6], yel)
        hook_z = rng.uniform(2.5, crane_z - 1.0)
        for dy in (-0.1, 0.1):
            b.add(
                cylinder(
                    [xb, yh + dy, crane_z + 0.2], [xb, yh + dy, hook_z + 0.4], 0.015, segments=6
                ),
                ob.DARK_METAL,
            )
        b.box([xb - 0.2, yh - 0.25, hook_z], [xb + 0.2, yh + 0.25, hook_z + 0.5], yel)
        b.count("crane")

    # ---- floor markings (walkways)
    yw = rng.uniform(0.3, 0.7) * Ly
    for y in (yw - 1.2, yw + 1.2):
        b.box([1.0, y - 0.05, 0.0], [Lx - 1.0, y + 0.05, 0.003], ob.SAFETY_YELLOW)
    b.count("floor marking")
    plan.mark([0.4, yw - 1.1], [Lx - 0.4, yw + 1.1])  # keep the walkway clear

    # ---- racks: a block of parallel rows with aisles, and single rows
    if rng.random() < 0.7:
        n_rows = int(rng.integers(2, 5))
        length = rng.uniform(8.0, min(22.0, Lx * 0.5))
        depth = rng.uniform(0.9, 1.2)
        aisle = rng.uniform(2.8, 3.8)
        rh = rng.uniform(4.0, min(8.0, H - truss_h - 0.5))
        spot = plan.place(
            rng, length, n_rows * (2 * depth + 0.2) + (n_rows - 1) * aisle, margin=1.0, tries=150
        )
        if spot is not None:
            cx, cy, yaw = spot
            yaw = round(yaw / (np.pi / 2)) * np.pi / 2
            blk = MeshBuilder()
            y = -(n_rows * (2 * depth + 0.2) + (n_rows - 1) * aisle) / 2
            for _ in range(n_rows):
                blk.extend(
                    ob.pallet_rack(rng, length * rng.uniform(0.8, 1.0), 2 * depth + 0.2, rh),
                    t=[rng.uniform(-0.5, 0.5), y + depth + 0.1, 0],
                )
                y += 2 * depth + 0.2 + aisle
            _put(b, blk, cx, cy, yaw)
    for _ in range(int(rng.integers(1, 4))):
        length = rng.uniform(5.0, min(16.0, Lx * 0.4))
        depth = rng.uniform(0.9, 1.2)
        rh = rng.uniform(3.0, min(8.0, H - truss_h - 0.5))
        spot = plan.place(rng, length, depth, margin=1.2, against_wall=rng.random() < 0.5, tries=80)
        if spot is not None:
            cx, cy, yaw = spot
            _put(
                b,
                ob.pallet_rack(rng, length, depth, rh),
                cx,
                cy,
                round(yaw / (np.pi / 2)) * np.pi / 2,
            )
    # ---- tanks
    for _ in range(int(rng.integers(2, 6))):
        tb, pad = ob.tank(rng)
        spot = plan.place(rng, 2 * pad + 0.4, 2 * pad + 0.4, margin=0.8, tries=80)
        if spot is not None:
            _put(b, tb, spot[0], spot[1], rng.uniform(-np.pi, np.pi))
    if rng.random() < 0.6:  # horizontal tank on saddles
        L, r = rng.uniform(4.0, 8.0), rng.uniform(0.8, 1.4)
        spot = plan.place(rng, L + 2 * r * 0.5, 2 * r + 0.6, margin=1.0)
        if spot is not None:
            cx, cy, yaw = spot
            ht = MeshBuilder()
            zc = r + rng.uniform(0.5, 1.0)
            mat = ob.WHITE_PAINT.jitter(rng, 0.1)
            ht.add(cylinder([-L / 2, 0, zc], [L / 2, 0, zc], r, segments=36), mat)
            for s in (-1, 1):
                ht.add(ellipsoid([s * L / 2, 0, zc], [r * 0.45, r, r], subdivisions=3), mat)
                ht.box(
                    [s * L * 0.3 - 0.2, -r * 0.8, 0],
                    [s * L * 0.3 + 0.2, r * 0.8, zc - r * 0.6],
                    ob.CONCRETE,
                )
            ht.add(cylinder([0, 0, zc + r - 0.1], [0, 0, zc + r + 0.35], 0.3, segments=20), mat)
            ht.count("tank")
            _put(b, ht, cx, cy, yaw)
    # ---- machines and conveyors
    for _ in range(int(rng.integers(3, 9))):
        mb, mw, md = ob.machine(rng)
        spot = plan.place(rng, mw, md, margin=0.8, tries=100)
        if spot is not None:
            _put(b, mb, *spot)
    for _ in range(int(rng.integers(1, 4))):
        cab, cw_ = ob.electrical_cabinet(rng)
        spot = plan.place(rng, cw_, 0.6, against_wall=True, tries=60)
        if spot is not None:
            _put(b, cab, *spot)
    if rng.random() < 0.6:
        spot = plan.place(rng, 4.0, 1.3, margin=0.8, free_yaw=True)
        if spot is not None:
            _put(b, ob.forklift(rng), *spot)
    for _ in range(int(rng.integers(0, 3))):
        L = rng.uniform(4.0, 12.0)
        spot = plan.place(rng, L, 1.0, margin=1.0)
        if spot is not None:
            cx, cy, yaw = spot
            _put(b, ob.conveyor(rng, L), cx, cy, round(yaw / (np.pi / 2)) * np.pi / 2)
    # ---- mezzanine with stairs
    if rng.random() < 0.6:
        mw, md = rng.uniform(5.0, 9.0), rng.uniform(3.0, 5.0)
        mz = rng.uniform(2.8, 3.6)
        spot = plan.place(rng, mw, md + 4.5, margin=0.8, against_wall=True)
        if spot is not None:
            cx, cy, yaw = spot
            mz_b = MeshBuilder()
            y0 = -(md + 4.5) / 2
            mz_b.box([-mw / 2, y0, mz - 0.25], [mw / 2, y0 + md, mz], ob.METAL)
            for x in np.linspace(-mw / 2 + 0.15, mw / 2 - 0.15, max(2, int(mw // 3) + 1)):
                mz_b.box([x - 0.1, y0 + md - 0.3, 0], [x + 0.1, y0 + md - 0.1, mz - 0.25], steel)
            for x in np.arange(-mw / 2 + 0.05, mw / 2, 1.0):
                mz_b.add(
                    cylinder(
                        [x, y0 + md - 0.05, mz], [x, y0 + md - 0.05, mz + 1.1], 0.025, segments=6
                    ),
                    ob.SAFETY_YELLOW,
                )
            mz_b.add(
                cylinder(
                    [-mw / 2, y0 + md - 0.05, mz + 1.1],
                    [mw / 2, y0 + md - 0.05, mz + 1.1],
                    0.03,
                    segments=8,
                ),
                ob.SAFETY_YELLOW,
            )
            mz_b.add(
                cylinder(
                    [-mw / 2, y0 + md - 0.05, mz + 0.55],
                    [mw / 2, y0 + md - 0.05, mz + 0.55],
                    0.02,
                    segments=8,
                ),
                ob.SAFETY_YELLOW,
            )
            st, run_len = ob.stairs(rng, 1.0, mz, material=ob.METAL)
            mz_b.extend(st, R=rot_z(np.pi), t=[mw / 2 - 0.7, y0 + md + run_len - 0.3, 0])
            mz_b.count("mezzanine")
            _put(b, mz_b, cx, cy, yaw)
    # ---- pipe runs with bends, flanges and hangers
    for _ in range(int(rng.integers(5, 13))):
        _pipe_run(b, rng, Lx, Ly, H - truss_h - 0.3)
    # ---- cable trays along the long walls
    for y, s_ in ((0.3 + cd / 2 + 0.05, 1), (Ly - 0.3 - cd / 2 - 0.05, -1)):
        if rng.random() < 0.7:
            z = rng.uniform(3.0, 4.5)
            w = rng.uniform(0.2, 0.5)
            y0, y1 = sorted((y, y + s_ * w))
            b.box([0.3, y0, z], [Lx - 0.3, y1, z + 0.01], ob.METAL)
            b.box([0.3, y0, z], [Lx - 0.3, y0 + 0.01, z + 0.08], ob.METAL)
            b.box([0.3, y1 - 0.01, z], [Lx - 0.3, y1, z + 0.08], ob.METAL)
            b.count("cable tray")
    # ---- pallets and clutter on the floor
    for _ in range(int(rng.integers(10, 30))):
        spot = plan.place(rng, 1.3, 1.3, margin=0.3, free_yaw=True)
        if spot is not None:
            u = rng.random()
            obj = (
                ob.pallet_stack(rng) if u < 0.4 else (ob.clutter(rng) if u < 0.8 else ob.bin_(rng))
            )
            _put(b, obj, *spot)

    return _finish(b, "hall", seed, Lx, Ly, margin_m=0.8)


def i_beam_z(
    b: MeshBuilder, x: float, y: float, h: float, depth: float, width: float, mat: Material
) -> None:
    """Vertical I-section column from the floor to ``h`` with a base plate."""
    ob.i_beam([x, y, 0.0], [x, y, h], depth, width, b, mat, up=(0.0, 1.0, 0.0))
    b.box(
        [x - width / 2 - 0.1, y - depth / 2 - 0.1, 0.0],
        [x + width / 2 + 0.1, y + depth / 2 + 0.1, 0.03],
        mat,
    )
    b.count("column")


def _pipe_run(b: MeshBuilder, rng: np.random.Generator, Lx: float, Ly: float, z_max: float) -> None:
    """Manhattan pipe route with rounded bends, flanges and hangers to the roof structure."""
    r = float(rng.choice([0.03, 0.05, 0.08, 0.11, 0.16, 0.22]))
    z = rng.uniform(2.8, max(3.0, z_max))
    p = np.array([rng.choice([0.6, Lx - 0.6]), rng.uniform(1.0, Ly - 1.0), z])
    pts = [p.copy()]
    axis = 0
    for _ in range(int(rng.integers(2, 5))):
        q = pts[-1].copy()
        if axis == 0:
            q[0] = rng.uniform(1.0, Lx - 1.0)
        elif axis == 1:
            q[1] = rng.uniform(1.0, Ly - 1.0)
        else:
            q[2] = rng.uniform(0.5, z_max) if rng.random() < 0.5 else rng.uniform(2.5, z_max)
        if np.linalg.norm(q - pts[-1]) > 6 * r + 0.5:  # room for a bend at both ends
            pts.append(q)
        axis = int(rng.choice([a for a in (0, 1, 2) if a != axis]))
    if len(pts) < 2:
        return
    P = np.array(pts)
    # round the corners: replace each interior vertex by an arc
    path = [P[0]]
    bend = 3.0 * r + 0.05
    for i in range(1, len(P) - 1):
        a, c, d = P[i - 1], P[i], P[i + 1]
        u = (a - c) / np.linalg.norm(a - c)
        v = (d - c) / np.linalg.norm(d - c)
        s0, s1 = c + u * bend, c + v * bend
        for tt in np.linspace(0, 1, 7):  # quadratic Bezier through the corner
            path.append((1 - tt) ** 2 * s0 + 2 * (1 - tt) * tt * c + tt**2 * s1)
    path.append(P[-1])
    path_a = np.array(path)
    keep = np.r_[True, np.linalg.norm(np.diff(path_a, axis=0), axis=1) > 1e-6]
    path_a = path_a[keep]
    mat = Material.random(rng, float(rng.uniform(0.3, 0.7)), 40, 220)
    b.add(tube(path_a, r, segments=max(8, min(20, int(r * 120)))), mat)
    # flanges and hangers along the straight segments
    spacing = rng.uniform(3.0, 6.0)
    for a, c in pairwise(P):
        seg = c - a
        L = float(np.linalg.norm(seg))
        d = seg / L
        for s in np.arange(spacing / 2, L - bend, spacing):
            q = a + d * s
            b.add(cylinder(q - d * 0.02, q + d * 0.02, r * 1.6 + 0.02, segments=16), ob.METAL)
            if abs(d[2]) < 0.5:
                b.add(
                    cylinder(
                        q + [0, 0, r], [q[0], q[1], z_max + 0.3], 0.008 + r * 0.05, segments=4
                    ),
                    ob.DARK_METAL,
                )
    b.count("pipe")


# ==================================================================================== dispatch
def make_scene(
    kind: str,
    rng: np.random.Generator | int | None = 0,
    *,
    size_m: tuple[float, float] | None = None,
) -> Scene:
    """Generate a procedural scene.

    Parameters
    ----------
    kind : {"room", "courtyard", "hall"}
    rng : numpy Generator, int or None
        Seed or generator; the same int gives the identical mesh.
    size_m : (float, float), optional
        Floor size ``(x, y)`` in metres; drawn from the kind's range when omitted.

    Returns
    -------
    Scene

    Examples
    --------
    >>> s = make_scene("room", 1)
    >>> s.kind, s.n_triangles == make_scene("room", 1).n_triangles
    ('room', True)
    """
    gens: dict[str, Callable[..., Scene]] = {"room": room, "courtyard": courtyard, "hall": hall}
    if kind not in gens:
        raise ConfigError(f"unknown scene kind {kind!r}; choose one of {', '.join(SCENE_KINDS)}")
    return gens[kind](rng, size_m=size_m)


def _load_mesh(
    mesh: Any,
) -> tuple[NDArray[np.float64], NDArray[np.int32], NDArray[np.uint8] | None, str]:
    import open3d as o3d

    if isinstance(mesh, (str, PathLike)):
        p = Path(mesh)
        if not p.is_file():
            raise InputError(p, "no such mesh file")
        m = o3d.io.read_triangle_mesh(p)
        name = p.stem
        if len(m.triangles) == 0:
            raise InputError(p, "mesh has no triangles (or could not be read)")
    elif isinstance(mesh, o3d.geometry.TriangleMesh):
        m, name = mesh, "mesh"
    else:
        raise InputError(
            "mesh", f"expected a path or an open3d TriangleMesh, got {type(mesh).__name__}"
        )
    V = np.asarray(m.vertices, dtype=np.float64)
    F = np.asarray(m.triangles, dtype=np.int32)
    if len(F) == 0:
        raise InputError(name, "mesh has no triangles")
    cols = None
    if m.has_vertex_colors():
        vc = np.asarray(m.vertex_colors)
        cols = np.clip(vc[F].mean(axis=1) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    return V, F, cols, name


def scene_from_mesh(
    mesh: str | PathLike[str] | Any,
    *,
    scale: float = 1.0,
    reflectance: float = 0.5,
    ground: bool = True,
    ground_margin_m: float = 10.0,
    up_axis: str = "z",
) -> Scene:
    """Use any triangle mesh (PLY, OBJ, STL, ... or an open3d mesh) as a scene.

    The mesh is turned so that ``up_axis`` points up, scaled by ``scale``, and moved so its
    lowest point is at ``z = 0`` and its bounding box is centred on the origin. With ``ground``
    a ground plane reaching ``ground_margin_m`` past the mesh is added, so that stations can
    stand around an object.

    Parameters
    ----------
    mesh : path-like or open3d.geometry.TriangleMesh
    scale : float
        Factor to metres (e.g. 40 makes the 0.15 m Stanford bunny a 6 m sculpture).
    reflectance : float
        Laser reflectance of the mesh, 0..1.
    up_axis : {"x", "y", "z"}
        The mesh's up direction (``"y"`` for most OBJ files and the Stanford models).
    """
    if not (np.isfinite(scale) and scale > 0):
        raise ConfigError(f"scale must be positive, got {scale}")
    if not 0 < reflectance <= 1:
        raise ConfigError(f"reflectance must be in (0, 1], got {reflectance}")
    turn = {
        "z": np.eye(3),
        "y": np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]),
        "x": np.array([[0, 0, -1.0], [0, 1, 0], [1, 0, 0]]),
    }
    if up_axis not in turn:
        raise ConfigError(f"up_axis must be x, y or z, got {up_axis!r}")
    V, F, cols, name = _load_mesh(mesh)
    V = (V @ turn[up_axis].T) * scale
    lo, hi = V.min(axis=0), V.max(axis=0)
    V = V - [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]]
    lo, hi = V.min(axis=0), V.max(axis=0)
    b = MeshBuilder()
    b.add((V, F), Material(reflectance, (180, 180, 180)))
    V2, T2, refl, rgb = b.arrays()
    if cols is not None:
        rgb = cols
    m = ground_margin_m
    region = (
        float(lo[0] - m * 0.8),
        float(lo[1] - m * 0.8),
        float(hi[0] + m * 0.8),
        float(hi[1] + m * 0.8),
    )
    if ground:
        gb = MeshBuilder()
        gb.box([lo[0] - m, lo[1] - m, -0.3], [hi[0] + m, hi[1] + m, 0.0], ob.PAVING)
        Vg, Tg, rg, cg = gb.arrays()
        T2 = np.vstack([T2, Tg + len(V2)])
        V2 = np.vstack([V2, Vg])
        refl = np.concatenate([refl, rg])
        rgb = np.vstack([rgb, cg])
    else:
        region = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
    return Scene(
        V2,
        T2,
        refl,
        rgb,
        kind="mesh",
        seed=None,
        floor_z=0.0 if ground else float(lo[2]),
        region=region,
        objects={name: 1},
        name=name,
    )


def add_mesh_objects(
    scene: Scene,
    mesh: str | PathLike[str] | Any,
    *,
    count: int = 1,
    size_m: float = 0.5,
    reflectance: float = 0.5,
    rng: np.random.Generator | int | None = 0,
) -> Scene:
    """Return a new scene with ``count`` copies of a mesh standing on free floor spots.

    Each copy is scaled so its largest extent is ``size_m`` (times 0.8-1.2), turned by a random
    yaw and set on the floor where a downward ray finds the bare floor in a clear 2 x extent
    square.
    """
    rng, _ = as_rng(rng)
    if count < 0 or size_m <= 0:
        raise ConfigError(f"count must be >= 0 and size_m > 0, got {count}, {size_m}")
    V, F, _cols, name = _load_mesh(mesh)
    ext = float((V.max(axis=0) - V.min(axis=0)).max())
    if ext <= 0:
        raise InputError(name, "mesh has zero extent")
    V = V - [
        (V[:, 0].min() + V[:, 0].max()) / 2,
        (V[:, 1].min() + V[:, 1].max()) / 2,
        V[:, 2].min(),
    ]
    b = MeshBuilder()
    placed = 0
    x0, y0, x1, y1 = scene.region
    for _ in range(count * 50):
        if placed == count:
            break
        s = size_m * rng.uniform(0.8, 1.2)
        c = np.array([rng.uniform(x0, x1), rng.uniform(y0, y1)])
        yaw = rng.uniform(-np.pi, np.pi)
        g = (
            np.stack(np.meshgrid(np.linspace(-s, s, 5), np.linspace(-s, s, 5)), -1).reshape(-1, 2)
            + c
        )
        origins = np.column_stack([g, np.full(len(g), scene.floor_z + 2.0)])
        hits = scene.cast(origins, np.tile([0.0, 0.0, -1.0], (len(g), 1)))
        z = origins[:, 2] - hits.t
        if not (
            np.all(np.isfinite(z))
            and np.all(np.abs(z - scene.floor_z) < 0.05)
            and np.all(hits.normal[:, 2] > 0.9)
        ):
            continue
        b.add(
            (V * (s / ext), F),
            Material(reflectance, (200, 200, 200)),
            R=rot_z(yaw),
            t=[c[0], c[1], float(np.median(z))],
        )
        placed += 1
    if placed < count:
        raise InputError(name, f"found free floor for only {placed} of {count} copies")
    Vn, Tn, rn, cn = b.arrays()
    objects = dict(scene.objects)
    objects[name] = objects.get(name, 0) + placed
    return Scene(
        np.vstack([scene.vertices, Vn]),
        np.vstack([scene.triangles, Tn + len(scene.vertices)]),
        np.concatenate([scene.reflectance, rn]),
        np.vstack([scene.colors, cn]),
        kind=scene.kind,
        seed=scene.seed,
        floor_z=scene.floor_z,
        region=scene.region,
        objects=objects,
        name=scene.name,
    )


def _finish(
    b: MeshBuilder, kind: str, seed: int | None, Lx: float, Ly: float, *, margin_m: float
) -> Scene:
    """The built mesh as a :class:`Scene` on floor z = 0, with stations allowed inside the
    ``Lx`` x ``Ly`` footprint less ``margin_m``."""
    V, T, refl, rgb = b.arrays()
    return Scene(
        V,
        T,
        refl,
        rgb,
        kind=kind,
        seed=seed,
        floor_z=0.0,
        region=(margin_m, margin_m, Lx - margin_m, Ly - margin_m),
        objects=b.counts,
        name=f"{kind}-{seed}" if seed is not None else kind,
    )
