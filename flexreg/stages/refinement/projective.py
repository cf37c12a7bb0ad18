"""Projective point-to-plane ICP on a range image.

A scan's range image already says which target surface a source point would be matched to: the
one the target scanner saw along the ray through that point. Mapping a sample of source points
into the target frame, projecting them through the target's camera model and reading the pixel
hit gives every correspondence in constant time (projective data association), where a
nearest-neighbour ICP searches a k-d tree; the normals come from the image grid as well
(:func:`grid_normals`). One iteration over tens of thousands of points then takes about a
millisecond, so the target keeps its full image resolution instead of being voxel-thinned.

Starting from a coarse transform within a few centimetres (the registration's inlier
threshold), each iteration linearises the point-to-plane residuals
``r_i = n_i . (R p_i + t - x_i)`` around the current pose, solves the 6x6 normal equations
(Tukey-weighted, Levenberg damped) and composes the increment, for a shrinking sequence of
correspondence distances.
The result is deterministic: one thread, one fixed summation order.
"""

from __future__ import annotations

import logging
import math

import numba
import numpy as np
from numba import prange
from numpy.typing import NDArray

from flexreg.core.camera import PinholeCamera, SphericalCamera
from flexreg.core.range_image import RangeImage
from flexreg.core.transforms import rotation_about_axis
from flexreg.errors import ConfigError, RegistrationError
from flexreg.stages.normals import grid_normals, masked_xyz
from flexreg.stages.refinement.result import IcpResult

log = logging.getLogger(__name__)

#: camera kinds of the compiled kernels
_SPHERICAL, _PINHOLE = 0, 1

#: points are paired in this many fixed chunks (in parallel), whose sums are added in order
_CHUNKS = 16
#: fewer points than this are paired on the calling thread (:func:`_associate_serial`, the same
#: result): the candidate polishing (5 000 points) and the refinement (15 000 per direction)
#: take well under a millisecond per pass, less than starting a parallel region costs
PARALLEL_MIN_POINTS = 200_000
#: convergence of the distance levels before the last (relative update, see projective_icp)
_LEVEL_TOLERANCE = 1e-5


def camera_params(image: RangeImage) -> tuple[int, NDArray[np.float64]]:
    """The camera of ``image`` as (kind, parameters) for compiled kernels: kind 0 spherical
    (``phi_min, dphi, theta_min, dtheta, wraps``), kind 1 pinhole (``fx, fy, cx, cy, skew``).

    Raises
    ------
    ConfigError
        The image has no camera model.
    """
    cam = image.camera
    if isinstance(cam, SphericalCamera):
        return _SPHERICAL, np.array(
            [cam.phi_min, cam.dphi, cam.theta_min, cam.dtheta, float(cam.wraps)]
        )
    if isinstance(cam, PinholeCamera):
        return _PINHOLE, np.array([cam.fx, cam.fy, cam.cx, cam.cy, cam.skew])
    raise ConfigError("projective ICP needs a range image with a camera model")


def angular_step(image: RangeImage) -> float:
    """Largest angle between neighbouring pixels' rays, radians (pinhole: at the centre)."""
    cam = image.camera
    if isinstance(cam, SphericalCamera):
        return float(max(cam.dphi, cam.dtheta))
    if isinstance(cam, PinholeCamera):
        return float(1.0 / min(cam.fx, cam.fy))
    raise ConfigError("projective ICP needs a range image with a camera model")


# ---------------------------------------------------------------------------- numba kernels


@numba.njit(cache=True, nogil=True, inline="always")
def _wrap(u, W):  # pragma: no cover
    """``u % W`` (Python's floating-point modulo, ``W > 0``), without the division for the
    ``u`` within one turn either side that a projection gives: ``fmod`` is exact there, so
    adding or subtracting ``W`` once is the same number. Within that turn the choice is a
    select, not a branch: whether ``u`` is negative follows the points' azimuths, which a
    branch predictor cannot guess (half the points of a panorama whose azimuths start at 0)."""
    if u >= -W and u < 2.0 * W:
        return u + W if u < 0.0 else (u - W if u >= W else u)
    return u % W


@numba.njit(cache=True, nogil=True, inline="always")
def spherical_pixel(qx, qy, qz, r, c0, c1, c2, c3, c4, W):  # pragma: no cover
    """The pixel coordinates ``(u, v)`` (before rounding) of a point at range ``r > 0`` in a
    spherical camera ``c0 .. c4`` (the entries of :func:`camera_params`) of width ``W``, as
    :meth:`~flexreg.core.camera.SphericalCamera.project` computes them (eq. 4-7). The
    parameters come as scalars: a kernel reads them once, before its loop (read from the
    array inside the loop, they cost a quarter of a full-resolution check's time).

    Inlined into the kernels of this module and of :mod:`flexreg.registration.fullres`;
    numba's on-disk cache of a kernel is keyed by its own file, so after changing this
    function remove the ``*.nbi``/``*.nbc`` files of ``fullres`` too."""
    u = (math.atan2(qy, qx) - c0) / c1
    c = min(1.0, max(-1.0, qz / r))
    v = (math.acos(c) - c2) / c3
    if c4 > 0.5:
        u = _wrap(u, W)
    elif u < -0.5:
        u += 2.0 * math.pi / c1
    return u, v


@numba.njit(cache=True, nogil=True, inline="always")
def _associate_chunk(
    ch, pts, M, T, reverse, front, xyz, nrm, kind, cam, dist, lateral, Ac, bc, cc, out_q, out_r
):  # pragma: no cover
    """Chunk ``ch`` of :func:`_associate` (its points' pairs summed into ``Ac[ch]``,
    ``bc[ch]``, ``cc[ch]``)."""
    H, W = xyz.shape[0], xyz.shape[1]
    wrap = kind == 0 and cam[4] > 0.5
    k0, k1, k2, k3, k4 = cam[0], cam[1], cam[2], cam[3], cam[4]
    n = pts.shape[0]
    J = np.empty(6)
    for i in range(ch * n // _CHUNKS, (ch + 1) * n // _CHUNKS):
        px, py, pz = pts[i, 0], pts[i, 1], pts[i, 2]
        out_r[i] = np.nan
        # into the image's frame
        qx = M[0, 0] * px + M[0, 1] * py + M[0, 2] * pz + M[0, 3]
        qy = M[1, 0] * px + M[1, 1] * py + M[1, 2] * pz + M[1, 3]
        qz = M[2, 0] * px + M[2, 1] * py + M[2, 2] * pz + M[2, 3]
        rq = math.sqrt(qx * qx + qy * qy + qz * qz)
        if kind == 0:
            if not rq > 0.0:
                continue
            u, v = spherical_pixel(qx, qy, qz, rq, k0, k1, k2, k3, k4, W)
        else:
            if not qz > 0.0:
                continue
            u = k0 * qx / qz + k4 * qy / qz + k2
            v = k1 * qy / qz + k3
        iu = math.floor(u + 0.5)
        iv = math.floor(v + 0.5)
        if wrap and iu >= W:
            iu -= W
        if iu < 0 or iu >= W or iv < 0 or iv >= H:
            continue
        nx = np.float64(nrm[iv, iu, 0])
        ny = np.float64(nrm[iv, iu, 1])
        nz = np.float64(nrm[iv, iu, 2])
        if not math.isfinite(nx):
            continue
        x0, x1, x2 = xyz[iv, iu, 0], xyz[iv, iu, 1], xyz[iv, iu, 2]
        if reverse:  # the pixel moves: its point and normal into the target frame
            mx = T[0, 0] * x0 + T[0, 1] * x1 + T[0, 2] * x2 + T[0, 3]
            my = T[1, 0] * x0 + T[1, 1] * x1 + T[1, 2] * x2 + T[1, 3]
            mz = T[2, 0] * x0 + T[2, 1] * x1 + T[2, 2] * x2 + T[2, 3]
            n0 = T[0, 0] * nx + T[0, 1] * ny + T[0, 2] * nz
            n1 = T[1, 0] * nx + T[1, 1] * ny + T[1, 2] * nz
            n2 = T[2, 0] * nx + T[2, 1] * ny + T[2, 2] * nz
            nx, ny, nz = n0, n1, n2
            dx, dy, dz = mx - px, my - py, mz - pz
        else:
            mx, my, mz = qx, qy, qz
            dx, dy, dz = qx - x0, qy - x1, qz - x2
        res = nx * dx + ny * dy + nz * dz
        if not abs(res) < dist:
            continue
        if front:
            # both scanners see the pixel's surface from the side its normal faces (the
            # normal points to its own scanner): a point the other scanner saw lies on that
            # face, not on the back of a wall a doorway or a window shows from the other side
            if reverse:  # the target scanner, at the target frame's origin
                facing = -(nx * mx + ny * my + nz * mz)
            else:  # the source scanner, at T's translation in the target frame
                facing = nx * (T[0, 3] - x0) + ny * (T[1, 3] - x1) + nz * (T[2, 3] - x2)
            if not facing > 0.0:
                continue
        # the pixel's point lies on the ray's surface within about a pixel footprint
        reach = dist + lateral * rq
        if dx * dx + dy * dy + dz * dz > reach * reach:
            continue
        out_q[i, 0], out_q[i, 1], out_q[i, 2] = mx, my, mz
        out_r[i] = res
        w = 1.0 - (res / dist) ** 2
        w *= w
        J[0] = my * nz - mz * ny  # (m x n): derivative for a small rotation about the origin
        J[1] = mz * nx - mx * nz
        J[2] = mx * ny - my * nx
        J[3], J[4], J[5] = nx, ny, nz
        for a in range(6):
            bc[ch, a] += w * J[a] * res
            for c2 in range(6):
                Ac[ch, a, c2] += w * J[a] * J[c2]
        cc[ch] += 1


@numba.njit(cache=True, nogil=True)
def _sum_chunks(Ac, bc, cc, A, b):  # pragma: no cover
    """Add the chunks' sums to ``A``, ``b`` in a fixed order: the same result with any number
    of threads. Returns the number of pairs."""
    count = 0
    for ch in range(_CHUNKS):
        A += Ac[ch]
        b += bc[ch]
        count += cc[ch]
    return count


@numba.njit(parallel=True, cache=True, nogil=True)
def _associate(
    pts, M, T, reverse, front, xyz, nrm, kind, cam, dist, lateral, A, b, out_q, out_r
):  # pragma: no cover
    """Pair points with the pixels their rays hit in an image and add the Tukey-weighted
    point-to-plane normal equations of ``T`` (a left increment) to ``A``, ``b``.

    Forward: ``pts`` are source points, ``M = T`` maps them into the target image's frame and
    the mapped point moves against the pixel's fixed plane. Reverse: ``pts`` are target points,
    ``M = T^-1`` maps them into the source image's frame, and the pixel's point and plane,
    mapped into the target frame by ``T``, move against the fixed target point.
    ``out_q`` receives the moving point of each pair (target frame), ``out_r`` its residual
    (NaN when unpaired). Returns the number of pairs."""
    Ac = np.zeros((_CHUNKS, 6, 6))
    bc = np.zeros((_CHUNKS, 6))
    cc = np.zeros(_CHUNKS, dtype=np.int64)
    for ch in prange(_CHUNKS):
        _associate_chunk(
            ch, pts, M, T, reverse, front, xyz, nrm, kind, cam, dist, lateral, Ac, bc, cc,
            out_q, out_r,
        )  # fmt: skip
    return _sum_chunks(Ac, bc, cc, A, b)


@numba.njit(cache=True, nogil=True)
def _associate_serial(
    pts, M, T, reverse, front, xyz, nrm, kind, cam, dist, lateral, A, b, out_q, out_r
):  # pragma: no cover
    """:func:`_associate` on the calling thread alone: the same chunks summed in the same order, so
    the same result, without a parallel region (whose start costs more than a few thousand
    points take, and much more on a loaded machine)."""
    Ac = np.zeros((_CHUNKS, 6, 6))
    bc = np.zeros((_CHUNKS, 6))
    cc = np.zeros(_CHUNKS, dtype=np.int64)
    for ch in range(_CHUNKS):
        _associate_chunk(
            ch, pts, M, T, reverse, front, xyz, nrm, kind, cam, dist, lateral, Ac, bc, cc,
            out_q, out_r,
        )  # fmt: skip
    return _sum_chunks(Ac, bc, cc, A, b)


# ---------------------------------------------------------------------------- Python API


def _exp_se3(delta: NDArray[np.float64]) -> NDArray[np.float64]:
    """4x4 transform of a small twist ``(omega, tau)`` (rotation vector about the origin, then
    translation)."""
    D = np.eye(4)
    angle = float(np.linalg.norm(delta[:3]))
    if angle > 0:
        D[:3, :3] = rotation_about_axis(delta[:3] / angle, angle)
    D[:3, 3] = delta[3:]
    return D


def point_information(q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Information matrix of paired points: the sum of ``G^T G`` with
    ``G = [[0, z, -y, 1, 0, 0], [-z, 0, x, 0, 1, 0], [y, -x, 0, 0, 0, 1]]`` per point
    (Open3D's convention: rotation first, then translation).

    Parameters
    ----------
    q : (N, 3) float64, metres
        The paired points in the target frame.

    Returns
    -------
    (6, 6) float64
    """
    q = np.asarray(q, dtype=np.float64).reshape(-1, 3)
    G = np.zeros((len(q), 3, 6))
    x, y, z = q[:, 0], q[:, 1], q[:, 2]
    G[:, 0, 1], G[:, 0, 2], G[:, 1, 0], G[:, 1, 2], G[:, 2, 0], G[:, 2, 1] = z, -y, -z, x, y, -x
    G[:, 0, 3] = G[:, 1, 4] = G[:, 2, 5] = 1.0
    return np.einsum("nij,nik->jk", G, G)


class _Side:
    """One direction of the association: points paired against an image."""

    def __init__(
        self,
        image: RangeImage,
        normals: NDArray[np.float32] | None,
        points: NDArray[np.float64],
        reverse: bool,
        facing: bool = False,
    ) -> None:
        self.kind, self.cam = camera_params(image)
        self.normals = grid_normals(image) if normals is None else normals
        self.xyz = masked_xyz(image)
        self.pts = np.ascontiguousarray(points, dtype=np.float64)
        self.reverse = reverse
        self.front = facing
        self.lateral = 2.0 * angular_step(image)
        self.q = np.empty_like(self.pts)
        self.res = np.empty(len(self.pts))

    def add(
        self, T: NDArray[np.float64], dist: float, A: NDArray[np.float64], b: NDArray[np.float64]
    ) -> int:
        M = np.ascontiguousarray(np.linalg.inv(T) if self.reverse else T)
        kernel = _associate if len(self.pts) >= PARALLEL_MIN_POINTS else _associate_serial
        return int(
            kernel(
                self.pts, M, T, self.reverse, self.front, self.xyz, self.normals, self.kind,
                self.cam, dist, self.lateral, A, b, self.q, self.res,
            )
        )  # fmt: skip


def projective_icp(
    target: RangeImage,
    source_points: NDArray[np.float64],
    T_init: NDArray[np.float64],
    *,
    max_distance_m: float,
    min_distance_m: float = 0.0,
    normals: NDArray[np.float32] | None = None,
    source: RangeImage | None = None,
    target_points: NDArray[np.float64] | None = None,
    source_normals: NDArray[np.float32] | None = None,
    max_iterations: int = 30,
    levels: int = 3,
    tolerance: float = 1e-6,
    facing: bool = False,
) -> IcpResult:
    """Refine ``T_target_source`` by point-to-plane ICP with projective data association.

    Each source point, mapped by the current transform, is paired with the target pixel its
    ray hits (:func:`grid_normals` gives that pixel's plane). With ``source`` and
    ``target_points`` the association is symmetric: target points are also paired with the
    source pixels their rays hit, and both sets of residuals enter one least-squares problem,
    so neither scan's viewpoint and normals alone decide the pose. The correspondence distance
    shrinks by a factor of three per level, from ``max_distance_m`` down to the larger of
    ``min_distance_m`` and four robust standard deviations of the residuals. The last level
    iterates until the update is below ``tolerance`` (radians and metres over the scan's
    extent) or ``max_iterations``; the levels before it only have to bring the next one
    close and stop at the looser of ``tolerance`` and 1e-5.

    Parameters
    ----------
    target : RangeImage
        Target scan with a camera model (spherical or pinhole).
    source_points : (N, 3) float64, metres
        Source points in the source frame (a sample spread over its surfaces is enough).
    T_init : (4, 4) float64
        Initial ``T_target_source``, at most about ``max_distance_m`` off.
    max_distance_m : float, metres
        First correspondence distance.
    min_distance_m : float, metres
        Smallest correspondence distance.
    normals : (H, W, 3) float32, optional
        The target's :func:`grid_normals` (computed when omitted).
    source : RangeImage, optional
        Source scan with a camera model, for the symmetric association.
    target_points : (M, 3) float64, optional
        Target points in the target frame, for the symmetric association.
    source_normals : (H', W', 3) float32, optional
        The source's :func:`grid_normals` (computed when omitted).
    max_iterations : int
        Per level (the last level's final convergence gets as many again).
    levels : int
        Most distance levels.
    tolerance : float
        Convergence on the size of the update.
    facing : bool
        Pair a point only where the scanner that saw it stands on the side of the pixel's
        plane its normal faces (each image's normals point to its own scanner): the back of a
        wall a doorway shows is not its front, a wall's thickness away along the normal. The
        refinement's answer (:func:`~flexreg.stages.refinement.refine`) uses it; the quick
        polishes that compare hypotheses (candidates, twins, slides) do not, their thresholds
        having been set on every pair.

    Returns
    -------
    IcpResult
        ``fitness`` and ``inlier_rmse_m`` over the pairs of both directions (``source_points``
        counts the points of both, ``association="projective"``, ``voxel_m`` NaN).

    Raises
    ------
    RegistrationError
        Fewer than 6 pairs at some iteration (no overlap at the initial pose), or the pairs
        cannot fix a pose.
    ConfigError
        An image has no camera model, or a distance is not positive.
    """
    if not (math.isfinite(max_distance_m) and max_distance_m > 0):
        raise ConfigError(f"ICP distance must be positive, got {max_distance_m}")
    if (source is None) != (target_points is None):
        raise ConfigError("symmetric projective ICP needs both the source image and target points")
    sides = [_Side(target, normals, source_points, False, facing)]
    if source is not None and target_points is not None:
        sides.append(_Side(source, source_normals, target_points, True, facing))
    n_points = sum(len(sd.pts) for sd in sides)
    if n_points < 6:
        raise RegistrationError(f"projective ICP needs at least 6 points, got {n_points}")
    extent = max(float(np.max(np.linalg.norm(sd.pts, axis=1))) for sd in sides) or 1.0
    T = np.array(T_init, dtype=np.float64)
    A, b = np.zeros((6, 6)), np.zeros(6)

    def accumulate(T: NDArray[np.float64], dist: float) -> int:
        A[:] = 0.0
        b[:] = 0.0
        return sum(sd.add(T, dist, A, b) for sd in sides)

    total = 0

    def iterate(T: NDArray[np.float64], dist: float, tol: float) -> NDArray[np.float64]:
        nonlocal total
        for _ in range(max_iterations):
            n = accumulate(T, dist)
            total += 1
            if n < 6:
                raise RegistrationError(f"projective ICP paired {n} points within {dist:.3g} m")
            damp = 1e-9 * float(np.trace(A)) + 1e-12
            try:
                delta = np.asarray(-np.linalg.solve(A + damp * np.eye(6), b), dtype=np.float64)
            except np.linalg.LinAlgError:
                raise RegistrationError("projective ICP: the pairs cannot fix a pose") from None
            T = _exp_se3(delta) @ T
            if np.linalg.norm(delta[:3]) * extent + np.linalg.norm(delta[3:]) < tol * extent:
                break
        return T

    # every level but the last only has to bring the next one close: it stops at a looser
    # tolerance; the last level then converges to ``tolerance``
    loose = max(tolerance, _LEVEL_TOLERANCE)
    dist = float(max_distance_m)
    for level in range(levels):
        T = iterate(T, dist, loose)
        r = np.concatenate([sd.res[np.isfinite(sd.res)] for sd in sides])
        sigma = 1.4826 * float(np.median(np.abs(r))) if len(r) else 0.0
        nxt = max(dist / 3.0, min_distance_m, 4.0 * sigma)
        if level == levels - 1 or nxt >= dist:
            if tolerance < loose:
                T = iterate(T, dist, tolerance)
            break
        dist = nxt
    n = accumulate(T, dist)
    res = np.concatenate([sd.res for sd in sides])
    q = np.concatenate([sd.q for sd in sides])
    paired = np.isfinite(res)
    rmse = float(np.sqrt(np.mean(res[paired] ** 2))) if n else float("nan")
    log.info(
        "projective ICP on %d points: %d paired within %.3g m, rmse %.3g m, %d iterations",
        n_points,
        n,
        dist,
        rmse,
        total,
    )
    return IcpResult(
        T_target_source=T,
        fitness=n / n_points,
        inlier_rmse_m=rmse,
        information=point_information(q[paired]),
        voxel_m=float("nan"),
        max_distance_m=dist,
        source_points=n_points,
        association="projective",
        iterations=total,
    )


__all__ = [
    "angular_step",
    "camera_params",
    "point_information",
    "projective_icp",
    "spherical_pixel",
]
