"""Scenes from any triangle mesh, and mesh objects added to a scene."""

from __future__ import annotations

from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.errors import ConfigError, InputError
from flexreg.synth import objects as ob
from flexreg.synth.mesh import Material, MeshBuilder, rot_z
from flexreg.synth.scene import Scene
from flexreg.synth.seeding import as_rng


def _load_mesh(
    mesh: Any,
) -> tuple[NDArray[np.float64], NDArray[np.int32], NDArray[np.uint8] | None, str]:
    import open3d as o3d  # heavy: loaded only to read a mesh

    if isinstance(mesh, (str, PathLike)):
        p = Path(mesh)
        if not p.is_file():
            raise InputError(p, "no such mesh file")
        m = o3d.io.read_triangle_mesh(p)
        name = p.stem
        if len(m.triangles) == 0:
            raise InputError(p, "mesh has no triangles (or could not be read)")
    elif isinstance(mesh, o3d.geometry.TriangleMesh):
        m, name = mesh, "mesh"
    else:
        raise InputError(
            "mesh", f"expected a path or an open3d TriangleMesh, got {type(mesh).__name__}"
        )
    V = np.asarray(m.vertices, dtype=np.float64)
    F = np.asarray(m.triangles, dtype=np.int32)
    if len(F) == 0:
        raise InputError(name, "mesh has no triangles")
    cols = None
    if m.has_vertex_colors():
        vc = np.asarray(m.vertex_colors)
        cols = np.clip(vc[F].mean(axis=1) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    return V, F, cols, name


def scene_from_mesh(
    mesh: str | PathLike[str] | Any,
    *,
    scale: float = 1.0,
    reflectance: float = 0.5,
    ground: bool = True,
    ground_margin_m: float = 10.0,
    up_axis: str = "z",
) -> Scene:
    """Use any triangle mesh (PLY, OBJ, STL, ... or an open3d mesh) as a scene.

    The mesh is turned so that ``up_axis`` points up, scaled by ``scale``, and moved so its
    lowest point is at ``z = 0`` and its bounding box is centred on the origin. With ``ground``
    a ground plane reaching ``ground_margin_m`` past the mesh is added, so that stations can
    stand around an object.

    Parameters
    ----------
    mesh : path-like or open3d.geometry.TriangleMesh
    scale : float
        Factor to metres (e.g. 40 makes the 0.15 m Stanford bunny a 6 m sculpture).
    reflectance : float
        Laser reflectance of the mesh, 0..1.
    up_axis : {"x", "y", "z"}
        The mesh's up direction (``"y"`` for most OBJ files and the Stanford models).
    """
    if not (np.isfinite(scale) and scale > 0):
        raise ConfigError(f"scale must be positive, got {scale}")
    if not 0 < reflectance <= 1:
        raise ConfigError(f"reflectance must be in (0, 1], got {reflectance}")
    turn = {
        "z": np.eye(3),
        "y": np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]),
        "x": np.array([[0, 0, -1.0], [0, 1, 0], [1, 0, 0]]),
    }
    if up_axis not in turn:
        raise ConfigError(f"up_axis must be x, y or z, got {up_axis!r}")
    V, F, cols, name = _load_mesh(mesh)
    V = (V @ turn[up_axis].T) * scale
    lo, hi = V.min(axis=0), V.max(axis=0)
    V = V - [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]]
    lo, hi = V.min(axis=0), V.max(axis=0)
    b = MeshBuilder()
    b.add((V, F), Material(reflectance, (180, 180, 180)))
    V2, T2, refl, rgb = b.arrays()
    if cols is not None:
        rgb = cols
    m = ground_margin_m
    region = (
        float(lo[0] - m * 0.8),
        float(lo[1] - m * 0.8),
        float(hi[0] + m * 0.8),
        float(hi[1] + m * 0.8),
    )
    if ground:
        gb = MeshBuilder()
        gb.box([lo[0] - m, lo[1] - m, -0.3], [hi[0] + m, hi[1] + m, 0.0], ob.PAVING)
        Vg, Tg, rg, cg = gb.arrays()
        T2 = np.vstack([T2, Tg + len(V2)])
        V2 = np.vstack([V2, Vg])
        refl = np.concatenate([refl, rg])
        rgb = np.vstack([rgb, cg])
    else:
        region = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
    return Scene(
        V2,
        T2,
        refl,
        rgb,
        kind="mesh",
        seed=None,
        floor_z=0.0 if ground else float(lo[2]),
        region=region,
        objects={name: 1},
        name=name,
    )


def add_mesh_objects(
    scene: Scene,
    mesh: str | PathLike[str] | Any,
    *,
    count: int = 1,
    size_m: float = 0.5,
    reflectance: float = 0.5,
    rng: np.random.Generator | int | None = 0,
) -> Scene:
    """Return a new scene with ``count`` copies of a mesh standing on free floor spots.

    Each copy is scaled so its largest extent is ``size_m`` (times 0.8-1.2), turned by a random
    yaw and set on the floor where a downward ray finds the bare floor in a clear 2 x extent
    square.
    """
    rng, _ = as_rng(rng)
    if count < 0 or size_m <= 0:
        raise ConfigError(f"count must be >= 0 and size_m > 0, got {count}, {size_m}")
    V, F, _cols, name = _load_mesh(mesh)
    ext = float((V.max(axis=0) - V.min(axis=0)).max())
    if ext <= 0:
        raise InputError(name, "mesh has zero extent")
    V = V - [
        (V[:, 0].min() + V[:, 0].max()) / 2,
        (V[:, 1].min() + V[:, 1].max()) / 2,
        V[:, 2].min(),
    ]
    b = MeshBuilder()
    placed = 0
    x0, y0, x1, y1 = scene.region
    for _ in range(count * 50):
        if placed == count:
            break
        s = size_m * rng.uniform(0.8, 1.2)
        c = np.array([rng.uniform(x0, x1), rng.uniform(y0, y1)])
        yaw = rng.uniform(-np.pi, np.pi)
        g = (
            np.stack(np.meshgrid(np.linspace(-s, s, 5), np.linspace(-s, s, 5)), -1).reshape(-1, 2)
            + c
        )
        origins = np.column_stack([g, np.full(len(g), scene.floor_z + 2.0)])
        hits = scene.cast(origins, np.tile([0.0, 0.0, -1.0], (len(g), 1)))
        z = origins[:, 2] - hits.t
        if not (
            np.all(np.isfinite(z))
            and np.all(np.abs(z - scene.floor_z) < 0.05)
            and np.all(hits.normal[:, 2] > 0.9)
        ):
            continue
        b.add(
            (V * (s / ext), F),
            Material(reflectance, (200, 200, 200)),
            R=rot_z(yaw),
            t=[c[0], c[1], float(np.median(z))],
        )
        placed += 1
    if placed < count:
        raise InputError(name, f"found free floor for only {placed} of {count} copies")
    Vn, Tn, rn, cn = b.arrays()
    objects = dict(scene.objects)
    objects[name] = objects.get(name, 0) + placed
    return Scene(
        np.vstack([scene.vertices, Vn]),
        np.vstack([scene.triangles, Tn + len(scene.vertices)]),
        np.concatenate([scene.reflectance, rn]),
        np.vstack([scene.colors, cn]),
        kind=scene.kind,
        seed=scene.seed,
        floor_z=scene.floor_z,
        region=scene.region,
        objects=objects,
        name=scene.name,
    )
