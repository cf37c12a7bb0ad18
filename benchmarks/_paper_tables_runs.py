"""The odometry runs of ``benchmarks/paper_tables.py``: the grid (image variants, features,
solvers), its data sets and one scored run per cell.

Each run is a JSON-ready record under :func:`key` in the run's ``runs``; the tables and the
figure are made from them by ``_paper_tables_report``.

``paper_tables.py`` imports this module as a sibling: ``python benchmarks/paper_tables.py``
puts ``benchmarks/`` on ``sys.path``.
"""

from __future__ import annotations

import contextlib
import io
import itertools
import json
import math
import time
import traceback
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from flexreg.cli import run as run_cli
from flexreg.core.trajectory import associate
from flexreg.errors import FlexregError, RegistrationError
from flexreg.io.sequence import Sequence, read_sequence
from flexreg.odometry import (
    FrameFeatures,
    OdometryConfig,
    feature_image,
    frame_features,
    track,
)
from flexreg.odometry.evaluation import ate, rpe
from flexreg.stages.keypoints import create_detector

REPO = Path(__file__).resolve().parents[1]

#: rows of the tables: (label, image kind, n)
VARIANTS: tuple[tuple[str, str, int], ...] = (
    *((f"Flexion {n}×{n}", "flexion", n) for n in (3, 5, 7, 9, 11, 13)),
    ("Flexion angle", "flexion-angle", 3),
    ("Flexion normalized", "flexion-normalized", 3),
    ("BA horizontal", "bearing-horizontal", 3),
    ("BA vertical", "bearing-vertical", 3),
    ("BA diagonal", "bearing-diagonal", 3),
    ("BA antidiagonal", "bearing-antidiagonal", 3),
    ("Color", "color", 3),
)
FEATURES = ("akaze", "orb", "sift", "kaze")
METHODS = ("essential", "svd")
#: RPE interval: 1 s, the unit of the TUM tools' --fixed_delta (0.25 s for --quick's short runs)
RPE_DELTA, RPE_UNIT = 1.0, "seconds"
RPE_DELTA_QUICK = 0.25


def datasets(quick: bool) -> dict[str, dict[str, Any]]:
    """The sequences: where they come from, which frames are used.

    Parameters
    ----------
    quick : bool
        The short sequences of ``--quick``.

    Returns
    -------
    dict
        By data-set name: ``title``, ``path`` (real data) or ``synth`` (the ``flexreg``
        arguments that write it), ``frames`` and ``step``.
    """
    frames_7s = 20 if quick else 60
    synth_frames, synth_step = (40, 2) if quick else (135, 3)
    out: dict[str, dict[str, Any]] = {
        "7scenes": {
            "title": "7-Scenes redkitchen (real Kinect, KinectFusion poses)",
            "path": "../shared/data/rgbd_7scenes_redkitchen",
            "frames": frames_7s,
            "step": 1,
        }
    }
    for seed in (1, 2):
        out[f"synth-room-{seed}"] = {
            "title": f"synthetic room, seed {seed} (flexreg synth)",
            "synth": [
                "synth",
                "--scene",
                "room",
                "--stations",
                "1",
                "--resolution",
                "256x128",
                "--rgbd-frames",
                str(synth_frames),
                "--seed",
                str(seed),
            ],
            "frames": synth_frames,
            "step": synth_step,
        }
    return out


# ------------------------------------------------------------------------------ sequences


def prepare(name: str, spec: dict[str, Any], work: Path) -> Sequence:
    """Read (and for synthetic data first write, once) a data set's sequence, subsampled.

    Parameters
    ----------
    name : str
        The data set.
    spec : dict
        Its entry of :func:`datasets`.
    work : Path
        Where synthetic sequences are written (and reused when written with the same
        arguments).

    Returns
    -------
    Sequence
        Every ``step``-th frame, renumbered.

    Raises
    ------
    RuntimeError
        ``flexreg synth`` failed.
    """
    if "synth" in spec:
        folder = work / name
        argv = [*spec["synth"], "--out", str(folder), "--overwrite"]
        stamp = folder / "flexreg-synth-argv.json"
        if not (stamp.is_file() and json.loads(stamp.read_text()) == argv):
            t0 = time.perf_counter()
            with contextlib.redirect_stdout(io.StringIO()):
                rc = run_cli(argv)
            if rc != 0:
                raise RuntimeError(f"flexreg {' '.join(argv)} failed ({rc})")
            stamp.write_text(json.dumps(argv))
            print(f"  wrote {folder} ({time.perf_counter() - t0:.0f} s)", flush=True)
        seq = read_sequence(folder)
    else:
        seq = read_sequence(REPO / spec["path"], max_frames=spec["frames"])
    step = int(spec["step"])
    frames = tuple(replace(f, index=k) for k, f in enumerate(seq.frames[::step]))
    return replace(seq, frames=frames)


def describe(seq: Sequence) -> dict[str, Any]:
    """Length and motion of a sequence's ground truth over its frames.

    Parameters
    ----------
    seq : Sequence
        A sequence with ground truth.

    Returns
    -------
    dict
        ``frames``, ``duration_s``, ground-truth ``path_m``, mean step (``step_mm``,
        ``step_deg``) and the camera.
    """
    gt = seq.groundtruth
    assert gt is not None
    ig, _ = associate(gt, seq.timestamps)
    P = gt.positions[np.sort(ig)]
    steps = np.linalg.norm(np.diff(P, axis=0), axis=1)
    R = gt.poses[np.sort(ig), :3, :3]
    rot = [
        math.degrees(math.acos(np.clip((np.trace(a.T @ b) - 1) / 2, -1, 1)))
        for a, b in itertools.pairwise(R)
    ]
    return {
        "frames": len(seq),
        "duration_s": float(seq.timestamps[-1] - seq.timestamps[0]),
        "path_m": float(steps.sum()),
        "step_mm": 1000 * float(np.mean(steps)),
        "step_deg": float(np.mean(rot)),
        "camera": seq.camera.to_dict() if seq.camera is not None else None,
    }


# ------------------------------------------------------------------------------ runs


def features_for(
    seq: Sequence, image: str, n: int, feats: tuple[str, ...]
) -> tuple[dict[str, list[FrameFeatures]], dict[str, float]]:
    """Every frame's features for one image variant and each detector (conversion shared).

    Parameters
    ----------
    seq : Sequence
        The frames.
    image : str
        The image kind (``OdometryConfig.image``).
    n : int
        Its neighbourhood size.
    feats : tuple of str
        The detectors.

    Returns
    -------
    (dict, dict)
        Each detector's features of every frame, and its seconds in total.
    """
    cfgs = {f: OdometryConfig(image=image, n=n, features=f) for f in feats}
    dets = {f: create_detector(f) for f in feats}
    out: dict[str, list[FrameFeatures]] = {f: [] for f in feats}
    secs = {f: 0.0 for f in feats}
    for i in range(len(seq)):
        img = seq.range_image(i)
        color = seq.color_image(i) if image == "color" else None
        conv = feature_image(img, cfgs[feats[0]], color=color)
        for f in feats:
            t0 = time.perf_counter()
            out[f].append(
                frame_features(img, cfgs[f], color=color, index=i, detector=dets[f], converted=conv)
            )
            secs[f] += time.perf_counter() - t0
    return out, secs


def run_one(
    seq: Sequence,
    frames: list[FrameFeatures],
    cfg: OdometryConfig,
    seconds_features: float,
    rpe_delta_s: float,
) -> dict[str, Any]:
    """One odometry run on precomputed features, scored against the ground truth.

    Parameters
    ----------
    seq : Sequence
        The frames and their ground truth.
    frames : list of FrameFeatures
        Every frame's features.
    cfg : OdometryConfig
        Image, features and solver of the run.
    seconds_features : float
        Time the features took, added to the run's.
    rpe_delta_s : float
        The RPE interval (s).

    Returns
    -------
    dict
        JSON-ready: ``ok``, ATE and RPE, bridged frames, failed attempts, median inliers and
        matches, seconds and path length; or ``ok`` False and the error.
    """
    assert seq.groundtruth is not None
    rec: dict[str, Any] = {"ok": False}
    t0 = time.perf_counter()
    try:
        res = track(frames, seq.timestamps, cfg)
    except RegistrationError as e:
        rec.update(error=str(e), seconds=seconds_features + time.perf_counter() - t0)
        return rec
    try:
        a = ate(seq.groundtruth, res.trajectory)
        r = rpe(seq.groundtruth, res.trajectory, delta=rpe_delta_s, delta_unit=RPE_UNIT)
    except FlexregError as e:
        rec.update(error=f"not evaluated: {e}", seconds=seconds_features + time.perf_counter() - t0)
        return rec
    ok_att = [x for x in res.attempts if x.ok]
    rec.update(
        ok=True,
        ate_rmse_m=a.rmse_m,
        rpe_trans_mean_m=r.trans_mean_m,
        rpe_trans_rmse_m=r.trans_rmse_m,
        rpe_rot_mean_deg=r.rot_mean_deg,
        bridged=len(res.failures),
        failed_attempts=len(res.failed_pairs),
        median_inliers=float(np.median([x.inliers for x in ok_att])) if ok_att else 0.0,
        median_matches=float(np.median([x.matches for x in ok_att])) if ok_att else 0.0,
        seconds=seconds_features + time.perf_counter() - t0,
        path_m=res.trajectory.path_length_m,
    )
    return rec


def key(dataset: str, label: str, feature: str, method: str) -> str:
    """The name of a run in the run's ``runs``: ``dataset|label|feature|method``.

    Parameters
    ----------
    dataset, label, feature, method : str
        Data set, image variant (its label), detector and solver.

    Returns
    -------
    str
    """
    return f"{dataset}|{label}|{feature}|{method}"


def run_grid(state: dict[str, Any], work_dir: Path, save: Callable[[], None]) -> None:
    """Every data set x variant x feature x solver not yet in ``state["runs"]``; saves after
    each variant.

    Parameters
    ----------
    state : dict
        The run (``results.json``): gets each data set's description in ``sequences`` and each
        record in ``runs``.
    work_dir : Path
        Where synthetic sequences are written.
    save : callable
        Rewrites the run's ``results.json``.
    """
    kinds = {lab: (kind, n) for lab, kind, n in VARIANTS}
    feats = tuple(state["features"])
    for ds in state["datasets"]:
        print(f"{ds}:", flush=True)
        seq = prepare(ds, state["specs"][ds], work_dir)
        state["sequences"][ds] = describe(seq)
        save()
        for lab in state["variants"]:
            kind, n = kinds[lab]
            if kind == "color" and not seq.has_color:
                continue
            todo = [
                f
                for f in feats
                if any(key(ds, lab, f, m) not in state["runs"] for m in state["methods"])
            ]
            if not todo:
                continue
            t0 = time.perf_counter()
            try:
                frames, secs = features_for(seq, kind, n, tuple(todo))
            except FlexregError as e:
                for f in todo:
                    for m in state["methods"]:
                        state["runs"][key(ds, lab, f, m)] = {"ok": False, "error": str(e)}
                save()
                continue
            for f in todo:
                for m in state["methods"]:
                    k = key(ds, lab, f, m)
                    if k in state["runs"]:
                        continue
                    cfg = OdometryConfig(image=kind, n=n, features=f, method=m)
                    try:
                        state["runs"][k] = run_one(
                            seq, frames[f], cfg, secs[f], state["rpe"]["delta"]
                        )
                    except Exception as e:  # a bug must not end a long run; it is recorded
                        traceback.print_exc()
                        state["runs"][k] = {"ok": False, "error": f"{type(e).__name__}: {e}"}
                    r = state["runs"][k]
                    msg = (
                        f"ATE {r['ate_rmse_m']:.4f} m, RPE {r['rpe_trans_mean_m']:.4f} m, "
                        f"{r['bridged']} bridged"
                        if r.get("ok")
                        else f"failed: {r.get('error', '')[:80]}"
                    )
                    print(f"  {lab:20s} {f:6s} {m:9s} {msg}", flush=True)
                save()
            print(f"  ({lab}: {time.perf_counter() - t0:.0f} s)", flush=True)
