"""The evidence of a registration: what the dense check (:mod:`flexreg.registration.check`)
measures on the final transform (:func:`gather`).

The evidence is measured with inputs the registration has already prepared: each scan's
view (range image, what it measured, range slack, normals) and each scan's even sample. It
answers, in numbers with units in their keys:

* ``overlap``: how much of each scan the other explains (both directions);
* ``free_space``: how much of each lies where the other scanner saw through empty space;
* ``inliers``: how many feature matches agree and how they spread in 3D;
* ``axis_strength``: how firmly the overlap's surfaces fix each of the six pose parameters
  (a corridor fixes nothing along its axis);
* ``runner_up``: the best clearly different candidate pose and its score against the winner;
* ``residual``: how closely the surfaces meet; ``refinement``: whether ICP was kept;
* measured only where it tells something (:func:`flexreg.registration.pipeline.register`
  gates them on the sample evidence): ``full_resolution``, ``sweep``, ``twins``.

It is held in one frozen :class:`Evidence`, measured once per registration before the single
decision (:func:`flexreg.registration.verdict.decide`).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.core.range_image import RangeImage
from flexreg.core.results import Hypothesis
from flexreg.core.transforms import invert, rotation_error_deg, translation_error_m
from flexreg.registration.check import TOLERANCE, Judged, Masks, Scored, TwoWay, duel, duel_masks
from flexreg.registration.config import JudgeConfig
from flexreg.registration.fullres import FullPair, pose_masks
from flexreg.stages.verification import AXES, axis_strength, plane_information, spread

#: most runner-up poses listed
MAX_RUNNER_UPS = 3

#: most other candidate poses the answer duels (``rivals`` of :func:`gather`)
MAX_RIVALS = 8


#: sections every evidence has (null when not measured), in the order results show them;
#: the others (``full_resolution``, ``sweep``, ``runner_ups``, ``twins``) only when measured
ALWAYS = (
    "overlap",
    "free_space",
    "inliers",
    "axis_strength",
    "runner_up",
    "candidates",
    "residual",
    "refinement",
)


@dataclass(frozen=True)
class Evidence(Mapping[str, Any]):
    """What a registration's checks measured on its answer, one attribute per section (each
    JSON-ready, units in its keys; see :func:`gather`). Read it by attribute; as a mapping
    it is the JSON the results store (:meth:`to_dict`), sections not measured left out.

    Attributes
    ----------
    overlap, free_space, inliers, axis_strength, residual, refinement : dict or None
    runner_up : dict or None
        The best clearly different candidate (the first of ``runner_ups``).
    candidates : int or None
        How many candidate poses were judged.
    full_resolution : dict or None
        The answer's open-space share at full resolution, and why the scans were compared
        there (:func:`full_evidence`).
    sweep : dict or None
        What the sweep along a weak axis or a repeat did.
    runner_ups, rivals : list of dict or None
        The close runner-ups and every rival the answer dueled.
    twins : dict or None
        The answer slid along the walls (:func:`flexreg.registration.twins.find_twins`).
    """

    overlap: dict[str, Any] | None = None
    free_space: dict[str, Any] | None = None
    inliers: dict[str, Any] | None = None
    axis_strength: dict[str, Any] | None = None
    runner_up: dict[str, Any] | None = None
    candidates: int | None = None
    residual: dict[str, Any] | None = None
    refinement: dict[str, Any] | None = None
    full_resolution: dict[str, Any] | None = None
    sweep: dict[str, Any] | None = None
    runner_ups: list[dict[str, Any]] | None = None
    rivals: list[dict[str, Any]] | None = None
    twins: dict[str, Any] | None = None

    @classmethod
    def of(cls, sections: Mapping[str, Any]) -> Evidence:
        """Evidence from its JSON (a result file's, or a hand-made case's).

        >>> Evidence.of({"overlap": {"source_explained": 0.5}}).overlap
        {'source_explained': 0.5}
        """
        known = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in sections.items() if k in known})

    def _keys(self) -> list[str]:
        return [
            f.name
            for f in fields(self)
            if f.name in ALWAYS or f.name == "rivals" or getattr(self, f.name) is not None
        ]

    def __getitem__(self, key: str) -> Any:
        if key not in self._keys():
            raise KeyError(key)
        return getattr(self, key)

    def __iter__(self) -> Iterator[str]:
        return iter(self._keys())

    def __len__(self) -> int:
        return len(self._keys())

    def to_dict(self) -> dict[str, Any]:
        """The JSON the results store."""
        return {k: getattr(self, k) for k in self._keys()}

    @property
    def doubt(self) -> float | None:
        """The larger free-space conflict ratio (share of a scan in the other's free space
        over the share the other explains, either direction), or None when unknown.

        >>> Evidence(free_space={"source_conflict_ratio": 0.1, "target_conflict_ratio": 0.3}).doubt
        0.3
        """
        fs = self.free_space or {}
        vals = [
            float(fs[k])
            for k in ("source_conflict_ratio", "target_conflict_ratio")
            if fs.get(k) is not None
        ]
        return max(vals) if vals else None

    @property
    def strengths(self) -> dict[str, float]:
        """Each pose parameter's strength (``x`` ... ``rz``, per point) that was measured."""
        s = self.axis_strength or {}
        return {a: float(s[a]) for a in AXES if a in s and s[a] is not None}


def _frac(mask: NDArray[np.bool_]) -> float:
    return float(mask.mean()) if len(mask) else 0.0


def _r(x: float, nd: int = 4) -> float:
    return round(float(x), nd)


def _vec(v: NDArray[np.float64], nd: int = 4) -> list[float]:
    return [round(float(x), nd) for x in v]


def _residual(rmse_m: float, fitness: float, threshold_m: float, kind: str) -> dict[str, Any]:
    """The evidence's ``residual`` section; the RMSE and its ratio None (never NaN) when no
    point paired after the refinement, so that no residual was measured."""
    measured = bool(np.isfinite(rmse_m))
    return {
        "inlier_rmse_m": _r(rmse_m, 5) if measured else None,
        "fitness": _r(fitness),
        "threshold_m": _r(threshold_m, 5),
        "rmse_over_threshold": _r(rmse_m / threshold_m) if measured and threshold_m > 0 else None,
        "kind": kind,
    }


def runner_ups(
    judged: Sequence[Judged],
    T: NDArray[np.float64],
    top: float,
    judge: JudgeConfig,
    *,
    ratio: float,
    limit: int = MAX_RUNNER_UPS,
) -> list[Hypothesis]:
    """The best candidates clearly different from ``T`` (:meth:`JudgeConfig.distinct`, and
    from each other), best first: always the best one, then any others whose score is at
    least ``ratio`` of the winner's ``top`` (at most ``limit``)."""
    far = judge.distinct
    out: list[Hypothesis] = []
    for j in sorted(judged, key=lambda j: -j.score):
        if not far(j.T_target_source, T) or any(
            not far(j.T_target_source, h.T_target_source) for h in out
        ):
            continue
        rel = j.score / top if top > 1e-9 else (1.0 if j.score >= top else 0.0)
        if out and rel < ratio:
            break
        out.append(
            Hypothesis(
                np.array(j.T_target_source, dtype=np.float64),
                _r(rel),
                _r(rotation_error_deg(j.T_target_source, T), 3),
                _r(translation_error_m(j.T_target_source, T), 3),
                j.origin,
            )
        )
        if len(out) >= limit:
            break
    return out


def _strength(
    target: RangeImage, normals: NDArray[np.float32] | None, q: NDArray[np.float64]
) -> dict[str, Any]:
    """Per-axis constraint strength of the overlap's points ``q`` (target frame)."""
    if normals is None or len(q) < 6:
        return {a: 0.0 for a in AXES} | {"points": len(q)}
    info, c, n = plane_information(target, normals, q)
    d2 = (q - c) ** 2
    # lever arm of each rotation: RMS distance of the points from that axis
    lever = np.sqrt(np.mean(d2.sum(axis=1)[:, None] - d2, axis=0))
    s, weakest, d = axis_strength(info, n, lever)
    kind = "translation" if np.linalg.norm(d[3:]) >= np.linalg.norm(d[:3]) else "rotation"
    part = d[3:] if kind == "translation" else d[:3]
    part = part / (np.linalg.norm(part) or 1.0)
    if part[int(np.argmax(np.abs(part)))] < 0:
        part = -part
    return {a: _r(v) for a, v in zip(AXES, s, strict=True)} | {
        "points": int(n),
        "lever_arm_m": _vec(lever, 3),
        "weakest": {
            "strength": _r(weakest),
            "kind": kind,
            "direction_target": _vec(part, 3),
        },
    }


def _no_viewpoint(two: TwoWay) -> dict[str, float]:
    """The clouds not taken from one point (``target``, ``source``) and the share of their
    points hidden behind their own from their origin: nothing is tested for open space in
    their view (:attr:`~flexreg.registration.check.Check.free_space`)."""
    sides = (("target", two.forward), ("source", two.backward))
    return {k: _r(c.hidden) for k, c in sides if not c.free_space and c.hidden is not None}


def gather(
    two: TwoWay,
    final: Scored,
    *,
    target_normals: NDArray[np.float32] | None,
    inlier_points: NDArray[np.float64],
    matches: int,
    fit_to_matches: bool,
    runner_up: Sequence[Hypothesis],
    candidates: int,
    inlier_rmse_m: float,
    fitness: float,
    threshold_m: float,
    residual_kind: str = "point-to-plane",
    refinement: dict[str, Any] | None,
    rivals: Sequence[Hypothesis] = (),
    full: FullPair | None = None,
    full_ratio: float = 0.6,
    sweep: dict[str, Any] | None = None,
) -> Evidence:
    """The evidence of a registration (JSON-ready sections, units in the keys).

    Parameters
    ----------
    two : TwoWay
        Both scans' views and samples.
    final : Scored
        The final transform scored in both directions
        (:meth:`~flexreg.registration.check.TwoWay.score`).
    target_normals : (H, W, 3) float32 or None
        The target's grid normals (for the per-axis strength).
    inlier_points : (K, 3) float64, metres
        The inlier feature matches' target points.
    matches : int
        Feature matches tested.
    fit_to_matches : bool
        Whether the coarse transform was fitted to the matches (not so for a plan overlay
        alone: then the matches do not carry the pose and their count is not tested).
    runner_up : sequence of Hypothesis
        From :func:`runner_ups`.
    candidates : int
        How many candidate poses were judged.
    inlier_rmse_m, fitness, threshold_m : float
        The final stage's residual and overlap, and the inlier threshold.
    residual_kind : {"point-to-plane", "keypoints", "open3d"}
        What ``inlier_rmse_m`` measures: point-to-plane residuals (projective refinement),
        keypoint residuals (no refinement kept), or Open3D's distances between voxel samples
        of the two clouds (GICP, point-to-point: they grow with the voxel, not with the misfit,
        so the residual test skips them).
    refinement : dict or None
        Whether the refinement was kept and the scores (None: not refined).
    rivals : sequence of Hypothesis
        Every other clearly different candidate worth a duel (:func:`runner_ups` without a
        score limit, at most :data:`MAX_RIVALS`): under ``"rivals"`` the answer's
        :func:`~flexreg.registration.check.duel` against each, whatever its overall score. A
        rival that explains what the answer puts in open space refutes it, even when it
        overlaps less (the true pose of two stations that barely see each other, against a
        wrong pose that overlays two identical rooms).
    full : FullPair, optional
        Both scans at full resolution: the answer's own open-space share there is recorded
        (:func:`full_evidence`), and each runner-up scoring at least ``full_ratio`` of the
        answer also duels it there (``full_refuted_share``, ``full_refuting_share``, shares of
        ``full_points``; :mod:`flexreg.registration.fullres`).
    full_ratio : float
    sweep : dict, optional
        What the sweep along a weak axis or a repeat did
        (:class:`~flexreg.registration.settle.Settlement`), with ``settled``: the answer
        beat every close slid pose at full resolution.
    """
    _, qf, okf, _ = final.forward
    _, _, okb, _ = final.backward
    # free space at the candidates' coarse tolerance: a surface clearly in front of what the
    # other scanner saw, not range noise
    free_tol, free_rel = TOLERANCE.free(threshold_m)
    answer = duel_masks(two, final.T, threshold_m)
    (_, badf), (_, badb) = answer
    sf, sb = _frac(okf), _frac(okb)
    overlap_q = qf[okf]
    std_xyz, std_pc = spread(inlier_points)
    _, overlap_pc = spread(overlap_q)
    ev: dict[str, Any] = {
        "overlap": {
            "source_explained": _r(_frac(okf)),
            "target_explained": _r(_frac(okb)),
            "tolerance_m": _r(final.tolerance_m),
            "tolerance_rel": TOLERANCE.fine_rel,
            "samples": [len(okf), len(okb)],
        },
        "free_space": {
            "source_conflicting": _r(_frac(badf)),
            "target_conflicting": _r(_frac(badb)),
            # contradicted as a fraction of explained, per direction
            "source_conflict_ratio": _r(_frac(badf) / sf) if sf > 0 else None,
            "target_conflict_ratio": _r(_frac(badb) / sb) if sb > 0 else None,
            "tolerance_m": _r(free_tol),
            "tolerance_rel": free_rel,
            "no_viewpoint": _no_viewpoint(two),
        },
        "inliers": {
            "count": len(inlier_points),
            "matches": int(matches),
            "fit_to_matches": bool(fit_to_matches),
            "std_xyz_m": _vec(std_xyz, 3),
            "std_principal_m": _vec(std_pc, 3),
            "overlap_std_principal_m": _vec(overlap_pc, 3),
            "spread_ratio": _r(std_pc[1] / overlap_pc[1]) if overlap_pc[1] > 0 else 0.0,
        },
        "axis_strength": _strength(two.forward.view, target_normals, overlap_q),
        "runner_up": None,
        "candidates": int(candidates),
        "residual": _residual(inlier_rmse_m, fitness, threshold_m, residual_kind),
        "refinement": refinement,
    }
    c = overlap_q.mean(axis=0) if len(overlap_q) else np.zeros(3)
    # whenever the settling made both scans' full views (a repeating plan, a weak axis or a
    # close rival) the answer's own open-space share there decides ``free_space`` (decide)
    full_answer = None
    if full is not None:
        ev["full_resolution"], full_answer = full_evidence(full, final.T, threshold_m)
    if sweep is not None:
        ev["sweep"] = dict(sweep)
    ups = []
    for h in runner_up:
        D = np.asarray(h.T_target_source) @ invert(final.T)
        won, lost = duel(answer, duel_masks(two, h.T_target_source, threshold_m))
        ups.append(
            {
                "score_ratio": h.score_ratio,
                "rotation_deg": h.rotation_deg,
                "translation_m": h.translation_m,
                "offset_m": _vec(D[:3, :3] @ c + D[:3, 3] - c, 3),
                "origin": h.origin,
                "refuted_share": _r(won),
                "refuting_share": _r(lost),
            }
            | _full_duel(full, full_answer, h, threshold_m, full_ratio)
        )
    if ups:
        ev["runner_up"] = ups[0]
        ev["runner_ups"] = ups
    ev["rivals"] = [_rival(two, answer, h, threshold_m) for h in rivals]
    return Evidence(**ev)


def full_evidence(
    full: FullPair,
    T: NDArray[np.float64],
    threshold_m: float,
    why: str = "settling",
) -> tuple[dict[str, Any], Masks]:
    """The ``full_resolution`` section: how many points of both scans ``full`` checks, the
    share of them the pose ``T`` puts in the other's open space, and ``why`` they were
    compared (``"settling"``: a repeat, a weak axis or a close rival, where a twin beside the
    truth is likely; ``"check"``: a confident answer checked anyway); and its masks
    (:func:`~flexreg.registration.fullres.pose_masks`)."""
    masks = pose_masks(full, T, threshold_m)
    bad = sum(int(b.sum()) for _, b in masks)
    section = {
        "points": full.points,
        "open_space_share": round(bad / full.points, 7) if full.points else 0.0,
        "why": why,
    }
    return section, masks


def _full_duel(
    full: FullPair | None,
    answer: Masks | None,
    h: Hypothesis,
    threshold_m: float,
    ratio: float,
) -> dict[str, Any]:
    """The answer's full-resolution duel against a close runner-up, and how much of what the
    answer explains there the runner-up explains (``full_support``; a pose the samples
    score well at long range, where their tolerance grows with the range, may explain
    almost nothing at full resolution: a street's plan turned half round, 48 m along,
    scored 64 % of the answer and explained 0.9 % of what it does). Empty when not held."""
    if full is None or answer is None or h.score_ratio < ratio:
        return {}
    masks = pose_masks(full, h.T_target_source, threshold_m)
    won, lost = duel(answer, masks)
    mine = sum(int(ok.sum()) for ok, _ in answer)
    return {
        "full_refuted_share": round(won, 6),
        "full_refuting_share": round(lost, 6),
        "full_points": full.points,
        "full_support": round(sum(int(ok.sum()) for ok, _ in masks) / mine, 4) if mine else None,
    }


def _rival(two: TwoWay, answer: Masks, h: Hypothesis, threshold_m: float) -> dict[str, Any]:
    won, lost = duel(answer, duel_masks(two, h.T_target_source, threshold_m))
    return {
        "score_ratio": h.score_ratio,
        "rotation_deg": h.rotation_deg,
        "translation_m": h.translation_m,
        "origin": h.origin,
        "refuted_share": _r(won),
        "refuting_share": _r(lost),
    }


__all__ = [
    "ALWAYS",
    "MAX_RIVALS",
    "MAX_RUNNER_UPS",
    "Evidence",
    "full_evidence",
    "gather",
    "runner_ups",
]
