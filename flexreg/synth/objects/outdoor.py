"""Street furniture, trees, cars and facade parts (awnings, air conditioners, entrance
steps), fences and kiosks."""

from __future__ import annotations

import numpy as np

from flexreg.synth.mesh import (
    Material,
    MeshBuilder,
    cylinder,
    ellipsoid,
    frustum,
    hexahedron,
    tube,
)
from flexreg.synth.objects.materials import (
    BARK,
    BRICK,
    CHROME,
    CONCRETE,
    DARK_METAL,
    FOLIAGE,
    GLASS,
    GRANITE,
    MARKING,
    METAL,
    PLASTIC,
    RUBBER,
    STEEL_BLUE,
    WHITE_PAINT,
    WOOD,
)


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
        BARK.jitter(rng, 0.15),
    )
    crown_r = rng.uniform(1.4, 3.0)
    for _ in range(int(rng.integers(2, 5))):
        off = rng.normal(0, crown_r * 0.35, size=3)
        off[2] = abs(off[2]) + crown_r * 0.6
        radii = crown_r * rng.uniform(0.55, 0.9, size=3)
        b.add(
            ellipsoid(trunk_top + off, radii, subdivisions=2, roughness=0.35, rng=rng),
            FOLIAGE.jitter(rng, 0.3),
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
    mat = (DARK_METAL if rng.random() < 0.6 else METAL).jitter(rng, 0.15)
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
    wood = WOOD.jitter(rng, 0.15)
    metal = DARK_METAL.jitter(rng, 0.15)
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
    mat = DARK_METAL.jitter(rng, 0.15)
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
    mat = [DARK_METAL, PLASTIC, STEEL_BLUE][rng.integers(3)].jitter(rng, 0.15)
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
    b.box([-w / 2, -d / 2, 0], [w / 2, d / 2, h], CONCRETE.jitter(rng, 0.15))
    b.add(
        ellipsoid(
            [0, 0, h + 0.2],
            [w * 0.45, d * 0.45, rng.uniform(0.3, 0.7)],
            subdivisions=2,
            roughness=0.3,
            rng=rng,
        ),
        FOLIAGE.jitter(rng, 0.3),
    )
    b.count("planter")
    return b


def shelter(rng: np.random.Generator) -> MeshBuilder:
    """Bus shelter: four posts, roof slab, back and side panels (back at -y)."""
    b = MeshBuilder()
    w, d, h = rng.uniform(3.0, 4.5), rng.uniform(1.3, 1.8), rng.uniform(2.3, 2.6)
    m = METAL.jitter(rng, 0.15)
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
    mat = GRANITE.jitter(rng, 0.15)
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
        mat = [BRICK, CONCRETE][rng.integers(2)].jitter(rng, 0.15)
        b.box([-L / 2, -0.12, 0], [L / 2, 0.12, h], mat)
        b.box([-L / 2 - 0.03, -0.16, h], [L / 2 + 0.03, 0.16, h + 0.06], GRANITE)
        b.count("low wall")
        return b
    mat = [DARK_METAL, WOOD][rng.integers(2)].jitter(rng, 0.15)
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
    mat = Material(0.5, (120, 140, 90)).jitter(rng, 0.3)
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
