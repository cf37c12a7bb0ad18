"""Where a cloud was seen from: the points it hides from a viewpoint tell.

A scan taken from one point never holds a point behind another of its own points on the same
ray from the scanner: the nearer surface would have stopped the beam. A cloud fused from many
viewpoints (an RGB-D fragment, a merged project, an exported building) does: from any one
point, some of its surfaces lie behind others. :func:`hidden_share` measures the share of a
cloud's points that lie clearly behind another of its points as seen from a viewpoint (on the
same pixel of an equirectangular image at the cloud's own angular spacing, more than
:data:`HIDDEN_REL` of the range farther). From the scanner only mixed pixels at depth edges
and far grazing floors count: 0-1.7 % of the synthetic stations, object views and lidar
frames, the Ouster frames, the PCL room scan and a Stanford bunny range scan; fused clouds
hide more: 0.1-6.9 % of our synthetic fragments (fused along a short path), 4.5-4.9 % of the
3DMatch fragments, 3.3 % of a station seen from 0.9 m beside its scanner.

:func:`choose_viewpoint` finds, for a cloud whose file says nothing of its scanner and whose
origin lies away from its points (project coordinates,
:func:`flexreg.io.origin.centring_problem`), the position from which it hides least of
itself: a virtual viewpoint for its images (near the scanner for a scan taken from one
point). A cloud that hides
more than :data:`MAX_HIDDEN_SHARE` of itself from its viewpoint has no single one: the verdict
does not test the open space seen from it (:class:`flexreg.registration.check.Check`) and
says so.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.core.camera import azimuth_polar_extent

__all__ = [
    "HIDDEN_REL",
    "MAX_HIDDEN_SHARE",
    "SEARCH_POINTS",
    "SEARCH_STOP",
    "VIEWPOINT_POINTS",
    "choose_viewpoint",
    "hidden_share",
    "one_viewpoint",
]

#: a point is hidden when it lies this share of its range behind the nearest point of its
#: pixel (less: a grazing floor's far points share a pixel with nearer ones of the same floor)
HIDDEN_REL = 0.25

#: a cloud that hides more than this share of its points from its viewpoint was not taken
#: from there (single scans from their scanner: up to 1.7 %; the 3DMatch fragments 4.5-4.9 %)
MAX_HIDDEN_SHARE = 0.03

#: points of the cloud (an even subset) a hidden share is measured on
VIEWPOINT_POINTS = 200_000

#: points of the cloud (an even subset) the search for a viewpoint scores each position on
SEARCH_POINTS = 30_000

#: the search for a viewpoint stops at steps this share of the cloud's bounding-box diagonal
SEARCH_STOP = 0.005


def hidden_share(points: ArrayLike, origin: ArrayLike | None = None) -> float:
    """The share of a cloud's points that lie behind another of its points from ``origin``.

    Parameters
    ----------
    points : (N, 3) float, metres
    origin : (3,) float, metres, optional
        The viewpoint (default: the points' origin).

    Returns
    -------
    float
        In [0, 1]; 0 for fewer than two points off the viewpoint.

    Examples
    --------
    >>> wall = np.stack(np.meshgrid(np.linspace(-2, 2, 60), np.linspace(-2, 2, 60)), -1)
    >>> wall = np.concatenate([wall.reshape(-1, 2), np.full((3600, 1), 5.0)], axis=1)
    >>> behind = 2.0 * wall  # the same wall again, twice as far along the same rays
    >>> hidden_share(wall), round(hidden_share(np.vstack([wall, behind])), 2)
    (0.0, 0.5)
    """
    P = np.asarray(points, dtype=np.float64)
    P = P[:: max(1, -(-len(P) // VIEWPOINT_POINTS))]
    if origin is not None:
        P = P - np.asarray(origin, dtype=np.float64)
    r = np.linalg.norm(P, axis=1)
    P, r = P[r > 0], r[r > 0]
    if len(P) < 2:
        return 0.0
    phi_min, phi_max, th_min, th_max, full = azimuth_polar_extent(P)
    span_phi = 2 * math.pi if full else max(phi_max - phi_min, 1e-9)
    span_th = max(th_max - th_min, 1e-9)
    # the cloud's own angular spacing per pixel: two points on one ray share a pixel
    pitch = math.sqrt(span_phi * span_th / len(P))
    phi = np.mod(np.arctan2(P[:, 1], P[:, 0]) - (-math.pi if full else phi_min), 2 * math.pi)
    th = np.arccos(np.clip(P[:, 2] / r, -1.0, 1.0)) - th_min
    W = max(1, math.ceil(span_phi / pitch))
    H = max(1, math.ceil(span_th / pitch))
    pix = np.minimum((th / pitch).astype(np.int64), H - 1) * W + np.minimum(
        (phi / pitch).astype(np.int64), W - 1
    )
    nearest = np.full(H * W, np.inf)
    np.minimum.at(nearest, pix, r)
    return float(np.mean(r > nearest[pix] * (1.0 + HIDDEN_REL)))


def one_viewpoint(hidden: float | None) -> bool:
    """Whether a cloud hiding ``hidden`` of its points (None: a grid, one viewpoint by
    construction) was taken from one point: at most :data:`MAX_HIDDEN_SHARE`."""
    return hidden is None or hidden <= MAX_HIDDEN_SHARE


def choose_viewpoint(points: ArrayLike) -> tuple[NDArray[np.float64], float]:
    """A virtual viewpoint for a cloud whose scanner position is unknown: where it hides least
    of itself.

    A compass search over :func:`hidden_share` (on an even subset of
    :data:`SEARCH_POINTS` points): from the better of the points' median and the centre of
    their bounding box, it moves by a step (an eighth of the box's diagonal at first) along
    each axis either way, within the box, to the position that hides least, and halves the
    step when none hides less, down to :data:`SEARCH_STOP` of the diagonal (outside its
    points a viewpoint sees them all at a sliver of the sphere, where nothing hides by a
    share of its range: no scanner's place). A scan taken from one point
    hides nothing from where its scanner stood, so the search ends near it; a cloud fused
    from many viewpoints ends where it hides least, which is still more than
    :data:`MAX_HIDDEN_SHARE` (its open space is then not tested).

    Parameters
    ----------
    points : (N, 3) float, metres

    Returns
    -------
    origin : (3,) float64, metres
        In the points' frame.
    hidden : float
        Its :func:`hidden_share` (of the whole cloud, up to :data:`VIEWPOINT_POINTS`).
    """
    P = np.asarray(points, dtype=np.float64)
    S = P[:: max(1, -(-len(P) // SEARCH_POINTS))]
    lo, hi = S.min(axis=0), S.max(axis=0)
    diagonal = float(np.linalg.norm(hi - lo))
    starts = [np.median(S, axis=0), (lo + hi) / 2]
    shares = [hidden_share(S, c) for c in starts]
    best, share = starts[int(np.argmin(shares))], min(shares)
    step = diagonal / 8
    moves = np.vstack([np.eye(3), -np.eye(3)])
    while step > SEARCH_STOP * diagonal and share > 0.0:
        tried = [np.clip(best + step * m, lo, hi) for m in moves]  # among the points
        found = [hidden_share(S, c) for c in tried]
        k = int(np.argmin(found))
        if found[k] < share:
            best, share = tried[k], found[k]
        else:
            step /= 2
    return best, hidden_share(P, best)
