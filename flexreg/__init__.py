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

from ._version import __version__
from .camera import PinholeCamera, SphericalCamera
from .errors import (
    ConfigError,
    DegenerateGeometryError,
    FlexregError,
    InputError,
    RegistrationError,
)
from .io import read_scan, read_scans, read_transform, write_scan
from .projection import RangeImage, from_depth, range_image
from .scan import Scan

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
