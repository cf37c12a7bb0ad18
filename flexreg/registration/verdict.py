"""Whether a registration can be trusted: the decision (:func:`decide`) on its evidence
(:func:`flexreg.registration.evidence.gather`).

:func:`decide` turns the evidence into a :class:`~flexreg.core.results.Verdict` with one
:class:`~flexreg.core.results.Reason` per failed test; its thresholds are the ``judge`` table
of :class:`~flexreg.registration.config.RegistrationConfig`. Whether a duel between
two poses settles them is the dense check's (:func:`~flexreg.registration.check.decisive`,
:func:`~flexreg.registration.check.decisive_full`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any, Literal

import numpy as np

from flexreg.core.results import Hypothesis, Reason, Verdict
from flexreg.registration.check import decisive, decisive_full
from flexreg.registration.config import (
    MAX_RMSE_RATIO,
    MIN_INLIER_SPREAD,
    TWIN_MIN_RATIO,
    JudgeConfig,
)
from flexreg.registration.evidence import Evidence
from flexreg.stages.verification import AXES


def _along(v: Sequence[float]) -> str:
    """``"x"`` when one axis carries most of a direction, else the direction's components."""
    a = np.asarray(v, dtype=np.float64)
    n = float(np.linalg.norm(a))
    if n <= 0:
        return "an unknown direction"
    k = int(np.argmax(np.abs(a)))
    if abs(a[k]) >= 0.9 * n:
        return "xyz"[k]
    return "({:.2f}, {:.2f}, {:.2f}) of the target frame".format(*(a / n))


def _sweep_settled(ev: Evidence) -> bool:
    """Whether a sweep along the weak axis found every other position refuted at full
    resolution (:mod:`flexreg.registration.settle`)."""
    sw = ev.sweep or {}
    return bool(sw.get("kind") == "weak_axis" and sw.get("settled"))


def _overlap_reason(ev: Evidence, judge: JudgeConfig) -> Reason | None:
    o = ev.overlap
    if not o:
        return None
    s, t = o["source_explained"], o["target_explained"]
    if min(s, t) >= judge.min_overlap:
        return None
    return Reason(
        "low_overlap",
        f"only {100 * s:.0f}% of the source and {100 * t:.0f}% of the target are explained by "
        f"the other scan (need {100 * judge.min_overlap:.0f}% of each): the scans may "
        "hardly overlap",
    )


def _free_space_reason(ev: Evidence, judge: JudgeConfig) -> Reason | None:
    f = ev.free_space
    if not f:
        return None
    worst = max(f["source_conflicting"], f["target_conflicting"])
    ratio = max(f.get("source_conflict_ratio") or 0.0, f.get("target_conflict_ratio") or 0.0)
    if worst > judge.max_free_space:
        return Reason(
            "free_space",
            f"{100 * worst:.0f}% of one scan lands where the other scanner saw through empty "
            f"space (allowed {100 * judge.max_free_space:.0f}%): the pose puts surfaces in "
            "open space",
        )
    if ratio > judge.max_free_space_ratio:
        return Reason(
            "free_space",
            f"for every 100 points of one scan the other explains, {100 * ratio:.0f} land where "
            f"the other scanner saw through empty space (allowed "
            f"{100 * judge.max_free_space_ratio:.0f}): the pose contradicts much of what it "
            "fits",
        )
    return None


def _full_open_limit(ev: Evidence, judge: JudgeConfig) -> float:
    """The most of both scans' points the answer may put in open space at full resolution:
    ``judge.open_share`` where the settling compared the scans (a twin beside the truth is
    likely), ``judge.full_max_open_check`` for a confident answer checked anyway."""
    f = ev.full_resolution or {}
    return judge.full_max_open_check if f.get("why") == "check" else judge.open_share


def full_open_clear(ev: Evidence, judge: JudgeConfig = JudgeConfig()) -> bool | None:
    """Whether the answer, checked at full resolution, puts no more of both scans' points in
    the other's open space than the verdict allows there (:func:`_full_open_limit`); None
    when it was not checked there.

    A ``free_space`` reason of an answer that is clear here comes from the even sample's
    shares alone, which count a scanner's stray returns (mixed pixels between a rack and the
    wall behind it, one sample cell each) against right poses as well: on a hall of racks
    the right answers' ratio has a median of 0.23 (docs/benchmarks.md, "Mixed pixels in the
    dense check's sample"). Full resolution allows each point its own range step. It does not
    tell a pose a whole bay off (those contradict little there too), which is why the
    verdict keeps the sample's reason: only what decides between a link's poses by other
    means (rough positions) reads this.

    >>> ev = Evidence(full_resolution={"points": 1000, "open_space_share": 0.001,
    ...                                "why": "settling"})
    >>> full_open_clear(ev), full_open_clear(Evidence())
    (True, None)
    """
    f = ev.full_resolution
    if not f:
        return None
    return bool(f["open_space_share"] <= _full_open_limit(ev, judge))


def _full_open_reason(ev: Evidence, judge: JudgeConfig) -> Reason | None:
    """The answer puts more than :func:`_full_open_limit` of both scans' points in the
    other's open space at full resolution: one bay, aisle or room beside the right pose,
    which the samples' checks cannot tell."""
    f = ev.full_resolution
    if not f or full_open_clear(ev, judge):
        return None
    allowed = _full_open_limit(ev, judge)
    return Reason(
        "free_space",
        f"at full resolution {100 * f['open_space_share']:.2f}% of both scans' points land where "
        f"the other scanner saw through empty space (allowed {100 * allowed:.1f}%): the pose is "
        "contradicted, perhaps a bay or room beside the right one",
    )


def _inlier_reason(ev: Evidence, judge: JudgeConfig) -> Reason | None:
    """The agreeing feature matches lie in a narrow patch (their second principal spread
    under :data:`~flexreg.registration.config.MIN_INLIER_SPREAD` of the overlap's); not
    tested where the pose is not fitted to them (a plan overlay)."""
    i = ev.inliers
    if not i or not i.get("fit_to_matches", True):
        return None
    if i["count"] >= 3 and i["spread_ratio"] < MIN_INLIER_SPREAD:
        return Reason(
            "clustered_inliers",
            f"the {i['count']} agreeing feature matches lie in a narrow patch (spread "
            f"{i['std_principal_m'][1]:.2f} m across, the overlap "
            f"{i['overlap_std_principal_m'][1]:.2f} m): the pose may tilt about them",
        )
    return None


def _axis_reason(ev: Evidence, judge: JudgeConfig) -> Reason | None:
    a = ev.axis_strength
    if not a:
        return None
    weak = [k for k in AXES if a.get(k, 1.0) < judge.min_axis_strength]
    if not weak:
        return None
    limit = f"strength {min(a[k] for k in weak):.3f}, need {judge.min_axis_strength:g}"
    w = a.get("weakest", {})
    direction = _along(w.get("direction_target", ()))
    if any(k in ("x", "y", "z") for k in weak) and w.get("kind", "translation") == "translation":
        if _sweep_settled(ev):
            return None
        return Reason(
            "weak_axis",
            f"the scans constrain almost nothing along {direction} ({limit}; a corridor or "
            "tunnel?): the position along it is a guess",
        )
    return Reason(
        "weak_axis",
        f"the scans constrain almost no rotation about {direction} ({limit}; a round room or "
        "a single surface?): the angle about it is a guess",
    )


def _settled(u: dict[str, Any], ev: Evidence, judge: JudgeConfig) -> bool:
    """Whether the answer beats a runner-up decisively, on the samples or at full
    resolution (there only when the answer itself puts almost nothing in open space, or
    when the runner-up puts ``judge.settle_open_share`` of the points in open space, ten times
    what the answer does and what it refutes of the runner-up's)."""
    if "refuted_share" in u and decisive(u["refuted_share"], u["refuting_share"], judge):
        return True
    full = ev.full_resolution or {}
    own = full.get("open_space_share", 1.0)
    if (  # a runner-up full resolution refutes outright (a bay off in a repeating hall)
        u.get("full_refuted_share", 0.0) >= judge.settle_open_share
        and own <= judge.settle_open_share / 3
        and u["full_refuted_share"] >= 10 * max(u["full_refuting_share"], own)
    ):
        return True
    if own > judge.full_max_conflict:
        return False
    return "full_refuted_share" in u and decisive_full(
        u["full_refuted_share"], u["full_refuting_share"], judge, points=u.get("full_points", 0)
    )


def _ambiguity_reason(ev: Evidence, judge: JudgeConfig) -> Reason | None:
    rivals = [
        u
        for u in ev.runner_ups or ([ev.runner_up] if ev.runner_up else [])
        if u["score_ratio"] >= judge.ambiguity_ratio and not _settled(u, ev, judge)
    ]
    if not rivals:
        return None
    r = rivals[0]
    if r["rotation_deg"] > 10:
        what = f"turned {r['rotation_deg']:.0f}° from each other"
        cause = "symmetric structure"
    else:
        what = f"{r['translation_m']:.1f} m apart along {_along(r.get('offset_m', ()))}"
        cause = "repeating structure"
    return Reason(
        "ambiguous",
        f"two poses {what} fit almost equally well (the other scores {100 * r['score_ratio']:.0f}"
        f"% of the answer): {cause}",
    )


def _refuted_reason(ev: Evidence, judge: JudgeConfig) -> Reason | None:
    """A rival pose beats the answer :func:`decisive`-ly in their duel, whatever the scores."""
    beaten = [
        u for u in ev.rivals or () if decisive(u["refuting_share"], u["refuted_share"], judge)
    ]
    if not beaten:
        return None
    r = max(beaten, key=lambda u: u["refuting_share"] - u["refuted_share"])
    return Reason(
        "ambiguous",
        f"another pose {r['rotation_deg']:.0f}° / {r['translation_m']:.1f} m away explains "
        f"{100 * r['refuting_share']:.1f}% of the scans where this one puts surfaces in open "
        f"space (the reverse: {100 * r['refuted_share']:.1f}%): this pose is contradicted, "
        "perhaps an identical room or bay beside the right one",
    )


def _twin_reason(ev: Evidence, judge: JudgeConfig) -> Reason | None:
    """A twin of the answer fits (:mod:`flexreg.registration.twins`): it puts at most
    ``judge.twin_fit_open`` in open space and explains ``TWIN_MIN_RATIO`` of the answer's."""
    twins = ev.twins or {}
    a = twins.get("answer")
    if not a:
        return None
    limit = max(judge.twin_fit_open, 2 * a["open_share"])
    least = max(TWIN_MIN_RATIO * a["explained_share"], 1e-9)
    won, lost = "full_refuted_share", "full_refuting_share"
    fits = [  # a weak twin the answer beats on every pixel does not count
        t
        for t in twins.get("twins", ())
        if t["open_share"] <= limit
        and t["explained_share"] >= least
        and not decisive_full(
            t.get(won, 0.0), t.get(lost, 0.0), judge, points=t.get("full_points", 0)
        )
    ]
    if not fits:
        return None
    t = max(fits, key=lambda t: t["explained_share"])
    return Reason(
        "ambiguous",
        f"the answer moved {t['shift_m']:.1f} m along {_along(t['offset_m'])} fits too: it "
        f"explains {100 * t['explained_share']:.0f}% of both scans (the answer "
        f"{100 * a['explained_share']:.0f}%) and contradicts nothing more: repeating "
        "structure (identical bays or rooms) these two scans alone cannot tell apart",
    )


def _residual_reason(ev: Evidence, judge: JudgeConfig) -> Reason | None:
    r = ev.residual
    if not r or r.get("kind") == "open3d":
        return None
    if "inlier_rmse_m" in r and r["inlier_rmse_m"] is None:  # nothing paired: unmeasured
        return Reason(
            "high_residual",
            "after the refinement no point of either scan lies on the other's surfaces (no "
            "residual to measure): they do not meet",
        )
    if r.get("rmse_over_threshold") is None:
        return None
    if r["rmse_over_threshold"] <= MAX_RMSE_RATIO:
        return None
    return Reason(
        "high_residual",
        f"the surfaces still differ by {100 * r['inlier_rmse_m']:.1f} cm RMS (allowed "
        f"{100 * MAX_RMSE_RATIO * r['threshold_m']:.1f} cm): they do not meet closely",
    )


#: A verdict test: the reason it fails the evidence for, or None.
VerdictTest = Callable[[Evidence, JudgeConfig], "Reason | None"]

#: The tests in the order their reasons are listed: each pair is (test, the reason codes
#: already given that make it moot): a second ``free_space`` or ``ambiguous`` reason adds
#: nothing to the first.
TESTS: tuple[tuple[VerdictTest, tuple[str, ...]], ...] = (
    (_overlap_reason, ()),
    (_free_space_reason, ()),
    (_axis_reason, ()),
    (_ambiguity_reason, ()),
    (_full_open_reason, ("free_space",)),
    (_refuted_reason, ("ambiguous",)),
    (_twin_reason, ("ambiguous",)),
    (_inlier_reason, ()),
    (_residual_reason, ()),
)


def reasons(evidence: Evidence, judge: JudgeConfig = JudgeConfig()) -> list[Reason]:
    """Every reason the evidence gives for doubt (:data:`TESTS`, in order); a test whose
    evidence was not measured passes. What :func:`decide` decides on, and what the
    registration reads to measure more only where the answer still stands (the full
    resolution check, the twins).

    >>> [r.code for r in reasons(Evidence(overlap={"source_explained": 0.05,
    ...                                            "target_explained": 0.6}))]
    ['low_overlap']
    """
    out: list[Reason] = []
    for test, moot in TESTS:
        if any(r.code in moot for r in out):
            continue
        r = test(evidence, judge)
        if r is not None:
            out.append(r)
    return out


def _notes(evidence: Evidence, judge: JudgeConfig) -> list[Reason]:
    """What is worth knowing and does not make the answer uncertain: a weak axis a sweep
    settled, open space not tested in a cloud not taken from one point, a refinement the
    guard discarded."""
    notes: list[Reason] = []
    if _sweep_settled(evidence) and _axis_reason(evidence, judge) is None:
        a = evidence.axis_strength or {}
        if any(a.get(k, 1.0) < judge.min_axis_strength for k in ("x", "y", "z")):
            sw = evidence.sweep or {}
            notes.append(
                Reason(
                    "weak_axis_settled",
                    f"the surfaces constrain almost nothing along {_along(sw['direction_target'])}"
                    f", but of {sw['poses']} positions tried along it within "
                    f"{sw['range_m']:g} m every other one puts surfaces in open space where this "
                    "one fits them (a unique object decides)",
                )
            )
    blind = (evidence.free_space or {}).get("no_viewpoint") or {}
    if blind:
        which = " and ".join(f"the {k} hides {100 * v:.0f}%" for k, v in blind.items())
        notes.append(
            Reason(
                "free_space_unknown",
                f"open space not tested in the view of a cloud not taken from one point ({which}"
                " of its points behind its own, seen from its origin): the answer rests on the "
                "surfaces it explains and the other tests",
            )
        )
    ref = evidence.refinement
    if ref and not ref.get("kept", True):
        notes.append(
            Reason(
                "refinement_rejected",
                f"the ICP refinement was discarded: it scored {ref['score_refined']:.4f} "
                f"against {ref['score_coarse']:.4f} before it (the coarse transform is kept)",
            )
        )
    return notes


def decide(
    evidence: Evidence | Mapping[str, Any],
    runner_up: Sequence[Hypothesis] = (),
    judge: JudgeConfig = JudgeConfig(),
) -> Verdict:
    """The verdict on a registration's evidence: ``"uncertain"`` with one reason per failed
    test (:func:`reasons`), else ``"confident"``.

    Tests (thresholds: ``judge``, :class:`~flexreg.registration.config.JudgeConfig`):
    ``low_overlap`` (either scan explained less than ``min_overlap``),
    ``free_space`` (either conflicting more than ``max_free_space``, or more than
    ``max_free_space_ratio`` of what the other explains of it, or, where the scans were
    compared at full resolution, more than ``open_share`` of all their points in the other's
    open space), ``clustered_inliers`` (the agreeing matches' second principal spread below
    :data:`~flexreg.registration.config.MIN_INLIER_SPREAD` of the overlap's),
    ``weak_axis`` (a pose parameter's strength below ``min_axis_strength``),
    ``ambiguous`` (a clearly different pose scores at least ``ambiguity_ratio`` of the
    winner and the answer does not beat it decisively, or any rival pose beats the answer
    decisively in their duel, or the answer moved a whole bay fits too: :func:`_twin_reason`),
    ``high_residual`` (inlier RMSE above
    :data:`~flexreg.registration.config.MAX_RMSE_RATIO` inlier thresholds). A rejected
    refinement is a note, not a reason.

    Parameters
    ----------
    evidence : Evidence
        As :func:`~flexreg.registration.evidence.gather` measures it (a mapping of its
        sections, such as a result file's, is read with :meth:`Evidence.of`).
    runner_up : sequence of Hypothesis
    judge : JudgeConfig

    Returns
    -------
    Verdict

    Examples
    --------
    >>> v = decide(Evidence(overlap={"source_explained": 0.05, "target_explained": 0.6}))
    >>> v.status, [r.code for r in v.reasons]
    ('uncertain', ['low_overlap'])
    >>> decide(Evidence(overlap={"source_explained": 0.7, "target_explained": 0.6})).status
    'confident'
    """
    ev = evidence if isinstance(evidence, Evidence) else Evidence.of(evidence)
    found = reasons(ev, judge)
    status: Literal["confident", "uncertain"] = "uncertain" if found else "confident"
    return Verdict(status, tuple(found), ev, tuple(runner_up), tuple(_notes(ev, judge)))


__all__ = ["TESTS", "VerdictTest", "decide", "full_open_clear", "reasons"]
