"""flexreg: register 3D scans through 2D Flexion images.

The public API in one place (the README's "Python API" section runs as a test)::

    import flexreg
    target, source = flexreg.read_scan("station1.ptx"), flexreg.read_scan("station2.ptx")
    result = flexreg.register(target, source)       # RegistrationConfig() defaults
    result.T_target_source                          # (4, 4) float64: source -> target frame

    config = flexreg.load_config(flexreg.RegistrationConfig, "run.toml", {"n": 7})
    img = flexreg.range_image(target)               # native grid, or z-buffer projection

This module only hands names on (docs/architecture.md shows the layers they come from); no
module inside flexreg imports it. The applications (``register``, ``calibrate``, ``odometry``,
...) load on first use, so ``import flexreg`` stays light for the command line.
"""

import logging
import os

from flexreg.core.jit import cache_env

# numba reads its cache folder at import: a read-only install caches in the user's cache folder
os.environ.update(cache_env())

import numba

# open3d ships an older TBB than numba's TBB layer accepts; prefer OpenMP, then workqueue.
if "NUMBA_THREADING_LAYER" not in os.environ:
    numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]  # type: ignore[attr-defined]

from flexreg._version import __version__
from flexreg.core.camera import PinholeCamera, SphericalCamera
from flexreg.core.range_image import RangeImage, from_depth
from flexreg.core.scan import Scan
from flexreg.errors import (
    ConfigError,
    DegenerateGeometryError,
    FlexregError,
    InputError,
    RegistrationError,
)
from flexreg.exports import lazy
from flexreg.io import read_scan, read_scans, read_transform, write_scan
from flexreg.stages.projection import range_image

logging.getLogger(__name__).addHandler(logging.NullHandler())

#: Loaded on first use: name -> the module (package face) that defines it.
_LAZY = {
    "load_config": "flexreg.config",
    "register": "flexreg.registration",
    "RegistrationConfig": "flexreg.registration",
    "RegistrationResult": "flexreg.registration",
    "calibrate": "flexreg.calibration",
    "CalibrationConfig": "flexreg.calibration",
    "CalibrationResult": "flexreg.calibration",
    "CalibrationError": "flexreg.errors",
    "odometry": "flexreg.odometry",
    "OdometryConfig": "flexreg.odometry",
    "OdometryResult": "flexreg.odometry",
    "read_trajectory": "flexreg.io.trajectory",
    "write_trajectory": "flexreg.io.trajectory",
    "rotation_error_deg": "flexreg.core.transforms",
    "translation_error_m": "flexreg.core.transforms",
}


__getattr__, __dir__ = lazy(globals(), _LAZY)


__all__ = [
    *sorted(_LAZY),
    "ConfigError",
    "DegenerateGeometryError",
    "FlexregError",
    "InputError",
    "PinholeCamera",
    "RangeImage",
    "RegistrationError",
    "Scan",
    "SphericalCamera",
    "__version__",
    "from_depth",
    "range_image",
    "read_scan",
    "read_scans",
    "read_transform",
    "write_scan",
]
