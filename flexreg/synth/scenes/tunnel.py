"""A featureless straight tunnel longer than a scanner's reach, and its variant with one cue.

The cross-section (walls, vault, walkways, cable trays, road) is the same all along, and both
tunnel ends lie farther than the scanner's range from every station: nothing fixes where along
the axis a station stands, and a half turn about a vertical axis maps the tunnel onto itself.
The ``cue`` variant has one emergency niche (with electrical cabinets) in one wall near the
stations.
"""

from __future__ import annotations

import math
from itertools import pairwise

import numpy as np
from numpy.typing import NDArray

from flexreg.errors import ConfigError
from flexreg.synth import objects as ob
from flexreg.synth.mesh import Material, MeshBuilder, profile_slabs, wall_boxes
from flexreg.synth.scene import Scene
from flexreg.synth.scenes._plan import finish, put, shift_x, turn_z
from flexreg.synth.seeding import as_rng

#: default tunnel length, metres: from the placement zone both ends are 190 m away,
#: beyond the 150 m maximal range of the default scanner (``TLSConfig.max_range_m``)
TUNNEL_LENGTH_M = 400.0
#: length of the zone around the middle of the tunnel where stations stand, metres
TUNNEL_ZONE_M = 20.0
#: longest piece of the lining along the axis, metres
_PIECE_M = 5.0
#: shifts along the axis listed as samples of the tunnel's continuous symmetry, metres
_SAMPLE_SHIFTS_M = (-5.0, -2.0, -1.0, 1.0, 2.0, 5.0)


def tunnel(
    rng: np.random.Generator | int | None = None,
    *,
    size_m: tuple[float, float] | None = None,
    cue: bool = False,
) -> Scene:
    """Straight tunnel of 400 m x 7-10 m (or ``size_m``) with a vault 5.5-8.5 m high.

    Concrete walls 2.5-3.5 m high carry an elliptical vault; walkways with kerbs and cable trays
    run along both walls and an asphalt road between them, all unchanged along the axis (x).
    End walls close the tube. Stations stand in a zone of ``TUNNEL_ZONE_M`` (20 m) around the
    middle, so with the default 400 m both ends are beyond a 150 m scanner range.

    Parameters
    ----------
    rng : numpy Generator, int or None
    size_m : (float, float), optional, metres
        ``(length, width)``: length at least 40 m, width 4-20 m; drawn when omitted (length
        ``TUNNEL_LENGTH_M``).
    cue : bool
        Cut one emergency niche (2.5-4 m wide, 1-1.5 m deep, with electrical cabinets at its
        back) into a wall within 5 m of the middle (kind ``"tunnel-cue"``); the rest of the
        tunnel is drawn identically.

    Returns
    -------
    Scene
        Kind ``"tunnel"``. Its ``symmetries`` are the half turn about the vertical axis through
        the middle and shifts along the axis by a few metres (samples of a continuous family:
        every shift fits); none for the cue variant.
    """
    rng, seed = as_rng(rng)
    if size_m is None:
        L, W = TUNNEL_LENGTH_M, float(rng.uniform(7.0, 10.0))
    else:
        L, W = (float(v) for v in size_m)
        if L < 40 or not 4 <= W <= 20:
            raise ConfigError(
                f"tunnel size must be at least 40 m long and 4-20 m wide, got {L} x {W}"
            )
    hw = float(rng.uniform(2.5, 3.5))
    rise = float(rng.uniform(0.3, 0.5)) * W
    lining = ob.CONCRETE.jitter(rng, 0.05)
    road = ob.ASPHALT.jitter(rng)
    walk_w = float(rng.uniform(0.8, 1.2))
    walk = ob.CONCRETE.jitter(rng, 0.1)
    tray_z = hw + float(rng.uniform(0.1, 0.3))
    b = MeshBuilder()
    openings: tuple[list[tuple[float, float, float, float]], ...] = ([], [])
    symmetries: tuple[NDArray[np.float64], ...] = ()
    if cue:  # drawn after everything the base tunnel draws
        niche, side, x_c, half_w, top = _niche(rng, L, hw, lining)
        openings[side].append((x_c - half_w, x_c + half_w, 0.5, top + 0.3))
        put(b, niche, x_c, (0.0, W)[side], (0.0, math.pi)[side])
    else:
        symmetries = (turn_z(L / 2, W / 2, 2), *(shift_x(d) for d in _SAMPLE_SHIFTS_M))
    t = np.linspace(math.pi, 0.0, 25)
    vault = np.column_stack([W / 2 + W / 2 * np.cos(t), hw + rise * np.sin(t)])
    # in pieces of at most _PIECE_M along the axis: long thin triangles make the distance
    # queries of the ray caster imprecise
    xs = np.linspace(0.0, L, math.ceil(L / _PIECE_M) + 1)
    for x0, x1 in pairwise(xs):
        x0, x1 = float(x0), float(x1)
        # walls (local y of wall_boxes: into the rock) and the vault over them
        for side, y_sign, y_face in ((0, -1.0, 0.0), (1, 1.0, W)):
            local = [(a - x0, c - x0, z0, z1) for a, c, z0, z1 in openings[side]]
            for lo, hi in wall_boxes(x1 - x0, hw + 0.3, 0.3, local):
                ys = sorted((y_face + y_sign * lo[1], y_face + y_sign * hi[1]))
                b.box([x0 + lo[0], ys[0], lo[2] - 0.3], [x0 + hi[0], ys[1], hi[2] - 0.3], lining)
        for slab in profile_slabs(vault, x0, x1, 0.3):
            b.add(slab, lining)
        b.box([x0, 0.0, -0.3], [x1, W, 0.0], road)
        for y0, y1 in ((0.0, walk_w), (W - walk_w, W)):
            b.box([x0, y0, 0.0], [x1, y1, 0.2], walk)
        for y0, y1 in ((0.0, 0.35), (W - 0.35, W)):
            b.box([x0, y0, tray_z - 0.08], [x1, y1, tray_z], ob.METAL)
    b.count("tunnel lining")
    b.count("walkway", 2)
    b.count("cable tray", 2)
    for x0, x1 in ((-0.3, 0.0), (L, L + 0.3)):
        b.box([x0, -0.4, -0.3], [x1, W + 0.4, hw + rise + 0.4], lining)
    b.count("end wall", 2)
    zone = min(TUNNEL_ZONE_M, L - 2.0)
    region = (L / 2 - zone / 2, 0.3, L / 2 + zone / 2, W - 0.3)
    kind = "tunnel-cue" if cue else "tunnel"
    return finish(b, kind, seed, L, W, margin_m=0.3, region=region, symmetries=symmetries)


def _niche(
    rng: np.random.Generator, L: float, hw: float, lining: Material
) -> tuple[MeshBuilder, int, float, float, float]:
    """The cue: an emergency niche 2.5-4 m wide and 1-1.5 m deep in one wall, with a row of
    electrical cabinets at its back, within 5 m of the middle.

    Returns the niche built at a wall on ``y = 0`` (recess at ``y < 0``, centred on ``x = 0``),
    the wall (0: ``y = 0``, 1: ``y = W``, turned by a half turn), the centre along the axis, the
    half width and the height of the opening (metres).
    """
    half_w = float(rng.uniform(2.5, 4.0)) / 2
    depth = float(rng.uniform(1.0, 1.5))
    top = min(hw - 0.2, float(rng.uniform(2.3, 2.8)))
    x_c = L / 2 + float(rng.uniform(-5.0, 5.0))
    side = int(rng.integers(2))
    cab, _width = ob.electrical_cabinet(rng)
    cab_d = -2.0 * float(cab.arrays()[0][:, 1].min())
    n = MeshBuilder()
    y_back = -0.3 - depth
    n.box([-half_w - 0.3, y_back - 0.3, -0.3], [half_w + 0.3, y_back, top + 0.3], lining)
    for xa, xb in ((-half_w - 0.3, -half_w), (half_w, half_w + 0.3)):
        n.box([xa, y_back, -0.3], [xb, -0.3, top + 0.3], lining)
    n.box([-half_w, y_back, top], [half_w, -0.3, top + 0.3], lining)
    n.box([-half_w, y_back, -0.3], [half_w, 0.0, 0.2], lining)  # niche floor at walkway level
    n.extend(cab, t=[0.0, y_back + cab_d / 2 + 0.02, 0.2])
    n.count("niche")
    return n, side, x_c, half_w, top
