"""Drawing on 8-bit BGR images with OpenCV: colour maps, a colour bar, a labelled pixel grid and
feature-match pictures. Functions over arrays only (no scans, no files)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.errors import InputError

__all__ = ["as_bgr", "colour_bar", "draw_grid", "match_image", "range_colours"]


def range_colours(r: ArrayLike, max_range_m: float) -> NDArray[np.uint8]:
    """(N, 3) uint8 BGR turbo colours of ranges ``r`` (metres), near red to far blue.

    Ranges from 0 to ``max_range_m`` span the colour map; farther ones get its far end.
    """
    import cv2  # heavy: OpenCV loads only when drawing

    q = np.clip(255.0 * (1.0 - np.asarray(r) / max_range_m), 0, 255).astype(np.uint8)
    return np.asarray(cv2.applyColorMap(q.reshape(-1, 1), cv2.COLORMAP_TURBO).reshape(-1, 3))


def as_bgr(image: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """A BGR copy of a grey, BGR or BGRA 8-bit image.

    Raises
    ------
    InputError
        Not 8-bit, or not of shape (H, W), (H, W, 3) or (H, W, 4).
    """
    import cv2  # heavy: OpenCV loads only when drawing

    a = np.asarray(image)
    if a.dtype != np.uint8:
        raise InputError("image", f"expected an 8-bit image, got {a.dtype}")
    if a.ndim == 2:
        return np.asarray(cv2.cvtColor(a, cv2.COLOR_GRAY2BGR))
    if a.ndim == 3 and a.shape[2] == 4:
        return np.asarray(cv2.cvtColor(a, cv2.COLOR_BGRA2BGR))
    if a.ndim == 3 and a.shape[2] == 3:
        return a.copy()
    raise InputError("image", f"expected a grey or BGR image, got shape {a.shape}")


def colour_bar(out: NDArray[np.uint8], max_range_m: float) -> None:
    """Draw the :func:`range_colours` scale (0 to ``max_range_m`` metres) in the lower right
    corner of the BGR image ``out``, in place; nothing on images narrower than 96 pixels."""
    import cv2  # heavy: OpenCV loads only when drawing

    H, W = out.shape[:2]
    bw, bh = min(256, W // 3), max(8, H // 60)
    if bw < 32:
        return
    x0, y0 = W - bw - 10, H - bh - 22
    ramp = range_colours(np.linspace(0.0, max_range_m, bw), max_range_m)
    out[y0 : y0 + bh, x0 : x0 + bw] = ramp[None, :, :]
    font, fs = cv2.FONT_HERSHEY_SIMPLEX, 0.4
    for text, x in (("0 m", x0), (f"{max_range_m:.0f} m", x0 + bw - 30)):
        cv2.putText(out, text, (x, y0 + bh + 14), font, fs, (0, 0, 0), 3, cv2.LINE_AA)
        cv2.putText(out, text, (x, y0 + bh + 14), font, fs, (255, 255, 255), 1, cv2.LINE_AA)


def draw_grid(out: NDArray[np.uint8], minor: int, major: int, *, top: str, left: str) -> None:
    """Draw a labelled pixel grid on the BGR image ``out``, in place.

    Lines every ``minor`` pixels (brighter every ``major``), the major coordinates written
    along the top and left edges (the image's own pixels), and the axis names ``top``
    (columns) and ``left`` (rows).
    """
    import cv2  # heavy: OpenCV loads only when drawing

    H, W = out.shape[:2]
    overlay = out.copy()
    for x in range(0, W, minor):
        c = (0, 255, 255) if x % major == 0 else (0, 160, 160)
        cv2.line(overlay, (x, 0), (x, H - 1), c, 1)
    for y in range(0, H, minor):
        c = (0, 255, 255) if y % major == 0 else (0, 160, 160)
        cv2.line(overlay, (0, y), (W - 1, y), c, 1)
    cv2.addWeighted(overlay, 0.35, out, 0.65, 0.0, dst=out)
    font, fs = cv2.FONT_HERSHEY_PLAIN, 0.8
    for x in range(major, W, major):
        for text, c, t in ((str(x), (0, 0, 0), 3), (str(x), (0, 255, 255), 1)):
            cv2.putText(out, text, (x + 2, 10), font, fs, c, t, cv2.LINE_AA)
    major_y = major if H > 150 else 2 * minor
    for y in range(major_y, H, major_y):
        for text, c, t in ((str(y), (0, 0, 0), 3), (str(y), (0, 255, 255), 1)):
            cv2.putText(out, text, (2, y - 2), font, fs, c, t, cv2.LINE_AA)
    for text, c, t in ((f"{top} ->", (0, 0, 0), 3), (f"{top} ->", (0, 255, 255), 1)):
        cv2.putText(out, text, (W // 2, 22) if H > 40 else (W // 2, 10), font, fs, c, t)
    if H > 60:
        for text, c, t in ((f"{left} v", (0, 0, 0), 3), (f"{left} v", (0, 255, 255), 1)):
            cv2.putText(out, text, (2, H // 2), font, fs, c, t)


def match_image(
    target_image: NDArray[np.uint8],
    source_image: NDArray[np.uint8],
    target_xy: NDArray[np.floating],
    source_xy: NDArray[np.floating],
    *,
    max_lines: int = 300,
) -> NDArray[np.uint8]:
    """Two feature images stacked vertically (target on top) with matches drawn as lines.

    Parameters
    ----------
    target_image, source_image : (H1, W1), (H2, W2) uint8
        Grey feature images; the narrower one is padded on the right with black.
    target_xy, source_xy : (K, 2) float, pixels
        Matched keypoints ``(u, v)`` = (column, row) in each image, row by row.
    max_lines : int
        At most this many matches are drawn, evenly spaced through the list (deterministic).

    Returns
    -------
    (H1 + H2, max(W1, W2), 3) uint8
        BGR image for ``cv2.imwrite``.

    >>> a, b = np.zeros((2, 4), np.uint8), np.zeros((3, 5), np.uint8)
    >>> match_image(a, b, [[1.0, 1.0]], [[2.0, 2.0]]).shape
    (5, 5, 3)
    """
    import cv2  # heavy: OpenCV loads only when drawing

    a, b = np.asarray(target_image, dtype=np.uint8), np.asarray(source_image, dtype=np.uint8)
    (h1, w1), (h2, w2) = a.shape, b.shape
    canvas = np.zeros((h1 + h2, max(w1, w2)), dtype=np.uint8)
    canvas[:h1, :w1] = a
    canvas[h1:, :w2] = b
    out = np.ascontiguousarray(cv2.cvtColor(canvas, cv2.COLOR_GRAY2BGR), dtype=np.uint8)
    pt = np.asarray(target_xy, dtype=np.float64).reshape(-1, 2)
    ps = np.asarray(source_xy, dtype=np.float64).reshape(-1, 2)
    if len(pt) != len(ps):
        raise InputError("match_image", f"{len(pt)} target but {len(ps)} source keypoints")
    k = len(pt)
    if k > max_lines:
        keep = np.unique(np.linspace(0, k - 1, max(max_lines, 1)).round().astype(np.int64))
        pt, ps = pt[keep], ps[keep]
    if k == 0:
        return out
    hues = np.linspace(0, 180, len(pt), endpoint=False).astype(np.uint8)
    hsv = np.stack([hues, np.full_like(hues, 255), np.full_like(hues, 255)], axis=1)
    colours = cv2.cvtColor(hsv[None], cv2.COLOR_HSV2BGR)[0].tolist()
    for (u1, v1), (u2, v2), c in zip(pt, ps, colours, strict=True):
        p1 = (round(u1), round(v1))
        p2 = (round(u2), round(v2) + h1)
        cv2.line(out, p1, p2, c, 1, cv2.LINE_AA)
        cv2.circle(out, p1, 3, c, 1, cv2.LINE_AA)
        cv2.circle(out, p2, 3, c, 1, cv2.LINE_AA)
    return out
