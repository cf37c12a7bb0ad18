"""3DTK / slam6D ``uos`` scans: ``scanNNN.3d`` (ASCII ``x y z``) with ``scanNNN.pose``.

3DTK works in centimetres in a LEFT-handed frame (x right, y up, z forward). flexreg works in
metres in a right-handed frame, so every point and pose is mapped with the usual 3DTK
convention

    X = z / 100 (forward),  Y = -x / 100 (left),  Z = y / 100 (up),

i.e. ``p_rh = S p_lh / 100`` with the axis change ``S = [[0, 0, 1], [-1, 0, 0], [0, 1, 0]]``
(det -1). A ``.pose`` file holds ``x y z`` (cm) and ``rx ry rz`` (degrees); 3DTK turns it into
``p_world = R p + t`` with ``R = Rx(rx) Ry(ry) Rz(rz)`` (``EulerToMatrix4`` in
``include/slam6d/globals.icc``), and the same map in flexreg's frame is
``T_world_scanner = [[S R S^T, S t / 100], [0, 1]]``.

A scanner-written ``.3d`` file is a sequence of 2D scan profiles (for the Kurt3D sample: 226
profiles of 360 points, a SICK line scanner pitched from -49 to +68 deg, each profile sweeping
the azimuth from +90 to -90 deg). A new profile starts where the azimuth ``atan2(x, z)`` jumps
back by more than 90 deg. The grid is oriented like flexreg's equirectangular images
(:class:`~flexreg.core.camera.SphericalCamera`): row 0 is the highest profile (rows run downwards)
and columns run with increasing azimuth ``atan2(Y, X)`` in the right-handed frame. Profiles or
points within a profile are reversed as needed; for the Kurt3D sample the profiles are stored
bottom-up, so rows are the profiles in reverse order and columns keep the file order.
No-return cells are kept in the file at the SICK maximum range (3276.7 cm) and become invalid.

A ``.pose`` file is a stored pose even when it holds the identity: 3DTK puts a sequence's first
scan at the origin of its world frame, and ``scan000.pose`` says so with six zeros. Only a scan
without a ``.pose`` file stores no pose (:func:`pose_file` tells the two apart; the scan's
``T_world_scanner`` is the identity in both cases).
"""

from __future__ import annotations

import re
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.core.scan import Scan
from flexreg.core.transforms import as_transform
from flexreg.errors import InputError

__all__ = ["pose_file", "pose_to_transform", "read", "read_pose"]

#: Left-handed 3DTK axes (x right, y up, z forward) -> right-handed (X forward, Y left, Z up).
S_RH_FROM_LH = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
CM = 0.01  # metres per 3DTK unit
_UOS_HEADER = re.compile(rb"^\s*\d+ x \d+\s*$")


def read(
    path: Path,
    *,
    pose: str | PathLike[str] | ArrayLike | bool | None = None,
    grid: tuple[int, int] | bool = True,
    max_range_m: float = 32.76,
    min_range_m: float = 0.0,
) -> list[Scan]:
    """Read a 3DTK ``.3d`` scan and its ``.pose``.

    Parameters
    ----------
    path : Path
        The ``.3d`` file: one ``x y z`` (cm) per line; blank lines, ``#`` comments and the
        optional ``W x H`` first line of the uos format are skipped.
    pose : path-like or (4, 4) array_like or bool, optional
        ``None`` / ``True``: the ``.pose`` file beside the scan with the same stem
        (:func:`pose_file`), identity if there is none. A path: that 3DTK ``.pose`` file
        (must exist). A (4, 4) array: ``T_world_scanner`` already in flexreg's frame (metres,
        right-handed). ``False``: identity, ignoring any pose file.
    grid : bool or (int, int)
        ``True``: find the scan profiles from the azimuth jumps and require them all to have the
        same length; ``(profiles, points_per_profile)``: require exactly that many lines;
        ``False``: read an unorganised cloud.
    max_range_m : float, metres
        Ranges at or beyond this are no-returns (the SICK maximum, 3276.7 cm, marks them).
    min_range_m : float, metres
        Ranges below this are dropped too. 0 keeps every return; the sample's own 3DTK
        ``config.ini`` uses 0.48 m, which removes hits on the robot's own body (~10-17 cm).

    Returns
    -------
    list of Scan
        One scan: ``points`` (N, 3) float64 metres, right-handed scanner frame; grid
        ``(profiles, points_per_profile)`` (226 x 360 for Kurt3D) unless ``grid=False``;
        ``T_world_scanner`` from the pose.

    Raises
    ------
    InputError
        A line without exactly three numbers, a line count that does not fit the grid
        (profiles of unequal length), a malformed or missing pose file, or no valid point.
    """
    xyz_lh = _read_points(path)
    n = len(xyz_lh)
    T = _resolve_pose(path, pose)
    xyz = (xyz_lh @ S_RH_FROM_LH.T) * CM
    rng = np.linalg.norm(xyz, axis=1)
    valid = (rng < max_range_m) & (rng >= min_range_m)
    if not valid.any():
        raise InputError(
            path, f"none of the {n} points has a range in [{min_range_m}, {max_range_m}) m"
        )

    if grid is False:
        return [Scan(points=xyz[valid], T_world_scanner=T, path=path, name=path.stem)]
    if grid is True:
        n_prof, n_pts = _profile_shape(path, xyz_lh)
    else:
        try:
            n_prof, n_pts = (int(v) for v in grid)
        except (TypeError, ValueError):
            raise InputError(
                path, f"grid must be True, False or (profiles, points), got {grid!r}"
            ) from None
        if n_prof <= 0 or n_pts <= 0 or n_prof * n_pts != n:
            raise InputError(
                path,
                f"{n} points do not form a {n_prof} x {n_pts} grid ({n_prof * n_pts} expected)",
            )
    cube = xyz.reshape(n_prof, n_pts, 3)
    ok = valid.reshape(n_prof, n_pts)
    flip_rows, flip_cols = _orientation(cube, ok)
    if flip_rows:
        cube, ok = cube[::-1], ok[::-1]
    if flip_cols:
        cube, ok = cube[:, ::-1], ok[:, ::-1]
    return [Scan.from_organized(cube, ok, T_world_scanner=T, path=path, name=path.stem)]


def _read_points(path: Path) -> NDArray[np.float64]:
    """All ``x y z`` rows of a ``.3d`` file, (N, 3) float64 in 3DTK units (cm, left-handed)."""
    with open(path, "rb") as f:
        lines = f.read().splitlines()
    first = 1 if lines and _UOS_HEADER.match(lines[0]) else 0
    rows: list[list[bytes]] = []
    numbers: list[int] = []
    for k in range(first, len(lines)):
        tok = lines[k].split(b"#", 1)[0].split()
        if not tok:
            continue
        if len(tok) != 3:
            raise InputError(path, f"line {k + 1}: expected 'x y z', got {len(tok)} value(s)")
        rows.append(tok)
        numbers.append(k + 1)
    if not rows:
        raise InputError(path, "no points (no 'x y z' lines)")
    try:
        xyz = np.array(rows, dtype=np.bytes_).astype(np.float64)
    except ValueError:
        for k, tok in zip(numbers, rows, strict=True):
            try:
                [float(v) for v in tok]
            except ValueError:
                text = b" ".join(tok).decode("latin-1")[:60]
                raise InputError(path, f"line {k}: not three numbers: {text!r}") from None
        raise InputError(path, "non-numeric values") from None
    bad = ~np.isfinite(xyz).all(axis=1)
    if bad.any():
        k = numbers[int(np.argmax(bad))]
        raise InputError(path, f"{int(bad.sum())} point(s) are NaN or Inf (first: line {k})")
    return xyz


def _profile_shape(path: Path, xyz_lh: NDArray[np.float64]) -> tuple[int, int]:
    """``(profiles, points_per_profile)`` from the azimuth jumps between scan profiles."""
    az = np.degrees(np.arctan2(xyz_lh[:, 0], xyz_lh[:, 2]))
    starts = np.r_[0, np.nonzero(np.abs(np.diff(az)) > 90.0)[0] + 1]
    lengths = np.diff(np.r_[starts, len(az)])
    if np.all(lengths == lengths[0]):
        return len(lengths), int(lengths[0])
    common = int(np.bincount(lengths).argmax())
    odd = np.nonzero(lengths != common)[0]
    k = int(odd[0])
    raise InputError(
        path,
        f"scan profiles have unequal lengths: profile {k} (from line {int(starts[k]) + 1}) has "
        f"{int(lengths[k])} points, {int(np.sum(lengths == common))} of {len(lengths)} profiles "
        f"have {common} (lines missing or extra? pass grid=False for an unorganised cloud)",
    )


def _orientation(cube: NDArray[np.float64], ok: NDArray[np.bool_]) -> tuple[bool, bool]:
    """Whether to reverse profiles (so row 0 is the highest) and points (so azimuth increases)."""
    x, y, z = cube[..., 0], cube[..., 1], cube[..., 2]
    elev = np.arctan2(z, np.hypot(x, y))
    rows = np.nonzero(ok.any(axis=1))[0]
    flip_rows = False
    if len(rows) >= 2:
        first, last = (float(np.median(elev[r][ok[r]])) for r in (rows[0], rows[-1]))
        flip_rows = last > first
    phi = np.arctan2(y, x)
    dphi = (np.diff(phi, axis=1) + np.pi) % (2.0 * np.pi) - np.pi  # wrapped to [-pi, pi)
    both = ok[:, 1:] & ok[:, :-1]
    flip_cols = bool(np.median(dphi[both]) < 0) if both.any() else False
    return flip_rows, flip_cols


def pose_file(path: str | PathLike[str]) -> Path | None:
    """The ``.pose`` file :func:`read` takes for the scan ``path`` by default (beside it, the
    same stem), or None when there is none: the scan stores no pose.

    A pose file holding the identity (six zeros, as 3DTK writes for a sequence's first scan)
    is a stored pose all the same.
    """
    candidate = Path(path).with_suffix(".pose")
    return candidate if candidate.is_file() else None


def _resolve_pose(path: Path, pose: Any) -> NDArray[np.float64]:
    if pose is None or pose is True:
        pose_path = pose_file(path)
        return np.eye(4) if pose_path is None else read_pose(pose_path)
    if pose is False:
        return np.eye(4)
    if isinstance(pose, (str, PathLike)):
        return read_pose(Path(pose))
    return as_transform(pose, name=f"{path} pose")


def read_pose(path: str | PathLike[str]) -> NDArray[np.float64]:
    """Read a 3DTK ``.pose`` file into ``T_world_scanner`` in flexreg's frame.

    Parameters
    ----------
    path : path-like
        Six numbers: ``x y z`` in centimetres, then ``rx ry rz`` in degrees.

    Returns
    -------
    (4, 4) float64
        Maps right-handed, metric scanner-frame points into the world frame.

    Raises
    ------
    InputError
        Missing file, or not exactly six finite numbers.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(p, "no such pose file")
    try:
        values = [float(v) for v in p.read_text(encoding="latin-1").split()]
    except ValueError:
        raise InputError(p, "a 3DTK pose holds six numbers: x y z (cm) rx ry rz (deg)") from None
    if len(values) != 6 or not np.all(np.isfinite(values)):
        raise InputError(
            p, f"a 3DTK pose holds six finite numbers x y z (cm) rx ry rz (deg), got {len(values)}"
        )
    return pose_to_transform(values[:3], values[3:])


def pose_to_transform(position_cm: ArrayLike, angles_deg: ArrayLike) -> NDArray[np.float64]:
    """3DTK pose (left-handed, cm, Euler degrees) -> ``T_world_scanner`` (right-handed, m).

    ``R_lh = Rx(rx) Ry(ry) Rz(rz)`` as 3DTK's ``EulerToMatrix4`` builds it, then conjugated by
    the axis change: ``R = S R_lh S^T``, ``t = S t_lh / 100``.

    Parameters
    ----------
    position_cm : (3,) array_like, centimetres
    angles_deg : (3,) array_like, degrees

    Returns
    -------
    (4, 4) float64

    Examples
    --------
    >>> T = pose_to_transform([0.0, 0.0, 100.0], [0.0, 0.0, 0.0])  # 1 m along 3DTK's z
    >>> T[:3, 3].tolist()                                            # = forward, X
    [1.0, 0.0, 0.0]
    """
    rx, ry, rz = np.radians(np.asarray(angles_deg, dtype=np.float64))
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    R_x = np.array([[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]])
    R_y = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    R_z = np.array([[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]])
    R_lh = R_x @ R_y @ R_z
    T = np.eye(4)
    T[:3, :3] = S_RH_FROM_LH @ R_lh @ S_RH_FROM_LH.T
    T[:3, 3] = S_RH_FROM_LH @ np.asarray(position_cm, dtype=np.float64) * CM
    return T
