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
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from flexreg.core.transforms import invert
from flexreg.errors import InputError
from flexreg.survey.links import GraphSolution, Link

Matrix = NDArray[np.float64]

#: 1-sigma of a position whose ``sigma_m`` is empty, metres (a pace-and-sketch position).
DEFAULT_SIGMA_M = 1.0
#: How far, in standard deviations of what the positions predict, a link's translation may
#: be from it and still agree with them; a pose further off is refused (:func:`sigmas_off`
#: counts the position's and the heading's error: 10 degrees move a station 20 m away by
#: 3.5 m).
AGREE_SIGMAS = 3.0
#: How far a link's turn about the vertical may be from the headings' difference and still
#: agree, degrees: two rough headings are off by up to about 20 degrees together, while
#: look-alike poses differ by a quarter or half turn (rooms, halls) or by a bay at the same
#: heading (then the translation tells).
AGREE_HEADING_DEG = 30.0
#: 1-sigma of a rough heading, degrees (a compass, a sketch's arrow): a third of
#: :data:`AGREE_HEADING_DEG`. Its error turns the offset it predicts to a station ``d`` away
#: by ``d`` times it, a share of the sigma :func:`sigmas_off` measures in.
HEADING_SIGMA_DEG = AGREE_HEADING_DEG / AGREE_SIGMAS
#: Most times the positions decide the links again with what a solution's groups carry.
DECIDE_ROUNDS = 3
#: Who picked a link's alternative (:meth:`~flexreg.survey.links.Link.take`).
PICKED_BY = "the rough positions"
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
    heading_sigma_rad : float, radians
        1-sigma of the heading: :data:`HEADING_SIGMA_DEG` as given, less once the solved
        poses of a group of stations carry it (:func:`sited_by_groups`).
    """

    xyz: Matrix
    has_z: bool
    heading_rad: float | None
    sigma_m: float
    heading_sigma_rad: float = math.radians(HEADING_SIGMA_DEG)


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
    predict, in standard deviations: the source's position in the target's frame (rotated
    by the target's heading; without one only the distance between them counts), against
    both positions' sigma and what the heading's sigma turns the offset by (both ways when
    both stations have a heading: the one whose heading is known better measures);
    infinite when both headings are known and the link turns more than
    :data:`AGREE_HEADING_DEG` from their difference.

    >>> a = Position(np.zeros(3), False, 0.0, 1.0, 0.0)
    >>> b = Position(np.array([6.0, 0.0, 0.0]), False, 0.0, 1.0, 0.0)
    >>> T = np.eye(4); T[0, 3] = 6.3
    >>> round(sigmas_off(T, a, b), 2)
    0.21
    >>> T[0, 3] = 12.2  # a bay further
    >>> round(sigmas_off(T, a, b), 2)
    4.38
    >>> T[0, 3], T[1, 3] = 6.0, 1.5  # a heading off by 10 degrees turns it by a metre
    >>> ten = math.radians(10.0)
    >>> a, b = replace(a, heading_sigma_rad=ten), replace(b, heading_sigma_rad=ten)
    >>> round(sigmas_off(T, a, b), 2)
    0.85
    """
    if target.heading_rad is not None and source.heading_rad is not None:
        turn = _wrap_deg(_yaw(T) - (source.heading_rad - target.heading_rad))
        if turn > AGREE_HEADING_DEG:
            return math.inf
        if source.heading_sigma_rad < target.heading_sigma_rad:
            return _off(invert(np.asarray(T, dtype=np.float64)), source, target)
    return _off(T, target, source)


def _off(T: Matrix, target: Position, source: Position) -> float:
    """:func:`sigmas_off` measured in the target's frame."""
    d = source.xyz - target.xyz
    t = np.asarray(T[:3, 3], dtype=np.float64)
    sigma = math.hypot(target.sigma_m, source.sigma_m)
    if target.heading_rad is None:
        off = abs(float(np.linalg.norm(t[:2])) - float(np.linalg.norm(d[:2])))
    else:
        c, s = math.cos(target.heading_rad), math.sin(target.heading_rad)
        local = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1]])
        off = float(np.linalg.norm(t[:2] - local))
        sigma = math.hypot(sigma, float(np.linalg.norm(d[:2])) * target.heading_sigma_rad)
    if target.has_z and source.has_z:
        off = math.hypot(off, float(t[2] - d[2]))
    return off / sigma


def choose(poses: list[Matrix], target: Position, source: Position) -> tuple[int | None, str]:
    """Which of a link's poses (its answer, then its alternatives) the positions pick: the
    one within :data:`AGREE_SIGMAS` when it is the only one; None with the reason otherwise
    (the reason starts "the positions refuse" when none is).

    >>> a = Position(np.zeros(3), False, 0.0, 1.0)
    >>> b = Position(np.array([6.0, 0.0, 0.0]), False, 0.0, 1.0)
    >>> poses = [np.eye(4), np.eye(4), np.eye(4)]
    >>> poses[0][0, 3], poses[1][0, 3], poses[2][0, 3] = 12.2, 6.3, 0.4
    >>> choose(poses, a, b)
    (1, '')
    """
    return _pick(*_near(poses, target, source))


def _near(poses: list[Matrix], target: Position, source: Position) -> tuple[list[int], list[float]]:
    """Which of ``poses`` lie within :data:`AGREE_SIGMAS` (indices), and each one's
    :func:`sigmas_off`."""
    off = [sigmas_off(T, target, source) for T in poses]
    return [i for i, x in enumerate(off) if x <= AGREE_SIGMAS], off


def _pick(near: list[int], off: list[float]) -> tuple[int | None, str]:
    """:func:`choose` from :func:`_near`'s answer."""
    if len(near) == 1:
        return near[0], ""
    if not near:
        best = min(off)
        what = "turns" if math.isinf(best) else f"lies {best:.1f} sigma"
        return None, f"the positions refuse every pose of the link (the nearest {what} off)"
    return None, f"{len(near)} poses of the link agree with the positions: they cannot tell"


def apply_positions(links: list[Link], positions: Mapping[str, Position]) -> int:
    """Let rough positions decide each link between two stations that have one (in place).
    A pose of the link (its answer or an alternative, :class:`~flexreg.survey.links.
    Alternative`) further than :data:`AGREE_SIGMAS` from what they predict
    (:func:`sigmas_off`, which counts the headings' error too) is no hypothesis of it: a
    link none of whose poses is within is rejected, with the reason, and of one with
    several within only those are kept. Among the poses the registration found fitting
    what both scans see (a confident answer, or an answer uncertain only because it is
    ambiguous or the scans share little, or for open space only the even sample finds
    where full resolution clears it, with its alternatives,
    :attr:`~flexreg.survey.links.Link.fits_where_seen`; a link whose answer contradicts its
    scans, in open space or along a weak axis, has none), the one pose they pick
    (:func:`choose`) becomes its transform and the link is vouched for
    (``vouched="positions"``, the answer kept as an alternative when replaced). What an
    earlier call decided is undone first. Returns how many links the positions vouched
    for."""
    vouched = 0
    for e in links:
        if e.T_target_source is None or e.status == "failed" or e.vouched == "hand":
            continue
        _undo(e)
        if e.target not in positions or e.source not in positions:
            continue
        near, off = _near(e.poses, positions[e.target], positions[e.source])
        i, why = _pick(near, off)
        e.undecided = why
        if not near:
            e.status, e.why, e.refused = "rejected", why, why
            continue
        if i is None:  # several agree: the others are no hypotheses of the link
            _keep_near(e, near)
        if not e.fits_where_seen:  # its answer contradicts its scans (open space, an axis)
            e.undecided = "no pose of the link fits the scans, seeded by them or not"
            continue
        if i is None:
            continue
        if i > 0:
            e.take(e.alternatives[i - 1], PICKED_BY)
        e.vouched = "positions"
        vouched += 1
    return vouched


def _keep_near(e: Link, near: list[int]) -> None:
    """Of link ``e``'s poses, those of indices ``near`` (:func:`_near`, at least one) stay
    its hypotheses, the first its transform."""
    keep = [e.alternatives[k - 1] for k in near if k > 0]
    if near[0] > 0:
        e.take(keep[0], PICKED_BY)
        keep = keep[1:]
    e.keep_only(keep)


def _undo(e: Link) -> None:
    """What an earlier :func:`apply_positions` decided of link ``e`` undone: positions that
    a group's poses have since carried decide again."""
    if e.picked.startswith(PICKED_BY) or (e.registered is not None and not e.picked):
        e.untake()  # what the positions picked or left out (a loop's pick stands)
    if e.vouched == "positions":
        e.vouched = ""
    e.refused = ""


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


@dataclass(frozen=True)
class _GroupFit:
    """A group's poses fitted to its stations' positions (:func:`site_from_positions`).

    ``T``: ``T_site_group``; ``centre``: the stations' weighted centre in the group's frame;
    ``var_centre`` (m^2) and ``var_turn`` (rad^2): the fit's variances, ``1 / sum(1 /
    sigma^2)`` and ``1 / sum(r^2 / sigma^2)`` (``r``: each station's distance from the
    centre)."""

    T: Matrix
    centre: Matrix
    var_centre: float
    var_turn: float

    def sigma_at(self, xy: Matrix) -> float:
        """1-sigma of where the fit puts a point of the group's frame, metres."""
        r2 = float(np.sum((np.asarray(xy)[:2] - self.centre) ** 2))
        return math.sqrt(self.var_centre + r2 * self.var_turn)


def _group_fit(poses: Mapping[str, Matrix], positions: Mapping[str, Position]) -> _GroupFit | None:
    """The fit of a group's poses (``T_group_station``) to its stations' positions; None
    with fewer than two positions, or when the fit leaves a station further than
    :data:`AGREE_SIGMAS` of its sigma from its position (a wrong position, or stations
    misplaced)."""
    common = [s for s in poses if s in positions]
    if len(common) < 2:
        return None
    fit = site_from_positions({s: poses[s] for s in common}, positions)
    assert fit is not None
    for s in common:
        off = np.linalg.norm((fit @ poses[s])[:2, 3] - positions[s].xyz[:2])
        if off > AGREE_SIGMAS * positions[s].sigma_m:
            return None
    w = np.array([1.0 / positions[s].sigma_m ** 2 for s in common])
    a = np.array([np.asarray(poses[s])[:2, 3] for s in common])
    centre = (w @ a) / w.sum()
    r2 = np.sum((a - centre) ** 2, axis=1)
    return _GroupFit(fit, centre, 1.0 / float(w.sum()), 1.0 / max(float(w @ r2), 1e-12))


def refutes(
    positions: Mapping[str, Position],
    first: Mapping[str, Matrix],
    second: Mapping[str, Matrix],
) -> bool:
    """Whether the positions refute placing two groups of stations so (``T_g_station``,
    both in the first group's frame): the fit of either group to its positions
    (:func:`_group_fit`) puts a station of the other further than :data:`AGREE_SIGMAS`
    from its position, in the sigma of both (the station's own, and the fit's where it
    puts it). Two groups placed a bay apart in a hall of look-alike bays move every station
    of one a bay from where its position says; a group of one station fits nothing.

    Four stations in a row 8 m apart, and a fifth a bay (5.65 m) across from where its
    position says:

    >>> pos = {f"s{i}": Position(np.array([8.0 * i, 0.0, 0.0]), False, None, 1.0)
    ...        for i in range(5)}
    >>> at = {s: np.eye(4) for s in pos}
    >>> for s, p in pos.items(): at[s][:3, 3] = p.xyz
    >>> row = {s: at[s] for s in ("s0", "s1", "s2", "s3")}
    >>> refutes(pos, row, {"s4": at["s4"]})
    False
    >>> at["s4"][1, 3] = 5.65
    >>> refutes(pos, row, {"s4": at["s4"]})
    True
    """
    for one, other in ((first, second), (second, first)):
        fit = _group_fit(one, positions)
        if fit is None:
            continue
        for s, P in other.items():
            if s not in positions:
                continue
            xy = np.asarray(P)[:2, 3]
            off = float(np.linalg.norm((fit.T @ P)[:2, 3] - positions[s].xyz[:2]))
            if off > AGREE_SIGMAS * math.hypot(positions[s].sigma_m, fit.sigma_at(xy)):
                return True
    return False


def sited_by_groups(
    positions: Mapping[str, Position],
    groups: Sequence[Sequence[str]],
    poses: Mapping[str, Matrix],
) -> dict[str, Position]:
    """The positions each group of solved stations carries: a group's poses
    (``T_group_station``) fitted to its stations' positions move as one
    (:func:`_group_fit`), so the fit's heading is known to ``1 / sqrt(sum r^2 / sigma^2)``
    (``r``: each station's distance from their weighted centre), combined with the mean of
    its stations' own headings (:data:`HEADING_SIGMA_DEG` each, weighed by their
    variance), and each station's fitted position to ``sqrt(1 / sum(1 / sigma^2) + r^2
    var(heading))``: n stations that one registration holds together are where their n
    positions say, to about ``sigma / sqrt(n)``. A group the fit finds misplaced keeps its
    positions as they are.

    Three stations in a row along the site's x axis, solved along their group's y axis:

    >>> pos = {s: Position(np.array([x, 0.0, 0.0]), False, None, 1.0) for s, x in
    ...        (("a", 0.0), ("b", 8.0), ("c", 16.0))}
    >>> poses = {s: np.eye(4) for s in pos}
    >>> for s, y in (("b", 8.0), ("c", 16.0)): poses[s][1, 3] = y
    >>> a = sited_by_groups(pos, [["a", "b", "c"]], poses)["a"]
    >>> round(math.degrees(a.heading_rad), 1), round(math.degrees(a.heading_sigma_rad), 1)
    (-90.0, 5.1)
    >>> bool(np.allclose(a.xyz[:2], 0.0)), round(a.sigma_m, 2)
    (True, 0.91)
    """
    out = dict(positions)
    for group in groups:
        common = [s for s in group if s in positions and s in poses]
        fit = _group_fit({s: poses[s] for s in common}, positions)
        if fit is None:
            continue
        yaw, var = _yaw(fit.T), fit.var_turn
        told = [s for s in common if positions[s].heading_rad is not None]
        if told:  # the group's turn the stations' own headings say, on the circle
            k = np.array([1.0 / positions[s].heading_sigma_rad ** 2 for s in told])
            said = [
                float(positions[s].heading_rad or 0.0) - _yaw(np.asarray(poses[s])) for s in told
            ]
            c = float(k @ np.cos(said)), float(k @ np.sin(said))
            var_said = 1.0 / float(k.sum())
            gap = math.atan2(c[1], c[0]) - yaw
            gap = (gap + math.pi) % (2 * math.pi) - math.pi
            yaw += gap * var / (var + var_said)
            var = var * var_said / (var + var_said)
        R = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
        shift = fit.T[:2, :2] @ fit.centre + fit.T[:2, 3] - R @ fit.centre
        for s in common:
            xy = np.asarray(poses[s])[:2, 3]
            xyz = positions[s].xyz.copy()
            xyz[:2] = R @ xy + shift
            r2 = float(np.sum((xy - fit.centre) ** 2))
            out[s] = replace(
                positions[s],
                xyz=xyz,
                sigma_m=math.sqrt(fit.var_centre + r2 * var),
                heading_rad=yaw + _yaw(np.asarray(poses[s])),
                heading_sigma_rad=math.sqrt(var),
            )
    return out


def decide_with_groups(
    links: list[Link],
    positions: Mapping[str, Position],
    sol: GraphSolution,
    solve: Callable[[list[Link]], GraphSolution],
) -> tuple[GraphSolution, dict[str, Position]]:
    """The positions decide the links again with what the solution's groups carry
    (:func:`sited_by_groups`, :func:`apply_positions`), and the graph is solved again
    (``solve``), until their decisions no longer change (at most :data:`DECIDE_ROUNDS`
    times). Returns the last solution and the positions its groups carry."""

    def decisions() -> list[tuple[str, str, int, tuple[float, ...]]]:
        return [
            (
                e.vouched,
                e.undecided,
                len(e.alternatives),
                tuple(np.round(e.T_target_source[:3, 3], 2)) if e.vouched else (),
            )
            for e in links
            if e.T_target_source is not None
        ]

    sited = sited_by_groups(positions, sol.groups, sol.poses)
    for _ in range(DECIDE_ROUNDS):
        before = decisions()
        apply_positions(links, sited)
        if decisions() == before:
            break
        sol = solve(links)
        sited = sited_by_groups(positions, sol.groups, sol.poses)
    return sol, sited


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
    (:func:`predicted_T_target_source`): :data:`AGREE_SIGMAS` of the sigma
    :func:`sigmas_off` measures in (metres; both positions' and what the target's heading
    sigma turns the offset by) and :data:`AGREE_HEADING_DEG` (radians), the bounds within
    which they agree with a link. None when a heading is unknown: the predicted offset's
    direction is then unknown too, and the link is only seeded.

    >>> a = Position(np.zeros(3), False, 0.0, 1.0)
    >>> shift, turn = window_of(a, a)
    >>> round(shift, 3), round(math.degrees(turn), 1)
    (4.243, 30.0)
    """
    if target.heading_rad is None or source.heading_rad is None:
        return None
    d = float(np.linalg.norm(source.xyz[:2] - target.xyz[:2]))
    sigma = math.hypot(target.sigma_m, source.sigma_m, d * target.heading_sigma_rad)
    return AGREE_SIGMAS * sigma, math.radians(AGREE_HEADING_DEG)


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
    "DECIDE_ROUNDS",
    "DEFAULT_SIGMA_M",
    "HEADING_SIGMA_DEG",
    "PICKED_BY",
    "Position",
    "T_site_station",
    "apply_positions",
    "choose",
    "decide_with_groups",
    "near_pairs",
    "predicted_T_target_source",
    "read_positions_csv",
    "refutes",
    "sigmas_off",
    "site_from_positions",
    "sited_by_groups",
    "stored_positions",
    "unsettled",
    "window_of",
]
