"""Camera-lidar extrinsic calibration: :func:`calibrate`, the one call.

Conventions. ``T_camera_lidar`` is a 4 x 4 float64 rigid transform that maps lidar-frame points
(metres) into the camera frame (OpenCV: x right, y down, z forward):
``p_camera = R p_lidar + t``. Its inverse ``T_lidar_camera`` holds the camera's pose in the
lidar frame. Quaternions are labelled ``xyzw`` (scalar last, SciPy's order) or ``wxyz`` (scalar
first). Pixels follow :mod:`flexreg.core.camera`: integer ``(u, v)`` is the centre of pixel
``[v, u]``, so the image spans ``[-0.5, W - 0.5] x [-0.5, H - 0.5]``. Pixel coordinates are
those of the image as given (distorted); the lens model is OpenCV's (see
:mod:`flexreg.io.intrinsics`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.calibration.auto import calibrate_auto
from flexreg.calibration.config import CalibrationConfig
from flexreg.calibration.pnp import solve_pnp
from flexreg.calibration.types import CalibrationResult
from flexreg.core.correspondences import Correspondences2D3D
from flexreg.core.scan import Scan
from flexreg.errors import InputError
from flexreg.io.intrinsics import CameraIntrinsics

__all__ = ["calibrate"]


def calibrate(
    image: NDArray[np.uint8] | None,
    scan: Scan | None,
    intrinsics: CameraIntrinsics,
    *,
    pairs: Correspondences2D3D | None = None,
    T_init: ArrayLike | None = None,
    auto: bool = False,
    config: CalibrationConfig = CalibrationConfig(),
) -> CalibrationResult:
    """Camera-lidar extrinsic ``T_camera_lidar``: the one call.

    Parameters
    ----------
    image : (H, W[, 3]) uint8 or None
        Camera image; needed for ``auto`` (otherwise only its size is checked).
    scan : Scan or None
        Lidar scan; needed for ``auto``.
    intrinsics : CameraIntrinsics
    pairs : Correspondences2D3D, optional
        Given correspondences.
    T_init : (4, 4) float, optional
        Initial guess; required for ``auto`` unless ``pairs`` give one.
    auto : bool
        Propose correspondences automatically (:func:`flexreg.calibration.calibrate_auto`);
        given pairs join every round.
    config : CalibrationConfig

    Returns
    -------
    CalibrationResult
    """
    if image is not None:
        h, w = np.asarray(image).shape[:2]
        intrinsics = intrinsics.for_image(w, h)
    if not auto:
        if pairs is None:
            raise InputError("pairs", "give correspondences or use the automatic mode")
        return solve_pnp(pairs, intrinsics, config=config, T_init=T_init)
    if image is None or scan is None:
        raise InputError("auto", "the automatic mode needs the camera image and the scan")
    if T_init is None:
        if pairs is None:
            raise InputError("auto", "the automatic mode needs an initial guess or pairs")
        T_init = solve_pnp(pairs, intrinsics, config=config).T_camera_lidar
    return calibrate_auto(image, scan, intrinsics, T_init, config=config, pairs=pairs)
