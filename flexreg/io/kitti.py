"""KITTI Velodyne scans: raw little-endian float32 records ``x y z reflectance`` (16 bytes each).

Points are in the Velodyne frame in metres; reflectance is the sensor's remission in 0..1.
The file has no header, no grid and no pose.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.core.scan import Scan
from flexreg.errors import InputError

__all__ = ["read"]

RECORD_BYTES = 16  # four little-endian float32
#: farthest believable coordinate of a Velodyne-style return, metres
MAX_COORDINATE_M = 10_000.0
#: nearest non-zero coordinate a sensor reports, metres; smaller magnitudes are what float64
#: or text bytes look like when read as float32
MIN_NONZERO_M = 1e-9


def _check_plausible(path: Path, rec: NDArray[np.float32]) -> None:
    """Refuse records that cannot be float32 ``x y z reflectance`` returns: coordinates beyond
    :data:`MAX_COORDINATE_M`, many tiny non-zero ones (float64 or text bytes read as float32),
    or a non-finite reflectance."""
    xyz = np.abs(rec[:, :3])
    far = int(np.count_nonzero((xyz > MAX_COORDINATE_M).any(axis=1)))
    tiny = int(np.count_nonzero(((xyz > 0) & (xyz < MIN_NONZERO_M)).any(axis=1)))
    hint = "not float32 x y z reflectance records (a text or float64 file?)"
    if far:
        raise InputError(
            path, f"{far} of {len(rec)} points lie beyond {MAX_COORDINATE_M:g} m: {hint}"
        )
    if tiny > max(1, len(rec) // 100):
        raise InputError(
            path, f"{tiny} of {len(rec)} points have coordinates below {MIN_NONZERO_M:g} m: {hint}"
        )
    if not np.isfinite(rec[:, 3]).all():
        raise InputError(path, f"reflectance holds NaN or Inf: {hint}")


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
        File size not a multiple of 16 bytes, NaN / Inf coordinates, coordinates that cannot
        be float32 returns (beyond 10 km, or many below a nanometre: a text or float64 file),
        or no points.
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
    _check_plausible(path, rec)
    keep = np.any(xyz != 0.0, axis=1)
    if not keep.any():
        raise InputError(path, f"all {len(rec)} points are (0, 0, 0): no returns")
    return [Scan(points=xyz[keep], intensity=rec[keep, 3], path=path, name=path.stem)]
