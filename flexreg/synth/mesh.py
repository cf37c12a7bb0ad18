"""Triangle-mesh primitives for the procedural scenes, built with numpy.

Every primitive returns ``(vertices (V, 3) float64, triangles (T, 3) int32)`` with outward-facing
(counter-clockwise seen from outside) triangles, so a ray that starts inside a closed object hits
a back face. :class:`MeshBuilder` collects primitives with a pose and a :class:`Material` and
concatenates them into one mesh with per-triangle reflectance and colour.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from itertools import pairwise

import numpy as np
from numpy.typing import ArrayLike, NDArray

Mesh = tuple[NDArray[np.float64], NDArray[np.int32]]

# vertex k of a box: x from bit 0 of (0,1,1,0), y from (0,0,1,1), z from k >= 4
_BOX_CORNERS = np.array(
    [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
    dtype=np.float64,
)
_BOX_TRIANGLES = np.array(
    [
        [0, 2, 1], [0, 3, 2],  # z = lo, normal -z
        [4, 5, 6], [4, 6, 7],  # z = hi, normal +z
        [0, 1, 5], [0, 5, 4],  # y = lo, normal -y
        [2, 3, 7], [2, 7, 6],  # y = hi, normal +y
        [1, 2, 6], [1, 6, 5],  # x = hi, normal +x
        [3, 0, 4], [3, 4, 7],  # x = lo, normal -x
    ],
    dtype=np.int32,
)  # fmt: skip


@dataclass(frozen=True)
class Material:
    """Surface properties used by the simulated sensors.

    Attributes
    ----------
    reflectance : float
        Diffuse reflectance at the laser wavelength, 0..1 (intensity at normal incidence).
    rgb : (int, int, int)
        Base colour for the shaded camera images, 0..255.
    """

    reflectance: float
    rgb: tuple[int, int, int]

    def jitter(self, rng: np.random.Generator, amount: float = 0.08) -> Material:
        """A slightly different shade of this material (per-object variation)."""
        f = 1.0 + amount * rng.uniform(-1.0, 1.0)
        r, g, b = (
            int(np.clip(round(c * (f + 0.5 * amount * rng.uniform(-1, 1))), 0, 255))
            for c in self.rgb
        )
        return Material(float(np.clip(self.reflectance * f, 0.01, 1.0)), (r, g, b))

    @classmethod
    def random(
        cls, rng: np.random.Generator, reflectance: float, lo: int = 20, hi: int = 235
    ) -> Material:
        """A material of the given reflectance and a random colour, channels in ``[lo, hi)``."""
        r, g, b = (int(c) for c in rng.integers(lo, hi, 3))
        return cls(float(reflectance), (r, g, b))


def rot_z(yaw: float) -> NDArray[np.float64]:
    """(3, 3) rotation by ``yaw`` radians about +Z."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def box(lo: ArrayLike, hi: ArrayLike) -> Mesh:
    """Axis-aligned box between corners ``lo`` and ``hi`` (metres), 8 vertices, 12 triangles."""
    lo_ = np.asarray(lo, dtype=np.float64)
    hi_ = np.asarray(hi, dtype=np.float64)
    return lo_ + _BOX_CORNERS * (hi_ - lo_), _BOX_TRIANGLES.copy()


def hexahedron(corners: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Convex hexahedron from 8 corners ordered like :func:`box`'s."""
    _, T = box([0, 0, 0], [1, 1, 1])
    return np.asarray(corners, dtype=np.float64).reshape(8, 3), T


def _frame(tangent: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two unit vectors ``u, v`` with ``(u, v, tangent)`` right-handed and orthonormal."""
    t = tangent / np.linalg.norm(tangent)
    helper = np.array([0.0, 0.0, 1.0]) if abs(t[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(helper, t)
    u /= np.linalg.norm(u)
    return u, np.cross(t, u)


def tube(
    path: ArrayLike, radius: float | ArrayLike, *, segments: int = 16, caps: bool = True
) -> Mesh:
    """Circular tube swept along a polyline (pipes, rails, cylinders, frusta).

    Parameters
    ----------
    path : (K, 3) float, metres
        Centre line, ``K >= 2`` distinct consecutive points.
    radius : float or (K,) float, metres
        Radius at each path point (a frustum when it varies).
    segments : int
        Vertices around the circumference.
    caps : bool
        Close both ends with flat discs.
    """
    P = np.asarray(path, dtype=np.float64).reshape(-1, 3)
    K = len(P)
    r = np.broadcast_to(np.asarray(radius, dtype=np.float64), (K,))
    seg = P[1:] - P[:-1]
    seg /= np.linalg.norm(seg, axis=1, keepdims=True)
    tangents = np.empty_like(P)
    tangents[0], tangents[-1] = seg[0], seg[-1]
    if K > 2:
        mid = seg[:-1] + seg[1:]
        norm = np.linalg.norm(mid, axis=1, keepdims=True)
        tangents[1:-1] = np.where(norm > 1e-9, mid / np.maximum(norm, 1e-12), seg[:-1])
    # parallel transport of the ring frame along the path (no twist)
    u, v = _frame(tangents[0])
    us, vs = [u], [v]
    for k in range(1, K):
        t = tangents[k]
        u = u - np.dot(u, t) * t
        u /= np.linalg.norm(u)
        v = np.cross(t, u)
        us.append(u)
        vs.append(v)
    U, Vv = np.array(us), np.array(vs)
    a = 2.0 * np.pi * np.arange(segments) / segments
    ca, sa = np.cos(a), np.sin(a)
    rings = P[:, None, :] + r[:, None, None] * (
        ca[None, :, None] * U[:, None, :] + sa[None, :, None] * Vv[:, None, :]
    )
    verts = rings.reshape(-1, 3)
    i = np.arange(K - 1)[:, None] * segments
    kk_ = np.arange(segments)[None, :]
    a0, a1 = i + kk_, i + (kk_ + 1) % segments
    b0, b1 = a0 + segments, a1 + segments
    tris = [np.stack([a0, a1, b1], -1).reshape(-1, 3), np.stack([a0, b1, b0], -1).reshape(-1, 3)]
    if caps:
        n = len(verts)
        verts = np.vstack([verts, P[0], P[-1]])
        kk = np.arange(segments)
        kk1 = (kk + 1) % segments
        last = (K - 1) * segments
        tris.append(np.stack([np.full(segments, n), kk1, kk], -1))
        tris.append(np.stack([np.full(segments, n + 1), last + kk, last + kk1], -1))
    return verts, np.vstack(tris).astype(np.int32)


def cylinder(p0: ArrayLike, p1: ArrayLike, radius: float, *, segments: int = 16) -> Mesh:
    """Closed cylinder with axis from ``p0`` to ``p1`` (metres)."""
    return tube(np.array([p0, p1], dtype=np.float64), radius, segments=segments)


def frustum(p0: ArrayLike, p1: ArrayLike, r0: float, r1: float, *, segments: int = 16) -> Mesh:
    """Closed truncated cone, radius ``r0`` at ``p0`` and ``r1`` at ``p1``."""
    return tube(np.array([p0, p1], dtype=np.float64), [r0, r1], segments=segments)


@lru_cache(maxsize=8)
def _unit_icosphere(subdivisions: int) -> Mesh:
    t = (1.0 + 5.0**0.5) / 2.0
    V = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
         [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]  # fmt: skip
    F = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
         [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
         [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]]  # fmt: skip
    verts = [np.array(p, dtype=np.float64) / np.linalg.norm(p) for p in V]
    faces = F

    def mid(i: int, j: int, cache: dict[tuple[int, int], int]) -> int:
        key = (min(i, j), max(i, j))
        if key not in cache:
            m = verts[i] + verts[j]
            verts.append(m / np.linalg.norm(m))
            cache[key] = len(verts) - 1
        return cache[key]

    for _ in range(subdivisions):
        cache: dict[tuple[int, int], int] = {}
        new = []
        for a, b, c in faces:
            ab, bc, ca = mid(a, b, cache), mid(b, c, cache), mid(c, a, cache)
            new += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        faces = new
    Vn = np.array(verts)
    Fn = np.array(faces, dtype=np.int32)
    # orient every face outward
    n = np.cross(Vn[Fn[:, 1]] - Vn[Fn[:, 0]], Vn[Fn[:, 2]] - Vn[Fn[:, 0]])
    flip = np.einsum("ij,ij->i", n, Vn[Fn].mean(axis=1)) < 0
    Fn[flip] = Fn[flip][:, ::-1]
    Vn.setflags(write=False)
    Fn.setflags(write=False)
    return Vn, Fn


def ellipsoid(
    center: ArrayLike,
    radii: float | ArrayLike,
    *,
    subdivisions: int = 2,
    roughness: float = 0.0,
    rng: np.random.Generator | None = None,
) -> Mesh:
    """Ellipsoid (icosphere scaled by ``radii``), optionally with random radial bumps.

    Parameters
    ----------
    roughness : float
        Relative amplitude of smooth random radial displacement (tree crowns, rocks); needs
        ``rng`` when non-zero.
    """
    V, F = _unit_icosphere(subdivisions)
    scale = np.ones(len(V))
    if roughness > 0.0:
        if rng is None:
            raise ValueError("roughness needs an rng")
        # a few random low-frequency lobes keep the surface smooth but irregular
        dirs = rng.normal(size=(6, 3))
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        amp = rng.uniform(-1.0, 1.0, size=6)
        scale = 1.0 + roughness * np.tanh((np.clip(V @ dirs.T, 0, None) ** 3) @ amp)
        scale *= 1.0 + 0.25 * roughness * rng.uniform(-1.0, 1.0, size=len(V))
    verts = np.asarray(center, dtype=np.float64) + V * scale[:, None] * np.asarray(
        radii, dtype=np.float64
    )
    return verts, F.copy()


def dome(
    center: ArrayLike, radius: float, height: float, *, segments: int = 24, rings: int = 6
) -> Mesh:
    """Open spherical-cap-like dome (tank heads) standing on the circle at ``center``."""
    c = np.asarray(center, dtype=np.float64)
    el = np.linspace(0.0, np.pi / 2, rings + 1)[:-1]
    a = 2.0 * np.pi * np.arange(segments) / segments
    ring_r = radius * np.cos(el)
    ring_z = height * np.sin(el)
    verts = (
        np.concatenate(
            [
                np.stack(
                    [
                        ring_r[:, None] * np.cos(a),
                        ring_r[:, None] * np.sin(a),
                        np.broadcast_to(ring_z[:, None], (rings, segments)),
                    ],
                    -1,
                ).reshape(-1, 3),
                [[0.0, 0.0, height]],
            ]
        )
        + c
    )
    i = np.arange(rings - 1)[:, None] * segments
    k = np.arange(segments)[None, :]
    k1 = (k + 1) % segments
    a0, a1, b0, b1 = i + k, i + k1, i + k + segments, i + k1 + segments
    top = rings * segments
    last = (rings - 1) * segments
    kk = np.arange(segments)
    tris = np.vstack(
        [
            np.stack([a0, a1, b1], -1).reshape(-1, 3),
            np.stack([a0, b1, b0], -1).reshape(-1, 3),
            np.stack([last + kk, last + (kk + 1) % segments, np.full(segments, top)], -1),
        ]
    )
    return verts, tris.astype(np.int32)


def quad(p0: ArrayLike, p1: ArrayLike, p2: ArrayLike, p3: ArrayLike) -> Mesh:
    """Single planar quadrilateral ``p0 p1 p2 p3`` (counter-clockwise seen from its front)."""
    return np.array([p0, p1, p2, p3], dtype=np.float64), np.array([[0, 1, 2], [0, 2, 3]], np.int32)


def profile_slabs(profile_yz: ArrayLike, x0: float, x1: float, thickness: float) -> list[Mesh]:
    """Solid lining along x (tunnels): one slab behind each segment of a cross-section.

    Parameters
    ----------
    profile_yz : (K, 2) float, metres
        Cross-section polyline ``(y, z)``, running up the wall at small y, over the top and down
        the wall at large y, so that the slabs lie outside it and their inner faces (wound
        outward) look into the space it encloses.
    x0, x1 : float, metres
        Extent along x.
    thickness : float, metres

    Returns
    -------
    list of Mesh
        One closed hexahedron per segment.
    """
    P = np.asarray(profile_yz, dtype=np.float64).reshape(-1, 2)
    out = []
    for (ya, za), (yb, zb) in pairwise(P):
        v = np.array([yb - ya, zb - za]) / np.hypot(yb - ya, zb - za)
        n = np.array([-v[1], v[0]]) * thickness  # x cross (0, v): outward
        corners = []
        for (y_a, z_a), (y_b, z_b) in (((ya, za), (yb, zb)), ((ya, za) + n, (yb, zb) + n)):
            corners += [(x0, y_a, z_a), (x1, y_a, z_a), (x1, y_b, z_b), (x0, y_b, z_b)]
        out.append(hexahedron(corners))
    return out


def arch(
    x_center: float,
    y0: float,
    y1: float,
    z_spring: float,
    radius: float,
    depth: float,
    *,
    segments: int = 10,
) -> list[Mesh]:
    """Semicircular arch ring in the x-z plane, as ``segments`` closed voussoirs.

    Inner radius ``radius`` about ``(x_center, z_spring)``, ``depth`` thick radially, spanning
    ``y0..y1`` (all metres).
    """
    a = np.linspace(np.pi, 0.0, segments + 1)
    out = []
    for ta, tb in pairwise(a):
        corners = []
        for r in (radius, radius + depth):
            xa, za = x_center + r * np.cos(ta), z_spring + r * np.sin(ta)
            xb, zb = x_center + r * np.cos(tb), z_spring + r * np.sin(tb)
            corners += [(xa, y0, za), (xb, y0, zb), (xb, y1, zb), (xa, y1, za)]
        out.append(hexahedron(corners))
    return out


def wall_boxes(
    length: float,
    height: float,
    thickness: float,
    openings: list[tuple[float, float, float, float]],
) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """Split a wall with rectangular openings into solid boxes, in the wall's local frame.

    The wall spans ``x in [0, length]`` (along the wall), ``y in [0, thickness]`` and
    ``z in [0, height]``. Each opening is ``(x0, x1, z0, z1)``; openings must not overlap. The
    boxes' side faces form the reveals of the openings.

    Returns
    -------
    list of (lo (3,), hi (3,)) box corners, metres
    """
    xs = sorted(
        {0.0, float(length)} | {float(np.clip(v, 0, length)) for o in openings for v in o[:2]}
    )
    out = []
    for xa, xb in pairwise(xs):
        if xb - xa < 1e-6:
            continue
        covering = sorted((o[2], o[3]) for o in openings if o[0] <= xa + 1e-9 and o[1] >= xb - 1e-9)
        z = 0.0
        for z0, z1 in covering:
            if z0 - z > 1e-6:
                out.append((np.array([xa, 0.0, z]), np.array([xb, thickness, z0])))
            z = max(z, z1)
        if height - z > 1e-6:
            out.append((np.array([xa, 0.0, z]), np.array([xb, thickness, height])))
    return out


class MeshBuilder:
    """Accumulates primitives with a pose and a material into one triangle mesh.

    Objects are built in their own frame in a fresh builder and added to the scene's builder
    with :meth:`extend` and a pose.
    """

    def __init__(self) -> None:
        self._verts: list[NDArray[np.float64]] = []
        self._tris: list[NDArray[np.int32]] = []
        self._refl: list[NDArray[np.float32]] = []
        self._rgb: list[NDArray[np.uint8]] = []
        self.counts: dict[str, int] = {}

    def add(
        self,
        mesh: Mesh,
        material: Material,
        *,
        R: NDArray[np.float64] | None = None,
        t: ArrayLike | None = None,
    ) -> None:
        """Add a primitive, posed by ``p -> R @ p + t``."""
        V, T = mesh
        if R is not None:
            V = V @ np.asarray(R).T
        if t is not None:
            V = V + np.asarray(t, dtype=np.float64)
        self._verts.append(np.asarray(V, dtype=np.float64))
        self._tris.append(np.asarray(T, dtype=np.int32))
        self._refl.append(np.full(len(T), material.reflectance, dtype=np.float32))
        self._rgb.append(np.tile(np.asarray(material.rgb, dtype=np.uint8), (len(T), 1)))

    def box(
        self,
        lo: ArrayLike,
        hi: ArrayLike,
        material: Material,
        *,
        R: NDArray[np.float64] | None = None,
        t: ArrayLike | None = None,
    ) -> None:
        """Add an axis-aligned box (in the frame given by ``R``, ``t``)."""
        self.add(box(lo, hi), material, R=R, t=t)

    def extend(
        self,
        other: MeshBuilder,
        *,
        R: NDArray[np.float64] | None = None,
        t: ArrayLike | None = None,
    ) -> None:
        """Add everything of another builder (an object built in its own frame), posed."""
        for V, T, rf, c in zip(other._verts, other._tris, other._refl, other._rgb, strict=True):
            Vp = V if R is None else V @ np.asarray(R).T
            if t is not None:
                Vp = Vp + np.asarray(t, dtype=np.float64)
            self._verts.append(Vp)
            self._tris.append(T)
            self._refl.append(rf)
            self._rgb.append(c)
        for k, v in other.counts.items():
            self.count(k, v)

    def count(self, category: str, n: int = 1) -> None:
        """Record ``n`` objects of a category (reported in the scene summary)."""
        self.counts[category] = self.counts.get(category, 0) + n

    @property
    def n_triangles(self) -> int:
        return int(sum(len(t) for t in self._tris))

    def arrays(
        self,
    ) -> tuple[NDArray[np.float64], NDArray[np.int32], NDArray[np.float32], NDArray[np.uint8]]:
        """``(vertices (V,3) float64, triangles (T,3) int32, reflectance (T,) float32,
        rgb (T,3) uint8)``."""
        if not self._verts:
            return (
                np.zeros((0, 3)),
                np.zeros((0, 3), np.int32),
                np.zeros(0, np.float32),
                np.zeros((0, 3), np.uint8),
            )
        offsets = np.cumsum([0] + [len(v) for v in self._verts[:-1]])
        return (
            np.vstack(self._verts),
            np.vstack([T + o for T, o in zip(self._tris, offsets, strict=True)]).astype(np.int32),
            np.concatenate(self._refl),
            np.vstack(self._rgb),
        )
