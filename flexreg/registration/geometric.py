"""The geometric route of :func:`~flexreg.registration.register`: which route a pair takes
(``config.method``) and the FPFH hypotheses (:mod:`flexreg.stages.geometric`) as candidates
the dense check and the verdict judge like the feature images' own.

Feature images need a scanner's view of a scene: a panorama, or a depth image of a room with
texture in its shapes. An object scanned from outside, a narrow-field lidar frame or a
fragment fused from many views give them few keypoints and fewer true matches; descriptors of
the 3D shape still match there. The geometric hypotheses carry their pose without keypoint
inliers (origin ``"geometric"``, a dense prior), so only the check of the whole clouds decides
between them and the feature images' hypotheses.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Literal

from flexreg.core.camera import PinholeCamera
from flexreg.core.range_image import RangeImage
from flexreg.core.scan import Scan, as_points
from flexreg.errors import DegenerateGeometryError, InputError
from flexreg.registration.candidates import Candidate
from flexreg.registration.config import RegistrationConfig
from flexreg.stages.geometric import geometric_hypotheses

log = logging.getLogger(__name__)

#: geometric hypotheses judged per pair: the best supported and its distinct runner-ups
GEOMETRIC_HYPOTHESES = 3

Route = Literal["flexion", "both", "geometric"]


def panoramic(images: list[RangeImage]) -> bool:
    """Whether every working image is a panorama (a terrestrial station, a spinning lidar)."""
    return all(not isinstance(i.camera, PinholeCamera) for i in images)


def gridded(scans: Sequence[Scan | RangeImage]) -> bool:
    """Whether every scan comes as a grid (a range image, or a file with its native grid: PTX,
    gridded E57, organised PCD), not as a cloud the registration projects itself."""
    return all(not isinstance(s, Scan) or s.has_grid for s in scans)


def route(method: str, images: list[RangeImage], found: bool, grids: bool = True) -> Route:
    """Which hypotheses a pair's answer is chosen among.

    ``"flexion"``: the feature images' alone (``method="flexion"``; ``"init"``, whose one
    hypothesis is the given transform; or ``"auto"`` for two panoramic ``grids`` on which
    they ``found`` a prior: the stations they were made for); ``"both"``: both routes'
    hypotheses judged together (``"auto"`` on every other pair: depth images, clouds
    projected from their origin, or stations on which the feature images found nothing; a
    confident answer of the feature images alone is not enough there, since on such scans
    they can fit a look-alike that only the other route's hypotheses reveal);
    ``"geometric"``: the geometric ones alone.

    >>> route("auto", [], False)
    'both'
    >>> route("auto", [], True, grids=False)
    'both'
    """
    if method in ("flexion", "init"):  # init: the given transform alone (no search)
        return "flexion"
    if method == "geometric":
        return "geometric"
    return "flexion" if found and grids and panoramic(images) else "both"


def geometric_priors(
    images: list[RangeImage], config: RegistrationConfig, notes: list[str]
) -> list[Candidate]:
    """The FPFH hypotheses of two working images' points, as ``("geometric", T)`` candidates
    (in the order found); none, and a note why, when the descriptors support none.

    Parameters
    ----------
    images : [RangeImage, RangeImage]
        Target and source working images, points in their scanner frames (the viewpoint
        that orients the normals is each frame's origin).
    config : RegistrationConfig
        ``seed`` seeds the search.
    notes : list of str
        Appended to: why the route gave nothing.
    """
    try:
        pts = [as_points(i, name="scan") for i in images]
        hyps, dt, _ = geometric_hypotheses(
            pts[0], pts[1], count=GEOMETRIC_HYPOTHESES, rng=config.seed
        )
    except (DegenerateGeometryError, InputError) as e:
        notes.append(f"geometric: {e}")
        return []
    if not hyps:
        notes.append(f"geometric: no pose supported by FPFH matches at a {dt.voxel_m:.3g} m voxel")
        return []
    log.info("geometric priors: supports %s", [h.support for h in hyps])
    return [("geometric", h.T_target_source) for h in hyps]


__all__ = ["GEOMETRIC_HYPOTHESES", "Route", "geometric_priors", "gridded", "panoramic", "route"]
