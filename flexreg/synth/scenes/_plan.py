"""Shared tools of the scene generators: floor occupancy, walls with openings, doors,
windows, the exterior around an enclosed building and the final :class:`Scene`."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

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


class Floorplan:
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


def put(b: MeshBuilder, obj: MeshBuilder, cx: float, cy: float, yaw: float, z: float = 0.0) -> None:
    b.extend(obj, R=rot_z(yaw), t=[cx, cy, z])


def intervals(
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


class Walls:
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


def door(
    b: MeshBuilder,
    walls: Walls,
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


def window(
    b: MeshBuilder,
    walls: Walls,
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


def exterior(
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
            put(b, ob.tree(rng), cx, cy, rng.uniform(0, 2 * np.pi), -0.35)


def finish(
    b: MeshBuilder,
    kind: str,
    seed: int | None,
    Lx: float,
    Ly: float,
    *,
    margin_m: float,
    region: tuple[float, float, float, float] | None = None,
    symmetries: tuple[NDArray[np.float64], ...] = (),
    zones: tuple[tuple[float, float, float, float, int], ...] = (),
    layout: dict[str, Any] | None = None,
    stand_points: tuple[tuple[float, float, int], ...] = (),
) -> Scene:
    """The built mesh as a :class:`Scene` on floor z = 0, with stations allowed inside the
    ``Lx`` x ``Ly`` footprint less ``margin_m`` (or inside ``region`` when given)."""
    V, T, refl, rgb = b.arrays()
    if region is None:
        region = (margin_m, margin_m, Lx - margin_m, Ly - margin_m)
    return Scene(
        V,
        T,
        refl,
        rgb,
        kind=kind,
        seed=seed,
        floor_z=0.0,
        region=region,
        objects=b.counts,
        name=f"{kind}-{seed}" if seed is not None else kind,
        symmetries=symmetries,
        zones=zones,
        layout=layout or {},
        stand_points=stand_points,
    )


def turn_z(cx: float, cy: float, quarter_turns: int) -> NDArray[np.float64]:
    """(4, 4) rotation by ``quarter_turns`` x 90 degrees about the vertical line through
    ``(cx, cy)``, with exact 0/1 entries."""
    c, s = ((1, 0), (0, 1), (-1, 0), (0, -1))[quarter_turns % 4]
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:2, 3] = [cx - c * cx + s * cy, cy - s * cx - c * cy]
    return T


def shift_x(dx: float) -> NDArray[np.float64]:
    """(4, 4) translation by ``dx`` metres along x."""
    T = np.eye(4)
    T[0, 3] = dx
    return T


def side_by_side(parts: list[Scene], kind: str, seed: int | None, gap_m: float) -> Scene:
    """One scene of several, laid out along x with ``gap_m`` metres of nothing between their
    bounding boxes; part ``g``'s placement zones become group ``g``'s.

    With a gap beyond the scanner's range nothing of one part can be seen from another, so
    the stations of different parts never overlap.
    """
    verts, tris, refl, rgb = [], [], [], []
    zones: list[tuple[float, float, float, float, int]] = []
    stand: list[tuple[float, float, int]] = []
    objects: dict[str, int] = {}
    n_v, x = 0, float(parts[0].bounds[0][0])  # the first part stays where it is
    offsets: list[float] = []
    for g, part in enumerate(parts):
        lo, hi = part.bounds
        dx = x - float(lo[0])
        verts.append(part.vertices + np.array([dx, 0.0, 0.0]))
        tris.append(part.triangles + n_v)
        n_v += len(part.vertices)
        refl.append(part.reflectance)
        rgb.append(part.colors)
        own = part.zones or ((*part.region, 0),)
        zones += [(z[0] + dx, z[1], z[2] + dx, z[3], g) for z in own]
        stand += [(x + dx, y, g) for x, y, _g in part.stand_points]
        for k, v in part.objects.items():
            objects[k] = objects.get(k, 0) + v
        offsets.append(round(dx, 6))
        x = float(hi[0]) + dx + gap_m
    if len(parts) == 1:
        layout = dict(parts[0].layout)
    else:
        layout = {"groups": len(parts), "group_offsets_m": offsets}
        layout.update({f"group_{g}": dict(p.layout) for g, p in enumerate(parts)})
    Z = np.array([z[:4] for z in zones])
    lo_xy, hi_xy = Z[:, :2].min(axis=0), Z[:, 2:].max(axis=0)
    return Scene(
        np.vstack(verts),
        np.vstack(tris),
        np.concatenate(refl),
        np.vstack(rgb),
        kind=kind,
        seed=seed,
        floor_z=0.0,
        region=(float(lo_xy[0]), float(lo_xy[1]), float(hi_xy[0]), float(hi_xy[1])),
        objects=objects,
        name=f"{kind}-{seed}" if seed is not None else kind,
        zones=tuple(zones),
        layout=layout,
        stand_points=tuple(stand),
    )
