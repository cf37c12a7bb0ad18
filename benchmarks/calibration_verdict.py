"""False alarms and misses of the calibration verdict (figures quoted in docs/calibration.md).

Normal sets: the reference projections of the real KITTI and PJLab sets, 10-100 pairs, 1 px
noise, 0 or 20 % outliers (seeds 0-9): every "uncertain" is a false alarm. Degenerate sets,
hand-made on a 640 x 480 camera (f = 500 px), 1 px noise: pairs on one wall, pixels in one
corner, 6-9 pairs, points near one line (seeds 0-9 each): every "confident" is a miss, and a
confident answer more than 0.5° or 5 cm off is a silent wrong answer.

Run: ``python benchmarks/calibration_verdict.py [DATA_DIR]`` (default ../shared/data).
"""

from __future__ import annotations

import sys
from collections import Counter
from pathlib import Path

import numpy as np

from flexreg import read_scan
from flexreg.calibration import CalibrationConfig, Correspondences2D3D, project_points, solve_pnp
from flexreg.core.transforms import (
    apply,
    invert,
    make_transform,
    rotation_about_axis,
    rotation_error_deg,
    translation_error_m,
)
from flexreg.errors import CalibrationError
from flexreg.io.intrinsics import (
    CameraIntrinsics,
    read_extrinsic,
    read_intrinsics,
    read_kitti_calib,
)

K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
CAMERA = CameraIntrinsics(K, np.zeros(0), 640, 480, "benchmark camera")


def real_sets(data: Path):
    d = data / "camlidar_kitti_object"
    intr, T = read_kitti_calib(d / "calib_000000.txt")
    yield "kitti", intr.for_image(1224, 370), T, read_scan(d / "velodyne_000000.bin").points
    d = data / "camlidar_pjlab"
    intr = read_intrinsics(d / "scene_a_center_camera-intrinsic.json").for_image(1920, 1200)
    T = read_extrinsic(d / "scene_a_top_center_lidar-to-center_camera-extrinsic.json")
    yield "pjlab", intr, T, read_scan(d / "scene_a_calib.pcd").points


def projected(points, intr, T, n, rng, outliers=0.0):
    uv, z = project_points(points, intr, T)
    W, H = intr.size
    ok = (z > 0.5) & (uv[:, 0] >= 3) & (uv[:, 0] <= W - 4) & (uv[:, 1] >= 3) & (uv[:, 1] <= H - 4)
    sel = rng.choice(np.flatnonzero(ok), n, replace=False)
    px = uv[sel] + rng.normal(0, 1, (n, 2))
    bad = rng.random(n) < outliers
    px[bad] = rng.uniform([0, 0], [W - 1, H - 1], (int(bad.sum()), 2))
    return Correspondences2D3D(px, points[sel])


def hand_made(kind, rng):
    """Camera-frame points of a degenerate kind, their pixels, and the true T_camera_lidar."""
    T = make_transform(rotation_about_axis(rng.normal(size=3), 0.3), rng.uniform(-0.3, 0.3, 3))
    if kind == "one wall":
        d, half, n = rng.uniform(3, 20), rng.uniform(0.5, 3), 20
        pc = np.column_stack([rng.uniform(-half, half, n), rng.uniform(-half, half, n) * 0.7])
        pc = np.column_stack([pc, np.full(n, d)]) @ rotation_about_axis([1, 0.3, 0], 0.3).T
    elif kind == "one corner":
        n = 20
        uv = rng.uniform([0, 0], [128, 96], (n, 2))  # 20 % x 20 % of the image
        pc = np.column_stack([(uv - [320, 240]) / 500, np.ones(n)]) * rng.uniform(3, 30, (n, 1))
    elif kind == "6-9 pairs":
        n = int(rng.integers(6, 10))
        uv = rng.uniform([0, 0], [639, 479], (n, 2))
        pc = np.column_stack([(uv - [320, 240]) / 500, np.ones(n)]) * rng.uniform(3, 30, (n, 1))
    else:  # near one line: points along a 3D line, 2 cm off it
        n = 12
        a, b = rng.uniform([-3, -2, 4], [3, 2, 20], (2, 3))
        pc = a + rng.uniform(0, 1, (n, 1)) * (b - a) + rng.normal(0, 0.02, (n, 3))
    uv = pc[:, :2] / pc[:, 2:] * 500 + [320, 240] + rng.normal(0, 1, (len(pc), 2))
    keep = (uv[:, 0] > 0) & (uv[:, 0] < 639) & (uv[:, 1] > 0) & (uv[:, 1] < 479) & (pc[:, 2] > 0)
    return Correspondences2D3D(uv[keep], apply(invert(T), pc[keep])), T


def run(pairs, intr, T, seed):
    try:
        r = solve_pnp(pairs, intr, config=CalibrationConfig(seed=seed))
    except (CalibrationError, ValueError) as e:
        return "failed", False, str(e)[:60]
    wrong = (
        rotation_error_deg(r.T_camera_lidar, T) > 0.5
        or translation_error_m(r.T_camera_lidar, T) > 0.05
    )
    return r.verdict.status, wrong, ",".join(x.code for x in r.verdict.reasons)


def main() -> None:
    data = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("../shared/data")
    print("normal sets (uncertain = false alarm)")
    for name, intr, T, points in real_sets(data):
        for outliers in (0.0, 0.2):
            tally, codes, wrong_conf = Counter(), Counter(), 0
            for n in (10, 20, 50, 100):
                for seed in range(10):
                    rng = np.random.default_rng(seed)
                    status, wrong, why = run(
                        projected(points, intr, T, n, rng, outliers), intr, T, seed
                    )
                    tally[status] += 1
                    codes.update(c for c in why.split(",") if c and status == "uncertain")
                    wrong_conf += status == "confident" and wrong
            print(
                f"  {name} {outliers:.0%} outliers: {dict(tally)} reasons {dict(codes)}; "
                f"confident but > 0.5°/5 cm: {wrong_conf}"
            )
    print("degenerate sets (confident = miss)")
    for kind in ("one wall", "one corner", "6-9 pairs", "near one line"):
        tally, wrong_conf, wrong_all = Counter(), 0, 0
        for seed in range(10):
            pairs, T = hand_made(kind, np.random.default_rng(100 + seed))
            status, wrong, _ = run(pairs, CAMERA, T, seed)
            tally[status] += 1
            wrong_conf += status == "confident" and wrong
            wrong_all += wrong
        print(f"  {kind}: {dict(tally)}; wrong answers {wrong_all}, of them confident {wrong_conf}")


if __name__ == "__main__":
    main()
