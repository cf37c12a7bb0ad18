"""Camera-lidar extrinsic calibration from 2D-3D correspondences (PnP).

The classic targetless recipe (Scaramuzza et al., the paper's ref. [5]) turns the scan into an
image that shows geometry, pairs points between that image and the photo, and solves a
Perspective-n-Point problem. Here the image is a Flexion image (paper eq. 11-13) and every stage
is a public function:

====================================  =========================================================
stage                                 function
====================================  =========================================================
correspondences from a CSV file       :func:`read_correspondences` (``u,v`` + ``X,Y,Z`` or
                                      ``row,col`` of the scan's range image), ``panorama.py``
input checks                          :func:`check_correspondences`, ``types.py``
PnP (RANSAC + Levenberg-Marquardt)    :func:`solve_pnp`, ``pnp.py`` (over
                                      :func:`flexreg.stages.camera_pose.solve_pnp`)
Flexion image seen from the camera    :func:`render_flexion_view`, ``auto.py``
automatic proposals                   :func:`propose_correspondences`, :func:`calibrate_auto`
the one call                          :func:`calibrate`, ``calibrate.py``
verification / picking aids           :func:`overlay_image`, :func:`picking_views`,
                                      ``views.py``
====================================  =========================================================

Conventions: see :mod:`flexreg.calibration.calibrate`.
"""

from flexreg.calibration.auto import (
    FlexionView,
    auto_scale,
    calibrate_auto,
    edge_score,
    propose_correspondences,
    render_flexion_view,
)
from flexreg.calibration.calibrate import calibrate
from flexreg.calibration.config import CalibrationConfig
from flexreg.calibration.panorama import (
    panorama_camera,
    panorama_flexion,
    read_correspondences,
    scan_range_image,
)
from flexreg.calibration.pnp import solve_pnp
from flexreg.calibration.types import CalibrationResult, check_correspondences
from flexreg.calibration.views import overlay_image, picking_views
from flexreg.core.correspondences import Correspondences2D3D
from flexreg.errors import CalibrationError
from flexreg.stages.camera_pose import MIN_CORRESPONDENCES, project_points, reprojection_errors

__all__ = [
    "MIN_CORRESPONDENCES",
    "CalibrationConfig",
    "CalibrationError",
    "CalibrationResult",
    "Correspondences2D3D",
    "FlexionView",
    "auto_scale",
    "calibrate",
    "calibrate_auto",
    "check_correspondences",
    "edge_score",
    "overlay_image",
    "panorama_camera",
    "panorama_flexion",
    "picking_views",
    "project_points",
    "propose_correspondences",
    "read_correspondences",
    "render_flexion_view",
    "reprojection_errors",
    "scan_range_image",
    "solve_pnp",
]
