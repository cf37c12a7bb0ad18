"""Descriptor matching: k-NN with Lowe's ratio test and a mutual (cross) check."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from .features import Features


def match(
    target: Features,
    source: Features,
    *,
    ratio: float = 0.8,
    mutual: bool = True,
) -> NDArray[np.int64]:
    """Match source features to target features.

    A pair ``(i, j)`` is kept when target ``i`` is source ``j``'s nearest neighbour, the
    nearest is clearly better than the second (``d1 < ratio * d2``, Lowe's ratio test), and,
    with ``mutual``, source ``j`` is also target ``i``'s nearest neighbour. Distances use the
    L2 norm for float descriptors and the Hamming norm for binary ones (ORB, AKAZE, BRISK).

    Parameters
    ----------
    target, source : Features
    ratio : float
        Ratio-test threshold in (0, 1]; 1 disables it.
    mutual : bool
        Keep only mutual nearest neighbours.

    Returns
    -------
    (Q, 2) int64
        ``[target index, source index]`` per match, sorted by source index.
    """
    import cv2

    if len(target) < 2 or len(source) < 1:
        return np.zeros((0, 2), dtype=np.int64)
    norm = cv2.NORM_HAMMING if source.binary else cv2.NORM_L2
    bf = cv2.BFMatcher(norm, crossCheck=False)
    fwd = bf.knnMatch(source.descriptors, target.descriptors, k=2)
    pairs = []
    for m in fwd:
        if len(m) == 2 and m[0].distance < ratio * m[1].distance:
            pairs.append((m[0].trainIdx, m[0].queryIdx))
        elif len(m) == 1:
            pairs.append((m[0].trainIdx, m[0].queryIdx))
    if not pairs:
        return np.zeros((0, 2), dtype=np.int64)
    out = np.asarray(pairs, dtype=np.int64)
    if mutual:
        back: Any = bf.match(target.descriptors, source.descriptors)  # nearest source per target
        nn = np.full(len(target), -1, dtype=np.int64)
        for b in back:
            nn[b.queryIdx] = b.trainIdx
        out = out[nn[out[:, 0]] == out[:, 1]]
    return out[np.argsort(out[:, 1], kind="stable")]
