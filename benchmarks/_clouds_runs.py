"""The pairs and calls of ``benchmarks/clouds.py``: every method on every pair, judged against
the truth.

A pair is *right* when the final transform is within 1 degree and 1 % of the source's median
range of the truth (the data's own scale: 3 mm for an object 0.3 m away, 10 cm for a lidar
frame whose points lie 10 m away); *off* when it is not right but within 5 degrees and 10 % of
that range (the right pose, refined imprecisely); *wrong* beyond that (another pose).
*Registered* by flexreg: right and confident; by FPFH + RANSAC + ICP: right (it has no
verdict). A *confident wrong* pair is a flexreg answer the verdict calls confident that is
wrong: the count that must stay 0; confident answers that are off are counted beside it.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.baselines.fpfh import fpfh_ransac
from flexreg.core.scan import Scan, as_points
from flexreg.core.transforms import invert, rotation_error_deg, translation_error_m
from flexreg.errors import FlexregError
from flexreg.io import read_scan, read_scans
from flexreg.registration import RegistrationConfig, register

#: flexreg's routes compared, and the baseline
FLEXREG_METHODS = ("auto", "flexion", "geometric")
BASELINE = "fpfh-ransac-icp"
METHODS = (*FLEXREG_METHODS, BASELINE)

#: the limits of a right pair: rotation, and translation as a share of the median range
ROT_DEG, TRANS_SHARE = 1.0, 0.01

#: the limits of a pair that is only off, as multiples of those (beyond: wrong)
OFF_FACTOR_DEG, OFF_FACTOR_TRANS = 5.0, 10.0


@dataclass(frozen=True, eq=False)
class Pair:
    """One pair to register.

    Attributes
    ----------
    kind : str
        Its group in the tables (``object``, ``rosette``, ``fragments``, ``real``).
    name : str
    target, source : Scan
    T_true : (4, 4) float64 or None
        The truth or reference ``T_target_source`` (None: none).
    reference : str
        What ``T_true`` is.
    trans_m : float or None
        Its translation limit, metres (None: 1 % of the source's median range).
    rot_deg : float
    """

    kind: str
    name: str
    target: Scan
    source: Scan
    T_true: NDArray[np.float64] | None
    reference: str = "ground truth"
    trans_m: float | None = None
    rot_deg: float = ROT_DEG


def median_range_m(scan: Scan) -> float:
    """The median distance of a scan's points from its origin, metres."""
    p = as_points(scan)
    return float(np.median(np.linalg.norm(p[:: max(1, len(p) // 20000)], axis=1)))


def limits(pair: Pair) -> tuple[float, float]:
    """The pair's (rotation degrees, translation metres) limits."""
    t = pair.trans_m if pair.trans_m is not None else TRANS_SHARE * median_range_m(pair.source)
    return pair.rot_deg, t


def _errors(T: NDArray[np.float64] | None, pair: Pair) -> dict[str, Any]:
    if T is None or pair.T_true is None:
        return {}
    rot, trans = rotation_error_deg(T, pair.T_true), translation_error_m(T, pair.T_true)
    lr, lt = limits(pair)
    off = rot <= OFF_FACTOR_DEG * lr and trans <= OFF_FACTOR_TRANS * lt
    return {
        "rot_deg": rot,
        "trans_m": trans,
        "right": bool(rot <= lr and trans <= lt),
        "wrong": not off,
    }


def run_flexreg(pair: Pair, method: str, seed: int) -> dict[str, Any]:
    """``register`` with ``method``: its status (confident, uncertain or refused), errors,
    seconds."""
    t0 = time.perf_counter()
    try:
        res = register(pair.target, pair.source, RegistrationConfig(method=method, seed=seed))
    except FlexregError as e:
        return {"status": "refused", "why": str(e), "s": time.perf_counter() - t0}
    except Exception as e:  # a bug must not end a long run
        traceback.print_exc()
        return {"status": "error", "why": repr(e), "s": time.perf_counter() - t0}
    v = res.verdict
    rec = {
        "status": "confident" if v is not None and v.confident else "uncertain",
        "s": time.perf_counter() - t0,
        "prior": res.prior,
        "reasons": [] if v is None else [r.code for r in v.reasons],
        "T": res.T_target_source,
    }
    return rec | _errors(res.T_target_source, pair)


def run_baseline(pair: Pair, seed: int) -> dict[str, Any]:
    """Open3D FPFH + RANSAC + point-to-plane ICP (:func:`flexreg.baselines.fpfh.fpfh_ransac`,
    one RANSAC thread: the same seed gives the same answer)."""
    t0 = time.perf_counter()
    try:
        res = fpfh_ransac(pair.target, pair.source, seed=seed, ransac_threads=1)
    except FlexregError as e:
        return {"status": "failed", "why": str(e), "s": time.perf_counter() - t0}
    rec = {"status": "answered", "s": time.perf_counter() - t0, "T": res.T_target_source}
    return rec | _errors(res.T_target_source, pair)


def run_pair(pair: Pair, seed: int) -> dict[str, Any]:
    """Every method on one pair; the record is JSON-ready."""
    rec: dict[str, Any] = {
        "kind": pair.kind,
        "pair": pair.name,
        "reference": pair.reference,
        "points": [len(pair.target), len(pair.source)],
    }
    if pair.T_true is not None:
        lr, lt = limits(pair)
        rec["limits"] = {"rot_deg": lr, "trans_m": lt}
    for m in FLEXREG_METHODS:
        rec[m] = run_flexreg(pair, m, seed)
    rec[BASELINE] = run_baseline(pair, seed)
    return rec


def registered(rec: dict[str, Any], method: str) -> bool:
    """Whether ``method`` registered the pair: right, and confident for flexreg."""
    r = rec[method]
    if not r.get("right"):
        return False
    return method == BASELINE or r["status"] == "confident"


def confident_wrong(rec: dict[str, Any], method: str) -> bool:
    """A flexreg answer the verdict calls confident that is another pose than the truth."""
    r = rec[method]
    return method != BASELINE and r["status"] == "confident" and r.get("wrong") is True


def confident_off(rec: dict[str, Any], method: str) -> bool:
    """A flexreg answer the verdict calls confident near the truth but outside its limits."""
    r = rec[method]
    return (
        method != BASELINE
        and r["status"] == "confident"
        and r.get("right") is False
        and r.get("wrong") is False
    )


def summary_line(rec: dict[str, Any]) -> str:
    """One line per pair for the console."""
    parts = []
    for m in METHODS:
        r = rec[m]
        err = f"{r['rot_deg']:.2f}°/{r['trans_m'] * 1000:.0f}mm" if "rot_deg" in r else r["status"]
        parts.append(f"{m} {r['status'][:4]} {err} {r['s']:.1f}s")
    return f"{rec['kind']:9s} {rec['pair']:32s} " + " | ".join(parts)


# --------------------------------------------------------------------------- synthetic pairs


def synth(out: Path, args: list[str]) -> Path | None:
    """Run ``flexreg synth --out out ARGS`` once (kept when ``out/gt.json`` exists); None, and
    its error line printed, when the generator refuses (a fragment path whose overlap jumps)."""
    if not (out / "gt.json").is_file():
        exe = Path(sys.executable).with_name("flexreg")  # the console script beside Python
        cmd = [str(exe), "synth", "--out", str(out), *args]
        run = subprocess.run(cmd, capture_output=True, text=True)
        if run.returncode != 0:
            print(f"{out.name}: not generated: {run.stderr.strip().splitlines()[-1]}", flush=True)
            return None
    return out


def synthetic_pairs(kind: str, folder: Path) -> list[Pair]:
    """The neighbouring pairs of a ``flexreg synth`` data set with their true transforms."""
    gt = json.loads((folder / "gt.json").read_text())
    files = {
        f.stem: f
        for f in folder.rglob("*")
        if f.suffix in (".png", ".pcd", ".ply", ".ptx") and f.name != "scene.ply"
    }
    pairs = []
    for p in gt["pairs"]:
        t, s = p["target"], p["source"]
        target, source = read_scan(files[t]), read_scan(files[s])
        T = np.asarray(p["T_target_source"], dtype=np.float64)
        pairs.append(Pair(kind, f"{folder.name} {t} <- {s}", target, source, T))
    return pairs


def frame_pairs(kind: str, folder: Path, steps: tuple[int, ...]) -> list[Pair]:
    """Lidar frames ``i <- i + k`` of a ``flexreg synth --lidar-frames`` set for every ``k`` of
    ``steps`` (from frame 0 and from the middle frame): neighbours and frames a second or
    more apart along the path."""
    gt = json.loads((folder / "gt.json").read_text())
    frames = gt["lidar"]["frames"]
    pose = {f["name"]: np.asarray(f["T_world_sensor"], dtype=np.float64) for f in frames}
    names = [f["name"] for f in frames]
    out = []
    for k in steps:
        for i in sorted({0, len(names) // 2}):
            if i + k >= len(names):
                continue
            t, s = names[i], names[i + k]
            T = invert(pose[t]) @ pose[s]
            target = read_scan(folder / frames[i]["file"])
            source = read_scan(folder / frames[i + k]["file"])
            out.append(Pair(kind, f"{folder.name} {t} <- {s}", target, source, T))
    return out


# --------------------------------------------------------------------------- real pairs


def _orthonormal(T: NDArray[np.float64]) -> NDArray[np.float64]:
    U, _, Vt = np.linalg.svd(T[:3, :3])
    out = T.copy()
    out[:3, :3] = U @ Vt
    return out


def _kitti(path: Path) -> list[NDArray[np.float64]]:
    rows = np.loadtxt(path).reshape(-1, 3, 4)
    return [np.vstack([r, [0, 0, 0, 1]]) for r in rows]


def real_pairs(data: Path) -> list[Pair]:
    """The real pairs of ``data`` (the shared data folder) that are not terrestrial stations:
    a 3DMatch fragment pair, two Ouster frame pairs, the Stanford bunny, the PCL tutorials'
    room scans and Kinect clouds (no truth). Missing folders are skipped."""
    out: list[Pair] = []
    d = data / "reg_3dmatch_geotransformer_demo"
    if d.is_dir():
        T = _orthonormal(np.load(d / "gt.npy").astype(np.float64))
        out.append(
            Pair(
                "real",
                "3DMatch ref <- src",
                read_scan(d / "ref.npy"),
                read_scan(d / "src.npy"),
                T,
                "gt.npy (re-orthonormalised; 7e-5 off)",
                trans_m=0.3,
                rot_deg=15.0,
            )
        )
    d = data / "lidar_ouster_os1_128_3scans"
    if d.is_dir():
        scans = read_scans(d / "derived_destaggered_3scans.npz")
        poses = _kitti(d / "OS-1-128_v2.3.0_1024x10_lb_n3_poses_kitti.txt")
        for i in (0, 1):
            T = invert(poses[i]) @ poses[i + 1]
            out.append(
                Pair(
                    "real",
                    f"Ouster frame {i} <- {i + 1}",
                    scans[i],
                    scans[i + 1],
                    T,
                    "SDK reference poses",
                    trans_m=0.1,
                )
            )
    d = data / "bunny_range_scans_gt"
    if d.is_dir():
        a, b = read_scans(d / "derived_bunny_grids_and_gt.npz")
        T = invert(a.T_world_scanner) @ b.T_world_scanner
        out.append(Pair("real", "bunny bun000 <- bun045", a, b, T, "bun.conf", trans_m=0.003))
    d = data / "pcl_room_scans"
    if d.is_dir():
        out.append(
            Pair(
                "real",
                "PCL room_scan1 <- room_scan2",
                read_scan(d / "room_scan1.pcd"),
                read_scan(d / "room_scan2.pcd"),
                None,
                "none (odometry guess only)",
            )
        )
    d = data / "pcl_organized_kinect_pairwise"
    if d.is_dir():
        for i in range(1, 5):
            out.append(
                Pair(
                    "real",
                    f"Kinect capture{i:04d} <- {i + 1:04d}",
                    read_scan(d / f"capture{i:04d}.pcd"),
                    read_scan(d / f"capture{i + 1:04d}.pcd"),
                    None,
                    "none",
                )
            )
    return out


def agreement(rec: dict[str, Any]) -> str:
    """For a pair without truth: how far flexreg's auto answer lies from the baseline's."""
    a, b = rec["auto"].get("T"), rec[BASELINE].get("T")
    if a is None or b is None:
        return "n/a"
    return f"{rotation_error_deg(a, b):.2f}° / {translation_error_m(a, b) * 1000:.0f} mm"


def finite(x: float) -> bool:
    return isinstance(x, float) and math.isfinite(x)
