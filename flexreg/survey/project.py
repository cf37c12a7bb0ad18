""":func:`run_survey`: a whole project of stations, from scan files to poses.

Prepare every station once (cached), choose the candidate links, register them on Dask, solve
the graph, try the pairs the first solution suggests (close solved positions, unplaced
stations' next candidates), refine jointly, and return a :class:`SurveyResult` (poses.json).

The surveyor may name pairs (a CSV: exactly these, or added to the automatic ones) and give
links by hand (:func:`~flexreg.survey.pairs.hand_links`), registered seeded with their pose.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from flexreg.errors import InputError, RegistrationError
from flexreg.survey.adjust import STATUSES, Adjustment, adjust
from flexreg.survey.config import STORED_MAX_DEG, STORED_MAX_M, SurveyConfig
from flexreg.survey.document import SCHEMA, poses_document
from flexreg.survey.execute import (
    OutcomeCounter,
    Progress,
    align_link,
    check_workers,
    dashboard_address,
    dask_client,
    default_workers,
    run_tasks,
)
from flexreg.survey.frames import Frame, read_origins_csv, site_of_reference
from flexreg.survey.graph import GraphSolution, Link, Veto, single_link, solve_graph, uncertain_via
from flexreg.survey.links import Matrix
from flexreg.survey.mapcheck import (
    PairJudge,
    PairLook,
    open_space_at_full,
    pair_looks,
    pairs_to_check,
    refuted_at_full,
    unconfirmed_pairs,
    write_glance,
)
from flexreg.survey.pairs import (
    Candidate,
    HandLink,
    all_pairs,
    auto_pairs,
    hand_links,
    later_pairs,
    merge_candidates,
    place_scores,
    read_pairs_csv,
    sequential_pairs,
)
from flexreg.survey.positions import (
    AGREE_HEADING_DEG,
    AGREE_SIGMAS,
    Position,
    apply_positions,
    decide_with_groups,
    near_pairs,
    predicted_T_target_source,
    read_positions_csv,
    site_from_positions,
    stored_positions,
    unsettled,
    window_of,
)
from flexreg.survey.stations import (
    Prepared,
    Station,
    find_scans,
    load_descriptor,
    prepare_station,
    stations_of,
)
from flexreg.survey.stored import check_stations, stored_T_target_source

log = logging.getLogger(__name__)


@dataclass(eq=False)
class SurveyResult:
    """Everything a survey found (see poses.json in :mod:`flexreg.survey`).

    Attributes
    ----------
    stations : list of Station
    prepared : dict of str -> Prepared
    links : list of Link
    solution : GraphSolution
    config : SurveyConfig
    workers : int
    wall_s : float
    timings_s : dict
        Wall seconds per stage: ``prepare`` (reading and preparing the stations), ``pairs``,
        ``links`` (registering them; the map check's glances), ``graph`` (the solves between
        link rounds), ``map_check``, ``refine`` (the final joint alignment); and seconds
        summed over the stations (worker time): ``read_sum`` (hashing and reading the files)
        and ``prepare_sum`` (the rest of their preparation).
    refined : bool
    stored : dict
        Stored poses per station (``T_world_scanner``).
    map_looks : list of PairLook
        The last map check: every pair of placed stations scored at its solved pose.
    vetoes : list of Veto
        Every conflict the map checks found (each cut the links between its two stations
        that no loop confirms, or the most doubtful one).
    adjustment : Adjustment or None
        The final joint alignment (None when off or nothing placed): accuracies, statuses.
    frame : {"reference", "stored"}
        The frame the poses are written in besides the reference's (``T_site_station``).
    positions : dict of str -> Position
        Rough positions given per station (:mod:`flexreg.survey.positions`): the poses are
        also written in their site frame, unless ``frame`` is ``"stored"``.
    """

    stations: list[Station]
    prepared: dict[str, Prepared]
    links: list[Link]
    solution: GraphSolution
    config: SurveyConfig
    workers: int
    wall_s: float = 0.0
    timings_s: dict[str, float] = field(default_factory=dict)
    refined: bool = False
    stored: dict[str, Any] = field(default_factory=dict)
    map_looks: list[PairLook] = field(default_factory=list)
    vetoes: list[Veto] = field(default_factory=list)
    adjustment: Adjustment | None = None
    frame: Frame = "reference"
    positions: dict[str, Position] = field(default_factory=dict)

    def site(self) -> tuple[Matrix, str]:
        """``T_site_reference`` and what the site frame is (:mod:`flexreg.survey.frames`)."""
        sol = self.solution
        poses = {s: sol.poses[s] for s in self.placed if s in sol.poses}
        origins = {st.stem: st.origin for st in self.stations if st.origin is not None}
        if not poses:
            return np.eye(4), f"the frame of station {sol.reference}"
        T = None if self.frame == "stored" else site_from_positions(poses, self.positions)
        if T is not None:
            n = sum(s in self.positions for s in poses)
            return T, f"the site frame of the rough positions (fitted to {n} placed stations)"
        return site_of_reference(
            self.frame, sol.reference, poses, self.stored, self.stored_checks(), origins
        )

    def stored_checks(self) -> dict[str, dict[str, Any]]:
        """Every placed station against the pose its file stores
        (:func:`~flexreg.survey.stored.check_stations`); empty with ``stored_poses="ignore"``
        or fewer than two placed stations storing a pose."""
        sol = self.solution
        poses = {s: sol.poses[s] for s in self.placed if s in sol.poses}
        sigma = self.config.stored_sigma_m
        if sigma is None:
            return check_stations(poses, self.stored, STORED_MAX_DEG, STORED_MAX_M)
        return check_stations(
            poses, self.stored, AGREE_HEADING_DEG, AGREE_SIGMAS * math.sqrt(2.0) * sigma
        )

    @property
    def placed(self) -> list[str]:
        """Stations with a pose in the reference frame (group 0 of two or more)."""
        g0 = self.solution.groups[0]
        return list(g0) if len(g0) > 1 else []

    def status(self, stem: str) -> str:
        """``verified``, ``placed``, ``outside_tolerance`` or ``unplaced``
        (:mod:`flexreg.survey.adjust`); without the final alignment a placed station is
        ``placed`` (its accuracy unchecked)."""
        if stem not in self.placed:
            return "unplaced"
        adj = self.adjustment
        st = adj.status.get(stem, "placed") if adj is not None else "placed"
        conf = self.solution.confidence.get(stem)
        if st == "verified" and conf == "uncertain":
            return "placed"  # only uncertain links chose where it is: not independent
        if st in ("verified", "outside_tolerance") and conf == "single":
            return "placed"  # one registration fixes it; the final pairs start from its pose
        return st

    def status_why(self, stem: str) -> str | None:
        """Why a station is not ``verified``, in words (None when it is)."""
        st = self.status(stem)
        if st == "verified":
            return None
        if st == "unplaced":
            p = self.prepared[stem]
            return f"unreadable: {p.error}" if p.error else self.solution.reasons.get(stem, "")
        if self.adjustment is None:
            return "accuracy unchecked: the final alignment was off (--no-refine)"
        if self.solution.confidence.get(stem) == "uncertain" and stem not in self.adjustment.why:
            via = ", ".join(uncertain_via(stem, self.solution.reference, self.links))
            return f"placed only through uncertain links that a loop confirms ({via}); check them"
        if self.solution.confidence.get(stem) == "single":
            why = self.adjustment.why.get(stem)
            link = single_link(stem, self.solution.reference, self.links)
            return (
                f"{link}: the final alignment starts from "
                "its pose and cannot tell a look-alike bay or a pose slid along a wall; a "
                "second link (a scan between it and its neighbours, --link, or rough "
                "positions) would verify it" + (f"; {why}" if why else "")
            )
        return self.adjustment.why.get(stem, "")

    def status_counts(self) -> dict[str, int]:
        """Stations per status, every status named."""
        out = dict.fromkeys(STATUSES, 0)
        for st in self.stations:
            out[self.status(st.stem)] += 1
        return out

    def problems(self) -> list[str]:
        """One line per station that is not verified, per stored pose that disagrees and per
        pair of placed stations that contradict each other."""
        out = []
        for st in self.stations:
            why = self.status_why(st.stem)
            if why is not None:
                out.append(f"{st.stem}: {self.status(st.stem).replace('_', ' ')}: {why}")
        for stem, chk in self.stored_checks().items():
            if chk["agrees"] is False:
                out.append(
                    f"{stem}: the pose stored in its file disagrees with the registration by "
                    f"{chk['rotation_deg']:.2f}° / {chk['translation_m']:.3f} m; check which is "
                    "right"
                )
        for look in self.map_looks:
            if look.conflicts(self.config):
                out.append(
                    f"stations {look.a} and {look.b} contradict each other where they are "
                    f"placed ({look.describe(self.config)}); one of them is placed wrongly"
                )
        return out

    def headline(self) -> str:
        """The statuses on one line: ``8 verified, 1 placed, 0 outside tolerance, 1
        unplaced``."""
        return ", ".join(f"{n} {k.replace('_', ' ')}" for k, n in self.status_counts().items())

    @property
    def exit_status(self) -> int:
        """0 every station verified and nothing contradicts; 3 written but something to
        check (see :meth:`problems`); 1 nothing registered."""
        if not self.placed:
            return 1
        return 3 if self.problems() else 0

    def to_dict(self) -> dict[str, Any]:
        """The poses document (poses.json; :func:`flexreg.survey.document.poses_document`)."""
        return poses_document(self)


@dataclass(frozen=True)
class _Given:
    """What the surveyor gave: the pairs of a CSV (``add``: beside the automatic candidates,
    else instead of them; None: no file) and links with their transforms (``hand``)."""

    pairs: list[Candidate] | None = None
    add: bool = False
    hand: list[Candidate] = field(default_factory=list)
    positions: dict[str, Position] = field(default_factory=dict)

    @property
    def automatic(self) -> bool:
        """Whether the configuration's candidates (``pairs``) are tried too."""
        return self.pairs is None or self.add

    def among(self, stems: list[str]) -> list[Candidate]:
        """The CSV's pairs, then the hand links, between the given (readable) stations."""
        ok = set(stems)
        return [c for c in [*(self.pairs or []), *self.hand] if {c.target, c.source} <= ok]


def _candidates(
    stems: list[str],
    files: dict[str, str],
    config: SurveyConfig,
    given: _Given,
    max_links: int,
) -> tuple[list[Candidate], dict[frozenset[str], int]]:
    """The candidates of the first round and the place-recognition scores: the
    configuration's (unless a CSV gave exactly the pairs), with the CSV's pairs and then the
    hand links in place of those of the same pairs."""
    cands, scores = _automatic(stems, files, config, max_links) if given.automatic else ([], {})
    return merge_candidates(cands, given.among(stems)), scores


def _automatic(
    stems: list[str], files: dict[str, str], config: SurveyConfig, max_links: int
) -> tuple[list[Candidate], dict[frozenset[str], int]]:
    if config.pairs == "all":
        return all_pairs(stems), {}
    if config.pairs == "sequential":
        return sequential_pairs(stems, max(1, config.neighbours)), {}
    scores = place_scores({s: load_descriptor(files[s]) for s in stems})
    cands = auto_pairs(
        stems,
        scores,
        neighbours=config.neighbours,
        place_candidates=config.place_candidates,
        max_links=max_links,
    )
    return cands, scores


def _register(
    client: Any,
    cands: list[Candidate],
    files: dict[str, str],
    config: SurveyConfig,
    progress: Progress,
    stored: dict[str, Any],
    phase: str = "links",
) -> list[Link]:
    prior = config.stored_poses == "prior"
    items = []
    for c in cands:
        seed = c.T_target_source  # a hand link's pose (or the rough positions'), else the
        if seed is None and prior:  # one the files store, if any
            seed = stored_T_target_source(stored, c.target, c.source)
        items.append((files[c.target], files[c.source], config.registration, c, seed))
    return run_tasks(
        client, align_link, items, on_result=OutcomeCounter(phase, len(items), progress)
    )


def _positioned(
    client: Any,
    found: list[Link],
    stores: tuple[dict[str, str], dict[str, Any]],
    config: SurveyConfig,
    priors: dict[str, Position],
    progress: Progress,
    new_pairs: tuple[list[str], int] = ([], 0),
) -> list[Link]:
    """Rough positions seed links and decide each link's pose (:func:`~flexreg.survey.
    positions.apply_positions`). The pairs of stations they put within ``proximity_m`` of
    each other that no link joins yet are linked as any pair is (``new_pairs``: the
    project's stems and at most how many), then every link they do not find confident near
    what they predict (:func:`~flexreg.survey.positions.unsettled`) is registered again:
    seeded with the pose the positions predict and bounded by their window
    (:func:`~flexreg.survey.positions.window_of`), the new result replacing the old unless
    it failed (a re-run reuses both from the cache)."""
    tried = {frozenset((e.target, e.source)) for e in found}
    stems, budget = new_pairs
    new = [
        Candidate(a, b, "positions")
        for a, b in near_pairs(stems, priors, config.proximity_m)
        if frozenset((a, b)) not in tried
    ][: max(0, budget)]
    if new:  # registered as any pair first: a confident answer needs no window
        found = found + _register(client, new, stores[0], config, progress, stores[1])
    redo = unsettled(found, priors)
    if redo:
        cands = [
            Candidate(
                e.target,
                e.source,
                e.origin,
                e.place_score,
                predicted_T_target_source(priors[e.target], priors[e.source]),
                window_of(priors[e.target], priors[e.source]),
            )
            for e in redo
        ]
        again = _register(client, cands, stores[0], config, progress, stores[1], "positions")
        by_id = {id(e): n for e, n in zip(redo, again, strict=True) if n.usable or not e.usable}
        found = [by_id.get(id(e), e) for e in found]
    apply_positions(found, priors)
    return found


def _check_inputs(
    paths: list[Path],
    reference: str | None,
    pairs: tuple[Path | None, bool, Sequence[HandLink] | None],
    cluster: tuple[int | None, str | None, str | None],
    origins_file: Path | None = None,
    frame: str = "reference",
    positions_file: Path | None = None,
) -> tuple[list[Station], _Given]:
    """What a survey refuses before any work: the cluster's options ``(workers, scheduler,
    dashboard)`` first (nothing read yet), then the stations, the reference, the pairs
    ``(pairs_file, add_pairs, links)`` and the origins (set on the stations they name).
    Returns the stations and the pairs and links given."""
    pairs_file, add_pairs, links = pairs
    workers, scheduler, dashboard = cluster
    if frame not in ("reference", "stored"):
        raise InputError("--frame", f"must be reference or stored (got {frame!r})")
    check_workers(workers, scheduler)
    dashboard_address(dashboard)
    stations = stations_of(find_scans(paths))
    if not stations:
        raise InputError(paths[0] if paths else "SCAN", "no scan files given")
    if len(stations) < 2:
        raise InputError(stations[0].path, "only one scan: a survey registers two or more stations")
    stems = [s.stem for s in stations]
    if reference is not None and reference not in stems:
        raise InputError("--reference", f"{reference!r} is not one of the stations")
    if add_pairs and pairs_file is None:
        raise InputError("add_pairs", "adds the pairs of a pairs_file: none given")
    given = _Given(
        None if pairs_file is None else read_pairs_csv(pairs_file, stems),
        add_pairs,
        hand_links(links or (), stems),
        {} if positions_file is None else read_positions_csv(positions_file, stems),
    )
    if origins_file is not None:
        origins = read_origins_csv(origins_file, stems)
        stations = [replace(st, origin=origins.get(st.stem)) for st in stations]
    return stations, given


def run_survey(
    paths: list[Path],
    out_dir: Path,
    config: SurveyConfig | None = None,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    dashboard: str | None = None,
    reference: str | None = None,
    pairs_file: Path | None = None,
    add_pairs: bool = False,
    links: Sequence[HandLink] | None = None,
    origins_file: Path | None = None,
    positions_file: Path | None = None,
    frame: Frame = "reference",
    progress: Progress = None,
) -> SurveyResult:
    """Register a project of stations; writes only ``out_dir/cache/``.

    Parameters
    ----------
    paths : list of Path
        Scan files and folders (:func:`~flexreg.survey.stations.find_scans`).
    out_dir : Path
        Output folder; prepared stations are cached in ``out_dir/cache/`` (on a path every
        worker sees when a scheduler is given).
    config : SurveyConfig, optional
    workers : int, optional
        Processes of the local cluster (default: this machine's cores; 1 runs here, without
        Dask). Ignored with ``scheduler``.
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:8786``).
    dashboard : str, optional
        ``[HOST:]PORT`` of the local cluster's dashboard (loopback unless a host is named;
        default: no dashboard).
    reference : str, optional
        The station whose frame the poses are in (default: the first station by name of the
        largest group).
    pairs_file : Path, optional
        CSV of ``target,source`` stems: exactly these links (with ``add_pairs``: these and
        the configuration's candidates, ``config.pairs``).
    add_pairs : bool
        Add the pairs of ``pairs_file`` to the configuration's candidates (a pair in both is
        registered once, as the file orients it) instead of trying only them; the proximity
        rounds of ``pairs="auto"`` run as without a file.
    links : sequence of (str, str, array_like or path-like), optional
        Links given by hand, ``(target, source, T_target_source)``: two stations (stems, or
        file names whose stem is a station) and the pose mapping the source into the target,
        as a 4x4 matrix or a transform file (4x4 text, a JSON with ``T_target_source``, a
        ``flexreg synth`` gt.json; :func:`~flexreg.io.transform_io.read_pair_transform`).
        Each is registered like any other link with that pose as its seed (refined, and it
        competes with what the images find on the dense check), in place of any other
        candidate of the same pair; its link's ``origin`` is ``"hand"``, and its cached
        result is reused only for the same transform.
    origins_file : Path, optional
        CSV of ``stem,x,y,z``: the scanner positions of stations whose points are in project
        coordinates (metres, in each file's frame); poses then come out in the files'
        coordinates (:mod:`flexreg.survey.frames`).
    positions_file : Path, optional
        CSV of ``stem,x,y,z,heading_deg,sigma_m``: rough positions of some or all stations
        (:mod:`flexreg.survey.positions`). Of each link between two of them they pick the
        one pose (its answer or an alternative) within three sigma, which then places
        stations as a confident link does; a link none of whose poses agrees is rejected.
        The poses come out in their site frame too (``T_site_station``).
    frame : {"reference", "stored"}
        ``stored``: the poses also in the site frame the files store (``T_site_station``).
    progress : callable, optional
        Called with a :class:`~flexreg.survey.execute.ProgressEvent` as tasks finish.

    Raises
    ------
    InputError
        A missing path, a folder without scans, one scan only, duplicate station names, an
        unknown ``reference``, a bad pairs file, ``add_pairs`` without one; a hand link
        naming an unknown station, a station with itself or a pair twice, or whose
        transform is unreadable or not rigid (naming its file); all before any work.
    ConfigError
        ``workers`` out of range, a bad ``dashboard`` or ``scheduler`` address (before any
        work), or a scheduler that cannot be reached.
    ClusterError
        The local Dask cluster did not start (a full disk, say); nothing written.
    RegistrationError
        Fewer than two readable stations.
    """
    config = config if config is not None else SurveyConfig()
    t_start = time.perf_counter()
    stations, given = _check_inputs(
        paths,
        reference,
        (pairs_file, add_pairs, links),
        (workers, scheduler, dashboard),
        origins_file,
        frame,
        positions_file,
    )
    cache = out_dir / "cache"
    timings: dict[str, float] = {}
    n_workers = 1 if workers == 1 and scheduler is None else (workers or default_workers())
    with dask_client(workers, scheduler, dashboard=dashboard) as client:
        if client is not None and scheduler is not None:
            n_workers = len(client.scheduler_info().get("workers", {})) or n_workers
        prepared, files, stored = _prepare(client, stations, cache, config, progress, timings)
        stems = [s.stem for s in stations if s.stem in files]
        t = time.perf_counter()
        max_links = max(1, int(config.max_links_per_station * len(stems)))
        cands, scores = _candidates(stems, files, config, given, max_links)
        timings["pairs"] = time.perf_counter() - t
        t = time.perf_counter()
        # rough positions, or rough stored poses: priors that decide between link poses
        priors = given.positions or stored_positions(stored, config.stored_sigma_m)
        found, sol, glances, judge = _link_rounds(
            client, stems, (files, stored), config, (given, cands, scores, max_links),
            (reference, priors), progress, timings,
        )  # fmt: skip
        timings["links"] = time.perf_counter() - t - timings.get("graph", 0.0)
        vetoes: list[Veto] = []
        looks: list[PairLook] = []
        if config.map_check:
            t = time.perf_counter()
            sol, looks = _map_check(
                client, stems, found, sol, (files, glances), config, (reference, priors),
                vetoes, judge, progress,
            )  # fmt: skip
            timings["map_check"] = time.perf_counter() - t
        if judge is not None:
            judge.keep()  # the map's looks, for a re-run
        adjustment = _final_alignment(client, sol, (found, looks), files, config, progress, timings)
    sol = _with_unreadable(sol, stations, prepared)
    log.info("survey: %d of %d stations placed", len(sol.groups[0]), len(stations))
    return SurveyResult(
        stations,
        prepared,
        found,
        sol,
        config,
        n_workers,
        time.perf_counter() - t_start,
        timings,
        adjustment is not None,
        stored,
        looks,
        vetoes,
        adjustment,
        frame,
        given.positions,
    )


def _link_rounds(
    client: Any,
    stems: list[str],
    stores: tuple[dict[str, str], dict[str, Any]],
    config: SurveyConfig,
    plan: tuple[_Given, list[Candidate], dict[frozenset[str], int], int],
    anchors: tuple[str | None, dict[str, Position]],
    progress: Progress,
    timings: dict[str, float],
) -> tuple[list[Link], GraphSolution, dict[str, str], PairJudge | None]:
    """The links of the candidates and their graph, then the proximity rounds (``stores``:
    prepared files, stored poses; ``plan``: given, candidates, place scores, most links;
    ``anchors``: the reference and the priors, rough positions or rough stored poses).
    The priors seed links and decide between their poses, and
    again with what the groups solved carry (``near``: their headings, fitted positions).
    Returns links, solution, glances, the map's judge; solves' seconds: timings["graph"]."""

    def solve(found: list[Link]) -> GraphSolution:
        t = time.perf_counter()
        sol = solve_graph(
            stems, found, config, reference=reference, judge=judge, fit=fit, positions=priors,
            full=judge.at_full if judge is not None else None,
        )  # fmt: skip
        timings["graph"] = timings.get("graph", 0.0) + time.perf_counter() - t
        return sol

    files, stored = stores
    given, cands, scores, max_links = plan
    reference, priors = anchors
    found = _register(client, cands, files, config, progress, stored)
    glances, judge = _glances(client, stems, files, config, progress)
    fit = judge.fit_groups if judge is not None else None
    budget = max_links - len(found) if given.automatic else 0  # a pairs CSV: its pairs only
    found = _positioned(client, found, stores, config, priors, progress, (stems, budget))
    sol, near = decide_with_groups(found, priors, solve(found), solve)
    auto = given.automatic and config.pairs == "auto"
    rounds = config.proximity_rounds if auto else 0
    maps = None if judge is None else (judge, config.map_min_conflict, config.map_conflict_ratio)
    for r in range(rounds):
        tried = {frozenset((e.target, e.source)) for e in found}
        more = later_pairs(
            *(stems, sol, found, tried, scores),
            reach_m=config.proximity_m,
            place_candidates=config.place_candidates,
            # the budget left shared by the rounds left: a round's placements bring the
            # next round's loops
            budget=(max_links - len(found)) // (rounds - r),
            judge=maps,
        )
        if not more:
            break
        found += _register(client, more, files, config, progress, stored)
        found = _positioned(client, found, stores, config, near, progress)
        sol, near = decide_with_groups(found, priors, solve(found), solve)
    return found, sol, glances, judge


def _prepare(
    client: Any,
    stations: list[Station],
    cache: Path,
    config: SurveyConfig,
    progress: Progress,
    timings: dict[str, float],
) -> tuple[dict[str, Prepared], dict[str, str], dict[str, Any]]:
    """Every station prepared (or found in ``cache``): the outcome and, of the readable
    ones, the prepared file and the pose the file stores (none with
    ``stored_poses="ignore"``). The stage's wall time, and the stations' reading and the
    rest of their preparation summed over them (worker time), go into ``timings``.

    Raises
    ------
    RegistrationError
        Fewer than two readable stations.
    """
    t = time.perf_counter()
    items = [(s, str(cache.resolve()), config.registration) for s in stations]
    done = run_tasks(
        client, prepare_station, items, on_result=OutcomeCounter("prepare", len(items), progress)
    )
    timings["prepare"] = time.perf_counter() - t
    timings["read_sum"] = sum(p.read_seconds for p in done)
    timings["prepare_sum"] = sum(p.seconds - p.read_seconds for p in done)
    files = {p.stem: p.cache_file for p in done if p.cache_file is not None}
    if len(files) < 2:
        bad = "; ".join(p.error or "" for p in done if p.error)
        raise RegistrationError(f"fewer than two readable stations ({bad})")
    ignore = config.stored_poses == "ignore"
    stored = {
        p.stem: p.T_world_scanner
        for p in done
        if p.T_world_scanner is not None and p.stem in files and not ignore
    }
    return {p.stem: p for p in done}, files, stored


def _final_alignment(
    client: Any,
    sol: GraphSolution,
    found: tuple[list[Link], list[PairLook]],
    files: dict[str, str],
    config: SurveyConfig,
    progress: Progress,
    timings: dict[str, float],
) -> Adjustment | None:
    """The final joint alignment (:mod:`flexreg.survey.adjust`) when on; its poses replace
    the solution's (in place). ``found``: the links and the last map check's pairs."""
    if not config.joint_refine:
        return None
    t = time.perf_counter()
    adjustment = adjust(client, sol, *found, files, config, progress)
    if adjustment is not None:
        sol.poses.update(adjustment.poses)
    timings["refine"] = time.perf_counter() - t
    return adjustment


def _map_check(
    client: Any,
    stems: list[str],
    links: list[Link],
    sol: GraphSolution,
    stored: tuple[dict[str, str], dict[str, str]],
    config: SurveyConfig,
    anchors: tuple[str | None, dict[str, Position]],
    vetoes: list[Veto],
    judge: PairJudge | None,
    progress: Progress,
) -> tuple[GraphSolution, list[PairLook]]:
    """Check every pair of placed stations (:mod:`flexreg.survey.mapcheck`), veto the
    conflicting ones and solve again, until no pair conflicts or ``map_rounds`` are used.
    ``stored``: the prepared files and glances per station; ``anchors``: the reference and
    the rough positions. Returns the solution and the last round's pair scores (``vetoes``
    grows in place)."""
    reference, positions = anchors
    looks: list[PairLook] = []
    rounds = config.map_rounds + 1
    for i in range(rounds):
        pairs = pairs_to_check(sol.groups, sol.poses, config.map_radius_m)
        looks = pair_looks(
            pairs,
            sol.poses,
            stored,
            judge,
            lambda fn, items: run_tasks(
                client, fn, items, on_result=OutcomeCounter("map check", len(items), progress)
            ),
        )
        bad = [p for p in looks if p.conflicts(config)]
        bad.sort(key=lambda p: -max(p.conflicting))
        found = [Veto(p.a, p.b, p.T_a_b, p.describe(config)) for p in bad]
        found += _unconfirmed_refuted(client, looks, sol, stored, config, judge, progress)
        if not found or i >= config.map_rounds:
            break
        vetoes.extend(found)
        log.info("map check: %d pair(s) of placed stations contradict each other", len(found))
        sol = solve_graph(stems, links, config, reference=reference, vetoes=vetoes, judge=judge,
                          fit=judge.fit_groups if judge is not None else None,
                          positions=positions,
                          full=judge.at_full if judge is not None else None)  # fmt: skip
    return sol, looks


def _unconfirmed_refuted(
    client: Any,
    looks: list[PairLook],
    sol: GraphSolution,
    stored: tuple[dict[str, str], dict[str, str]],
    config: SurveyConfig,
    judge: PairJudge | None,
    progress: Progress,
) -> list[Veto]:
    """Placements no loop confirms against the stations loops confirm, at full resolution
    (:func:`~flexreg.survey.mapcheck.unconfirmed_pairs`): the vetoes of the pairs refuted.
    ``judge`` remembers each pair and pose's test across the rounds and for later runs."""
    files, glances = stored
    assert judge is not None  # made with the glances whenever the map check runs
    todo = unconfirmed_pairs(looks, sol.confidence, config.map_min_conflict)
    new = [t for t in todo if judge.recall_full(*t) is None]
    results = run_tasks(
        client,
        open_space_at_full,
        [((files[a], files[b]), (glances[a], glances[b]), T) for a, b, T in new],
        on_result=OutcomeCounter("map check", len(new), progress),
    )
    for (a, b, T), r in zip(new, results, strict=True):
        judge.remember_full(a, b, T, r)
        at = np.round(T[:3], 4).ravel().tolist()
        log.debug("map check at full resolution %s - %s: %.4f open, %.4f seen %s", a, b, *r[:2], at)
    tests = [r for r in (judge.recall_full(*t) for t in todo) if r is not None]  # all made now
    limit = config.registration.judge.settle_open_share
    return refuted_at_full(todo, tests, sol.confidence, limit, config.map_min_conflict)


def _glances(
    client: Any, stems: list[str], files: dict[str, str], config: SurveyConfig, progress: Progress
) -> tuple[dict[str, str], PairJudge | None]:
    """Each station's glance (:func:`~flexreg.survey.mapcheck.write_glance`) for the map
    check, and the graph's loop judge; neither without the map check."""
    if not config.map_check:
        return {}, None
    made = run_tasks(
        client,
        write_glance,
        [(files[s],) for s in stems],
        on_result=OutcomeCounter("map check", len(stems), progress),
    )
    glances = {s: g for s, g in zip(stems, made, strict=True) if g is not None}
    return glances, PairJudge(files, glances, config)


def _with_unreadable(
    sol: GraphSolution, stations: list[Station], prepared: dict[str, Prepared]
) -> GraphSolution:
    """Unreadable stations as single groups at the end (so every station has a group)."""
    for s in stations:
        if prepared[s.stem].error is not None:
            sol.groups.append([s.stem])
            sol.group_reference.append(s.stem)
            sol.reasons[s.stem] = f"unreadable: {prepared[s.stem].error}"
    return sol


__all__ = ["SCHEMA", "SurveyResult", "run_survey"]
