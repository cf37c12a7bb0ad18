"""Procedural objects for the scenes: furniture, street furniture, cars, trees, plant.

Each builder returns a :class:`~flexreg.synth.mesh.MeshBuilder` in the object's own frame:
footprint centred on the origin, standing on ``z = 0``, front towards ``+y`` (backs of
wall-standing objects at ``-y``). Dimensions are drawn from ``rng`` so no two objects are
identical; sizes are in metres.
"""

from __future__ import annotations

from itertools import pairwise

import numpy as np
from numpy.typing import ArrayLike

from flexreg.synth.mesh import Material, MeshBuilder, box, cylinder, ellipsoid, frustum, rot_z, tube

# ------------------------------------------------------------------ materials
PLASTER = Material(0.78, (226, 222, 212))
CEILING = Material(0.82, (240, 240, 236))
CONCRETE = Material(0.5, (152, 150, 144))
SCREED = Material(0.42, (128, 126, 120))
PARQUET = Material(0.4, (168, 128, 84))
WOOD = Material(0.45, (150, 108, 66))
DARK_WOOD = Material(0.3, (96, 64, 40))
WHITE_PAINT = Material(0.85, (236, 236, 232))
METAL = Material(0.45, (160, 164, 170))
DARK_METAL = Material(0.22, (70, 72, 78))
STEEL_BLUE = Material(0.35, (60, 90, 140))
SAFETY_YELLOW = Material(0.6, (230, 190, 30))
FABRIC = Material(0.28, (90, 100, 120))
PLASTIC = Material(0.5, (200, 60, 50))
CARDBOARD = Material(0.5, (190, 150, 100))
BOOK_COLOURS = [(150, 40, 40), (40, 80, 140), (50, 120, 60), (200, 180, 120), (30, 30, 30)]
ASPHALT = Material(0.12, (60, 60, 62))
PAVING = Material(0.38, (170, 160, 150))
GRANITE = Material(0.3, (120, 120, 124))
MARKING = Material(0.9, (245, 245, 240))
BRICK = Material(0.32, (150, 80, 60))
RENDER = Material(0.6, (210, 196, 170))
GLASS = Material(0.08, (60, 80, 90))
BARK = Material(0.2, (90, 70, 50))
FOLIAGE = Material(0.35, (70, 120, 50))
RUBBER = Material(0.06, (30, 30, 30))
CHROME = Material(0.7, (200, 200, 205))
SOIL = Material(0.15, (90, 70, 50))


def hexahedron(corners: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Convex hexahedron from 8 corners ordered like :func:`~flexreg.synth.mesh.box`'s."""
    _, T = box([0, 0, 0], [1, 1, 1])
    return np.asarray(corners, dtype=np.float64).reshape(8, 3), T


def _colour(rng: np.random.Generator, base: Material, spread: float = 0.15) -> Material:
    return base.jitter(rng, spread)


# ------------------------------------------------------------------ indoor furniture
def table(rng: np.random.Generator, w: float, d: float, h: float | None = None) -> MeshBuilder:
    """Table with four legs (or a pedestal) and a top, footprint ``w x d``."""
    b = MeshBuilder()
    h = rng.uniform(0.72, 0.76) if h is None else h
    top = rng.uniform(0.025, 0.045)
    mat = _colour(rng, WOOD if rng.random() < 0.6 else WHITE_PAINT)
    b.box([-w / 2, -d / 2, h - top], [w / 2, d / 2, h], mat)
    leg_mat = _colour(rng, METAL if rng.random() < 0.5 else DARK_WOOD)
    if rng.random() < 0.8:
        lw = rng.uniform(0.04, 0.07)
        inset = rng.uniform(0.03, 0.1)
        round_legs = rng.random() < 0.5
        for sx in (-1, 1):
            for sy in (-1, 1):
                cx, cy = sx * (w / 2 - inset - lw / 2), sy * (d / 2 - inset - lw / 2)
                if round_legs:
                    b.add(cylinder([cx, cy, 0], [cx, cy, h - top], lw / 2, segments=10), leg_mat)
                else:
                    b.box(
                        [cx - lw / 2, cy - lw / 2, 0], [cx + lw / 2, cy + lw / 2, h - top], leg_mat
                    )
        if rng.random() < 0.5:  # apron
            b.box(
                [-w / 2 + inset, -d / 2 + inset, h - top - 0.08],
                [w / 2 - inset, -d / 2 + inset + 0.02, h - top],
                mat,
            )
    else:
        b.add(cylinder([0, 0, 0.02], [0, 0, h - top], 0.05, segments=12), leg_mat)
        b.add(cylinder([0, 0, 0], [0, 0, 0.03], min(w, d) * 0.3, segments=20), leg_mat)
    b.count("table")
    return b


def chair(rng: np.random.Generator) -> MeshBuilder:
    """Chair with seat, back (towards -y) and legs; about 0.45 x 0.45 m."""
    b = MeshBuilder()
    w, d = rng.uniform(0.4, 0.5), rng.uniform(0.4, 0.5)
    sh = rng.uniform(0.43, 0.48)
    mat = _colour(rng, [WOOD, PLASTIC, FABRIC, DARK_METAL][rng.integers(4)], 0.25)
    leg = _colour(rng, METAL)
    b.box([-w / 2, -d / 2, sh - 0.04], [w / 2, d / 2, sh], mat)
    lw = 0.025
    for sx in (-1, 1):
        for sy in (-1, 1):
            cx, cy = sx * (w / 2 - lw), sy * (d / 2 - lw)
            b.add(cylinder([cx, cy, 0], [cx, cy, sh - 0.04], lw / 2 + 0.003, segments=8), leg)
    bh = rng.uniform(0.35, 0.5)
    tilt = rng.uniform(0.0, 0.15)
    back = box([-w / 2, -0.015, 0], [w / 2, 0.015, bh])
    R = np.array([[1, 0, 0], [0, np.cos(tilt), -np.sin(tilt)], [0, np.sin(tilt), np.cos(tilt)]])
    b.add(back, mat, R=R, t=[0, -d / 2 + 0.02, sh])
    b.count("chair")
    return b


def office_chair(rng: np.random.Generator) -> MeshBuilder:
    """Swivel chair: five-star base with castors, column, seat, back."""
    b = MeshBuilder()
    dark = _colour(rng, DARK_METAL)
    fab = _colour(rng, FABRIC, 0.3)
    for k in range(5):
        a = 2 * np.pi * k / 5 + rng.uniform(0, 0.3)
        end = [0.3 * np.cos(a), 0.3 * np.sin(a), 0.07]
        b.add(cylinder([0, 0, 0.09], end, 0.018, segments=6), dark)
        b.add(ellipsoid([end[0], end[1], 0.03], 0.03, subdivisions=1), dark)
    sh = rng.uniform(0.44, 0.52)
    b.add(cylinder([0, 0, 0.08], [0, 0, sh - 0.06], 0.025, segments=10), METAL)
    b.box([-0.24, -0.23, sh - 0.07], [0.24, 0.23, sh], fab)
    b.box([-0.22, -0.27, sh + 0.1], [0.22, -0.2, sh + rng.uniform(0.5, 0.65)], fab)
    b.box([-0.03, -0.26, sh - 0.04], [0.03, -0.22, sh + 0.12], dark)
    b.count("office chair")
    return b


def shelf(rng: np.random.Generator, w: float, d: float, h: float) -> MeshBuilder:
    """Open shelf unit (back at -y) filled with books, boxes and jars."""
    b = MeshBuilder()
    mat = _colour(rng, [WOOD, WHITE_PAINT, METAL][rng.integers(3)])
    t = 0.02
    b.box([-w / 2, -d / 2, 0], [-w / 2 + t, d / 2, h], mat)
    b.box([w / 2 - t, -d / 2, 0], [w / 2, d / 2, h], mat)
    b.box([-w / 2, -d / 2, 0], [w / 2, -d / 2 + 0.01, h], mat)  # back panel
    n_levels = int(rng.integers(4, 7))
    zs = np.linspace(0.05, h - t, n_levels)
    for z in zs:
        b.box([-w / 2 + t, -d / 2, z], [w / 2 - t, d / 2, z + t], mat)
    for z0, z1 in pairwise(zs):
        room_h = z1 - z0 - t
        x = -w / 2 + t + rng.uniform(0.0, 0.08)
        while x < w / 2 - t - 0.05:
            kind = rng.random()
            if kind < 0.45:  # a run of books
                n = int(rng.integers(3, 15))
                for _ in range(n):
                    bw = rng.uniform(0.015, 0.05)
                    bh = min(room_h - 0.01, rng.uniform(0.16, 0.32))
                    bd = min(d - 0.03, rng.uniform(0.12, 0.24))
                    if x + bw > w / 2 - t:
                        break
                    col = BOOK_COLOURS[rng.integers(len(BOOK_COLOURS))]
                    b.box(
                        [x, -d / 2 + 0.02, z0 + t],
                        [x + bw, -d / 2 + 0.02 + bd, z0 + t + bh],
                        Material(float(rng.uniform(0.15, 0.6)), col),
                    )
                    x += bw + rng.uniform(0.0, 0.004)
                x += rng.uniform(0.02, 0.1)
            elif kind < 0.7:  # a box
                bw = rng.uniform(0.1, 0.35)
                if x + bw > w / 2 - t:
                    break
                bh = min(room_h - 0.01, rng.uniform(0.06, 0.3))
                bd = min(d - 0.03, rng.uniform(0.1, d))
                b.box(
                    [x, -d / 2 + 0.02, z0 + t],
                    [x + bw, -d / 2 + 0.02 + bd, z0 + t + bh],
                    _colour(rng, CARDBOARD, 0.3),
                )
                x += bw + rng.uniform(0.01, 0.08)
            elif kind < 0.85:  # jars / bottles
                r = rng.uniform(0.03, 0.07)
                if x + 2 * r > w / 2 - t:
                    break
                hh = min(room_h - 0.01, rng.uniform(0.08, 0.3))
                cy = -d / 2 + 0.02 + r + rng.uniform(0, max(d - 2 * r - 0.04, 0))
                b.add(
                    cylinder([x + r, cy, z0 + t], [x + r, cy, z0 + t + hh], r, segments=12),
                    _colour(rng, PLASTIC, 0.4),
                )
                x += 2 * r + rng.uniform(0.01, 0.05)
            else:  # gap
                x += rng.uniform(0.05, 0.25)
    b.count("shelf")
    return b


def cabinet(rng: np.random.Generator, w: float, d: float, h: float) -> MeshBuilder:
    """Closed cabinet with door gaps and handles (back at -y)."""
    b = MeshBuilder()
    mat = _colour(rng, [WHITE_PAINT, WOOD, METAL][rng.integers(3)])
    b.box([-w / 2, -d / 2, 0.05], [w / 2, d / 2, h], mat)
    b.box([-w / 2 + 0.03, -d / 2 + 0.03, 0], [w / 2 - 0.03, d / 2 - 0.05, 0.05], DARK_METAL)
    n_doors = max(1, round(w / rng.uniform(0.4, 0.6)))
    dw = w / n_doors
    for k in range(n_doors):
        x0 = -w / 2 + k * dw
        b.box([x0 + 0.003, d / 2, 0.06], [x0 + dw - 0.003, d / 2 + 0.018, h - 0.01], mat)
        hx = x0 + (dw - 0.05 if k % 2 == 0 else 0.05)
        b.add(
            cylinder(
                [hx, d / 2 + 0.018, h * 0.55],
                [hx, d / 2 + 0.018, h * 0.55 + 0.12],
                0.008,
                segments=6,
            ),
            CHROME,
        )
    b.count("cabinet")
    return b


def sofa(rng: np.random.Generator, w: float) -> MeshBuilder:
    """Sofa (back at -y) with arms and cushions."""
    b = MeshBuilder()
    mat = _colour(rng, FABRIC, 0.4)
    d = rng.uniform(0.8, 0.95)
    b.box([-w / 2, -d / 2, 0.1], [w / 2, d / 2, 0.42], mat)
    b.box([-w / 2, -d / 2, 0.42], [w / 2, -d / 2 + 0.2, rng.uniform(0.75, 0.9)], mat)
    for sx in (-1, 1):
        b.box(
            [sx * w / 2 - (0.18 if sx > 0 else 0), -d / 2, 0.1],
            [sx * w / 2 + (0.18 if sx < 0 else 0), d / 2, 0.6],
            mat,
        )
    n = max(1, int((w - 0.36) // 0.6))
    cw = (w - 0.36) / n
    for k in range(n):
        x0 = -w / 2 + 0.18 + k * cw
        b.box([x0 + 0.01, -d / 2 + 0.2, 0.42], [x0 + cw - 0.01, d / 2 - 0.02, 0.5], mat)
    for sx in (-1, 1):
        for sy in (-1, 1):
            b.box(
                [sx * (w / 2 - 0.05) - 0.02, sy * (d / 2 - 0.05) - 0.02, 0],
                [sx * (w / 2 - 0.05) + 0.02, sy * (d / 2 - 0.05) + 0.02, 0.1],
                DARK_WOOD,
            )
    b.count("sofa")
    return b


def desk_items(rng: np.random.Generator, b: MeshBuilder, w: float, d: float, h: float) -> None:
    """Put a monitor, a laptop, mugs, books and papers on a table top at height ``h``."""
    n = int(rng.integers(1, 6))
    for _ in range(n):
        x = rng.uniform(-w / 2 + 0.15, w / 2 - 0.15)
        y = rng.uniform(-d / 2 + 0.12, d / 2 - 0.12)
        k = rng.random()
        if k < 0.25:  # monitor on a stand
            mw = rng.uniform(0.45, 0.7)
            b.box([x - 0.1, y - 0.08, h], [x + 0.1, y + 0.08, h + 0.015], DARK_METAL)
            b.box([x - 0.02, y - 0.02, h], [x + 0.02, y + 0.02, h + 0.12], DARK_METAL)
            b.box([x - mw / 2, y - 0.03, h + 0.1], [x + mw / 2, y, h + 0.1 + mw * 0.6], DARK_METAL)
            b.count("monitor")
        elif k < 0.45:  # laptop, lid open
            b.box([x - 0.17, y - 0.12, h], [x + 0.17, y + 0.12, h + 0.02], METAL)
            lid = box([-0.17, 0, 0], [0.17, 0.008, 0.23])
            a = rng.uniform(0.1, 0.4)
            R = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
            b.add(lid, METAL, R=R, t=[x, y - 0.12, h + 0.02])
        elif k < 0.7:  # mug or bottle
            r = rng.uniform(0.035, 0.045)
            hh = rng.uniform(0.09, 0.3)
            b.add(cylinder([x, y, h], [x, y, h + hh], r, segments=12), _colour(rng, PLASTIC, 0.5))
        else:  # pile of books / papers
            zz = h
            for _ in range(int(rng.integers(1, 5))):
                bw, bd, bh = rng.uniform(0.15, 0.3), rng.uniform(0.2, 0.3), rng.uniform(0.01, 0.05)
                yaw = rng.uniform(-0.3, 0.3)
                col = BOOK_COLOURS[rng.integers(len(BOOK_COLOURS))]
                b.add(
                    box([-bw / 2, -bd / 2, 0], [bw / 2, bd / 2, bh]),
                    Material(float(rng.uniform(0.2, 0.7)), col),
                    R=rot_z(yaw),
                    t=[x, y, zz],
                )
                zz += bh


def plant(rng: np.random.Generator, scale: float = 1.0) -> MeshBuilder:
    """Potted plant: frustum pot and one to three irregular leaf clusters."""
    b = MeshBuilder()
    r = rng.uniform(0.12, 0.25) * scale
    ph = rng.uniform(0.2, 0.45) * scale
    b.add(frustum([0, 0, 0], [0, 0, ph], r * 0.75, r, segments=16), _colour(rng, PLASTIC, 0.5))
    for _ in range(int(rng.integers(1, 4))):
        c = [rng.uniform(-r, r) * 0.5, rng.uniform(-r, r) * 0.5, ph + rng.uniform(0.2, 0.6) * scale]
        rad = rng.uniform(0.15, 0.35) * scale
        b.add(
            ellipsoid(
                c, [rad, rad, rad * rng.uniform(0.8, 1.5)], subdivisions=2, roughness=0.3, rng=rng
            ),
            _colour(rng, FOLIAGE, 0.3),
        )
    b.add(cylinder([0, 0, ph * 0.8], [0, 0, ph + 0.3 * scale], 0.015 * scale, segments=6), BARK)
    b.count("plant")
    return b


def clutter(rng: np.random.Generator) -> MeshBuilder:
    """A small floor item: stacked boxes, a bin, a ball, a crate or a bucket."""
    b = MeshBuilder()
    k = rng.random()
    if k < 0.4:
        z = 0.0
        for _ in range(int(rng.integers(1, 4))):
            w, d, h = rng.uniform(0.2, 0.6), rng.uniform(0.2, 0.5), rng.uniform(0.15, 0.45)
            b.add(
                box([-w / 2, -d / 2, 0], [w / 2, d / 2, h]),
                _colour(rng, CARDBOARD, 0.3),
                R=rot_z(rng.uniform(-0.4, 0.4)),
                t=[rng.uniform(-0.05, 0.05), 0, z],
            )
            z += h
        b.count("boxes")
    elif k < 0.6:
        r, h = rng.uniform(0.15, 0.25), rng.uniform(0.35, 0.7)
        b.add(frustum([0, 0, 0], [0, 0, h], r * 0.85, r, segments=16), _colour(rng, PLASTIC, 0.5))
        b.count("bin")
    elif k < 0.75:
        r = rng.uniform(0.1, 0.35)
        b.add(ellipsoid([0, 0, r], r, subdivisions=2), _colour(rng, PLASTIC, 0.6))
        b.count("ball")
    else:
        w, d, h = rng.uniform(0.4, 0.8), rng.uniform(0.3, 0.6), rng.uniform(0.25, 0.5)
        mat = _colour(rng, WOOD)
        for sy in (-1, 1):  # crate made of slats
            for z in np.arange(0.0, h - 0.05, 0.12):
                b.box(
                    [-w / 2, sy * d / 2 - 0.02 * (sy > 0), z],
                    [w / 2, sy * d / 2 + 0.02 * (sy < 0), z + 0.08],
                    mat,
                )
        for sx in (-1, 1):
            b.box(
                [sx * w / 2 - 0.02 * (sx > 0), -d / 2, 0],
                [sx * w / 2 + 0.02 * (sx < 0), d / 2, h],
                mat,
            )
        b.box([-w / 2, -d / 2, 0], [w / 2, d / 2, 0.02], mat)
        b.count("crate")
    return b


def stairs(
    rng: np.random.Generator, width: float, rise_total: float, *, material: Material | None = None
) -> tuple[MeshBuilder, float]:
    """Straight solid stair climbing along +y, with a landing and railing posts.

    Returns
    -------
    builder, run_length : MeshBuilder, float
        Total footprint length along y (steps plus landing), metres.
    """
    b = MeshBuilder()
    mat = material or _colour(rng, CONCRETE)
    n = max(3, round(rise_total / rng.uniform(0.16, 0.185)))
    rise = rise_total / n
    run = rng.uniform(0.26, 0.3)
    nosing = 0.02
    for k in range(n):
        b.box([-width / 2, k * run, 0], [width / 2, (k + 1) * run + nosing, (k + 1) * rise], mat)
    land = rng.uniform(1.0, 1.6)
    y_end = n * run + land
    b.box([-width / 2, n * run, 0], [width / 2, y_end, rise_total], mat)
    rail = _colour(rng, METAL)
    side = -1 if rng.random() < 0.5 else 1
    x = side * (width / 2 - 0.04)
    top = []
    for k in range(0, n + 1, 2):
        y = min(k, n) * run + run / 2
        z0 = min(k + 1, n) * rise
        b.add(cylinder([x, y, z0], [x, y, z0 + 0.9], 0.02, segments=8), rail)
        top.append([x, y, z0 + 0.9])
    for y in np.arange(n * run + 0.2, y_end, 0.5):
        b.add(cylinder([x, y, rise_total], [x, y, rise_total + 1.0], 0.02, segments=8), rail)
        top.append([x, y, rise_total + 1.0])
    if len(top) >= 2:
        pts = np.array(top)
        keep = np.r_[True, np.linalg.norm(np.diff(pts, axis=0), axis=1) > 1e-3]
        b.add(tube(pts[keep], 0.025, segments=8), rail)
    b.count("stairs")
    return b, y_end


def radiator(rng: np.random.Generator, w: float, h: float) -> MeshBuilder:
    """Column radiator (fins every ~5 cm) with supply pipes; back at -y, 6-10 cm deep."""
    b = MeshBuilder()
    mat = _colour(rng, WHITE_PAINT, 0.05)
    d = rng.uniform(0.06, 0.1)
    pitch = rng.uniform(0.045, 0.06)
    fin = pitch * rng.uniform(0.5, 0.7)
    x = -w / 2
    while x + fin <= w / 2:
        b.box([x, 0, 0.12], [x + fin, d, 0.12 + h], mat)
        x += pitch
    b.add(
        cylinder([-w / 2 - 0.05, d / 2, 0.14], [w / 2 + 0.05, d / 2, 0.14], 0.015, segments=8), mat
    )
    b.add(
        cylinder(
            [-w / 2 - 0.05, d / 2, 0.1 + h], [w / 2 + 0.05, d / 2, 0.1 + h], 0.015, segments=8
        ),
        mat,
    )
    b.add(
        cylinder([w / 2 + 0.05, d / 2, 0.0], [w / 2 + 0.05, d / 2, 0.14], 0.012, segments=8), METAL
    )
    b.add(
        cylinder([w / 2 + 0.05, d / 2, 0.1 + h], [w / 2 + 0.05, d / 2, 0.2 + h], 0.02, segments=8),
        CHROME,
    )
    b.count("radiator")
    return b


def pendant_lamp(rng: np.random.Generator, drop: float) -> MeshBuilder:
    """Lamp hanging ``drop`` metres below the ceiling (origin at the ceiling, hangs to -z)."""
    b = MeshBuilder()
    if rng.random() < 0.5:
        r = rng.uniform(0.15, 0.3)
        b.add(cylinder([0, 0, 0], [0, 0, -drop], 0.004, segments=4), DARK_METAL)
        b.add(
            frustum([0, 0, -drop - 0.22], [0, 0, -drop], r, 0.04, segments=16),
            _colour(rng, WHITE_PAINT),
        )
    else:
        w, d = rng.uniform(0.6, 1.4), rng.uniform(0.15, 0.6)
        for sx in (-1, 1):
            b.add(
                cylinder([sx * w / 3, 0, 0], [sx * w / 3, 0, -drop], 0.003, segments=4), DARK_METAL
            )
        b.box([-w / 2, -d / 2, -drop - 0.05], [w / 2, d / 2, -drop], _colour(rng, WHITE_PAINT))
    b.count("lamp")
    return b


# ------------------------------------------------------------------ outdoor objects
def tree(rng: np.random.Generator) -> MeshBuilder:
    """Tree: tapered trunk, a few branches and two to four irregular crown lobes."""
    b = MeshBuilder()
    r0 = rng.uniform(0.12, 0.3)
    h = rng.uniform(2.2, 4.0)
    lean = rng.normal(0, 0.05, size=2)
    trunk_top = np.array([lean[0] * h, lean[1] * h, h])
    b.add(
        tube(
            np.stack([np.zeros(3), trunk_top * 0.5, trunk_top]),
            [r0 * 1.15, r0 * 0.85, r0 * 0.6],
            segments=12,
        ),
        _colour(rng, BARK),
    )
    crown_r = rng.uniform(1.4, 3.0)
    for _ in range(int(rng.integers(2, 5))):
        off = rng.normal(0, crown_r * 0.35, size=3)
        off[2] = abs(off[2]) + crown_r * 0.6
        radii = crown_r * rng.uniform(0.55, 0.9, size=3)
        b.add(
            ellipsoid(trunk_top + off, radii, subdivisions=2, roughness=0.35, rng=rng),
            _colour(rng, FOLIAGE, 0.3),
        )
    for _ in range(int(rng.integers(2, 5))):
        a = rng.uniform(0, 2 * np.pi)
        z = rng.uniform(0.6, 0.95) * h
        end = [np.cos(a) * crown_r * 0.8, np.sin(a) * crown_r * 0.8, z + rng.uniform(0.5, 1.5)]
        b.add(frustum([lean[0] * z, lean[1] * z, z], end, r0 * 0.35, r0 * 0.12, segments=6), BARK)
    b.count("tree")
    return b


def street_lamp(rng: np.random.Generator) -> MeshBuilder:
    """Street lamp: base, tapered pole, arm towards +y and a luminaire."""
    b = MeshBuilder()
    h = rng.uniform(4.5, 8.0)
    mat = _colour(rng, DARK_METAL if rng.random() < 0.6 else METAL)
    b.add(cylinder([0, 0, 0], [0, 0, 0.5], rng.uniform(0.1, 0.15), segments=12), mat)
    b.add(frustum([0, 0, 0.5], [0, 0, h], rng.uniform(0.07, 0.1), 0.05, segments=12), mat)
    reach = rng.uniform(0.8, 2.0)
    b.add(
        tube([[0, 0, h - 0.3], [0, reach * 0.5, h], [0, reach, h + 0.05]], 0.035, segments=8), mat
    )
    b.box([-0.15, reach - 0.3, h - 0.1], [0.15, reach + 0.3, h + 0.05], mat)
    b.count("street lamp")
    return b


def bench(rng: np.random.Generator) -> MeshBuilder:
    """Park bench of wooden slats on two metal frames (back at -y)."""
    b = MeshBuilder()
    w = rng.uniform(1.5, 2.2)
    wood = _colour(rng, WOOD)
    metal = _colour(rng, DARK_METAL)
    for sx in (-1, 1):
        x = sx * (w / 2 - 0.15)
        b.box([x - 0.03, -0.25, 0], [x + 0.03, 0.25, 0.42], metal)
        b.box([x - 0.03, -0.28, 0.42], [x + 0.03, -0.22, 0.85], metal)
    for y in np.linspace(-0.2, 0.2, 4):
        b.box([-w / 2, y - 0.045, 0.42], [w / 2, y + 0.045, 0.45], wood)
    for z in (0.55, 0.7):
        b.box([-w / 2, -0.28, z], [w / 2, -0.25, z + 0.1], wood)
    b.count("bench")
    return b


def car(rng: np.random.Generator) -> MeshBuilder:
    """Car along +x: body, cabin with sloped glass, wheels, mirrors, lights and plates."""
    b = MeshBuilder()
    L = rng.uniform(3.8, 4.9)
    W = rng.uniform(1.7, 1.9)
    hb = rng.uniform(0.65, 0.85)
    clear = rng.uniform(0.15, 0.2)
    paint = Material.random(rng, float(rng.uniform(0.2, 0.8)), 20, 235)
    b.box([-L / 2, -W / 2, clear + 0.2], [L / 2, W / 2, clear + hb], paint)
    b.box(
        [-L / 2 + 0.1, -W / 2 + 0.05, clear], [L / 2 - 0.1, W / 2 - 0.05, clear + 0.2], DARK_METAL
    )
    # cabin as a sloped hexahedron
    ch = rng.uniform(0.5, 0.65)
    zb, zt = clear + hb, clear + hb + ch
    xr, xf = -L / 2 + rng.uniform(0.5, 1.0), L / 2 - rng.uniform(1.0, 1.4)
    xr_t, xf_t = xr + rng.uniform(0.2, 0.5), xf - rng.uniform(0.5, 0.8)
    wb, wt = W / 2 - 0.05, W / 2 - 0.2
    corners = [[xr, -wb, zb], [xf, -wb, zb], [xf, wb, zb], [xr, wb, zb],
               [xr_t, -wt, zt], [xf_t, -wt, zt], [xf_t, wt, zt], [xr_t, wt, zt]]  # fmt: skip
    b.add(hexahedron(corners), GLASS)
    b.box([xr_t + 0.05, -wt + 0.02, zt], [xf_t - 0.05, wt - 0.02, zt + 0.03], paint)  # roof
    r = rng.uniform(0.3, 0.34)
    tw = rng.uniform(0.19, 0.24)
    axle = L / 2 - rng.uniform(0.75, 0.95)
    for sx in (-1, 1):
        for sy in (-1, 1):
            cx, y0 = sx * axle, sy * (W / 2 - 0.02)
            b.add(cylinder([cx, y0 - sy * tw, r], [cx, y0, r], r, segments=20), RUBBER)
            b.add(cylinder([cx, y0, r], [cx, y0 + sy * 0.01, r], r * 0.6, segments=16), CHROME)
        # mirrors
        b.box(
            [xf - 0.05, sx * (W / 2) - 0.06 * (sx > 0), zb - 0.05],
            [xf + 0.1, sx * (W / 2 + 0.15) + 0.06 * (sx < 0), zb + 0.08],
            paint,
        )
    for sx in (-1, 1):  # lights and number plates (retro-reflective)
        x = sx * L / 2
        for sy in (-1, 1):
            b.box(
                [x - 0.02 * (sx > 0), sy * (W / 2 - 0.25) - 0.12, clear + hb - 0.2],
                [x + 0.02 * (sx < 0), sy * (W / 2 - 0.25) + 0.12, clear + hb - 0.08],
                CHROME,
            )
        b.box(
            [x - 0.01 * (sx > 0), -0.26, clear + 0.25],
            [x + 0.01 * (sx < 0), 0.26, clear + 0.37],
            MARKING,
        )
    b.count("car")
    return b


def bollard(rng: np.random.Generator) -> MeshBuilder:
    b = MeshBuilder()
    r = rng.uniform(0.06, 0.12)
    h = rng.uniform(0.7, 1.0)
    mat = _colour(rng, DARK_METAL)
    b.add(cylinder([0, 0, 0], [0, 0, h], r, segments=12), mat)
    b.add(ellipsoid([0, 0, h], [r, r, r * 0.5], subdivisions=1), mat)
    b.add(cylinder([0, 0, h - 0.15], [0, 0, h - 0.1], r + 0.005, segments=12), MARKING)
    b.count("bollard")
    return b


def sign_post(rng: np.random.Generator) -> MeshBuilder:
    """Traffic sign on a pole (round or rectangular plate facing +y)."""
    b = MeshBuilder()
    h = rng.uniform(2.2, 3.0)
    b.add(cylinder([0, 0, 0], [0, 0, h + 0.3], 0.03, segments=8), METAL)
    if rng.random() < 0.5:
        b.add(cylinder([0, 0.03, h], [0, 0.05, h], rng.uniform(0.3, 0.4), segments=24), MARKING)
    else:
        w = rng.uniform(0.4, 0.8)
        b.box([-w / 2, 0.03, h - w / 2], [w / 2, 0.05, h + w / 2], MARKING)
    b.count("sign")
    return b


def bike_stand(rng: np.random.Generator) -> MeshBuilder:
    """Row of inverted-U bike stands."""
    b = MeshBuilder()
    n = int(rng.integers(2, 6))
    a = np.linspace(0, np.pi, 9)
    for k in range(n):
        x = (k - (n - 1) / 2) * rng.uniform(0.7, 0.9)
        path = np.stack([np.full(9, x), 0.35 * np.cos(a), 0.45 + 0.35 * np.sin(a)], -1)
        path = np.vstack([[x, 0.35, 0.0], path, [x, -0.35, 0.0]])
        b.add(tube(path, 0.025, segments=8), CHROME)
    b.count("bike stand")
    return b


def bin_(rng: np.random.Generator) -> MeshBuilder:
    b = MeshBuilder()
    mat = _colour(rng, [DARK_METAL, PLASTIC, STEEL_BLUE][rng.integers(3)])
    if rng.random() < 0.5:
        r, h = rng.uniform(0.2, 0.3), rng.uniform(0.8, 1.0)
        b.add(cylinder([0, 0, 0.05], [0, 0, h], r, segments=16), mat)
        b.add(cylinder([0, 0, 0], [0, 0, 0.05], r * 0.3, segments=8), mat)
    else:  # wheelie bin
        w, d, h = rng.uniform(0.5, 0.7), rng.uniform(0.55, 0.75), rng.uniform(0.95, 1.1)
        b.box([-w / 2, -d / 2, 0.05], [w / 2, d / 2, h], mat)
        b.box([-w / 2 - 0.02, -d / 2 - 0.03, h], [w / 2 + 0.02, d / 2 + 0.02, h + 0.04], mat)
        for sx in (-1, 1):
            b.add(
                cylinder(
                    [sx * (w / 2 - 0.04), -d / 2, 0.1],
                    [sx * (w / 2 + 0.01), -d / 2, 0.1],
                    0.1,
                    segments=12,
                ),
                RUBBER,
            )
    b.count("bin")
    return b


def planter(rng: np.random.Generator) -> MeshBuilder:
    """Concrete planter box with a shrub."""
    b = MeshBuilder()
    w, d, h = rng.uniform(0.8, 2.0), rng.uniform(0.6, 1.2), rng.uniform(0.4, 0.7)
    b.box([-w / 2, -d / 2, 0], [w / 2, d / 2, h], _colour(rng, CONCRETE))
    b.add(
        ellipsoid(
            [0, 0, h + 0.2],
            [w * 0.45, d * 0.45, rng.uniform(0.3, 0.7)],
            subdivisions=2,
            roughness=0.3,
            rng=rng,
        ),
        _colour(rng, FOLIAGE, 0.3),
    )
    b.count("planter")
    return b


def shelter(rng: np.random.Generator) -> MeshBuilder:
    """Bus shelter: four posts, roof slab, back and side panels (back at -y)."""
    b = MeshBuilder()
    w, d, h = rng.uniform(3.0, 4.5), rng.uniform(1.3, 1.8), rng.uniform(2.3, 2.6)
    m = _colour(rng, METAL)
    for sx in (-1, 1):
        for sy in (-1, 1):
            x, y = sx * (w / 2 - 0.05), sy * (d / 2 - 0.05)
            b.box([x - 0.04, y - 0.04, 0], [x + 0.04, y + 0.04, h], m)
    b.box([-w / 2 - 0.1, -d / 2 - 0.1, h], [w / 2 + 0.1, d / 2 + 0.15, h + 0.1], m)
    b.box([-w / 2 + 0.1, -d / 2 - 0.01, 0.15], [w / 2 - 0.1, -d / 2 + 0.01, h - 0.1], GLASS)
    b.box([-w / 2 - 0.01, -d / 2 + 0.1, 0.15], [-w / 2 + 0.01, d / 2 - 0.3, h - 0.1], GLASS)
    b.box([-w / 2 + 0.3, -d / 2 + 0.05, 0.45], [w / 2 - 0.3, -d / 2 + 0.4, 0.5], m)
    b.count("shelter")
    return b


# ------------------------------------------------------------------ industrial objects
def i_beam(
    p0: ArrayLike,
    p1: ArrayLike,
    depth: float,
    width: float,
    b: MeshBuilder,
    material: Material,
    *,
    up: ArrayLike = (0.0, 0.0, 1.0),
) -> None:
    """Add an I-section (two flanges, one web) from ``p0`` to ``p1``; the web lies along ``up``."""
    a = np.asarray(p0, dtype=np.float64)
    c = np.asarray(p1, dtype=np.float64)
    ax = c - a
    length = float(np.linalg.norm(ax))
    x = ax / length
    u = np.asarray(up, dtype=np.float64)
    u = u - np.dot(u, x) * x
    if np.linalg.norm(u) < 1e-9:
        u = np.array([1.0, 0.0, 0.0]) - x[0] * x
    z = u / np.linalg.norm(u)
    y = np.cross(z, x)
    R = np.stack([x, y, z], axis=1)
    tf = max(0.01, depth * 0.08)
    tw = max(0.008, width * 0.05)
    b.add(
        box([0, -width / 2, -depth / 2], [length, width / 2, -depth / 2 + tf]), material, R=R, t=a
    )
    b.add(box([0, -width / 2, depth / 2 - tf], [length, width / 2, depth / 2]), material, R=R, t=a)
    b.add(box([0, -tw / 2, -depth / 2 + tf], [length, tw / 2, depth / 2 - tf]), material, R=R, t=a)


def tank(rng: np.random.Generator) -> tuple[MeshBuilder, float]:
    """Vertical tank on a pad with a domed head, ladder, nozzles and flanges.

    Returns
    -------
    builder, radius_of_footprint
    """
    b = MeshBuilder()
    r = rng.uniform(0.8, 2.0)
    h = rng.uniform(2.5, 6.0)
    mat = _colour(rng, [WHITE_PAINT, METAL, STEEL_BLUE][rng.integers(3)])
    pad = r + 0.3
    b.box([-pad, -pad, 0], [pad, pad, 0.2], CONCRETE)
    legs = rng.random() < 0.4
    z0 = 0.2
    if legs:
        leg_h = rng.uniform(0.6, 1.5)
        for k in range(4):
            a = np.pi / 4 + k * np.pi / 2
            b.add(
                cylinder(
                    [0.8 * r * np.cos(a), 0.8 * r * np.sin(a), 0.2],
                    [0.8 * r * np.cos(a), 0.8 * r * np.sin(a), 0.2 + leg_h + 0.1],
                    0.06,
                    segments=8,
                ),
                DARK_METAL,
            )
        z0 += leg_h
        b.add(frustum([0, 0, z0 - 0.4], [0, 0, z0], 0.15, r, segments=32), mat)
    b.add(cylinder([0, 0, z0], [0, 0, z0 + h], r, segments=40), mat)
    from flexreg.synth.mesh import dome

    b.add(dome([0, 0, z0 + h], r, r * rng.uniform(0.2, 0.4), segments=40), mat)
    for z in np.arange(z0 + 1.0, z0 + h, rng.uniform(1.2, 2.0)):  # stiffening rings
        b.add(cylinder([0, 0, z], [0, 0, z + 0.05], r + 0.02, segments=40), mat)
    # ladder up the side
    a = rng.uniform(0, 2 * np.pi)
    n = np.array([np.cos(a), np.sin(a), 0.0])
    t = np.array([-np.sin(a), np.cos(a), 0.0])
    base = n * (r + 0.2)
    for s in (-0.22, 0.22):
        p = base + s * t
        b.add(
            cylinder([p[0], p[1], 0.2], [p[0], p[1], z0 + h + 1.0], 0.02, segments=6), SAFETY_YELLOW
        )
    for z in np.arange(0.5, z0 + h + 0.9, 0.3):
        p0, p1 = base - 0.22 * t, base + 0.22 * t
        b.add(cylinder([p0[0], p0[1], z], [p1[0], p1[1], z], 0.012, segments=6), SAFETY_YELLOW)
    # nozzles with flanges
    for _ in range(int(rng.integers(2, 6))):
        a2 = rng.uniform(0, 2 * np.pi)
        if abs(np.angle(np.exp(1j * (a2 - a)))) < 0.5:
            continue
        z = rng.uniform(z0 + 0.4, z0 + h - 0.3)
        rn = rng.uniform(0.04, 0.15)
        d = np.array([np.cos(a2), np.sin(a2), 0.0])
        p_in, p_out = d * (r - 0.05) + [0, 0, z], d * (r + rng.uniform(0.2, 0.4)) + [0, 0, z]
        b.add(cylinder(p_in, p_out, rn, segments=12), mat)
        b.add(cylinder(p_out - d * 0.03, p_out, rn * 1.6, segments=16), METAL)
    b.count("tank")
    return b, pad


def pallet_rack(
    rng: np.random.Generator, length: float, depth: float, height: float
) -> MeshBuilder:
    """Pallet rack along +x: uprights, braced frames, beams, pallets with varied loads."""
    b = MeshBuilder()
    orange = _colour(rng, Material(0.45, (220, 110, 30)), 0.1)
    blue = _colour(rng, STEEL_BLUE, 0.1)
    bay = rng.uniform(2.4, 2.9)
    n_bays = max(1, int(length // bay))
    bay = length / n_bays
    levels = np.sort(rng.uniform(1.2, 2.0, size=int(rng.integers(2, 5))).cumsum())
    levels = levels[levels < height - 0.3]
    xs = -length / 2 + bay * np.arange(n_bays + 1)
    for x in xs:
        for y in (-depth / 2, depth / 2):
            b.box([x - 0.04, y - 0.04, 0], [x + 0.04, y + 0.04, height], blue)
        # frame bracing (zig-zag)
        zs = np.arange(0.15, height - 0.1, 0.9)
        for k, (za, zb) in enumerate(pairwise(zs)):
            ya, yb = (-depth / 2, depth / 2) if k % 2 == 0 else (depth / 2, -depth / 2)
            b.add(cylinder([x, ya, za], [x, yb, zb], 0.015, segments=6), blue)
    for x0, x1 in pairwise(xs):
        for z in np.concatenate([[0.0], levels]):
            if z > 0:
                for y in (-depth / 2, depth / 2):
                    b.box([x0 + 0.04, y - 0.03, z - 0.12], [x1 - 0.04, y + 0.03, z], orange)
            n_pal = int((bay - 0.1) // 1.0)
            for k in range(n_pal):
                if rng.random() < 0.25:
                    continue
                px = x0 + 0.1 + k * (bay - 0.1) / n_pal + 0.05
                pw = min(0.9, (bay - 0.1) / n_pal - 0.1)
                b.box(
                    [px, -depth / 2 + 0.05, z],
                    [px + pw, depth / 2 - 0.05, z + 0.14],
                    _colour(rng, WOOD),
                )
                top = (
                    levels[levels > z + 0.01].min() if np.any(levels > z + 0.01) else height
                ) - 0.2
                load_h = rng.uniform(0.3, max(0.35, top - z - 0.2))
                if rng.random() < 0.3:  # drums
                    for dx in (0.22, pw - 0.22):
                        b.add(
                            cylinder(
                                [px + dx, 0, z + 0.14],
                                [px + dx, 0, z + 0.14 + min(0.9, load_h)],
                                0.2,
                                segments=16,
                            ),
                            _colour(rng, PLASTIC, 0.5),
                        )
                else:  # stacked cartons
                    zz = z + 0.14
                    while zz < z + 0.14 + load_h - 0.1:
                        hh = rng.uniform(0.15, 0.5)
                        shrink = rng.uniform(0.0, 0.08, size=2)
                        b.box(
                            [px + shrink[0], -depth / 2 + 0.08 + shrink[1], zz],
                            [px + pw - shrink[1], depth / 2 - 0.08 - shrink[0], zz + hh],
                            _colour(rng, CARDBOARD, 0.3),
                        )
                        zz += hh
    b.count("rack")
    return b


def machine(rng: np.random.Generator) -> tuple[MeshBuilder, float, float]:
    """Machine: base, housing blocks, motor cylinders, control cabinet and a guard fence.

    Returns
    -------
    builder, width, depth
    """
    b = MeshBuilder()
    w, d = rng.uniform(2.0, 5.0), rng.uniform(1.5, 3.0)
    body = _colour(rng, Material(0.45, (90, 140, 110)), 0.3)
    b.box([-w / 2, -d / 2, 0], [w / 2, d / 2, 0.3], DARK_METAL)
    for _ in range(int(rng.integers(2, 6))):
        bw, bd, bh = rng.uniform(0.4, w * 0.6), rng.uniform(0.4, d * 0.8), rng.uniform(0.4, 2.0)
        cx = rng.uniform(-w / 2 + bw / 2, w / 2 - bw / 2)
        cy = rng.uniform(-d / 2 + bd / 2, d / 2 - bd / 2)
        b.box([cx - bw / 2, cy - bd / 2, 0.3], [cx + bw / 2, cy + bd / 2, 0.3 + bh], body)
    for _ in range(int(rng.integers(1, 4))):
        r = rng.uniform(0.12, 0.35)
        L = rng.uniform(0.4, 1.2)
        cx, cy = rng.uniform(-w / 2 + L / 2, w / 2 - L / 2), rng.uniform(-d / 2 + r, d / 2 - r)
        z = 0.3 + r
        b.add(cylinder([cx - L / 2, cy, z], [cx + L / 2, cy, z], r, segments=20), STEEL_BLUE)
        for k in np.linspace(-L / 2 + 0.05, L / 2 - 0.05, 5):  # cooling fins
            b.add(
                cylinder([cx + k - 0.01, cy, z], [cx + k + 0.01, cy, z], r + 0.03, segments=20),
                STEEL_BLUE,
            )
    b.box(
        [w / 2 - 0.6, d / 2 + 0.3, 0],
        [w / 2, d / 2 + 0.7, 2.0],
        _colour(rng, Material(0.6, (200, 200, 190))),
    )
    b.count("machine")
    return b, w, d + 0.7


def conveyor(rng: np.random.Generator, length: float) -> MeshBuilder:
    """Roller conveyor along +x on legs (rollers every ~10 cm)."""
    b = MeshBuilder()
    w = rng.uniform(0.5, 0.9)
    h = rng.uniform(0.7, 0.9)
    frame = _colour(rng, METAL)
    for sy in (-1, 1):
        b.box([-length / 2, sy * w / 2 - 0.03, h - 0.15], [length / 2, sy * w / 2 + 0.03, h], frame)
    for x in np.arange(-length / 2 + 0.2, length / 2, rng.uniform(1.5, 2.2)):
        for sy in (-1, 1):
            b.box([x - 0.03, sy * w / 2 - 0.03, 0], [x + 0.03, sy * w / 2 + 0.03, h - 0.15], frame)
    pitch = rng.uniform(0.08, 0.12)
    for x in np.arange(-length / 2 + 0.05, length / 2 - 0.03, pitch):
        b.add(
            cylinder([x, -w / 2 + 0.03, h - 0.03], [x, w / 2 - 0.03, h - 0.03], 0.025, segments=8),
            CHROME,
        )
    for _ in range(int(rng.integers(0, 4))):
        x = rng.uniform(-length / 2 + 0.4, length / 2 - 0.4)
        s = rng.uniform(0.2, 0.5)
        b.box(
            [x - s / 2, -min(s, w) / 2 + 0.02, h],
            [x + s / 2, min(s, w) / 2 - 0.02, h + rng.uniform(0.1, 0.4)],
            _colour(rng, CARDBOARD, 0.3),
        )
    b.count("conveyor")
    return b


# ------------------------------------------------------------------ additions
def wall_item(rng: np.random.Generator) -> tuple[MeshBuilder, float, float, float]:
    """An item fixed to a wall (local frame: x along the wall, y out of it, z up, origin at its
    bottom centre on the wall face): picture, whiteboard, clock, socket/switch box, wall cabinet,
    coat rack or a cable tray.

    Returns
    -------
    builder, width, bottom_height, top_height
    """
    b = MeshBuilder()
    k = rng.random()
    if k < 0.3:  # picture with a frame
        w, h = rng.uniform(0.3, 1.2), rng.uniform(0.3, 0.9)
        z0 = rng.uniform(1.2, 1.7) - h / 2
        b.box([-w / 2, 0, z0], [w / 2, 0.02, z0 + h], _colour(rng, DARK_WOOD, 0.3))
        b.box(
            [-w / 2 + 0.04, 0.02, z0 + 0.04],
            [w / 2 - 0.04, 0.025, z0 + h - 0.04],
            Material.random(rng, float(rng.uniform(0.1, 0.9)), 20, 235),
        )
        b.count("picture")
    elif k < 0.42:  # whiteboard with a tray
        w, h = rng.uniform(1.2, 2.4), rng.uniform(0.9, 1.2)
        z0 = 0.9
        b.box([-w / 2, 0, z0], [w / 2, 0.025, z0 + h], MARKING)
        b.box([-w / 2, 0, z0 - 0.03], [w / 2, 0.08, z0], METAL)
        b.count("whiteboard")
        return b, w, z0 - 0.03, z0 + h
    elif k < 0.52:  # clock
        r = rng.uniform(0.12, 0.2)
        z0 = rng.uniform(2.0, 2.3)
        b.add(cylinder([0, 0, z0 + r], [0, 0.04, z0 + r], r, segments=24), WHITE_PAINT)
        b.count("clock")
        return b, 2 * r, z0, z0 + 2 * r
    elif k < 0.7:  # switches / sockets / small electrical box
        w = rng.uniform(0.08, 0.35)
        h = rng.uniform(0.08, 0.4)
        z0 = float(rng.choice([0.25, 1.05, rng.uniform(0.3, 1.8)]))
        b.box(
            [-w / 2, 0, z0], [w / 2, rng.uniform(0.01, 0.1), z0 + h], _colour(rng, WHITE_PAINT, 0.1)
        )
        b.count("electrical box")
        return b, w, z0, z0 + h
    elif k < 0.85:  # wall cabinet
        w, h, d = rng.uniform(0.6, 1.6), rng.uniform(0.5, 0.8), rng.uniform(0.25, 0.38)
        z0 = rng.uniform(1.4, 1.7)
        mat = _colour(rng, [WHITE_PAINT, WOOD][rng.integers(2)])
        b.box([-w / 2, 0, z0], [w / 2, d, z0 + h], mat)
        b.box([-0.005, d, z0 + 0.01], [0.005, d + 0.01, z0 + h - 0.01], DARK_METAL)
        b.count("wall cabinet")
        return b, w, z0, z0 + h
    else:  # coat rack: a board with hooks
        w = rng.uniform(0.6, 1.4)
        z0 = rng.uniform(1.5, 1.7)
        b.box([-w / 2, 0, z0], [w / 2, 0.02, z0 + 0.1], _colour(rng, WOOD))
        for x in np.arange(-w / 2 + 0.08, w / 2 - 0.05, rng.uniform(0.12, 0.2)):
            b.add(
                tube(
                    [[x, 0.02, z0 + 0.05], [x, 0.08, z0 + 0.05], [x, 0.1, z0 + 0.09]],
                    0.008,
                    segments=6,
                ),
                CHROME,
            )
        b.count("coat rack")
        return b, w, z0, z0 + 0.1
    return b, w, z0, z0 + h


def desk(rng: np.random.Generator, w: float, d: float) -> MeshBuilder:
    """Office desk (back at -y) with a drawer block, items and an office chair in front."""
    b = MeshBuilder()
    h = rng.uniform(0.72, 0.76)
    mat = _colour(rng, [WHITE_PAINT, WOOD][rng.integers(2)])
    b.box([-w / 2, -d / 2, h - 0.03], [w / 2, d / 2, h], mat)
    for sx in (-1, 1):
        b.box(
            [sx * w / 2 - (0.03 if sx > 0 else 0), -d / 2, 0],
            [sx * w / 2 + (0.03 if sx < 0 else 0), d / 2, h - 0.03],
            mat,
        )
    b.box([-w / 2 + 0.03, -d / 2, h - 0.45], [w / 2 - 0.03, -d / 2 + 0.02, h - 0.03], mat)
    if rng.random() < 0.7:
        dw = 0.42
        x0 = w / 2 - 0.03 - dw if rng.random() < 0.5 else -w / 2 + 0.03
        b.box([x0, -d / 2 + 0.05, 0.02], [x0 + dw, d / 2 - 0.02, h - 0.05], mat)
        for z in np.linspace(0.1, h - 0.15, 3):
            b.box(
                [x0 + dw / 2 - 0.06, d / 2 - 0.02, z + 0.08],
                [x0 + dw / 2 + 0.06, d / 2, z + 0.1],
                CHROME,
            )
    desk_items(rng, b, w, d, h)
    if rng.random() < 0.8:
        b.extend(
            office_chair(rng),
            R=rot_z(np.pi + rng.normal(0, 0.4)),
            t=[rng.uniform(-w / 4, w / 4), d / 2 + rng.uniform(0.2, 0.45), 0],
        )
    b.count("desk")
    return b


def pallet_stack(rng: np.random.Generator) -> MeshBuilder:
    """Stack of empty pallets or a pallet with a wrapped load, on the floor."""
    b = MeshBuilder()
    wood = _colour(rng, WOOD)
    n = int(rng.integers(1, 8))
    z = 0.0
    for _ in range(n):
        for y in (-0.35, 0.0, 0.35):  # runners
            b.box([-0.6, y - 0.05, z], [0.6, y + 0.05, z + 0.1], wood)
        for x in np.linspace(-0.55, 0.55, 5):  # deck boards
            b.box([x - 0.05, -0.4, z + 0.1], [x + 0.05, 0.4, z + 0.125], wood)
        z += 0.125 + rng.uniform(0.0, 0.01)
    if n <= 2 and rng.random() < 0.7:
        h = rng.uniform(0.5, 1.5)
        b.box(
            [-0.58, -0.38, z],
            [0.58, 0.38, z + h],
            _colour(rng, Material(0.55, (200, 200, 210)), 0.2),
        )
    b.count("pallets")
    return b


def forklift(rng: np.random.Generator) -> MeshBuilder:
    """Forklift along +x: body, overhead guard, mast, forks, wheels."""
    b = MeshBuilder()
    paint = _colour(rng, SAFETY_YELLOW if rng.random() < 0.6 else PLASTIC, 0.1)
    L, W = rng.uniform(2.2, 2.8), rng.uniform(1.0, 1.2)
    b.box([-L / 2, -W / 2, 0.2], [L / 2 - 0.4, W / 2, 1.1], paint)
    b.box([-L / 2, -W / 2, 1.1], [-L / 2 + 0.5, W / 2, 1.3], DARK_METAL)  # counterweight
    for sx in (-1, 1):
        for sy in (-1, 1):
            x = -L / 2 + 0.2 if sx < 0 else L / 2 - 0.6
            b.box(
                [x - 0.03, sy * W / 2 - 0.03, 1.1], [x + 0.03, sy * W / 2 + 0.03, 2.1], DARK_METAL
            )
            b.add(
                cylinder(
                    [sx * (L / 2 - 0.6), sy * (W / 2 - 0.1), 0.25],
                    [sx * (L / 2 - 0.6), sy * (W / 2 + 0.02), 0.25],
                    0.25,
                    segments=16,
                ),
                RUBBER,
            )
    b.box([-L / 2 + 0.15, -W / 2, 2.1], [L / 2 - 0.55, W / 2, 2.15], DARK_METAL)
    b.box([-0.2, -0.25, 1.1], [0.2, 0.25, 1.6], FABRIC)  # seat
    mh = rng.uniform(2.0, 2.6)
    for sy in (-1, 1):
        b.box([L / 2 - 0.4, sy * 0.35 - 0.04, 0.1], [L / 2 - 0.3, sy * 0.35 + 0.04, mh], DARK_METAL)
    fz = rng.uniform(0.05, 1.2)
    for sy in (-1, 1):
        b.box(
            [L / 2 - 0.3, sy * 0.3 - 0.05, fz],
            [L / 2 - 0.25, sy * 0.3 + 0.05, fz + 0.5],
            DARK_METAL,
        )
        b.box(
            [L / 2 - 0.3, sy * 0.3 - 0.05, fz],
            [L / 2 + 0.9, sy * 0.3 + 0.05, fz + 0.05],
            DARK_METAL,
        )
    b.count("forklift")
    return b


def electrical_cabinet(rng: np.random.Generator) -> tuple[MeshBuilder, float]:
    """Row of electrical cabinets (back at -y) with door seams and handles; returns width."""
    b = MeshBuilder()
    n = int(rng.integers(1, 5))
    mat = _colour(rng, Material(0.6, (200, 200, 192)), 0.05)
    w1 = rng.uniform(0.6, 0.8)
    h = rng.uniform(1.8, 2.2)
    d = rng.uniform(0.4, 0.6)
    for i in range(n):
        x0 = -n * w1 / 2 + i * w1
        b.box([x0 + 0.002, -d / 2, 0.1], [x0 + w1 - 0.002, d / 2, h], mat)
        b.box([x0 + 0.05, d / 2, h * 0.5], [x0 + 0.07, d / 2 + 0.03, h * 0.5 + 0.15], DARK_METAL)
    b.box([-n * w1 / 2, -d / 2, 0], [n * w1 / 2, d / 2 - 0.05, 0.1], DARK_METAL)
    b.count("electrical cabinet", n)
    return b, n * w1


def awning(rng: np.random.Generator, w: float) -> MeshBuilder:
    """Sloped awning over a shop window (wall face at y = 0, sticks out to +y)."""
    b = MeshBuilder()
    d = rng.uniform(0.8, 1.6)
    drop = rng.uniform(0.3, 0.6)
    col = Material.random(rng, 0.5, 40, 230)
    corners = [[-w / 2, 0, 0], [w / 2, 0, 0], [w / 2, d, -drop], [-w / 2, d, -drop],
               [-w / 2, 0, 0.03], [w / 2, 0, 0.03], [w / 2, d, 0.03 - drop],
               [-w / 2, d, 0.03 - drop]]  # fmt: skip
    b.add(hexahedron(corners), col)
    b.box([-w / 2, d - 0.01, -drop - 0.25], [w / 2, d + 0.01, -drop + 0.02], col)
    b.count("awning")
    return b


def ac_unit(rng: np.random.Generator) -> MeshBuilder:
    """Outdoor air-conditioning unit on brackets (wall at y = 0)."""
    b = MeshBuilder()
    w, h, d = rng.uniform(0.7, 0.95), rng.uniform(0.5, 0.7), rng.uniform(0.25, 0.35)
    b.box([-w / 2, 0.08, 0], [w / 2, 0.08 + d, h], WHITE_PAINT)
    b.add(
        cylinder([-w / 6, 0.08 + d, h / 2], [-w / 6, 0.1 + d, h / 2], h * 0.38, segments=20),
        DARK_METAL,
    )
    for sx in (-1, 1):
        b.box([sx * w / 3 - 0.02, 0, -0.05], [sx * w / 3 + 0.02, 0.08 + d, 0.0], DARK_METAL)
    b.count("ac unit")
    return b


def entrance_steps(rng: np.random.Generator, w: float) -> tuple[MeshBuilder, float, float]:
    """One to three steps up to a door (wall at y = 0, steps to +y).

    Returns
    -------
    builder, depth, height : MeshBuilder, float, float
    """
    b = MeshBuilder()
    n = int(rng.integers(1, 4))
    run = rng.uniform(0.28, 0.35)
    rise = rng.uniform(0.12, 0.17)
    mat = _colour(rng, GRANITE)
    for k in range(n):
        b.box([-w / 2, 0, 0], [w / 2, (n - k) * run, (k + 1) * rise], mat)
    b.count("entrance steps")
    return b, n * run, n * rise


def fence(rng: np.random.Generator) -> MeshBuilder:
    """Fence segment along x: posts every 1.5-2 m with two or three rails, or a low wall."""
    b = MeshBuilder()
    L = rng.uniform(3.0, 4.0)
    if rng.random() < 0.4:  # low garden wall with a coping stone
        h = rng.uniform(0.5, 1.0)
        mat = _colour(rng, [BRICK, CONCRETE][rng.integers(2)])
        b.box([-L / 2, -0.12, 0], [L / 2, 0.12, h], mat)
        b.box([-L / 2 - 0.03, -0.16, h], [L / 2 + 0.03, 0.16, h + 0.06], GRANITE)
        b.count("low wall")
        return b
    mat = _colour(rng, [DARK_METAL, WOOD][rng.integers(2)])
    h = rng.uniform(0.9, 1.3)
    n = max(2, int(L // rng.uniform(1.5, 2.0)) + 1)
    for x in np.linspace(-L / 2, L / 2, n):
        b.box([x - 0.04, -0.04, 0], [x + 0.04, 0.04, h], mat)
    for z in np.linspace(0.25, h - 0.08, int(rng.integers(2, 4))):
        b.box([-L / 2, -0.02, z], [L / 2, 0.02, z + 0.06], mat)
    b.count("fence")
    return b


def kiosk(rng: np.random.Generator) -> MeshBuilder:
    """Small kiosk: a box with a counter opening, an overhanging roof and a sign."""
    b = MeshBuilder()
    w, d, h = rng.uniform(2.0, 3.0), rng.uniform(1.5, 2.2), rng.uniform(2.4, 2.8)
    mat = _colour(rng, Material(0.5, (120, 140, 90)), 0.3)
    b.box([-w / 2, -d / 2, 0], [w / 2, d / 2, 1.0], mat)
    b.box([-w / 2, -d / 2, 1.0], [w / 2, -d / 2 + 0.1, h], mat)
    for sx in (-1, 1):
        b.box(
            [sx * w / 2 - (0.1 if sx > 0 else 0), -d / 2, 1.0],
            [sx * w / 2 + (0.1 if sx < 0 else 0), d / 2, h],
            mat,
        )
    b.box([-w / 2, d / 2 - 0.1, 1.9], [w / 2, d / 2, h], mat)
    b.box([-w / 2 + 0.1, d / 2 - 0.3, 1.0], [w / 2 - 0.1, d / 2 + 0.25, 1.05], WOOD)  # counter
    b.box([-w / 2 - 0.3, -d / 2 - 0.2, h], [w / 2 + 0.3, d / 2 + 0.6, h + 0.12], DARK_METAL)
    b.box([-w / 2 + 0.2, d / 2 + 0.5, h + 0.12], [w / 2 - 0.2, d / 2 + 0.55, h + 0.5], MARKING)
    b.count("kiosk")
    return b
