"""Trajectories on disk: TUM RGB-D and KITTI odometry text formats.

A :class:`~flexreg.core.trajectory.Trajectory` is a time-stamped sequence of poses
``T_world_frame`` (4x4 float64, mapping points of frame ``i`` into the world frame; the
camera-to-world convention both formats use).

===========  ==================================================================================
format       one pose per line
===========  ==================================================================================
``tum``      ``t tx ty tz qx qy qz qw``: time (s), position (m), unit quaternion **xyzw**
             (scalar last); ``#`` starts a comment line; commas or tabs may separate values
             (as the TUM benchmark tools accept).
``kitti``    12 numbers: the first three rows of the 4x4 matrix, row-major; the timestamp of
             line ``i`` (counting from 0) is the frame index ``i``.
===========  ==================================================================================

Reading never half-reads a file: a malformed line raises :class:`~flexreg.errors.InputError`
naming the file and the line number.
"""

from __future__ import annotations

import logging
import math
from os import PathLike
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from flexreg.core.trajectory import Trajectory
from flexreg.core.transforms import matrix_to_quat, nearest_rotation, quat_to_matrix
from flexreg.errors import InputError
from flexreg.io.files import atomic_write, protect

log = logging.getLogger(__name__)

__all__ = [
    "FORMATS",
    "detect_format",
    "read_trajectory",
    "write_trajectory",
]

#: trajectory text formats, by name
FORMATS = ("tum", "kitti")
#: numbers per data line of each format
_VALUES = {"tum": 8, "kitti": 12}
#: a TUM quaternion whose norm differs from 1 by more than this is not a rotation (files
#: written with 4 decimals, like the TUM ground truth, stay within 1e-4)
QUAT_NORM_TOL = 1e-2
#: a KITTI 3x3 block with max |R R^T - I| above this is not a rotation (7-digit KITTI ground
#: truth stays within 1e-6)
ROTATION_TOL = 1e-4


def _parse_lines(path: Path, text: str, fmt: str) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """All data lines of ``text`` as an (M, k) array and their 1-based line numbers.

    ``fmt`` is ``tum``, ``kitti`` or ``auto`` (decided by the first data line: 8 or 12 values).
    """
    rows: list[list[float]] = []
    linenos: list[int] = []
    width = _VALUES.get(fmt)
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        tokens = line.replace(",", " ").split()
        try:
            values = [float(tok) for tok in tokens]
        except ValueError:
            bad = next(tok for tok in tokens if not _is_float(tok))
            raise InputError(path, f"line {lineno}: not a number: {bad[:40]!r}") from None
        if width is None:  # auto: the first data line decides
            if len(values) not in (8, 12):
                raise InputError(
                    path,
                    f"line {lineno}: expected 8 values (TUM: t tx ty tz qx qy qz qw) or 12 "
                    f"(KITTI: 3x4 matrix, row-major), got {len(values)}",
                )
            width = len(values)
            fmt = "tum" if width == 8 else "kitti"
        if len(values) != width:
            what = "t tx ty tz qx qy qz qw" if fmt == "tum" else "a 3x4 matrix, row-major"
            raise InputError(
                path, f"line {lineno}: expected {width} values ({what}), got {len(values)}"
            )
        if not all(map(math.isfinite, values)):
            raise InputError(path, f"line {lineno}: NaN or Inf")
        rows.append(values)
        linenos.append(lineno)
    if not rows:
        raise InputError(path, "no poses (the file holds only blank or comment lines)")
    return np.asarray(rows, dtype=np.float64), np.asarray(linenos, dtype=np.intp)


def _is_float(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


#: a repeated TUM timestamp is a rounding collision (kept, later line wins, as in the TUM
#: tools) when its two poses agree this well; two farther poses at one time are refused
REPEAT_TOL_M, REPEAT_TOL_DEG = 0.05, 5.0


def _check_increasing(path: Path, rows: NDArray[np.float64], linenos: NDArray[np.intp]) -> None:
    """Refuse a decreasing timestamp, and a repeated one whose two poses disagree (more than
    :data:`REPEAT_TOL_M` / :data:`REPEAT_TOL_DEG`), naming both lines. Official TUM ground
    truth repeats a timestamp now and then (4 decimals of a 100+ Hz mocap) with poses 1 mm
    apart: that is kept."""
    t = rows[:, 0]
    step = np.diff(t)
    if (step > 0).all():
        return
    for k in np.flatnonzero(step <= 0) + 1:
        if step[k - 1] < 0:
            how = "is earlier than"
        else:
            q0, q1 = rows[k - 1, 4:8], rows[k, 4:8]
            cos = abs(float(q0 @ q1)) / max(float(np.linalg.norm(q0) * np.linalg.norm(q1)), 1e-12)
            angle = math.degrees(2 * math.acos(min(1.0, cos)))
            gap = float(np.linalg.norm(rows[k, 1:4] - rows[k - 1, 1:4]))
            if gap <= REPEAT_TOL_M and angle <= REPEAT_TOL_DEG:
                continue
            how = f"repeats, with a pose {gap:.3g} m / {angle:.3g}° away from the one on"
        raise InputError(
            path,
            f"line {linenos[k]}: timestamp {t[k]:.17g} {how} line {linenos[k - 1]}; timestamps "
            "must increase (two poses at one time, or files joined out of order?)",
        )


def _from_tum(
    path: Path, rows: NDArray[np.float64], linenos: NDArray[np.intp], *, strict: bool = True
) -> Trajectory:
    q = rows[:, 4:8]
    norm = np.linalg.norm(q, axis=1)
    bad = np.abs(norm - 1.0) > QUAT_NORM_TOL
    if bad.any():
        k = int(np.argmax(bad))
        raise InputError(
            path,
            f"line {linenos[k]}: quaternion qx qy qz qw = {q[k].tolist()} has norm "
            f"{norm[k]:.6g}, not a rotation (expected a unit quaternion)",
        )
    t = rows[:, 0]
    if strict:
        _check_increasing(path, rows, linenos)
    # the TUM tools keep poses in a dict keyed by timestamp: sorted, the last line of a
    # repeated timestamp wins; do the same, and say so
    order = np.lexsort((np.arange(len(t)), t))
    if (np.diff(t) < 0).any():
        log.warning("%s: timestamps are not in order; poses sorted by time", path)
    ts = t[order]
    last = np.append(ts[1:] != ts[:-1], True)
    if not last.all():
        dup = order[~last]
        log.warning(
            "%s: %d repeated timestamp(s) (first at line %d); the later line is used",
            path,
            len(dup),
            linenos[dup[0]],
        )
    keep = order[last]
    poses = np.tile(np.eye(4), (len(keep), 1, 1))
    poses[:, :3, :3] = quat_to_matrix(q[keep], order="xyzw")
    poses[:, :3, 3] = rows[keep, 1:4]
    return Trajectory(t[keep], poses, name=str(path))


def _from_kitti(path: Path, rows: NDArray[np.float64], linenos: NDArray[np.intp]) -> Trajectory:
    M = rows.reshape(-1, 3, 4)
    R = M[:, :, :3]
    dev = np.abs(R @ R.transpose(0, 2, 1) - np.eye(3)).max(axis=(1, 2))
    det = np.linalg.det(R)
    bad = (dev > ROTATION_TOL) | (det <= 0)
    if bad.any():
        k = int(np.argmax(bad))
        raise InputError(
            path,
            f"line {linenos[k]}: the 3x3 block is not a rotation (max |R R^T - I| = "
            f"{dev[k]:.3g}, det = {det[k]:.6g})",
        )
    poses = np.tile(np.eye(4), (len(M), 1, 1))
    poses[:, :3, :3] = nearest_rotation(R)
    poses[:, :3, 3] = M[:, :, 3]
    return Trajectory(np.arange(len(M), dtype=np.float64), poses, name=str(path))


def detect_format(path: str | PathLike[str]) -> str:
    """``"tum"`` or ``"kitti"``, by the number of values on the first data line (8 or 12).

    Raises
    ------
    InputError
        Missing file, no data line, or a first data line with another number of values.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(p, "no such file")
    try:
        with p.open(encoding="utf-8-sig", errors="replace") as f:
            for lineno, raw in enumerate(f, start=1):
                line = raw.strip()
                if not line or line.startswith("#"):
                    continue
                n = len(line.replace(",", " ").split())
                if n in (8, 12):
                    return "tum" if n == 8 else "kitti"
                raise InputError(
                    p,
                    f"line {lineno}: expected 8 values (TUM: t tx ty tz qx qy qz qw) or 12 "
                    f"(KITTI: 3x4 matrix, row-major), got {n}",
                )
    except OSError as e:
        raise InputError(p, f"cannot read: {e.strerror or e}") from None
    raise InputError(p, "no poses (the file holds only blank or comment lines)")


def read_trajectory(
    path: str | PathLike[str],
    fmt: Literal["auto", "tum", "kitti"] | str = "auto",
    *,
    strict: bool = True,
) -> Trajectory:
    """Read a TUM or KITTI trajectory file.

    Parameters
    ----------
    path : str or path-like
        The text file.
    fmt : {"auto", "tum", "kitti"}
        ``auto`` decides by the number of values on the first data line (8: TUM, 12: KITTI).
    strict : bool
        True: TUM timestamps must increase line by line: a decreasing one is an error, and so is
        a repeated one unless its two poses agree within 5 cm and 5° (a rounding collision, as
        in the official TUM ground truth). False: do as the TUM benchmark tools do (below).

    Returns
    -------
    Trajectory
        Poses ``T_world_frame`` (camera-to-world). TUM quaternions are normalised (the files
        carry 4 to 9 decimals) and the KITTI 3x3 blocks projected onto the nearest rotation
        (``U V^T`` of their SVD), so every pose is exactly rigid to rounding. With
        ``strict=False``, TUM lines are sorted by time and, for a repeated timestamp, the
        later line wins (as in the TUM benchmark tools); both cases are logged as warnings.
        KITTI timestamps are the frame indices 0, 1, 2, ...

    Raises
    ------
    InputError
        Missing file; a line with a wrong number of values, a non-number, NaN/Inf, a
        quaternion far from unit norm (more than 1e-2) or a 3x3 block that is not a rotation
        (max ``|R R^T - I|`` above 1e-4, or det <= 0) -- each naming the file and the line;
        a file without poses; an unknown ``fmt``.
    """
    p = Path(path)
    protect(p)
    if fmt not in ("auto", *FORMATS):
        raise InputError(p, f"unknown trajectory format {fmt!r}; known: auto, {', '.join(FORMATS)}")
    if not p.is_file():
        raise InputError(p, "no such file")
    try:
        text = p.read_text(encoding="utf-8-sig", errors="replace")
    except OSError as e:
        raise InputError(p, f"cannot read: {e.strerror or e}") from None
    rows, linenos = _parse_lines(p, text, fmt)
    if rows.shape[1] == 8:
        traj = _from_tum(p, rows, linenos, strict=strict)
    else:
        traj = _from_kitti(p, rows, linenos)
    log.debug("read %r", traj)
    return traj


def _fmt(x: float) -> str:
    """Shortest text that reads back as exactly the same float64."""
    return repr(float(x))


def write_trajectory(
    path: str | PathLike[str], traj: Trajectory, fmt: Literal["tum", "kitti"] | str = "tum"
) -> Path:
    """Write a trajectory as TUM (default) or KITTI text.

    Every number is written with the shortest decimal text that reads back as the same
    float64, so timestamps and positions round-trip exactly and rotations to rounding
    (~1e-16; TUM stores them as quaternions, **xyzw** with ``qw >= 0``). KITTI files carry no
    timestamps (they are the frame indices when read back).

    Parameters
    ----------
    path : str or path-like
        Output text file, written atomically (whole or not at all).
    traj : Trajectory
        The poses ``T_world_frame``.
    fmt : {"tum", "kitti"}
        Output format.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    p = Path(path)
    if fmt not in FORMATS:
        raise InputError(p, f"unknown trajectory format {fmt!r}; known: {', '.join(FORMATS)}")
    if fmt == "tum":
        q = matrix_to_quat(traj.poses[:, :3, :3], order="xyzw")
        lines = ["# timestamp tx ty tz qx qy qz qw"]
        for t, xyz, quat in zip(traj.timestamps, traj.positions, q, strict=True):
            lines.append(" ".join(_fmt(v) for v in (t, *xyz, *quat)))
    else:
        lines = [" ".join(_fmt(v) for v in T[:3].ravel()) for T in traj.poses]
    text = "\n".join(lines) + "\n"
    atomic_write(p, lambda tmp: tmp.write_text(text))
    return p
