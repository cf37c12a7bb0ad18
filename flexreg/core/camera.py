"""Camera models of the paper's section II: pinhole (eq. 1-2) and equirectangular (eq. 3-8).

Pixel convention (both models): continuous pixel coordinates ``(u, v)``, ``u`` along the image
width (column), ``v`` along the height (row, top row first). An integer ``(u, v)`` is the sample
of pixel ``[v, u]`` of an image array, so pixel ``[v, u]`` *is* the ray of integer coordinates
``(u, v)``: for the pinhole camera this is OpenCV's convention (the principal point ``(cx, cy)`` is
given in the same coordinates), for the spherical camera it is eq. 7 of the paper and the
convention of the authors' reference implementation (``phi(u) = phi_min + u * dphi``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.errors import InputError

DepthKind = Literal["z", "range"]
TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class PinholeCamera:
    """Distortion-free pinhole camera (paper eq. 1-2).

    Attributes
    ----------
    fx, fy : float
        Focal lengths in pixels.
    cx, cy : float
        Principal point in pixels (OpenCV convention: pixel centres at integers).
    width, height : int
        Image size in pixels.
    skew : float
        Skew coefficient ``s`` of eq. 1 (0 for almost every camera).

    Examples
    --------
    >>> cam = PinholeCamera(500.0, 500.0, 320.0, 240.0, 640, 480)
    >>> u, v, z = cam.project(np.array([[0.1, -0.2, 2.0]]))
    >>> float(u[0]), float(v[0]), float(z[0])
    (345.0, 190.0, 2.0)
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    skew: float = 0.0

    def __post_init__(self) -> None:
        vals = (self.fx, self.fy, self.cx, self.cy, self.skew)
        if not all(np.isfinite(vals)) or self.fx <= 0 or self.fy <= 0:
            raise InputError("pinhole camera", f"focal lengths must be positive and finite: {vals}")
        if int(self.width) <= 0 or int(self.height) <= 0:
            raise InputError("pinhole camera", f"size must be positive: {self.width}x{self.height}")

    @property
    def K(self) -> NDArray[np.float64]:
        """The (3, 3) intrinsic matrix of eq. 1."""
        return np.array([[self.fx, self.skew, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def shape(self) -> tuple[int, int]:
        """Image shape ``(height, width)``."""
        return (int(self.height), int(self.width))

    def project(
        self, points: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Project camera-frame points to pixels (eq. 1).

        Parameters
        ----------
        points : (N, 3) float, metres

        Returns
        -------
        u, v : (N,) float64, pixels
        z : (N,) float64, metres
            Orthographic depth; points with ``z <= 0`` get ``u = v = NaN``.
        """
        P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        z = P[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            x = np.where(z > 0, P[:, 0] / z, np.nan)
            y = np.where(z > 0, P[:, 1] / z, np.nan)
        return self.fx * x + self.skew * y + self.cx, self.fy * y + self.cy, z

    def normalized(
        self, u: ArrayLike, v: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Normalised image coordinates ``(X/Z, Y/Z)`` of pixels (inverse matrix of eq. 2)."""
        u = np.asarray(u, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        y = (v - self.cy) / self.fy
        x = (u - self.cx - self.skew * y) / self.fx
        return x, y

    def backproject(
        self, u: ArrayLike, v: ArrayLike, depth: ArrayLike, *, depth_kind: DepthKind = "z"
    ) -> NDArray[np.float64]:
        """Back-project pixels with depth to camera-frame points (eq. 2).

        Parameters
        ----------
        u, v : (...) float, pixels
        depth : (...) float, metres
            Orthographic depth ``Z`` (``depth_kind="z"``) or Euclidean range
            (``depth_kind="range"``).

        Returns
        -------
        (..., 3) float64, metres
        """
        x, y = self.normalized(u, v)
        d = np.asarray(depth, dtype=np.float64)
        if depth_kind == "range":
            d = d / np.sqrt(1.0 + x * x + y * y)
        elif depth_kind != "z":
            raise InputError("depth_kind", f"must be 'z' or 'range', got {depth_kind!r}")
        return np.stack(np.broadcast_arrays(x * d, y * d, d), axis=-1)

    def rays(self) -> NDArray[np.float64]:
        """(H, W, 3) float64 ray of every pixel, scaled to ``Z = 1``."""
        v, u = np.mgrid[0 : self.height, 0 : self.width].astype(np.float64)
        return self.backproject(u, v, np.ones_like(u))

    def z_to_range(self, u: ArrayLike, v: ArrayLike, z: ArrayLike) -> NDArray[np.float64]:
        """Orthographic depth -> Euclidean range: ``r = z * sqrt(1 + x^2 + y^2)``."""
        x, y = self.normalized(u, v)
        return np.asarray(z, dtype=np.float64) * np.sqrt(1.0 + x * x + y * y)

    def range_to_z(self, u: ArrayLike, v: ArrayLike, r: ArrayLike) -> NDArray[np.float64]:
        """Euclidean range -> orthographic depth (inverse of :meth:`z_to_range`)."""
        x, y = self.normalized(u, v)
        return np.asarray(r, dtype=np.float64) / np.sqrt(1.0 + x * x + y * y)

    def to_dict(self) -> dict[str, object]:
        """JSON-ready description."""
        return {
            "model": "pinhole",
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "skew": self.skew,
            "width": int(self.width),
            "height": int(self.height),
        }


@dataclass(frozen=True)
class SphericalCamera:
    """Equirectangular (spherical) camera of a TLS or omnidirectional sensor (eq. 3-8).

    Azimuth ``phi = atan2(Y, X)`` runs along the width, polar angle ``theta = arccos(Z / r)``
    (0 at +Z, top row first) along the height. Pixel ``(u, v)`` is the sample at
    ``phi = phi_min + u * dphi``, ``theta = theta_min + v * dtheta`` (eq. 7) with
    ``dphi = (phi_max - phi_min) / width`` and ``dtheta = (theta_max - theta_min) / height``
    (eq. 3). When the azimuth span is a full turn the image wraps: column ``width`` is column 0.

    Attributes
    ----------
    width, height : int
        Image size in pixels.
    phi_min, phi_max : float, radians
        Azimuth field of view.
    theta_min, theta_max : float, radians
        Polar field of view, ``0 <= theta_min < theta_max <= pi``.

    Examples
    --------
    >>> cam = SphericalCamera.from_reference(360, 180, 0.0, np.pi)
    >>> u, v, r = cam.project(np.array([[0.0, 2.0, 0.0]]))   # +Y: phi = 90 deg, theta = 90 deg
    >>> float(u[0]), float(v[0]), float(r[0])
    (270.0, 90.0, 2.0)
    """

    width: int
    height: int
    phi_min: float
    phi_max: float
    theta_min: float
    theta_max: float

    def __post_init__(self) -> None:
        if int(self.width) <= 0 or int(self.height) <= 0:
            raise InputError(
                "spherical camera", f"size must be positive: {self.width}x{self.height}"
            )
        if not (self.phi_max > self.phi_min and self.phi_max - self.phi_min <= TWO_PI + 1e-9):
            raise InputError(
                "spherical camera",
                f"azimuth range must be increasing and at most 360 deg: "
                f"[{np.degrees(self.phi_min):.3f}, {np.degrees(self.phi_max):.3f}] deg",
            )
        if not (0.0 <= self.theta_min < self.theta_max <= np.pi + 1e-9):
            raise InputError(
                "spherical camera",
                f"polar range must satisfy 0 <= min < max <= 180 deg: "
                f"[{np.degrees(self.theta_min):.3f}, {np.degrees(self.theta_max):.3f}] deg",
            )

    @classmethod
    def from_reference(
        cls, width: int, height: int, theta_min: float, theta_max: float
    ) -> SphericalCamera:
        """Full-turn camera in the convention of the authors' reference implementation.

        ``phi(u) = u * 2 pi / W - pi`` and ``theta(v) = theta_min + v (theta_max - theta_min) / H``,
        as in ``laser_intrinsic.txt`` ("W H / theta_min theta_max", radians).
        """
        return cls(int(width), int(height), -np.pi, np.pi, float(theta_min), float(theta_max))

    @property
    def shape(self) -> tuple[int, int]:
        """Image shape ``(height, width)``."""
        return (int(self.height), int(self.width))

    @property
    def dphi(self) -> float:
        """Azimuth step per pixel, radians (eq. 3)."""
        return (self.phi_max - self.phi_min) / self.width

    @property
    def dtheta(self) -> float:
        """Polar step per pixel, radians (eq. 3)."""
        return (self.theta_max - self.theta_min) / self.height

    @property
    def wraps(self) -> bool:
        """True if the azimuth span is a full turn, so the image wraps horizontally."""
        return bool(abs((self.phi_max - self.phi_min) - TWO_PI) < 1e-9)

    def project(
        self, points: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Project scanner-frame points to pixels (eq. 4-6 with the offsets of eq. 7).

        Parameters
        ----------
        points : (N, 3) float, metres

        Returns
        -------
        u, v : (N,) float64, pixels
            For a wrapping camera ``u`` is reduced to ``[0, width)``.
        r : (N,) float64, metres
            Range (eq. 4). A point at the origin gets ``u = v = NaN``.
        """
        P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        r = np.sqrt(np.einsum("ij,ij->i", P, P))
        phi = np.arctan2(P[:, 1], P[:, 0])
        with np.errstate(divide="ignore", invalid="ignore"):
            theta = np.arccos(np.clip(P[:, 2] / r, -1.0, 1.0))
        u = (phi - self.phi_min) / self.dphi
        if self.wraps:
            u = np.mod(u, self.width)
        else:
            # an azimuth just below phi_min may sit a full turn away
            u = np.where(u < -0.5, u + TWO_PI / self.dphi, u)
        v = (theta - self.theta_min) / self.dtheta
        bad = r <= 0
        u[bad] = np.nan
        v[bad] = np.nan
        return u, v, r

    def angles(self, u: ArrayLike, v: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Azimuth and polar angle (radians) of pixel coordinates (eq. 7)."""
        phi = self.phi_min + np.asarray(u, dtype=np.float64) * self.dphi
        theta = self.theta_min + np.asarray(v, dtype=np.float64) * self.dtheta
        return phi, theta

    def backproject(self, u: ArrayLike, v: ArrayLike, r: ArrayLike) -> NDArray[np.float64]:
        """Back-project pixels with range to scanner-frame points (eq. 7-8).

        Returns
        -------
        (..., 3) float64, metres
        """
        phi, theta = self.angles(u, v)
        r = np.asarray(r, dtype=np.float64)
        st = np.sin(theta)
        return np.stack(
            np.broadcast_arrays(st * np.cos(phi) * r, st * np.sin(phi) * r, np.cos(theta) * r),
            axis=-1,
        )

    def rays(self) -> NDArray[np.float64]:
        """(H, W, 3) float64 unit ray of every pixel."""
        v, u = np.mgrid[0 : self.height, 0 : self.width].astype(np.float64)
        return self.backproject(u, v, np.ones_like(u))

    def to_dict(self) -> dict[str, object]:
        """JSON-ready description (angles in radians)."""
        return {
            "model": "spherical",
            "width": int(self.width),
            "height": int(self.height),
            "phi_min": self.phi_min,
            "phi_max": self.phi_max,
            "theta_min": self.theta_min,
            "theta_max": self.theta_max,
        }


Camera = PinholeCamera | SphericalCamera


def camera_from_dict(d: dict[str, object]) -> Camera:
    """Inverse of ``camera.to_dict()``."""
    model = d.get("model")
    kw = {k: v for k, v in d.items() if k != "model"}
    if model == "pinhole":
        return PinholeCamera(**kw)  # type: ignore[arg-type]
    if model == "spherical":
        return SphericalCamera(**kw)  # type: ignore[arg-type]
    raise InputError("camera", f"unknown camera model {model!r}")


#: an azimuth gap at least this wide (degrees) means the points do not cover a full turn
FULL_TURN_GAP_DEG = 5.0
#: points whose angles are computed at a time (a multiple of every SIMD width, so each element
#: is computed exactly as in one pass over all points)
ANGLE_CHUNK = 1 << 18


@numba.njit(cache=True, nogil=True)
def _bucket_extent(phi, width, lo, hi):  # pragma: no cover - compiled
    """Least and greatest azimuth per bucket ``floor((phi + pi) / width)`` (clipped)."""
    last = lo.shape[0] - 1
    for i in range(phi.shape[0]):
        b = min(max(int(np.floor((phi[i] + np.pi) / width)), 0), last)
        if phi[i] < lo[b]:
            lo[b] = phi[i]
        if phi[i] > hi[b]:
            hi[b] = phi[i]


def azimuth_polar_extent(
    points: NDArray[np.floating],
) -> tuple[float, float, float, float, bool]:
    """Angular extent of points seen from the origin.

    Returns
    -------
    phi_min, phi_max, theta_min, theta_max : float, radians
        ``phi_max`` may exceed pi when the covered azimuth interval crosses the -pi/pi cut.
    full_turn : bool
        True when no azimuth gap of :data:`FULL_TURN_GAP_DEG` (5 degrees) or more exists.
    """
    n = len(points)
    if n == 0:
        raise InputError("points", "no points")
    # In chunks, with no per-point array kept: each azimuth lands in a bucket of half the
    # widest gap that can leave the turn full (the buckets keep their least and greatest
    # azimuth), so a gap that wide lies between two occupied buckets and is found exactly,
    # as in the sorted azimuths, and one narrower leaves the turn full either way.
    width = np.radians(FULL_TURN_GAP_DEG) / 2
    lo_b = np.full(math.ceil(2 * np.pi / width), np.inf)
    hi_b = np.full(len(lo_b), -np.inf)
    th_lo, th_hi = np.inf, -np.inf
    for a in range(0, n, ANGLE_CHUNK):
        P = np.asarray(points[a : a + ANGLE_CHUNK], dtype=np.float64)
        r = np.linalg.norm(P, axis=1)
        P, r = P[r > 0], r[r > 0]
        if len(P):
            _bucket_extent(np.arctan2(P[:, 1], P[:, 0]), width, lo_b, hi_b)
            theta = np.arccos(np.clip(P[:, 2] / r, -1.0, 1.0))
            th_lo, th_hi = min(th_lo, float(theta.min())), max(th_hi, float(theta.max()))
    used = np.flatnonzero(lo_b <= hi_b)
    if len(used) == 0:
        raise InputError("points", "no points away from the origin")
    lo_b, hi_b = lo_b[used], hi_b[used]
    # the gaps between occupied buckets in azimuth order, then the one across the -pi/pi
    # cut: the first widest wins, as in the sorted azimuths
    gaps = lo_b[1:] - hi_b[:-1]
    k = int(np.argmax(gaps)) if len(gaps) else -1
    widest = float(gaps[k]) if len(gaps) else -np.inf
    if lo_b[0] + 2 * np.pi - hi_b[-1] > widest:
        k, widest = len(used) - 1, float(lo_b[0] + 2 * np.pi - hi_b[-1])
    full = bool(widest < np.radians(FULL_TURN_GAP_DEG))
    if full:
        phi_min, phi_max = -np.pi, np.pi
    else:  # the covered interval starts after the widest gap
        phi_min = float(lo_b[(k + 1) % len(used)])
        phi_max = float(hi_b[k])
        if phi_max < phi_min:
            phi_max += 2 * np.pi
    return float(phi_min), float(phi_max), th_lo, th_hi, full
