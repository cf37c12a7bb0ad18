"""The ``register`` calls of ``benchmarks/registration.py`` and the criteria they are judged by.

The synthetic suite, the speed run and the real pairs each give JSON-ready records (one per
``register`` call); :func:`summarise` sums up the synthetic ones. The Markdown and the figure
are made from these records by ``_registration_report``.

``registration.py`` imports this module as a sibling: ``python benchmarks/registration.py``
puts ``benchmarks/`` on ``sys.path``.
"""

from __future__ import annotations

import math
import statistics
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from flexreg.core.scan import Scan
from flexreg.core.transforms import invert, rotation_error_deg, translation_error_m
from flexreg.errors import RegistrationError
from flexreg.io import read_scan, read_scans
from flexreg.registration import RegistrationConfig, register
from flexreg.stages.projection import range_image
from flexreg.stages.refinement import refine
from flexreg.stages.sampling import area_sample
from flexreg.synth import station_pair

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data"

SCENES = ("room", "courtyard")
# acceptance criteria
COARSE_ROT_DEG, COARSE_TRANS_M = 0.5, 0.05  # success before refinement
TARGET_SUCCESS = 0.95
TARGET_ROT_DEG, TARGET_TRANS_M = 0.01, 0.002  # median after refinement
TARGET_SPEED_S = 10.0
BUNNY_ROT_DEG, BUNNY_TRANS_M = 1.0, 0.005
VELODYNE_REF_ROT_DEG, VELODYNE_REF_TRANS_M = 0.2, 0.02  # uncertainty of the reference
# 3DTK: the data's config.ini drops points nearer than 48 cm (the robot's own body, which moves
# with the scanner and would favour "no motion"); the same minimum range is used here
KURT_MIN_RANGE_M = 0.48
KURT_PAIRS = ((0, 1), (1, 2), (0, 2))
KURT_GROSS_ROT_DEG, KURT_GROSS_TRANS_M = 5.0, 0.5  # further from odometry = wrong solution
KURT_ODOMETRY_ERROR_M = 0.05  # ICP start tolerance when register failed (no threshold)
NN_WITHIN_M = 0.05


# ------------------------------------------------------------------ one register call


def timed_register(
    target: Scan,
    source: Scan,
    config: RegistrationConfig,
    T_ref: NDArray[np.float64] | None = None,
) -> dict[str, Any]:
    """One ``register`` call, timed alone.

    Parameters
    ----------
    target, source : Scan
        The pair.
    config : RegistrationConfig
        The configuration of the call.
    T_ref : (4, 4) array, optional
        The reference ``T_target_source``; without it the record has no errors.

    Returns
    -------
    dict
        JSON-ready: ``ok``, times, the result's fields and transforms and, with ``T_ref``, the
        rotation and translation errors before (``*_coarse_*``) and after refinement; when
        ``register`` raised, ``ok`` False, the error and infinite errors (:data:`FAILURE_ERRORS`).
    """
    t0 = time.perf_counter()
    try:
        res = register(target, source, config)
    except RegistrationError as e:
        return _failure(time.perf_counter() - t0, "RegistrationError", str(e))
    except Exception as e:  # a bug in the code under tuning must not end a long run
        traceback.print_exc()
        return _failure(time.perf_counter() - t0, type(e).__name__, str(e))
    total = time.perf_counter() - t0
    rec: dict[str, Any] = {
        "ok": True,
        "error": None,
        "error_type": None,
        "total_s": total,
        "timings_s": dict(res.timings_s),
        "prior": res.prior,
        "matches": res.matches,
        "inliers": res.inliers,
        "inlier_rmse_m": res.inlier_rmse_m,
        "fitness": res.fitness,
        "fitness_denominator": res.fitness_denominator,
        # the one overlap figure (flexreg.stages.overlap) and Open3D's on the same clouds
        "overlap_result": None if res.overlap is None else res.overlap.to_dict(),
        "threshold_m": res.threshold_m,
        "T_coarse": res.T_coarse.tolist(),
        "T_target_source": res.T_target_source.tolist(),
    }
    if T_ref is not None:
        rec |= {
            "T_reference": np.asarray(T_ref).tolist(),
            "rot_coarse_deg": rotation_error_deg(res.T_coarse, T_ref),
            "trans_coarse_m": translation_error_m(res.T_coarse, T_ref),
            "rot_deg": rotation_error_deg(res.T_target_source, T_ref),
            "trans_m": translation_error_m(res.T_target_source, T_ref),
        }
    return rec


#: the errors of a pair whose ``register`` raised (infinite: they count in the medians)
FAILURE_ERRORS = ("rot_coarse_deg", "trans_coarse_m", "rot_deg", "trans_m")


def _failure(total_s: float, kind: str, message: str) -> dict[str, Any]:
    """The record of a ``register`` call that raised.

    Parameters
    ----------
    total_s : float
        Seconds until it raised.
    kind : str
        The exception's class name.
    message : str
        Its message.

    Returns
    -------
    dict
        ``ok`` False, the error, and the :data:`FAILURE_ERRORS` as infinity.
    """
    return {
        "ok": False,
        "error": message,
        "error_type": kind,
        "total_s": total_s,
        "timings_s": {},
        **dict.fromkeys(FAILURE_ERRORS, math.inf),
    }


def coarse_success(rec: dict[str, Any]) -> bool:
    """Whether a record's ``T_coarse`` is within the success limits.

    Parameters
    ----------
    rec : dict
        A record of :func:`timed_register` made with a reference.

    Returns
    -------
    bool
        Registered, and ``T_coarse`` within ``COARSE_ROT_DEG`` and ``COARSE_TRANS_M`` of the
        reference.
    """
    return bool(
        rec["ok"]
        and rec["rot_coarse_deg"] < COARSE_ROT_DEG
        and rec["trans_coarse_m"] < COARSE_TRANS_M
    )


def warm_up(config: RegistrationConfig) -> None:
    """A first call on a small pair: compiles (or loads) the numba kernels, imports Open3D.

    Parameters
    ----------
    config : RegistrationConfig
        The configuration of the timed calls.
    """
    p = station_pair("room", seed=0, resolution=(512, 256))
    t0 = time.perf_counter()
    rec = timed_register(p.target, p.source, config, p.T_target_source)
    print(f"warm-up (512x256 room pair): {time.perf_counter() - t0:.1f} s", flush=True)
    if not rec["ok"]:
        print(f"  warm-up registration failed: {rec['error']}", flush=True)


# ------------------------------------------------------------------ synthetic suite and speed run


def synthetic_suite(
    pairs: int,
    resolution: tuple[int, int],
    config: RegistrationConfig,
    save: Callable[[], None],
    out: list[dict[str, Any]],
) -> None:
    """Register ``pairs`` station pairs per scene kind, saving after each.

    Parameters
    ----------
    pairs : int
        Pairs per scene kind (seeds ``0 .. pairs - 1``).
    resolution : (int, int)
        Width and height of the synthetic stations.
    config : RegistrationConfig
        The configuration of every call.
    save : callable
        Called after each pair.
    out : list of dict
        Gets one record per pair (:func:`timed_register`'s, with the pair's scene, seed,
        distance, overlap, points and synthesis time, and ``coarse_success``).
    """
    n = pairs * len(SCENES)
    for scene in SCENES:
        for seed in range(pairs):
            t0 = time.perf_counter()
            p = station_pair(scene, seed=seed, resolution=resolution)
            synth_s = time.perf_counter() - t0
            rec = {
                "scene": scene,
                "seed": seed,
                "resolution": list(resolution),
                "distance_m": p.distance_m,
                "overlap": p.overlap,
                "points": [len(p.target), len(p.source)],
                "synth_s": synth_s,
            }
            rec |= timed_register(p.target, p.source, config, p.T_target_source)
            rec["coarse_success"] = coarse_success(rec)
            out.append(rec)
            save()
            del p
            print(f"[{len(out)}/{n}] {_progress(rec)}", flush=True)


def _progress(r: dict[str, Any]) -> str:
    """The progress line of a synthetic pair's record.

    Parameters
    ----------
    r : dict
        A record of :func:`synthetic_suite`.

    Returns
    -------
    str
        Its pair, errors before and after refinement, time and prior, or its failure.
    """
    head = f"{r['scene']} seed {r['seed']}: {r['distance_m']:.2f} m, overlap {r['overlap']:.2f}"
    if not r["ok"]:
        return f"{head} -> FAILED after {r['total_s']:.1f} s ({r['error_type']}: {r['error']})"
    return (
        f"{head} -> coarse {r['rot_coarse_deg']:.3f} deg / {1000 * r['trans_coarse_m']:.1f} mm "
        f"({'ok' if r['coarse_success'] else 'MISS'}), refined {r['rot_deg']:.4f} deg / "
        f"{1000 * r['trans_m']:.2f} mm, {r['total_s']:.1f} s, prior {r['prior']}"
    )


def speed_run(
    resolution: tuple[int, int], config: RegistrationConfig, repeats: int
) -> dict[str, Any]:
    """Two large room stations (seed 0): ``register`` with and without refinement.

    Parameters
    ----------
    resolution : (int, int)
        Width and height of the stations.
    config : RegistrationConfig
        The configuration (its ``refine`` is set for each setting).
    repeats : int
        Timed calls per setting.

    Returns
    -------
    dict
        The pair (points, distance, overlap, synthesis time) and ``runs``: the records of
        :func:`timed_register` under ``"with refinement"`` and ``"without refinement"``.
    """
    t0 = time.perf_counter()
    p = station_pair("room", seed=0, resolution=resolution)
    synth_s = time.perf_counter() - t0
    print(
        f"speed pair {resolution[0]}x{resolution[1]}: {len(p.target):,} + {len(p.source):,} "
        f"points, {p.distance_m:.2f} m, overlap {p.overlap:.2f} (synthesis {synth_s:.1f} s)",
        flush=True,
    )
    out: dict[str, Any] = {
        "scene": "room",
        "seed": 0,
        "resolution": list(resolution),
        "points": [len(p.target), len(p.source)],
        "distance_m": p.distance_m,
        "overlap": p.overlap,
        "synth_s": synth_s,
        "runs": {},
    }
    for label, refined in (("with refinement", True), ("without refinement", False)):
        runs = []
        for _ in range(repeats):
            rec = timed_register(
                p.target, p.source, config.replace(refine=refined), p.T_target_source
            )
            runs.append(rec)
            state = (
                f"{rec['rot_deg']:.4f} deg / {1000 * rec['trans_m']:.2f} mm"
                if rec["ok"]
                else f"FAILED ({rec['error']})"
            )
            print(f"  {label}: {rec['total_s']:.2f} s, {state}", flush=True)
        out["runs"][label] = runs
    return out


# ------------------------------------------------------------------ real pairs


def _range_image_note(scan: Scan) -> dict[str, Any]:
    """Size and valid share of the range image ``register`` builds from a scan.

    Parameters
    ----------
    scan : Scan
        The scan.

    Returns
    -------
    dict
        ``width``, ``height`` and ``valid`` (the share of pixels holding a point).
    """
    img = range_image(scan)
    return {"width": img.width, "height": img.height, "valid": float(img.valid.mean())}


class _Nearest:
    """Nearest-neighbour distances from sampled source points to the target (every k-th point
    of it, at most a million)."""

    def __init__(self, target: NDArray[np.float64], source: NDArray[np.float64]) -> None:
        self.source = source
        self._tree = cKDTree(target[:: max(1, math.ceil(len(target) / 1_000_000))])

    def distances(self, T: NDArray[np.float64]) -> NDArray[np.float64]:
        d, _ = self._tree.query(self.source @ T[:3, :3].T + T[:3, 3])
        return np.asarray(d, dtype=np.float64)


def _nn_fit(fit: _Nearest, T: NDArray[np.float64]) -> tuple[float, float]:
    """How well ``T`` lays the fit's source points onto its target.

    Parameters
    ----------
    fit : _Nearest
        The target and the sampled source points.
    T : (4, 4) array
        A ``T_target_source``.

    Returns
    -------
    (float, float)
        The median nearest-neighbour distance (m) and the share within ``NN_WITHIN_M``.
    """
    d = fit.distances(T)
    return float(np.median(d)), float(np.mean(d < NN_WITHIN_M))


def bunny_gt_from_conf(path: Path) -> dict[str, NDArray[np.float64]]:
    """``T_world_scan`` of each scan of a Stanford ``.conf`` file.

    A line ``bmesh <file> tx ty tz qx qy qz qw`` means ``p_world = R(conj(q)) p_scan + t`` with
    the quaternion as written (xyzw): the conjugate, i.e. the inverse rotation (see the data's
    README; q itself does not align the scans).

    Parameters
    ----------
    path : Path
        The ``.conf`` file.

    Returns
    -------
    dict
        ``T_world_scan`` (4 x 4) by the stem of each scan's file name.
    """
    from scipy.spatial.transform import Rotation

    poses = {}
    for line in path.read_text().splitlines():
        f = line.split()
        if f and f[0] == "bmesh":
            T = np.eye(4)
            T[:3, :3] = Rotation.from_quat([float(v) for v in f[5:9]]).inv().as_matrix()
            T[:3, 3] = [float(v) for v in f[2:5]]
            poses[Path(f[1]).stem] = T
    return poses


def real_pairs(config: RegistrationConfig) -> list[dict[str, Any]]:
    """Register the real pairs; missing data is reported as a skipped pair.

    Parameters
    ----------
    config : RegistrationConfig
        The configuration of every call.

    Returns
    -------
    list of dict
        One record per pair (:func:`timed_register`'s, with the pair's name, reference,
        points, range images and what its data set adds), or ``{"pair", "skipped"}`` for data
        that is not there.
    """
    out: list[dict[str, Any]] = []
    _bunny(config, out)
    _kurt3d(config, out)
    _velodyne(config, out)
    return out


def _run_pair(
    config: RegistrationConfig,
    out: list[dict[str, Any]],
    name: str,
    reference: str,
    pair: tuple[Scan, Scan],
    T_ref: Any,
) -> dict[str, Any]:
    """Register one real pair, print its line and append its record to ``out``.

    Parameters
    ----------
    config : RegistrationConfig
        The configuration of the call.
    out : list of dict
        The records so far.
    name, reference : str
        The pair (``target <- source``) and where its reference comes from.
    pair : (Scan, Scan)
        Target and source.
    T_ref : (4, 4) array
        The reference ``T_target_source``.

    Returns
    -------
    dict
        The record (also appended to ``out``).
    """
    target, source = pair
    rec: dict[str, Any] = {
        "pair": name,
        "reference": reference,
        "points": [len(target), len(source)],
        "range_images": [_range_image_note(target), _range_image_note(source)],
    }
    rec |= timed_register(target, source, config, T_ref)
    out.append(rec)
    state = (
        f"{rec['rot_coarse_deg']:.3f} deg / {rec['trans_coarse_m']:.4f} m coarse, "
        f"{rec['rot_deg']:.3f} deg / {rec['trans_m']:.4f} m refined, prior {rec['prior']}"
        if rec["ok"]
        else f"FAILED ({rec['error_type']}: {rec['error']})"
    )
    print(f"{name} vs {reference}: {state}, {rec['total_s']:.1f} s", flush=True)
    return rec


def _missing(out: list[dict[str, Any]], name: str, path: Path) -> None:
    """Report a data set that is not there and append its skipped record to ``out``.

    Parameters
    ----------
    out : list of dict
        The records so far.
    name : str
        The data set.
    path : Path
        The file that was looked for.
    """
    print(f"{name}: skipped, {path} not found", flush=True)
    out.append({"pair": name, "skipped": f"{path} not found"})


def _bunny(config: RegistrationConfig, out: list[dict[str, Any]]) -> None:
    """Stanford bunny: bun000 (target, = world frame) <- bun045, against its ground truth,
    which is checked against ``bun.conf``.

    Parameters
    ----------
    config : RegistrationConfig
        The configuration of the call.
    out : list of dict
        Gets the pair's record.
    """
    folder = DATA / "bunny_range_scans_gt"
    npz = folder / "derived_bunny_grids_and_gt.npz"
    if not npz.is_file():
        _missing(out, "bunny", npz)
        return
    a, b = read_scans(npz)
    T_gt = invert(a.T_world_scanner) @ b.T_world_scanner
    rec = _run_pair(config, out, "bunny bun000 <- bun045", "ground truth (bun.conf)", (a, b), T_gt)
    conf = bunny_gt_from_conf(folder / "bun.conf")
    T_conf = invert(conf["bun000"]) @ conf["bun045"]
    rec["gt_check_vs_bun_conf"] = {
        "rot_deg": rotation_error_deg(T_gt, T_conf),
        "trans_m": translation_error_m(T_gt, T_conf),
    }


def _kurt3d(config: RegistrationConfig, out: list[dict[str, Any]]) -> None:
    """3DTK Kurt3D: the ``KURT_PAIRS`` of its three scans against the odometry prior (which is
    not given to ``register``: it ignores stored poses), their fits and the loop check.

    Parameters
    ----------
    config : RegistrationConfig
        The configuration of the calls.
    out : list of dict
        Gets the pairs' records.
    """
    folder = DATA / "tls_3dtk_kurt3d"
    if not (folder / "scan000.3d").is_file():
        _missing(out, "3DTK", folder / "scan000.3d")
        return
    k = [read_scan(folder / f"scan00{i}.3d", min_range_m=KURT_MIN_RANGE_M) for i in range(3)]
    for i, j in KURT_PAIRS:
        T_prior = invert(k[i].T_world_scanner) @ k[j].T_world_scanner
        name = f"3DTK scan00{i} <- scan00{j}"
        rec = _run_pair(config, out, name, "odometry prior", (k[i], k[j]), T_prior)
        _kurt_fits(rec, k[i], k[j], T_prior)
    _loop_check(out)


def _kurt_fits(
    rec: dict[str, Any], target: Scan, source: Scan, T_prior: NDArray[np.float64]
) -> None:
    """Add to a 3DTK record how well the odometry prior, the result and the prior refined by
    ICP lay the source onto the target (``nn_*``, see :func:`_nn_fit`).

    Parameters
    ----------
    rec : dict
        The pair's record.
    target, source : Scan
        The pair.
    T_prior : (4, 4) array
        The odometry prior ``T_target_source``.
    """
    # the source sampled evenly over its surfaces (the dense near field must not dominate)
    tree = _Nearest(target.points, area_sample(source.points, 20000))
    rec["prior_distance_m"] = float(np.linalg.norm(T_prior[:3, 3]))
    rec["nn_prior"] = _nn_fit(tree, T_prior)
    if rec["ok"]:
        rec["nn_result"] = _nn_fit(tree, np.asarray(rec["T_target_source"]))
    # the same refinement register uses, started from the odometry: the nearest local optimum
    try:
        thr = rec.get("threshold_m") or KURT_ODOMETRY_ERROR_M
        T_icp = refine(target, source, T_prior, threshold_m=thr).T_target_source
        rec["T_prior_icp"] = T_icp.tolist()
        rec["nn_prior_icp"] = _nn_fit(tree, T_icp)
    except RegistrationError as e:
        rec["prior_icp_error"] = str(e)


def _loop_check(out: list[dict[str, Any]]) -> None:
    """No reference needed: scan000 <- scan001 <- scan002 against the direct result, added to
    the scan000 <- scan002 record as ``loop_vs_chain`` when all three registered.

    Parameters
    ----------
    out : list of dict
        The records, with the three 3DTK pairs.
    """
    by = {r["pair"]: r for r in out}
    chain = [by[f"3DTK scan00{i} <- scan00{j}"] for i, j in ((0, 1), (1, 2), (0, 2))]
    if all(r["ok"] for r in chain):
        T01, T12, T02 = (np.asarray(r["T_target_source"]) for r in chain)
        chain[2]["loop_vs_chain"] = {
            "rot_deg": rotation_error_deg(T01 @ T12, T02),
            "trans_m": translation_error_m(T01 @ T12, T02),
        }


def _velodyne(config: RegistrationConfig, out: list[dict[str, Any]]) -> None:
    """The Velodyne pair of fast_gicp against its ``relative.txt`` (``T_target_source``), and
    how far small_gicp's matrix for the same scans is from that reference.

    Parameters
    ----------
    config : RegistrationConfig
        The configuration of the call.
    out : list of dict
        Gets the pair's record.
    """
    folder = DATA / "lidar_pair_fast_gicp"
    if not (folder / "relative.txt").is_file():
        _missing(out, "Velodyne", folder / "relative.txt")
        return
    t = read_scan(folder / "251370668.pcd")
    s = read_scan(folder / "251371071.pcd")
    T_ref = np.loadtxt(folder / "relative.txt")
    name = "Velodyne 251370668 <- 251371071"
    rec = _run_pair(config, out, name, "fast_gicp relative.txt", (t, s), T_ref)
    T_small = np.loadtxt(folder / "small_gicp_T_target_source.txt")
    rec["reference_spread"] = {
        "rot_deg": rotation_error_deg(T_ref, T_small),
        "trans_m": translation_error_m(T_ref, T_small),
    }


# ------------------------------------------------------------------ summaries


def median(values: list[float]) -> float:
    """The median, NaN for no values.

    Parameters
    ----------
    values : list of float
        The values.

    Returns
    -------
    float
    """
    return statistics.median(values) if values else math.nan


def summarise(records: list[dict[str, Any]]) -> dict[str, Any]:
    """Success rate and medians of a set of synthetic pairs (failures: infinite error).

    Parameters
    ----------
    records : list of dict
        Records of :func:`synthetic_suite`.

    Returns
    -------
    dict
        Pairs, registered pairs, coarse successes and their rate, the median errors before
        and after refinement, and the median and longest time.
    """
    n = len(records)
    ok = [r for r in records if r["ok"]]
    succ = sum(r["coarse_success"] for r in records)
    return {
        "pairs": n,
        "registered": len(ok),
        "coarse_successes": succ,
        "coarse_success_rate": succ / n if n else math.nan,
        "median_rot_deg": median([r["rot_deg"] for r in records]),
        "median_trans_m": median([r["trans_m"] for r in records]),
        "median_rot_coarse_deg": median([r["rot_coarse_deg"] for r in records]),
        "median_trans_coarse_m": median([r["trans_coarse_m"] for r in records]),
        "median_total_s": median([r["total_s"] for r in records]),
        "max_total_s": max((r["total_s"] for r in records), default=math.nan),
    }
