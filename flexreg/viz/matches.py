"""The match figure of a registered pair: both feature images, inliers and outliers, labelled.

``flexreg register --matches m.png`` draws it: the target's feature image on top, the source's
below, each matched keypoint pair as a line -- inliers (kept by RANSAC) solid green, outliers
thin dashed vermillion (Okabe-Ito colours, distinguishable when colour-blind) -- with the file
names and the counts in the title and a legend.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.errors import InputError

__all__ = ["INLIER_COLOUR", "OUTLIER_COLOUR", "match_figure", "save_figure"]

#: Okabe-Ito bluish green and vermillion
INLIER_COLOUR = "#009E73"
OUTLIER_COLOUR = "#D55E00"


def _evenly(idx: NDArray[np.intp], max_lines: int) -> NDArray[np.intp]:
    if len(idx) <= max_lines:
        return idx
    return idx[np.linspace(0, len(idx) - 1, max_lines).round().astype(np.intp)]


def match_figure(
    target_image: NDArray[np.uint8],
    source_image: NDArray[np.uint8],
    target_xy: NDArray[np.floating],
    source_xy: NDArray[np.floating],
    inlier_mask: NDArray[np.bool_],
    *,
    target_name: str,
    source_name: str,
    threshold_m: float | None = None,
    max_lines: int = 300,
    dpi: int = 100,
) -> Any:
    """Both feature images (target on top) with every match drawn, inliers apart from outliers.

    Parameters
    ----------
    target_image, source_image : (H1, W1), (H2, W2) uint8
        Grey feature images.
    target_xy, source_xy : (K, 2) float, pixels
        The matched keypoints ``(u, v)`` = (column, row), pair by pair.
    inlier_mask : (K,) bool
        Which pairs are inliers.
    target_name, source_name : str
        File names for the title.
    threshold_m : float, optional, metres
        The inlier distance, for the title.
    max_lines : int
        At most this many lines of each kind are drawn, evenly spaced through the list
        (the legend says how many); the counts in the title are always the full ones.
    dpi : int
        Dots per inch: the images are drawn at about one pixel per image pixel.

    Returns
    -------
    matplotlib.figure.Figure
        Not attached to pyplot (no display needed); save it with :func:`save_figure`.

    Raises
    ------
    InputError
        Keypoint arrays or mask of different lengths.
    """
    from matplotlib.collections import LineCollection  # heavy: only when a figure is drawn
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    a, b = np.asarray(target_image), np.asarray(source_image)
    pt = np.asarray(target_xy, dtype=np.float64).reshape(-1, 2)
    ps = np.asarray(source_xy, dtype=np.float64).reshape(-1, 2)
    inl = np.asarray(inlier_mask, dtype=bool).reshape(-1)
    if not len(pt) == len(ps) == len(inl):
        raise InputError(
            "match figure", f"{len(pt)} target, {len(ps)} source keypoints, {len(inl)} flags"
        )
    (h1, w1), (h2, w2) = a.shape[:2], b.shape[:2]
    width, height = max(w1, w2), h1 + h2
    canvas = np.zeros((height, width), dtype=np.uint8)
    canvas[:h1, :w1] = a
    canvas[h1:, :w2] = b
    header_in = 1.1
    fig = Figure(figsize=(max(width / dpi, 6.0), height / dpi + header_in), dpi=dpi)
    ax = fig.add_axes((0.0, 0.0, 1.0, height / (height + header_in * dpi)))
    ax.imshow(canvas, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
    ax.set_xlim(-0.5, width - 0.5)
    ax.set_ylim(height - 0.5, -0.5)
    ax.set_axis_off()
    ax.axhline(h1 - 0.5, color="white", lw=0.8)
    ax.text(5, 5, f"target: {target_name}", color="white", va="top", fontsize=9)
    ax.text(5, h1 + 5, f"source: {source_name}", color="white", va="top", fontsize=9)
    n, n_in = len(inl), int(inl.sum())
    handles = []
    for mask, colour, style, width_pt, label in (
        (~inl, OUTLIER_COLOUR, (0, (3, 2)), 0.6, "outliers"),
        (inl, INLIER_COLOUR, "solid", 1.0, "inliers"),
    ):
        idx = _evenly(np.flatnonzero(mask), max_lines)
        segs = np.stack([pt[idx], ps[idx] + [0.0, h1]], axis=1)
        ax.add_collection(
            LineCollection(
                list(segs), colors=colour, linestyles=style, linewidths=width_pt, alpha=0.8
            )
        )
        count = int(mask.sum())
        drawn = f", {len(idx)} drawn" if len(idx) < count else ""
        handles.append(
            Line2D([], [], color=colour, ls=style, lw=1.5, label=f"{label} ({count:,}{drawn})")
        )
    share = f" ({100 * n_in / n:.1f} %)" if n else ""
    within = f" within {1000 * threshold_m:.1f} mm" if threshold_m is not None else ""
    fig.suptitle(
        f"target = {target_name} (top), source = {source_name} (bottom)\n"
        f"{n:,} matched keypoint pairs: {n_in:,} inliers{share}{within}, "
        f"{n - n_in:,} outliers",
        fontsize=10,
        y=1.0 - 0.1 / (height / dpi + header_in),
        va="top",
    )
    total_in = height / dpi + header_in
    fig.legend(
        handles=handles,
        loc="upper center",
        bbox_to_anchor=(0.5, 1.0 - 0.55 / total_in),
        fontsize=9,
        frameon=False,
        ncols=2,
    )
    return fig


def save_figure(fig: Any, path: Any) -> None:
    """Write a figure as PNG (through the Agg canvas: no display, no pyplot state)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    fig.savefig(path, format="png", dpi=fig.dpi)
