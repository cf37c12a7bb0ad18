"""A scan's vertical from its own surfaces: levelling for the plan-view prior.

Floors and ceilings are perpendicular to the vertical, walls parallel to it
(:func:`estimate_up`); a coarse search over tilted verticals covers scanners set up without
levelling, and a floor test keeps the vault of a tunnel from passing for one.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

from flexreg.errors import DegenerateGeometryError

log = logging.getLogger(__name__)


def _rotation_onto_z(u: NDArray[np.float64]) -> NDArray[np.float64]:
    """Smallest rotation taking the unit vector ``u`` onto +Z (keeps the heading)."""
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(u, z)
    s, c = float(np.linalg.norm(v)), float(u @ z)
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]]) / s
    a = math.atan2(s, c)
    return np.eye(3) + math.sin(a) * K + (1 - math.cos(a)) * (K @ K)


@numba.njit(cache=True, nogil=True)
def _cone_moments(normals, area, u, cos_h, sin_v):  # pragma: no cover - compiled
    """Area and area-weighted ``n n^T`` of the normals within the cone ``|n.u| > cos_h``
    (horizontal surfaces) and of those with ``|n.u| < sin_v`` (vertical surfaces)."""
    ah = 0.0
    av = 0.0
    Mh = np.zeros((3, 3))
    Mv = np.zeros((3, 3))
    for i in range(normals.shape[0]):
        c = abs(normals[i, 0] * u[0] + normals[i, 1] * u[1] + normals[i, 2] * u[2])
        a = area[i]
        if c > cos_h:
            ah += a
            for p in range(3):
                for q in range(3):
                    Mh[p, q] += a * normals[i, p] * normals[i, q]
        elif c < sin_v:
            av += a
            for p in range(3):
                for q in range(3):
                    Mv[p, q] += a * normals[i, p] * normals[i, q]
    return ah, av, Mh, Mv


#: largest tilt of a scan treated as levelled (radians): verticals are estimated reliably up to
#: about 25° (a scanner's own compensator keeps it within a few degrees; tripods set up
#: without levelling, handheld and mobile scanners lean more). Beyond it, plan-view priors are
#: not made (the reason names the measured tilt) and registration rests on the descriptors.
MAX_TILT_RAD = math.radians(25.0)
#: tilts the search for a tilted scanner's vertical covers, and its step (radians)
SEARCH_TILT_RAD, SEARCH_STEP_RAD = math.radians(45.0), math.radians(5.0)
#: the searched vertical must explain this many times the surface the first one explains
SEARCH_GAIN = 1.1
#: normals the search scores each candidate vertical with
SEARCH_NORMALS = 20_000
#: a searched vertical must show at least this share of the floor the first one shows
#: (surface facing up within ``FLOOR_CONE_RAD`` of the vertical, below the scanner): a tunnel's
#: vault or an arch offers tilted "verticals" that explain much surface as ceiling and wall
#: but have no floor under the scanner (measured on the synthetic tunnels: 4-11 m² of floor
#: against 88-150 m² for the levelled vertical)
SEARCH_FLOOR_SHARE = 0.5
#: cone around the vertical within which an up-facing surface below the scanner is floor
FLOOR_CONE_RAD = math.radians(5.0)
#: a vertical is taken only when the scan shows floor under it, at least this share of its
#: horizontal surface: a scanner stands on a floor and sees some of it (7.6-160 % of the
#: horizontal surface on 386 synthetic and foreign stations, the least in a warehouse aisle
#: whose racks hide the floor under shelves and ceilings, lidar frames and the PCL room
#: scans), while a depth camera facing a wall or an object seen from outside offers a
#: "vertical" from its walls or its optical axis with no floor below at all (0 on the object
#: views, fused fragments and Kinect frames)
MIN_FLOOR_SHARE = 0.01


def _refine_up(
    nrm: NDArray[np.float64], wts: NDArray[np.float64], u: NDArray[np.float64]
) -> tuple[NDArray[np.float64], float, float]:
    """The vertical from shrinking cones (20°, 10°, 5°, 3°) around a start ``u``, and the
    horizontal and vertical surface areas of the last cone."""
    ah = av = 0.0
    for cone in (20.0, 10.0, 5.0, 3.0):
        ah, av, Mh, Mv = _cone_moments(
            nrm, wts, u, math.cos(math.radians(cone)), math.sin(math.radians(cone))
        )
        if ah <= 0.0 and av <= 0.0:
            break
        M = np.zeros((3, 3))
        if ah > 0:
            M += Mh / ah
        if av > 0:
            M -= Mv / av
        w, V = np.linalg.eigh(M)
        u = V[:, int(np.argmax(w))]
        if u[2] < 0:
            u = -u
    return u, ah, av


def _explained(nrm: NDArray[np.float64], wts: NDArray[np.float64], u: NDArray[np.float64]) -> float:
    """Surface area within 3° of horizontal or vertical for the vertical ``u``."""
    c, s = math.cos(math.radians(3.0)), math.sin(math.radians(3.0))
    ah, av, _, _ = _cone_moments(nrm, wts, u, c, s)
    return float(ah + av)


def _floor_area(
    pts: NDArray[np.float64],
    nrm: NDArray[np.float64],
    wts: NDArray[np.float64],
    u: NDArray[np.float64],
) -> float:
    """Surface facing up (normal within ``FLOOR_CONE_RAD`` of ``u``, normals oriented towards
    the scanner) and lying below the scanner along ``u``: the floor a vertical stands on."""
    up = (nrm @ u > math.cos(FLOOR_CONE_RAD)) & (pts @ u < 0.0)
    return float(wts[up].sum())


def _search_up(nrm: NDArray[np.float64], wts: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """The tilted vertical (5° to 45° from Z, 5° steps) that explains the most surface within
    10° of horizontal or vertical, judged on an even subset of the normals; None without
    normals."""
    if len(nrm) == 0:
        return None
    step = max(1, len(nrm) // SEARCH_NORMALS)
    n, w = np.ascontiguousarray(nrm[::step]), np.ascontiguousarray(wts[::step])
    c, s = math.cos(math.radians(10.0)), math.sin(math.radians(10.0))
    best, best_u = -1.0, None
    n_tilts = round(SEARCH_TILT_RAD / SEARCH_STEP_RAD)
    for i in range(1, n_tilts + 1):
        t = i * SEARCH_STEP_RAD
        n_az = max(1, math.ceil(2 * math.pi * math.sin(t) / SEARCH_STEP_RAD))
        for j in range(n_az):
            a = 2 * math.pi * j / n_az
            u = np.array([math.sin(t) * math.cos(a), math.sin(t) * math.sin(a), math.cos(t)])
            ah, av, _, _ = _cone_moments(n, w, u, c, s)
            if ah + av > best:
                best, best_u = ah + av, u
    return best_u


def _stands_on_floor(
    points: NDArray[np.float64],
    nrm: NDArray[np.float64],
    wts: NDArray[np.float64],
    u_new: NDArray[np.float64],
    u_old: NDArray[np.float64],
) -> bool:
    """Whether the vertical ``u_new`` shows at least ``SEARCH_FLOOR_SHARE`` of the floor
    ``u_old`` shows."""
    pts = np.asarray(points, dtype=np.float64)
    new, old = _floor_area(pts, nrm, wts, u_new), _floor_area(pts, nrm, wts, u_old)
    if new < SEARCH_FLOOR_SHARE * old:
        log.debug("tilted vertical refused: %.3g m² of floor against %.3g m²", new, old)
        return False
    return True


@dataclass(eq=False)
class Levelling:
    """A scan's estimated vertical.

    Attributes
    ----------
    up : (3,) float64
        Unit vertical in the scanner frame.
    R_level : (3, 3) float64
        Rotation taking scanner-frame vectors into the levelled frame (``up`` -> +Z; the
        heading is kept).
    tilt_rad : float, radians
        Angle between ``up`` and the scanner's Z axis.
    horizontal_area_m2, vertical_area_m2 : float, square metres
        Surface that supported the estimate (floors/ceilings, walls).
    """

    up: NDArray[np.float64]
    R_level: NDArray[np.float64]
    tilt_rad: float
    horizontal_area_m2: float
    vertical_area_m2: float


def estimate_up(
    normals: NDArray[np.float64],
    area: NDArray[np.float64],
    *,
    max_tilt_rad: float = MAX_TILT_RAD,
    points: NDArray[np.float64] | None = None,
) -> Levelling:
    """Estimate the vertical of a levelled (or tilted) scan from its surface normals.

    Starting from the scanner's Z axis, surfaces whose normals lie within a shrinking cone
    (20°, 10°, 5°, 3°) of the current vertical count as horizontal (floors, ceilings, tables),
    those within the same angle of the horizontal plane as vertical (walls); the new vertical
    is the unit vector that best aligns with the first and best stands perpendicular to the
    second: the leading eigenvector of ``sum_h a n n^T / A_h - sum_v a n n^T / A_v``.
    The same refinement also starts from the best of a coarse search over verticals 5° to 45°
    from Z (5° steps); its answer is taken when both horizontal and vertical surfaces support
    it and it explains at least 1.1 times the surface within 3° of horizontal or vertical (a
    scanner tilted 15° or more: the cones around Z may settle on a wrong vertical there), and,
    when ``points`` are given, it shows at least ``SEARCH_FLOOR_SHARE`` (half) of the floor
    the first vertical shows (up-facing surface below the scanner): the vault of a tunnel
    offers a vertical 40-46° off that explains more surface as ceiling and wall but stands on
    no floor. With ``points``, a vertical is given only when the scan shows floor below it
    (at least :data:`MIN_FLOOR_SHARE` of its horizontal surface): levelling only where there
    is a floor.

    Parameters
    ----------
    normals : (M, 3) float64
        Unit normals in the scanner frame (:func:`surface_normals`).
    area : (M,) float64, square metres
        Surface per normal (weights).
    max_tilt_rad : float, radians
        Largest plausible tilt of a levelled scanner.
    points : (M, 3) float64, metres, optional
        The points of the normals (scanner frame); without them the floor test is skipped.

    Raises
    ------
    DegenerateGeometryError
        Not enough horizontal or vertical surface to tell the vertical, no floor below it
        (with ``points``), or a vertical more than ``max_tilt_rad`` from the scanner's Z axis
        (the scan is not levelled).
    """
    nrm = np.ascontiguousarray(normals, dtype=np.float64)
    wts = np.ascontiguousarray(area, dtype=np.float64)
    u, ah, av = _refine_up(nrm, wts, np.array([0.0, 0.0, 1.0]))
    # a tilted scanner: the cones around Z may settle on a wrong vertical; a coarse search
    # over tilted verticals finds the one that explains the most surface, and it replaces
    # the first answer only when it explains clearly more (a levelled scan keeps its answer)
    seed = _search_up(nrm, wts)
    if seed is not None:
        u2, ah2, av2 = _refine_up(nrm, wts, seed)
        both = ah2 > 0 and av2 > 0  # floors and walls agree on a tilted vertical
        if both and _explained(nrm, wts, u2) > SEARCH_GAIN * _explained(nrm, wts, u):
            if points is None or _stands_on_floor(points, nrm, wts, u2, u):
                u, ah, av = u2, ah2, av2
    total = float(area.sum())
    if total <= 0 or (ah < 0.02 * total and av < 0.05 * total):
        raise DegenerateGeometryError(
            f"cannot tell the vertical: {ah:.3g} m² horizontal and {av:.3g} m² vertical "
            f"surface of {total:.3g} m²"
        )
    if points is not None:
        floor = _floor_area(np.asarray(points, dtype=np.float64), nrm, wts, u)
        if floor < MIN_FLOOR_SHARE * ah:
            raise DegenerateGeometryError(
                f"cannot tell the vertical: no floor below the scanner ({floor:.3g} m² facing "
                f"up below it of {ah:.3g} m² horizontal surface): not a levelled scanner's view"
            )
    tilt = math.acos(min(1.0, float(u[2])))
    if tilt > max_tilt_rad:
        raise DegenerateGeometryError(
            f"the scan is not levelled: tilt {math.degrees(tilt):.1f}° (its vertical from the "
            f"scanner's Z axis), more than the {math.degrees(max_tilt_rad):.1f}° limit "
            "(max_tilt_rad)"
        )
    return Levelling(u, _rotation_onto_z(u), tilt, ah, av)


__all__ = [
    "FLOOR_CONE_RAD",
    "MAX_TILT_RAD",
    "MIN_FLOOR_SHARE",
    "SEARCH_FLOOR_SHARE",
    "Levelling",
    "estimate_up",
]
