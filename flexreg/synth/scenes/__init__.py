"""Seeded procedural scenes: an indoor room, an outdoor courtyard/street, an industrial hall,
and three ambiguous scenes (a symmetric room, a featureless tunnel, repeating bays), each also
with one asymmetric cue.

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
from flexreg.synth.scenes.bays import bays
from flexreg.synth.scenes.courtyard import courtyard
from flexreg.synth.scenes.from_mesh import add_mesh_objects, scene_from_mesh
from flexreg.synth.scenes.hall import hall
from flexreg.synth.scenes.room import room
from flexreg.synth.scenes.symmetric_room import symmetric_room
from flexreg.synth.scenes.tunnel import tunnel

__all__ = [
    "AMBIGUOUS_SCENE_KINDS",
    "CUE_SCENE_KINDS",
    "SCENE_KINDS",
    "add_mesh_objects",
    "bays",
    "courtyard",
    "hall",
    "make_scene",
    "room",
    "scene_from_mesh",
    "symmetric_room",
    "tunnel",
]

#: scenes whose symmetry or repetition lets several poses explain a station equally well
AMBIGUOUS_SCENE_KINDS = ("symmetric-room", "tunnel", "bays")
#: the same scenes with one asymmetric cue each, in the same order
CUE_SCENE_KINDS = ("symmetric-room-cue", "tunnel-cue", "bays-cue")
#: every procedural scene kind of :func:`make_scene`
SCENE_KINDS = ("room", "courtyard", "hall", *AMBIGUOUS_SCENE_KINDS, *CUE_SCENE_KINDS)

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
