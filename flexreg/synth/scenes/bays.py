"""A long arcade of identical bays, and its variant in which one bay differs.

Two rows of columns carry arches every ``period`` metres (3.2-3.8 m, like the arches of the 3DTK
Kurt3D hall that repeat every ~3.4 m), with a window, a transverse beam and a light in every bay.
The arcade is long enough that its ends are beyond a scanner's range from every station, so a
station one bay further along sees the same scan: shifts by whole bays fit almost equally. The
``cue`` variant parks a forklift in one bay next to the stations.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from flexreg.errors import ConfigError
from flexreg.synth import objects as ob
from flexreg.synth.mesh import MeshBuilder, arch, cylinder, wall_boxes
from flexreg.synth.scene import Scene
from flexreg.synth.scenes._plan import finish, put, shift_x, turn_z
from flexreg.synth.seeding import as_rng

#: distance from the placement zone to either end of the arcade, metres (beyond the 150 m
#: maximal range of the default scanner, ``TLSConfig.max_range_m``)
BAYS_END_CLEARANCE_M = 160.0
#: bays on each side of the middle column where stations stand
BAYS_ZONE = 3


def bays(
    rng: np.random.Generator | int | None = None,
    *,
    size_m: tuple[float, float] | None = None,
    cue: bool = False,
) -> Scene:
    """Arcade of identical bays along x, 10-14 m wide (or ``size_m``), about 350 m long.

    Square columns in two rows carry semicircular arches and a longitudinal beam; a transverse
    beam crosses the hall at every column pair, each bay has a window in both side walls (open,
    nothing outside) and a ceiling light over the middle; aisle markings run along the floor.
    Stations stand within ``BAYS_ZONE`` (3) bays of the middle column; the end walls are at least
    ``BAYS_END_CLEARANCE_M`` (160 m) beyond.

    Parameters
    ----------
    rng : numpy Generator, int or None
    size_m : (float, float), optional, metres
        ``(length, width)``: the length is rounded up to an even number of bays (at least 8)
        and the width must be 8-30 m; drawn when omitted.
    cue : bool
        Park one forklift in the aisle of the bay just past the middle column (kind
        ``"bays-cue"``); the rest is drawn identically.

    Returns
    -------
    Scene
        Kind ``"bays"``. Its ``symmetries`` are the shifts by one and two bays either way
        (``symmetries[0][0, 3]`` is the period) and the half turn about the vertical axis
        through the middle column pair; none for the cue variant.
    """
    rng, seed = as_rng(rng)
    p = float(rng.uniform(3.2, 3.8))
    if size_m is None:
        W = float(rng.uniform(10.0, 14.0))
        n = 2 * math.ceil((BAYS_END_CLEARANCE_M + BAYS_ZONE * p) / p)
    else:
        length, W = (float(v) for v in size_m)
        if not 8 <= W <= 30 or length <= 0:
            raise ConfigError(f"bays width must be 8-30 m and length positive, got {W}")
        n = max(8, 2 * math.ceil(length / (2 * p)))
    L = n * p
    c = float(rng.uniform(2.0, 3.0))  # column rows at y = c and W - c
    s = float(rng.uniform(0.35, 0.5))  # column width
    hs = float(rng.uniform(2.6, 3.2))  # arch springing height
    r = (p - s) / 2  # inner radius of the arches
    top = hs + r + 0.35  # top of the arches: longitudinal beams from here
    H = top + 0.3 + float(rng.uniform(0.8, 1.5))  # ceiling
    stone = ob.CONCRETE.jitter(rng, 0.05)
    wall_mat = ob.PLASTER.jitter(rng, 0.05)
    b = MeshBuilder()
    floor_mat = ob.SCREED.jitter(rng)
    for x0, x1 in ((-0.3, 0.0), (L, L + 0.3)):
        b.box([x0, -0.3, -0.3], [x1, W + 0.3, H + 0.3], wall_mat)
    b.count("end wall", 2)
    win_w, sill = float(rng.uniform(1.2, 1.8)), float(rng.uniform(1.0, 1.2))
    win_top = min(H - 0.5, sill + float(rng.uniform(1.2, 1.8)))
    window = [(p / 2 - win_w / 2, p / 2 + win_w / 2, sill, win_top)]
    # bay by bay (long thin triangles make the distance queries of the ray caster imprecise)
    for i in range(n):
        x0 = i * p
        b.box([x0, -0.3, -0.3], [x0 + p, W + 0.3, 0.0], floor_mat)
        b.box([x0, -0.3, H], [x0 + p, W + 0.3, H + 0.3], ob.CEILING)
        for lo, hi in wall_boxes(p, H, 0.3, window):  # wall at y = 0 (outside: y < 0) ...
            b.box([x0 + lo[0], -hi[1], lo[2]], [x0 + hi[0], -lo[1], hi[2]], wall_mat)
            b.box([x0 + lo[0], W + lo[1], lo[2]], [x0 + hi[0], W + hi[1], hi[2]], wall_mat)
    b.count("side wall", 2)
    b.count("window", 2 * n)
    for y in (c, W - c):
        y0, y1 = y - s / 2, y + s / 2
        for i in range(1, n):
            b.box([i * p - s / 2, y0, 0.0], [i * p + s / 2, y1, top], stone)
        for i in range(n):
            for voussoir in arch((i + 0.5) * p, y0, y1, hs, r, 0.3):
                b.add(voussoir, stone)
        for i in range(n):
            b.box([i * p, y0, top], [(i + 1) * p, y1, top + 0.3], stone)
    b.count("column", 2 * (n - 1))
    b.count("arch", 2 * n)
    for i in range(1, n):
        b.box([i * p - 0.15, 0.0, H - 0.4], [i * p + 0.15, W, H], stone)
    b.count("transverse beam", n - 1)
    _lights_and_markings(b, rng, n, p, W, c, H)
    if cue:
        put(b, ob.forklift(rng), L / 2 + p / 2, W / 2, float(rng.uniform(-0.3, 0.3)))
        symmetries: tuple[NDArray[np.float64], ...] = ()
    else:
        shifts = tuple(shift_x(k * p) for k in (1, -1, 2, -2))
        symmetries = (*shifts, turn_z(L / 2, W / 2, 2))
    region = (L / 2 - BAYS_ZONE * p, 0.3, L / 2 + BAYS_ZONE * p, W - 0.3)
    kind = "bays-cue" if cue else "bays"
    return finish(b, kind, seed, L, W, margin_m=0.3, region=region, symmetries=symmetries)


def _lights_and_markings(
    b: MeshBuilder, rng: np.random.Generator, n: int, p: float, W: float, c: float, H: float
) -> None:
    """A light panel on two hangers over the middle of every bay; aisle lines on the floor."""
    drop = float(rng.uniform(0.4, 0.8))
    panel = MeshBuilder()
    panel.box([-0.6, -0.15, -drop - 0.06], [0.6, 0.15, -drop], ob.WHITE_PAINT)
    for sx in (-0.45, 0.45):
        panel.add(cylinder([sx, 0.0, 0.0], [sx, 0.0, -drop], 0.004, segments=4), ob.DARK_METAL)
    for i in range(n):
        put(b, panel, (i + 0.5) * p, W / 2, 0.0, H)
    b.count("light", n)
    for y in (c + 0.8, W - c - 0.8):
        for i in range(n):
            b.box([i * p, y - 0.05, 0.0], [(i + 1) * p, y + 0.05, 0.003], ob.MARKING)
    b.count("floor marking", 2)
