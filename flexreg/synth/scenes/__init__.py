"""Seeded procedural scenes: an indoor room, an outdoor courtyard/street, an industrial hall.

Every generator draws all its randomness from one ``rng`` in a fixed order, so the same seed
gives the same mesh bit for bit, and different seeds give different layouts. Geometry spans
the scales a surveyor sees: walls and facades (metres), furniture, cars and machines
(decimetres), radiator fins, book spines, railings, kerbs and ladder rungs (centimetres).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from flexreg.errors import ConfigError
from flexreg.synth.scene import Scene
from flexreg.synth.scenes.courtyard import courtyard
from flexreg.synth.scenes.from_mesh import add_mesh_objects, scene_from_mesh
from flexreg.synth.scenes.hall import hall
from flexreg.synth.scenes.room import room

__all__ = [
    "SCENE_KINDS",
    "add_mesh_objects",
    "courtyard",
    "hall",
    "make_scene",
    "room",
    "scene_from_mesh",
]

SCENE_KINDS = ("room", "courtyard", "hall")


def make_scene(
    kind: str,
    rng: np.random.Generator | int | None = 0,
    *,
    size_m: tuple[float, float] | None = None,
) -> Scene:
    """Generate a procedural scene.

    Parameters
    ----------
    kind : {"room", "courtyard", "hall"}
    rng : numpy Generator, int or None
        Seed or generator; the same int gives the identical mesh.
    size_m : (float, float), optional
        Floor size ``(x, y)`` in metres; drawn from the kind's range when omitted.

    Returns
    -------
    Scene

    Examples
    --------
    >>> s = make_scene("room", 1)
    >>> s.kind, s.n_triangles == make_scene("room", 1).n_triangles
    ('room', True)
    """
    gens: dict[str, Callable[..., Scene]] = {"room": room, "courtyard": courtyard, "hall": hall}
    if kind not in gens:
        raise ConfigError(f"unknown scene kind {kind!r}; choose one of {', '.join(SCENE_KINDS)}")
    return gens[kind](rng, size_m=size_m)
