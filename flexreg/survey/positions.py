"""Rough station positions from the field: a sketch, a GNSS fix, a total station's setup.

A CSV file with the header ``stem,x,y,z,heading_deg,sigma_m`` gives, per station, where the
scanner stood in the site's frame (metres), which way its x axis pointed (degrees from the
site's x axis, counter-clockwise about the site's z; levelled scanners) and how far off the
position may be (1-sigma, metres). ``z``, ``heading_deg`` and ``sigma_m`` may be empty or
absent. The survey uses them as priors that decide between a link's answer and its
alternatives (:func:`choose`): the pose the positions predict for a link, within their
uncertainty, picks the one hypothesis that fits it.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from flexreg.core.transforms import invert
from flexreg.errors import InputError
from flexreg.survey.links import Link

Matrix = NDArray[np.float64]

#: 1-sigma of a position whose ``sigma_m`` is empty, metres (a pace-and-sketch position).
DEFAULT_SIGMA_M = 1.0
#: How far, in standard deviations of what the positions predict, a link's translation may
#: be from it and still agree with them.
AGREE_SIGMAS = 3.0
#: Beyond this many standard deviations from what the positions predict, every pose of a
#: link is refused. Between it and :data:`AGREE_SIGMAS` the positions neither vouch nor
#: refuse: a rough heading turns the predicted offset (10 degrees move a station 20 m away by
#: 3.5 m), so they are not trusted to refuse what lies only a little beyond.
REFUSE_SIGMAS = 6.0
#: How far a link's turn about the vertical may be from the headings' difference and still
#: agree, degrees: two rough headings are off by up to about 20 degrees together, while
#: look-alike poses differ by a quarter or half turn (rooms, halls) or by a bay at the same
#: heading (then the translation tells).
AGREE_HEADING_DEG = 30.0
#: Columns of the file, in order (the first two required).
COLUMNS = ("stem", "x", "y", "z", "heading_deg", "sigma_m")


@dataclass(frozen=True)
class Position:
    """Where a station's scanner stood in the site's frame, roughly.

    Attributes
    ----------
    xyz : (3,) float64, metres
        ``z`` 0 when the file leaves it empty (then only the horizontal position counts).
    has_z : bool
    heading_rad : float or None, radians
        The scanner's x axis from the site's x axis, about the site's z; None: unknown.
    sigma_m : float, metres
        1-sigma of the position.
    """

    xyz: Matrix
    has_z: bool
    heading_rad: float | None
    sigma_m: float


def _number(path: Path, n: int, name: str, text: str) -> float | None:
    text = text.strip()
    if not text:
        return None
    try:
        v = float(text)
    except ValueError:
        raise InputError(path, f"row {n}: {name} is not a number ({text!r})") from None
    if not math.isfinite(v):
        raise InputError(path, f"row {n}: {name} is not a finite number ({text!r})")
    return v


def read_positions_csv(path: Path, stems: list[str]) -> dict[str, Position]:
    """The positions of a CSV file (see the module); a row per station, for some or all.

    Raises
    ------
    InputError
        Unreadable file, a missing or unknown header, an unknown or repeated station, a
        row without x and y, a value that is not a finite number, a sigma that is not
        positive, or no row at all.
    """
    try:
        with path.open(newline="") as f:
            rows = [r for r in csv.reader(f) if r and any(x.strip() for x in r)]
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(path, f"cannot read: {getattr(e, 'strerror', None) or e}") from None
    header = [x.strip().lower() for x in rows[0]] if rows else []
    if header[:3] != list(COLUMNS[:3]) or any(h not in COLUMNS for h in header):
        raise InputError(
            path, f"expected the header {','.join(COLUMNS)} (z, heading_deg, sigma_m optional)"
        )
    known, out = set(stems), {}
    for n, row in enumerate(rows[1:], 2):
        values = dict(zip(header, [*row, *[""] * len(header)], strict=False))
        stem = Path(values["stem"].strip()).stem
        if stem not in known:
            raise InputError(path, f"row {n}: {stem!r} is not one of the stations")
        if stem in out:
            raise InputError(path, f"row {n}: {stem} is given twice")
        num = {k: _number(path, n, k, values.get(k, "")) for k in COLUMNS[1:]}
        x, y, z = num["x"], num["y"], num["z"]
        if x is None or y is None:
            raise InputError(path, f"row {n}: x and y are needed")
        sigma = num["sigma_m"] if num["sigma_m"] is not None else DEFAULT_SIGMA_M
        if sigma <= 0:
            raise InputError(path, f"row {n}: sigma_m must be positive (got {sigma:g})")
        heading = num["heading_deg"]
        out[stem] = Position(
            np.array([x, y, z or 0.0]),
            z is not None,
            None if heading is None else math.radians(heading),
            sigma,
        )
    if not out:
        raise InputError(path, "no station in the file")
    return out


def _yaw(T: Matrix) -> float:
    """The turn about the vertical of a levelled pose, radians."""
    return math.atan2(float(T[1, 0]), float(T[0, 0]))


def _wrap_deg(a: float) -> float:
    return abs((math.degrees(a) + 180.0) % 360.0 - 180.0)


def sigmas_off(T: Matrix, target: Position, source: Position) -> float:
    """How far a link's ``T_target_source`` is from what two stations' rough positions
    predict, in standard deviations of both positions: the source's position in the target's
    frame (rotated by the target's heading; without one only the distance between them
    counts); infinite when both headings are known and the link turns more than
    :data:`AGREE_HEADING_DEG` from their difference. A heading's own error is not in the
    sigma: a pose vouched for is one near what the positions predict as they stand.

    >>> a = Position(np.zeros(3), False, 0.0, 1.0)
    >>> b = Position(np.array([6.0, 0.0, 0.0]), False, 0.0, 1.0)
    >>> T = np.eye(4); T[0, 3] = 6.3
    >>> round(sigmas_off(T, a, b), 2)
    0.21
    >>> T[0, 3] = 12.2  # a bay further
    >>> round(sigmas_off(T, a, b), 2)
    4.38
    """
    d = source.xyz - target.xyz
    t = np.asarray(T[:3, 3], dtype=np.float64)
    if target.heading_rad is None:
        off = abs(float(np.linalg.norm(t[:2])) - float(np.linalg.norm(d[:2])))
    else:
        c, s = math.cos(target.heading_rad), math.sin(target.heading_rad)
        local = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1]])
        off = float(np.linalg.norm(t[:2] - local))
    if target.has_z and source.has_z:
        off = math.hypot(off, float(t[2] - d[2]))
    sigma = math.hypot(target.sigma_m, source.sigma_m)
    if target.heading_rad is not None and source.heading_rad is not None:
        turn = _wrap_deg(_yaw(T) - (source.heading_rad - target.heading_rad))
        if turn > AGREE_HEADING_DEG:
            return math.inf
    return off / sigma


def choose(poses: list[Matrix], target: Position, source: Position) -> tuple[int | None, str]:
    """Which of a link's poses (its answer, then its alternatives) the positions pick: the
    one within :data:`AGREE_SIGMAS` when it is the only one; None with the reason otherwise
    (the reason starts "the positions refuse" when every pose lies beyond
    :data:`REFUSE_SIGMAS`).

    >>> a = Position(np.zeros(3), False, 0.0, 1.0)
    >>> b = Position(np.array([6.0, 0.0, 0.0]), False, 0.0, 1.0)
    >>> poses = [np.eye(4), np.eye(4), np.eye(4)]
    >>> poses[0][0, 3], poses[1][0, 3], poses[2][0, 3] = 12.2, 6.3, 0.4
    >>> choose(poses, a, b)
    (1, '')
    """
    off = [sigmas_off(T, target, source) for T in poses]
    near = [i for i, x in enumerate(off) if x <= AGREE_SIGMAS]
    if len(near) == 1:
        return near[0], ""
    if not near:
        best = min(off)
        what = "turns" if math.isinf(best) else f"lies {best:.1f} sigma"
        if best > REFUSE_SIGMAS:
            return None, f"the positions refuse every pose of the link (the nearest {what} off)"
        return None, f"no pose of the link is near the positions (the nearest {what} off)"
    return None, f"{len(near)} poses of the link agree with the positions: they cannot tell"


def apply_positions(links: list[Link], positions: Mapping[str, Position]) -> int:
    """Let rough positions decide each link between two stations that have one (in place),
    among the poses the registration found fitting what both scans see (a confident answer,
    or an answer uncertain only because it is ambiguous or the scans share little, or for
    open space only the even sample finds where full resolution clears it, with its
    alternatives, :attr:`~flexreg.survey.links.Link.fits_where_seen`; a link whose answer
    contradicts its scans, in open space or along a weak axis, has none): the one
    pose of the link (its answer or an alternative, :class:`~flexreg.survey.links.
    Alternative`) they pick (:func:`choose`) becomes its transform and the link is vouched
    for (``vouched="positions"``, the answer kept as an alternative when replaced); a link
    all of whose poses lie beyond :data:`REFUSE_SIGMAS` is rejected, with the reason.
    Returns how many links the positions vouched for."""
    vouched = 0
    for e in links:
        if e.T_target_source is None or e.status == "failed" or e.vouched == "hand":
            continue
        if e.target not in positions or e.source not in positions:
            continue
        if not e.fits_where_seen:  # its answer contradicts its scans (open space, an axis)
            e.undecided = "no pose of the link fits the scans, seeded by them or not"
            continue
        i, why = choose(e.poses, positions[e.target], positions[e.source])
        e.undecided = "" if i is not None else why
        if i is None:
            if why.startswith("the positions refuse"):
                e.status, e.why, e.refused = "rejected", why, why
            continue
        if i > 0:
            e.take(e.alternatives[i - 1], "the rough positions")
        e.vouched = "positions"
        vouched += 1
    return vouched


def unsettled(links: list[Link], positions: Mapping[str, Position]) -> list[Link]:
    """The links between two stations with positions that a registration seeded by them
    (and bounded by their window, :func:`window_of`) may settle: every one that is not
    confident with its answer near what they predict (within :data:`AGREE_SIGMAS`) -- failed,
    uncertain, or placing the source elsewhere. Hand links, and links already registered
    so, are left alone."""
    out = []
    for e in links:
        if e.target not in positions or e.source not in positions or e.vouched == "hand":
            continue
        if e.windowed:
            continue
        if (
            e.T_target_source is not None
            and e.status != "failed"
            and e.verdict == "confident"
            and sigmas_off(e.T_target_source, positions[e.target], positions[e.source])
            <= AGREE_SIGMAS
        ):
            continue
        out.append(e)
    return out


def site_from_positions(
    poses: Mapping[str, Matrix], positions: Mapping[str, Position]
) -> Matrix | None:
    """``T_site_reference`` that best puts the placed stations (``T_reference_station``) on
    their rough positions: a turn about the vertical and a shift, weighted by 1 / sigma^2
    (None when no placed station has a position, or only one and without a heading)."""
    common = [s for s in poses if s in positions]
    if not common:
        return None
    if len(common) == 1:
        p = positions[common[0]]
        if p.heading_rad is None:
            return None
        return T_site_station(p) @ invert(np.asarray(poses[common[0]], dtype=np.float64))
    w = np.array([1.0 / positions[s].sigma_m ** 2 for s in common])
    a = np.array([np.asarray(poses[s])[:2, 3] for s in common])
    b = np.array([positions[s].xyz[:2] for s in common])
    ca, cb = (w @ a) / w.sum(), (w @ b) / w.sum()
    H = ((a - ca) * w[:, None]).T @ (b - cb)
    yaw = math.atan2(H[0, 1] - H[1, 0], H[0, 0] + H[1, 1])
    R = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
    T = np.eye(4)
    T[:2, :2] = R
    T[:2, 3] = cb - R @ ca
    zs = [
        positions[s].xyz[2] - float(np.asarray(poses[s])[2, 3])
        for s in common
        if positions[s].has_z
    ]
    T[2, 3] = float(np.mean(zs)) if zs else 0.0
    return T


def stored_positions(stored: Mapping[str, Matrix], sigma_m: float | None) -> dict[str, Position]:
    """The poses the files store (``T_world_station``) as rough positions of sigma
    ``sigma_m`` (none when it is None: the stored poses are then not rough priors)."""
    if sigma_m is None:
        return {}
    return {
        s: Position(
            np.asarray(T, dtype=np.float64)[:3, 3].copy(), True, _yaw(np.asarray(T)), sigma_m
        )
        for s, T in stored.items()
    }


def predicted_T_target_source(target: Position, source: Position) -> Matrix:
    """The relative pose two stations' rough positions predict (levelled; no heading taken as
    0 and no height as the target's): what a link between them is seeded with."""
    return invert(T_site_station(target)) @ T_site_station(source)


def window_of(target: Position, source: Position) -> tuple[float, float] | None:
    """How far the true ``T_target_source`` may be from what two rough positions predict
    (:func:`predicted_T_target_source`): :data:`AGREE_SIGMAS` of both positions' sigma
    (metres) and :data:`AGREE_HEADING_DEG` (radians), the bounds within which they agree
    with a link (:func:`sigmas_off`). None when a heading is unknown: the predicted offset's
    direction is then unknown too, and the link is only seeded.

    >>> a = Position(np.zeros(3), False, 0.0, 1.0)
    >>> shift, turn = window_of(a, a)
    >>> round(shift, 3), round(math.degrees(turn), 1)
    (4.243, 30.0)
    """
    if target.heading_rad is None or source.heading_rad is None:
        return None
    return AGREE_SIGMAS * math.hypot(target.sigma_m, source.sigma_m), math.radians(
        AGREE_HEADING_DEG
    )


def near_pairs(
    stems: list[str], positions: Mapping[str, Position], reach_m: float
) -> list[tuple[str, str]]:
    """Pairs of stations whose rough positions are within ``reach_m`` of each other, nearest
    first (in the order of ``stems`` within a pair): the pairs a surveyor would link from a
    sketch, whatever the place recognition ranks."""
    order = {s: i for i, s in enumerate(stems)}
    have = [s for s in stems if s in positions]
    near = []
    for i, a in enumerate(have):
        for b in have[i + 1 :]:
            d = float(np.linalg.norm(positions[a].xyz[:2] - positions[b].xyz[:2]))
            if d <= reach_m:
                near.append((d, order[a], order[b], a, b))
    near.sort()
    return [(a, b) for *_, a, b in near]


def T_site_station(p: Position) -> Matrix:
    """The rough pose of a station in the site frame (levelled; heading 0 when unknown)."""
    T = np.eye(4)
    a = p.heading_rad or 0.0
    T[:2, :2] = [[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]
    T[:3, 3] = p.xyz
    return T


__all__ = [
    "AGREE_HEADING_DEG",
    "AGREE_SIGMAS",
    "COLUMNS",
    "DEFAULT_SIGMA_M",
    "REFUSE_SIGMAS",
    "Position",
    "T_site_station",
    "apply_positions",
    "choose",
    "near_pairs",
    "predicted_T_target_source",
    "read_positions_csv",
    "sigmas_off",
    "site_from_positions",
    "stored_positions",
    "unsettled",
    "window_of",
]
