"""Figures of docs/synthetic-data.md: each scene kind and the TLS noise model.

Run: ``.venv/bin/python scripts/synth_figures.py [--out docs/figures]``. Writes
``synth_room.png``, ``synth_courtyard.png``, ``synth_hall.png`` (top-down height map with two
stations, and the range and intensity panoramas of station 0), ``synth_noise.png`` (the TLS
measurement model against ground truth) and ``synth_rgbd.png`` (one RGB-D frame). Everything is
seeded, so reruns give the same pictures.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from flexreg.synth import (
    RGBDConfig,
    Scene,
    TLSConfig,
    camera_trajectory,
    make_scene,
    place_stations,
    render_rgbd,
    scan_tls,
)
from flexreg.synth.mesh import box

SEED = 0
CUT_M = {"room": 2.6, "courtyard": 60.0, "hall": 6.0}  # height of the horizontal section
TOP_M = {"room": 2.6, "courtyard": 4.0, "hall": 6.0}  # heights above this saturate the colours


def height_map(scene: Scene, cut_z: float, cell: float = 0.05, margin: float = 2.0):
    """Orthographic top view: height of the first surface below ``cut_z``, hill-shaded."""
    x0, y0, x1, y1 = scene.region
    xs = np.arange(x0 - margin, x1 + margin, cell)
    ys = np.arange(y0 - margin, y1 + margin, cell)
    X, Y = np.meshgrid(xs, ys)
    o = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, cut_z)])
    h = scene.cast(o, np.broadcast_to(np.array([0.0, 0.0, -1.0]), o.shape))
    z = (cut_z - h.t).reshape(X.shape)
    up = scene.cast(o, np.broadcast_to(np.array([0.0, 0.0, 1.0]), o.shape))
    cut = (up.hit & (up.normal[:, 2] > 0)).reshape(X.shape)  # inside a solid: section through it
    z[cut | ~np.isfinite(z)] = np.nan
    n = h.normal.reshape(*X.shape, 3).astype(np.float64)
    light = np.array([-0.5, -0.6, 0.62])
    shade = np.clip(n @ (light / np.linalg.norm(light)), 0, 1)
    return xs, ys, z, shade, cut


def scene_figure(kind: str, out: Path) -> None:
    scene = make_scene(kind, SEED)
    cfg = TLSConfig(width=1024, height=512)
    poses = place_stations(scene, 2, min_overlap=0.5, rng=SEED, max_tilt_rad=math.radians(3))
    scan = scan_tls(scene, poses[0], config=cfg, rng=SEED)
    xyz, valid = scan.organized()
    rng_img = np.linalg.norm(xyz, axis=2)
    inten = np.full(valid.shape, np.nan)
    inten[scan.grid_index[:, 0], scan.grid_index[:, 1]] = scan.intensity

    xs, ys, z, shade, cut = height_map(scene, CUT_M[kind])
    aspect = (ys[-1] - ys[0]) / (xs[-1] - xs[0])
    fig = plt.figure(figsize=(11, 11 * (aspect + 1.0) + 1.2), layout="constrained")
    gs = fig.add_gridspec(3, 1, height_ratios=[aspect, 0.5, 0.5])
    ax = fig.add_subplot(gs[0])
    cmap = plt.get_cmap("terrain").copy()
    lo, hi = np.nanmin(z), min(np.nanmax(z), TOP_M[kind])
    rgb = cmap(np.clip((np.nan_to_num(z, nan=lo) - lo) / max(1e-6, hi - lo), 0, 1))[..., :3]
    rgb = rgb * (0.55 + 0.45 * shade[..., None])
    rgb[cut] = 0.15
    rgb[~np.isfinite(z) & ~cut] = 1.0
    ax.imshow(rgb, origin="lower", extent=[xs[0], xs[-1], ys[0], ys[-1]], interpolation="nearest")
    for i, T in enumerate(poses):
        ax.plot(T[0, 3], T[1, 3], "o", ms=9, mfc="red", mec="white")
        ax.annotate(
            f"station {i}",
            (T[0, 3], T[1, 3]),
            xytext=(6, 6),
            textcoords="offset points",
            color="red",
            fontsize=10,
            weight="bold",
        )
    d = np.linalg.norm(poses[1][:3, 3] - poses[0][:3, 3])
    ax.set_title(
        f"{kind} (seed {SEED}): {scene.n_triangles} triangles, {sum(scene.objects.values())} "
        f"objects; stations {d:.1f} m apart\ntop view cut at {CUT_M[kind]:g} m, colour = "
        f"height {lo:.1f}..{hi:.1f} m (higher saturates), black = cut through solids"
    )
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax2 = fig.add_subplot(gs[1])
    im = ax2.imshow(
        rng_img, cmap="turbo", vmin=0, vmax=np.nanpercentile(rng_img, 98), interpolation="nearest"
    )
    ax2.set_title(f"station 0: range panorama {cfg.width} x {cfg.height} (white = no return)")
    fig.colorbar(im, ax=ax2, label="range [m]", shrink=0.9)
    ax3 = fig.add_subplot(gs[2])
    im = ax3.imshow(
        inten, cmap="gray", vmin=0, vmax=np.nanpercentile(inten, 99.5), interpolation="nearest"
    )
    ax3.set_title("station 0: intensity (reflectance x cos incidence x range falloff)")
    fig.colorbar(im, ax=ax3, label="intensity", shrink=0.9)
    for a in (ax2, ax3):
        a.set_xlabel("column (azimuth)")
        a.set_ylabel("row (polar)")
    fig.savefig(out / f"synth_{kind}.png", dpi=80)
    plt.close(fig)


def noise_figure(out: Path) -> None:
    fig, axs = plt.subplots(2, 2, figsize=(12, 9), layout="constrained")
    # (a, b) range residuals of a courtyard station against the noise-free cast of the same pixels
    scene = make_scene("courtyard", SEED)
    (T,) = place_stations(scene, 1, rng=SEED)
    base = dict(width=1024, height=512, mixed_pixel_prob=0.0, dropout_rate=0.0)
    noisy = scan_tls(scene, T, config=TLSConfig(**base), rng=1)
    clean = scan_tls(
        scene, T, config=TLSConfig(**base, range_noise_m=0.0, range_noise_per_m=0.0), rng=1
    )
    key_n = noisy.grid_index[:, 0].astype(np.int64) * 1024 + noisy.grid_index[:, 1]
    key_c = clean.grid_index[:, 0].astype(np.int64) * 1024 + clean.grid_index[:, 1]
    _, i_n, i_c = np.intersect1d(key_n, key_c, return_indices=True)
    r_c = np.linalg.norm(clean.points[i_c], axis=1)
    res = np.linalg.norm(noisy.points[i_n], axis=1) - r_c
    cfg = TLSConfig()
    sigma = cfg.range_noise_m + cfg.range_noise_per_m * r_c
    ax = axs[0, 0]
    ax.hist(
        res / sigma, bins=120, range=(-5, 5), density=True, color="0.6", label="residual / sigma(r)"
    )
    t = np.linspace(-5, 5, 200)
    ax.plot(t, np.exp(-t * t / 2) / math.sqrt(2 * math.pi), "r", label="N(0, 1)")
    ax.set_title(
        f"range noise, {len(res)} returns: std of residual/sigma = {np.std(res / sigma):.3f}"
    )
    ax.legend()
    ax = axs[0, 1]
    bins = np.linspace(0, np.percentile(r_c, 99.5), 16)
    idx = np.digitize(r_c, bins)
    centres = [(bins[k - 1] + bins[k]) / 2 for k in range(1, len(bins)) if np.sum(idx == k) > 200]
    stds = [np.std(res[idx == k]) * 1000 for k in range(1, len(bins)) if np.sum(idx == k) > 200]
    ax.plot(centres, stds, "o", label="measured std")
    rr = np.linspace(0, bins[-1], 50)
    ax.plot(
        rr,
        (cfg.range_noise_m + cfg.range_noise_per_m * rr) * 1000,
        "r-",
        label="model: 3 mm + 10 ppm x range",
    )
    ax.set_xlabel("range [m]")
    ax.set_ylabel("range noise sigma [mm]")
    ax.set_ylim(0, 5)
    ax.set_title("noise grows with range (constant + proportional)")
    ax.legend()
    # (c) intensity against incidence on a plane of reflectance 0.5
    V = np.array([[-100.0, -100, -1.5], [100, -100, -1.5], [100, 100, -1.5], [-100, 100, -1.5]])
    plane = Scene(V, np.array([[0, 1, 2], [0, 2, 3]]), 0.5, (128, 128, 128))
    s = scan_tls(plane, np.eye(4), config=TLSConfig(width=1024, height=512), rng=0)
    r = np.linalg.norm(s.points, axis=1)
    inc = np.degrees(np.arccos(np.clip(-s.points[:, 2] / r, -1, 1)))
    ax = axs[1, 0]
    sc = ax.scatter(inc[::7], s.intensity[::7], c=r[::7], s=1, cmap="viridis", vmax=60)
    a = np.linspace(0, 86, 100)
    for dist in (2.0, 20.0, 60.0):
        ax.plot(
            a,
            0.5 * np.cos(np.radians(a)) * np.exp(-dist / cfg.intensity_range_scale_m),
            "--",
            lw=1,
            label=f"model, {dist:g} m",
        )
    fig.colorbar(sc, ax=ax, label="range [m]")
    ax.set_xlabel("incidence angle [deg]")
    ax.set_ylabel("intensity")
    ax.set_title(
        "intensity: 0.5 x cos(incidence) x exp(-r / 80 m), 4 % speckle;\n"
        "no return beyond 86 deg, nothing in the 30 deg tripod cone"
    )
    ax.legend(loc="upper right")
    # (d) mixed pixels behind a block in front of a wall (top view of a horizontal slice)
    b, w = box([3.0, -0.5, -1.0], [3.5, 0.5, 1.0]), box([7.0, -10, -10], [7.5, 10, 10])
    scene2 = Scene(np.vstack([b[0], w[0]]), np.vstack([b[1], w[1] + 8]), 0.6, (100, 100, 100))
    cfg2 = TLSConfig(width=2048, height=1024, dropout_rate=0.0)
    s2 = scan_tls(scene2, np.eye(4), config=cfg2, rng=0)
    sel = np.abs(s2.points[:, 2]) < 0.3
    p = s2.points[sel]
    off = scene2.distance(p) > 0.05
    ax = axs[1, 1]
    ax.scatter(p[~off, 0], p[~off, 1], s=1, c="0.4", label="returns on surfaces")
    ax.scatter(p[off, 0], p[off, 1], s=4, c="red", label=f"mixed pixels ({off.sum()})")
    ax.plot(0, 0, "k^", ms=10, label="scanner")
    ax.set_xlim(-0.2, 8)
    ax.set_ylim(-2, 2)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title("mixed pixels at depth edges (probability 0.5 per edge pixel)")
    ax.legend(loc="lower left", markerscale=3)
    fig.savefig(out / "synth_noise.png", dpi=80)
    plt.close(fig)


def rgbd_figure(out: Path) -> None:
    scene = make_scene("room", SEED)
    cfg = RGBDConfig()
    (T,) = camera_trajectory(scene, 1, step_m=0.01, rng=SEED)
    f = render_rgbd(scene, T, config=cfg, rng=0)
    fig, axs = plt.subplots(1, 2, figsize=(12, 4.6), layout="constrained")
    axs[0].imshow(f.image)
    axs[0].set_title("shaded colour image (640 x 480)")
    im = axs[1].imshow(f.depth, cmap="turbo")
    axs[1].set_title("depth (TUM 16-bit, 5000 / m; white = no reading)")
    fig.colorbar(im, ax=axs[1], label="depth z [m]")
    for a in axs:
        a.axis("off")
    fig.savefig(out / "synth_rgbd.png", dpi=80)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--out", type=Path, default=Path(__file__).resolve().parents[1] / "docs" / "figures"
    )
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for kind in ("room", "courtyard", "hall"):
        scene_figure(kind, args.out)
    noise_figure(args.out)
    rgbd_figure(args.out)
    print(f"figures written to {args.out}")


if __name__ == "__main__":
    main()
