"""The outdoor street/courtyard scene, built in steps that draw from one ``rng`` in a fixed
order; :func:`add_building` makes each facade."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from flexreg.errors import ConfigError
from flexreg.synth import objects as ob
from flexreg.synth.mesh import (
    Material,
    MeshBuilder,
    cylinder,
    rot_z,
    tube,
    wall_boxes,
)
from flexreg.synth.scene import Scene
from flexreg.synth.scenes._plan import (
    Floorplan,
    finish,
    put,
)
from flexreg.synth.seeding import as_rng


@dataclass
class _Street:
    """What the steps of :func:`courtyard` build on: the mesh ``b``, the floor plan, the size
    ``Lx`` x ``Ly``, the road between ``yr0`` and ``yr1`` with its kerb height and crossing at
    ``xc``, and the two sidewalks ``walks`` as ``(y0, y1)`` (metres)."""

    rng: np.random.Generator
    b: MeshBuilder
    plan: Floorplan
    Lx: float
    Ly: float
    yr0: float
    yr1: float
    kerb: float
    xc: float
    walks: list[tuple[float, float]]


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
    site = add_road(rng, size_m)
    _facades(site)
    add_street_furniture(site)
    add_parked_cars(site)
    return finish(site.b, "courtyard", seed, site.Lx, site.Ly, margin_m=0.5)


def add_road(rng: np.random.Generator, size_m: tuple[float, float] | None) -> _Street:
    """Size; pavement, road with kerbs, markings and manhole covers; the road kept free."""
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

    plan = Floorplan(0.0, 0.0, Lx, Ly)
    plan.mark([0, yr0 - 0.15], [Lx, yr1 + 0.15])  # keep the road free of street furniture
    walks = [(0.0, yr0 - 0.15), (yr1 + 0.15, Ly)]
    return _Street(rng, b, plan, Lx, Ly, yr0, yr1, kerb, xc, walks)


def _facades(site: _Street) -> None:
    """Buildings: the south row faces +y at y = 0, the north row faces -y at y = Ly;
    a cross building may close the east end over the road."""
    rng, b, Lx, Ly, yr0, yr1 = site.rng, site.b, site.Lx, site.Ly, site.yr0, site.yr1
    for side in (0, 1):
        x = rng.uniform(-15, -2)
        while x < Lx + 10:
            w = rng.uniform(8.0, 22.0)
            depth = rng.uniform(8.0, 14.0)
            if side == 0:
                add_building(b, rng, origin=(x, 0.0), yaw=0.0, width=w, depth=depth)
            else:
                add_building(b, rng, origin=(x + w, Ly), yaw=np.pi, width=w, depth=depth)
            x += w + (rng.uniform(2.0, 5.0) if rng.random() < 0.35 else 0.0)
    if rng.random() < 0.7:  # cross building closing the east end over the road
        w = Ly + 10.0
        add_building(
            b,
            rng,
            origin=(Lx + 0.5, -5.0),
            yaw=np.pi / 2,
            width=w,
            depth=rng.uniform(8, 12),
            gate=(yr0 + 5.0 - 0.5, yr1 + 5.0 + 0.5),
        )


def _sidewalk_spot(
    site: _Street, w: float, d: float, *, kerb_side: bool, face_road: bool
) -> tuple[float, float, float] | None:
    """A free spot on a sidewalk for a ``w`` x ``d`` object, marked taken; ``(x, y, yaw)``."""
    rng, plan, Lx, walks = site.rng, site.plan, site.Lx, site.walks
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


def add_street_furniture(site: _Street) -> None:
    """Street lamps alternating sides, trees in grates, benches, bollards, signs,
    bins, bike stands, planters, shelters, fences and kiosks."""
    rng, b, plan, Lx, walks = site.rng, site.b, site.plan, site.Lx, site.walks
    for x in np.arange(rng.uniform(2, 8), Lx, rng.uniform(12, 20)):  # lamps alternate sides
        s = int(rng.integers(2))
        y = walks[s][1] - 0.45 if s == 0 else walks[s][0] + 0.45
        put(b, ob.street_lamp(rng), x + rng.normal(0, 1.0), y, np.pi if s == 0 else 0.0)
        plan.mark([x - 0.5, y - 0.5], [x + 0.5, y + 0.5])
    for _ in range(int(rng.integers(4, 13))):
        spot = _sidewalk_spot(site, 1.0, 1.0, kerb_side=rng.random() < 0.6, face_road=False)
        if spot is not None:
            x, y, yaw = spot
            b.box([x - 0.7, y - 0.7, 0.0], [x + 0.7, y + 0.7, 0.02], ob.DARK_METAL)  # tree grate
            put(b, ob.tree(rng), x, y, yaw, 0.0)
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
            spot = _sidewalk_spot(site, size, size * 0.5, kerb_side=kerb_side, face_road=True)
            if spot is not None:
                put(b, make(rng), *spot)


def add_parked_cars(site: _Street) -> None:
    """Parked cars along both road edges, none on the crossing."""
    rng, b, Lx, yr0, yr1, kerb = site.rng, site.b, site.Lx, site.yr0, site.yr1, site.kerb
    xc = site.xc
    for s in (0, 1):
        x = rng.uniform(-5, 3)
        while x < Lx + 5:
            if rng.random() < 0.6 and abs(x - xc) > 4:
                c = ob.car(rng)
                y = yr0 + 1.1 if s == 0 else yr1 - 1.1
                put(
                    b,
                    c,
                    x + 2.4,
                    y + rng.normal(0, 0.1),
                    (0.0 if s == 0 else np.pi) + rng.normal(0, 0.03),
                    -kerb,
                )
            x += rng.uniform(5.2, 7.5)


@dataclass
class _Building:
    """What the steps of :func:`add_building` build on, in the facade's frame: ``floors`` floors of
    height ``fh`` over a ground floor of height ``gh`` (total ``height``), window recess depth
    ``recess``, wall and trim materials, and the open ``gate`` interval (metres)."""

    rng: np.random.Generator
    local: MeshBuilder
    width: float
    depth: float
    floors: int
    fh: float
    gh: float
    height: float
    recess: float
    mat: Material
    trim: Material
    gate: tuple[float, float] | None


def add_building(
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
    site = _Building(rng, local, width, depth, floors, fh, gh, height, recess, mat, trim, gate)
    _body(site)
    openings, balcony_cols, shop, bay = _facade(site)
    _window_trims(site, openings)
    top = _cornices(site)
    _balconies(site, balcony_cols, bay)
    _plinth(site, openings)
    _drainpipes(site, top)

    if shop and rng.random() < 0.6:  # shop sign
        local.box(
            [0.5, 0, gh - 0.5],
            [width - 0.5, 0.12, gh - 0.15],
            Material.random(rng, 0.7, 30, 230),
        )
    local.count("building")
    b.extend(local, R=R, t=t)


def _body(site: _Building) -> None:
    """The body behind the facade layer; a gate cuts through the ground floor."""
    local, width, depth, gh, height = site.local, site.width, site.depth, site.gh, site.height
    recess, mat, gate = site.recess, site.mat, site.gate
    if gate is None:
        local.box([0, -depth, 0], [width, -recess, height], mat)
    else:
        local.box([0, -depth, 0], [gate[0], -recess, height], mat)
        local.box([gate[1], -depth, 0], [width, -recess, height], mat)
        local.box([gate[0], -depth, gh], [gate[1], -recess, height], mat)


def _facade(
    site: _Building,
) -> tuple[list[tuple[float, float, float, float]], set[int], bool, float]:
    """The facade layer with its openings: per bay a shop window, door (maybe with
    steps) or window on the ground floor, windows or balcony doors above. Returns the openings
    ``(x0, x1, z0, z1)``, the balcony columns, whether the ground floor has shops, the bay width."""
    rng, local, width, floors, fh = site.rng, site.local, site.width, site.floors, site.fh
    gh, height, recess, mat, gate = site.gh, site.height, site.recess, site.mat, site.gate
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
    if gate is not None:
        openings.append((gate[0], gate[1], 0.0, gh))
    shop = rng.random() < 0.5
    for i in range(n_bays):
        xc = (i + 0.5) * bay + rng.normal(0, 0.03)
        if gate is not None and gate[0] - 0.3 < xc < gate[1] + 0.3:
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
    return openings, balcony_cols, shop, bay


def _window_trims(site: _Building, openings: list[tuple[float, float, float, float]]) -> None:
    """Window furniture: sills, frames with a mullion, inside each recess."""
    local, recess, trim = site.local, site.recess, site.trim
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


def _cornices(site: _Building) -> float:
    """A cornice band at every floor, a big one on top, and the parapet; returns the
    top cornice's projection."""
    rng, local, width, depth, floors = site.rng, site.local, site.width, site.depth, site.floors
    fh, gh, height, recess, mat = site.fh, site.gh, site.height, site.recess, site.mat
    trim = site.trim
    cp = rng.uniform(0.04, 0.12)
    for f in range(1, floors):
        zf = gh + (f - 1) * fh
        local.box([0, -0.01, zf - 0.12], [width, cp, zf + 0.08], trim)
    top = rng.uniform(0.25, 0.6)
    local.box([-0.1, -0.01, height - 0.35], [width + 0.1, top, height], trim)
    local.box([-0.1, -0.01, height - 0.5], [width + 0.1, top * 0.5, height - 0.35], trim)
    local.box([0, -depth, height], [width, -recess, height + rng.uniform(0.5, 1.1)], mat)  # parapet
    local.count("cornice", floors)
    return top


def _balconies(site: _Building, balcony_cols: set[int], bay: float) -> None:
    """Balconies with solid or bar railings on every upper floor of the chosen bays."""
    rng, local, floors, fh, gh, mat = site.rng, site.local, site.floors, site.fh, site.gh, site.mat
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


def _plinth(site: _Building, openings: list[tuple[float, float, float, float]]) -> None:
    """A plinth along the ground floor, interrupted by doors and low openings."""
    rng, local, width, mat = site.rng, site.local, site.width, site.mat
    ph = rng.uniform(0.4, 0.9)
    cuts = sorted((o[0], o[1]) for o in openings if o[2] < ph)
    edges = [0.0] + [v for c in cuts for v in c] + [width]
    pm = (ob.GRANITE if rng.random() < 0.5 else mat).jitter(rng, 0.1)
    for a, c in zip(edges[0::2], edges[1::2], strict=True):
        if c - a > 0.05:
            local.box([a, -0.01, 0.0], [c, rng.uniform(0.02, 0.05), ph], pm)


def _drainpipes(site: _Building, top: float) -> None:
    """Drainpipes at the ends of the facade."""
    rng, local, width, height = site.rng, site.local, site.width, site.height
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
