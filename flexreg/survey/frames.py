"""The frame a survey's poses come out in, and the stations' scanner origins.

The graph solves every station in the frame of one station, the *reference* (``--reference``,
else the first by name of the largest group: the same in every run of a project). A surveyor
wants the project's own frame back:

* ``reference`` (default): poses ``T_reference_station``, the reference at the identity;
* ``stored`` (``--frame stored``): the site frame the files store their setups in (E57 poses,
  PTX headers). The site frame is tied to the reference frame through the placed stations whose
  stored poses agree with the registration (:func:`flexreg.survey.stored.check_stations`):
  ``T_site_reference`` is the mean of their ``T_site_k @ inv(T_reference_k)`` (chordal mean
  of the rotations, then the translations), so no one station's stored pose sets it alone;
* ``origins`` (given ``--origins FILE.csv``): stations whose points are in project coordinates
  (georeferenced LAS/LAZ, a cloud exported in a site frame) are registered about their
  scanner positions (``stem,x,y,z`` in the file's frame, metres), and the poses come out in
  the files' coordinates: ``T_site_reference`` is the shift to the reference's origin, and a
  station's correction in its own file's coordinates is
  ``T_site_file = T_site_station @ shift(-origin)`` (the identity for files already
  co-registered).

Every pose is float64; site coordinates of hundreds of kilometres keep their millimetres.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from flexreg.core.transforms import make_transform, nearest_rotation
from flexreg.errors import InputError

Matrix = NDArray[np.float64]
Frame = Literal["reference", "stored"]


def shift(origin: Any) -> Matrix:
    """The 4 x 4 translation by ``origin`` (metres)."""
    return make_transform(np.eye(3), origin)


def read_origins_csv(path: Path, stems: list[str]) -> dict[str, tuple[float, float, float]]:
    """Scanner origins from a CSV of ``stem,x,y,z`` (metres, in the file's own frame; a
    header row ``stem,x,y,z`` is allowed; a file name is taken as its stem).

    Raises
    ------
    InputError
        Unreadable file, a row without four fields, a number that is not finite, an unknown
        station, a station given twice, or no row at all.
    """
    known = set(stems)
    try:
        with path.open(newline="") as f:
            rows = [r for r in csv.reader(f) if r and any(x.strip() for x in r)]
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(path, f"cannot read: {getattr(e, 'strerror', None) or e}") from None
    if rows and [x.strip().lower() for x in rows[0][:4]] == ["stem", "x", "y", "z"]:
        rows = rows[1:]
    out: dict[str, tuple[float, float, float]] = {}
    for n, row in enumerate(rows, 1):
        if len(row) < 4:
            raise InputError(path, f"row {n}: expected stem,x,y,z")
        name = row[0].strip()
        stem = name if name in known else Path(name).stem
        if stem not in known:
            raise InputError(path, f"row {n}: {name!r} is not one of the stations")
        if stem in out:
            raise InputError(path, f"row {n}: {stem!r} is given twice")
        try:
            xyz = tuple(float(v) for v in row[1:4])
        except ValueError:
            raise InputError(path, f"row {n}: x, y and z must be numbers (metres)") from None
        if not all(math.isfinite(v) for v in xyz):
            raise InputError(path, f"row {n}: x, y and z must be finite")
        out[stem] = (xyz[0], xyz[1], xyz[2])
    if not out:
        raise InputError(path, "no origins in the file")
    return out


def site_of_reference(
    frame: Frame,
    reference: str,
    poses: dict[str, Matrix],
    stored: dict[str, Matrix],
    checks: dict[str, dict[str, Any]],
    origins: dict[str, tuple[float, float, float]],
) -> tuple[Matrix, str]:
    """``T_site_reference`` and what the site frame is, in words.

    Parameters
    ----------
    frame : {"reference", "stored"}
    reference : str
    poses : dict
        ``T_reference_station`` of the placed stations.
    stored : dict
        ``T_world_station`` the files store.
    checks : dict
        :func:`~flexreg.survey.stored.check_stations` of the placed stations.
    origins : dict
        Scanner origins per station (``--origins``).

    Raises
    ------
    InputError
        ``stored`` asked for but no placed station stores a pose.
    """
    if frame == "stored":
        agree = sorted(s for s, c in checks.items() if c["agrees"])
        tie = agree or sorted(s for s in poses if s in stored)[:1]
        if not tie:
            raise InputError(
                "--frame stored", "no placed station stores a pose in its file (E57 or PTX)"
            )
        return _mean_tie(poses, stored, tie), (
            "the site frame the files store their poses in (tied through "
            + (f"the {len(tie)} stations whose stored poses agree)" if agree else f"{tie[0]})")
        )
    if origins.get(reference) is not None:
        return shift(origins[reference]), "the files' own coordinates (--origins)"
    return np.eye(4), f"the frame of station {reference}"


def _mean_tie(poses: dict[str, Matrix], stored: dict[str, Matrix], tie: list[str]) -> Matrix:
    """``T_site_reference`` that best maps the registered poses of ``tie`` onto their stored
    ones: the chordal mean of the rotations ``R_site_k @ R_reference_k^T`` (SVD of their sum)
    and the mean translation that rotation leaves."""
    # the stations agree (within degrees), so the sum of their rotations is near a rotation
    R = nearest_rotation(np.sum([stored[k][:3, :3] @ poses[k][:3, :3].T for k in tie], axis=0))
    t = np.mean([stored[k][:3, 3] - R @ poses[k][:3, 3] for k in tie], axis=0)
    return make_transform(R, t)


def file_correction(T_site_station: Matrix, origin: Any) -> Matrix:
    """``T_site_file``: a station's correction in its file's coordinates (its points moved
    into the site frame), given its scanner ``origin`` in the file (None: the scanner frame is
    the file's)."""
    if origin is None:
        return np.asarray(T_site_station, dtype=np.float64)
    return np.asarray(T_site_station, dtype=np.float64) @ shift(-np.asarray(origin, np.float64))


__all__ = ["Frame", "file_correction", "read_origins_csv", "shift", "site_of_reference"]
