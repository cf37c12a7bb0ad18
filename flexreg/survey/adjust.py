"""The survey's final joint alignment: every placed station refined together on its
overlapping points, each with its accuracy (``SurveyConfig.joint_refine``, on by default).

After the graph has chosen the links and placed the stations, the pairs that overlap are
measured again on their points: every accepted link of the reference's group, and every other
pair of its stations that the map check found seeing each other (at least 10 % of both
samples explained, :data:`~flexreg.survey.config.MIN_EXPLAINED`). Each pair is aligned by robust
point-to-plane ICP on the stations' adjustment clouds, started from the relative pose the
current solution holds (:func:`flexreg.survey.c2c.fit_pair`), and gives a relative pose with
its information matrix. A pose graph of these measurements (GTSAM: ``BetweenFactorPose3``
per pair with its information as a Gaussian model under a Huber kernel, the reference held
fixed) is optimised by Levenberg-Marquardt; a pair that still disagrees with the optimised
poses by more than ``tolerance_mm`` is left out (worst first: the kernel bounds its pull, but
it still pulls) and the graph optimised again; the pairs are measured again from the new poses
(those whose solved relative pose lies their fit's own kernel width or more,
:data:`~flexreg.survey.c2c.TUKEY_C` residual sigmas, a turn counted at the source's median
range, both from where their last fit started and from where it ended), until no pair needs
measuring again or ``refine_iterations`` rounds are done. ICP started inside its kernel of
either ends where that fit ended, so measuring such a pair again only repeats the
measurement (on our 36-station warehouse the rounds after the first, each measuring every
pair again, moved no station by more than 0.21 mm, against a 10 mm tolerance and 1-sigma
accuracies of 0.5-1.4 mm). This is the usual two-step form of a multi-view
cloud-to-cloud adjustment (Open3D's multiway and the surveying tools' "cloud-to-cloud bundle"
alike): the pose graph is the least-squares adjustment of every pair's point-to-plane fit,
linearised at the pair's own optimum.

Why GTSAM: it gives the marginal covariance of every pose in the same call
(``gtsam.Marginals``), which neither Open3D's pose graph nor small_gicp offers, and robust
kernels per factor.

Accuracy (1 sigma) of a station: its marginal covariance, in the reference frame (rotation
and translation per axis), scaled by the a-posteriori variance factor of the adjustment when
the network has redundancy (the weighted squared residuals over the redundancy, as in a
least-squares survey adjustment; only ever to enlarge it). A pair that closes no loop (a
bridge of the adjustment graph) cannot be checked: its residual is zero by construction and
is reported as ``unchecked``.

A station is

* ``verified``: within ``tolerance_mm`` (its 95 % error radius, translation and rotation at
  its median range, under the tolerance) and confirmed by an independent route: it stays
  joined to the reference when any one pair is taken out (2-edge-connected) through pairs
  whose residuals are within tolerance;
* ``placed``: no independent route confirms it (one pair alone places it); tested before
  the tolerance, since its 95 % error does not bound a slid or look-alike pose (the reason
  says when that error is over the tolerance too);
* ``outside_tolerance``: placed, but its 95 % error radius exceeds the tolerance, or no
  pair holds it (every pair at it left out);
* ``unplaced``.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.core.transforms import invert, rotation_error_deg, translation_error_m
from flexreg.survey.c2c import (
    TUKEY_C,
    PairFit,
    adjustment_cloud,
    fit_cache_path,
    fit_pair,
    load_fit,
    median_range,
    save_fit,
)
from flexreg.survey.config import MIN_EXPLAINED, SurveyConfig
from flexreg.survey.execute import Progress, ProgressEvent, run_tasks
from flexreg.survey.links import GraphSolution, Link, Matrix, bridges, reached

log = logging.getLogger(__name__)

#: chi-square quantile (3 degrees of freedom, 95 %) for the error radius: 2.80 sigma
RADIUS_95 = float(np.sqrt(7.815))
#: Huber kernel of the pose graph, in whitened units (95 % efficiency)
HUBER_K = 1.345
#: 1-sigma of the reference station's prior, radians and metres: the frame's anchor, a
#: thousandth of the finest accuracy reported (a millimetre), so every station's covariance
#: is its own against the reference
REF_SIGMA = 1e-6
STATUSES = ("verified", "placed", "outside_tolerance", "unplaced")


@dataclass
class Pair:
    """One pair of the adjustment and what it measured.

    Attributes
    ----------
    target, source : str
    kind : {"link", "overlap"}
        An accepted link of the graph, or a pair the map check found overlapping.
    fit : PairFit or None
        None when the pair could not be measured (too few points) or its ICP moved beyond the
        loop tolerance from the graph's pose (it then takes no part).
    residual_deg, residual_m : float or None
        Disagreement of the pair's own fit with the adjusted poses; None while unchecked.
    bridge : bool
        No loop closes through it: its residual is zero by construction (``unchecked``).
    start : (4, 4) float64 or None
        The relative pose ``fit`` was started from: a later round measures the pair again
        only when the solution holds it ``kernel_m`` or more both from there and from where
        that fit ended (from ``start`` alone when it was left out; :func:`_moved`).
    kernel_m : float or None
        The kernel width of its last fit (:data:`~flexreg.survey.c2c.TUKEY_C` residual
        sigmas; that of a voxel-wide sigma when it could not be fitted), metres, kept when
        the fit is left out.
    """

    target: str
    source: str
    kind: str
    fit: PairFit | None = None
    residual_deg: float | None = None
    residual_m: float | None = None
    bridge: bool = False
    why: str | None = None
    left_out_mm: float | None = None
    start: Matrix | None = None
    kernel_m: float | None = None

    def to_dict(self) -> dict[str, Any]:
        f = self.fit
        return {
            "target": self.target,
            "source": self.source,
            "kind": self.kind,
            "measured": f is not None,
            "why": self.why,
            "left_out_mm": None if self.left_out_mm is None else round(self.left_out_mm, 2),
            "T_target_source": None if f is None else f.T_target_source.tolist(),
            "residual_sigma_mm": None if f is None else round(f.sigma_m * 1e3, 3),
            **({} if f is None else {"cloud_to_cloud": f.figures.to_dict()}),
            "link_error": (
                "unchecked"
                if f is not None and self.bridge
                else None
                if self.residual_m is None
                else {
                    "deg": round(self.residual_deg or 0.0, 5),
                    "mm": round(self.residual_m * 1e3, 3),
                }
            ),
        }


@dataclass
class Accuracy:
    """A placed station's 1-sigma accuracy in the reference frame.

    Attributes
    ----------
    sigma_deg : (3,) float
        About the reference's x, y, z axes (roll, pitch, yaw), degrees.
    sigma_mm : (3,) float
        Along the reference's x, y, z axes, millimetres.
    radius95_mm : float
        95 % error radius of the position (largest axis of its covariance), mm.
    rotation95_mm : float
        95 % error of the rotation as a displacement at the station's median range, mm.
    """

    sigma_deg: tuple[float, float, float]
    sigma_mm: tuple[float, float, float]
    radius95_mm: float
    rotation95_mm: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "sigma_deg": {
                k: round(v, 5)
                for k, v in zip(("roll", "pitch", "yaw"), self.sigma_deg, strict=True)
            },
            "sigma_mm": {k: round(v, 3) for k, v in zip("xyz", self.sigma_mm, strict=True)},
            "radius95_mm": round(self.radius95_mm, 3),
            "rotation95_mm": round(self.rotation95_mm, 3),
        }


@dataclass
class Adjustment:
    """The final joint alignment of the reference's group.

    Attributes
    ----------
    poses : dict of str -> (4, 4) float64
        Adjusted ``T_reference_station``.
    accuracy : dict of str -> Accuracy
    status : dict of str -> str
        One of :data:`STATUSES` per station of the group.
    why : dict of str -> str
        Why a station is not ``verified``, in words.
    pairs : list of Pair
    rounds : int
    settled : bool
    variance_factor : float or None
        A-posteriori variance factor (None without redundancy).
    redundancy : int
    seconds : float
    """

    poses: dict[str, Matrix]
    accuracy: dict[str, Accuracy] = field(default_factory=dict)
    status: dict[str, str] = field(default_factory=dict)
    why: dict[str, str] = field(default_factory=dict)
    pairs: list[Pair] = field(default_factory=list)
    rounds: int = 0
    settled: bool = False
    variance_factor: float | None = None
    redundancy: int = 0
    seconds: float = 0.0

    def summary(self) -> dict[str, Any]:
        checked = [p for p in self.pairs if p.fit is not None and not p.bridge]
        m = np.array([p.residual_m for p in checked if p.residual_m is not None], np.float64)
        d = np.array([p.residual_deg for p in checked if p.residual_deg is not None], np.float64)
        return {
            "rounds": self.rounds,
            "settled": self.settled,
            "pairs": len(self.pairs),
            "pairs_measured": sum(p.fit is not None for p in self.pairs),
            "pairs_checked": len(checked),
            "pairs_unchecked": sum(p.fit is not None and p.bridge for p in self.pairs),
            "pairs_left_out": sum(p.left_out_mm is not None for p in self.pairs),
            "bundle_error_mm": None
            if not len(m)
            else round(float(np.sqrt(np.mean(m**2))) * 1e3, 3),
            "bundle_error_deg": None if not len(d) else round(float(np.sqrt(np.mean(d**2))), 5),
            "variance_factor": None
            if self.variance_factor is None
            else round(self.variance_factor, 3),
            "redundancy": self.redundancy,
            "seconds": round(self.seconds, 3),
        }


def _pairs(
    sol: GraphSolution, links: list[Link], looks: list[Any], config: SurveyConfig
) -> list[Pair]:
    group = set(sol.groups[0]) if len(sol.groups[0]) > 1 else set()
    out: list[Pair] = []
    seen: set[frozenset[str]] = set()
    for e in links:
        k = frozenset((e.target, e.source))
        if e.status == "accepted" and e.target in group and e.source in group and k not in seen:
            seen.add(k)
            out.append(Pair(e.target, e.source, "link"))
    for look in looks:
        k = frozenset((look.a, look.b))
        if look.a in group and look.b in group and k not in seen:
            if min(look.explained) >= MIN_EXPLAINED:
                seen.add(k)
                out.append(Pair(look.a, look.b, "overlap"))
    return out


def _graph(
    stems: list[str], ref: str, pairs: list[Pair], poses: dict[str, Matrix]
) -> tuple[Any, Any, dict[str, int]]:
    import gtsam

    key = {s: i for i, s in enumerate(stems)}
    g = gtsam.NonlinearFactorGraph()
    v = gtsam.Values()
    for s in stems:
        v.insert(key[s], gtsam.Pose3(np.asarray(poses[s], np.float64)))
    # the reference held to a micron and a microradian by a Gaussian prior: a constrained
    # (infinitely precise) one makes the marginals' Cholesky factorisation fail as
    # indeterminate for some orderings, and then no station's accuracy is known
    g.add(
        gtsam.PriorFactorPose3(
            key[ref], gtsam.Pose3(poses[ref]), gtsam.noiseModel.Isotropic.Sigma(6, REF_SIGMA)
        )
    )
    huber = gtsam.noiseModel.mEstimator.Huber.Create(HUBER_K)
    for p in pairs:
        if p.fit is None:
            continue
        info = 0.5 * (p.fit.information + p.fit.information.T)
        info = info + np.eye(6) * 1e-9 * max(float(np.trace(info)), 1.0)
        model = gtsam.noiseModel.Robust.Create(huber, gtsam.noiseModel.Gaussian.Information(info))
        g.add(
            gtsam.BetweenFactorPose3(
                key[p.target], key[p.source], gtsam.Pose3(p.fit.T_target_source), model
            )
        )
    return g, v, key


def _optimise(
    stems: list[str], ref: str, pairs: list[Pair], poses: dict[str, Matrix]
) -> tuple[dict[str, Matrix], Any, Any, dict[str, int]]:
    import gtsam

    g, v, key = _graph(stems, ref, pairs, poses)
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(100)
    params.setRelativeErrorTol(1e-12)
    params.setAbsoluteErrorTol(1e-15)
    res = gtsam.LevenbergMarquardtOptimizer(g, v, params).optimize()
    out = {s: np.asarray(res.atPose3(key[s]).matrix(), np.float64) for s in stems}
    return out, g, res, key


def _optimise_robust(
    stems: list[str], ref: str, pairs: list[Pair], poses: dict[str, Matrix], config: SurveyConfig
) -> tuple[dict[str, Matrix], Any, Any, dict[str, int]]:
    """Optimise; while the pair that fits the optimised poses worst disagrees with them by
    more than ``tolerance_mm`` (the Huber kernel bounds its pull but it still pulls), leave
    it out and optimise again. Returns every station's pose (those no pair holds keep
    theirs), the graph, its values and keys."""
    tol_m = config.tolerance_mm / 1e3
    while True:
        used = [p for p in pairs if p.fit is not None]
        held = [s for s in stems if s == ref or any(s in (p.target, p.source) for p in used)]
        new, graph, result, key = _optimise(held, ref, pairs, poses)
        new = {**poses, **new}
        worst, err = None, tol_m
        for p in used:
            assert p.fit is not None
            T = invert(new[p.target]) @ new[p.source]
            m = translation_error_m(p.fit.T_target_source, T)
            if m > err:
                worst, err = p, m
        if worst is None:
            return new, graph, result, key
        worst.fit = None
        worst.left_out_mm = err * 1e3
        worst.why = (
            f"its cloud-to-cloud fit disagrees with the adjusted poses by {err * 1e3:.1f} mm, "
            f"over the {config.tolerance_mm:g} mm tolerance: left out"
        )


def covariances(graph: Any, result: Any, key: dict[str, int], ref: str) -> dict[str, Matrix]:
    """Each station's (6, 6) covariance against the reference (rotation in radians, then
    translation in metres, in the station's frame) from the optimised pose graph: gtsam's
    marginals, or where their sparse factorisation stops at an ill-conditioned pivot (it
    then fails for the whole graph, "indeterminate linear system"), the inverse of the dense
    information matrix of the same linearisation. A station that matrix does not fix (not
    finite, not positive definite) has none.

    Parameters
    ----------
    graph, result
        The gtsam factor graph (the reference held by a Gaussian prior) and its solution.
    key : dict of str -> int
        Each station's variable.
    ref : str
        The reference station (no covariance of its own).
    """
    import gtsam

    order = sorted(key, key=key.__getitem__)
    try:
        marg = gtsam.Marginals(graph, result)
        return {s: np.asarray(marg.marginalCovariance(key[s])) for s in order if s != ref}
    except (RuntimeError, IndexError):
        log.info("final alignment: the marginals' factorisation failed; inverting the dense "
                 "information matrix")  # fmt: skip
    return _dense_covariances(graph, result, key, ref)


def _dense_covariances(graph: Any, result: Any, key: dict[str, int], ref: str) -> dict[str, Matrix]:
    """:func:`covariances` from the inverse of the dense information matrix."""
    import gtsam

    order = sorted(key, key=key.__getitem__)
    ordering = gtsam.Ordering()
    for s in order:
        ordering.push_back(key[s])
    H, _ = graph.linearize(result).hessian(ordering)
    try:
        inv = np.linalg.inv(np.asarray(H, dtype=np.float64))
    except np.linalg.LinAlgError:
        return {}
    out: dict[str, Matrix] = {}
    for i, s in enumerate(order):
        c = inv[6 * i : 6 * i + 6, 6 * i : 6 * i + 6]
        c = 0.5 * (c + c.T)
        if s != ref and np.all(np.isfinite(c)) and np.linalg.eigvalsh(c)[0] > 0:
            out[s] = c
    return out


def _two_edge_connected(
    ref: str, edges: list[tuple[str, str]], cut: set[int] | None = None
) -> set[str]:
    """Stations still joined to ``ref`` after any one edge is removed (``cut``: the edges'
    :func:`~flexreg.survey.links.bridges`, when known)."""
    cut = bridges(edges) if cut is None else cut
    return reached(ref, [x for j, x in enumerate(edges) if j not in cut])


def _accuracy(cov: NDArray[np.float64], pose: Matrix, lever_m: float) -> Accuracy:
    R = np.asarray(pose, np.float64)[:3, :3]
    rot = R @ cov[:3, :3] @ R.T  # a perturbation of the station frame, turned to the reference
    tra = R @ cov[3:, 3:] @ R.T
    sd = np.sqrt(np.clip(np.diag(rot), 0, None))
    st = np.sqrt(np.clip(np.diag(tra), 0, None))
    radius = RADIUS_95 * float(np.sqrt(max(np.linalg.eigvalsh(tra)[-1], 0.0)))
    rot95 = RADIUS_95 * float(np.sqrt(max(np.linalg.eigvalsh(rot)[-1], 0.0))) * lever_m
    return Accuracy(
        tuple(float(x) for x in np.degrees(sd)),  # type: ignore[arg-type]
        tuple(float(x) * 1e3 for x in st),  # type: ignore[arg-type]
        radius * 1e3,
        rot95 * 1e3,
    )


def _measure(
    client: Any,
    pairs: list[Pair],
    clouds: dict[str, str],
    poses: dict[str, Matrix],
    config: SurveyConfig,
    progress: Progress,
    round_: int,
) -> int:
    """Measure the pairs whose relative pose the solution has moved since their fit (in the
    first round every pair no earlier run fitted), keeping each fit for later runs; returns
    how many were measured."""
    t0 = time.perf_counter()
    done = [0]
    levers = {s: median_range(clouds[s]) for s in {p.source for p in pairs}}
    todo = [p for p in pairs if _moved(p, poses, levers[p.source])]

    def report(_: int, __: Any) -> None:
        done[0] += 1
        if progress is not None:
            progress(
                ProgressEvent("refine", done[0], len(todo), elapsed_s=time.perf_counter() - t0)
            )

    items = [
        (
            clouds[p.target],
            clouds[p.source],
            invert(poses[p.target]) @ poses[p.source],
            config.refine_voxel_m,
        )
        for p in todo
    ]
    fits = run_tasks(client, _fit_or_none, items, on_result=report)
    for p, args, f in zip(todo, items, fits, strict=True):
        if f is not None:
            save_fit(fit_cache_path(args[0], args[1]), args[2], f)
        _take(p, args[2], f, config, f"round {round_}")
    return len(todo)


def _take(p: Pair, start: Matrix, f: PairFit | None, config: SurveyConfig, when: str) -> None:
    """Let ``f``, fitted from ``start``, be the pair's measurement, unless there is none or
    it moved beyond the loop tolerance from where it started (the pair is then left out)."""
    p.start = start
    p.kernel_m = TUKEY_C * (config.refine_voxel_m if f is None else f.sigma_m)
    if f is None:
        p.fit, p.why = None, "too few overlapping points to align"
        return
    moved = (
        rotation_error_deg(f.T_target_source, start),
        translation_error_m(f.T_target_source, start),
    )
    if moved[0] > config.loop_max_deg or moved[1] > config.loop_max_m:
        p.fit = None
        p.why = (
            f"its cloud-to-cloud fit moved {moved[0]:.3f}° / {moved[1] * 1e3:.1f} mm from "
            f"the solved poses ({when}): left out"
        )
        return
    p.fit, p.why, p.left_out_mm = f, None, None


def _recall(pairs: list[Pair], clouds: dict[str, str], config: SurveyConfig) -> int:
    """Give each pair the fit an earlier run kept (:func:`~flexreg.survey.c2c.save_fit`), with
    the pose it started from: a round measures it again only if the solution moved it
    beyond that fit's kernel (:func:`_moved`), so a re-run of the same project, or one with a
    link added, measures only the pairs it changed. Returns how many were recalled."""
    n = 0
    for p in pairs:
        kept = load_fit(fit_cache_path(clouds[p.target], clouds[p.source]))
        if kept is not None:
            _take(p, kept[0], kept[1], config, "kept from an earlier run")
            n += 1
    return n


def _moved(p: Pair, poses: dict[str, Matrix], lever_m: float) -> bool:
    """The pair was never measured, or the solution holds its relative pose ``kernel_m`` or
    more (:attr:`Pair.kernel_m`; a turn at ``lever_m``, the source's median range) both from
    where its last fit started and from where it ended. ICP started inside its kernel of
    where an earlier fit started, or of an optimum it reached, ends where that fit ended (its
    first stages bring it there to a hundredth of their kernel, the last runs to
    convergence), so measuring such a pair again would only repeat the measurement. A pair
    left out stays out until the solution moves it by that much from its start."""
    if p.start is None or p.kernel_m is None:
        return True
    T = invert(poses[p.target]) @ poses[p.source]
    ends = [p.start] if p.fit is None else [p.start, p.fit.T_target_source]
    return all(_shift_m(T, end, lever_m) >= p.kernel_m for end in ends)


def _shift_m(A: Matrix, B: Matrix, lever_m: float) -> float:
    """How far two poses of a station lie apart: the larger of the translation and the turn
    at ``lever_m`` (metres)."""
    turn = np.radians(rotation_error_deg(A, B)) * max(lever_m, 1.0)
    return max(translation_error_m(A, B), float(turn))


def _fit_or_none(target: str, source: str, T: Matrix, voxel_m: float) -> PairFit | None:
    try:
        return fit_pair(target, source, T, voxel_m)
    except ValueError:
        return None


def adjust(
    client: Any,
    sol: GraphSolution,
    links: list[Link],
    looks: list[Any],
    files: dict[str, str],
    config: SurveyConfig,
    progress: Progress = None,
) -> Adjustment | None:
    """The final joint alignment of the reference's group (see the module); None when fewer
    than two stations are placed. ``files``: the prepared station per stem."""
    t0 = time.perf_counter()
    stems = list(sol.groups[0]) if len(sol.groups[0]) > 1 else []
    if not stems:
        return None
    ref = sol.reference
    made = run_tasks(client, adjustment_cloud, [(files[s], config.refine_voxel_m) for s in stems])
    clouds = dict(zip(stems, made, strict=True))
    levers = {s: median_range(clouds[s]) for s in stems}
    pairs = _pairs(sol, links, looks, config)
    kept = _recall(pairs, clouds, config)
    log.info("final alignment: %d of %d pairs fitted by an earlier run", kept, len(pairs))
    poses = {s: np.asarray(sol.poses[s], np.float64) for s in stems}
    adj = Adjustment(poses=poses, pairs=pairs)
    graph: Any = None
    result: Any = None
    key: dict[str, int] = {}
    for r in range(1, config.refine_iterations + 1):
        if _measure(client, pairs, clouds, poses, config, progress, r) == 0 and r > 1:
            adj.settled = True  # nothing moved since every pair's fit: as in the last round
            break
        new, graph, result, key = _optimise_robust(stems, ref, pairs, poses, config)
        step = max(_shift_m(new[s], poses[s], levers[s]) for s in stems)
        poses = new
        adj.rounds = r
        log.info("final alignment round %d: stations moved up to %.3f mm (a turn at the "
                 "median range)", r, step * 1e3)  # fmt: skip
    adj.poses = poses
    _finish(adj, stems, ref, graph, result, key, clouds, config)
    adj.seconds = time.perf_counter() - t0
    log.info("final alignment: %s", adj.summary())
    return adj


def _finish(
    adj: Adjustment,
    stems: list[str],
    ref: str,
    graph: Any,
    result: Any,
    key: dict[str, int],
    clouds: dict[str, str],
    config: SurveyConfig,
) -> None:
    """Residuals, bridges, the variance factor, accuracies and statuses."""
    import gtsam

    used = [p for p in adj.pairs if p.fit is not None]
    edges = [(p.target, p.source) for p in used]
    alone = bridges(edges)
    chi2 = 0.0
    for i, p in enumerate(used):
        assert p.fit is not None
        T = invert(adj.poses[p.target]) @ adj.poses[p.source]
        p.bridge = i in alone
        p.residual_deg = rotation_error_deg(p.fit.T_target_source, T)
        p.residual_m = translation_error_m(p.fit.T_target_source, T)
        xi = gtsam.Pose3.Logmap(gtsam.Pose3(p.fit.T_target_source).between(gtsam.Pose3(T)))
        chi2 += float(xi @ p.fit.information @ xi)
    adj.redundancy = 6 * (len(used) - (len(stems) - 1))
    factor = 1.0
    if adj.redundancy > 0:
        adj.variance_factor = chi2 / adj.redundancy
        factor = max(1.0, adj.variance_factor)
    covs = {s: factor * c for s, c in covariances(graph, result, key, ref).items()}
    confirmed = _two_edge_connected(ref, edges, alone)
    touched = {s for p in used for s in (p.target, p.source)}
    for s in stems:
        if s == ref:
            adj.status[s] = "verified" if len(stems) > 1 and s in touched else "placed"
            continue
        cov = covs.get(s)
        if cov is None or s not in touched or not np.all(np.isfinite(cov)):
            adj.status[s] = "outside_tolerance"
            out = [p for p in adj.pairs if s in (p.target, p.source) and p.left_out_mm]
            adj.why[s] = "no cloud-to-cloud pair fixes it: its accuracy is unknown" + (
                f" ({len(out)} pair(s) at it disagree with the rest by more than the "
                "tolerance: check its links)"
                if out
                else ""
            )
            continue
        acc = _accuracy(cov, adj.poses[s], median_range(clouds[s]))
        adj.accuracy[s] = acc
        worst = max(acc.radius95_mm, acc.rotation95_mm)
        over = (
            f"its 95 % error is {worst:.1f} mm, over the {config.tolerance_mm:g} mm "
            "tolerance (the overlapping surfaces do not fix it well enough)"
        )
        if s not in confirmed:  # unconfirmed comes first: a slid or look-alike pose is no
            adj.status[s] = "placed"  # noise, and its 95 % error does not bound it
            adj.why[s] = (
                "one cloud-to-cloud pair alone places it (no independent route confirms it, "
                "and its accuracy does not cover a wrong link); add a scan between it and "
                "its neighbours, or check that pair"
                + (f"; {over}" if worst > config.tolerance_mm else "")
            )
        elif worst > config.tolerance_mm:
            adj.status[s] = "outside_tolerance"
            adj.why[s] = over
        else:
            adj.status[s] = "verified"


__all__ = ["REF_SIGMA", "STATUSES", "Accuracy", "Adjustment", "Pair", "adjust", "covariances"]
