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
    try:
        M = np.asarray(T, dtype=np.float64)
    except (ValueError, TypeError):
        raise InputError(name, "expected a 4x4 matrix of numbers (ragged or non-numeric)") from None
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


def nearest_rotation(R: ArrayLike) -> NDArray[np.float64]:
    """The orthonormal matrix nearest to ``R`` in the Frobenius norm: ``U V^T`` of its SVD.

    Used to re-orthonormalise rotations stored with few digits (KITTI, 7-Scenes poses) or
    accumulated with rounding. The result is a proper rotation (det +1) when ``det(R) > 0``;
    for a reflection it stays a reflection, so callers that need a rotation check the sign.

    Parameters
    ----------
    R : (..., 3, 3) array_like
        One matrix or a stack of them.

    Returns
    -------
    (..., 3, 3) float64

    Examples
    --------
    >>> R = nearest_rotation([[1.0, 1e-4, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    >>> bool(np.allclose(R @ R.T, np.eye(3), atol=1e-15))
    True
    """
    U, _, Vt = np.linalg.svd(np.asarray(R, dtype=np.float64))
    out: NDArray[np.float64] = U @ Vt
    return out


#: quaternion component orders: ``xyzw`` (scalar last: TUM, ROS, scipy) or ``wxyz`` (scalar
#: first: E57, PCD ``VIEWPOINT``)
QUAT_ORDERS = ("xyzw", "wxyz")


def _check_order(order: str) -> None:
    if order not in QUAT_ORDERS:
        raise InputError("order", f"quaternion order must be xyzw or wxyz, got {order!r}")


def quat_to_matrix(q: ArrayLike, order: str = "xyzw") -> NDArray[np.float64]:
    """Rotation matrices of quaternions (normalised here).

    Parameters
    ----------
    q : (4,) or (N, 4) array_like
        Quaternions in ``order``; they need not be exactly unit (files carry 4 to 9 decimals).
    order : {"xyzw", "wxyz"}
        Scalar last (TUM trajectories) or scalar first (E57 poses, PCD viewpoints).

    Returns
    -------
    (3, 3) or (N, 3, 3) float64

    Examples
    --------
    >>> quat_to_matrix([0.0, 1.0, 0.0, 0.0], order="wxyz").round(12).tolist()
    [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]
    """
    # heavy: scipy.spatial costs ~0.3 s at import; every command imports this module
    from scipy.spatial.transform import Rotation

    _check_order(order)
    Q = np.asarray(q, dtype=np.float64)
    xyzw = Q if order == "xyzw" else Q[..., [1, 2, 3, 0]]
    M = np.asarray(Rotation.from_quat(xyzw.reshape(-1, 4)).as_matrix(), dtype=np.float64)
    return M.reshape(3, 3) if Q.ndim == 1 else M.reshape(-1, 3, 3)


def matrix_to_quat(R: ArrayLike, order: str = "xyzw") -> NDArray[np.float64]:
    """Unit quaternions of rotation matrices, with a non-negative scalar part.

    Parameters
    ----------
    R : (3, 3) or (N, 3, 3) array_like
        Rotations.
    order : {"xyzw", "wxyz"}
        Scalar last or scalar first.

    Returns
    -------
    (4,) or (N, 4) float64
        ``w >= 0`` (of the two quaternions of a rotation, the one with non-negative scalar).

    Examples
    --------
    >>> matrix_to_quat(np.eye(3), order="wxyz").tolist()
    [1.0, 0.0, 0.0, 0.0]
    """
    from scipy.spatial.transform import Rotation  # heavy: see quat_to_matrix

    _check_order(order)
    M = np.asarray(R, dtype=np.float64)
    q = np.asarray(Rotation.from_matrix(M.reshape(-1, 3, 3)).as_quat(), dtype=np.float64)
    q = np.where(q[:, 3:] < 0, -q, q)
    if order == "wxyz":
        q = q[:, [3, 0, 1, 2]]
    return q.reshape(4) if M.ndim == 2 else q


def scale_motion(T: ArrayLike, factor: float) -> NDArray[np.float64]:
    """The rigid motion ``T`` continued for ``factor`` times as long at constant velocity:
    ``exp(factor * log(T))`` on SE(3) (a screw motion; ``factor`` 2 gives ``T @ T``).

    >>> scale_motion(make_transform(np.eye(3), [0.2, 0.0, 0.0]), 0.5)[:3, 3].round(12).tolist()
    [0.1, 0.0, 0.0]
    """
    from scipy.linalg import expm, logm  # heavy: scipy.linalg costs ~0.25 s at import

    M = np.asarray(T, dtype=np.float64)
    L = np.real(logm(M))
    out = np.asarray(np.real(expm(float(factor) * L)), dtype=np.float64)
    out[:3, :3] = nearest_rotation(out[:3, :3])  # exact rotation despite rounding
    out[3] = [0.0, 0.0, 0.0, 1.0]
    return out
