"""Clouds in project coordinates: tell them from clouds centred on their scanner, and move them.

Range images are made from where the scanner stood: a scan's points must be in the scanner's
own frame (origin at the scanner). An exported cloud often is not: a georeferenced LAS/LAZ holds
UTM-sized coordinates (eastings of 10^5-10^6 m), and an export moved into a site frame has its
scanner anywhere. Seen from the file's origin such a cloud covers a sliver of the sphere, and
the projection fails with messages about the field of view or the range. :func:`centring_problem`
says when that is the case; :func:`recentre` moves the cloud to the scanner position the user
gives (``--origin X Y Z`` on the command line), in float64, so that georeferenced coordinates
keep their precision (10^-9 m at 10^6 m).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.core.scan import Scan
from flexreg.core.transforms import make_transform
from flexreg.errors import InputError

__all__ = ["GEOREFERENCED_M", "centring_problem", "in_file_frame", "origin_hint", "recentre"]

#: a cloud whose centre lies this far from the origin has georeferenced (project) coordinates
GEOREFERENCED_M = 10_000.0


def centring_problem(scan: Scan) -> str | None:
    """Why ``scan`` looks not centred on its scanner, or None when it looks centred.

    Only scans without a grid and without a camera are judged (a grid or a camera fixes the
    projection, wherever the points are). A scan is not centred when its origin lies outside
    the points' bounding box and

    - the box's centre is more than :data:`GEOREFERENCED_M` from the origin (georeferenced
      coordinates), or
    - the origin is farther from the box than half the box's diagonal (the cloud fills less
      than about a quarter of the sphere around the origin: a scanner sees around itself).

    A single view of a distant object (a lidar looking at a far wall) also matches the second
    rule; ``--origin 0 0 0`` says that the file's origin is the scanner.

    Parameters
    ----------
    scan : Scan

    Returns
    -------
    str or None
        One clause for a message, e.g. ``"its points lie 5.4e+06 m from the file's origin
        (project coordinates)"``.
    """
    if scan.grid_shape is not None or scan.camera is not None or len(scan) == 0:
        return None
    lo, hi = scan.points.min(axis=0), scan.points.max(axis=0)
    outside = np.maximum(np.maximum(lo, -hi), 0.0)  # per axis: how far 0 lies outside [lo, hi]
    gap = float(np.linalg.norm(outside))
    if gap == 0.0:
        return None
    centre = float(np.linalg.norm((lo + hi) / 2))
    half_diagonal = float(np.linalg.norm(hi - lo)) / 2
    if centre > GEOREFERENCED_M:
        return (
            f"its points lie {centre:.3g} m from the file's origin (project or map "
            "coordinates, not the scanner's frame)"
        )
    if gap > half_diagonal:
        return (
            f"the file's origin lies {gap:.3g} m outside its points' bounding box "
            f"({2 * half_diagonal:.3g} m across), so it is not where the scanner stood"
        )
    return None


def recentre(scan: Scan, origin: ArrayLike) -> Scan:
    """The scan with its points relative to the scanner position ``origin``.

    Parameters
    ----------
    scan : Scan
    origin : (3,) float, metres
        Where the scanner stood, in the file's frame (the scanner's axes are taken parallel to
        the file's).

    Returns
    -------
    Scan
        ``points - origin`` (float64) and ``T_world_scanner = T_world_scanner @ translation
        (origin)``, so that the pose still maps the points into the file's frame.

    Raises
    ------
    InputError
        ``origin`` is not three finite numbers.
    """
    o = np.asarray(origin, dtype=np.float64).reshape(-1)
    if o.shape != (3,) or not all(math.isfinite(v) for v in o):
        raise InputError("origin", f"must be three finite numbers X Y Z, got {o.tolist()}")
    T = scan.T_world_scanner @ make_transform(np.eye(3), o)
    return replace(scan, points=scan.points - o, T_world_scanner=T)


def origin_hint(why: str, option: str) -> str:
    """The advice for a cloud that is not centred on its scanner (``why`` from
    :func:`centring_problem`), naming the ``option`` that gives the scanner position."""
    return (
        f"not centred on its scanner: {why}; give the scanner position in the file's frame "
        f"with {option} X Y Z (metres)"
    )


def in_file_frame(
    T_target_source: ArrayLike,
    target_origin: ArrayLike | None,
    source_origin: ArrayLike | None,
) -> NDArray[np.float64]:
    """A transform between clouds moved to their scanners (:func:`recentre`), expressed in the
    files' own coordinates: ``O_t @ T @ inv(O_s)``, ``O`` the translation by each origin.

    Applied to the source file's points it maps them onto the target file's; two files
    already in one project frame give the identity. The translation is summed as
    ``(o_t - o_s) + t - (R - I) o_s`` so that georeferenced origins (10^6 m) cancel before
    they are added to the correction (float64 keeps ~10^-9 m of it).

    Parameters
    ----------
    T_target_source : (4, 4) float, metres
        Maps source points relative to ``source_origin`` onto target points relative to
        ``target_origin``.
    target_origin, source_origin : (3,) float or None, metres
        The scanner positions in each file's frame; None: the file's origin.

    Returns
    -------
    (4, 4) float64

    Examples
    --------
    >>> import numpy as np
    >>> o = [455013.02, 5455000.84, 121.71]
    >>> T = np.eye(4); T[:3, 3] = [0.0, 7.0, 0.0]          # from o to o + (0, 7, 0)
    >>> in_file_frame(T, o, np.add(o, [0.0, 7.0, 0.0]))[:3, 3].tolist()
    [0.0, 0.0, 0.0]
    """
    T = np.asarray(T_target_source, dtype=np.float64)
    o_t = np.zeros(3) if target_origin is None else np.asarray(target_origin, dtype=np.float64)
    o_s = np.zeros(3) if source_origin is None else np.asarray(source_origin, dtype=np.float64)
    R, t = T[:3, :3], T[:3, 3]
    out = np.eye(4)
    out[:3, :3] = R
    out[:3, 3] = (o_t - o_s) + t - (R - np.eye(3)) @ o_s
    return out
