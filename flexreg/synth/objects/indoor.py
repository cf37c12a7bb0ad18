"""Indoor furniture and fittings: tables, chairs, shelves, cabinets, sofas, desk items,
plants, clutter, stairs, radiators, lamps and things on walls."""

from __future__ import annotations

from itertools import pairwise

import numpy as np

from flexreg.synth.mesh import (
    Material,
    MeshBuilder,
    box,
    cylinder,
    ellipsoid,
    frustum,
    rot_z,
    tube,
)
from flexreg.synth.objects.materials import (
    BARK,
    BOOK_COLOURS,
    CARDBOARD,
    CHROME,
    CONCRETE,
    DARK_METAL,
    DARK_WOOD,
    FABRIC,
    FOLIAGE,
    MARKING,
    METAL,
    PLASTIC,
    WHITE_PAINT,
    WOOD,
)


def table(rng: np.random.Generator, w: float, d: float, h: float | None = None) -> MeshBuilder:
    """Table with four legs (or a pedestal) and a top, footprint ``w x d``."""
    b = MeshBuilder()
    h = rng.uniform(0.72, 0.76) if h is None else h
    top = rng.uniform(0.025, 0.045)
    mat = (WOOD if rng.random() < 0.6 else WHITE_PAINT).jitter(rng, 0.15)
    b.box([-w / 2, -d / 2, h - top], [w / 2, d / 2, h], mat)
    leg_mat = (METAL if rng.random() < 0.5 else DARK_WOOD).jitter(rng, 0.15)
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
    mat = [WOOD, PLASTIC, FABRIC, DARK_METAL][rng.integers(4)].jitter(rng, 0.25)
    leg = METAL.jitter(rng, 0.15)
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
    dark = DARK_METAL.jitter(rng, 0.15)
    fab = FABRIC.jitter(rng, 0.3)
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
    mat = [WOOD, WHITE_PAINT, METAL][rng.integers(3)].jitter(rng, 0.15)
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
                    CARDBOARD.jitter(rng, 0.3),
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
                    PLASTIC.jitter(rng, 0.4),
                )
                x += 2 * r + rng.uniform(0.01, 0.05)
            else:  # gap
                x += rng.uniform(0.05, 0.25)
    b.count("shelf")
    return b


def cabinet(rng: np.random.Generator, w: float, d: float, h: float) -> MeshBuilder:
    """Closed cabinet with door gaps and handles (back at -y)."""
    b = MeshBuilder()
    mat = [WHITE_PAINT, WOOD, METAL][rng.integers(3)].jitter(rng, 0.15)
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
    mat = FABRIC.jitter(rng, 0.4)
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
            b.add(cylinder([x, y, h], [x, y, h + hh], r, segments=12), PLASTIC.jitter(rng, 0.5))
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
    b.add(frustum([0, 0, 0], [0, 0, ph], r * 0.75, r, segments=16), PLASTIC.jitter(rng, 0.5))
    for _ in range(int(rng.integers(1, 4))):
        c = [rng.uniform(-r, r) * 0.5, rng.uniform(-r, r) * 0.5, ph + rng.uniform(0.2, 0.6) * scale]
        rad = rng.uniform(0.15, 0.35) * scale
        b.add(
            ellipsoid(
                c, [rad, rad, rad * rng.uniform(0.8, 1.5)], subdivisions=2, roughness=0.3, rng=rng
            ),
            FOLIAGE.jitter(rng, 0.3),
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
                CARDBOARD.jitter(rng, 0.3),
                R=rot_z(rng.uniform(-0.4, 0.4)),
                t=[rng.uniform(-0.05, 0.05), 0, z],
            )
            z += h
        b.count("boxes")
    elif k < 0.6:
        r, h = rng.uniform(0.15, 0.25), rng.uniform(0.35, 0.7)
        b.add(frustum([0, 0, 0], [0, 0, h], r * 0.85, r, segments=16), PLASTIC.jitter(rng, 0.5))
        b.count("bin")
    elif k < 0.75:
        r = rng.uniform(0.1, 0.35)
        b.add(ellipsoid([0, 0, r], r, subdivisions=2), PLASTIC.jitter(rng, 0.6))
        b.count("ball")
    else:
        w, d, h = rng.uniform(0.4, 0.8), rng.uniform(0.3, 0.6), rng.uniform(0.25, 0.5)
        mat = WOOD.jitter(rng, 0.15)
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
    mat = material or CONCRETE.jitter(rng, 0.15)
    n = max(3, round(rise_total / rng.uniform(0.16, 0.185)))
    rise = rise_total / n
    run = rng.uniform(0.26, 0.3)
    nosing = 0.02
    for k in range(n):
        b.box([-width / 2, k * run, 0], [width / 2, (k + 1) * run + nosing, (k + 1) * rise], mat)
    land = rng.uniform(1.0, 1.6)
    y_end = n * run + land
    b.box([-width / 2, n * run, 0], [width / 2, y_end, rise_total], mat)
    rail = METAL.jitter(rng, 0.15)
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
    mat = WHITE_PAINT.jitter(rng, 0.05)
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
            WHITE_PAINT.jitter(rng, 0.15),
        )
    else:
        w, d = rng.uniform(0.6, 1.4), rng.uniform(0.15, 0.6)
        for sx in (-1, 1):
            b.add(
                cylinder([sx * w / 3, 0, 0], [sx * w / 3, 0, -drop], 0.003, segments=4), DARK_METAL
            )
        b.box([-w / 2, -d / 2, -drop - 0.05], [w / 2, d / 2, -drop], WHITE_PAINT.jitter(rng, 0.15))
    b.count("lamp")
    return b


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
        b.box([-w / 2, 0, z0], [w / 2, 0.02, z0 + h], DARK_WOOD.jitter(rng, 0.3))
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
            [-w / 2, 0, z0], [w / 2, rng.uniform(0.01, 0.1), z0 + h], WHITE_PAINT.jitter(rng, 0.1)
        )
        b.count("electrical box")
        return b, w, z0, z0 + h
    elif k < 0.85:  # wall cabinet
        w, h, d = rng.uniform(0.6, 1.6), rng.uniform(0.5, 0.8), rng.uniform(0.25, 0.38)
        z0 = rng.uniform(1.4, 1.7)
        mat = [WHITE_PAINT, WOOD][rng.integers(2)].jitter(rng, 0.15)
        b.box([-w / 2, 0, z0], [w / 2, d, z0 + h], mat)
        b.box([-0.005, d, z0 + 0.01], [0.005, d + 0.01, z0 + h - 0.01], DARK_METAL)
        b.count("wall cabinet")
        return b, w, z0, z0 + h
    else:  # coat rack: a board with hooks
        w = rng.uniform(0.6, 1.4)
        z0 = rng.uniform(1.5, 1.7)
        b.box([-w / 2, 0, z0], [w / 2, 0.02, z0 + 0.1], WOOD.jitter(rng, 0.15))
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
    mat = [WHITE_PAINT, WOOD][rng.integers(2)].jitter(rng, 0.15)
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
