"""An outdoor street block for multi-station projects: a long street and a side street.

The main street is built like the courtyard scene's street (road with kerbs and markings,
sidewalks, facades of two to six floors with windows, shops, balconies and cornices, trees,
lamps, parked cars, benches, bollards, signs...), but its length grows with the number of
stations, and from 12 stations on a side street branches off to the north: a level lane
between two rows of facades with its own trees, lamps, bollards and parked cars. Stations stand
on the sidewalks, on the road and in the lane.
"""

from __future__ import annotations

import math

import numpy as np

from flexreg.synth import objects as ob
from flexreg.synth.mesh import MeshBuilder
from flexreg.synth.scene import Scene
from flexreg.synth.scenes._plan import finish, put
from flexreg.synth.scenes.courtyard import (
    add_building,
    add_parked_cars,
    add_road,
    add_street_furniture,
)
from flexreg.synth.seeding import as_rng

#: ground area per station the street is sized for, m^2 (stations about 6-9 m apart)
STREET_AREA_PER_STATION_M2 = 70.0


def street(
    rng: np.random.Generator | int | None = None,
    *,
    stations: int = 12,
    size_m: tuple[float, float] | None = None,
) -> Scene:
    """Street with facades on both sides and, from 12 stations on, a side street.

    Parameters
    ----------
    rng : numpy Generator, int or None
    stations : int
        Stations the street should hold (about :data:`STREET_AREA_PER_STATION_M2` of ground
        each); a quarter of the ground is in the side street.
    size_m : (float, float), optional
        ``(length, width)`` of the main street between the facades, metres (at least
        30 x 16 m); the side street is then 40 m long.

    Returns
    -------
    Scene
        Kind ``"street"``; ``layout`` gives the street lengths; placement zones are the main
        street and the lane (group 0).
    """
    rng, seed = as_rng(rng)
    Ly = float(rng.uniform(18.0, 26.0)) if size_m is None else float(size_m[1])
    ws = float(rng.uniform(9.0, 12.0))  # width of the side street between facades
    area = stations * STREET_AREA_PER_STATION_M2
    side = stations >= 12 or size_m is not None
    if size_m is None:
        Lx = max(30.0, (0.75 if side else 1.0) * area / Ly)
        Ls = max(20.0, 0.25 * area / ws) if side else 0.0
    else:
        Lx, Ls = max(30.0, float(size_m[0])), 40.0
    site = add_road(rng, (Lx, max(16.0, Ly)))
    Ly = site.Ly
    xs = float(rng.uniform(0.35, 0.65)) * Lx if side else -1e9
    gap = (xs - ws / 2, xs + ws / 2)
    b = site.b
    _facade_row(b, rng, 0.0, Lx, y=0.0, facing=+1, gap=None)
    _facade_row(b, rng, 0.0, Lx, y=Ly, facing=-1, gap=gap if side else None)
    if rng.random() < 0.6:  # a cross building closing the east end, with an arcade over the road
        add_building(
            b, rng, origin=(Lx + 0.5, -5.0), yaw=np.pi / 2, width=Ly + 10.0, depth=10.0,
            gate=(site.yr0 + 5.0 - 0.5, site.yr1 + 5.0 + 0.5),
        )  # fmt: skip
    if side:
        site.plan.mark([gap[0], Ly - 0.5], [gap[1], Ly + 0.5])
    add_street_furniture(site)
    add_parked_cars(site)
    zones: list[tuple[float, float, float, float, int]] = [(0.5, 0.5, Lx - 0.5, Ly - 0.5, 0)]
    if side:
        _lane(b, rng, gap, Ly, Ls)
        zones.append((gap[0] + 0.5, Ly - 0.5, gap[1] - 0.5, Ly + Ls - 0.5, 0))
    layout = {
        "street_length_m": round(Lx, 3),
        "street_width_m": round(Ly, 3),
        "side_street_length_m": round(Ls, 3),
        "side_street_width_m": round(ws, 3) if side else 0.0,
    }
    return finish(b, "street", seed, Lx, Ly, margin_m=0.5, zones=tuple(zones), layout=layout)


def _facade_row(
    b: MeshBuilder,
    rng: np.random.Generator,
    x0: float,
    x1: float,
    *,
    y: float,
    facing: int,
    gap: tuple[float, float] | None,
) -> None:
    """Buildings of 8-22 m frontage from ``x0 - 15`` to ``x1 + 10`` with their facade on
    ``y``, facing +y (``facing=1``) or -y; no building over the ``gap`` x-interval."""
    x = x0 + float(rng.uniform(-15, -2))
    while x < x1 + 10:
        w = float(rng.uniform(8.0, 22.0))
        if gap is not None and x < gap[1] and x + w > gap[0]:
            w = gap[0] - x
            if w < 4.0:  # too narrow for a building: jump over the side street
                x = gap[1]
                continue
        depth = float(rng.uniform(8.0, 14.0))
        if facing > 0:
            add_building(b, rng, origin=(x, y), yaw=0.0, width=w, depth=depth)
        else:
            add_building(b, rng, origin=(x + w, y), yaw=np.pi, width=w, depth=depth)
        x += w + (float(rng.uniform(2.0, 5.0)) if rng.random() < 0.35 else 0.0)
        if gap is not None and gap[0] <= x < gap[1]:
            x = gap[1]


def _lane(
    b: MeshBuilder, rng: np.random.Generator, gap: tuple[float, float], y0: float, Ls: float
) -> None:
    """The side street: paving, facades on both sides, trees, lamps, bollards, parked cars
    and a building closing its far end."""
    xa, xb = gap
    # the main street's pavement reaches 40 m beyond its facades; pave the rest of the lane
    b.box([xa - 1.0, y0 + 40.0, -0.5], [xb + 1.0, y0 + max(40.0, Ls) + 45.0, 0.0], ob.PAVING)
    for side, xf in ((0, xa), (1, xb)):
        y = y0 + 0.5
        while y < y0 + Ls:
            w = min(float(rng.uniform(8.0, 20.0)), y0 + Ls - y)
            if w < 4.0:
                break
            depth = float(rng.uniform(8.0, 12.0))
            if side == 0:  # west row, facade facing +x
                add_building(b, rng, origin=(xf, y + w), yaw=-np.pi / 2, width=w, depth=depth)
            else:
                add_building(b, rng, origin=(xf, y), yaw=np.pi / 2, width=w, depth=depth)
            y += w
    add_building(b, rng, origin=(xb + 1.0, y0 + Ls), yaw=np.pi, width=xb - xa + 2.0, depth=10.0)
    b.count("side street")
    for y in np.arange(
        y0 + float(rng.uniform(3.0, 8.0)), y0 + Ls - 2.0, float(rng.uniform(10, 16))
    ):
        s = int(rng.integers(2))
        put(b, ob.street_lamp(rng), xa + 0.5 if s == 0 else xb - 0.5, y, 0.0 if s == 0 else math.pi)
    for _ in range(int(rng.integers(1, 2 + int(Ls // 12)))):
        y = float(rng.uniform(y0 + 3.0, y0 + Ls - 3.0))
        u = rng.random()
        x = float(rng.choice([xa + 1.3, xb - 1.3]))
        if u < 0.4:
            put(b, ob.tree(rng), x, y, float(rng.uniform(0, 2 * math.pi)))
        elif u < 0.7:
            put(b, ob.car(rng), x, y, math.pi / 2 + rng.normal(0, 0.05))
        elif u < 0.85:
            put(b, ob.bench(rng), x, y, math.pi / 2 if x < (xa + xb) / 2 else -math.pi / 2)
        else:
            for k in range(int(rng.integers(2, 5))):
                put(b, ob.bollard(rng), x, y + 1.2 * k, 0.0)
