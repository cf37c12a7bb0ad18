"""Scan and transform I/O: ``read_scan`` / ``read_scans`` / ``write_scan`` dispatch on the suffix.

Every reader returns whole, validated :class:`~flexreg.core.scan.Scan` objects or raises
:class:`~flexreg.errors.InputError` naming the file and the problem; nothing is half-read.

=============  ==========================================================================
suffix         reader
=============  ==========================================================================
``.ptx``       Leica PTX, every cloud, native grid, pose (``flexreg.io.ptx``)
``.e57``       ASTM E57 via pye57, every scan, row/column grid, pose (``flexreg.io.e57``)
``.ply``       PLY via open3d (``flexreg.io.pointcloud``)
``.pcd``       PCD via open3d; an organised PCD keeps its width x height grid (written:
               unorganised binary, the pose as ``VIEWPOINT``; ``pointcloud.write_pcd``)
``.las/.laz``  LAS/LAZ via laspy (``flexreg.io.las``)
``.bin``       KITTI Velodyne float32 ``x y z reflectance`` (``flexreg.io.kitti``)
``.3d``        3DTK scan (cm, left-handed) with its ``.pose`` (``flexreg.io.threedtk``)
``.npy/.npz``  NumPy arrays; ``.npz`` in flexreg's own layout round-trips (``flexreg.io.npz``)
``.png``       16-bit depth/range image + camera (``flexreg.io.depth``)
=============  ==========================================================================
"""

from __future__ import annotations

from flexreg.io.files import atomic_write
from flexreg.io.formats import FORMATS, detect_format
from flexreg.io.scans import read_scan, read_scans, read_working_scan, write_scan
from flexreg.io.transform_io import read_transform, write_transform_json, write_transform_txt

__all__ = [
    "FORMATS",
    "atomic_write",
    "detect_format",
    "read_scan",
    "read_scans",
    "read_transform",
    "read_working_scan",
    "write_scan",
    "write_transform_json",
    "write_transform_txt",
]
