"""PTX read/write throughput on a full 4096 x 2048 station, against numpy.loadtxt.

Run: ``.venv/bin/python benchmarks/io.py [--cols 4096 --rows 2048] [--repeat 3]``.
Prints a Markdown table (points/s); the figures are recorded in docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from flexreg import read_scan, write_scan
from flexreg.bench.harness import machine_info
from flexreg.core.camera import SphericalCamera
from flexreg.core.range_image import from_depth, to_scan


def make_station(cols: int, rows: int, seed: int = 0):
    """A full-turn station: smooth room-like ranges, 8 % no-returns, intensity 0..1."""
    rng = np.random.default_rng(seed)
    cam = SphericalCamera(cols, rows, -np.pi, np.pi, 0.0, np.pi)
    v, u = np.mgrid[0:rows, 0:cols]
    r = 4.0 + 2.0 * np.sin(u * 2 * np.pi / cols * 3) ** 2 + 1.5 * np.cos(v * np.pi / rows)
    r = r + rng.normal(0, 0.003, r.shape)
    r[rng.random(r.shape) < 0.08] = np.nan
    scan = to_scan(from_depth(r, cam), name="bench")
    scan.intensity = rng.random(len(scan)).astype(np.float32)
    return scan


def best_of(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--cols", type=int, default=4096)
    ap.add_argument("--rows", type=int, default=2048)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--skip-loadtxt", action="store_true")
    args = ap.parse_args()
    n = args.cols * args.rows
    scan = make_station(args.cols, args.rows)
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "station.ptx"
        write_scan(path, scan)  # warm-up (JIT compile/cache load)
        t_write = best_of(lambda: write_scan(path, scan), args.repeat)
        size_mb = os.path.getsize(path) / 1e6
        read_scan(path)  # warm-up
        t_read = best_of(lambda: read_scan(path), args.repeat)
        rows = [
            ("flexreg read_scan (PTX)", t_read),
            ("flexreg write_scan (PTX)", t_write),
        ]
        if not args.skip_loadtxt:
            t_lt = best_of(lambda: np.loadtxt(path, skiprows=10), 1)
            rows.append(("numpy.loadtxt (values only)", t_lt))
    m = machine_info()
    print(
        f"PTX station {args.cols} x {args.rows} = {n:,} cells, {size_mb:.0f} MB, "
        f"{len(scan):,} valid points; {m['cores']} cores, {m['python']}, numpy {m['numpy']}"
    )
    print()
    print("| operation | time (s) | points/s | MB/s |")
    print("|---|---:|---:|---:|")
    for name, t in rows:
        print(f"| {name} | {t:.2f} | {n / t / 1e6:.1f} M | {size_mb / t:.0f} |")


if __name__ == "__main__":
    main()
