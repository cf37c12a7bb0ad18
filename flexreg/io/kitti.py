"""KITTI Velodyne scans: raw little-endian float32 records ``x y z reflectance`` (16 bytes each).

Points are in the Velodyne frame in metres; reflectance is the sensor's remission in 0..1.
The file has no header, no grid and no pose.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from flexreg.core.scan import Scan
from flexreg.errors import InputError

__all__ = ["read"]

RECORD_BYTES = 16  # four little-endian float32


def read(path: Path, **options: Any) -> list[Scan]:
    """Read a KITTI ``.bin`` Velodyne scan.

    Parameters
    ----------
    path : Path
    **options
        None are accepted; an unknown option raises :class:`InputError`.

    Returns
    -------
    list of Scan
        One scan: ``points`` (N, 3) float64 in metres (Velodyne frame), ``intensity`` (N,)
        float32 = reflectance. Records at exactly ``(0, 0, 0)`` (the sensor origin, never a
        return) are dropped.

    Raises
    ------
    InputError
        File size not a multiple of 16 bytes, NaN / Inf coordinates, or no points.
    """
    if options:
        raise InputError(path, f"unknown KITTI option(s): {', '.join(sorted(options))}")
    size = path.stat().st_size
    if size % RECORD_BYTES:
        raise InputError(
            path,
            f"size {size} bytes is not a multiple of {RECORD_BYTES} "
            "(KITTI records are 4 float32: x y z reflectance); truncated or not a KITTI scan",
        )
    try:
        raw = np.fromfile(path, dtype="<f4")
    except OSError as exc:
        raise InputError(path, f"cannot read: {exc}") from None
    if raw.size * 4 != size:
        raise InputError(path, f"read {raw.size * 4} of {size} bytes")
    rec = raw.reshape(-1, 4)
    xyz = rec[:, :3].astype(np.float64)
    finite = np.isfinite(xyz).all(axis=1)
    if not finite.all():
        bad = int(np.count_nonzero(~finite))
        raise InputError(path, f"{bad} of {len(rec)} points have NaN or Inf coordinates")
    keep = np.any(xyz != 0.0, axis=1)
    if not keep.any():
        raise InputError(path, f"all {len(rec)} points are (0, 0, 0): no returns")
    return [Scan(points=xyz[keep], intensity=rec[keep, 3], path=path, name=path.stem)]
