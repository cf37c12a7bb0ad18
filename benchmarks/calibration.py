"""Camera-lidar calibration accuracy: synthetic rigs, KITTI and PJLab, and the automatic mode.

Sections (the acceptance criteria of ``flexreg calibrate``)
  * synthetic: a 64 x 1024 spinning lidar and a 1280 x 960 camera (f = 1050 px) mounted 33 cm
    away and turned 7 deg off the lidar's axes, in ``room`` and ``courtyard`` scenes of
    :mod:`flexreg.synth` (seeds 0..N-1). Correspondences: lidar points the camera sees
    (occlusion-checked against a rendered depth image), projected with the true extrinsic,
    plus 1 px Gaussian noise per axis, 30 % of them replaced by random pixels. Target: within
    0.1 deg and 1 cm with 200 pairs; 20, 50 and 100 pairs are measured too.
  * real: ``../shared/data/camlidar_kitti_object`` (official KITTI extrinsic, image-2 camera,
    see ``flexreg.io.intrinsics``) and ``../shared/data/camlidar_pjlab`` (the authors'
    reference extrinsic). Correspondences: lidar points projected with the reference
    calibration plus 1 px noise (and a variant with 30 % outliers). Target: within 0.2 deg and
    2 cm.
  * automatic mode: the reference extrinsic perturbed by 2 deg about a random axis and 10 cm
    in a random direction is the initial guess; ``calibrate_auto`` with the default
    configuration. Counted: refused (raises), rotation and translation improved over the
    guess, and "converged" (within 0.5 deg and 5 cm). The same on a synthetic courtyard rig
    (640 x 480 rendered camera image).

Every number is an error against the reference: rotation as the geodesic angle in degrees,
translation as the Euclidean distance in metres.

Raw results go to ``benchmarks/results/calibration-<timestamp>/`` (``results.json``,
``results.md``, figures).

Usage::

    .venv/bin/python benchmarks/calibration.py               # print the tables
    .venv/bin/python benchmarks/calibration.py --write-docs  # also rewrite the measured
                                                             # section of docs/calibration.md
                                                             # and docs/figures/calibration-*.png
    .venv/bin/python benchmarks/calibration.py --quick       # fewer trials (smoke test)
    .venv/bin/python benchmarks/calibration.py --write-docs --from-json \
        benchmarks/results/calibration-<timestamp>/results.json  # render a saved run again
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from flexreg import read_scan  # noqa: E402
from flexreg.bench.harness import machine_info, publish, results_folder, write_json  # noqa: E402
from flexreg.calibration import (  # noqa: E402
    CalibrationConfig,
    CalibrationError,
    Correspondences2D3D,
    calibrate_auto,
    overlay_image,
    project_points,
    render_flexion_view,
    solve_pnp,
)
from flexreg.core.transforms import (  # noqa: E402
    invert,
    make_transform,
    rotation_about_axis,
    rotation_error_deg,
    translation_error_m,
)
from flexreg.io.intrinsics import (  # noqa: E402
    CameraIntrinsics,
    read_extrinsic,
    read_intrinsics,
    read_kitti_calib,
)

DATA = REPO.parent / "shared" / "data"
DOC = REPO / "docs" / "calibration.md"
FIGURES = REPO / "docs" / "figures"
RESULTS = REPO / "benchmarks" / "results"
BEGIN, END = "<!-- calibration-benchmark:begin -->", "<!-- calibration-benchmark:end -->"

SYN_ROT_DEG, SYN_TRANS_M = 0.1, 0.01
REAL_ROT_DEG, REAL_TRANS_M = 0.2, 0.02
AUTO_ROT_DEG, AUTO_TRANS_M = 0.5, 0.05  # "converged"
PERTURB_DEG, PERTURB_M = 2.0, 0.10


# ------------------------------------------------------------------ data


def synthetic_rig(kind: str, seed: int, *, scale: float = 2.0) -> dict[str, Any]:
    """Lidar + camera in a synthetic scene; the camera image is rendered at 640 x 480 and the
    intrinsics are those of the same view at ``scale`` times the resolution."""
    from flexreg.synth import (
        RGBDConfig,
        lidar_config,
        make_scene,
        place_stations,
        render_rgbd,
        scan_lidar,
    )

    scene = make_scene(kind, seed)
    (T_world_lidar,) = place_stations(
        scene, 1, config=lidar_config(), rng=seed, max_tilt_rad=math.radians(2.0)
    )
    axes = np.array([[0.0, -1, 0], [0, 0, -1], [1, 0, 0]]).T
    R = rotation_about_axis([0.3, 1.0, 0.2], math.radians(7.0)) @ axes
    T_lidar_camera = make_transform(R, [0.12, -0.25, -0.18])
    scan = scan_lidar(scene, T_world_lidar, rng=seed)
    frame = render_rgbd(
        scene, T_world_lidar @ T_lidar_camera, config=RGBDConfig(max_depth_m=13.0), rng=seed
    )
    c = frame.camera
    K = c.K.copy()
    K[:2] *= scale
    K[0, 2], K[1, 2] = (c.cx + 0.5) * scale - 0.5, (c.cy + 0.5) * scale - 0.5
    W, H = round(c.width * scale), round(c.height * scale)
    intr = CameraIntrinsics(K, np.zeros(0), W, H, f"synthetic {kind} camera")
    T = invert(T_lidar_camera)
    uv, z = project_points(scan.points, intr, T)
    iu = np.rint((np.nan_to_num(uv) + 0.5) / scale - 0.5).astype(int)
    iu = np.clip(iu, 0, [c.width - 1, c.height - 1])
    d = frame.depth[iu[:, 1], iu[:, 0]].astype(np.float64)
    with np.errstate(invalid="ignore"):
        visible = np.isfinite(d) & (np.abs(d - z) < 0.05 + 0.02 * z)
    native = CameraIntrinsics(c.K, np.zeros(0), c.width, c.height, f"synthetic {kind} camera")
    return {
        "scan": scan,
        "intrinsics": intr,
        "native_intrinsics": native,
        "image": np.ascontiguousarray(frame.image[..., ::-1]),  # RGB -> BGR
        "T": T,
        "visible": visible,
    }


def real_set(name: str) -> dict[str, Any]:
    import cv2

    if name == "kitti":
        d = DATA / "camlidar_kitti_object"
        image = cv2.imread(str(d / "image_2_000000.png"))
        intr, T = read_kitti_calib(d / "calib_000000.txt")
        scan = read_scan(d / "velodyne_000000.bin")
    else:
        d = DATA / "camlidar_pjlab"
        image = cv2.imread(str(d / "scene_a_calib.png"))
        intr = read_intrinsics(d / "scene_a_center_camera-intrinsic.json")
        T = read_extrinsic(d / "scene_a_top_center_lidar-to-center_camera-extrinsic.json")
        scan = read_scan(d / "scene_a_calib.pcd")
    intr = intr.for_image(image.shape[1], image.shape[0])
    return {"scan": scan, "intrinsics": intr, "image": image, "T": T, "visible": None}


def ground_truth_pairs(
    data: dict[str, Any],
    n: int,
    rng: np.random.Generator,
    *,
    noise_px: float = 1.0,
    outliers: float = 0.0,
) -> Correspondences2D3D:
    """``n`` visible lidar points projected with the reference extrinsic + Gaussian noise; a
    fraction ``outliers`` get a uniformly random pixel instead."""
    intr = data["intrinsics"]
    points = data["scan"].points
    uv, z = project_points(points, intr, data["T"])
    W, H = intr.size
    ok = (z > 0.5) & (uv[:, 0] >= 3) & (uv[:, 0] <= W - 4) & (uv[:, 1] >= 3) & (uv[:, 1] <= H - 4)
    if data["visible"] is not None:
        ok &= data["visible"]
    sel = rng.choice(np.flatnonzero(ok), n, replace=False)
    px = uv[sel] + rng.normal(0.0, noise_px, (n, 2))
    bad = rng.choice(n, round(outliers * n), replace=False)
    px[bad] = rng.uniform([-0.5, -0.5], [W - 0.5, H - 0.5], (len(bad), 2))
    return Correspondences2D3D(px, points[sel])


def perturbed(T: NDArray[np.float64], rng: np.random.Generator) -> NDArray[np.float64]:
    """``T`` moved by PERTURB_DEG about a random axis and PERTURB_M in a random direction."""
    axis = rng.normal(size=3)
    d = rng.normal(size=3)
    P = make_transform(rotation_about_axis(axis, math.radians(PERTURB_DEG)), d / np.linalg.norm(d))
    P[:3, 3] *= PERTURB_M
    return P @ T


def errors(T: NDArray[np.float64], T_ref: NDArray[np.float64]) -> tuple[float, float]:
    return rotation_error_deg(T, T_ref), translation_error_m(T, T_ref)


# ------------------------------------------------------------------ runs


def pnp_trials(
    data: dict[str, Any], *, n: int, outliers: float, trials: int, seed0: int = 0
) -> dict[str, Any]:
    rot, trans, times, inl = [], [], [], []
    for k in range(trials):
        rng = np.random.default_rng(seed0 + k)
        pairs = ground_truth_pairs(data, n, rng, outliers=outliers)
        t0 = time.perf_counter()
        r = solve_pnp(pairs, data["intrinsics"], config=CalibrationConfig(seed=k))
        times.append(time.perf_counter() - t0)
        e = errors(r.T_camera_lidar, data["T"])
        rot.append(e[0])
        trans.append(e[1])
        inl.append(r.inliers)
    return {
        "pairs": n,
        "outliers": outliers,
        "trials": trials,
        "rotation_deg": rot,
        "translation_m": trans,
        "inliers": inl,
        "time_s": times,
    }


def auto_trials(data: dict[str, Any], *, trials: int, seed0: int = 100) -> list[dict[str, Any]]:
    out = []
    for k in range(trials):
        rng = np.random.default_rng(seed0 + k)
        T0 = perturbed(data["T"], rng)
        e0 = errors(T0, data["T"])
        t0 = time.perf_counter()
        rec: dict[str, Any] = {"trial": k, "init_rotation_deg": e0[0], "init_translation_m": e0[1]}
        try:
            r = calibrate_auto(data["image"], data["scan"], data["intrinsics"], T0)
        except CalibrationError as exc:
            rec.update(refused=True, message=str(exc), time_s=time.perf_counter() - t0)
        else:
            e = errors(r.T_camera_lidar, data["T"])
            assert r.auto is not None
            rec.update(
                refused=False,
                rotation_deg=e[0],
                translation_m=e[1],
                inliers=r.inliers,
                proposals=len(r.correspondences),
                edge_score_init=r.auto["edge_score_init"],
                edge_score_final=r.auto["edge_score_final"],
                time_s=time.perf_counter() - t0,
                T_init=T0.tolist(),
                T=r.T_camera_lidar.tolist(),
            )
        out.append(rec)
        print(f"    auto trial {k}: {_auto_line(rec)}", flush=True)
    return out


def _auto_line(rec: dict[str, Any]) -> str:
    if rec["refused"]:
        return f"refused ({rec['time_s']:.1f} s)"
    return (
        f"{rec['init_rotation_deg']:.2f} deg / {100 * rec['init_translation_m']:.1f} cm -> "
        f"{rec['rotation_deg']:.3f} deg / {100 * rec['translation_m']:.1f} cm, "
        f"{rec['inliers']} inliers ({rec['time_s']:.1f} s)"
    )


def summarise_auto(recs: list[dict[str, Any]]) -> dict[str, Any]:
    n = len(recs)
    ran = [r for r in recs if not r["refused"]]
    conv = [
        r for r in ran if r["rotation_deg"] < AUTO_ROT_DEG and r["translation_m"] < AUTO_TRANS_M
    ]
    rot_better = [r for r in ran if r["rotation_deg"] < r["init_rotation_deg"]]
    trans_better = [r for r in ran if r["translation_m"] < r["init_translation_m"]]

    def med(key: str) -> float:
        return statistics.median(r[key] for r in ran) if ran else float("nan")

    return {
        "trials": n,
        "refused": n - len(ran),
        "converged": len(conv),
        "rotation_improved": len(rot_better),
        "translation_improved": len(trans_better),
        "median_rotation_deg": med("rotation_deg"),
        "median_translation_m": med("translation_m"),
        "max_rotation_deg": max((r["rotation_deg"] for r in ran), default=float("nan")),
        "median_time_s": statistics.median(r["time_s"] for r in recs) if recs else float("nan"),
    }


# ------------------------------------------------------------------ report


def _stats(run: dict[str, Any]) -> str:
    r = np.asarray(run["rotation_deg"])
    t = np.asarray(run["translation_m"]) * 100
    return (
        f"{np.median(r):.4f} | {r.max():.4f} | {np.median(t):.2f} | {t.max():.2f} | "
        f"{1000 * statistics.median(run['time_s']):.1f}"
    )


def markdown(state: dict[str, Any]) -> str:
    L: list[str] = []
    L.append(f"Measured with `{state['command']}` on {state['date']} ({state['machine_line']}).")
    L.append("")
    if state.get("synthetic"):
        L.append(
            "**Synthetic rigs** (64 × 1024 lidar, 1280 × 960 camera with f = 1050 px, 1 px noise, "
            "30 % outliers; one rig per scene and seed, "
            f"{state['synthetic_trials']} draws of correspondences each). Target with 200 pairs: "
            f"every error within {SYN_ROT_DEG}° and {100 * SYN_TRANS_M:.0f} cm."
        )
        L.append("")
        L.append(
            "| pairs | runs | rotation median ° | max ° | translation median cm | max cm "
            "| PnP time ms | target |"
        )
        L.append("|---|---|---|---|---|---|---|---|")
        for run in state["synthetic"]:
            ok = max(run["rotation_deg"]) < SYN_ROT_DEG and max(run["translation_m"]) < SYN_TRANS_M
            verdict = ("met" if ok else "**missed**") if run["pairs"] == 200 else "–"
            L.append(f"| {run['pairs']} | {run['trials']} | {_stats(run)} | {verdict} |")
        L.append("")
    if state.get("real"):
        L.append(
            "**Real sets**: lidar points projected with the reference calibration + 1 px noise. "
            f"Target: every error within {REAL_ROT_DEG}° and {100 * REAL_TRANS_M:.0f} cm."
        )
        L.append("")
        L.append(
            "| set | pairs | outliers | runs | rotation median ° | max ° | translation median cm "
            "| max cm | PnP time ms | target |"
        )
        L.append("|---|---|---|---|---|---|---|---|---|---|")
        for run in state["real"]:
            ok = (
                max(run["rotation_deg"]) < REAL_ROT_DEG and max(run["translation_m"]) < REAL_TRANS_M
            )
            L.append(
                f"| {run['set']} | {run['pairs']} | {100 * run['outliers']:.0f} % | "
                f"{run['trials']} | {_stats(run)} | {'met' if ok else '**missed**'} |"
            )
        L.append("")
    if state.get("auto"):
        L.append(
            f"**Automatic mode**: initial guess = reference perturbed by {PERTURB_DEG:g}° about "
            f"a random axis and {100 * PERTURB_M:.0f} cm in a random direction; converged = "
            f"within {AUTO_ROT_DEG}° and {100 * AUTO_TRANS_M:.0f} cm of the reference."
        )
        L.append("")
        L.append(
            "| set | trials | refused | converged | rotation improved | translation improved "
            "| median rotation ° | median translation cm | worst rotation ° | median time s |"
        )
        L.append("|---|---|---|---|---|---|---|---|---|---|")

        def num(x: float, fmt: str, scale: float = 1.0) -> str:
            return "–" if x is None or not math.isfinite(x) else format(scale * x, fmt)

        for name, s in state["auto_summary"].items():
            L.append(
                f"| {name} | {s['trials']} | {s['refused']} | {s['converged']} | "
                f"{s['rotation_improved']} | {s['translation_improved']} | "
                f"{num(s['median_rotation_deg'], '.3f')} | "
                f"{num(s['median_translation_m'], '.1f', 100.0)} | "
                f"{num(s['max_rotation_deg'], '.3f')} | {s['median_time_s']:.1f} |"
            )
        L.append("")
    return "\n".join(L)


def plot_auto(state: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sets = list(state["auto"])
    fig, axes = plt.subplots(1, len(sets), figsize=(4.2 * len(sets), 3.6), squeeze=False)
    for ax, name in zip(axes[0], sets, strict=True):
        recs = state["auto"][name]
        ran = [r for r in recs if not r["refused"]]
        ax.scatter(
            [100 * r["translation_m"] for r in ran],
            [r["rotation_deg"] for r in ran],
            s=18,
            color="#0072B2",
            label=f"result ({len(ran)})",
        )
        ax.scatter(
            [100 * r["init_translation_m"] for r in recs],
            [r["init_rotation_deg"] for r in recs],
            s=18,
            marker="x",
            color="#E69F00",
            label="initial guess",
        )
        refused = len(recs) - len(ran)
        ax.set_title(f"{name}: {refused} of {len(recs)} refused", fontsize=10)
        ax.set_xlabel("translation error, cm")
        ax.set_ylabel("rotation error, °")
        ax.set_yscale("log")
        ax.axhline(AUTO_ROT_DEG, color="grey", lw=0.8, ls="--")
        ax.axvline(100 * AUTO_TRANS_M, color="grey", lw=0.8, ls="--")
        ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def overlay_figures(
    state: dict[str, Any], datasets: dict[str, dict[str, Any]], folder: Path
) -> list[Path]:
    """KITTI: initial guess vs automatic result (the first converged trial, else the first run);
    PJLab: the reference; plus a Flexion view next to the camera edges (KITTI)."""
    import cv2

    from flexreg.stages import feature_images as images

    png = [cv2.IMWRITE_PNG_COMPRESSION, 9]
    paths = []
    if "kitti" in state.get("auto", {}) and "kitti" in datasets:
        data = datasets["kitti"]
        ran = [r for r in state["auto"]["kitti"] if not r["refused"]]
        if ran:
            conv = [r for r in ran if r["rotation_deg"] < AUTO_ROT_DEG] or ran
            rec = conv[0]
            a = overlay_image(
                data["image"], data["scan"].points, data["intrinsics"], np.array(rec["T_init"])
            )
            b = overlay_image(
                data["image"], data["scan"].points, data["intrinsics"], np.array(rec["T"])
            )
            for img, text in ((a, "initial guess (2 deg, 10 cm off)"), (b, "automatic result")):
                for colour, width in (((0, 0, 0), 4), ((255, 255, 255), 1)):
                    cv2.putText(img, text, (10, 125), cv2.FONT_HERSHEY_SIMPLEX, 0.7, colour, width)
            p = folder / "calibration-kitti-auto.png"
            top = 100  # the lidar's field of view starts lower; keep the file small
            cv2.imwrite(str(p), np.vstack([a[top:], b[top:]]), png)
            paths.append(p)
            view = render_flexion_view(data["scan"], data["intrinsics"], data["T"])
            q, _ = images.quantize(view.flexion, 8)
            W, H = data["intrinsics"].size
            fv = cv2.resize(np.asarray(q, np.uint8), (W, H), interpolation=cv2.INTER_NEAREST)
            grey = cv2.cvtColor(data["image"], cv2.COLOR_BGR2GRAY)
            p = folder / "calibration-kitti-flexion-view.png"
            cv2.imwrite(str(p), np.vstack([grey, fv]), png)
            paths.append(p)
    if "pjlab" in datasets:
        data = datasets["pjlab"]
        o = overlay_image(
            data["image"], data["scan"].points, data["intrinsics"], data["T"], radius_px=2
        )
        p = folder / "calibration-pjlab-reference.png"
        half = cv2.resize(o, (o.shape[1] // 2, o.shape[0] // 2), interpolation=cv2.INTER_AREA)
        cv2.imwrite(str(p), half, png)
        paths.append(p)
    return paths


def synthetic_section(
    state: dict[str, Any], datasets: dict[str, dict[str, Any]], *, rigs_per_scene: int, trials: int
) -> None:
    """PnP on synthetic rigs with 20-200 pairs, 30 % outliers; keeps the last rig for the
    figures."""
    print("synthetic rigs", flush=True)
    rigs = []
    for kind in ("room", "courtyard"):
        for seed in range(rigs_per_scene):
            t0 = time.perf_counter()
            rigs.append(synthetic_rig(kind, seed))
            print(f"  {kind} seed {seed}: rig in {time.perf_counter() - t0:.1f} s", flush=True)
    state["synthetic"] = []
    for n in (20, 50, 100, 200):
        runs = [pnp_trials(rig, n=n, outliers=0.3, trials=trials) for rig in rigs]
        merged = {
            "pairs": n,
            "outliers": 0.3,
            "trials": sum(r["trials"] for r in runs),
            **{
                key: [x for r in runs for x in r[key]]
                for key in ("rotation_deg", "translation_m", "inliers", "time_s")
            },
        }
        state["synthetic"].append(merged)
        print(f"  {n} pairs: {_stats(merged)}", flush=True)
    datasets["synthetic courtyard"] = {
        **rigs[-1],
        "intrinsics": rigs[-1]["native_intrinsics"],
        "visible": None,
    }


def real_section(
    state: dict[str, Any], datasets: dict[str, dict[str, Any]], *, trials: int
) -> None:
    """PnP on the KITTI and PJLab rigs with 100 pairs, with and without outliers."""
    print("real sets", flush=True)
    state["real"] = []
    for name in ("kitti", "pjlab"):
        datasets[name] = real_set(name)
        for outliers in (0.0, 0.3):
            run = pnp_trials(datasets[name], n=100, outliers=outliers, trials=trials)
            run["set"] = name
            state["real"].append(run)
            print(f"  {name} outliers {outliers:.0%}: {_stats(run)}", flush=True)


def auto_section(
    state: dict[str, Any], datasets: dict[str, dict[str, Any]], *, trials: int
) -> None:
    """The automatic mode from perturbed starts on each rig."""
    print("automatic mode", flush=True)
    state["auto"] = {}
    for name in ("kitti", "pjlab", "synthetic courtyard"):
        if name not in datasets:
            if name == "synthetic courtyard":
                rig = synthetic_rig("courtyard", 0)
                datasets[name] = {**rig, "intrinsics": rig["native_intrinsics"]}
            else:
                datasets[name] = real_set(name)
        print(f"  {name}", flush=True)
        state["auto"][name] = auto_trials(datasets[name], trials=trials)
    state["auto_summary"] = {k: summarise_auto(v) for k, v in state["auto"].items()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer rigs and trials (smoke test)")
    ap.add_argument(
        "--write-docs",
        action="store_true",
        help="rewrite docs/calibration.md's measured section and docs/figures/calibration-*.png",
    )
    ap.add_argument("--no-synthetic", action="store_true")
    ap.add_argument("--no-real", action="store_true")
    ap.add_argument("--no-auto", action="store_true")
    ap.add_argument("--results", type=Path, default=RESULTS, help="parent of the result folder")
    ap.add_argument(
        "--from-json",
        type=Path,
        metavar="RESULTS_JSON",
        help="render a saved run's results.json again (tables, figures; with --write-docs)",
    )
    args = ap.parse_args(argv)
    if args.from_json is not None:
        state = json.loads(args.from_json.read_text())
        datasets = {name: real_set(name) for name in ("kitti", "pjlab")}
        return finish(state, datasets, args.from_json.parent, write_docs=args.write_docs)
    rigs_per_scene = 1 if args.quick else 3
    syn_trials = 3 if args.quick else 10
    real_trials = 5 if args.quick else 20
    auto_n = 4 if args.quick else 20
    command = ".venv/bin/python benchmarks/calibration.py" + "".join(
        part
        for part, on in (
            (" --quick", args.quick),
            (" --no-synthetic", args.no_synthetic),
            (" --no-real", args.no_real),
            (" --no-auto", args.no_auto),
        )
        if on
    )
    folder = results_folder(args.results, "calibration")
    machine = machine_info()
    state: dict[str, Any] = {
        "benchmark": "calibration",
        "command": command,
        "date": f"{datetime.now():%Y-%m-%d}",
        "machine_line": f"{machine['cores']} cores, Python {machine['python']}, "
        f"OpenCV {machine['opencv']}",
        "machine": machine,
        "config": CalibrationConfig().to_dict(),
        "synthetic_trials": syn_trials,
    }
    datasets: dict[str, dict[str, Any]] = {}

    if not args.no_synthetic:
        synthetic_section(state, datasets, rigs_per_scene=rigs_per_scene, trials=syn_trials)
    if not args.no_real:
        real_section(state, datasets, trials=real_trials)
    if not args.no_auto:
        auto_section(state, datasets, trials=auto_n)
    write_json(folder / "results.json", state)
    return finish(state, datasets, folder, write_docs=args.write_docs)


def finish(
    state: dict[str, Any], datasets: dict[str, dict[str, Any]], folder: Path, *, write_docs: bool
) -> int:
    """Print the tables, write results.md and the figures (into docs/ with ``write_docs``)."""
    text = markdown(state)
    publish(text + "\n", folder, doc=DOC if write_docs else None, markers=(BEGIN, END))
    fig_folder = FIGURES if write_docs else folder
    if state.get("auto"):
        plot_auto(state, fig_folder / "calibration-auto.png")
    for p in overlay_figures(state, datasets, fig_folder):
        print(f"wrote {p}")
    print(f"results in {folder}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
