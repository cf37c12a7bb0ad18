"""``register(target, source, config)``: the whole chain from two scans to ``T_target_source``.

Stages (each public and usable alone, see :mod:`flexreg.stages`): range image
(:func:`flexreg.stages.projection.working_image`) -> feature image
(:func:`flexreg.stages.feature_images.feature_image`) -> keypoints and descriptors
(:func:`flexreg.stages.keypoints.detect_and_describe`) -> 3D points
(:func:`flexreg.stages.correspondences.lift`) -> priors: descriptor matches
(:func:`flexreg.stages.matching.match`) with consistency pruning and RANSAC
(:mod:`flexreg.stages.alignment`), plan-view overlays (:mod:`flexreg.stages.priors`) ->
candidates judged by the dense check (:mod:`flexreg.registration.candidates`) -> ICP
refinement (:func:`flexreg.stages.refinement.refine`).

Everything up to the 3D points, the plan views and the checks' inputs depends on one scan
alone: :meth:`Registration.prepare` computes it once per scan and :meth:`Registration.align`
registers two prepared scans, so N stations of a survey cost N preparations and one
alignment per pair. :func:`register` does both for one pair, its stages overlapping in two
background threads exactly as a prepare-then-align would compute them.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from flexreg.core.range_image import RangeImage
from flexreg.core.scan import Scan, as_points
from flexreg.core.transforms import as_transform
from flexreg.errors import ConfigError, DegenerateGeometryError, RegistrationError
from flexreg.registration.candidates import (
    Aliases,
    Candidate,
    Coarse,
    Keypoints3D,
    choose,
    polisher,
    require_inliers,
    self_symmetries,
)
from flexreg.registration.check import Check, TwoWay
from flexreg.registration.conclude import Judging, conclude, slid_answer
from flexreg.registration.config import RegistrationConfig
from flexreg.registration.fullres import full_pair_of
from flexreg.registration.geometric import geometric_priors, gridded, panoramic, route
from flexreg.registration.preparation import (
    PreparedScan,
    Progress,
    Run,
    ScanView,
    feature_image,
    keypoints_of,
    plans_of,
    range_images_of,
    refinement_sample,
    scan_views,
    timed_stage,
)
from flexreg.registration.result import RegistrationResult
from flexreg.registration.settle import Settlement, settle
from flexreg.stages.alignment import Window, consistent_subset, ransac_rigid, windowed_fit
from flexreg.stages.correspondences import derive_threshold
from flexreg.stages.matching import match
from flexreg.stages.overlap import measure_overlap
from flexreg.stages.priors import PlanView, plan_overlays, windowed_plan_overlays

log = logging.getLogger(__name__)

#: the plan overlays (origin ``"plan"``, or ``"window-plan"`` inside a rough prior's window)
#: and the scans' symmetries
PlanPriors = tuple[list[Candidate], Aliases]


def _plan_priors(
    target: PlanView | str | None,
    source: PlanView | str | None,
    config: RegistrationConfig,
    window: Window | None = None,
    symmetries: tuple[Sequence[NDArray[np.float64]] | None, ...] = (None, None),
) -> PlanPriors:
    """The plan overlays of two plan views (raises the reason a scan has none), the best ones
    inside a rough prior's ``window`` first (:func:`~flexreg.stages.priors.
    windowed_plan_overlays`), and the symmetries of each (when
    ``config.judge.runs("aliases")``; those given, of prepared scans, as they are)."""
    for p in (target, source):
        if not isinstance(p, PlanView):
            raise DegenerateGeometryError(str(p))
    overlays: list[Candidate] = [
        ("plan", T)
        for T in plan_overlays(target, source, hypotheses=config.prior.plan_hypotheses)  # type: ignore[arg-type]
    ]
    if window is not None:
        inside = windowed_plan_overlays(
            target,  # type: ignore[arg-type]
            source,  # type: ignore[arg-type]
            window.T_prior,
            shift_m=window.shift_m,
            turn_rad=window.turn_rad,
            hypotheses=config.prior.plan_hypotheses,
        )
        overlays = [("window-plan", T) for T in inside] + overlays
    up = np.asarray(target.levelling.up, dtype=np.float64)  # type: ignore[union-attr]
    if not config.judge.runs("aliases"):
        return overlays, Aliases(up=up)
    st, ss = (
        list(given) if given is not None else self_symmetries(plan)
        for given, plan in zip(symmetries, (target, source), strict=True)
    )
    return overlays, Aliases(st, ss, up)


def _pair_plan_priors(
    images: list[RangeImage], config: RegistrationConfig, window: Window | None = None
) -> PlanPriors:
    t, s = plans_of(images, config)
    return _plan_priors(t, s, config, window)


# ------------------------------------------------------------------------------ per pair


@dataclass(eq=False)
class _Matched:
    """What global descriptor matching found (see :func:`_match`)."""

    thr: float
    pairs: NDArray[np.int64]
    priors: list[Candidate]
    notes: list[str]
    few: bool = False  # too few keypoints: matching did not run


def _descriptor_prior(
    pt: NDArray[np.float64],
    ps: NDArray[np.float64],
    thr: float,
    config: RegistrationConfig,
    priors: list[Candidate],
    notes: list[str],
) -> None:
    """Consistency pruning and RANSAC of the matched points: the descriptor prior."""
    idx = np.arange(len(pt))
    if config.consistency:
        idx = consistent_subset(pt, ps, threshold_m=2 * thr, relative=0.01)
    try:
        rr = ransac_rigid(
            pt[idx],
            ps[idx],
            threshold_m=thr,
            confidence=config.confidence,
            max_iterations=config.max_iterations,
            min_inliers=3,
            rng=config.seed,
        )
        priors.append(("descriptors", rr.T_target_source))
    except DegenerateGeometryError as e:
        notes.append(f"global matching: {e}")


def _match(
    images: list[RangeImage], kps: list[Keypoints3D], config: RegistrationConfig, run: Run
) -> _Matched:
    """The inlier threshold, descriptor matching and RANSAC (the descriptor prior)."""
    (ti, si), (kt, ks) = images, kps
    n_lt, n_ls = int(kt.lifted.sum()), int(ks.lifted.sum())
    nt, ns = len(kt.features), len(ks.features)
    log.info("%d/%d keypoints, %d/%d lifted", nt, ns, n_lt, n_ls)
    if n_lt < 3 or n_ls < 3:
        why = f"too few keypoints on valid surface: {n_lt} target / {n_ls} source " + (
            f"(of {nt} / {ns} detected)"
        )
        if config.method == "flexion":
            raise RegistrationError(why)
        thr = _pixel_threshold(images, config)
        return _Matched(thr, np.zeros((0, 2), np.int64), [], [why], few=True)
    thr = (
        float(config.threshold_m)
        if config.threshold_m is not None
        else derive_threshold(
            ti,
            si,
            kt.features.xy[kt.lifted],
            ks.features.xy[ks.lifted],
            threshold_px=config.threshold_px,
        )
    )
    priors: list[Candidate] = []
    notes: list[str] = []
    with run.stage("matching"):  # descriptors, then the global model (consistency, RANSAC)
        pairs = match(kt.features, ks.features, ratio=config.ratio, mutual=config.mutual)
        pairs = pairs[kt.lifted[pairs[:, 0]] & ks.lifted[pairs[:, 1]]]
        if len(pairs) >= 3:
            pt, ps = kt.points[pairs[:, 0]], ks.points[pairs[:, 1]]
            _descriptor_prior(pt, ps, thr, config, priors, notes)
        else:
            notes.append(f"global matching: {len(pairs)} matches")
    return _Matched(thr, pairs, priors, notes)


def _pixel_threshold(images: list[RangeImage], config: RegistrationConfig) -> float:
    """The inlier distance without keypoints: ``config.threshold_m``, or ``threshold_px``
    times the median footprint of an even sample of both images' valid pixels."""
    if config.threshold_m is not None:
        return float(config.threshold_m)
    xy = []
    for img in images:
        rows, cols = np.nonzero(img.valid)
        k = max(1, len(rows) // 2000)
        xy.append(np.stack([cols[::k], rows[::k]], axis=1).astype(np.float64))
    return derive_threshold(images[0], images[1], xy[0], xy[1], threshold_px=config.threshold_px)


def _plan_candidates(
    job: Future[PlanPriors] | None,
    config: RegistrationConfig,
    run: Run,
    notes: list[str],
) -> tuple[list[Candidate], Aliases | None]:
    """The plan overlays of the background job and the scans' symmetries, or none (the
    reason noted)."""
    if job is None:
        return [], None
    run.wait("plan views")
    try:
        overlays, aliases = job.result()
    except DegenerateGeometryError as e:
        if config.prior.upright == "on":
            raise RegistrationError(f"upright prior impossible: {e}") from None
        notes.append(f"no plan prior ({e})")
        log.info("no plan prior: %s", e)
        return [], None
    return overlays, aliases


def _finish(
    scans: list[Scan | RangeImage],
    kps: list[Keypoints3D],
    views: list[ScanView],
    m: _Matched,
    plan_priors: list[Candidate],
    config: RegistrationConfig,
    run: Run,
    init: NDArray[np.float64] | None = None,
    aliases: Aliases | None = None,
    window: Window | None = None,
) -> RegistrationResult:
    """Candidates, the coarse transform and its checks, the refinement (kept when it scores
    better), the verdict, the result.

    ``init`` (a given ``T_target_source``) competes as one more prior; with
    ``config.icp_only`` it is the only one. With a ``window`` (``init`` is rough) the answer
    is bounded by it: the window's own fit (:func:`~flexreg.stages.alignment.windowed_fit`)
    joins the priors, and only a candidate inside the window can win; the others stay the
    evidence the verdict duels the answer against. An answer the verdict refutes in open
    space may be replaced by its slide along the walls
    (:func:`~flexreg.registration.conclude.slid_answer`), judged again."""
    (kt, ks), (vt, vs), thr = kps, views, m.thr
    assert vt.normals is not None and vs.sample is not None
    check, two = _checks(vt, vs)
    polish = _polisher(vt, vs, thr, config)
    counts = f"{len(kt.features)}/{len(ks.features)} keypoints, {len(m.pairs)} descriptor matches"
    priors = _priors(init, plan_priors, m, (kt, ks), window, config)
    with run.stage("estimation"):
        c = choose(priors, kt, ks, check, polish, thr, config, counts, m.notes, aliases, window)
    pair = full_pair_of(views)
    settled = _settled(
        c, pair, check, vt.normals, polish, thr, aliases, (kt, ks), config, window, run
    )
    c = settled.coarse
    log.info(
        "coarse estimate from %s: %d/%d keypoint inliers", c.origin, c.inliers.sum(), len(c.inliers)
    )
    require_inliers(c, thr, config.min_inliers, counts)
    up = aliases.up if aliases is not None else None
    judging = Judging(scans, views, check, two, thr, config, run, pair, polish, up)
    done = conclude(c, settled, judging)
    slid = slid_answer(c, done, (kt, ks), judging) if window is None else None
    if slid is not None:
        c, settled = slid, Settlement(slid, settled.pair, settled.sweep, settled.players)
        done = conclude(c, settled, judging)
    log.info("verdict: %s", done.verdict.summary())
    T = done.T
    with run.stage("overlap"):
        overlap = measure_overlap(
            as_points(scans[0], keep_float32=True),
            as_points(scans[1], keep_float32=True),
            T,
            open3d_check=config.judge.runs("open3d"),
        )
    log.info("overlap %s", overlap.headline())
    inl = c.inliers
    return RegistrationResult(
        T_target_source=T,
        T_coarse=done.T_coarse,
        matches=len(c.pairs),
        inliers=int(inl.sum()),
        inlier_rmse_m=done.rmse,
        fitness=done.fitness,
        fitness_denominator=done.denom,
        information=done.info,
        timings_s=run.timings,
        threshold_m=thr,
        config=config,
        correspondences=np.stack([c.target_points, c.source_points], axis=1),
        inlier_mask=inl,
        keypoints=(kt.features.xy[c.pairs[:, 0]], ks.features.xy[c.pairs[:, 1]]),
        prior=c.origin,
        wall_s=time.perf_counter() - run.start,
        verdict=done.verdict,
        overlap=overlap,
    )


def _answer(
    grids: bool,
    scans: list[Scan | RangeImage],
    images: list[RangeImage],
    kps: list[Keypoints3D],
    views: list[ScanView],
    m: _Matched,
    plans: list[Candidate],
    config: RegistrationConfig,
    run: Run,
    init: NDArray[np.float64] | None,
    aliases: Aliases | None,
    window: Window | None,
) -> RegistrationResult:
    """The answer of the route ``config.method`` takes (:func:`route`): the feature images'
    hypotheses alone, the geometric ones alone, or both judged together by one
    :func:`_finish`. ``grids``: both scans came as grids (:func:`~flexreg.registration.
    geometric.gridded`: their files' native grids, or working images the caller gave)."""
    found = bool(m.priors) or (bool(plans) and not m.few)
    way = route(config.method, images, found, grids)
    if way == "flexion":
        return _finish(scans, kps, views, m, plans, config, run, init, aliases, window)
    with run.stage("geometric"):
        geo = geometric_priors(images, config, m.notes)
    if way == "geometric":
        m, plans = _Matched(m.thr, m.pairs, geo, m.notes), []
    else:
        m = _Matched(m.thr, m.pairs, m.priors + geo, m.notes)
    return _finish(scans, kps, views, m, plans, config, run, init, aliases, window)


# ------------------------------------------------------------------------------ entry points


def _check_upright(config: RegistrationConfig) -> None:
    if config.prior.upright not in ("auto", "on", "off"):
        raise ConfigError(f"upright must be 'auto', 'on' or 'off', got {config.prior.upright!r}")


def _checks(vt: ScanView, vs: ScanView) -> tuple[Check, TwoWay]:
    """The dense check (the source's sample in the target's view) and both directions."""
    assert vt.measured is not None and vt.slack is not None and vt.sample is not None
    assert vs.measured is not None and vs.slack is not None and vs.sample is not None
    check = Check(vt.image, vt.measured, vt.slack, vs.sample, vt.hidden)
    return check, TwoWay(check, Check(vs.image, vs.measured, vs.slack, vt.sample, vs.hidden))


def _polisher(
    vt: ScanView, vs: ScanView, thr: float, config: RegistrationConfig
) -> Callable[..., NDArray[np.float64]] | None:
    """The candidates' quick local ICP (:func:`~flexreg.registration.candidates.polisher`;
    from afar within two plan cells), or None when the judge does not polish."""
    if not config.judge.runs("polish"):
        return None
    assert vt.normals is not None and vs.polish_sample is not None
    return polisher(vt.image, vt.normals, vs.polish_sample, thr, 2 * config.prior.plan_cell_m)


def _settled(
    c: Coarse,
    pair: Any,
    check: Check,
    normals: Any,
    polish: Any,
    thr: float,
    aliases: Aliases | None,
    kps: tuple[Keypoints3D, Keypoints3D],
    config: RegistrationConfig,
    window: Window | None,
    run: Run,
) -> Settlement:
    """The coarse pose settled along a weak axis or a repeat
    (:func:`~flexreg.registration.settle.settle`) when the judge runs that step; not taken
    when it leaves a rough prior's ``window``."""
    if not config.judge.runs("settle") or config.icp_only:
        return Settlement(c)
    with run.stage("settling"):
        settled = settle(c, pair, check, normals, polish, thr, aliases, kps, config.judge)
    if window is not None and not window.contains(settled.coarse.T_target_source)[0]:
        log.info("the settled pose leaves the rough prior's window: not taken")
        return Settlement(c)
    return settled


def _priors(
    init: NDArray[np.float64] | None,
    plan_priors: list[Candidate],
    m: _Matched,
    kps: tuple[Keypoints3D, Keypoints3D],
    window: Window | None,
    config: RegistrationConfig,
) -> list[Candidate]:
    """Every prior that competes: the given ``init``, then the plan overlays and the
    descriptor prior (``init`` alone with ``config.icp_only``); with a rough prior's
    ``window``, its own fit (:func:`_windowed`) too (only a candidate inside the window can
    win, :func:`~flexreg.registration.candidates.choose`; all are judged)."""
    given: list[Candidate] = [] if init is None else [("init", init)]
    if config.icp_only:
        return given
    if window is None:
        return given + plan_priors + m.priors
    return given + _windowed(*kps, window, m.thr, config, m.notes) + plan_priors + m.priors


def _windowed(
    kt: Keypoints3D,
    ks: Keypoints3D,
    window: Window,
    thr: float,
    config: RegistrationConfig,
    notes: list[str],
) -> list[Candidate]:
    """The rough prior's own fit (:func:`~flexreg.stages.alignment.windowed_fit`), as a
    prior ``"window-matches"``; none (and a note why) when no pose inside the window is
    supported."""
    fit = windowed_fit(
        kt.features,
        ks.features,
        kt.points,
        ks.points,
        window,
        threshold_m=thr,
        confidence=config.confidence,
        max_iterations=config.max_iterations,
        rng=config.seed,
    )
    if fit is None:
        notes.append("no pose inside the rough prior's window is supported by 3 matches")
        return []
    log.info("windowed fit: %d inliers", fit.n_inliers)
    return [("window-matches", fit.T_target_source)]


def _check_init(
    config: RegistrationConfig,
    init: NDArray[np.float64] | None,
    window: tuple[float, float] | None = None,
) -> tuple[NDArray[np.float64] | None, Window | None]:
    """The checked ``init`` and the :class:`~flexreg.stages.alignment.Window` it comes
    with, if any."""
    if window is not None:
        if init is None:
            raise ConfigError("a window needs the rough T_target_source it bounds (init)")
        shift, turn = window
        if not (math.isfinite(shift) and shift > 0 and math.isfinite(turn) and turn > 0):
            raise ConfigError(
                f"a window needs a positive shift (metres) and turn (radians), got {window}"
            )
    if init is None:
        if config.icp_only:
            raise ConfigError('method "init" (icp_only) needs an initial T_target_source (init)')
        return None, None
    T = as_transform(init, name="init")
    return T, None if window is None else Window(T, *window)


def _plan_wanted(config: RegistrationConfig, images: list[RangeImage]) -> bool:
    """Plan views for these images: ``upright="on"``, or ``"auto"`` and all panoramas."""
    auto = config.prior.upright == "auto" and panoramic(images)
    return config.prior.upright == "on" or auto


@contextmanager
def _single_threaded(workers: int) -> Iterator[ThreadPoolExecutor]:
    """A pool of background threads; the calling thread runs single-threaded in numba until
    the block ends (every thread single-threaded, so that together they fill the cores).
    Interrupted (Ctrl-C, SIGTERM: not an ``Exception``), the block does not wait for the jobs
    still running (a kernel compiling on a cold cache takes a minute): the command unwinds
    and exits without them."""
    pool = ThreadPoolExecutor(max_workers=workers)
    threads = numba.get_num_threads()
    interrupted = False
    try:
        numba.set_num_threads(1)
        yield pool
    except BaseException as e:
        interrupted = not isinstance(e, Exception)
        raise
    finally:
        numba.set_num_threads(threads)
        pool.shutdown(wait=not interrupted, cancel_futures=True)


def register(
    target: Scan | RangeImage,
    source: Scan | RangeImage,
    config: RegistrationConfig = RegistrationConfig(),
    *,
    progress: Progress = None,
    init: NDArray[np.float64] | None = None,
    images: Sequence[RangeImage | None] | None = None,
    window: tuple[float, float] | None = None,
) -> RegistrationResult:
    """Register ``source`` onto ``target``: returns ``T_target_source``.

    Priors come from two independent routes: global descriptor matching (ratio test, mutual
    check, pairwise-consistency pruning, RANSAC) and, for levelled scanners, plan-view overlays
    (:func:`flexreg.stages.priors.upright_priors`). Each prior guides a second matching of all
    keypoints near its predictions (:func:`flexreg.stages.alignment.guided_fit`) and a
    least-squares fit with a shrinking inlier radius. The candidates are judged, after a quick
    local ICP, by the dense free-space check
    (:func:`flexreg.stages.verification.overlap_score`); the winner is the coarse transform,
    refined by ICP (:func:`flexreg.stages.refinement.refine`). The plan views and the checks'
    inputs are computed in two background threads beside the feature stages.

    Parameters
    ----------
    target, source : Scan or RangeImage
        Scans in their own scanner frames (a gridded scan keeps its native grid).
    config : RegistrationConfig
    progress : callable, optional
        Called with the name of each stage as it starts; for the stages that run in background
        threads (plan views, preparation), when the call starts waiting for them.
    init : (4, 4) float64, optional
        A known rough ``T_target_source`` (a stored pose, a guess): it competes with the other
        priors on the same dense check (result ``prior`` ``"init"`` when it wins). With
        ``config.icp_only`` it is the only prior: no global search, ICP from it.
    images : (RangeImage or None, RangeImage or None), optional
        The target's and the source's working images when the caller has them already (read
        with the scans, :func:`flexreg.io.read_working_scan`, which then keeps no grid in the
        scans); each scan then serves only for its points. The call holds them no longer
        than it needs them when the caller keeps no reference of its own.
    window : (float, float), optional
        ``init`` is rough: the true pose lies within this shift (metres) of its translation
        and this turn (radians) of its rotation (two stations' rough positions). The answer
        is then bounded by it: the plan overlays and a RANSAC inside the window
        (:func:`~flexreg.stages.alignment.windowed_fit`) join the priors, and only a
        candidate inside the window can win; the others are judged all the same, and the
        verdict duels the answer against them (a look-alike outside the window still makes
        it ambiguous).

    Raises
    ------
    RegistrationError
        Too few matches or inliers, degenerate (collinear) inliers, or ICP without overlap;
        the message gives the counts. No transform is returned then.
    ConfigError
        ``config.icp_only`` without ``init``; a ``window`` without ``init`` or not positive.
    """
    _check_upright(config)
    init, win = _check_init(config, init, window)
    run = Run(progress)
    scans = [target, source]
    given: list[Scan | RangeImage] = [
        x if i is None else i
        for x, i in zip(scans, [None, None] if images is None else images, strict=True)
    ]
    images = None  # the working images made below replace the given ones
    with run.stage("range images"):
        images = range_images_of(given, config)
    grids = gridded(given)  # a working image given for a scan read lean is its grid
    del given
    roles = [(True, False), (False, True)]
    with _single_threaded(2) as pool:
        plan_job = (
            pool.submit(run.background("plan views", _pair_plan_priors, images, config, win))
            if _plan_wanted(config, images) and not config.icp_only
            else None
        )
        view_job = pool.submit(
            run.background("preparation", scan_views, scans, images, config, roles)
        )
        kps = keypoints_of(images, config, run)
        matched = _match(images, kps, config, run)
        plans, aliases = _plan_candidates(plan_job, config, run, matched.notes)
        run.wait("preparation")
        views = view_job.result()
    return _answer(
        grids, scans, images, kps, views, matched, plans, config, run, init, aliases, win
    )


class Registration:
    """Registration of many pairs among the same scans: each scan prepared once.

    ``Registration(config).prepare(scan)`` computes everything that depends on one scan
    alone (range image, feature image, keypoints and their 3D points, plan views, the checks'
    and the refinement's inputs); ``align(prepared_target, prepared_source)`` registers a pair
    of them. The result equals :func:`register` on the same scans, bit for bit.

    >>> reg = Registration(RegistrationConfig())                    # doctest: +SKIP
    >>> a, b, c = (reg.prepare(s) for s in scans)                   # doctest: +SKIP
    >>> T_ab = reg.align(a, b).T_target_source                      # doctest: +SKIP
    """

    def __init__(self, config: RegistrationConfig = RegistrationConfig()) -> None:
        _check_upright(config)
        self.config = config

    def prepare(
        self,
        scan: Scan | RangeImage,
        *,
        progress: Progress = None,
        overlap: bool = True,
        keep_scan: bool = True,
        image: RangeImage | None = None,
    ) -> PreparedScan:
        """Everything of one scan that :meth:`align` needs, in either role. ``overlap``: the
        plan views and the checks' inputs run beside the feature stages (as in :func:`register`);
        else after them, the same result at a lower peak memory (for survey workers).

        ``keep_scan=False``: the prepared scan's ``scan`` is its working image, and this call
        lets go of the scan as soon as the working image and the refinement's sample are
        made, before the feature stages (a caller that keeps no reference of its own, as
        ``prepare(read_scan(path), keep_scan=False)``, so frees it: the largest array of a
        large station). :meth:`align` gives the same result unless the refinement reads the
        scan's points (the Open3D ICP variants) or the overlap is measured on them: it is
        measured on the working image's points then.

        ``image``: the scan's working image when the caller has it already (a reader that
        builds it while reading, :func:`flexreg.io.read_working_scan`); the scan then serves
        only for the refinement's sample.
        """
        config, run = self.config, Run(progress)
        with run.stage("range images"):
            images = range_images_of([scan if image is None else image], config)
        image = None  # the caller's working image, holes unfilled, is no longer needed
        refine_sample = None
        if not keep_scan:
            with timed_stage(run.timings, "preparation"):
                refine_sample = refinement_sample(scan, config)
            scan = images[0]
        views_of = [None] if not keep_scan else [scan]
        with _single_threaded(2) as pool:
            submit = pool.submit if overlap else (lambda job: SimpleNamespace(result=job))
            plan_job = (
                submit(run.background("plan views", plans_of, images, config))
                if _plan_wanted(config, images)
                else None
            )
            view_job = submit(
                run.background("preparation", scan_views, views_of, images, config, [(True, True)])
            )
            (kp,) = keypoints_of(images, config, run)
            plan = None
            if plan_job is not None:
                run.wait("plan views")
                plan = plan_job.result()[0]
            run.wait("preparation")
            (view,) = view_job.result()
        if not keep_scan:
            view.refine_sample = refine_sample
        symmetries = None
        if isinstance(plan, PlanView) and config.judge.runs("aliases"):
            with timed_stage(run.timings, "plan views"):
                symmetries = self_symmetries(plan)
        return PreparedScan(scan, images[0], kp, plan, view, config, run.timings, symmetries)

    def align(
        self,
        target: PreparedScan,
        source: PreparedScan,
        *,
        progress: Progress = None,
        init: NDArray[np.float64] | None = None,
        window: tuple[float, float] | None = None,
    ) -> RegistrationResult:
        """Register two prepared scans: ``T_target_source`` and the evidence (as
        :func:`register`, ``init`` and ``window`` included)."""
        config = self.config
        init, win = _check_init(config, init, window)
        if target.config != config or source.config != config:
            raise ConfigError("align needs scans prepared with the same configuration")
        run = Run(progress)
        for p in (target, source):
            for name, s in p.timings_s.items():
                run.timings[name] = run.timings.get(name, 0.0) + s
        images, kps = [target.image, source.image], [target.keypoints, source.keypoints]
        with _single_threaded(1) as pool:
            plan_job = (
                pool.submit(
                    run.background(
                        "plan views",
                        _plan_priors,
                        target.plan,
                        source.plan,
                        config,
                        win,
                        (target.symmetries, source.symmetries),
                    )
                )
                if _plan_wanted(config, images) and not config.icp_only
                else None
            )
            matched = _match(images, kps, config, run)
            plans, aliases = _plan_candidates(plan_job, config, run, matched.notes)
        scans, views = [target.scan, source.scan], [target.view, source.view]
        grids = gridded(scans)
        return _answer(
            grids, scans, images, kps, views, matched, plans, config, run, init, aliases, win
        )


__all__ = [
    "PreparedScan",
    "Registration",
    "RegistrationConfig",
    "RegistrationResult",
    "ScanView",
    "feature_image",
    "register",
]
