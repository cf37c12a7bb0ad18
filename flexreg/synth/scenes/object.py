"""Objects to scan all around: a seeded procedural object, or a mesh file, alone in the air or
on a floor.

An object scene records where the object is in ``Scene.layout``: ``object_center_m`` (the
centre of its bounding box, metres) and ``object_radius_m`` (the radius of the sphere about
that centre that holds it), so that views can be set up around it whatever else the scene
holds (a floor).
"""

from __future__ import annotations

from dataclasses import replace
from os import PathLike
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.errors import InputError
from flexreg.synth import objects as ob
from flexreg.synth.mesh import Material, MeshBuilder, box, cylinder, ellipsoid, frustum, tube
from flexreg.synth.scene import Scene
from flexreg.synth.scenes.from_mesh import scene_from_mesh
from flexreg.synth.seeding import as_rng

__all__ = ["object_extent", "object_from_mesh", "procedural_object", "with_floor"]


def _rotation(rng: np.random.Generator) -> NDArray[np.float64]:
    """A uniformly random rotation (3, 3) from a normalised Gaussian quaternion."""
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _on_body(
    rng: np.random.Generator,
    center: NDArray[np.float64],
    radii: NDArray[np.float64],
    depth: float = 0.85,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A point at ``depth`` of the body's radius along a random direction of its upper three
    quarters, and its outward direction."""
    d = rng.normal(size=3)
    d[2] = abs(d[2]) * 0.8 - 0.2 * np.linalg.norm(d[:2])
    d /= np.linalg.norm(d)
    p = center + depth * radii * d
    n = d / radii
    return p, n / np.linalg.norm(n)


def procedural_object(rng: np.random.Generator | int | None = 0, *, floor: bool = False) -> Scene:
    """A seeded object of about 0.3 m to scan all around (a figurine or a machined part).

    A turned pedestal with thin rings (1-3 mm steps), an irregular body (a rough ellipsoid),
    bent handles, knobs and small bumps (6-12 mm) attached at random places: every side
    looks different, and detail spans centimetres to millimetres.

    Parameters
    ----------
    rng : numpy Generator, int or None
        Every dimension, place and colour is drawn from it in a fixed order.
    floor : bool
        Stand the object on a floor (:func:`with_floor`); by default it floats alone.

    Returns
    -------
    Scene
        Kind ``"object"``, ``layout`` with ``object_center_m`` and ``object_radius_m``.

    Examples
    --------
    >>> s = procedural_object(3)
    >>> s.kind, 0.1 < s.layout["object_radius_m"] < 0.3
    ('object', True)
    """
    gen, seed = as_rng(rng)
    s = gen.uniform(0.25, 0.35)  # overall size, metres
    b = MeshBuilder()
    # pedestal: a frustum with two or three thin rings
    h_ped, r_ped = gen.uniform(0.12, 0.18) * s, gen.uniform(0.2, 0.26) * s
    b.add(frustum([0, 0, 0], [0, 0, h_ped], r_ped, 0.8 * r_ped, segments=48), ob.DARK_WOOD)
    for k in range(int(gen.integers(2, 4))):
        z = h_ped * (0.2 + 0.25 * k) + gen.uniform(-0.02, 0.02) * s
        step = gen.uniform(0.001, 0.003)
        r = r_ped * (1.0 - 0.2 * (z / h_ped)) + step
        b.add(cylinder([0, 0, z], [0, 0, z + gen.uniform(0.004, 0.008)], r, segments=48), ob.METAL)
    # body: a rough ellipsoid leaning a little
    radii = np.array([gen.uniform(0.28, 0.36), gen.uniform(0.2, 0.26), gen.uniform(0.2, 0.28)]) * s
    c = np.array([gen.uniform(-0.03, 0.03) * s, gen.uniform(-0.03, 0.03) * s, h_ped + radii[2]])
    body = Material.random(gen, 0.55, 90, 220)
    b.add(ellipsoid(c, radii, subdivisions=4, roughness=0.12, rng=gen), body)
    # bent handles
    for _ in range(int(gen.integers(2, 4))):
        p, n = _on_body(gen, c, radii)
        side = np.cross(n, gen.normal(size=3))
        side /= np.linalg.norm(side)
        reach, bend = gen.uniform(0.12, 0.22) * s, gen.uniform(0.6, 1.4)
        a = np.linspace(0.0, bend, 8)[:, None]
        path = p + reach * (np.sin(a) * n + (1 - np.cos(a)) * side) / max(np.sin(bend), 0.5)
        b.add(tube(path, gen.uniform(0.02, 0.035) * s, segments=16), ob.CHROME.jitter(gen))
    # knobs: small boxes set into the body at random angles
    for _ in range(int(gen.integers(3, 6))):
        p, _n = _on_body(gen, c, radii, 1.0)
        half = gen.uniform(0.03, 0.06, size=3) * s
        b.add(box(-half, half), ob.PLASTIC.jitter(gen, 0.4), R=_rotation(gen), t=p)
    # bumps: small spheres half sunk into the surface
    for _ in range(int(gen.integers(4, 9))):
        p, n = _on_body(gen, c, radii)
        r = gen.uniform(0.006, 0.012)
        b.add(ellipsoid(p + 0.18 * radii * n, r, subdivisions=2), ob.SAFETY_YELLOW.jitter(gen))
    V, T, refl, rgb = b.arrays()
    scene = _object_scene(V, T, refl, rgb, kind="object", seed=seed, name="object")
    return with_floor(scene) if floor else scene


def object_from_mesh(
    mesh: str | PathLike[str] | Any,
    *,
    scale: float = 1.0,
    up_axis: str = "z",
    floor: bool = False,
) -> Scene:
    """A mesh file (PLY, OBJ, STL...) as an object to scan all around.

    The mesh is turned and scaled as by :func:`~flexreg.synth.scenes.scene_from_mesh`
    (``up_axis`` up, ``scale`` to metres, its lowest point at ``z = 0``, its footprint
    centred on the origin), without the ground plane of that function.

    Parameters
    ----------
    mesh : path-like or open3d.geometry.TriangleMesh
    scale : float
        Factor to metres (1 for the Stanford bunny's files, about 0.15 m tall).
    up_axis : {"x", "y", "z"}
    floor : bool
        Stand the object on a floor (:func:`with_floor`).

    Returns
    -------
    Scene
        Kind ``"mesh"``, ``layout`` with ``object_center_m`` and ``object_radius_m``.
    """
    m = scene_from_mesh(mesh, scale=scale, up_axis=up_axis, ground=False)
    scene = _object_scene(
        m.vertices, m.triangles, m.reflectance, m.colors, kind="mesh", seed=None, name=m.name
    )
    scene = replace(scene, objects=dict(m.objects))
    return with_floor(scene) if floor else scene


def _object_scene(
    V: NDArray[np.float64],
    T: NDArray[np.int32],
    refl: NDArray[np.float32],
    rgb: NDArray[np.uint8],
    *,
    kind: str,
    seed: int | None,
    name: str,
) -> Scene:
    lo, hi = V.min(axis=0), V.max(axis=0)
    center = (lo + hi) / 2
    radius = float(np.linalg.norm(V - center, axis=1).max())
    if not radius > 0:
        raise InputError(name, "the object has no extent")
    return Scene(
        V,
        T,
        refl,
        rgb,
        kind=kind,
        seed=seed,
        floor_z=float(lo[2]),
        region=(float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])),
        objects={name: 1},
        name=name,
        layout={"object_center_m": center.tolist(), "object_radius_m": radius},
    )


def object_extent(scene: Scene) -> tuple[NDArray[np.float64], float]:
    """Centre (3,) float64 and radius (float), metres, of the object of an object scene.

    Raises
    ------
    InputError
        The scene is not an object scene (no ``object_center_m`` in its layout).
    """
    lay = scene.layout
    if "object_center_m" not in lay or "object_radius_m" not in lay:
        raise InputError(scene.name or "scene", "not an object scene (no object centre)")
    return np.asarray(lay["object_center_m"], dtype=np.float64), float(lay["object_radius_m"])


def with_floor(scene: Scene) -> Scene:
    """The object scene on a floor: a slab 4 radii square whose top touches the object's
    lowest point (a table top under a figurine)."""
    c, r = object_extent(scene)
    z = float(scene.vertices[:, 2].min())
    fb = MeshBuilder()
    fb.box([c[0] - 2 * r, c[1] - 2 * r, z - 0.1 * r], [c[0] + 2 * r, c[1] + 2 * r, z], ob.WOOD)
    Vf, Tf, rf, cf = fb.arrays()
    objects = dict(scene.objects)
    objects["floor"] = 1
    return replace(
        scene,
        vertices=np.vstack([scene.vertices, Vf]),
        triangles=np.vstack([scene.triangles, Tf + len(scene.vertices)]),
        reflectance=np.concatenate([scene.reflectance, rf]),
        colors=np.vstack([scene.colors, cf]),
        floor_z=z,
        objects=objects,
    )
