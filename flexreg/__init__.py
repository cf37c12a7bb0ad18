"""flexreg: register 3D scans through 2D Flexion images.

Public API (see the user guide in ``docs/``)::

    from flexreg import read_scan, range_image, SphericalCamera
    scan = read_scan("station1.ptx")
    img = range_image(scan)          # native grid, or z-buffer projection
"""

import logging
import os

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
from flexreg.io import read_scan, read_scans, read_transform, write_scan
from flexreg.stages.projection import range_image

logging.getLogger(__name__).addHandler(logging.NullHandler())

__all__ = [
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
