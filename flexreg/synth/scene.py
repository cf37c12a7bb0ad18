"""The :class:`Scene`: a triangle mesh with materials, a floor, and a ray caster.

Sensors ray-cast a scene with open3d's :class:`open3d.t.geometry.RaycastingScene` (Embree). The
casts are deterministic ray by ray, whatever the number of threads, so a scene, a pose and a
seed fix a scan exactly.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.errors import InputError
from flexreg.io import atomic_write

if TYPE_CHECKING:
    import open3d as o3d

#: open3d's id for "no primitive hit"
_INVALID_ID = np.uint32(0xFFFFFFFF)


@dataclass(eq=False)
class RayHits:
    """Result of :meth:`Scene.cast`.

    Attributes
    ----------
    t : (N,) float64, metres
        Distance along each (unit) ray to the first hit; ``inf`` for a miss.
    primitive : (N,) int64
        Index of the triangle hit, -1 for a miss.
    normal : (N, 3) float32
        Unit normal of the triangle hit (as wound, i.e. outward for closed objects); 0 for a miss.
    """

    t: NDArray[np.float64]
    primitive: NDArray[np.int64]
    normal: NDArray[np.float32]

    @property
    def hit(self) -> NDArray[np.bool_]:
        """(N,) bool, rays that hit something."""
        return self.primitive >= 0


@dataclass(eq=False)
class Scene:
    """A static world to scan: triangles with a reflectance and a colour each.

    Attributes
    ----------
    vertices : (V, 3) float64, metres
        World coordinates, Z up.
    triangles : (T, 3) int32
        Vertex indices, counter-clockwise seen from outside.
    reflectance : (T,) float32
        Laser reflectance of each triangle, 0..1.
    colors : (T, 3) uint8
        RGB base colour of each triangle.
    kind : str
        A kind of :data:`~flexreg.synth.scenes.SCENE_KINDS` or ``"mesh"``.
    seed : int or None
        Seed the scene was generated with, if it was an int.
    floor_z : float, metres
        Nominal height of the ground where sensors stand.
    region : (xmin, ymin, xmax, ymax) float, metres
        Area in which sensors may be placed.
    objects : dict of str to int
        Number of objects of each category (for summaries).
    name : str
    symmetries : tuple of (4, 4) float64
        World motions ``S`` (``p -> S p``) that map the scene's structure, as seen from its
        placement ``region`` within a scanner's range, onto itself: a station at
        ``S @ T_world_scanner`` then measures (nearly) the same scan as one at
        ``T_world_scanner``. Empty for scenes without such ambiguity (every scene except the
        ``symmetric-room``, ``tunnel`` and ``bays`` kinds); a tunnel lists samples of its
        continuous family of shifts along the axis.
    zones : tuple of (xmin, ymin, xmax, ymax, group)
        Where the stations of a multi-station *project* may stand (metres), each rectangle
        with the id of the disconnected group it belongs to; empty for single-space scenes,
        whose stations stand anywhere in ``region``.
    layout : dict of str to Any
        JSON-ready facts of a project's layout (rooms, bay period, street lengths...).
    stand_points : tuple of (x, y, group)
        Spots where a surveyor would set up to link two spaces (in front of and behind each
        doorway, a corridor junction), metres; placement starts on the first one and tries
        them when the open floor around a station is taken. Not stored in files.
    """

    vertices: NDArray[np.float64]
    triangles: NDArray[np.int32]
    reflectance: NDArray[np.float32]
    colors: NDArray[np.uint8]
    kind: str = "mesh"
    seed: int | None = None
    floor_z: float = 0.0
    region: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    objects: dict[str, int] = field(default_factory=dict)
    name: str = ""
    symmetries: tuple[NDArray[np.float64], ...] = ()
    zones: tuple[tuple[float, float, float, float, int], ...] = ()
    layout: dict[str, Any] = field(default_factory=dict)
    stand_points: tuple[tuple[float, float, int], ...] = ()
    _raycaster: Any = field(default=None, init=False, repr=False)
    _cache: dict[str, Any] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        src = self.name or "scene"
        self.vertices = np.ascontiguousarray(self.vertices, dtype=np.float64)
        self.triangles = np.ascontiguousarray(self.triangles, dtype=np.int32)
        if self.vertices.ndim != 2 or self.vertices.shape[1] != 3:
            raise InputError(src, f"vertices must be (V, 3), got {self.vertices.shape}")
        if self.triangles.ndim != 2 or self.triangles.shape[1] != 3 or len(self.triangles) == 0:
            raise InputError(
                src, f"triangles must be a non-empty (T, 3), got {self.triangles.shape}"
            )
        if not np.all(np.isfinite(self.vertices)):
            raise InputError(src, "vertices hold NaN or Inf")
        if self.triangles.min() < 0 or self.triangles.max() >= len(self.vertices):
            raise InputError(src, "triangle index out of range")
        T = len(self.triangles)
        self.reflectance = np.ascontiguousarray(
            np.broadcast_to(np.asarray(self.reflectance, dtype=np.float32), (T,))
        )
        self.colors = np.ascontiguousarray(
            np.broadcast_to(np.asarray(self.colors, dtype=np.uint8), (T, 3))
        )
        self.symmetries = tuple(np.array(S, dtype=np.float64) for S in self.symmetries)
        self.zones = tuple(
            (float(a), float(b), float(c), float(d), int(g)) for a, b, c, d, g in self.zones
        )
        if self.region == (0.0, 0.0, 0.0, 0.0):
            lo, hi = self.bounds
            self.region = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))

    def __repr__(self) -> str:
        lo, hi = self.bounds
        size = "x".join(f"{v:.1f}" for v in hi - lo)
        return f"Scene({self.kind!r}, seed={self.seed}, {len(self.triangles)} triangles, {size} m)"

    # ------------------------------------------------------------------ properties
    @property
    def n_triangles(self) -> int:
        return len(self.triangles)

    @property
    def bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(min (3,), max (3,))`` corners of the axis-aligned bounding box, metres."""
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    def triangle_normals(self) -> NDArray[np.float64]:
        """(T, 3) float64 unit normals from the winding (zero for degenerate triangles)."""
        V, F = self.vertices, self.triangles
        n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
        norm = np.linalg.norm(n, axis=1, keepdims=True)
        return np.divide(n, norm, out=np.zeros_like(n), where=norm > 0)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description (no geometry); ``symmetries``, ``zones_m`` and ``layout`` only
        when there are any."""
        lo, hi = self.bounds
        d = {
            "kind": self.kind,
            "seed": self.seed,
            "name": self.name,
            "triangles": self.n_triangles,
            "vertices": len(self.vertices),
            "bounds_m": [lo.tolist(), hi.tolist()],
            "floor_z_m": self.floor_z,
            "region_m": list(self.region),
            "objects": dict(sorted(self.objects.items())),
        }
        if self.symmetries:
            d["symmetries"] = [S.tolist() for S in self.symmetries]
        if self.zones:
            d["zones_m"] = [list(z) for z in self.zones]
        if self.layout:
            d["layout"] = dict(self.layout)
        return d

    # ------------------------------------------------------------------ ray casting
    def raycaster(self) -> Any:
        """The open3d ``RaycastingScene`` of this mesh (built once, then cached)."""
        if self._raycaster is None:
            import open3d as o3d

            rc = o3d.t.geometry.RaycastingScene()
            rc.add_triangles(
                o3d.core.Tensor.from_numpy(np.ascontiguousarray(self.vertices, dtype=np.float32)),
                o3d.core.Tensor.from_numpy(np.ascontiguousarray(self.triangles, dtype=np.uint32)),
            )
            self._raycaster = rc
        return self._raycaster

    def cast(self, origins: ArrayLike, directions: ArrayLike) -> RayHits:
        """Cast rays and return the first hits.

        Parameters
        ----------
        origins : (N, 3) or (3,) float, metres
        directions : (N, 3) float
            Unit directions (``t`` is then a distance in metres).

        Returns
        -------
        RayHits
        """
        import open3d as o3d

        D = np.asarray(directions, dtype=np.float32).reshape(-1, 3)
        Og = np.broadcast_to(np.asarray(origins, dtype=np.float32).reshape(-1, 3), D.shape)
        rays = np.empty((len(D), 6), dtype=np.float32)
        rays[:, :3] = Og
        rays[:, 3:] = D
        ans = self.raycaster().cast_rays(o3d.core.Tensor.from_numpy(rays))
        prim = ans["primitive_ids"].numpy()
        miss = prim == _INVALID_ID
        t = ans["t_hit"].numpy().astype(np.float64)
        t[miss] = np.inf
        primitive = prim.astype(np.int64)
        primitive[miss] = -1
        return RayHits(t=t, primitive=primitive, normal=ans["primitive_normals"].numpy())

    def distance(self, points: ArrayLike) -> NDArray[np.float64]:
        """(N,) float64 unsigned distance (metres) from each point to the nearest triangle."""
        import open3d as o3d

        P = np.asarray(points, dtype=np.float32).reshape(-1, 3)
        d = self.raycaster().compute_distance(o3d.core.Tensor.from_numpy(np.ascontiguousarray(P)))
        return d.numpy().astype(np.float64)

    # ------------------------------------------------------------------ export
    def to_open3d(self) -> o3d.geometry.TriangleMesh:
        """Legacy open3d mesh with vertex colours (each vertex takes a colour of a triangle using
        it; primitives never share vertices, so objects keep their colour)."""
        import open3d as o3d

        m = o3d.geometry.TriangleMesh(
            o3d.utility.Vector3dVector(self.vertices), o3d.utility.Vector3iVector(self.triangles)
        )
        vc = np.zeros((len(self.vertices), 3))
        vc[self.triangles.reshape(-1)] = np.repeat(self.colors / 255.0, 3, axis=0)
        m.vertex_colors = o3d.utility.Vector3dVector(vc)
        m.compute_triangle_normals()
        return m

    def write(self, path: str | PathLike[str]) -> Path:
        """Write the mesh as binary little-endian PLY with per-face colour and reflectance.

        The file holds float64 vertices (exact ground truth), int32 faces, and per face
        ``red green blue`` (uint8) and ``reflectance`` (float32); identical scenes give
        identical bytes.
        """
        p = Path(path)
        if p.suffix.lower() != ".ply":
            raise InputError(p, "scene meshes are written as .ply")
        nv, nf = len(self.vertices), len(self.triangles)
        header = (
            "ply\nformat binary_little_endian 1.0\ncomment flexreg synthetic scene "
            f"kind={self.kind} seed={self.seed} floor_z={self.floor_z!r} "
            f"region={','.join(repr(float(v)) for v in self.region)}\n"
            f"element vertex {nv}\nproperty double x\nproperty double y\nproperty double z\n"
            f"element face {nf}\nproperty list uchar int vertex_indices\n"
            "property uchar red\nproperty uchar green\nproperty uchar blue\n"
            "property float reflectance\nend_header\n"
        ).encode("ascii")
        face_dtype = np.dtype(
            [("n", "u1"), ("v", "<i4", (3,)), ("rgb", "u1", (3,)), ("refl", "<f4")]
        )
        faces = np.empty(nf, dtype=face_dtype)
        faces["n"] = 3
        faces["v"] = self.triangles
        faces["rgb"] = self.colors
        faces["refl"] = self.reflectance

        def _write(tmp: Path) -> None:
            with open(tmp, "wb") as f:
                f.write(header)
                f.write(self.vertices.astype("<f8").tobytes())
                f.write(faces.tobytes())

        atomic_write(p, _write)
        return p


def read_scene(path: str | PathLike[str]) -> Scene:
    """Read a mesh written by :meth:`Scene.write` back (exact vertices, colours, reflectance).

    Other meshes are read by :func:`flexreg.synth.scene_from_mesh`.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(p, "no such file")
    data = p.read_bytes()
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply\n") or end < 0:
        raise InputError(p, "not a PLY file")
    header = data[:end].decode("ascii", errors="replace")
    if "property float reflectance" not in header or "binary_little_endian" not in header:
        raise InputError(p, "not a flexreg scene mesh; use scene_from_mesh for other meshes")
    nv = nf = 0
    kind, seed, floor_z = "mesh", None, 0.0
    region = (0.0, 0.0, 0.0, 0.0)
    for line in header.splitlines():
        parts = line.split()
        if parts[:2] == ["element", "vertex"]:
            nv = int(parts[2])
        elif parts[:2] == ["element", "face"]:
            nf = int(parts[2])
        elif parts[:3] == ["comment", "flexreg", "synthetic"]:
            for kv in parts[3:]:
                k, _, v = kv.partition("=")
                if k == "kind":
                    kind = v
                elif k == "seed" and v != "None":
                    seed = int(v)
                elif k == "floor_z":
                    floor_z = float(v)
                elif k == "region":
                    a, b, c, d = (float(x) for x in v.split(","))
                    region = (a, b, c, d)
    body = data[end + len(b"end_header\n") :]
    face_dtype = np.dtype([("n", "u1"), ("v", "<i4", (3,)), ("rgb", "u1", (3,)), ("refl", "<f4")])
    if len(body) != nv * 24 + nf * face_dtype.itemsize:
        raise InputError(p, "truncated or inconsistent PLY body")
    V = np.frombuffer(body[: nv * 24], dtype="<f8").reshape(nv, 3).astype(np.float64)
    F = np.frombuffer(body[nv * 24 :], dtype=face_dtype)
    return Scene(
        V,
        F["v"].astype(np.int32),
        F["refl"].astype(np.float32),
        F["rgb"].astype(np.uint8),
        kind=kind,
        seed=seed,
        floor_z=floor_z,
        region=region,
        name=p.stem,
    )
