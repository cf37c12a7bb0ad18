"""What the survey report reads from a poses document, and the project's figures.

The poses document is the content of ``DIR/poses.json`` (schema ``flexreg.survey/1``, described
in :mod:`flexreg.survey`). Everything here is pure: dicts in, numbers and words out, so the
report's figures can be checked without drawing a page.

Readers are lenient where the schema leaves room (an older engine, a hand-made document): a
verdict may be a status string or a ``Verdict.to_dict()``; the overlap a fraction or both
directions; the strength, inliers and RMSE may also come from the verdict's evidence. They are
strict where the report would otherwise lie: a link naming an unknown station or a transform
that is not a finite 4x4 matrix raises :class:`~flexreg.errors.InputError`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from numbers import Real
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.core.transforms import invert, rotation_error_deg
from flexreg.errors import InputError
from flexreg.registration.config import RegistrationConfig

__all__ = [
    "AXES",
    "KINDS",
    "LinkError",
    "ReportFigures",
    "check_document",
    "group_of",
    "link_errors",
    "link_inliers",
    "link_kind",
    "link_overlap",
    "link_pose_source",
    "link_reasons",
    "link_rmse",
    "link_strength",
    "report_figures",
    "station_pose",
    "station_reasons",
    "weak_axis_threshold",
]

#: the six pose parameters of a link's strength, in the order the report shows them
AXES = ("x", "y", "z", "roll", "pitch", "yaw")
#: kinds of link: accepted and confident, accepted and uncertain, rejected, failed
KINDS = ("confident", "uncertain", "rejected", "failed")

SOURCE = "poses document"


def _matrix(value: Any, what: str) -> NDArray[np.float64] | None:
    """A 4x4 transform from the document (None stays None)."""
    if value is None:
        return None
    try:
        M = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(SOURCE, f"{what} is not a 4x4 matrix of numbers") from None
    if M.shape != (4, 4) or not np.all(np.isfinite(M)):
        raise InputError(SOURCE, f"{what} is not a finite 4x4 matrix")
    return M


def check_document(doc: Any) -> None:
    """Raise :class:`InputError` when ``doc`` does not follow the poses schema: no
    ``stations`` object, no ``links`` list, a link naming an unknown station, a transform that
    is not a finite 4x4 matrix."""
    if not isinstance(doc, Mapping):
        raise InputError(SOURCE, "is not a JSON object")
    stations, links = doc.get("stations"), doc.get("links")
    if not isinstance(stations, Mapping) or not stations:
        raise InputError(SOURCE, "has no 'stations' object (one entry per station)")
    if not isinstance(links, list):
        raise InputError(SOURCE, "has no 'links' list")
    for stem, st in stations.items():
        if not isinstance(st, Mapping):
            raise InputError(SOURCE, f"station {stem!r} is not an object")
        for key in ("T_reference_station", "T_group_station"):
            _matrix(st.get(key), f"{key} of station {stem!r}")
    for i, lk in enumerate(links):
        if not isinstance(lk, Mapping):
            raise InputError(SOURCE, f"link {i} is not an object")
        for end in ("target", "source"):
            if lk.get(end) not in stations:
                raise InputError(SOURCE, f"link {i}: {end} {lk.get(end)!r} is not a station")
        _matrix(lk.get("T_target_source"), f"T_target_source of link {i}")


# --------------------------------------------------------------------------- one link


def _verdict(link: Mapping[str, Any]) -> dict[str, Any]:
    """The link's verdict as a dict (a bare status string becomes ``{"status": ...}``)."""
    v = link.get("verdict")
    if isinstance(v, Mapping):
        return dict(v)
    return {"status": v} if isinstance(v, str) else {}


def _texts(value: Any) -> list[str]:
    """Messages from a string, a ``{"code", "message"}`` dict or a list of them."""
    if value is None or value == "":
        return []
    if isinstance(value, str):
        return [value]
    if isinstance(value, Mapping):
        return [str(value.get("message") or value.get("code") or "")]
    if isinstance(value, Iterable):
        return [t for v in value for t in _texts(v)]
    return [str(value)]


def _unique(texts: Iterable[str]) -> list[str]:
    return list(dict.fromkeys(t for t in texts if t))


def link_kind(link: Mapping[str, Any]) -> str:
    """``"confident"`` or ``"uncertain"`` for an accepted link (by its verdict), else its
    status, ``"rejected"`` or ``"failed"`` (anything unknown counts as failed)."""
    status = str(link.get("status", "failed"))
    if status != "accepted":
        return status if status in KINDS else "failed"
    return "uncertain" if _verdict(link).get("status") == "uncertain" else "confident"


def link_reasons(link: Mapping[str, Any]) -> list[str]:
    """Why a link was rejected or failed (the engine's words first), then why its verdict is
    uncertain, each once."""
    own = [t for k in ("why", "reason", "error") for t in _texts(link.get(k))]
    return _unique(own + _texts(link.get("reasons")) + _texts(_verdict(link).get("reasons")))


def station_reasons(station: Mapping[str, Any]) -> list[str]:
    """Why a station is unplaced, unreadable or not verified, where its stored pose disagrees,
    in words, and its 1-sigma accuracy."""
    own = [t for k in ("reason", "why", "error", "status_why") for t in _texts(station.get(k))]
    acc = station.get("accuracy")
    if isinstance(acc, Mapping) and isinstance(acc.get("sigma_mm"), Mapping):
        own.append(
            "1σ "
            + " / ".join(f"{k} {_float(v) or 0.0:.1f}" for k, v in acc["sigma_mm"].items())
            + " mm"
            + (
                ""
                if acc.get("checked", True)
                else " (unchecked: it holds if the links that alone place it are right)"
            )
        )
    chk = station.get("stored_pose_check")
    if isinstance(chk, Mapping) and chk.get("agrees") is False:
        own.append(
            f"the pose stored in its file disagrees by {float(chk['rotation_deg']):.2f}° / "
            f"{float(chk['translation_m']):.3f} m"
        )
    return _unique(own)


def _evidence(link: Mapping[str, Any], *keys: str) -> Any:
    node: Any = _verdict(link).get("evidence") or {}
    for k in keys:
        if not isinstance(node, Mapping):
            return None
        node = node.get(k)
    return node


def _float(x: Any) -> float | None:
    """``x`` as a float when it is a real number (numpy's too), else None."""
    return float(x) if isinstance(x, Real) and not isinstance(x, bool) else None


def link_overlap(link: Mapping[str, Any]) -> tuple[float | None, float | None]:
    """(source explained by the target, target explained by the source), fractions 0..1; a
    single overlap figure stands for both when the link gives only that."""
    s, t = _float(link.get("overlap_source")), _float(link.get("overlap_target"))
    if s is not None or t is not None:
        return s, t
    o = link.get("overlap")
    if o is None:
        o = _evidence(link, "overlap")
    if isinstance(o, Mapping):
        return _float(o.get("source_explained")), _float(o.get("target_explained"))
    return _float(o), _float(o)


def link_inliers(link: Mapping[str, Any]) -> tuple[int | None, int | None]:
    """(inliers, matches tested)."""
    ev = _evidence(link, "inliers") or {}
    n = link.get("inliers", ev.get("count"))
    m = link.get("matches", ev.get("matches"))
    return (None if _float(n) is None else int(n), None if _float(m) is None else int(m))


def link_pose_source(link: Mapping[str, Any]) -> str | None:
    """Where the link's pose came from when feature matches did not make it (None: they did,
    or nothing says otherwise): a pose fitted to matches rests on at least three that agree,
    so fewer (or a verdict saying so) mean the plan views' overlay found it, or the poses the
    files store when the pair has them. Its inlier count is then no measure of the link.

    >>> T = np.eye(4).tolist()
    >>> link_pose_source({"T_target_source": T, "inliers": 0, "matches": 1})
    'pose from the plan view'
    >>> link_pose_source({"T_target_source": T, "inliers": 52, "matches": 211}) is None
    True
    """
    if link.get("T_target_source") is None:  # failed: no pose at all
        return None
    fit = _evidence(link, "inliers", "fit_to_matches")
    n, _ = link_inliers(link)
    if fit is True or (fit is None and (n is None or n >= 3)):
        return None
    stored = link.get("stored_deviation") is not None
    return "pose from the plan view" + (" or the stored poses" if stored else "")


def link_strength(link: Mapping[str, Any]) -> dict[str, float]:
    """Strength per pose parameter of :data:`AXES` (0 = not constrained, 1 = fully)."""
    s = link.get("strength")
    if not isinstance(s, Mapping):
        s = _evidence(link, "axis_strength") or {}
    return {a: v for a in AXES if (v := _float(s.get(a))) is not None}


def link_rmse(link: Mapping[str, Any]) -> float | None:
    """Cloud-to-cloud RMSE of the link's inliers, metres."""
    r = link.get("rmse_m")
    return _float(_evidence(link, "residual", "inlier_rmse_m") if r is None else r)


# --------------------------------------------------------------------------- stations


def group_of(station: Mapping[str, Any]) -> int | None:
    """The station's group number (None: unreadable, or no group given)."""
    g = _float(station.get("group"))
    return None if g is None else int(g)


def station_pose(station: Mapping[str, Any]) -> NDArray[np.float64] | None:
    """The station's pose in its group's frame: ``T_reference_station`` when placed, else
    ``T_group_station`` (a group that no link joins to the reference's), else None."""
    if station.get("placed"):
        T = _matrix(station.get("T_reference_station"), "T_reference_station")
        if T is not None:
            return T
    return _matrix(station.get("T_group_station"), "T_group_station")


def weak_axis_threshold(doc: Mapping[str, Any]) -> float:
    """The strength under which an axis counts as weak: the document's
    ``config.registration.judge.min_axis_strength`` when given (``verdict_min_axis_strength``
    in documents written before the judge's table), else the default."""
    cfg = doc.get("config")
    if isinstance(cfg, Mapping):
        reg = cfg.get("registration", cfg)
        if isinstance(reg, Mapping):
            judge = reg.get("judge")
            v = _float(judge.get("min_axis_strength") if isinstance(judge, Mapping) else None)
            v = v if v is not None else _float(reg.get("verdict_min_axis_strength"))
            if v is not None:
                return v
    return float(RegistrationConfig().judge.min_axis_strength)


# --------------------------------------------------------------------------- figures


@dataclass(frozen=True)
class LinkError:
    """How far an accepted link disagrees with the adjusted poses.

    Attributes
    ----------
    rotation_deg : float
        Angle between the link's rotation and the adjusted relative rotation, degrees.
    translation_m : float
        Distance between where the link and the adjusted poses put the source's origin, in
        the target's frame, metres.
    """

    rotation_deg: float
    translation_m: float


def _computed_error(doc: Mapping[str, Any], lk: Mapping[str, Any]) -> LinkError | None:
    t, s = doc["stations"][lk["target"]], doc["stations"][lk["source"]]
    Tt, Ts = station_pose(t), station_pose(s)
    Tl = _matrix(lk.get("T_target_source"), "T_target_source")
    if Tt is None or Ts is None or Tl is None or group_of(t) != group_of(s):
        return None
    D = invert(invert(Tt) @ Ts) @ Tl  # identity when the link agrees with the poses
    return LinkError(rotation_error_deg(D, np.eye(4)), float(np.linalg.norm(D[:3, 3])))


def link_errors(doc: Mapping[str, Any]) -> list[LinkError | None]:
    """The error of every accepted link against the adjusted poses (None for the others).

    The document's ``loop_error_deg`` / ``loop_error_m`` of an accepted link is this error
    (the engine measures it against its final poses); when a document lacks them, the error
    is computed from the poses: the angle of and the source-origin displacement by
    ``inv(inv(T_group_target) @ T_group_source) @ T_target_source``.

    Parameters
    ----------
    doc : dict
        A poses document.

    Returns
    -------
    list of LinkError or None
        One per ``doc["links"]``, in order.

    Examples
    --------
    >>> I = np.eye(4).tolist()
    >>> T = np.eye(4); T[0, 3] = 1.0
    >>> st = {"T_reference_station": I, "placed": True, "group": 0}
    >>> doc = {"stations": {"a": st, "b": dict(st, T_reference_station=T.tolist())},
    ...        "links": [{"target": "a", "source": "b", "status": "accepted",
    ...                   "T_target_source": I}]}
    >>> e = link_errors(doc)[0]
    >>> round(e.rotation_deg, 6), round(e.translation_m, 6)
    (0.0, 1.0)
    """
    out: list[LinkError | None] = []
    for lk in doc["links"]:
        if lk.get("status") != "accepted":
            out.append(None)
            continue
        if lk.get("loop_error") == "unchecked":  # it closes no loop: it fits by construction
            out.append(None)
            continue
        d, m = _float(lk.get("loop_error_deg")), _float(lk.get("loop_error_m"))
        out.append(LinkError(d, m) if d is not None and m is not None else _computed_error(doc, lk))
    return out


@dataclass(frozen=True)
class ReportFigures:
    """The figures of a whole project, as the report states them.

    Attributes
    ----------
    outcome : {"confident", "uncertain", "failed"}
        As the command's exit code says it: 0, 3 or 1.
    stations, placed : int
        All stations; those placed in the reference frame.
    groups : dict
        Group number -> its stations, in document order (unreadable stations belong to none).
    group_frames : dict
        Group number -> the station whose frame the group is solved in.
    links : dict
        Number of links of each kind of :data:`KINDS`.
    bundle_error_deg, bundle_error_m : float or None
        Root mean square of the accepted links' errors (None: no accepted link).
    mean_link_error_deg, mean_link_error_m, max_link_error_deg, max_link_error_m : float or None
    unplaced : list of str
        Stations not placed in the reference frame (other groups, no link, unreadable).
    uncertain_links : list of int
        Indices of the accepted links whose verdict is uncertain.
    problems : list of str
        The engine's one-line problems (``summary.problems``), when it gives them.
    status_line : str
        Stations per status on one line (``summary.status_line``; empty in older documents).
    """

    outcome: str
    stations: int
    placed: int
    groups: dict[int, list[str]]
    group_frames: dict[int, str]
    links: dict[str, int]
    bundle_error_deg: float | None
    bundle_error_m: float | None
    mean_link_error_deg: float | None
    mean_link_error_m: float | None
    max_link_error_deg: float | None
    max_link_error_m: float | None
    unplaced: list[str] = field(default_factory=list)
    uncertain_links: list[int] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    status_line: str = ""


def _groups(doc: Mapping[str, Any]) -> tuple[dict[int, list[str]], dict[int, str]]:
    """Group number -> stations (every station with a group number, also one alone in its
    group), and -> the station whose frame the group is solved in."""
    stations = doc["stations"]
    members: dict[int, list[str]] = {}
    for stem, st in stations.items():
        g = group_of(st)
        if g is not None:
            members.setdefault(g, []).append(stem)
    frames: dict[int, str] = {}
    for g in doc.get("groups") or []:
        if isinstance(g, Mapping) and _float(g.get("id")) is not None:
            frames[int(g["id"])] = str(g.get("reference", ""))
    reference = str(doc.get("reference", ""))
    for g, stems in members.items():
        if g not in frames:
            refs = [str(stations[s].get("group_reference") or "") for s in stems]
            frames[g] = reference if reference in stems else next((r for r in refs if r), stems[0])
    return dict(sorted(members.items())), {g: frames[g] for g in sorted(members)}


def _outcome(doc: Mapping[str, Any], placed: int, accepted: int, uncertain: bool) -> str:
    summary = doc.get("summary")
    code = summary.get("exit_status") if isinstance(summary, Mapping) else None
    if code in (0, 1, 3):
        return {0: "confident", 1: "failed", 3: "uncertain"}[code]
    if accepted == 0 or placed <= 1 < len(doc["stations"]):
        return "failed"
    return "uncertain" if uncertain else "confident"


def _stats(errs: Sequence[LinkError | None], doc: Mapping[str, Any]) -> dict[str, float | None]:
    """Bundle, mean and max link error: the document's summary when it gives them, else
    computed from ``errs``."""
    deg = np.array([e.rotation_deg for e in errs if e is not None])
    met = np.array([e.translation_m for e in errs if e is not None])
    out: dict[str, float | None] = {}
    for unit, a in (("deg", deg), ("m", met)):
        ok = len(a) > 0
        out[f"bundle_error_{unit}"] = math.sqrt(float(np.mean(a**2))) if ok else None
        out[f"mean_link_error_{unit}"] = float(np.mean(a)) if ok else None
        out[f"max_link_error_{unit}"] = float(np.max(a)) if ok else None
    summary = doc.get("summary")
    if isinstance(summary, Mapping):
        for k in out:
            if (v := _float(summary.get(k))) is not None:
                out[k] = v
    return out


def report_figures(
    doc: Mapping[str, Any], errors: Sequence[LinkError | None] | None = None
) -> ReportFigures:
    """The project's figures (see :class:`ReportFigures`).

    Parameters
    ----------
    doc : dict
        A poses document.
    errors : list of LinkError or None, optional
        From :func:`link_errors` (computed when not given).

    Raises
    ------
    InputError
        The document does not follow the schema (:func:`check_document`).
    """
    check_document(doc)
    errs = list(link_errors(doc) if errors is None else errors)
    stations = doc["stations"]
    kinds = [link_kind(lk) for lk in doc["links"]]
    groups, frames = _groups(doc)
    unplaced = [stem for stem, st in stations.items() if not st.get("placed")]
    uncertain = [i for i, k in enumerate(kinds) if k == "uncertain"]
    placed = len(stations) - len(unplaced)
    accepted = kinds.count("confident") + len(uncertain)
    summary = doc.get("summary")
    problems = _texts(summary.get("problems")) if isinstance(summary, Mapping) else []
    return ReportFigures(
        outcome=_outcome(doc, placed, accepted, bool(unplaced or uncertain)),
        stations=len(stations),
        placed=placed,
        groups=groups,
        group_frames=frames,
        links={k: kinds.count(k) for k in KINDS},
        unplaced=unplaced,
        uncertain_links=uncertain,
        problems=problems,
        status_line=str(summary.get("status_line") or "") if isinstance(summary, Mapping) else "",
        **_stats(errs, doc),
    )
