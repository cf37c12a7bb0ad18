"""A warehouse for multi-station projects: a long hall of identical rack bays, a few cues.

Main aisles run along the hall (x); between them, and between the outer main aisles and the
side aisles along the long walls, bands of double-sided pallet racks stand across the hall,
one rack row every ``period`` metres, with a cross aisle between neighbouring rows. Every rack
row is the *same* mesh (same loads), and columns, roof beams and lights repeat with the same
period, so a station in a cross aisle sees almost the same scan as one a period further on:
links between such stations also fit a bay-shifted pose. What breaks the repetition, as in a
real warehouse: a loading zone with dock gates at the west end, an office block at the east
end, personnel doors and electrical cabinets at irregular places on the long walls, and a few
parked forklifts and pallet stacks in the aisles.
"""

from __future__ import annotations

import math

import numpy as np

from flexreg.errors import ConfigError
from flexreg.synth import objects as ob
from flexreg.synth.mesh import Material, MeshBuilder, box, cylinder, wall_boxes
from flexreg.synth.scene import Scene
from flexreg.synth.scenes._plan import finish, put
from flexreg.synth.seeding import as_rng

#: floor area per station the hall is sized for, m^2
WAREHOUSE_AREA_PER_STATION_M2 = 60.0


def warehouse(
    rng: np.random.Generator | int | None = None,
    *,
    stations: int = 12,
    size_m: tuple[float, float] | None = None,
) -> Scene:
    """Warehouse hall with identical rack rows, sized for ``stations`` stations.

    Parameters
    ----------
    rng : numpy Generator, int or None
    stations : int
        Stations the floor should hold (about :data:`WAREHOUSE_AREA_PER_STATION_M2` each):
        one main aisle up to 20 stations, two above; the number of rack periods follows.
    size_m : (float, float), optional
        ``(length, width)`` in metres instead (length at least 20 m; the width sets the
        rack length).

    Returns
    -------
    Scene
        Kind ``"warehouse"``; ``layout`` gives the rack ``period_m``, the number of rack rows
        and the cues; one placement zone over the floor.
    """
    rng, seed = as_rng(rng)
    p = float(rng.uniform(2.3, 2.6)) + float(rng.uniform(3.0, 3.6))  # rack depth + cross aisle
    rd = float(rng.uniform(2.2, 2.5))  # depth of a double rack row (along x)
    n_main = 1 if stations <= 20 else 2
    side, main = float(rng.uniform(2.6, 3.2)), float(rng.uniform(3.8, 4.6))
    rack_len = float(rng.uniform(8.0, 11.0))
    if size_m is not None:
        length, W = (float(v) for v in size_m)
        if length < 20 or W < 2 * side + main + 2 * 4.0:
            raise ConfigError(f"warehouse size must be at least 20 x 22 m, got {length} x {W}")
        rack_len = (W - 2 * side - n_main * main) / (n_main + 1)
    W = 2 * side + n_main * main + (n_main + 1) * rack_len
    e0, e1 = float(rng.uniform(8.0, 11.0)), float(rng.uniform(6.0, 8.0))  # loading zone, offices
    if size_m is None:
        n_per = max(3, math.ceil(stations * WAREHOUSE_AREA_PER_STATION_M2 / (W * p)))
    else:
        n_per = max(3, int((length - e0 - e1) // p))
    L = e0 + n_per * p + e1
    H = float(rng.uniform(9.0, 11.0))
    b = MeshBuilder()
    wall_mat = Material(0.55, (196, 198, 192)).jitter(rng, 0.1)
    bands = []  # y-spans of the rack bands
    y = side
    for k in range(n_main + 1):
        bands.append((y, y + rack_len))
        y += rack_len + (main if k < n_main else 0.0)
    _hall_shell(b, rng, L, W, H, e0, wall_mat)
    steel = ob.STEEL_BLUE.jitter(rng, 0.1)
    rack_h = float(rng.uniform(5.5, min(7.5, H - 2.5)))
    rack = ob.pallet_rack(rng, rack_len, rd, rack_h)  # one rack row, repeated everywhere
    xs = [e0 + (i + 0.5) * p for i in range(n_per)]
    for x in xs:
        for y0, y1 in bands:
            put(b, rack, x, (y0 + y1) / 2, math.pi / 2)
    b.count("rack row", len(xs) * len(bands))
    for i in range(n_per + 1):  # columns and roof beams on the period grid
        x = e0 + i * p
        for yc in (0.35, W - 0.35):
            _column(b, x, yc, H, steel)
        b.box([x - 0.15, 0.0, H - 0.7], [x + 0.15, W, H - 0.2], steel)
        for a, c in _main_aisles(bands) if i < n_per else []:
            _light(b, x + p / 2, (a + c) / 2, H - 0.9)
    b.count("roof beam", n_per + 1)
    for a, c in _main_aisles(bands):
        for yl in (a + 0.15, c - 0.15):
            b.box([0.5, yl - 0.05, 0.0], [L - 0.5, yl + 0.05, 0.003], ob.SAFETY_YELLOW)
    cues = _loading_zone(b, rng, e0, W) + _offices(b, rng, L, e1, W, H)
    cues += _aisle_cues(b, rng, xs, p, bands, W, stations)
    m = 0.3
    layout = {
        "period_m": round(p, 4),
        "rack_rows": len(xs) * len(bands),
        "periods": n_per,
        "main_aisles": n_main,
        "cues": cues,
    }
    return finish(
        b, "warehouse", seed, L, W, margin_m=m, zones=((m, m, L - m, W - m, 0),), layout=layout
    )


def _main_aisles(bands: list[tuple[float, float]]) -> list[tuple[float, float]]:
    return [(bands[k][1], bands[k + 1][0]) for k in range(len(bands) - 1)]


def _column(b: MeshBuilder, x: float, y: float, H: float, steel: Material) -> None:
    ob.i_beam([x, y, 0.0], [x, y, H], 0.35, 0.25, b, steel, up=(0.0, 1.0, 0.0))
    b.box([x - 0.25, y - 0.3, 0.0], [x + 0.25, y + 0.3, 0.03], steel)
    b.count("column")


def _light(b: MeshBuilder, x: float, y: float, z: float) -> None:
    b.box([x - 0.7, y - 0.12, z - 0.08], [x + 0.7, y + 0.12, z], ob.WHITE_PAINT)
    for sx in (-0.5, 0.5):
        b.add(cylinder([x + sx, y, z], [x + sx, y, z + 0.7], 0.004, segments=4), ob.DARK_METAL)
    b.count("light")


def _hall_shell(
    b: MeshBuilder, rng: np.random.Generator, L: float, W: float, H: float, e0: float, mat: Material
) -> None:
    """Floor, roof and walls: dock gates in the west end wall and along the loading zone,
    personnel doors at irregular places, a ribbon of high windows."""
    t = 0.3
    b.box([-t, -t, -0.3], [L + t, W + t, 0.0], ob.SCREED.jitter(rng))
    b.box([-t, -t, H], [L + t, W + t, H + 0.3], ob.METAL.jitter(rng))
    band0 = float(rng.uniform(6.5, 7.0))
    band1 = min(H - 0.6, band0 + float(rng.uniform(1.0, 1.5)))
    n_gates = max(1, int(W // 9))
    gates = [((i + 0.5) * W / n_gates - 1.8, (i + 0.5) * W / n_gates + 1.8) for i in range(n_gates)]
    for wall, (length, at) in enumerate(((W, 0.0), (W, L), (L, 0.0), (L, W))):
        openings = []
        if wall == 0:
            openings += [(a, c, 0.0, 4.2) for a, c in gates]
        elif wall >= 2:  # long walls: a dock gate at the loading zone, 1-3 personnel doors
            a = float(rng.uniform(1.0, max(1.5, e0 - 5.0)))
            openings.append((a, a + 3.6, 0.0, 4.2))
            for d in sorted(rng.uniform(e0 + 2, length - 3, size=int(rng.integers(1, 4)))):
                if all(d > o[1] + 1 for o in openings):
                    openings.append((float(d), float(d) + 1.0, 0.0, 2.1))
        n_w = max(1, int(length // 2.0))
        for i in range(n_w):
            openings.append((i * length / n_w + 0.1, (i + 1) * length / n_w - 0.1, band0, band1))
        for lo, hi in wall_boxes(length, H, t, openings):
            if wall < 2:  # end walls, along y at x = at
                x0 = at - t if wall == 0 else at
                b.box([x0 + lo[1], lo[0], lo[2]], [x0 + hi[1], hi[0], hi[2]], mat)
            else:
                y0 = at - t if wall == 2 else at
                b.box([lo[0], y0 + lo[1], lo[2]], [hi[0], y0 + hi[1], hi[2]], mat)
        for a, c, z0, z1 in openings:
            if z0 == 0.0 and c - a > 2:  # a roller door, partly open
                z_open = float(rng.uniform(1.5, 3.5))
                if wall < 2:
                    x0 = at - t / 2 if wall == 0 else at + t / 2
                    b.add(box([x0 - 0.03, a, z_open], [x0 + 0.03, c, z1]), ob.METAL)
                else:
                    y0 = at - t / 2 if wall == 2 else at + t / 2
                    b.add(box([a, y0 - 0.03, z_open], [c, y0 + 0.03, z1]), ob.METAL)
                b.count("gate")
    b.count("wall", 4)


def _loading_zone(b: MeshBuilder, rng: np.random.Generator, e0: float, W: float) -> list[str]:
    """Pallet stacks, a conveyor and a wrapping machine in the loading zone (west end)."""
    cues = []
    for _ in range(int(rng.integers(3, 7))):
        put(b, ob.pallet_stack(rng), rng.uniform(1.5, e0 - 2.0), rng.uniform(2.0, W - 2.0), 0.0)
    cues.append("pallet stacks in the loading zone")
    cl = float(rng.uniform(4.0, 7.0))
    put(b, ob.conveyor(rng, cl), e0 / 2, rng.uniform(0.3, 0.7) * W, rng.uniform(-0.2, 0.2))
    cues.append("conveyor")
    mach, _w, _d = ob.machine(rng)
    put(b, mach, rng.uniform(2.0, e0 - 3.0), W - 2.5, math.pi)
    cues.append("machine")
    return cues


def _offices(
    b: MeshBuilder, rng: np.random.Generator, L: float, e1: float, W: float, H: float
) -> list[str]:
    """An office block with windows across part of the east end, electrical cabinets."""
    depth = float(rng.uniform(3.5, e1 - 2.5))
    y0, y1 = float(rng.uniform(0.0, 0.3)) * W, float(rng.uniform(0.6, 1.0)) * W
    hh = float(rng.uniform(3.0, 3.6))
    openings = [(s, s + 1.4, 1.0, 2.2) for s in np.arange(1.0, y1 - y0 - 2.0, 2.6)]
    mat = ob.WHITE_PAINT.jitter(rng, 0.1)
    for lo, hi in wall_boxes(y1 - y0, hh, 0.15, openings):
        b.box(
            [L - depth - 0.15 + lo[1], y0 + lo[0], lo[2]],
            [L - depth + hi[1] - 0.15, y0 + hi[0], hi[2]],
            mat,
        )
    for ya in (y0, y1):
        b.box([L - depth - 0.15, ya - 0.075, 0.0], [L, ya + 0.075, hh], mat)
    b.box([L - depth - 0.15, y0, hh], [L, y1, hh + 0.15], mat)
    for _ in range(int(rng.integers(2, 5))):
        cab, _w = ob.electrical_cabinet(rng)
        put(b, cab, rng.uniform(L - depth - 6.0, L - depth - 1.5), W - 0.45, math.pi)
    b.count("office block")
    return ["office block", "electrical cabinets"]


def _aisle_cues(
    b: MeshBuilder,
    rng: np.random.Generator,
    xs: list[float],
    p: float,
    bands: list[tuple[float, float]],
    W: float,
    stations: int,
) -> list[str]:
    """A forklift or pallet stack in every few periods, at the edge of a main or side aisle."""
    cues = []
    aisles = [(0.0, bands[0][0]), *_main_aisles(bands), (bands[-1][1], W)]
    n = max(2, stations // 8)
    for i in rng.choice(len(xs), size=min(n, len(xs)), replace=False):
        a, c = aisles[int(rng.integers(len(aisles)))]
        y = a + 0.9 if rng.random() < 0.5 else c - 0.9
        x = xs[int(i)] + float(rng.uniform(-p / 2, p / 2))
        if rng.random() < 0.5:
            put(b, ob.forklift(rng), x, y, float(rng.choice([0.0, math.pi])) + rng.normal(0, 0.1))
            cues.append(f"forklift at x={x:.1f} m")
        else:
            put(b, ob.pallet_stack(rng), x, y, float(rng.uniform(0, math.pi)))
            cues.append(f"pallet stack at x={x:.1f} m")
    return cues
