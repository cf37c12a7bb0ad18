""":func:`run_survey`: a whole project of stations, from scan files to poses.

Prepare every station once (cached), choose the candidate links, register them on Dask, solve
the graph, try the pairs the first solution suggests (stations whose solved positions are
close, unplaced stations' next candidates), optionally refine jointly, and return a
:class:`SurveyResult` whose :meth:`~SurveyResult.to_dict` is poses.json.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from flexreg._version import __version__
from flexreg.errors import InputError, RegistrationError
from flexreg.survey.config import SurveyConfig
from flexreg.survey.execute import (
    Progress,
    ProgressEvent,
    align_link,
    check_workers,
    dashboard_address,
    dask_client,
    default_workers,
    run_tasks,
)
from flexreg.survey.graph import GraphSolution, Link, Veto, solve_graph
from flexreg.survey.groupjoin import join_by_map
from flexreg.survey.mapcheck import (
    PairJudge,
    PairLook,
    assemble,
    look_from,
    pairs_to_check,
    plan_looks,
    write_glance,
)
from flexreg.survey.multiview import refine_links
from flexreg.survey.pairs import (
    Candidate,
    all_pairs,
    auto_pairs,
    place_scores,
    ranked_partners,
    read_pairs_csv,
    sequential_pairs,
)
from flexreg.survey.stations import (
    Prepared,
    Station,
    find_scans,
    load_descriptor,
    prepare_station,
    stations_of,
)
from flexreg.survey.stored import check_stations, deviation, stored_T_target_source

log = logging.getLogger(__name__)

SCHEMA = "flexreg.survey/1"


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
    refined : bool
    stored : dict
        Stored poses per station (``T_world_scanner``).
    map_looks : list of PairLook
        The last map check: every pair of placed stations scored at its solved pose.
    vetoes : list of Veto
        Every conflict the map checks found (each cut the most doubtful link between its
        two stations).
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

    def stored_checks(self) -> dict[str, dict[str, Any]]:
        """Every placed station against the pose its file stores
        (:func:`~flexreg.survey.stored.check_stations`); empty with ``stored_poses="ignore"``
        or fewer than two placed stations storing a pose."""
        sol = self.solution
        poses = {s: sol.poses[s] for s in self.placed if s in sol.poses}
        c = self.config
        return check_stations(poses, self.stored, c.stored_max_deg, c.stored_max_m)

    @property
    def placed(self) -> list[str]:
        """Stations with a pose in the reference frame (group 0 of two or more)."""
        g0 = self.solution.groups[0]
        return list(g0) if len(g0) > 1 else []

    def problems(self) -> list[str]:
        """One line per unreadable, unplaced or uncertainly placed station."""
        out = []
        for st in self.stations:
            p = self.prepared[st.stem]
            if p.error is not None:
                out.append(f"{st.stem}: unreadable: {p.error}")
            elif st.stem not in self.placed:
                out.append(f"{st.stem}: unplaced: {self.solution.reasons.get(st.stem, '')}")
            elif self.solution.confidence.get(st.stem) == "uncertain":
                out.append(
                    f"{st.stem}: placed only through uncertain links that a loop confirms; "
                    "check them"
                )
        for stem, chk in self.stored_checks().items():
            if not chk["agrees"]:
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
        for e in self.links:
            if e.status == "accepted" and e.verdict == "uncertain":
                codes = ", ".join(r.get("code", "?") for r in e.reasons) or "uncertain"
                out.append(
                    f"link {e.target} <- {e.source}: kept although uncertain ({codes})"
                    + ("; a loop confirms it" if e.confirmed_by_loop else "")
                    + (
                        "; it joins two groups as the only placement no station contradicts"
                        if e.map_joined
                        else ""
                    )
                )
        return out

    @property
    def exit_status(self) -> int:
        """0 every station placed and every kept link confident, 3 not (some station unplaced
        or unreadable, or some kept link uncertain), 1 nothing registered."""
        if not self.placed:
            return 1
        return 3 if self.problems() else 0

    def to_dict(self) -> dict[str, Any]:
        """The poses document (poses.json)."""
        sol = self.solution
        placed = set(self.placed)
        stations: dict[str, Any] = {}
        checks = self.stored_checks()
        for st in self.stations:
            stations[st.stem] = self._station(st, placed, checks.get(st.stem))
        links = [self._link(e) for e in self.links]
        count = {k: sum(e.status == k for e in self.links) for k in ("accepted", "rejected")}
        summary = {
            "stations": len(self.stations),
            "readable": sum(p.error is None for p in self.prepared.values()),
            "placed": len(placed),
            "unplaced": [s.stem for s in self.stations if s.stem not in placed],
            "groups": sum(1 for g in sol.groups if g and self._readable(g[0])),
            "links_attempted": len(self.links),
            "links_accepted": count["accepted"],
            "links_rejected": count["rejected"],
            "links_failed": sum(e.status == "failed" for e in self.links),
            **sol.stats,
            "refined": self.refined,
            "exit_status": self.exit_status,
            "problems": self.problems(),
            "wall_s": round(self.wall_s, 3),
            "timings_s": {k: round(v, 3) for k, v in self.timings_s.items()},
            "workers": self.workers,
            "prepared": sum(p.computed for p in self.prepared.values()),
            "from_cache": sum((not p.computed) and p.error is None for p in self.prepared.values()),
            "links_from_cache": sum(e.cached for e in self.links),
        }
        return {
            "schema": SCHEMA,
            "flexreg_version": __version__,
            "reference": sol.reference,
            "stations": stations,
            "groups": self._groups(),
            "links": links,
            "map_check": self._map_check(),
            "summary": summary,
            "config": self.config.to_dict(),
        }

    def _map_check(self) -> dict[str, Any]:
        c = self.config
        return {
            "enabled": c.map_check,
            "pairs_checked": len(self.map_looks),
            "conflicting_now": [p.to_dict() for p in self.map_looks if p.conflicts(c)],
            "conflicts_found": [
                {"a": v.a, "b": v.b, "T_a_b": np.asarray(v.T_a_b).tolist(), "why": v.why}
                for v in self.vetoes
            ],
            "min_conflict": c.map_min_conflict,
            "conflict_ratio": c.map_conflict_ratio,
            "radius_m": c.map_radius_m,
        }

    def _link(self, e: Link) -> dict[str, Any]:
        d = e.to_dict()
        T_stored = stored_T_target_source(self.stored, e.target, e.source)
        d["stored_deviation"] = (
            None
            if T_stored is None or e.T_target_source is None
            else deviation(e.T_target_source, T_stored)
        )
        return d

    def _readable(self, stem: str) -> bool:
        return self.prepared[stem].error is None

    def _groups(self) -> list[dict[str, Any]]:
        sol, out = self.solution, []
        for i, g in enumerate(sol.groups):
            if g and self._readable(g[0]):
                out.append(
                    {
                        "id": i,
                        "reference": sol.group_reference[i],
                        "stations": list(g),
                        "placed": i == 0 and len(g) > 1,
                    }
                )
        return out

    def _station(
        self, st: Station, placed: set[str], check: dict[str, Any] | None
    ) -> dict[str, Any]:
        setup = {"setup": st.setup, "setup_name": st.setup_name}
        T_stored = self.stored.get(st.stem)
        stored = {
            "T_world_station_stored": None if T_stored is None else np.asarray(T_stored).tolist(),
            "stored_pose_check": check,
        }
        return {**self._station_core(st, placed), **setup, **stored}

    def _station_core(self, st: Station, placed: set[str]) -> dict[str, Any]:
        sol, p = self.solution, self.prepared[st.stem]
        if p.error is not None:
            return {
                "file": str(st.path),
                "points": None,
                "placed": False,
                "T_reference_station": None,
                "group": None,
                "group_reference": None,
                "T_group_station": None,
                "degree": 0,
                "links_attempted": 0,
                "confidence": None,
                "reason": "unreadable",
                "error": p.error,
            }
        gi = sol.group_of(st.stem)
        pose = sol.poses.get(st.stem)
        mine = [e for e in self.links if st.stem in (e.target, e.source)]
        on = st.stem in placed
        return {
            "file": str(st.path),
            "points": p.points,
            "placed": on,
            "T_reference_station": pose.tolist() if on and pose is not None else None,
            "group": gi,
            "group_reference": sol.group_reference[gi],
            "T_group_station": pose.tolist() if pose is not None else None,
            "degree": sum(e.status == "accepted" for e in mine),
            "links_attempted": len(mine),
            "confidence": sol.confidence.get(st.stem) if on else None,
            "reason": None if on else sol.reasons.get(st.stem),
            "error": None,
        }


def _candidates(
    stems: list[str],
    files: dict[str, str],
    config: SurveyConfig,
    pairs_file: Path | None,
    max_links: int,
) -> tuple[list[Candidate], dict[frozenset[str], int]]:
    if pairs_file is not None:
        return read_pairs_csv(pairs_file, stems), {}
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


def _more_candidates(
    stems: list[str],
    sol: GraphSolution,
    tried: set[frozenset[str]],
    scores: dict[frozenset[str], int],
    config: SurveyConfig,
    budget: int,
) -> list[Candidate]:
    """Pairs the solution suggests: close solved positions in one group (loops), then each
    unplaced station's next place-recognition partners."""
    order = {s: i for i, s in enumerate(stems)}
    near: list[tuple[float, str, str]] = []
    for g in sol.groups:
        for i, a in enumerate(g):
            for b in g[i + 1 :]:
                if frozenset((a, b)) in tried or a not in sol.poses or b not in sol.poses:
                    continue
                d = float(np.linalg.norm(sol.poses[a][:3, 3] - sol.poses[b][:3, 3]))
                if d <= config.proximity_m:
                    near.append((d, a, b))
    near.sort(key=lambda t: (t[0], order[t[1]], order[t[2]]))
    out = []
    for _, a, b in near:
        t, src = sorted((a, b), key=order.__getitem__)
        out.append(Candidate(t, src, "proximity", _score(scores, t, src)))
    unplaced = [s for g in sol.groups[1:] for s in g] if len(sol.groups[0]) > 1 else list(stems)
    for s in unplaced:
        extra = [
            (o, sc)
            for o, sc in ranked_partners(s, stems, scores)
            if frozenset((s, o)) not in tried and sc > 0
        ][: config.place_candidates]
        for o, sc in extra:
            t, src = sorted((s, o), key=order.__getitem__)
            out.append(Candidate(t, src, "place", float(sc)))
    seen: set[frozenset[str]] = set()
    unique = []
    for c in out:
        if c.key not in seen:
            seen.add(c.key)
            unique.append(c)
    return unique[:budget]


def _score(scores: dict[frozenset[str], int], a: str, b: str) -> float | None:
    v = scores.get(frozenset((a, b)))
    return None if v is None else float(v)


class _Counter:
    """Counts link outcomes and reports progress."""

    def __init__(self, phase: str, total: int, progress: Progress) -> None:
        self.phase, self.total, self.progress = phase, total, progress
        self.done = self.confident = self.uncertain = self.failed = 0
        self.t0 = time.perf_counter()
        self._emit()

    def _emit(self) -> None:
        if self.progress is not None:
            self.progress(
                ProgressEvent(
                    self.phase,
                    self.done,
                    self.total,
                    self.confident,
                    self.uncertain,
                    self.failed,
                    time.perf_counter() - self.t0,
                )
            )

    def __call__(self, _: int, result: Any) -> None:
        self.done += 1
        if isinstance(result, Link):
            if result.T_target_source is None:
                self.failed += 1
            elif result.verdict == "confident":
                self.confident += 1
            else:
                self.uncertain += 1
        elif isinstance(result, Prepared) and result.error is not None:
            self.failed += 1
        self._emit()


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
    items = [
        (
            files[c.target],
            files[c.source],
            config.registration,
            c,
            stored_T_target_source(stored, c.target, c.source) if prior else None,
        )
        for c in cands
    ]
    return run_tasks(client, align_link, items, on_result=_Counter(phase, len(items), progress))


def _check_inputs(
    paths: list[Path],
    reference: str | None,
    pairs_file: Path | None,
    cluster: tuple[int | None, str | None, str | None],
) -> list[Station]:
    """What a survey refuses before any work: the cluster's options ``(workers, scheduler,
    dashboard)`` first (nothing read yet), then the stations, the reference and the pairs."""
    workers, scheduler, dashboard = cluster
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
    if pairs_file is not None:
        read_pairs_csv(pairs_file, stems)
    return stations


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
        The station whose frame the poses are in (default: the best connected).
    pairs_file : Path, optional
        CSV of ``target,source`` stems: exactly these links.
    progress : callable, optional
        Called with a :class:`~flexreg.survey.execute.ProgressEvent` as tasks finish.

    Raises
    ------
    InputError
        A missing path, a folder without scans, one scan only, duplicate station names, an
        unknown ``reference``, a bad pairs file; all before any work.
    ConfigError
        ``workers`` out of range, a bad ``dashboard`` or ``scheduler`` address (before any
        work), or a scheduler that cannot be reached.
    RegistrationError
        Fewer than two readable stations.
    """
    config = config if config is not None else SurveyConfig()
    t_start = time.perf_counter()
    stations = _check_inputs(paths, reference, pairs_file, (workers, scheduler, dashboard))
    cache = out_dir / "cache"
    timings: dict[str, float] = {}
    n_workers = 1 if workers == 1 and scheduler is None else (workers or default_workers())
    with dask_client(workers, scheduler, dashboard=dashboard) as client:
        if client is not None and scheduler is not None:
            n_workers = len(client.scheduler_info().get("workers", {})) or n_workers
        t = time.perf_counter()
        items = [(s, str(cache.resolve()), config.registration) for s in stations]
        prepared_list = run_tasks(
            client, prepare_station, items, on_result=_Counter("prepare", len(items), progress)
        )
        timings["prepare"] = time.perf_counter() - t
        prepared = {p.stem: p for p in prepared_list}
        files = {p.stem: p.cache_file for p in prepared_list if p.cache_file is not None}
        stems = [s.stem for s in stations if s.stem in files]
        if len(stems) < 2:
            bad = "; ".join(p.error or "" for p in prepared_list if p.error)
            raise RegistrationError(f"fewer than two readable stations ({bad})")
        t = time.perf_counter()
        max_links = max(1, int(config.max_links_per_station * len(stems)))
        cands, scores = _candidates(stems, files, config, pairs_file, max_links)
        timings["pairs"] = time.perf_counter() - t
        t = time.perf_counter()
        stored = (
            {}
            if config.stored_poses == "ignore"
            else {
                p.stem: p.T_world_scanner
                for p in prepared_list
                if p.T_world_scanner is not None and p.stem in files
            }
        )
        links = _register(client, cands, files, config, progress, stored)
        glances, judge = _glances(client, stems, files, config, progress)
        sol = solve_graph(stems, links, config, reference=reference, judge=judge)
        auto = pairs_file is None and config.pairs == "auto"
        for _ in range(config.proximity_rounds if auto else 0):
            tried = {frozenset((e.target, e.source)) for e in links}
            more = _more_candidates(stems, sol, tried, scores, config, max_links - len(links))
            if not more:
                break
            links += _register(client, more, files, config, progress, stored)
            sol = solve_graph(stems, links, config, reference=reference, judge=judge)
        timings["links"] = time.perf_counter() - t
        vetoes: list[Veto] = []
        looks: list[PairLook] = []
        if config.map_check:
            t = time.perf_counter()
            sol, looks = _map_check(
                client,
                stems,
                links,
                sol,
                (files, glances),
                config,
                reference,
                vetoes,
                judge,
                progress,
            )
            timings["map_check"] = time.perf_counter() - t
        if config.joint_refine:
            t = time.perf_counter()
            for _ in range(config.refine_iterations):
                refine_links(client, sol, links, files, config, progress)
                sol = solve_graph(
                    stems, links, config, reference=reference, vetoes=vetoes, judge=judge
                )
            timings["refine"] = time.perf_counter() - t
    sol = _with_unreadable(sol, stations, prepared)
    log.info("survey: %d of %d stations placed", len(sol.groups[0]), len(stations))
    return SurveyResult(
        stations,
        prepared,
        links,
        sol,
        config,
        n_workers,
        time.perf_counter() - t_start,
        timings,
        config.joint_refine,
        stored,
        looks,
        vetoes,
    )


def _map_check(
    client: Any,
    stems: list[str],
    links: list[Link],
    sol: GraphSolution,
    stored: tuple[dict[str, str], dict[str, str]],
    config: SurveyConfig,
    reference: str | None,
    vetoes: list[Veto],
    judge: PairJudge | None,
    progress: Progress,
) -> tuple[GraphSolution, list[PairLook]]:
    """Check every pair of placed stations (:mod:`flexreg.survey.mapcheck`), veto the
    conflicting ones and solve again, until no pair conflicts or ``map_rounds`` are used.
    ``stored``: the prepared files and glances per station. Returns the solution and the
    last round's pair scores (``vetoes`` grows in place)."""
    files, glances = stored
    looks: list[PairLook] = []
    rounds = config.map_rounds + 1 + (len(sol.groups) if config.map_joins_groups else 0)
    for i in range(rounds):
        pairs = pairs_to_check(sol.groups, sol.poses, config.map_radius_m)
        todo = plan_looks(pairs, sol.poses, glances)
        order = sorted(todo)
        results = run_tasks(
            client,
            look_from,
            [(files[a], glances[a], todo[a]) for a in order],
            on_result=_Counter("map check", len(order), progress),
        )
        seen = {a: {b: (x, c, n) for b, x, c, n in r} for a, r in zip(order, results, strict=True)}
        looks = assemble(pairs, sol.poses, seen)
        bad = [p for p in looks if p.conflicts(config)]
        if not bad:  # a consistent map: may a separate group join it in one place only?
            joins = (
                join_by_map(sol, links, judge, config)
                if judge is not None and config.map_joins_groups and i < rounds - 1
                else []
            )
            if not joins:
                break
            for e, _ in joins:
                e.map_joined = True
            sol = solve_graph(stems, links, config, reference=reference, vetoes=vetoes, judge=judge)
            continue
        if i >= config.map_rounds:
            break
        bad.sort(key=lambda p: -max(p.conflicting))
        vetoes.extend(Veto(p.a, p.b, p.T_a_b, p.describe(config)) for p in bad)
        log.info("map check: %d pair(s) of placed stations contradict each other", len(bad))
        sol = solve_graph(stems, links, config, reference=reference, vetoes=vetoes, judge=judge)
    return sol, looks


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
        on_result=_Counter("map check", len(stems), progress),
    )
    glances = {s: g for s, g in zip(stems, made, strict=True) if g is not None}
    return glances, PairJudge(files, glances, config) if config.map_judges_loops else None


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
