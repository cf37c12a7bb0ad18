"""Seeded procedural scenes: an indoor room, an outdoor courtyard/street, an industrial hall,
and three ambiguous scenes (a symmetric room, a featureless tunnel, repeating bays), each also
with one asymmetric cue; and project scenes sized for many stations (a multi-room building, a
warehouse of identical rack bays, a street with a side street), optionally as several
disconnected groups; and objects to scan all around (a procedural object or a mesh file,
:mod:`flexreg.synth.scenes.object`).

Every generator draws all its randomness from one ``rng`` in a fixed order, so the same seed
gives the same mesh bit for bit, and different seeds give different layouts. Geometry spans
the scales a surveyor sees: walls and facades (metres), furniture, cars and machines
(decimetres), radiator fins, book spines, railings, kerbs and ladder rungs (centimetres).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

import numpy as np

from flexreg.errors import ConfigError
from flexreg.synth.scene import Scene
from flexreg.synth.scenes._plan import side_by_side
from flexreg.synth.scenes.bays import bays
from flexreg.synth.scenes.building import building
from flexreg.synth.scenes.courtyard import courtyard
from flexreg.synth.scenes.from_mesh import add_mesh_objects, scene_from_mesh
from flexreg.synth.scenes.hall import hall
from flexreg.synth.scenes.object import (
    object_extent,
    object_from_mesh,
    procedural_object,
    with_floor,
)
from flexreg.synth.scenes.room import room
from flexreg.synth.scenes.street import street
from flexreg.synth.scenes.symmetric_room import symmetric_room
from flexreg.synth.scenes.tunnel import tunnel
from flexreg.synth.scenes.warehouse import warehouse
from flexreg.synth.seeding import as_rng

__all__ = [
    "AMBIGUOUS_SCENE_KINDS",
    "CUE_SCENE_KINDS",
    "GROUP_GAP_M",
    "OBJECT_SCENE_KINDS",
    "PROJECT_SCENE_KINDS",
    "SCENE_KINDS",
    "add_mesh_objects",
    "bays",
    "building",
    "courtyard",
    "group_sizes",
    "hall",
    "make_project_scene",
    "make_scene",
    "object_extent",
    "object_from_mesh",
    "procedural_object",
    "room",
    "scene_from_mesh",
    "street",
    "symmetric_room",
    "tunnel",
    "warehouse",
    "with_floor",
]

#: scenes whose symmetry or repetition lets several poses explain a station equally well
AMBIGUOUS_SCENE_KINDS = ("symmetric-room", "tunnel", "bays")
#: the same scenes with one asymmetric cue each, in the same order
CUE_SCENE_KINDS = ("symmetric-room-cue", "tunnel-cue", "bays-cue")
#: every procedural scene kind of :func:`make_scene`
SCENE_KINDS = ("room", "courtyard", "hall", *AMBIGUOUS_SCENE_KINDS, *CUE_SCENE_KINDS)

#: objects to scan all around with object views (``SynthConfig.views``), not with stations
OBJECT_SCENE_KINDS = ("object",)

#: scenes of multi-station projects, sized by their number of stations
PROJECT_SCENE_KINDS = ("building", "warehouse", "street")
#: empty space between the bounding boxes of disconnected groups, metres: beyond the 150 m
#: range of the default scanner (``TLSConfig.max_range_m``), so no group sees another
GROUP_GAP_M = 160.0

_PROJECT_GENERATORS: dict[str, Callable[..., Scene]] = {
    "building": building,
    "warehouse": warehouse,
    "street": street,
}

_GENERATORS: dict[str, Callable[..., Scene]] = {
    "room": room,
    "courtyard": courtyard,
    "hall": hall,
    "symmetric-room": symmetric_room,
    "tunnel": tunnel,
    "bays": bays,
    "symmetric-room-cue": partial(symmetric_room, cue=True),
    "tunnel-cue": partial(tunnel, cue=True),
    "bays-cue": partial(bays, cue=True),
}


def make_scene(
    kind: str,
    rng: np.random.Generator | int | None = 0,
    *,
    size_m: tuple[float, float] | None = None,
) -> Scene:
    """Generate a procedural scene.

    Parameters
    ----------
    kind : str
        One of :data:`SCENE_KINDS`: ``"room"``, ``"courtyard"``, ``"hall"``, the ambiguous
        ``"symmetric-room"``, ``"tunnel"``, ``"bays"`` or their ``"-cue"`` variants.
    rng : numpy Generator, int or None
        Seed or generator; the same int gives the identical mesh.
    size_m : (float, float), optional
        Floor size ``(x, y)`` in metres (``(length, width)`` for a tunnel or bays); drawn from
        the kind's range when omitted.

    Returns
    -------
    Scene

    Examples
    --------
    >>> s = make_scene("room", 1)
    >>> s.kind, s.n_triangles == make_scene("room", 1).n_triangles
    ('room', True)
    """
    if kind not in _GENERATORS:
        raise ConfigError(f"unknown scene kind {kind!r}; choose one of {', '.join(SCENE_KINDS)}")
    return _GENERATORS[kind](rng, size_m=size_m)


def group_sizes(stations: int, groups: int) -> list[int]:
    """Stations per group: as even as possible, the first groups taking one more.

    >>> group_sizes(11, 2)
    [6, 5]
    """
    return [stations // groups + (1 if g < stations % groups else 0) for g in range(groups)]


def make_project_scene(
    kind: str,
    rng: np.random.Generator | int | None = 0,
    *,
    stations: int = 12,
    groups: int = 1,
    size_m: tuple[float, float] | None = None,
) -> Scene:
    """Generate the scene of a multi-station project, sized for its stations.

    Parameters
    ----------
    kind : str
        One of :data:`PROJECT_SCENE_KINDS`: ``"building"``, ``"warehouse"``, ``"street"``.
    rng : numpy Generator, int or None
        Seed or generator; the same int gives the identical mesh.
    stations : int
        Number of stations of the whole project (>= 2 per group); each group's site is sized
        for its share (:func:`group_sizes`).
    groups : int
        Number of disconnected sites (1-4), each its own layout drawn from the same generator,
        laid out along x with :data:`GROUP_GAP_M` between them: no station of one group can
        see anything of another.
    size_m : (float, float), optional
        Size of each site (see the kind's generator); drawn from ``stations`` when omitted.

    Returns
    -------
    Scene
        With ``zones`` (placement rectangles, each with its group id) and ``layout``.
    """
    if kind not in _PROJECT_GENERATORS:
        raise ConfigError(
            f"unknown project scene kind {kind!r}; choose one of {', '.join(PROJECT_SCENE_KINDS)}"
        )
    if isinstance(groups, bool) or int(groups) != groups or not 1 <= groups <= 4:
        raise ConfigError(f"groups must be 1..4, got {groups}")
    if isinstance(stations, bool) or int(stations) != stations or stations < 2 * groups:
        raise ConfigError(
            f"a project needs at least 2 stations per group, got {stations} for {groups} group(s)"
        )
    gen, seed = as_rng(rng)
    parts = [
        _PROJECT_GENERATORS[kind](gen, stations=n, size_m=size_m)
        for n in group_sizes(int(stations), int(groups))
    ]
    return side_by_side(parts, kind, seed, GROUP_GAP_M)
