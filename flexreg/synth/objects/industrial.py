"""Industrial objects: I-beams, tanks, pallet racks and stacks, machines, conveyors,
forklifts and electrical cabinets."""

from __future__ import annotations

from itertools import pairwise

import numpy as np
from numpy.typing import ArrayLike

from flexreg.synth.mesh import (
    Material,
    MeshBuilder,
    box,
    cylinder,
    dome,
    frustum,
)
from flexreg.synth.objects.materials import (
    CARDBOARD,
    CHROME,
    CONCRETE,
    DARK_METAL,
    FABRIC,
    METAL,
    PLASTIC,
    RUBBER,
    SAFETY_YELLOW,
    STEEL_BLUE,
    WHITE_PAINT,
    WOOD,
)


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
    mat = [WHITE_PAINT, METAL, STEEL_BLUE][rng.integers(3)].jitter(rng, 0.15)
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
    orange = Material(0.45, (220, 110, 30)).jitter(rng, 0.1)
    blue = STEEL_BLUE.jitter(rng, 0.1)
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
                    WOOD.jitter(rng, 0.15),
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
                            PLASTIC.jitter(rng, 0.5),
                        )
                else:  # stacked cartons
                    zz = z + 0.14
                    while zz < z + 0.14 + load_h - 0.1:
                        hh = rng.uniform(0.15, 0.5)
                        shrink = rng.uniform(0.0, 0.08, size=2)
                        b.box(
                            [px + shrink[0], -depth / 2 + 0.08 + shrink[1], zz],
                            [px + pw - shrink[1], depth / 2 - 0.08 - shrink[0], zz + hh],
                            CARDBOARD.jitter(rng, 0.3),
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
    body = Material(0.45, (90, 140, 110)).jitter(rng, 0.3)
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
        Material(0.6, (200, 200, 190)).jitter(rng, 0.15),
    )
    b.count("machine")
    return b, w, d + 0.7


def conveyor(rng: np.random.Generator, length: float) -> MeshBuilder:
    """Roller conveyor along +x on legs (rollers every ~10 cm)."""
    b = MeshBuilder()
    w = rng.uniform(0.5, 0.9)
    h = rng.uniform(0.7, 0.9)
    frame = METAL.jitter(rng, 0.15)
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
            CARDBOARD.jitter(rng, 0.3),
        )
    b.count("conveyor")
    return b


def pallet_stack(rng: np.random.Generator) -> MeshBuilder:
    """Stack of empty pallets or a pallet with a wrapped load, on the floor."""
    b = MeshBuilder()
    wood = WOOD.jitter(rng, 0.15)
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
            Material(0.55, (200, 200, 210)).jitter(rng, 0.2),
        )
    b.count("pallets")
    return b


def forklift(rng: np.random.Generator) -> MeshBuilder:
    """Forklift along +x: body, overhead guard, mast, forks, wheels."""
    b = MeshBuilder()
    paint = (SAFETY_YELLOW if rng.random() < 0.6 else PLASTIC).jitter(rng, 0.1)
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
    mat = Material(0.6, (200, 200, 192)).jitter(rng, 0.05)
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
