"""The calibration result and the checks correspondences must pass before PnP."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.calibration.config import CalibrationConfig
from flexreg.core.correspondences import Correspondences2D3D
from flexreg.core.results import Verdict
from flexreg.core.transforms import as_transform, invert, matrix_to_quat
from flexreg.errors import InputError
from flexreg.io.intrinsics import CameraIntrinsics
from flexreg.stages.camera_pose import MIN_CORRESPONDENCES, to_rvec_tvec

__all__ = [
    "CalibrationResult",
    "DroppedPair",
    "check_correspondences",
    "describe_dropped",
    "usable_correspondences",
]


@dataclass(frozen=True)
class DroppedPair:
    """A correspondence left out of a calibration, and why.

    Attributes
    ----------
    where : str
        ``"line 12"`` (its line in the CSV file) or ``"pair 3"``.
    line : int
        Its line in the file (1-based), 0 when it was not read from a file.
    reason : str
        ``"pixel (1300, 20) outside the 1224x370 image"``, ``"behind the camera of the
        initial guess (z = -3.10 m)"`` or ``"behind the camera under the solution (z = ...)"``.
    """

    where: str
    line: int
    reason: str

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready record."""
        return {"where": self.where, "line": self.line or None, "reason": self.reason}


def _outside(c: Correspondences2D3D, intrinsics: CameraIntrinsics) -> NDArray[np.bool_]:
    """(N,) bool: pixels outside the image (False everywhere when its size is unknown)."""
    if intrinsics.size is None:
        return np.zeros(len(c), dtype=bool)
    W, H = intrinsics.size
    u, v = c.pixels[:, 0], c.pixels[:, 1]
    return np.asarray((u < -0.5) | (u > W - 0.5) | (v < -0.5) | (v > H - 0.5))


def _depth(c: Correspondences2D3D, T: ArrayLike, name: str) -> NDArray[np.float64]:
    """(N,) float64 camera-frame depth of the pairs' lidar points under ``T``, metres."""
    M = as_transform(T, name=name)
    return np.asarray(c.points @ M[2, :3] + M[2, 3], dtype=np.float64)


def usable_correspondences(
    correspondences: Correspondences2D3D,
    intrinsics: CameraIntrinsics,
    *,
    T_camera_lidar: ArrayLike | None = None,
    pose: str = "initial guess",
) -> tuple[Correspondences2D3D, tuple[DroppedPair, ...]]:
    """The pairs PnP can use, and the ones left out with the reason.

    A pair is left out when its pixel lies outside the image (intrinsics must know its size)
    or -- with a pose -- its lidar point lies behind that camera (``z <= 0``). A hand-made file
    often holds a few such slips; one of them should not refuse the whole file.

    Parameters
    ----------
    correspondences : Correspondences2D3D
    intrinsics : CameraIntrinsics
    T_camera_lidar : (4, 4) float, optional
        Pose under which points behind the camera are left out.
    pose : str
        What the pose is, for the reasons (``"initial guess"``, ``"solution"``).

    Returns
    -------
    kept : Correspondences2D3D
        The usable pairs, in their order (line numbers kept).
    dropped : tuple of DroppedPair
        In file order.

    Examples
    --------
    >>> from flexreg.io.intrinsics import CameraIntrinsics
    >>> intr = CameraIntrinsics([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]], [], 640, 480)
    >>> c = Correspondences2D3D([[10.0, 20], [700, 20]], [[0, 0, 5.0], [1, 0, -5]], [2, 3])
    >>> kept, dropped = usable_correspondences(c, intr)
    >>> len(kept), [d.where for d in dropped], dropped[0].reason
    (1, ['line 3'], 'pixel (700, 20) outside the 640x480 image')
    """
    c = correspondences
    reasons: dict[int, str] = {}
    out = _outside(c, intrinsics)
    if out.any():
        assert intrinsics.size is not None
        W, H = intrinsics.size
        for i in np.flatnonzero(out):
            u, v = c.pixels[i]
            reasons[int(i)] = f"pixel ({u:g}, {v:g}) outside the {W}x{H} image"
    if T_camera_lidar is not None:
        z = _depth(c, T_camera_lidar, pose)
        for i in np.flatnonzero(~(z > 0)):
            reasons.setdefault(int(i), f"behind the camera of the {pose} (z = {z[i]:.2f} m)")
    if not reasons:
        return c, ()
    keep = np.ones(len(c), dtype=bool)
    keep[list(reasons)] = False
    dropped = tuple(DroppedPair(c.where(i), int(c.lines[i]), reasons[i]) for i in sorted(reasons))
    return c.subset(keep), dropped


def describe_dropped(dropped: tuple[DroppedPair, ...], *, limit: int = 10) -> str:
    """``"line 4 (pixel (1300, 20) outside ...), line 9 (...)"``: the first ``limit`` pairs,
    then how many more."""
    text = ", ".join(f"{d.where} ({d.reason})" for d in dropped[:limit])
    return text + (f" and {len(dropped) - limit} more" if len(dropped) > limit else "")


def check_correspondences(
    correspondences: Correspondences2D3D,
    intrinsics: CameraIntrinsics,
    *,
    T_init: ArrayLike | None = None,
) -> None:
    """Reject correspondences PnP cannot use, naming the offending lines (strict: the solver
    leaves such pairs out instead, see :func:`usable_correspondences`).

    Raises
    ------
    InputError
        Fewer than :data:`flexreg.stages.camera_pose.MIN_CORRESPONDENCES` pairs, a pixel
        outside the image (intrinsics must know the image size), or -- with an initial guess --
        a lidar point that lies behind the camera under it.
    """
    c = correspondences
    src = c.source or "correspondences"
    if len(c) < MIN_CORRESPONDENCES:
        raise InputError(
            src,
            f"only {len(c)} correspondence(s); camera-lidar calibration needs at least "
            f"{MIN_CORRESPONDENCES}",
        )
    if intrinsics.size is not None:
        W, H = intrinsics.size
        u, v = c.pixels[:, 0], c.pixels[:, 1]
        out = np.flatnonzero((u < -0.5) | (u > W - 0.5) | (v < -0.5) | (v > H - 0.5))
        if out.size:
            i = int(out[0])
            more = f" (and {out.size - 1} more)" if out.size > 1 else ""
            raise InputError(
                src,
                f"{c.where(i)}: pixel ({u[i]:g}, {v[i]:g}) lies outside the {W}x{H} camera "
                f"image{more}",
            )
    if T_init is not None:
        T = as_transform(T_init, name="initial guess")
        z = c.points @ T[2, :3] + T[2, 3]
        behind = np.flatnonzero(z <= 0)
        if behind.size:
            i = int(behind[0])
            more = f" (and {behind.size - 1} more)" if behind.size > 1 else ""
            raise InputError(
                src,
                f"{c.where(i)}: lidar point ({', '.join(f'{x:.3f}' for x in c.points[i])}) lies "
                f"behind the camera of the initial guess (z = {z[i]:.2f} m){more}",
            )


@dataclass(eq=False)
class CalibrationResult:
    """A camera-lidar extrinsic with the evidence for it.

    Attributes
    ----------
    T_camera_lidar : (4, 4) float64
        Maps lidar points into the camera frame (x right, y down, z forward), metres.
    correspondences : Correspondences2D3D
        Every pair the solver saw (for the automatic mode: the final round's).
    inlier_mask : (N,) bool
        Pairs within ``threshold_px`` of their projection (in front of the camera).
    residuals_px : (N,) float64, pixels
        Reprojection error of every pair under ``T_camera_lidar`` (inf behind the camera).
    threshold_px : float, pixels
    intrinsics : CameraIntrinsics
    method : str
        ``"pairs"`` (given correspondences) or ``"auto"`` (automatic proposals).
    config : CalibrationConfig
    timings_s : dict of str to float
    T_init : (4, 4) float64 or None
        The initial guess, when one was used.
    auto : dict or None
        Automatic mode: per-round matches, inliers, search radius and edge score.
    dropped : tuple of DroppedPair
        Given pairs left out before or after solving (pixel outside the image, point behind
        the camera of the initial guess or of the solution); not in ``correspondences``.
    verdict : Verdict or None
        Whether the inliers' geometry can be trusted (:mod:`flexreg.calibration.verdict`):
        ``"uncertain"`` with reasons for near-degenerate sets (few inliers, coplanar or
        nearly collinear points, pixels in one small region, weak axes).
    """

    T_camera_lidar: NDArray[np.float64]
    correspondences: Correspondences2D3D
    inlier_mask: NDArray[np.bool_]
    residuals_px: NDArray[np.float64]
    threshold_px: float
    intrinsics: CameraIntrinsics
    method: str = "pairs"
    config: CalibrationConfig = field(default_factory=CalibrationConfig)
    timings_s: dict[str, float] = field(default_factory=dict)
    T_init: NDArray[np.float64] | None = None
    auto: dict[str, Any] | None = None
    verdict: Verdict | None = None
    dropped: tuple[DroppedPair, ...] = ()

    def __repr__(self) -> str:
        t = self.translation_m
        return (
            f"CalibrationResult({self.method}, {self.inliers}/{len(self.correspondences)} "
            f"inliers, RMSE {self.reprojection_rmse_px:.2f} px, "
            f"t = [{t[0]:.3f}, {t[1]:.3f}, {t[2]:.3f}] m"
            + ("" if self.verdict is None else f", {self.verdict.status}")
            + ")"
        )

    @property
    def T_lidar_camera(self) -> NDArray[np.float64]:
        """(4, 4) float64 inverse: maps camera points into the lidar frame (camera pose)."""
        return invert(self.T_camera_lidar)

    @property
    def translation_m(self) -> NDArray[np.float64]:
        """(3,) float64 ``t`` of ``T_camera_lidar``: the lidar origin in the camera frame."""
        return self.T_camera_lidar[:3, 3].copy()

    @property
    def quaternion_xyzw(self) -> NDArray[np.float64]:
        """(4,) float64 rotation of ``T_camera_lidar`` as a unit quaternion, scalar last."""
        return matrix_to_quat(self.T_camera_lidar[:3, :3], order="xyzw")

    @property
    def quaternion_wxyz(self) -> NDArray[np.float64]:
        """(4,) float64 the same quaternion, scalar first."""
        return matrix_to_quat(self.T_camera_lidar[:3, :3], order="wxyz")

    @property
    def inliers(self) -> int:
        """Number of inlier pairs."""
        return int(np.count_nonzero(self.inlier_mask))

    @property
    def reprojection_rmse_px(self) -> float:
        """Root mean square reprojection error of the inliers, pixels (NaN without inliers)."""
        r = self.residuals_px[self.inlier_mask]
        return float(np.sqrt(np.mean(r * r))) if r.size else float("nan")

    def _pairs(self) -> list[dict[str, Any]]:
        """Per-pair record of :meth:`to_dict`."""
        c = self.correspondences
        return [
            {
                "line": int(c.lines[i]) or None,
                "u": float(c.pixels[i, 0]),
                "v": float(c.pixels[i, 1]),
                "X": float(c.points[i, 0]),
                "Y": float(c.points[i, 1]),
                "Z": float(c.points[i, 2]),
                "residual_px": float(self.residuals_px[i])
                if math.isfinite(self.residuals_px[i])
                else None,
                "inlier": bool(self.inlier_mask[i]),
            }
            for i in range(len(c))
        ]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict: both transforms, labelled quaternions, RMSE, per-pair residuals."""
        rvec, _ = to_rvec_tvec(self.T_camera_lidar)
        return {
            "T_camera_lidar": self.T_camera_lidar.tolist(),
            "T_lidar_camera": self.T_lidar_camera.tolist(),
            "convention": (
                "T_camera_lidar maps lidar points (metres) into the camera frame "
                "(x right, y down, z forward): p_camera = R p_lidar + t; "
                "T_lidar_camera is its inverse (the camera pose in the lidar frame)"
            ),
            "rotation_camera_lidar": {
                "quaternion_xyzw": self.quaternion_xyzw.tolist(),
                "quaternion_wxyz": self.quaternion_wxyz.tolist(),
                "rotation_vector_rad": rvec.tolist(),
            },
            "translation_camera_lidar_m": self.translation_m.tolist(),
            "camera_position_in_lidar_m": self.T_lidar_camera[:3, 3].tolist(),
            "method": self.method,
            "solver": "cv2.solvePnPRansac (USAC_MAGSAC) + cv2.solvePnPRefineLM on the inliers",
            "reprojection_rmse_px": self.reprojection_rmse_px,
            "inliers": self.inliers,
            "correspondences": len(self.correspondences),
            "threshold_px": self.threshold_px,
            "intrinsics": self.intrinsics.to_dict(),
            "T_init": None if self.T_init is None else self.T_init.tolist(),
            "auto": self.auto,
            "verdict": None if self.verdict is None else self.verdict.to_dict(),
            "dropped": [d.to_dict() for d in self.dropped],
            "timings_s": self.timings_s,
            "seed": self.config.seed,
            "config": self.config.to_dict(),
            "pairs": self._pairs(),
        }
