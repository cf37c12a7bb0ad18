"""The map check: every pair of placed stations must agree on free space, linked or not.

A link is judged on its own two scans. Repeating structure (identical rooms, rack bays) lets
a wrong link overlay two copies of the same geometry so well that its own check cannot tell
it from the truth; several such links even agree with each other, so loops confirm them. The
rest of the project can tell: a station placed one room off sits where another station
*saw through* — that station's rays crossed the space where the misplaced station puts its
walls. So once the graph has placed the stations, every pair of placed stations of a group
within :attr:`~flexreg.survey.config.SurveyConfig.map_radius_m` is scored in both directions
on the registration's dense check (each station's even sample in the other's view):

* **explained**: the share of the sample that lies on the other station's surfaces (half an
  inlier threshold plus 0.2 % of the range, as the verdict's fine check);
* **conflicting**: the share that lies clearly in front of what the other scanner measured,
  in its free space (2.5 inlier thresholds plus 1 % of the range, as the verdict's free-space
  test).

Both count only the points at pixels whose four neighbours measured too
(:func:`~flexreg.stages.verification.open_space_witnesses`): beside a pixel with no return
nothing bounds how far a surface runs within a pixel's footprint. Far-apart stations see each
other's walls along their length: a wall 35-40 m off and a metre beside the line of sight
falls into one column of the other scan, the last before its returns stop, whose centre ray
passes the wall and measures the corner behind it; by that pixel the whole wall lay in open
space (6 % of a station's sample at its true pose, in a 36-station building).

A pair **conflicts** when, in either direction, at least ``map_min_conflict`` of the sample is
in the other's free space and that is at least ``map_conflict_ratio`` times what the other
explains there: more of what one station sees contradicts the other than agrees with it. Two
correctly placed stations that barely see each other explain little and contradict less
(moving objects and grazing rays stay a few percent); a station placed into the twin of its
room contradicts every station that looked into that room.

Two stations placed within 1 m of each other (:data:`~flexreg.survey.config.COINCIDENT_M`)
are one viewpoint, and from one viewpoint two scans must show the same scene: they also
conflict when either explains less than 80 % of the other
(:data:`~flexreg.survey.config.COINCIDENT_EXPLAINED`). A repeated set-up passes; stations
of different aisles of a repeating hall folded onto one spot agree on the racks but not on
the far walls, and do not.

A station placed only through a link that closes no loop is also tested against each station
loops confirm at full resolution (:func:`unconfirmed_pairs`, :func:`open_space_at_full`,
:func:`refuted_at_full`): every valid pixel of both scans, the registration's own open-space
test, where a right pose puts almost nothing and a look-alike bay the hall's unique objects.

A conflict is handed to the graph as a *veto* (:func:`flexreg.survey.graph.solve_graph`):
while the solution keeps the two stations in the vetoed configuration, the accepted links of
a path between them that no loop confirms are cut (the most doubtful one, by the link's own
free-space conflict ratio, when loops confirm them all; for a full-resolution veto, only those
beyond the last station the map holds right), and the graph solved again; the map is checked
again until no pair conflicts.
"""

from __future__ import annotations

import hashlib
import logging
import os
from collections.abc import Callable
from dataclasses import astuple, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.core.transforms import invert
from flexreg.errors import InputError
from flexreg.registration.check import TOLERANCE, Check, check_masks
from flexreg.registration.fullres import full_pair_of, pose_masks
from flexreg.stages.correspondences import derive_threshold
from flexreg.stages.verification import open_space_witnesses
from flexreg.survey.c2c import adjustment_cloud, fit_groups
from flexreg.survey.config import COINCIDENT_EXPLAINED, COINCIDENT_M, SurveyConfig
from flexreg.survey.links import Veto
from flexreg.survey.stations import (
    PREPARED_SUFFIX,
    CacheEntryError,
    load_prepared,
    read_entry,
    write_entry,
)

log = logging.getLogger(__name__)

Matrix = NDArray[np.float64]

#: memory the graph's :class:`PairJudge` keeps its stations' views in, bytes
JUDGE_VIEW_BYTES = 256 * 2**20

#: bumped when a look's scores change (the dense check's tests, the glances): looks kept by
#: older code are scored again
LOOK_FORMAT = 3
#: the cache entry kind of the kept looks
LOOKS_KIND = "map-looks"


@dataclass(eq=False)
class PairLook:
    """Two placed stations scored at their solved relative pose.

    Attributes
    ----------
    a, b : str
        Station stems (``a`` first in file order).
    T_a_b : (4, 4) float64
        Their relative pose in the solution (maps ``b``'s points into ``a``'s frame).
    explained : (float, float)
        Share of ``b``'s sample on ``a``'s surfaces, and of ``a``'s on ``b``'s.
    conflicting : (float, float)
        Share of ``b``'s sample in ``a``'s free space, and of ``a``'s in ``b``'s.
    samples : (int, int)
        Sizes of the two samples.
    """

    a: str
    b: str
    T_a_b: Matrix
    explained: tuple[float, float]
    conflicting: tuple[float, float]
    samples: tuple[int, int]

    @property
    def distance_m(self) -> float:
        """How far apart the two scanners are placed, metres."""
        return float(np.linalg.norm(np.asarray(self.T_a_b)[:3, 3]))

    def coincident(self, config: SurveyConfig) -> bool:
        """Placed within :data:`COINCIDENT_M` of each other but not seeing the same scene:
        from (nearly) one viewpoint two scans must explain :data:`COINCIDENT_EXPLAINED` of
        each other (a repeated set-up does); less means one is in the wrong place."""
        return self.distance_m < COINCIDENT_M and min(self.explained) < (COINCIDENT_EXPLAINED)

    @property
    def seen(self) -> tuple[float, float]:
        """Share of each sample on the other's surfaces or in its free space (where the other
        scanner measured anything): how much each direction sees of the other."""
        x, c = self.explained, self.conflicting
        return (x[0] + c[0], x[1] + c[1])

    def conflicts(self, config: SurveyConfig) -> bool:
        """Whether either direction contradicts more than it explains, or the two are
        placed at one spot without seeing the same scene (see the module)."""
        return self.coincident(config) or any(
            c >= config.map_min_conflict and c >= config.map_conflict_ratio * x
            for x, c in zip(self.explained, self.conflicting, strict=True)
        )

    def describe(self, config: SurveyConfig | None = None) -> str:
        """The contradiction in words (``config``: the coincidence test's thresholds)."""
        if self.coincident(config or SurveyConfig()) and not any(
            c >= x for x, c in zip(self.explained, self.conflicting, strict=True)
        ):
            return (
                f"placed {self.distance_m:.2f} m apart, yet only "
                f"{100 * min(self.explained):.0f}% of one matches the other: they cannot "
                "both stand there"
            )
        i = int(np.argmax(self.conflicting))
        seen, seer = (self.b, self.a) if i == 0 else (self.a, self.b)
        return (
            f"{100 * self.conflicting[i]:.1f}% of {seen}'s points lie where {seer} saw open "
            f"space and {100 * self.explained[i]:.1f}% on its surfaces"
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "a": self.a,
            "b": self.b,
            "T_a_b": np.asarray(self.T_a_b, dtype=np.float64).tolist(),
            "explained": [round(float(v), 4) for v in self.explained],
            "conflicting": [round(float(v), 4) for v in self.conflicting],
            "samples": [int(v) for v in self.samples],
        }


def glance_path(cache_file: str) -> Path:
    """Where a station's sample and inlier threshold are kept beside its prepared file."""
    p = Path(cache_file)
    return p.with_name(p.name.removesuffix(PREPARED_SUFFIX) + ".glance.npz")


def write_glance(cache_file: str) -> str | None:
    """Write (once) what other stations need to score this one: its even sample, (N, 3)
    float64 metres, and its inlier threshold (metres, as the registration derives it from
    the keypoints' pixel footprints). Runs on a worker; returns the file, or None when the
    station has no sample. A glance already written is used when it reads back whole
    (:func:`~flexreg.survey.stations.read_entry`), else written again after one warning."""
    path = glance_path(cache_file)
    if path.exists():
        try:
            _read_glance_entry(path, cache_file)
            return str(path)
        except CacheEntryError as e:
            log.warning("%s: unusable cache entry (%s); writing it again", path, e)
    p = load_prepared(cache_file)
    sample = p.view.sample
    if sample is None or len(sample) == 0:
        return None
    cfg = p.config
    if cfg.threshold_m is not None:
        thr = float(cfg.threshold_m)
    else:
        kp = p.keypoints
        xy = kp.features.xy[kp.lifted]
        thr = derive_threshold(p.image, p.image, xy, xy[:0], threshold_px=cfg.threshold_px)
    arrays = {"sample": np.asarray(sample, dtype=np.float64), "threshold_m": np.float64(thr)}
    write_entry(path, "glance", arrays, {"of": Path(cache_file).name})
    return str(path)


def _read_glance_entry(
    path: Path | str, cache_file: str | None
) -> tuple[NDArray[np.float64], float]:
    """A glance's sample and threshold; ``cache_file``: the prepared station it must be of.

    Raises
    ------
    CacheEntryError
    """
    meta, z = read_entry(path, "glance")
    if cache_file is not None and meta.get("of") != Path(cache_file).name:
        raise CacheEntryError("made of another station")
    try:
        sample, thr = z["sample"], z["threshold_m"]
        if sample.dtype != np.float64 or sample.ndim != 2 or sample.shape[1] != 3:
            raise CacheEntryError("not a station sample")
        return sample, float(thr)
    except (KeyError, TypeError, ValueError) as e:
        raise CacheEntryError(f"not a station sample ({e})") from None


def _read_glance(path: str) -> tuple[NDArray[np.float64], float]:
    try:
        return _read_glance_entry(path, None)
    except CacheEntryError as e:
        raise InputError(path, f"unreadable station sample ({e})") from None


def _witnesses(view: Any) -> NDArray[np.bool_]:
    """The view's pixels whose footprint its neighbours bound: the only ones the map
    check judges points at (:func:`open_space_witnesses`)."""
    return open_space_witnesses(view.measured, view.image.wraps)


def _shares(
    view: Any,
    witnesses: NDArray[np.bool_],
    thr_a: float,
    sample: NDArray[np.float64],
    thr_b: float,
    T: Matrix,
) -> tuple[float, float, int]:
    """Explained and conflicting shares of ``sample`` (another station's, posed by ``T``)
    in the view of a station, on the registration's dense check; only the points at the
    view's ``witnesses`` are judged."""
    check = Check(view.image, view.measured, view.slack, sample, witnesses=witnesses)
    ok, bad = check_masks(check, np.asarray(T, dtype=np.float64), max(thr_a, thr_b))
    n = len(ok)
    return (float(ok.mean()) if n else 0.0, float(bad.mean()) if n else 0.0, n)


def look_from(
    cache_file: str, glance: str, others: list[tuple[str, str, Matrix]]
) -> list[tuple[str, float, float, int]]:
    """Score other stations' samples in one station's view (runs on a worker).

    Parameters
    ----------
    cache_file, glance : str
        The viewing station's prepared file and glance (:func:`write_glance`).
    others : list of (stem, glance file, T_this_other)
        The stations to score and their poses in the viewing station's frame.

    Returns
    -------
    list of (stem, explained share, conflicting share, sample size)
    """
    v = load_prepared(cache_file).view
    _, thr_a = _read_glance(glance)
    if v.measured is None or v.slack is None:
        return []
    out: list[tuple[str, float, float, int]] = []
    witnesses = _witnesses(v)
    for stem, g, T in others:
        sample, thr_b = _read_glance(g)
        out.append((stem, *_shares(v, witnesses, thr_a, sample, thr_b, T)))
    return out


def open_space_at_full(
    files: tuple[str, str], glances: tuple[str, str], T_a_b: Matrix
) -> tuple[float, float, int]:
    """Two stations at one relative pose, every valid pixel of both (runs on a worker): the
    registration's full-resolution test (:func:`~flexreg.registration.fullres.pose_masks`,
    each point against the other's nearest range in a 5 x 5 square, with its own range
    step), where a right pose puts almost nothing in open space.

    Parameters
    ----------
    files, glances : (str, str)
        Both stations' prepared files and glances (:func:`write_glance`: the inlier
        thresholds), ``a`` first.
    T_a_b : (4, 4) float64
        Maps ``b``'s points into ``a``'s frame.

    Returns
    -------
    (open share, explained share, points)
        The share of both stations' points in the other's open space, the share the other
        explains, and how many points were tested (both directions).
    """
    views = [load_prepared(f).view for f in files]
    thr = max(_read_glance(g)[1] for g in glances)
    (ex_b, op_b), (ex_a, op_a) = pose_masks(
        full_pair_of(views)(), np.asarray(T_a_b, dtype=np.float64), thr
    )
    n = len(op_b) + len(op_a)
    if n == 0:
        return 0.0, 0.0, 0
    return (
        float(op_b.sum() + op_a.sum()) / n,
        float(ex_b.sum() + ex_a.sum()) / n,
        n,
    )


def unconfirmed_pairs(
    looks: list[PairLook], confidence: dict[str, str], min_seen: float
) -> list[tuple[str, str, Matrix]]:
    """The pairs of ``looks`` (the sample's scores of this round) that join a placement no
    loop confirms to a station loops confirm and see each other (in either direction at least
    ``min_seen`` of a sample on the other's surfaces or in its free space, as
    :meth:`PairJudge.contradiction` asks), with their relative poses ``T_a_b``: what
    :func:`open_space_at_full` tests.

    A station that confident links place through one that closes no loop (confidence
    ``single``: :attr:`~flexreg.survey.graph.GraphSolution.confidence`) rests on that one
    registration, one that uncertain links place (``uncertain``: two answers uncertain only
    for their small overlap that agree around a loop, or poses rough positions picked) on
    registrations that saw little of each other, and in a hall that repeats bay by bay a
    wrong answer explains its two scans as well as the right one; the sample's map check
    cannot tell either (stray returns at depth edges fill a few percent of each sample at
    every pose). The stations that loops
    confirm around the placement can, at full resolution: there a right pose puts almost
    none of either station's points where the other saw open space, and one a few bays off
    puts the hall's unique objects there (:func:`refuted_at_full`). Pairs that do not see
    each other are left out: they would say little, and a project of many stations holds
    many of them."""
    out = []
    for p in looks:
        ca, cb = confidence.get(p.a), confidence.get(p.b)
        if None in (ca, cb) or (ca == "confident") == (cb == "confident"):
            continue
        if max(p.seen) >= min_seen:
            out.append((p.a, p.b, np.asarray(p.T_a_b, dtype=np.float64)))
    return out


def refuted_at_full(
    todo: list[tuple[str, str, Matrix]],
    tested: list[tuple[float, float, int]],
    confidence: dict[str, str],
    limit: float,
    min_seen: float,
) -> list[Veto]:
    """Vetoes of the pairs of :func:`unconfirmed_pairs` whose full-resolution test
    (:func:`open_space_at_full`, in ``tested``) puts ``limit`` or more of both stations' points
    in the other's open space: the registration's ``judge.settle_open_share``, the share from
    which it sweeps a pose in a repeating plan along the repeat.

    Each veto holds right (:attr:`~flexreg.survey.links.Veto.held`) the stations loops
    confirm and the unconfirmed ones that passed: no pair refuted, and in one at least
    ``min_seen`` of the points explained (``map_min_conflict``: the two see each other). A
    chain of lone links is then cut beyond the last station it placed right, not along its
    whole length."""
    lone_of = [b if confidence.get(a) == "confident" else a for a, b, _ in todo]
    refuted = {s for s, (share, _, _) in zip(lone_of, tested, strict=True) if share >= limit}
    seen = {s for s, (_, x, _) in zip(lone_of, tested, strict=True) if x >= min_seen}
    held = frozenset(s for s, c in confidence.items() if c == "confident") | (seen - refuted)
    out = []
    for (a, b, T), lone, (share, _, _) in zip(todo, lone_of, tested, strict=True):
        if share >= limit:
            firm = b if lone == a else a
            why = (
                f"at full resolution {100 * share:.2f}% of both stations' points lie where the "
                f"other saw open space: {lone}, which no loop of confident links confirms, "
                f"against {firm}, which loops confirm (refuted from {100 * limit:.2f}%)"
            )
            out.append(Veto(a, b, T, why, held))
    return out


def _pose_key(T: Matrix) -> bytes:
    """A relative pose to 1e-4 of the rotation and 1 mm: what the judge remembers it by."""
    return np.round(np.r_[T[:3, :3].ravel() * 1e4, T[:3, 3] * 1e3]).tobytes()


class PairJudge:
    """The map check's dense scores for a single pair at any relative pose, in this process.

    The graph asks it, when two groups could be joined in several places, whether the
    stations of the links between them would contradict each other at each placement
    (:mod:`flexreg.survey.consensus`).
    Views are loaded from the prepared files on first use, only what the check reads (the
    camera, the measured ranges, their slack and which pixels are judged: 10 bytes a working
    pixel, not the view's points and normals), and the most recently used kept within
    ``keep_bytes``; answers are remembered per pair and pose (to 1 mm / 1e-4 of the
    rotation), and kept for later runs
    by :meth:`keep` in the cache (:meth:`kept_path`: named by the dense check's tolerances and
    :data:`LOOK_FORMAT`, each look by both stations' cache keys and the pose), so a re-run
    scores only the placements it has not seen; the full-resolution tests of lone placements
    (:meth:`recall_full`, :meth:`remember_full`) are kept beside them.

    Parameters
    ----------
    files, glances : dict of str
        Prepared file and glance (:func:`write_glance`) per station stem.
    config : SurveyConfig
        ``map_min_conflict`` and ``map_conflict_ratio``, as :meth:`PairLook.conflicts`.
    keep_bytes : int
        Memory for the views held at once (at least one is held): 256 MiB by default, all
        of 45 stations of 1024 x 512, or 10 of the largest working images (2.5 Mpx).
    """

    def __init__(
        self,
        files: dict[str, str],
        glances: dict[str, str],
        config: SurveyConfig,
        keep_bytes: int = JUDGE_VIEW_BYTES,
    ) -> None:
        self.files, self.glances, self.config = files, glances, config
        self.keep_bytes = keep_bytes
        self._views: dict[str, tuple[Any, NDArray[np.float64], float, NDArray[np.bool_]]] = {}
        self._memo: dict[tuple[str, str, bytes], PairLook | None] = {}
        self._full: dict[tuple[str, str, bytes], tuple[float, float, int]] = {}
        self._fits: dict[bytes, Matrix | None] = {}
        self._kept: dict[str, NDArray[np.float64]] | None = None  # read on first use
        self._new = 0
        self._used: set[str] = set()  # the kept looks this run asked for

    def kept_path(self) -> str | None:
        """Where the looks are kept: beside the prepared stations (None without any)."""
        if not self.files:
            return None
        tol = np.asarray(astuple(TOLERANCE), dtype="<f8").tobytes()  # what scores follow
        tag = hashlib.sha256(tol).hexdigest()[:8]
        folder = os.path.dirname(next(iter(sorted(self.files.values()))))
        return os.path.join(folder, f"looks-{tag}.v{LOOK_FORMAT}.npz")

    def _kept_looks(self) -> dict[str, NDArray[np.float64]]:
        if self._kept is None:
            self._kept = {}
            path = self.kept_path()
            if path is not None and os.path.isfile(path):
                try:
                    _, z = read_entry(path, LOOKS_KIND)
                    keys, values = z["keys"], z["values"]
                    if values.shape != (len(keys), 6) or not np.isfinite(values).all():
                        raise CacheEntryError("unexpected arrays")
                    self._kept = {str(k): v for k, v in zip(keys, values, strict=True)}
                except (CacheEntryError, KeyError) as e:
                    log.warning("%s: unusable kept looks (%s); scoring them again", path, e)
        return self._kept

    def keep(self) -> None:
        """Write the looks this run asked for, for later runs (when any is new: those of
        placements no longer asked are dropped, so the file does not grow run after run; a
        cache that cannot be written is only a warning)."""
        path = self.kept_path()
        if path is None or not self._new:
            return
        kept = self._kept_looks()
        keys = sorted(self._used & kept.keys())
        values = np.asarray([kept[k] for k in keys], dtype=np.float64).reshape(-1, 6)
        arrays = {"keys": np.asarray(keys, dtype=str), "values": values}
        try:
            write_entry(Path(path), LOOKS_KIND, arrays, {"format": LOOK_FORMAT})
            self._new = 0
        except OSError as e:
            log.warning("%s: cannot keep the map's looks (%s)", path, e.strerror or e)

    def _view(self, stem: str) -> tuple[Any, NDArray[np.float64], float, NDArray[np.bool_]] | None:
        if stem not in self.files or stem not in self.glances:
            return None
        if stem in self._views:
            self._views[stem] = self._views.pop(stem)  # most recently used last
            return self._views[stem]
        v = load_prepared(self.files[stem]).view
        if v.measured is None or v.slack is None:
            return None
        sample, thr = _read_glance(self.glances[stem])
        image = v.image
        points = np.broadcast_to(np.float32(np.nan), (image.height, image.width, 3))
        light = replace(
            v,
            image=replace(image, xyz=points),
            normals=None,
            sample=None,
            polish_sample=None,
            refine_sample=None,
        )
        self._views[stem] = (light, sample, thr, _witnesses(v))
        while len(self._views) > 1 and self._held() > self.keep_bytes:
            self._views.pop(next(iter(self._views)))  # the least recently used
        return self._views[stem]

    def _held(self) -> int:
        return sum(
            v.measured.nbytes + v.slack.nbytes + v.image.valid.nbytes + s.nbytes + w.nbytes
            for v, s, _, w in self._views.values()
        )

    def look(self, a: str, b: str, T_a_b: Matrix) -> PairLook | None:
        """Both directions of the pair at ``T_a_b``; None when a station has no view."""
        T = np.asarray(T_a_b, dtype=np.float64)
        key = (a, b, _pose_key(T))
        if key not in self._memo:
            look = self.known(a, b, T)
            va, vb = (None, None) if look is not None else (self._view(a), self._view(b))
            if va is not None and vb is not None:
                ab = _shares(va[0], va[3], va[2], vb[1], vb[2], T)
                ba = _shares(vb[0], vb[3], vb[2], va[1], va[2], invert(T))
                look = PairLook(a, b, T, (ab[0], ba[0]), (ab[1], ba[1]), (ab[2], ba[2]))
                log.debug("map judge %s <- %s: %s", a, b, look.describe())
                self.remember(look)
            self._memo[key] = look
        return self._memo[key]

    def known(self, a: str, b: str, T_a_b: Matrix) -> PairLook | None:
        """The pair's look at ``T_a_b`` when this run or an earlier one (the kept looks)
        scored it, else None (nothing is scored here)."""
        T = np.asarray(T_a_b, dtype=np.float64)
        key = (a, b, _pose_key(T))
        if self._memo.get(key) is not None:
            return self._memo[key]
        stored = self._stored_key(a, b, key[2])
        kept = self._kept_looks().get(stored) if stored is not None else None
        if stored is None or kept is None:
            return None
        self._used.add(stored)
        return PairLook(a, b, T, (kept[0], kept[1]), (kept[2], kept[3]),
                        (int(kept[4]), int(kept[5])))  # fmt: skip

    def remember(self, look: PairLook) -> None:
        """Keep a look scored here or on a worker (:func:`look_from`, :func:`assemble`) for
        this run and (:meth:`keep`) later ones."""
        T = np.asarray(look.T_a_b, dtype=np.float64)
        key = (look.a, look.b, _pose_key(T))
        self._memo[key] = look
        stored = self._stored_key(look.a, look.b, key[2])
        if stored is not None:
            self._used.add(stored)
            self._kept_looks()[stored] = np.asarray(
                [*look.explained, *look.conflicting, *look.samples], dtype=np.float64
            )
            self._new += 1

    def recall_full(self, a: str, b: str, T_a_b: Matrix) -> tuple[float, float, int] | None:
        """The full-resolution test of the pair at ``T_a_b`` (:func:`open_space_at_full`),
        when this run or an earlier one (the kept looks) made it; else None."""
        key, stored = self._full_key(a, b, T_a_b)
        if key not in self._full:
            kept = self._kept_looks().get(stored) if stored is not None else None
            if kept is None:
                return None
            self._full[key] = (float(kept[0]), float(kept[1]), int(kept[2]))
        if stored is not None:
            self._used.add(stored)
        return self._full[key]

    def remember_full(
        self, a: str, b: str, T_a_b: Matrix, tested: tuple[float, float, int]
    ) -> None:
        """Keep a full-resolution test for this run and (:meth:`keep`) later ones."""
        key, stored = self._full_key(a, b, T_a_b)
        self._full[key] = tested
        if stored is not None:
            self._used.add(stored)
            self._kept_looks()[stored] = np.asarray([*tested, 0, 0, 0], dtype=np.float64)
            self._new += 1

    def at_full(self, a: str, b: str, T_a_b: Matrix) -> tuple[float, float, int] | None:
        """The full-resolution test of the pair at ``T_a_b`` (:func:`open_space_at_full`),
        made here (in this process) when no run made it yet, and remembered; None when a
        station has no prepared file or glance (:data:`~flexreg.survey.links.FullJudge`)."""
        T = np.asarray(T_a_b, dtype=np.float64)
        hit = self.recall_full(a, b, T)
        if hit is not None:
            return hit
        if any(s not in self.files or s not in self.glances for s in (a, b)):
            return None
        tested = open_space_at_full(
            (self.files[a], self.files[b]), (self.glances[a], self.glances[b]), T
        )
        log.debug("map judge %s <- %s at full resolution: %.4f open, %.4f seen", a, b,
                  *tested[:2])  # fmt: skip
        self.remember_full(a, b, T, tested)
        return tested

    def _full_key(self, a: str, b: str, T_a_b: Matrix) -> tuple[Any, str | None]:
        pose = _pose_key(np.asarray(T_a_b, dtype=np.float64))
        stored = self._stored_key(a, b, pose)
        return (a, b, pose), None if stored is None else "full|" + stored

    def _stored_key(self, a: str, b: str, pose: bytes) -> str | None:
        """A look's name among the kept ones: both stations' cache keys and the pose."""
        if a not in self.files or b not in self.files:
            return None
        ka, kb = (os.path.basename(self.files[s]).removesuffix(PREPARED_SUFFIX) for s in (a, b))
        return f"{ka}|{kb}|{pose.hex()}"

    def fit_groups(
        self, target: dict[str, Matrix], source: dict[str, Matrix], X: Matrix
    ) -> Matrix | None:
        """Where all the overlap of two groups' stations fits, from ``X`` (``T_target_source``
        of the groups' frames; each group given as its stations' poses in its frame): their
        adjustment clouds (made here when the final alignment has not yet) aligned by
        :func:`~flexreg.survey.c2c.fit_groups`. None when a station has no prepared file or
        too few points overlap. Answers are remembered per stations and poses (see
        :data:`~flexreg.survey.links.GroupFit`)."""
        X = np.asarray(X, dtype=np.float64)
        key = b"".join(
            s.encode() + _pose_key(P) for g in (target, source) for s, P in sorted(g.items())
        ) + _pose_key(X)
        if key not in self._fits:
            voxel = self.config.refine_voxel_m
            try:
                sides = [
                    [(adjustment_cloud(self.files[s], voxel), P) for s, P in sorted(g.items())]
                    for g in (target, source)
                ]
                self._fits[key] = fit_groups(sides[0], sides[1], X, voxel)
            except (KeyError, ValueError, CacheEntryError) as e:
                log.debug("group fit %s <- %s: %s", sorted(target), sorted(source), e)
                self._fits[key] = None
        return self._fits[key]

    def __call__(self, a: str, b: str, T_a_b: Matrix) -> tuple[float, float, float] | None:
        """How much ``a`` and ``b`` contradict each other at ``T_a_b`` (see
        :data:`flexreg.survey.links.Judge`); None when a station has no view or, in both
        directions, less than ``map_min_conflict`` of a sample lands on the other's surfaces
        or in its free space (they hardly see each other there)."""
        look = self.look(a, b, T_a_b)
        return None if look is None else self.contradiction(look)

    def contradiction(self, look: PairLook) -> tuple[float, float, float] | None:
        """``(contradiction, conflict, explained)`` of a pair's scores (see
        :meth:`__call__`)."""
        seen = look.seen
        if max(seen) < self.config.map_min_conflict:
            return None
        r = max(
            c / s
            for s, c in zip(seen, look.conflicting, strict=True)
            if s >= self.config.map_min_conflict
        )
        return float(r), float(max(look.conflicting)), float(min(look.explained))


def pairs_to_check(
    groups: list[list[str]], poses: dict[str, Matrix], radius_m: float
) -> list[tuple[str, str]]:
    """Every pair of placed stations of one group whose positions lie within ``radius_m``,
    in group and file order."""
    out = []
    for g in groups:
        placed = [s for s in g if s in poses]
        for i, a in enumerate(placed):
            for b in placed[i + 1 :]:
                d = float(np.linalg.norm(poses[a][:3, 3] - poses[b][:3, 3]))
                if d <= radius_m:
                    out.append((a, b))
    return out


def assemble(
    pairs: list[tuple[str, str]],
    poses: dict[str, Matrix],
    seen: dict[str, dict[str, tuple[float, float, int]]],
) -> list[PairLook]:
    """Both directions of every pair from the per-station results of :func:`look_from`
    (``seen[a][b]``: ``b``'s sample in ``a``'s view)."""
    out = []
    for a, b in pairs:
        ab, ba = seen.get(a, {}).get(b), seen.get(b, {}).get(a)
        if ab is None or ba is None:
            continue
        out.append(
            PairLook(
                a,
                b,
                invert(poses[a]) @ poses[b],
                (ab[0], ba[0]),
                (ab[1], ba[1]),
                (ab[2], ba[2]),
            )
        )
    return out


def plan_looks(
    pairs: list[tuple[str, str]], poses: dict[str, Matrix], glances: dict[str, str]
) -> dict[str, list[tuple[str, str, Matrix]]]:
    """Per viewing station, the stations to score in its view and their relative poses."""
    todo: dict[str, list[tuple[str, str, Matrix]]] = {}
    for a, b in pairs:
        if a not in glances or b not in glances:
            continue
        T = invert(poses[a]) @ poses[b]
        todo.setdefault(a, []).append((b, glances[b], T))
        todo.setdefault(b, []).append((a, glances[a], invert(T)))
    return todo


def pair_looks(
    pairs: list[tuple[str, str]],
    poses: dict[str, Matrix],
    stored: tuple[dict[str, str], dict[str, str]],
    judge: PairJudge | None,
    run: Callable[[Callable[..., Any], list[tuple[Any, ...]]], list[Any]],
) -> list[PairLook]:
    """The map check's looks at every pair of placed stations, in ``pairs``' order: those
    ``judge`` knows (scored this run or an earlier one at the same poses,
    :meth:`PairJudge.known`) recalled, the rest scored by :func:`look_from` per viewing
    station through ``run(fn, items)`` (on the workers) and kept with the judge's.

    Parameters
    ----------
    pairs : list of (str, str)
    poses : dict of str -> (4, 4) float64
        ``T_group_station`` of the placed stations.
    stored : (dict, dict)
        The prepared file and the glance per station.
    judge : PairJudge or None
    run : callable
        ``run(fn, items)``: ``[fn(*item) for item in items]``, in order.
    """
    files, glances = stored
    known: dict[tuple[str, str], PairLook] = {}
    for a, b in pairs:
        hit = judge.known(a, b, invert(poses[a]) @ poses[b]) if judge is not None else None
        if hit is not None:
            known[(a, b)] = hit
    rest = [p for p in pairs if p not in known]
    todo = plan_looks(rest, poses, glances)
    order = sorted(todo)
    results = run(look_from, [(files[a], glances[a], todo[a]) for a in order])
    seen = {a: {b: (x, c, n) for b, x, c, n in r} for a, r in zip(order, results, strict=True)}
    for look in assemble(rest, poses, seen):
        known[(look.a, look.b)] = look
        if judge is not None:
            judge.remember(look)
    return [known[p] for p in pairs if p in known]


__all__ = [
    "LOOK_FORMAT",
    "PairJudge",
    "PairLook",
    "assemble",
    "glance_path",
    "look_from",
    "open_space_at_full",
    "pair_looks",
    "pairs_to_check",
    "plan_looks",
    "refuted_at_full",
    "unconfirmed_pairs",
    "write_glance",
]
