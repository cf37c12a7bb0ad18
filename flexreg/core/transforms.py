"""Rigid-transform helpers on 4x4 homogeneous matrices (float64, ``T_target_source``)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.errors import InputError


def as_transform(
    T: ArrayLike, *, name: str = "transform", rigid: bool = True
) -> NDArray[np.float64]:
    """Validate and return a 4x4 float64 transform.

    Parameters
    ----------
    T : (4, 4) array_like
        Homogeneous matrix whose last row must be ``[0, 0, 0, 1]``.
    name : str
        Name used in the error message.
    rigid : bool
        Require the 3x3 block to be a proper rotation (orthonormal, det +1, to 1e-6);
        otherwise only require it to be invertible (an affine pose, as some PTX files hold).

    Raises
    ------
    InputError
        If the matrix is not finite, not homogeneous, or not rigid/invertible as required.
    """
    M = np.asarray(T, dtype=np.float64)
    if M.shape != (4, 4):
        raise InputError(name, f"expected a 4x4 matrix, got shape {M.shape}")
    if not np.all(np.isfinite(M)):
        raise InputError(name, "matrix holds NaN or Inf")
    if not np.allclose(M[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise InputError(name, f"last row must be 0 0 0 1, got {M[3].tolist()}")
    R = M[:3, :3]
    if not rigid:
        if abs(np.linalg.det(R)) < 1e-12:
            raise InputError(name, "matrix is singular")
        return M
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise InputError(name, "rotation block is not a proper rotation (orthonormal, det +1)")
    return M


def is_rigid(T: ArrayLike, *, atol: float = 1e-6) -> bool:
    """True if the 3x3 block of a 4x4 matrix is a proper rotation (to ``atol``)."""
    R = np.asarray(T, dtype=np.float64)[:3, :3]
    return bool(np.allclose(R @ R.T, np.eye(3), atol=atol) and np.linalg.det(R) > 0)


def make_transform(R: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
    """Build a 4x4 transform from a (3, 3) rotation and a (3,) translation in metres."""
    T = np.eye(4)
    T[:3, :3] = np.asarray(R, dtype=np.float64)
    T[:3, 3] = np.asarray(t, dtype=np.float64)
    return T


def invert(T: ArrayLike) -> NDArray[np.float64]:
    """Inverse of a rigid transform, exact up to rounding (uses R^T, not a general inverse).

    >>> T = make_transform(np.eye(3), [1.0, 2.0, 3.0])
    >>> invert(T)[:3, 3].tolist()
    [-1.0, -2.0, -3.0]
    """
    M = np.asarray(T, dtype=np.float64)
    out = np.eye(4)
    out[:3, :3] = M[:3, :3].T
    out[:3, 3] = -M[:3, :3].T @ M[:3, 3]
    return out


def apply(T: ArrayLike, points: ArrayLike) -> NDArray[np.float64]:
    """Map (N, 3) points with a 4x4 transform: ``R @ p + t`` for each row."""
    M = np.asarray(T, dtype=np.float64)
    P = np.asarray(points, dtype=np.float64)
    return P @ M[:3, :3].T + M[:3, 3]


def rotation_error_deg(R_est: ArrayLike, R_ref: ArrayLike) -> float:
    """Geodesic angle between two rotations (or the rotation blocks of two 4x4), in degrees."""
    A = np.asarray(R_est, dtype=np.float64)[:3, :3]
    B = np.asarray(R_ref, dtype=np.float64)[:3, :3]
    c = (np.trace(A.T @ B) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def translation_error_m(T_est: ArrayLike, T_ref: ArrayLike) -> float:
    """Euclidean distance between the translations of two 4x4 transforms, in metres."""
    a = np.asarray(T_est, dtype=np.float64)[:3, 3]
    b = np.asarray(T_ref, dtype=np.float64)[:3, 3]
    return float(np.linalg.norm(a - b))


def rotation_about_axis(axis: ArrayLike, angle_rad: float) -> NDArray[np.float64]:
    """(3, 3) rotation of ``angle_rad`` about ``axis`` (Rodrigues' formula)."""
    k = np.asarray(axis, dtype=np.float64)
    k = k / np.linalg.norm(k)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle_rad) * K + (1.0 - np.cos(angle_rad)) * (K @ K)
