"""poses.json: the document of a survey's result (see :mod:`flexreg.survey` for its schema)."""

from __future__ import annotations

from typing import Any

import numpy as np

from flexreg._version import __version__
from flexreg.survey.frames import file_correction
from flexreg.survey.links import Link
from flexreg.survey.stations import Station
from flexreg.survey.stored import deviation, stored_T_target_source

SCHEMA = "flexreg.survey/1"


def poses_document(r: Any) -> dict[str, Any]:
    """The poses document (poses.json) of a :class:`~flexreg.survey.project.SurveyResult`."""
    sol = r.solution
    placed = set(r.placed)
    stations: dict[str, Any] = {}
    checks = r.stored_checks()
    T_site, what = r.site()
    for st in r.stations:
        stations[st.stem] = _station(r, st, placed, checks.get(st.stem))
        pose = sol.poses.get(st.stem) if st.stem in placed else None
        T = None if pose is None else T_site @ pose
        stations[st.stem]["origin"] = None if st.origin is None else list(st.origin)
        stations[st.stem]["T_site_station"] = None if T is None else T.tolist()
        stations[st.stem]["T_site_file"] = (
            None if T is None else file_correction(T, st.origin).tolist()
        )
    links = [_link(r, e) for e in r.links]
    count = {k: sum(e.status == k for e in r.links) for k in ("accepted", "rejected")}
    summary = {
        "stations": len(r.stations),
        "readable": sum(p.error is None for p in r.prepared.values()),
        "placed": len(placed),
        "unplaced": [s.stem for s in r.stations if s.stem not in placed],
        "groups": sum(1 for g in sol.groups if g and _readable(r, g[0])),
        "links_attempted": len(r.links),
        "links_accepted": count["accepted"],
        "links_rejected": count["rejected"],
        "links_failed": sum(e.status == "failed" for e in r.links),
        **sol.stats,
        **_bundle(r),
        "refined": r.refined,
        "statuses": r.status_counts(),
        "status_line": r.headline(),
        "tolerance_mm": r.config.tolerance_mm,
        "exit_status": r.exit_status,
        "problems": r.problems(),
        "wall_s": round(r.wall_s, 3),
        "timings_s": {k: round(v, 3) for k, v in r.timings_s.items()},
        "workers": r.workers,
        "prepared": sum(p.computed for p in r.prepared.values()),
        "from_cache": sum((not p.computed) and p.error is None for p in r.prepared.values()),
        "links_from_cache": sum(e.cached for e in r.links),
    }
    return {
        "schema": SCHEMA,
        "flexreg_version": __version__,
        "reference": sol.reference,
        "frame": {
            "kind": r.frame
            if r.frame == "stored"
            else "positions"
            if what.startswith("the site frame of the rough positions")
            else ("origins" if any(st.origin is not None for st in r.stations) else "reference"),
            "site": what,
            "T_site_reference": T_site.tolist(),
        },
        "stations": stations,
        "groups": _groups(r),
        "links": links,
        "map_check": _map_check(r),
        "final_alignment": _final(r),
        "summary": summary,
        "config": r.config.to_dict(),
    }


def _map_check(r: Any) -> dict[str, Any]:
    c = r.config
    return {
        "enabled": c.map_check,
        "pairs_checked": len(r.map_looks),
        "conflicting_now": [p.to_dict() for p in r.map_looks if p.conflicts(c)],
        "conflicts_found": [
            {"a": v.a, "b": v.b, "T_a_b": np.asarray(v.T_a_b).tolist(), "why": v.why}
            for v in r.vetoes
        ],
        "min_conflict": c.map_min_conflict,
        "conflict_ratio": c.map_conflict_ratio,
        "radius_m": c.map_radius_m,
    }


def _bundle(r: Any) -> dict[str, Any]:
    """The bundle error of the final alignment, over the pairs that close loops (the
    graph's own over its links when the alignment is off); how many it is over."""
    if r.adjustment is None:
        n = sum(e.status == "accepted" and e.loop_error_m is not None for e in r.links)
        return {"bundle_of": f"{n} accepted links that close loops"}
    fa = r.adjustment.summary()
    mm = fa["bundle_error_mm"]
    return {
        "bundle_error_m": None if mm is None else mm / 1e3,
        "bundle_error_deg": fa["bundle_error_deg"],
        "bundle_of": f"{fa['pairs_checked']} cloud-to-cloud pairs that close loops "
        f"({fa['pairs_unchecked']} unchecked)",
    }


def _final(r: Any) -> dict[str, Any] | None:
    adj = r.adjustment
    if adj is None:
        return None
    return {**adj.summary(), "pair_list": [p.to_dict() for p in adj.pairs]}


def _link(r: Any, e: Link) -> dict[str, Any]:
    d = e.to_dict()
    if e.status == "accepted" and e.loop_error_m is None:
        d["loop_error"] = "unchecked"  # it closes no loop: nothing to compare it with
    pair = _pair(r, e)
    if pair is not None:
        p = pair.to_dict()
        d["cloud_to_cloud"] = p.get("cloud_to_cloud")
        d["link_error"] = p["link_error"]
    T_stored = stored_T_target_source(r.stored, e.target, e.source)
    d["stored_deviation"] = (
        None
        if T_stored is None or e.T_target_source is None
        else deviation(e.T_target_source, T_stored)
    )
    return d


def _pair(r: Any, e: Link) -> Any:
    if r.adjustment is None:
        return None
    key = frozenset((e.target, e.source))
    return next((p for p in r.adjustment.pairs if frozenset((p.target, p.source)) == key), None)


def _readable(r: Any, stem: str) -> bool:
    return r.prepared[stem].error is None


def _groups(r: Any) -> list[dict[str, Any]]:
    sol, out = r.solution, []
    for i, g in enumerate(sol.groups):
        if g and _readable(r, g[0]):
            out.append(
                {
                    "id": i,
                    "reference": sol.group_reference[i],
                    "stations": list(g),
                    "placed": i == 0 and len(g) > 1,
                }
            )
    return out


def _station(r: Any, st: Station, placed: set[str], check: dict[str, Any] | None) -> dict[str, Any]:
    setup: dict[str, Any] = {"setup": st.setup, "setup_name": st.setup_name}
    acc = r.adjustment.accuracy.get(st.stem) if r.adjustment is not None else None
    setup["status"] = r.status(st.stem)
    setup["status_why"] = r.status_why(st.stem)
    setup["accuracy"] = (
        # its sigma holds when its links are right: only an independent route checks that
        {**acc.to_dict(), "checked": setup["status"] != "placed"}
        if acc is not None and st.stem in placed
        else None
    )
    T_stored = r.stored.get(st.stem)
    stored = {
        "T_world_station_stored": None if T_stored is None else np.asarray(T_stored).tolist(),
        "stored_pose_check": check,
    }
    return {**_station_core(r, st, placed), **setup, **stored}


def _station_core(r: Any, st: Station, placed: set[str]) -> dict[str, Any]:
    sol, p = r.solution, r.prepared[st.stem]
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
    mine = [e for e in r.links if st.stem in (e.target, e.source)]
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


__all__ = ["SCHEMA", "poses_document"]
