"""Make the figures of docs/conversions.md from the real laser scan in ../shared/data.

    python scripts/conversion_figure.py [--out docs/figures]

Writes
  conversions.png            range, Flexion 3x3 / 5x5 / 9x9, normalized, angle and the four
                             Bearing Angles of the whole 360 degree scan
  conversions-detail.png     the same conversions on a crop, pixel for pixel
  conversions-curvature.png  Gaussian / mean / max curvature (the paper's Fig. 5 baselines)
                             next to Flexion 3x3
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from flexreg.core.camera import SphericalCamera  # noqa: E402
from flexreg.core.range_image import RangeImage, from_depth  # noqa: E402
from flexreg.io.depth import read_depth_png  # noqa: E402
from flexreg.stages import feature_images as I  # noqa: E402

SCAN = REPO.parent / "shared" / "data" / "conversions" / "laserscan-depth.png"
# the polar range the reference images were made with (laser_intrinsic.txt rounds it)
THETA = (math.radians(50.0), math.radians(130.0))

PANELS: list[tuple[str, str, int]] = [  # (title, kind, n)
    ("range (0 to 95th percentile)", "range", 3),
    ("Flexion 3x3", "flexion", 3),
    ("Flexion 5x5", "flexion", 5),
    ("Flexion 9x9", "flexion", 9),
    ("Flexion normalized 3x3", "flexion-normalized", 3),
    ("Flexion angle 3x3 (eq. 14)", "flexion-angle", 3),
    ("Bearing Angle horizontal (left)", "bearing-horizontal", 3),
    ("Bearing Angle vertical (above)", "bearing-vertical", 3),
    ("Bearing Angle diagonal (upper-left)", "bearing-diagonal", 3),
    ("Bearing Angle antidiagonal (lower-left)", "bearing-antidiagonal", 3),
]


def load() -> RangeImage:
    d = read_depth_png(SCAN)  # range in the PNG's units; the conversions are scale-free
    return from_depth(d, SphericalCamera.from_reference(d.shape[1], d.shape[0], *THETA))


def grey(kind: str, image: np.ndarray) -> np.ndarray:
    """8-bit display image: eq. 10 scaling for the conversions, percentiles for the rest."""
    if kind == "range":
        hi = float(np.nanpercentile(image, 95.0))
        q, _ = I.quantize(image, 8, value_range=(0.0, hi))
    else:
        q, _ = I.quantize(image, 8, value_range=I.value_range(kind, image))
    return q


def panel_grid(rimg: RangeImage, panels, crop=None, cols: int = 2, width: float = 16.0):
    import matplotlib.pyplot as plt

    rows = math.ceil(len(panels) / cols)
    H, W = rimg.shape
    if crop is not None:
        (r0, r1), (c0, c1) = crop
        H, W = r1 - r0, c1 - c0
    panel_h = width / cols * H / W
    fig, axes = plt.subplots(rows, cols, figsize=(width, rows * (panel_h + 0.35)), squeeze=False)
    for ax, (title, kind, n) in zip(axes.flat, panels, strict=False):
        img = grey(kind, I.convert(rimg, kind, n=n))
        if crop is not None:
            img = img[crop[0][0] : crop[0][1], crop[1][0] : crop[1][1]]
        ax.imshow(img, cmap="gray", vmin=0, vmax=255, interpolation="nearest", aspect="auto")
        ax.set_title(title, fontsize=10)
        ax.set_axis_off()
    for ax in list(axes.flat)[len(panels) :]:
        ax.set_axis_off()
    fig.tight_layout(pad=0.4)
    return fig


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=REPO / "docs" / "figures")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    import matplotlib

    matplotlib.use("Agg")

    rimg = load()
    fig = panel_grid(rimg, PANELS)
    fig.savefig(args.out / "conversions.png", dpi=110)

    crop = ((60, 330), (1050, 1450))  # rows, columns of a detail
    fig = panel_grid(rimg, PANELS, crop=crop, cols=5, width=20.0)
    fig.savefig(args.out / "conversions-detail.png", dpi=100)

    curv = [
        ("Flexion 3x3", "flexion", 3),
        ("Gaussian curvature (Fig. 5a baseline)", "curvature-gaussian", 3),
        ("mean curvature (Fig. 5b baseline)", "curvature-mean", 3),
        ("max curvature (Fig. 5c baseline)", "curvature-max", 3),
    ]
    fig = panel_grid(rimg, curv)
    fig.savefig(args.out / "conversions-curvature.png", dpi=110)
    for name in ("conversions.png", "conversions-detail.png", "conversions-curvature.png"):
        print(args.out / name)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
