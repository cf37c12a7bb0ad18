"""Registration accuracy and speed: synthetic station pairs, two 4096 x 2048 stations, real pairs.

Sections (the acceptance criteria of ``flexreg.registration.pipeline.register``)
  * synthetic suite: ``--pairs`` room and ``--pairs`` courtyard station pairs (seeds 0..N-1) from
    :func:`flexreg.synth.station_pair` -- stations 2-10 m apart, any yaw, tilt up to 5 deg, 3 mm
    range noise -- each registered once with ICP refinement, which gives both the coarse
    (``T_coarse``) and the refined transform. Success before refinement: ``T_coarse`` within
    0.5 deg and 5 cm of the truth (target: at least 95 % of the pairs). Targets after
    refinement: median error below 0.01 deg and 2 mm. A pair whose ``register`` raises counts as
    a failure, with infinite error in the medians.
  * speed: two 4096 x 2048 room stations (seed 0); only the ``register`` call is timed (no
    loading or synthesis), with and without refinement; target at most 10 s with refinement.
  * real pairs from ``../shared/data``: the Stanford bunny (bun000 <- bun045, ground truth from
    bun.conf), the three 3DTK Kurt3D scans (no ground truth: the difference to the odometry
    prior is reported; the prior is not given to ``register``) and two Velodyne scans of the
    fast_gicp repository (reference: its relative.txt, itself a registration result).

Every ``register`` call uses the default :class:`flexreg.registration.pipeline.RegistrationConfig`
with
``refine=True`` and ``seed=--seed``. One warm-up call on a small pair comes first (numba kernels
compile or load from the cache then); it is not part of any figure.

Raw per-pair results go to ``benchmarks/results/registration-<timestamp>/`` (``results.json``,
rewritten after every pair, ``config.json``, ``results.md`` and the figure).

Usage::

    .venv/bin/python benchmarks/registration.py               # full run: print the tables
    .venv/bin/python benchmarks/registration.py --write-docs  # also rewrite "## Registration"
                                                              # in docs/benchmarks.md + figure
    .venv/bin/python benchmarks/registration.py --quick       # 3 + 3 pairs at 1024x512, no
                                                              # 4096 x 2048 run (smoke test)
    .venv/bin/python benchmarks/registration.py --write-docs --from-json \
        benchmarks/results/registration-<timestamp>/results.json  # render a saved run again
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from flexreg.bench.compare import FitEvaluator  # noqa: E402
from flexreg.bench.harness import machine_info, publish, results_folder, write_json  # noqa: E402
from flexreg.core.scan import Scan  # noqa: E402
from flexreg.core.transforms import invert, rotation_error_deg, translation_error_m  # noqa: E402
from flexreg.errors import RegistrationError  # noqa: E402
from flexreg.registration import RegistrationConfig, register  # noqa: E402
from flexreg.stages.refinement import refine  # noqa: E402
from flexreg.stages.sampling import area_sample  # noqa: E402

DATA = REPO.parent / "shared" / "data"
DOC = REPO / "docs" / "benchmarks.md"
FIGURE = REPO / "docs" / "figures" / "registration-synthetic.png"
RESULTS = REPO / "benchmarks" / "results"
SECTION = "## Registration"

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
    """One ``register`` call, timed alone: a JSON-ready record with the errors against
    ``T_ref``, or with the error it raised (``ok`` False)."""
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
    return {
        "ok": False,
        "error": message,
        "error_type": kind,
        "total_s": total_s,
        "timings_s": {},
        **dict.fromkeys(FAILURE_ERRORS, math.inf),
    }


def coarse_success(rec: dict[str, Any]) -> bool:
    return bool(
        rec["ok"]
        and rec["rot_coarse_deg"] < COARSE_ROT_DEG
        and rec["trans_coarse_m"] < COARSE_TRANS_M
    )


def warm_up(config: RegistrationConfig) -> None:
    """A first call on a small pair: compiles (or loads) the numba kernels, imports Open3D."""
    from flexreg.synth import station_pair

    p = station_pair("room", seed=0, resolution=(512, 256))
    t0 = time.perf_counter()
    rec = timed_register(p.target, p.source, config, p.T_target_source)
    print(f"warm-up (512x256 room pair): {time.perf_counter() - t0:.1f} s", flush=True)
    if not rec["ok"]:
        print(f"  warm-up registration failed: {rec['error']}", flush=True)


# ------------------------------------------------------------------ sections


def synthetic_suite(
    pairs: int,
    resolution: tuple[int, int],
    config: RegistrationConfig,
    save: Callable[[], None],
    out: list[dict[str, Any]],
) -> None:
    """Register ``pairs`` station pairs per scene kind; appends one record per pair to
    ``out`` (and saves after each)."""
    from flexreg.synth import station_pair

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
    """Two large room stations (seed 0): ``register`` with and without refinement."""
    from flexreg.synth import station_pair

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


def _range_image_note(scan: Scan) -> dict[str, Any]:
    """Size and valid share of the range image ``register`` builds from a scan."""
    from flexreg.stages.projection import range_image

    img = range_image(scan)
    return {"width": img.width, "height": img.height, "valid": float(img.valid.mean())}


def _nn_fit(fit: FitEvaluator, T: NDArray[np.float64]) -> tuple[float, float]:
    """(median nearest-neighbour distance m, share within NN_WITHIN_M) of the fit's source
    points mapped by ``T``."""
    d = fit.distances(T)
    return float(np.median(d)), float(np.mean(d < NN_WITHIN_M))


def bunny_gt_from_conf(path: Path) -> dict[str, NDArray[np.float64]]:
    """``T_world_scan`` of each scan of a Stanford ``.conf`` file.

    A line ``bmesh <file> tx ty tz qx qy qz qw`` means ``p_world = R(conj(q)) p_scan + t`` with
    the quaternion as written (xyzw): the conjugate, i.e. the inverse rotation (see the data's
    README; q itself does not align the scans).
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
    """Register the real pairs; missing data is reported as a skipped pair."""
    from flexreg.io import read_scan, read_scans

    out: list[dict[str, Any]] = []

    def run(name: str, reference: str, target: Scan, source: Scan, T_ref: Any) -> dict[str, Any]:
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

    def missing(name: str, path: Path) -> None:
        print(f"{name}: skipped, {path} not found", flush=True)
        out.append({"pair": name, "skipped": f"{path} not found"})

    # Stanford bunny: bun000 (target, = world frame) <- bun045
    folder = DATA / "bunny_range_scans_gt"
    npz = folder / "derived_bunny_grids_and_gt.npz"
    if npz.is_file():
        a, b = read_scans(npz)
        T_gt = invert(a.T_world_scanner) @ b.T_world_scanner
        rec = run("bunny bun000 <- bun045", "ground truth (bun.conf)", a, b, T_gt)
        conf = bunny_gt_from_conf(folder / "bun.conf")
        T_conf = invert(conf["bun000"]) @ conf["bun045"]
        rec["gt_check_vs_bun_conf"] = {
            "rot_deg": rotation_error_deg(T_gt, T_conf),
            "trans_m": translation_error_m(T_gt, T_conf),
        }
    else:
        missing("bunny", npz)

    # 3DTK Kurt3D: the odometry poses are not given to register (it ignores stored poses)
    folder = DATA / "tls_3dtk_kurt3d"
    if (folder / "scan000.3d").is_file():
        k = [read_scan(folder / f"scan00{i}.3d", min_range_m=KURT_MIN_RANGE_M) for i in range(3)]
        for i, j in KURT_PAIRS:
            T_prior = invert(k[i].T_world_scanner) @ k[j].T_world_scanner
            rec = run(f"3DTK scan00{i} <- scan00{j}", "odometry prior", k[i], k[j], T_prior)
            # the source sampled evenly over its surfaces (the dense near field must not dominate)
            tree = FitEvaluator(k[i].points, area_sample(k[j].points, 20000), NN_WITHIN_M)
            rec["prior_distance_m"] = float(np.linalg.norm(T_prior[:3, 3]))
            rec["nn_prior"] = _nn_fit(tree, T_prior)
            if rec["ok"]:
                rec["nn_result"] = _nn_fit(tree, np.asarray(rec["T_target_source"]))
            # the same refinement register uses, started from the odometry: the nearest local
            # optimum
            try:
                thr = rec.get("threshold_m") or KURT_ODOMETRY_ERROR_M
                T_icp = refine(k[i], k[j], T_prior, threshold_m=thr).T_target_source
                rec["T_prior_icp"] = T_icp.tolist()
                rec["nn_prior_icp"] = _nn_fit(tree, T_icp)
            except RegistrationError as e:
                rec["prior_icp_error"] = str(e)
        # loop check, no reference needed: scan000 <- scan001 <- scan002 against the direct result
        by = {r["pair"]: r for r in out}
        chain = [by[f"3DTK scan00{i} <- scan00{j}"] for i, j in ((0, 1), (1, 2), (0, 2))]
        if all(r["ok"] for r in chain):
            T01, T12, T02 = (np.asarray(r["T_target_source"]) for r in chain)
            chain[2]["loop_vs_chain"] = {
                "rot_deg": rotation_error_deg(T01 @ T12, T02),
                "trans_m": translation_error_m(T01 @ T12, T02),
            }
    else:
        missing("3DTK", folder / "scan000.3d")

    # Velodyne pair of fast_gicp: reference relative.txt (T_target_source)
    folder = DATA / "lidar_pair_fast_gicp"
    if (folder / "relative.txt").is_file():
        t = read_scan(folder / "251370668.pcd")
        s = read_scan(folder / "251371071.pcd")
        T_ref = np.loadtxt(folder / "relative.txt")
        rec = run("Velodyne 251370668 <- 251371071", "fast_gicp relative.txt", t, s, T_ref)
        T_small = np.loadtxt(folder / "small_gicp_T_target_source.txt")
        rec["reference_spread"] = {
            "rot_deg": rotation_error_deg(T_ref, T_small),
            "trans_m": translation_error_m(T_ref, T_small),
        }
    else:
        missing("Velodyne", folder / "relative.txt")
    return out


# ------------------------------------------------------------------ summaries and rendering


def median(values: list[float]) -> float:
    return statistics.median(values) if values else math.nan


def summarise(records: list[dict[str, Any]]) -> dict[str, Any]:
    """Success rate and medians of a set of synthetic pairs (failures: infinite error)."""
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


def stage_names(records: list[dict[str, Any]]) -> list[str]:
    names: dict[str, None] = {}
    for r in records:
        names |= dict.fromkeys(r.get("timings_s", {}))
    return list(names)


def _f(x: float, fmt: str, scale: float = 1.0) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "–"
    if math.isinf(x):
        return "∞"
    return format(x * scale, fmt)


def _verdict(ok: bool) -> str:
    return "**met**" if ok else "**NOT met**"


def render_synthetic(records: list[dict[str, Any]], resolution: tuple[int, int]) -> list[str]:
    w, h = resolution
    kinds = [s for s in SCENES if any(r["scene"] == s for r in records)]
    groups = [("all", records)] + [(s, [r for r in records if r["scene"] == s]) for s in kinds]
    sums = {name: summarise(rs) for name, rs in groups}
    seeds = sorted({r["seed"] for r in records})
    lines = [
        "### Synthetic station pairs",
        "",
        f"{' + '.join(f'{len(rs)} {s}' for s, rs in groups[1:])} pairs (seeds "
        f"{seeds[0]}..{seeds[-1]}) from `flexreg.synth.station_pair` at {w} x {h}: stations "
        "2–10 m apart, any yaw, tilt up to 5°, 3 mm range noise, mutual visibility overlap at "
        "least 0.5 (the smaller of the two stations' shares of rays that see the other's "
        "surfaces). One `register` call per pair (ICP refinement on) gives both the coarse "
        "transform (`T_coarse`, before ICP) and the refined one. **Success before refinement** "
        f"= `T_coarse` within {COARSE_ROT_DEG}° and {100 * COARSE_TRANS_M:.0f} cm of the truth. "
        "A pair whose `register` raises counts as a failure and as an infinite error in the "
        "medians. Time = the `register` call alone (the scans are already in memory).",
        "",
        "| | " + " | ".join(name for name, _ in groups) + " | target |",
        "|---|" + "---:|" * len(groups) + "---|",
    ]
    s_all = sums["all"]

    def row(label: str, cell: Callable[[dict[str, Any]], str], target: str) -> str:
        return f"| {label} | " + " | ".join(cell(sums[n]) for n, _ in groups) + f" | {target} |"

    lines += [
        row(
            "success before refinement",
            lambda s: (
                f"{s['coarse_successes']}/{s['pairs']} ({_f(s['coarse_success_rate'], '.0%')})"
            ),
            f"≥ {TARGET_SUCCESS:.0%}: {_verdict(s_all['coarse_success_rate'] >= TARGET_SUCCESS)}",
        ),
        row("registered (no error raised)", lambda s: f"{s['registered']}/{s['pairs']}", ""),
        row(
            "median rotation error before refinement (°)",
            lambda s: _f(s["median_rot_coarse_deg"], ".3f"),
            "",
        ),
        row(
            "median translation error before refinement (mm)",
            lambda s: _f(s["median_trans_coarse_m"], ".2f", 1000),
            "",
        ),
        row(
            "median rotation error after refinement (°)",
            lambda s: _f(s["median_rot_deg"], ".4f"),
            f"< {TARGET_ROT_DEG}: {_verdict(s_all['median_rot_deg'] < TARGET_ROT_DEG)}",
        ),
        row(
            "median translation error after refinement (mm)",
            lambda s: _f(s["median_trans_m"], ".2f", 1000),
            f"< {1000 * TARGET_TRANS_M:.0f}: {_verdict(s_all['median_trans_m'] < TARGET_TRANS_M)}",
        ),
        row("median time per pair (s)", lambda s: _f(s["median_total_s"], ".1f"), ""),
        row("slowest pair (s)", lambda s: _f(s["max_total_s"], ".1f"), ""),
    ]

    return lines + _stage_medians(records) + _pair_rows(records) + _stage_rows(records)


def _stage_medians(records: list[dict[str, Any]]) -> list[str]:
    """Median and slowest time of each stage over the registered pairs."""
    stages = stage_names(records)
    ok = [r for r in records if r["ok"]]
    lines = [
        "",
        f"Median time per stage over the {len(ok)} registered pairs (`timings_s`; the plan views "
        "and the preparation of the checks run in background threads beside the feature stages, "
        "so the stages add up to more than the total):",
        "",
        "| stage | median s | max s | pairs |",
        "|---|---:|---:|---:|",
    ]
    for st in [*stages, "total"]:
        if st == "total":
            vals = [r["total_s"] for r in ok]
        else:
            vals = [r["timings_s"][st] for r in ok if st in r["timings_s"]]
        lines.append(
            f"| {st} | {_f(median(vals), '.2f')} | {_f(max(vals, default=math.nan), '.2f')} "
            f"| {len(vals)} |"
        )

    return lines


def _pair_rows(records: list[dict[str, Any]]) -> list[str]:
    """One row per synthetic pair, then the failures' messages."""
    lines = [
        "",
        "Per pair (errors against the exact `T_target_source`; *prior* = which prior led to the "
        "estimate; inliers / matches of the final guided matching):",
        "",
        "| scene | seed | distance m | overlap | prior | inliers / matches | coarse ° "
        "| coarse mm | success before refinement | refined ° | refined mm | time s |",
        "|---|---:|---:|---:|---|---:|---:|---:|---|---:|---:|---:|",
    ]
    for r in records:
        head = f"| {r['scene']} | {r['seed']} | {r['distance_m']:.2f} | {r['overlap']:.2f} "
        if not r["ok"]:
            lines.append(head + f"| **failed** | | | | no | | | {r['total_s']:.1f} |")
            continue
        lines.append(
            head + f"| {r['prior']} | {r['inliers']} / {r['matches']} "
            f"| {r['rot_coarse_deg']:.3f} | {1000 * r['trans_coarse_m']:.1f} "
            f"| {'yes' if r['coarse_success'] else '**no**'} "
            f"| {r['rot_deg']:.4f} | {1000 * r['trans_m']:.2f} | {r['total_s']:.1f} |"
        )
    failed = [r for r in records if not r["ok"]]
    if failed:
        lines += ["", "Failures (the message `register` raised):", ""]
        lines += [
            f"- {r['scene']} seed {r['seed']}: `{r['error_type']}: {r['error']}`" for r in failed
        ]

    return lines


def _stage_rows(records: list[dict[str, Any]]) -> list[str]:
    """Every stage's time, one row per synthetic pair."""
    stages = stage_names(records)
    lines = [
        "",
        "Stage timings per pair (s):",
        "",
        "| scene | seed | " + " | ".join(stages) + " | total |",
        "|---|---:|" + "---:|" * (len(stages) + 1),
    ]
    for r in records:
        cells = [_f(r["timings_s"].get(st, math.nan), ".2f") for st in stages]
        cells.append(f"{r['total_s']:.2f}")
        lines.append(f"| {r['scene']} | {r['seed']} | " + " | ".join(cells) + " |")
    return lines


def render_speed(speed: dict[str, Any]) -> list[str]:
    w, h = speed["resolution"]
    runs = speed["runs"]

    def best(label: str) -> dict[str, Any] | None:
        ok = [r for r in runs.get(label, []) if r["ok"]]
        return min(ok, key=lambda r: r["total_s"]) if ok else None

    n_runs = max(len(v) for v in runs.values())
    lines = [
        f"### Speed: two {w} x {h} stations",
        "",
        f"`station_pair('room', seed=0, resolution=({w}, {h}))`: {speed['points'][0]:,} + "
        f"{speed['points'][1]:,} points, stations {speed['distance_m']:.2f} m apart, overlap "
        f"{speed['overlap']:.2f}. Only the `register` call is timed (the stations are in "
        f"memory; simulating them took {speed['synth_s']:.0f} s); best of {n_runs} "
        f"call{'s' if n_runs > 1 else ''} (all calls listed), machine as above.",
        "",
        "| register | best s | all calls s | rotation error ° | translation error mm | prior |",
        "|---|---:|---|---:|---:|---|",
    ]
    for label, rs in runs.items():
        b = best(label)
        times = ", ".join(f"{r['total_s']:.2f}" + ("" if r["ok"] else " (failed)") for r in rs)
        if b is None:
            lines.append(f"| {label} | **failed** | {times} | | | |")
        else:
            lines.append(
                f"| {label} | {b['total_s']:.2f} | {times} | {b['rot_deg']:.4f} "
                f"| {1000 * b['trans_m']:.2f} | {b['prior']} |"
            )
    chosen = {label: best(label) for label in runs}
    ok_runs = [r for r in chosen.values() if r is not None]
    stages = stage_names(ok_runs)
    lines += [
        "",
        "Stage timings of the best calls (s):",
        "",
        "| stage | " + " | ".join(runs) + " |",
        "|---|" + "---:|" * len(runs),
    ]
    for st in [*stages, "total"]:
        cells = []
        for r in chosen.values():
            if r is None:
                cells.append("")
            elif st == "total":
                cells.append(f"{r['total_s']:.2f}")
            else:
                cells.append(_f(r["timings_s"].get(st, math.nan), ".2f"))
        lines.append(f"| {st} | " + " | ".join(cells) + " |")
    b = chosen.get("with refinement")
    nb = chosen.get("without refinement")
    lines += [
        "",
        f"Target (at most {TARGET_SPEED_S:.0f} s with refinement, loading excluded): "
        + (
            f"{_verdict(b['total_s'] <= TARGET_SPEED_S)} -- {b['total_s']:.1f} s"
            if b is not None
            else "**NOT met** -- the registration failed"
        )
        + (f"; {nb['total_s']:.1f} s without refinement." if nb is not None else "."),
    ]
    for label, rs in runs.items():
        for r in rs:
            if not r["ok"]:
                lines.append(f"\n{label}: `{r['error_type']}: {r['error']}`")
                break
    return lines


def render_real(records: list[dict[str, Any]]) -> list[str]:
    lines = [
        "### Real scan pairs",
        "",
        "Data in `../shared/data` (provenance and licences in each folder's README). Each pair is "
        "one `register` call with the same configuration; poses stored with the scans are never "
        "given to it. Errors are the rotation angle and translation distance between the result "
        "and the reference `T_target_source`; *coarse* = before ICP.",
        "",
        "| pair (target <- source) | reference | points | range image (target) | prior "
        "| inliers / matches | coarse ° | coarse m | refined ° | refined m | time s | verdict |",
        "|---|---|---:|---|---|---:|---:|---:|---:|---:|---:|---|",
    ]
    for r in records:
        if "skipped" in r:
            lines.append(f"| {r['pair']} | | | | skipped: {r['skipped']} | | | | | | | |")
            continue
        img = r["range_images"][0]
        head = (
            f"| {r['pair']} | {r['reference']} | {r['points'][0]:,} / {r['points'][1]:,} "
            f"| {img['width']}x{img['height']}, {img['valid']:.0%} valid "
        )
        if not r["ok"]:
            lines.append(head + f"| **failed** | | | | | | {r['total_s']:.1f} | **failed** |")
            continue
        lines.append(
            head + f"| {r['prior']} | {r['inliers']} / {r['matches']} "
            f"| {r['rot_coarse_deg']:.3f} | {r['trans_coarse_m']:.4f} "
            f"| {r['rot_deg']:.3f} | {r['trans_m']:.4f} | {r['total_s']:.1f} | {real_verdict(r)} |"
        )
    failed = [r for r in records if "skipped" not in r and not r["ok"]]
    if failed:
        lines += ["", "Failures (the message `register` raised):", ""]
        lines += [f"- {r['pair']}: `{r['error_type']}: {r['error']}`" for r in failed]

    kurt = [r for r in records if r["pair"].startswith("3DTK") and "skipped" not in r]
    if kurt:
        lines += [
            "",
            "3DTK: how well each transform lays the source onto the target (median "
            "nearest-neighbour distance of the source points to the target, and the share within "
            f"{100 * NN_WITHIN_M:.0f} cm). *odometry + ICP* = the odometry pose refined by the "
            "same refinement `register` uses (`flexreg.registration.pipeline.refine`), the local "
            "optimum "
            "nearest to it. Source points are sampled evenly over the surfaces. Without ground "
            "truth this shows which transform the data favour, and the last column how far the "
            "result is from where the odometry leads:",
            "",
            "| pair | odometry distance m | result | odometry | odometry + ICP "
            "| result vs odometry + ICP |",
            "|---|---:|---:|---:|---:|---:|",
        ]

        def fit(x: Any) -> str:
            return "–" if x is None else f"{1000 * x[0]:.1f} mm, {x[1]:.0%}"

        for r in kurt:
            diff = "–"
            if r["ok"] and "T_prior_icp" in r:
                T, T_icp = np.asarray(r["T_target_source"]), np.asarray(r["T_prior_icp"])
                diff = (
                    f"{rotation_error_deg(T, T_icp):.2f}° / {translation_error_m(T, T_icp):.3f} m"
                )
            lines.append(
                f"| {r['pair']} | {r['prior_distance_m']:.2f} | "
                + (fit(r.get("nn_result")) if r["ok"] else "failed")
                + f" | {fit(r['nn_prior'])} | {fit(r.get('nn_prior_icp'))} | {diff} |"
            )
        loop = next((r["loop_vs_chain"] for r in kurt if "loop_vs_chain" in r), None)
        if loop is not None:
            lines += [
                "",
                "Loop check (no reference needed): the result scan000 <- scan001 composed with "
                "scan001 <- scan002 differs from the direct scan000 <- scan002 result by "
                f"{loop['rot_deg']:.2f}° / {loop['trans_m']:.3f} m.",
            ]
    lines += ["", *real_notes(records)]
    return lines


def real_verdict(r: dict[str, Any]) -> str:
    if r["pair"].startswith("bunny"):
        ok = r["rot_deg"] < BUNNY_ROT_DEG and r["trans_m"] < BUNNY_TRANS_M
        return f"< {BUNNY_ROT_DEG:.0f}° and < {1000 * BUNNY_TRANS_M:.0f} mm: {_verdict(ok)}"
    if r["pair"].startswith("Velodyne"):
        ok = r["rot_deg"] < VELODYNE_REF_ROT_DEG and r["trans_m"] < VELODYNE_REF_TRANS_M
        return ("within" if ok else "outside") + " the reference's uncertainty"
    if r["pair"].startswith("3DTK"):
        gross = r["rot_deg"] > KURT_GROSS_ROT_DEG or r["trans_m"] > KURT_GROSS_TRANS_M
        return "**wrong solution**" if gross else "near odometry"
    return ""


def real_notes(records: list[dict[str, Any]]) -> list[str]:
    by = {r["pair"]: r for r in records}
    notes = []
    b = by.get("bunny bun000 <- bun045")
    if b is not None and "skipped" not in b:
        chk = b["gt_check_vs_bun_conf"]
        notes.append(
            "- **Bunny**: Cyberware triangulation scans (400 x 512 grids, about 0.6-0.8 mm "
            "spacing) of a 15 cm object, not TLS. Ground truth = `inv(T_world_bun000) @ "
            "T_world_bun045` from the poses `read_scans` returns for "
            "`derived_bunny_grids_and_gt.npz`; recomputed here from `bun.conf` (conjugate of the "
            "written xyzw quaternion) it "
            + (
                "agrees to rounding"
                if chk["rot_deg"] < 1e-6 and chk["trans_m"] < 1e-9
                else f"differs by {chk['rot_deg']:.1e}° / {chk['trans_m']:.1e} m"
            )
            + f". Targets: {BUNNY_ROT_DEG:.0f}° and {1000 * BUNNY_TRANS_M:.0f} mm."
        )
    moves = [
        (
            rotation_error_deg(r["T_prior_icp"], r["T_reference"]),
            translation_error_m(r["T_prior_icp"], r["T_reference"]),
        )
        for r in records
        if r.get("pair", "").startswith("3DTK") and "T_prior_icp" in r and "T_reference" in r
    ]
    shift = (
        f" (ICP started from it moves it by up to {max(m[0] for m in moves):.1f}° / "
        f"{max(m[1] for m in moves):.2f} m)"
        if moves
        else ""
    )
    notes.append(
        "- **3DTK Kurt3D**: SICK line scanner turned by a robot (226 x 360 grid, 0.5° steps), "
        "stop-and-go. **No ground truth**: the reference is the odometry prior "
        "`inv(T_world_target) @ T_world_source` from the `.pose` files, itself approximate"
        + shift
        + ", so differences of centimetres and about a degree are not necessarily errors of "
        "`register`. "
        f"Points nearer than {KURT_MIN_RANGE_M} m are dropped (`min_range_m`, as the data's "
        "`config.ini` does): the robot's own body moves with the scanner and favours \"no "
        f'motion". A difference above {KURT_GROSS_ROT_DEG:.0f}° or {KURT_GROSS_TRANS_M} m is '
        "taken as a wrong solution."
    )
    r02 = by.get("3DTK scan000 <- scan002")
    if r02 is not None and "skipped" not in r02 and real_verdict(r02) != "near odometry":
        near_zero = r02["ok"] and np.linalg.norm(np.asarray(r02["T_target_source"])[:3, 3]) < 0.5
        text = (
            "  scan002 against scan000 is close to ambiguous: the two stations are "
            f"{r02['prior_distance_m']:.1f} m apart and the scene's arches repeat about every "
            "3.4 m, so a solution shifted by one arch period"
            + (" (here: close to no motion)" if near_zero else "")
            + " lays as much of the source onto the target as the right one, or more"
        )
        res, icp = r02.get("nn_result"), r02.get("nn_prior_icp")
        if res is not None and icp is not None:
            text += (
                f" ({res[1]:.0%} of the points within {100 * NN_WITHIN_M:.0f} cm, against "
                f"{icp[1]:.0%} at the odometry pose refined by ICP)"
            )
        notes.append(text + ".")
    v = by.get("Velodyne 251370668 <- 251371071")
    if v is not None and "skipped" not in v:
        spread = v["reference_spread"]
        img = v["range_images"][0]
        notes.append(
            "- **Velodyne** (fast_gicp test pair): unorganised outdoor spinning-lidar clouds, "
            "turned by `register` (`flexreg.stages.projection.range_image`) into a "
            f"{img['width']}x{img['height']} range image ({img['valid']:.0%} of the pixels hold "
            "a point). "
            "The reference `relative.txt` is a registration result, not survey ground truth: "
            f"small_gicp's matrix for the same scans differs from it by {spread['rot_deg']:.2f}° "
            f"/ {spread['trans_m']:.3f} m, so agreement within about "
            f"{VELODYNE_REF_ROT_DEG}° / {100 * VELODYNE_REF_TRANS_M:.0f} cm is all it can show."
        )
    return notes


def markdown(state: dict[str, Any], figure: str | None) -> str:
    m = state["machine"]
    load = state["load_average"]
    lines = [
        f"Command: `{state['command']}` ({m['cores']} cores, {m['cpu']}, Python {m['python']}, "
        f"numpy {m['numpy']}, OpenCV {m['opencv']}, Open3D {m['open3d']}; default "
        f"`RegistrationConfig` with `refine=True`, `seed={state['config']['seed']}`; one warm-up "
        "call first, not counted). 1-minute load average "
        f"{load['start'][0]:.1f} at the start of the run, {load['end'][0]:.1f} at the end"
        + (
            ": other jobs shared the machine, so the times are pessimistic"
            if max(load["start"][0], load["end"][0]) > 0.5 * m["cores"] + 0.5
            else ""
        )
        + ". Raw per-pair results: `benchmarks/results/registration-*/results.json`.",
        "",
    ]
    if state.get("synthetic"):
        lines += render_synthetic(state["synthetic"], tuple(state["resolution"]))
        if figure:
            lines += [
                "",
                f"![Per-pair rotation and translation errors, before and after refinement]"
                f"({figure})",
            ]
        lines.append("")
    if state.get("speed"):
        lines += [*render_speed(state["speed"]), ""]
    if state.get("real"):
        lines += [*render_real(state["real"]), ""]
    return "\n".join(lines).rstrip("\n") + "\n"


def plot_synthetic(records: list[dict[str, Any]], path: Path) -> None:
    """Rotation vs translation error of each pair, before (hollow) and after (filled)
    refinement, with the success box and the targets."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    floor_deg, floor_mm = 1e-5, 1e-3  # exact zeros and tiny errors sit on the axes' floor
    fig, ax = plt.subplots(figsize=(6.4, 4.8), dpi=120)
    colours = {"room": "#E69F00", "courtyard": "#0072B2"}
    for scene in SCENES:
        rs = [r for r in records if r["scene"] == scene and r["ok"]]
        if not rs:
            continue
        c = colours[scene]
        rot_c = np.maximum([r["rot_coarse_deg"] for r in rs], floor_deg)
        tr_c = np.maximum([1000 * r["trans_coarse_m"] for r in rs], floor_mm)
        rot_f = np.maximum([r["rot_deg"] for r in rs], floor_deg)
        tr_f = np.maximum([1000 * r["trans_m"] for r in rs], floor_mm)
        for a, b, x, y in zip(rot_c, tr_c, rot_f, tr_f, strict=True):
            ax.plot([a, x], [b, y], color=c, lw=0.5, alpha=0.4)
        ax.scatter(rot_c, tr_c, facecolors="none", edgecolors=c, label=f"{scene}: coarse")
        ax.scatter(rot_f, tr_f, color=c, label=f"{scene}: refined")
    ax.axvline(COARSE_ROT_DEG, color="0.4", ls="--", lw=0.8)
    ax.axhline(1000 * COARSE_TRANS_M, color="0.4", ls="--", lw=0.8)
    ax.axvline(TARGET_ROT_DEG, color="0.4", ls=":", lw=0.8)
    ax.axhline(1000 * TARGET_TRANS_M, color="0.4", ls=":", lw=0.8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("rotation error (°)")
    ax.set_ylabel("translation error (mm)")
    n_fail = sum(not r["ok"] for r in records)
    ax.set_title(
        f"{len(records)} synthetic pairs: dashed = coarse success limits, dotted = targets"
        + (f"\n({n_fail} failed pairs not shown)" if n_fail else ""),
        fontsize=9,
    )
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(True, which="major", alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


# ------------------------------------------------------------------ main


def _resolution(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, got {text!r}") from None
    if w < 16 or h < 8:
        raise argparse.ArgumentTypeError(f"resolution too small: {text!r}")
    return w, h


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--pairs", type=int, default=None, help="pairs per scene kind (default 12)")
    ap.add_argument(
        "--resolution", type=_resolution, default=None, help="synthetic WIDTHxHEIGHT (2048x1024)"
    )
    ap.add_argument(
        "--speed-resolution", type=_resolution, default=(4096, 2048), help="speed-run stations"
    )
    ap.add_argument("--speed-repeats", type=int, default=2, help="timed calls per speed setting")
    ap.add_argument("--seed", type=int, default=0, help="RegistrationConfig seed")
    ap.add_argument("--quick", action="store_true", help="3 + 3 pairs at 1024x512, no speed run")
    ap.add_argument("--no-synthetic", action="store_true", help="skip the synthetic suite")
    ap.add_argument("--no-real", action="store_true", help="skip the real pairs")
    ap.add_argument("--no-speed", action="store_true", help="skip the 4096 x 2048 run")
    ap.add_argument(
        "--write-docs",
        "--update-docs",
        action="store_true",
        help='rewrite "## Registration" in docs/benchmarks.md and its figure',
    )
    ap.add_argument("--results", type=Path, default=RESULTS, help="parent of the result folder")
    ap.add_argument(
        "--from-json",
        type=Path,
        metavar="RESULTS_JSON",
        help="render a saved run's results.json again (no registration; with --write-docs)",
    )
    args = ap.parse_args(argv)
    if args.from_json is not None:
        return finish(
            load_results(args.from_json), args.from_json.parent, write_docs=args.write_docs
        )
    pairs = args.pairs if args.pairs is not None else (3 if args.quick else 12)
    resolution = args.resolution or ((1024, 512) if args.quick else (2048, 1024))
    if pairs < 1 or args.speed_repeats < 1:
        ap.error("--pairs and --speed-repeats must be at least 1")
    do_speed = not (args.no_speed or args.quick)

    command = ".venv/bin/python benchmarks/registration.py" + "".join(
        part
        for part, on in (
            (" --quick", args.quick),
            (f" --pairs {pairs}", args.pairs is not None),
            (f" --resolution {resolution[0]}x{resolution[1]}", args.resolution is not None),
            (
                f" --speed-resolution {args.speed_resolution[0]}x{args.speed_resolution[1]}",
                args.speed_resolution != (4096, 2048),
            ),
            (f" --speed-repeats {args.speed_repeats}", args.speed_repeats != 2),
            (f" --seed {args.seed}", args.seed != 0),
            (" --no-synthetic", args.no_synthetic),
            (" --no-real", args.no_real),
            (" --no-speed", args.no_speed),
        )
        if on
    )
    config = RegistrationConfig(refine=True, seed=args.seed)
    folder = results_folder(args.results, "registration")
    write_json(folder / "config.json", config.to_dict(), indent=2)
    state: dict[str, Any] = {
        "benchmark": "registration",
        "command": command,
        "machine": machine_info(),
        "config": config.to_dict(),
        "criteria": {
            "coarse_success": {"rot_deg": COARSE_ROT_DEG, "trans_m": COARSE_TRANS_M},
            "coarse_success_rate": TARGET_SUCCESS,
            "median_refined": {"rot_deg": TARGET_ROT_DEG, "trans_m": TARGET_TRANS_M},
            "speed_s": TARGET_SPEED_S,
            "bunny": {"rot_deg": BUNNY_ROT_DEG, "trans_m": BUNNY_TRANS_M},
        },
        "resolution": list(resolution),
        "load_average": {"start": list(os.getloadavg()), "end": None},
        "synthetic": [],
        "speed": None,
        "real": None,
    }

    def save() -> None:
        write_json(folder / "results.json", state)

    print(f"results: {folder}", flush=True)
    save()
    warm_up(config)
    if not args.no_synthetic:
        synthetic_suite(pairs, resolution, config, save, state["synthetic"])
        state["summary"] = summarise(state["synthetic"])
        save()
    if do_speed:
        state["speed"] = speed_run(args.speed_resolution, config, args.speed_repeats)
        save()
    if not args.no_real:
        state["real"] = real_pairs(config)
        save()
    state["load_average"]["end"] = list(os.getloadavg())
    save()

    return finish(state, folder, write_docs=args.write_docs)


def finish(state: dict[str, Any], folder: Path, *, write_docs: bool) -> int:
    """Figure, Markdown (printed, saved next to the results, optionally into the docs)."""
    figure = None
    if state["synthetic"]:
        plot_synthetic(state["synthetic"], folder / "registration-synthetic.png")
        if write_docs:
            plot_synthetic(state["synthetic"], FIGURE)
            figure = FIGURE.relative_to(DOC.parent).as_posix()
            print(f"updated {FIGURE.relative_to(REPO)}")
    text = markdown(state, figure)
    publish(text, folder, doc=DOC if write_docs else None, heading=SECTION)
    print(f"raw results: {folder / 'results.json'}")
    return 0


def load_results(path: Path) -> dict[str, Any]:
    """A saved ``results.json``, with the infinite errors of failed pairs restored (JSON holds
    them as null) and the synthetic summary recomputed from them."""
    state = json.loads(path.read_text())
    records = list(state.get("synthetic") or []) + list(state.get("real") or [])
    if state.get("speed"):
        records += [r for runs in state["speed"]["runs"].values() for r in runs]
    for r in records:
        if r.get("ok") is False:
            r |= {k: math.inf for k in FAILURE_ERRORS if r.get(k) is None}
    if state.get("synthetic"):
        state["summary"] = summarise(state["synthetic"])
    return state


if __name__ == "__main__":
    raise SystemExit(main())
