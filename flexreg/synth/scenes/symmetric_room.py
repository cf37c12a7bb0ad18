"""An empty room with rotational symmetry, and its variant with one asymmetric cue.

Every wall of the same length carries the same items at the same place in its own frame (door,
window, radiator, switch, skirting) and the lamps hang on a symmetric grid, so a square room
looks the same after every quarter turn about its centre (a rectangle after a half turn): that
many poses of a station explain its scan equally well. The ``cue`` variant adds one bookshelf
near a corner, which only the true pose explains.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from flexreg.errors import ConfigError
from flexreg.synth import objects as ob
from flexreg.synth.mesh import MeshBuilder, box, cylinder, wall_boxes
from flexreg.synth.scene import Scene
from flexreg.synth.scenes._plan import Walls, finish, put, turn_z
from flexreg.synth.seeding import as_rng

#: wall thickness, metres
_WALL_T = 0.25


def symmetric_room(
    rng: np.random.Generator | int | None = None,
    *,
    size_m: tuple[float, float] | None = None,
    cue: bool = False,
) -> Scene:
    """Empty square room of 7-10 m (or ``size_m``), 2.8-3.6 m high, symmetric by quarter turns.

    Each wall has the same closed door (casing, leaf, handle), window opening (sill, frame, no
    glass and nothing outside), radiator, light switch and skirting board at the same place in
    its own frame; four lamps hang on a grid that turns into itself. A square room maps onto
    itself under turns by 90, 180 and 270 degrees about its centre, a rectangle (``size_m`` with
    unequal sides) under the half turn; these motions are the scene's ``symmetries``.

    Parameters
    ----------
    rng : numpy Generator, int or None
    size_m : (float, float), optional, metres
        Floor size, each side at least 7 m; a square of 7-10 m is drawn when omitted.
    cue : bool
        Add one bookshelf next to a corner (kind ``"symmetric-room-cue"``): the one thing that
        tells the symmetric poses apart. The rest of the room is drawn identically.

    Returns
    -------
    Scene
        Kind ``"symmetric-room"`` (no symmetries listed for the cue variant).
    """
    rng, seed = as_rng(rng)
    if size_m is None:
        Lx = Ly = float(rng.uniform(7.0, 10.0))
    else:
        Lx, Ly = (float(v) for v in size_m)
        if Lx < 7 or Ly < 7:
            raise ConfigError(f"symmetric room size must be at least 7 x 7 m, got {Lx} x {Ly}")
    H = float(rng.uniform(2.8, 3.6))
    b = MeshBuilder()
    b.box([-_WALL_T, -_WALL_T, -0.25], [Lx + _WALL_T, Ly + _WALL_T, 0.0], ob.SCREED.jitter(rng))
    b.box([-_WALL_T, -_WALL_T, H], [Lx + _WALL_T, Ly + _WALL_T, H + 0.25], ob.CEILING)
    walls = Walls([(0, 0), (Lx, 0), (Lx, Ly), (0, Ly)])
    make_wall = _wall_maker(rng, H)
    layouts: dict[float, MeshBuilder] = {}
    for k in range(4):
        L = walls.length(k)
        if L not in layouts:
            layouts[L] = make_wall(L)
        walls.extend_local(b, k, layouts[L])
    lamp = ob.pendant_lamp(rng, float(rng.uniform(0.3, 0.8)))
    corners = ((-1, -1), (1, -1), (1, 1), (-1, 1))  # counter-clockwise: a quarter turn apart
    for i, (sx, sy) in enumerate(corners):
        put(b, lamp, Lx / 2 + sx * Lx / 4, Ly / 2 + sy * Ly / 4, i * np.pi / 2, H)
    symmetries: tuple[NDArray[np.float64], ...] = ()
    if cue:
        _bookshelf(b, rng, walls, H)
    else:
        turns = (1, 2, 3) if Lx == Ly else (2,)
        symmetries = tuple(turn_z(Lx / 2, Ly / 2, q) for q in turns)
    kind = "symmetric-room-cue" if cue else "symmetric-room"
    return finish(b, kind, seed, Lx, Ly, margin_m=0.3, symmetries=symmetries)


def _wall_maker(rng: np.random.Generator, H: float) -> Callable[[float], MeshBuilder]:
    """Draw the wall items once; return ``make(L)`` building a wall of length ``L`` with them
    in its local frame (x along the wall, +y into the room), drawing nothing more."""
    wall_mat = ob.PLASTER.jitter(rng, 0.05)
    frame_mat = ob.WHITE_PAINT.jitter(rng, 0.05)
    leaf_mat = ob.WOOD.jitter(rng)
    door_w, door_h = float(rng.uniform(0.9, 1.1)), float(rng.uniform(2.0, 2.2))
    win_w = float(rng.uniform(1.0, 1.6))
    sill = float(rng.uniform(0.85, 1.0))
    win_top = min(H - 0.3, float(rng.uniform(2.2, 2.5)))
    radiator = ob.radiator(rng, win_w * 0.8, sill - 0.35)
    t = _WALL_T

    def make(L: float) -> MeshBuilder:
        w = MeshBuilder()
        d0 = 0.4 * L  # door from here; the window centred at a fifth of the wall
        w0 = 0.2 * L - win_w / 2
        openings = [(d0, d0 + door_w, 0.0, door_h), (w0, w0 + win_w, sill, win_top)]
        shifted = [(x0 + t, x1 + t, z0, z1) for x0, x1, z0, z1 in openings]
        for lo, hi in wall_boxes(L + 2 * t, H, t, shifted):
            w.add(box(lo - [t, t, 0], hi - [t, t, 0]), wall_mat)
        w.count("wall")
        # closed door: casing on the inner face, leaf in the middle of the reveal, handle
        cw = 0.07
        w.box([d0 - cw, 0, 0], [d0, 0.02, door_h + cw], frame_mat)
        w.box([d0 + door_w, 0, 0], [d0 + door_w + cw, 0.02, door_h + cw], frame_mat)
        w.box([d0, 0, door_h], [d0 + door_w, 0.02, door_h + cw], frame_mat)
        w.box([d0, -t / 2 - 0.02, 0.01], [d0 + door_w, -t / 2 + 0.02, door_h - 0.01], leaf_mat)
        hx = d0 + door_w - 0.08
        w.add(
            cylinder([hx, -t / 2 + 0.02, 1.0], [hx, -t / 2 + 0.08, 1.0], 0.01, segments=6),
            ob.CHROME,
        )
        w.add(
            cylinder([hx - 0.1, -t / 2 + 0.08, 1.0], [hx, -t / 2 + 0.08, 1.0], 0.01, segments=6),
            ob.CHROME,
        )
        w.count("door")
        # window: sill, frame and one mullion in the reveal
        w.box([w0 - 0.05, -0.02, sill - 0.03], [w0 + win_w + 0.05, 0.06, sill], ob.GRANITE)
        yc, fw = -t / 2, 0.05
        for xa, xb in ((w0, w0 + fw), (w0 + win_w - fw, w0 + win_w)):
            w.box([xa, yc - 0.03, sill], [xb, yc + 0.03, win_top], frame_mat)
        for za, zb in ((sill, sill + fw), (win_top - fw, win_top)):
            w.box([w0, yc - 0.03, za], [w0 + win_w, yc + 0.03, zb], frame_mat)
        xm = w0 + win_w / 2
        w.box([xm - 0.025, yc - 0.03, sill], [xm + 0.025, yc + 0.03, win_top], frame_mat)
        w.count("window")
        w.extend(radiator, t=[w0 + win_w / 2, 0.04, 0.0])
        # light switch next to the door, skirting board on both sides of it
        w.box([d0 + door_w + 0.15, 0, 1.05], [d0 + door_w + 0.23, 0.012, 1.13], frame_mat)
        w.box([0, 0, 0], [d0 - cw, 0.015, 0.08], frame_mat)
        w.box([d0 + door_w + cw, 0, 0], [L, 0.015, 0.08], frame_mat)
        return w

    return make


def _bookshelf(b: MeshBuilder, rng: np.random.Generator, walls: Walls, H: float) -> None:
    """The cue: one wide bookshelf (1.8-2.4 m) against wall 0, next to its corner with wall 1."""
    w = float(rng.uniform(1.8, 2.4))
    d = 0.4
    h = float(rng.uniform(2.0, min(2.4, H - 0.3)))
    shelf: MeshBuilder = ob.shelf(rng, w, d, h)
    walls.extend_local(b, 0, shelf, t=[walls.length(0) - 0.25 - w / 2, d / 2 + 0.02, 0.0])
