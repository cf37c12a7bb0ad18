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
input checks                          :func:`usable_correspondences` (leaves slips out),
                                      :func:`check_correspondences` (strict), ``types.py``
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

import importlib
import sys
import types
from typing import TYPE_CHECKING, Any

from flexreg.exports import lazy

if TYPE_CHECKING:  # what the property below gives
    from flexreg.calibration.calibrate import calibrate as calibrate


class _Face(types.ModuleType):
    """This package's module type. ``calibrate`` names both a function and its submodule:
    importing the submodule binds the name on the package, which would hide the function, so
    the name is a property that always gives the function (loaded on first use, like the
    other names: the command line imports ``flexreg.calibration.config`` at start-up)."""

    @property
    def calibrate(self) -> Any:
        return importlib.import_module("flexreg.calibration.calibrate").calibrate

    @calibrate.setter
    def calibrate(self, value: Any) -> None:  # the import system binding the submodule
        pass


sys.modules[__name__].__class__ = _Face

#: public name -> the module that defines it (loaded on first use: see flexreg.exports)
_WHERE = {
    "MIN_CORRESPONDENCES": "flexreg.stages.camera_pose",
    "CalibrationConfig": "flexreg.calibration.config",
    "CalibrationError": "flexreg.errors",
    "CalibrationResult": "flexreg.calibration.types",
    "Correspondences2D3D": "flexreg.core.correspondences",
    "DroppedPair": "flexreg.calibration.types",
    "FlexionView": "flexreg.calibration.auto",
    "auto_scale": "flexreg.calibration.auto",
    "calibrate": "flexreg.calibration.calibrate",
    "calibrate_auto": "flexreg.calibration.auto",
    "check_correspondences": "flexreg.calibration.types",
    "edge_score": "flexreg.calibration.auto",
    "overlay_image": "flexreg.calibration.views",
    "panorama_camera": "flexreg.calibration.panorama",
    "panorama_flexion": "flexreg.calibration.panorama",
    "picking_views": "flexreg.calibration.views",
    "project_points": "flexreg.stages.camera_pose",
    "propose_correspondences": "flexreg.calibration.auto",
    "read_correspondences": "flexreg.calibration.panorama",
    "render_flexion_view": "flexreg.calibration.auto",
    "reprojection_errors": "flexreg.stages.camera_pose",
    "scan_range_image": "flexreg.calibration.panorama",
    "solve_pnp": "flexreg.calibration.pnp",
    "usable_correspondences": "flexreg.calibration.types",
}
__getattr__, __dir__ = lazy(globals(), _WHERE)
__all__ = list(_WHERE)
