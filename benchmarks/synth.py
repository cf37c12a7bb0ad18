"""Benchmark the synthetic scanner: seconds per 2048 x 1024 TLS station for each scene kind.

Run: ``.venv/bin/python benchmarks/synth.py [--seeds 3] [--repeats 3]``. Prints a Markdown table
(the numbers of docs/benchmarks.md, section "Synthetic scanner"). Per scene and seed it times the
scene generation, the ray caster's acceleration structure (built once per scene), placing two
stations with >= 50 % overlap, and the simulation of one station (ray cast + noise model + Scan),
median over ``--repeats`` runs.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from flexreg.bench.harness import machine_info
from flexreg.synth import TLSConfig, make_scene, place_stations, scan_tls


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3, help="scenes per kind (seeds 0..N-1)")
    ap.add_argument("--repeats", type=int, default=3, help="station simulations per scene")
    ap.add_argument("--resolution", default="2048x1024", help="station grid WIDTHxHEIGHT")
    args = ap.parse_args()
    w, h = (int(v) for v in args.resolution.split("x"))

    import open3d  # noqa: F401  (import time is not part of any figure)

    cfg = TLSConfig(width=w, height=h)
    rows = []
    for kind in ("room", "courtyard", "hall"):
        for seed in range(args.seeds):
            t0 = time.perf_counter()
            scene = make_scene(kind, seed)
            t_scene = time.perf_counter() - t0
            t0 = time.perf_counter()
            scene.cast(np.zeros(3), np.array([[1.0, 0.0, 0.0]]))  # builds the BVH
            t_bvh = time.perf_counter() - t0
            t0 = time.perf_counter()
            poses = place_stations(scene, 2, min_overlap=0.5, rng=seed, config=cfg)
            t_place = time.perf_counter() - t0
            times, n = [], 0
            for r in range(args.repeats):
                t0 = time.perf_counter()
                scan = scan_tls(scene, poses[r % 2], config=cfg, rng=r)
                times.append(time.perf_counter() - t0)
                n = len(scan)
            rows.append(
                (
                    kind,
                    seed,
                    scene.n_triangles,
                    t_scene,
                    t_bvh,
                    t_place,
                    statistics.median(times),
                    max(times),
                    n,
                )
            )

    m = machine_info()
    print(f"{m['cpu']}, {m['cores']} cores, Python {m['python']}, grid {w} x {h}\n")
    print(
        "| scene | seed | triangles | scene s | BVH s | placement s | station s (median) "
        "| station s (max) | points |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for kind, seed, tri, ts, tb, tp, tm, tx, n in rows:
        print(
            f"| {kind} | {seed} | {tri} | {ts:.2f} | {tb:.2f} | {tp:.2f} | {tm:.2f} | {tx:.2f} "
            f"| {n} |"
        )
    for kind in ("room", "courtyard", "hall"):
        med = statistics.median(r[6] for r in rows if r[0] == kind)
        print(f"\n{kind}: {med:.2f} s per {w} x {h} station (median over seeds)", end="")
    print()


if __name__ == "__main__":
    main()
