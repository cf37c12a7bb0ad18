"""2D keypoints and descriptors on feature images (OpenCV detectors).

``detect_and_describe`` wraps SIFT, ORB, AKAZE, KAZE, BRISK (and SURF where the installed OpenCV
is a nonfree build), looking each up in ``cv2`` and then ``cv2.xfeatures2d`` so a user's own
OpenCV build works too. Invalid pixels are masked (with a margin, so the artificial edge between
data and no-return is not described), and on full-turn panoramas keypoints near the seam are
found on a horizontally wrapped copy and mapped back.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.errors import ConfigError, InputError

log = logging.getLogger(__name__)

METHODS = ("sift", "orb", "akaze", "kaze", "brisk", "surf")
_FACTORIES = {
    "sift": "SIFT_create",
    "orb": "ORB_create",
    "akaze": "AKAZE_create",
    "kaze": "KAZE_create",
    "brisk": "BRISK_create",
    "surf": "SURF_create",
}
#: descriptor norm per method: binary descriptors use Hamming distance
BINARY = {"orb", "akaze", "brisk"}
#: rows of image above and below each strip's own rows when SIFT runs in strips
#: (:func:`detect_and_describe` ``strip_rows``): the blur and the descriptor window of every
#: keypoint up to about 12 px in diameter lie inside them
STRIP_MARGIN_PX = 64


@dataclass(eq=False)
class Features:
    """Keypoints and descriptors of one image.

    Attributes
    ----------
    xy : (K, 2) float64, pixels
        Sub-pixel keypoint positions ``(u, v)`` = (column, row), in the unpadded image.
    descriptors : (K, D) uint8 (binary methods) or float32
    response : (K,) float32
        Detector response (strength).
    size : (K,) float32, pixels
        Keypoint diameter.
    angle : (K,) float32, degrees
        Keypoint orientation (-1 if the method has none).
    method : str
    """

    xy: NDArray[np.float64]
    descriptors: NDArray[Any]
    response: NDArray[np.float32]
    size: NDArray[np.float32]
    angle: NDArray[np.float32]
    method: str

    def __len__(self) -> int:
        return len(self.xy)

    @property
    def binary(self) -> bool:
        """True for binary descriptors (Hamming norm)."""
        return self.method in BINARY


def create_detector(method: str, *, max_features: int | None = None) -> Any:
    """OpenCV ``Feature2D`` for a method name, from ``cv2`` or ``cv2.xfeatures2d``.

    Raises
    ------
    ConfigError
        Unknown method, or a method this OpenCV build lacks (SURF needs a nonfree build: use
        ``kaze``, whose descriptor is SURF-like).
    """
    import cv2

    m = method.lower()
    if m not in _FACTORIES:
        raise ConfigError(f"unknown feature method {method!r}; choose from {', '.join(METHODS)}")
    name = _FACTORIES[m]
    factory = getattr(cv2, name, None)
    if factory is None and hasattr(cv2, "xfeatures2d"):
        factory = getattr(cv2.xfeatures2d, name, None)
    if factory is None:
        hint = (
            " (it needs an OpenCV built with nonfree modules; try 'kaze', whose descriptor"
            " is SURF-like)"
            if m == "surf"
            else ""
        )
        raise ConfigError(f"this OpenCV ({cv2.__version__}) has no {method.upper()}{hint}")
    kw: dict[str, Any] = {}
    if max_features is not None and m in ("sift", "orb"):
        kw["nfeatures"] = int(max_features)
    try:
        return factory(**kw)
    except cv2.error as e:  # e.g. SURF present but disabled in a non-free-less build
        hint = "; try 'kaze', whose descriptor is SURF-like" if m == "surf" else ""
        raise ConfigError(f"OpenCV cannot create {method.upper()}: {e.err}{hint}") from None


def to_uint8(image: NDArray[Any]) -> NDArray[np.uint8]:
    """A feature image as 8-bit: uint8 as is, uint16 scaled by 1/257, float in [0, 1] by 255
    (NaN -> 0)."""
    a = np.asarray(image)
    if a.ndim != 2:
        raise InputError("image", f"feature image must be 2D, got shape {a.shape}")
    if a.dtype == np.uint8:
        return a
    if a.dtype == np.uint16:
        return ((a.astype(np.uint32) + 128) // 257).astype(np.uint8)
    if np.issubdtype(a.dtype, np.floating):
        return np.clip(np.rint(np.nan_to_num(a, nan=0.0) * 255.0), 0, 255).astype(np.uint8)
    raise InputError("image", f"unsupported feature image dtype {a.dtype}")


def strip_rows(shape: tuple[int, ...], pixels: int) -> int | None:
    """Rows per strip of the feature detection on an image of ``shape`` (None: the whole
    image): ``pixels`` pixels per strip (a configuration's ``feature_strip_pixels``), at
    least 64 rows."""
    H, W = shape[:2]
    if pixels <= 0 or H * W <= pixels:
        return None
    return max(64, pixels // max(W, 1))


def detect_and_describe(
    image: NDArray[Any],
    method: str = "sift",
    mask: NDArray[np.bool_] | None = None,
    *,
    max_features: int | None = None,
    border_px: int = 3,
    support: float = 0.5,
    wrap: bool = False,
    detector: Any = None,
    strip_rows: int | None = None,
    tile_pixels: int | None = None,
) -> Features:
    """Detect keypoints and compute descriptors on a feature image.

    Parameters
    ----------
    image : (H, W) uint8, uint16 or float in [0, 1]
        Feature image (Flexion, Bearing Angle, intensity...); NaN counts as invalid.
    method : {"sift", "orb", "akaze", "kaze", "brisk", "surf"}
    mask : (H, W) bool, optional
        Valid pixels. Keypoints closer than ``border_px`` to an invalid pixel are discarded,
        so the artificial contrast at no-return holes yields no features.
    max_features : int, optional
        Keep at most this many, strongest response first.
    border_px : int
        Safety margin around invalid pixels, pixels.
    support : float
        Also discard keypoints closer to an invalid pixel than ``support`` times their size
        (diameter): a large-scale descriptor centred near a hole would describe the hole.
    wrap : bool
        The image is a full-turn panorama: detect on a copy padded with the opposite side's
        columns so the seam loses no features, then map the keypoints back (``u mod W``) and
        drop the duplicates found twice.
    detector : cv2.Feature2D, optional
        A pre-built detector (overrides ``method``'s default parameters).
    strip_rows : int, optional
        SIFT only: detect in horizontal strips of this many rows, each seen with
        :data:`STRIP_MARGIN_PX` rows of image above and below and keeping the keypoints whose
        centre lies in its own rows. OpenCV builds SIFT's scale space on the image upsampled
        2x (about 0.45 MB per row of a 2048-pixel-wide image), so only one strip's exists at a
        time. SIFT's thresholds are absolute, so the keypoints are those of the whole image
        except a few, mostly large ones (diameter above about 12 px) whose blur or descriptor
        window crosses a strip's margin: on a 2048 x 1024 Flexion image 99.5 % of keypoints
        and descriptors are identical with 256-row strips. Other methods normalise over the whole
        image and always see it whole.
    tile_pixels : int, optional
        SIFT only: detect in tiles of about this many pixels of their own (:func:`tiles`: as
        square as the image allows), each seen with :data:`STRIP_MARGIN_PX` pixels of image
        on every inner side, keeping the keypoints whose centre lies in its own pixels (as
        ``strip_rows``, whose strips it replaces when both are given). A square tile needs
        less margin for its own pixels than a strip of the same area, so tiles of the same
        memory cost less time, and tiles of the same time less memory: on a 2048 x 1024
        image, 524,288 pixels per piece make six tiles of at most 576 x 811 pixels with their
        margins (about 0.47 Mpx each) instead of four strips of up to 384 x 2048 (0.79 Mpx),
        and the tiles see 1.27 times the image's pixels, the strips 1.38 times.

    Returns
    -------
    Features
    """
    import cv2

    img = to_uint8(image)
    H, W = img.shape
    valid = np.ones((H, W), dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    if valid.shape != (H, W):
        raise InputError("mask", f"mask shape {valid.shape} differs from the image's {(H, W)}")
    if np.issubdtype(np.asarray(image).dtype, np.floating):
        valid = valid & np.isfinite(image)
    det = detector if detector is not None else create_detector(method, max_features=None)
    pad = 0
    if wrap:
        pad = min(W, 64)
        img = np.concatenate([img[:, -pad:], img, img[:, :pad]], axis=1)
        valid = np.concatenate([valid[:, -pad:], valid, valid[:, :pad]], axis=1)
    keep = valid
    if border_px > 0:
        k = 2 * border_px + 1
        keep = cv2.erode(valid.astype(np.uint8), np.ones((k, k), np.uint8), borderValue=0) > 0
    mask8 = (keep * 255).astype(np.uint8)
    boxes = None
    if method.lower() == "sift" and tile_pixels is not None:
        boxes = tiles(img.shape, int(tile_pixels))
    elif method.lower() == "sift" and strip_rows is not None and img.shape[0] > strip_rows:
        rows = max(1, int(strip_rows))
        boxes = [(r, min(r + rows, H), 0, img.shape[1]) for r in range(0, H, rows)]
    if boxes is not None and len(boxes) > 1:
        found = _detect_tiles(det, img, mask8, boxes)
    else:
        found = _detect(det, img, mask8)
    if found is None:
        return _empty(method, det)
    xy, resp, size, angle, desc = found
    sel = np.ones(len(xy), dtype=bool)
    if support > 0 and not valid.all():
        dist = cv2.distanceTransform(valid.astype(np.uint8), cv2.DIST_L2, 5)
        r = np.clip(np.rint(xy[:, 1]).astype(np.int64), 0, dist.shape[0] - 1)
        c = np.clip(np.rint(xy[:, 0]).astype(np.int64), 0, dist.shape[1] - 1)
        sel &= dist[r, c] >= support * size
    if wrap:
        sel &= (xy[:, 0] >= pad - 0.5) & (xy[:, 0] < pad + W - 0.5)
        xy[:, 0] = np.mod(xy[:, 0] - pad, W)
    ok = np.flatnonzero(sel)
    order = ok[np.argsort(-resp[ok], kind="stable")]
    if max_features is not None:
        order = order[: int(max_features)]
    return Features(
        xy=xy[order],
        descriptors=desc[order],
        response=resp[order],
        size=size[order],
        angle=angle[order],
        method=method.lower(),
    )


_Found = tuple[
    NDArray[np.float64], NDArray[np.float32], NDArray[np.float32], NDArray[np.float32], NDArray[Any]
]


def _detect(det: Any, img: NDArray[np.uint8], mask: NDArray[np.uint8]) -> _Found | None:
    """``detectAndCompute`` as arrays: positions, responses, sizes, angles, descriptors (OpenCV
    may drop keypoints in compute(); the arrays stay aligned), or None when none is found."""
    kps, desc = det.detectAndCompute(img, mask)
    if desc is None or not kps:
        return None
    return (
        np.array([kp.pt for kp in kps], dtype=np.float64).reshape(-1, 2),
        np.array([kp.response for kp in kps], dtype=np.float32),
        np.array([kp.size for kp in kps], dtype=np.float32),
        np.array([kp.angle for kp in kps], dtype=np.float32),
        desc,
    )


def tiles(shape: tuple[int, ...], pixels: int) -> list[tuple[int, int, int, int]]:
    """The tiles of the SIFT detection on an image of ``shape`` (``detect_and_describe``
    ``tile_pixels``): ``(r0, r1, c0, c1)`` boxes of their own pixels, covering the image
    without overlap, each of at most ``pixels`` pixels and as square as the image allows
    (so that the margins they are seen with add the fewest pixels), at least 64 pixels a
    side. One box (the whole image) when the image has no more than ``pixels`` pixels or
    ``pixels`` <= 0.

    >>> tiles((1024, 2176), 524_288)[:2]
    [(0, 512, 0, 726), (0, 512, 726, 1452)]
    >>> len(tiles((1024, 2176), 524_288)), tiles((100, 100), 524_288)
    (6, [(0, 100, 0, 100)])
    """
    H, W = int(shape[0]), int(shape[1])
    if pixels <= 0 or H * W <= pixels:
        return [(0, H, 0, W)]
    side = max(64, math.isqrt(pixels))
    nr = max(1, -(-H // side))
    th = -(-H // nr)
    nc = max(1, -(-(W * th) // max(pixels, 64 * th)))
    tw = -(-W // nc)
    return [
        (r, min(r + th, H), c, min(c + tw, W)) for r in range(0, H, th) for c in range(0, W, tw)
    ]


Box = tuple[int, int, int, int]


def _detect_tiles(
    det: Any, img: NDArray[np.uint8], mask: NDArray[np.uint8], boxes: list[Box]
) -> _Found | None:
    """:func:`_detect` tile by tile (each box seen with :data:`STRIP_MARGIN_PX` pixels of
    margin on its inner sides): a keypoint belongs to the tile that holds its rounded centre,
    as OpenCV's mask test reads it, so no keypoint is found twice."""
    H, W = img.shape
    m0 = STRIP_MARGIN_PX
    parts: list[_Found] = []
    for r0, r1, c0, c1 in boxes:
        a0, a1 = max(0, r0 - m0), min(H, r1 + m0)
        b0, b1 = max(0, c0 - m0), min(W, c1 + m0)
        m = np.zeros((a1 - a0, b1 - b0), dtype=np.uint8)
        m[r0 - a0 : r1 - a0, c0 - b0 : c1 - b0] = mask[r0:r1, c0:c1]
        if not m.any():
            continue
        found = _detect(det, np.ascontiguousarray(img[a0:a1, b0:b1]), m)
        if found is not None:
            found[0][:, 1] += a0
            found[0][:, 0] += b0
            parts.append(found)
    if not parts:
        return None
    xy, resp, size, angle, desc = (np.concatenate([p[i] for p in parts]) for i in range(5))
    return xy, resp, size, angle, desc


def _empty(method: str, det: Any) -> Features:
    binary = method.lower() in BINARY
    d = int(det.descriptorSize()) if hasattr(det, "descriptorSize") else 0
    return Features(
        xy=np.zeros((0, 2)),
        descriptors=np.zeros((0, d), dtype=np.uint8 if binary else np.float32),
        response=np.zeros(0, np.float32),
        size=np.zeros(0, np.float32),
        angle=np.zeros(0, np.float32),
        method=method.lower(),
    )
