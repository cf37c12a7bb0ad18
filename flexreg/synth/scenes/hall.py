"""The industrial hall scene, built in steps that draw from one ``rng`` in a fixed order."""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from flexreg.errors import ConfigError
from flexreg.synth import objects as ob
from flexreg.synth.mesh import (
    Material,
    MeshBuilder,
    box,
    cylinder,
    ellipsoid,
    rot_z,
    tube,
)
from flexreg.synth.scene import Scene
from flexreg.synth.scenes._plan import (
    Floorplan,
    Walls,
    finish,
    intervals,
    put,
)
from flexreg.synth.seeding import as_rng


@dataclass
class _Hall:
    """What the steps of :func:`hall` build on: the mesh ``b``, its walls and floor plan, the
    floor size ``Lx`` x ``Ly``, the height ``H`` and wall thickness ``wt`` (metres)."""

    rng: np.random.Generator
    b: MeshBuilder
    walls: Walls
    plan: Floorplan
    Lx: float
    Ly: float
    H: float
    wt: float
    wall_mat: Material


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
    site = _shell(rng, size_m)
    _gates_and_windows(site)
    truss_h, cd, steel = _frame(site)
    _walkway(site)
    _racks(site, truss_h)
    _tanks(site)
    _machines(site)
    _mezzanine(site, steel)
    for _ in range(int(rng.integers(5, 13))):  # pipe runs with bends, flanges and hangers
        _pipe_run(site.b, rng, site.Lx, site.Ly, site.H - truss_h - 0.3)
    _cable_trays(site, cd)
    _floor_clutter(site)
    return finish(site.b, "hall", seed, site.Lx, site.Ly, margin_m=0.8)


def _shell(rng: np.random.Generator, size_m: tuple[float, float] | None) -> _Hall:
    """Size and height; floor and roof slabs."""
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
    walls = Walls([(0, 0), (Lx, 0), (Lx, Ly), (0, Ly)])
    wall_mat = ob.Material(0.55, (190, 192, 186)).jitter(rng, 0.1)
    plan = Floorplan(0.4, 0.4, Lx - 0.4, Ly - 0.4)
    return _Hall(rng, b, walls, plan, Lx, Ly, H, wt, wall_mat)


def _gates_and_windows(site: _Hall) -> None:
    """Gates with half-open roller doors, a personnel door and a ribbon of high
    windows on every wall."""
    rng, b, walls, plan, H, wt = site.rng, site.b, site.walls, site.plan, site.H, site.wt
    wall_mat = site.wall_mat
    band0 = rng.uniform(4.5, 6.0)
    band1 = min(H - 1.0, band0 + rng.uniform(1.0, 2.0))
    for k in range(4):
        L = walls.length(k)
        n_gates = int(rng.integers(0, 3)) if k % 2 == 0 else int(rng.integers(0, 2))
        widths = [rng.uniform(3.5, 5.0) for _ in range(n_gates)] + [1.0]
        spans = intervals(rng, L, widths, margin=1.0, gap=1.0)
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


def _frame(site: _Hall) -> tuple[float, float, Material]:
    """Steel I-section columns along both long walls, roof trusses across, purlins
    along, and maybe a crane. Returns the truss height, column depth and steel material."""
    rng, b, plan, Lx, Ly, H = site.rng, site.b, site.plan, site.Lx, site.Ly, site.H
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
        _crane(site, crane_z, steel)
    return truss_h, cd, steel


def _crane(site: _Hall, crane_z: float, steel: Material) -> None:
    """The crane runway beams, the bridge with its trolley and the hook."""
    rng, b, Lx, Ly = site.rng, site.b, site.Lx, site.Ly
    for y in (0.6, Ly - 0.6):
        ob.i_beam([0.0, y, crane_z - 0.05], [Lx, y, crane_z - 0.05], 0.5, 0.3, b, steel)
    xb = rng.uniform(3.0, Lx - 3.0)
    yel = ob.SAFETY_YELLOW
    for dx in (-0.6, 0.6):
        b.box([xb + dx - 0.25, 0.4, crane_z + 0.2], [xb + dx + 0.25, Ly - 0.4, crane_z + 1.0], yel)
    yh = rng.uniform(3.0, Ly - 3.0)
    b.box([xb - 1.0, yh - 0.6, crane_z + 1.0], [xb + 1.0, yh + 0.6, crane_z + 1.6], yel)
    hook_z = rng.uniform(2.5, crane_z - 1.0)
    for dy in (-0.1, 0.1):
        b.add(
            cylinder([xb, yh + dy, crane_z + 0.2], [xb, yh + dy, hook_z + 0.4], 0.015, segments=6),
            ob.DARK_METAL,
        )
    b.box([xb - 0.2, yh - 0.25, hook_z], [xb + 0.2, yh + 0.25, hook_z + 0.5], yel)
    b.count("crane")


def _walkway(site: _Hall) -> None:
    """Floor markings of a walkway, kept clear."""
    rng, b, plan, Lx, Ly = site.rng, site.b, site.plan, site.Lx, site.Ly
    yw = rng.uniform(0.3, 0.7) * Ly
    for y in (yw - 1.2, yw + 1.2):
        b.box([1.0, y - 0.05, 0.0], [Lx - 1.0, y + 0.05, 0.003], ob.SAFETY_YELLOW)
    b.count("floor marking")
    plan.mark([0.4, yw - 1.1], [Lx - 0.4, yw + 1.1])  # keep the walkway clear


def _racks(site: _Hall, truss_h: float) -> None:
    """Pallet racks: a block of parallel rows with aisles, and single rows."""
    rng, b, plan, Lx, H = site.rng, site.b, site.plan, site.Lx, site.H
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
            put(b, blk, cx, cy, yaw)
    for _ in range(int(rng.integers(1, 4))):
        length = rng.uniform(5.0, min(16.0, Lx * 0.4))
        depth = rng.uniform(0.9, 1.2)
        rh = rng.uniform(3.0, min(8.0, H - truss_h - 0.5))
        spot = plan.place(rng, length, depth, margin=1.2, against_wall=rng.random() < 0.5, tries=80)
        if spot is not None:
            cx, cy, yaw = spot
            put(
                b,
                ob.pallet_rack(rng, length, depth, rh),
                cx,
                cy,
                round(yaw / (np.pi / 2)) * np.pi / 2,
            )


def _tanks(site: _Hall) -> None:
    """Vertical tanks and a horizontal tank on saddles."""
    rng, b, plan = site.rng, site.b, site.plan
    for _ in range(int(rng.integers(2, 6))):
        tb, pad = ob.tank(rng)
        spot = plan.place(rng, 2 * pad + 0.4, 2 * pad + 0.4, margin=0.8, tries=80)
        if spot is not None:
            put(b, tb, spot[0], spot[1], rng.uniform(-np.pi, np.pi))
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
            put(b, ht, cx, cy, yaw)


def _machines(site: _Hall) -> None:
    """Machines, electrical cabinets, a forklift and conveyors."""
    rng, b, plan = site.rng, site.b, site.plan
    for _ in range(int(rng.integers(3, 9))):
        mb, mw, md = ob.machine(rng)
        spot = plan.place(rng, mw, md, margin=0.8, tries=100)
        if spot is not None:
            put(b, mb, *spot)
    for _ in range(int(rng.integers(1, 4))):
        cab, cw_ = ob.electrical_cabinet(rng)
        spot = plan.place(rng, cw_, 0.6, against_wall=True, tries=60)
        if spot is not None:
            put(b, cab, *spot)
    if rng.random() < 0.6:
        spot = plan.place(rng, 4.0, 1.3, margin=0.8, free_yaw=True)
        if spot is not None:
            put(b, ob.forklift(rng), *spot)
    for _ in range(int(rng.integers(0, 3))):
        L = rng.uniform(4.0, 12.0)
        spot = plan.place(rng, L, 1.0, margin=1.0)
        if spot is not None:
            cx, cy, yaw = spot
            put(b, ob.conveyor(rng, L), cx, cy, round(yaw / (np.pi / 2)) * np.pi / 2)


def _mezzanine(site: _Hall, steel: Material) -> None:
    """A mezzanine with railings and stairs, against a wall."""
    rng, b, plan = site.rng, site.b, site.plan
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
            put(b, mz_b, cx, cy, yaw)


def _cable_trays(site: _Hall, cd: float) -> None:
    """Cable trays along the long walls."""
    rng, b, Lx, Ly = site.rng, site.b, site.Lx, site.Ly
    for y, s_ in ((0.3 + cd / 2 + 0.05, 1), (Ly - 0.3 - cd / 2 - 0.05, -1)):
        if rng.random() < 0.7:
            z = rng.uniform(3.0, 4.5)
            w = rng.uniform(0.2, 0.5)
            y0, y1 = sorted((y, y + s_ * w))
            b.box([0.3, y0, z], [Lx - 0.3, y1, z + 0.01], ob.METAL)
            b.box([0.3, y0, z], [Lx - 0.3, y0 + 0.01, z + 0.08], ob.METAL)
            b.box([0.3, y1 - 0.01, z], [Lx - 0.3, y1, z + 0.08], ob.METAL)
            b.count("cable tray")


def _floor_clutter(site: _Hall) -> None:
    """Pallets, clutter and bins on the floor."""
    rng, b, plan = site.rng, site.b, site.plan
    for _ in range(int(rng.integers(10, 30))):
        spot = plan.place(rng, 1.3, 1.3, margin=0.3, free_yaw=True)
        if spot is not None:
            u = rng.random()
            obj = (
                ob.pallet_stack(rng) if u < 0.4 else (ob.clutter(rng) if u < 0.8 else ob.bin_(rng))
            )
            put(b, obj, *spot)


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
