"""Poses the files store per setup, as priors of a survey's links and as a check of its result.

A project export (E57 ``pose`` per setup, PTX header transform) often carries where the field
software put every setup: sometimes a rough guess, sometimes an earlier registration. A survey
seeds each link between two stations that store poses with their stored relative pose
(:func:`stored_T_target_source`), and checks every placed station against its stored pose
(:func:`check_stations`). Where the two disagree, one of them is wrong: the station is flagged
for the surveyor, never silently trusted.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.core.transforms import invert, rotation_error_deg, translation_error_m

Matrix = NDArray[np.float64]


def stored_T_target_source(stored: dict[str, Matrix], target: str, source: str) -> Matrix | None:
    """``inv(T_world_target) @ T_world_source`` when both stations store a pose, else None."""
    if target not in stored or source not in stored:
        return None
    return invert(stored[target]) @ stored[source]


def deviation(T_est: Matrix, T_stored: Matrix) -> dict[str, float]:
    """``{"rotation_deg", "translation_m"}`` between a registered and a stored transform."""
    return {
        "rotation_deg": rotation_error_deg(T_est, T_stored),
        "translation_m": translation_error_m(T_est, T_stored),
    }


def _within(d: dict[str, float], max_deg: float, max_m: float) -> bool:
    return d["rotation_deg"] <= max_deg and d["translation_m"] <= max_m


def check_stations(
    poses: dict[str, Matrix], stored: dict[str, Matrix], max_deg: float, max_m: float
) -> dict[str, dict[str, Any]]:
    """Each placed station's registered pose against the pose its file stores.

    The stored frame is tied to the reference frame through one station (the *pivot*):
    ``T_reference_world = T_reference_pivot @ inv(T_world_pivot)``; every station that stores a
    pose then has an expected ``T_reference_world @ T_world_station``. The pivot is the station
    with which the most stations agree (within ``max_deg`` and ``max_m``), so one wrong stored
    pose does not condemn the others.

    Parameters
    ----------
    poses : dict of str -> (4, 4) float64
        ``T_reference_station`` of the placed stations.
    stored : dict of str -> (4, 4) float64
        ``T_world_station`` of the stations whose files store a pose.
    max_deg : float, degrees
    max_m : float, metres

    Returns
    -------
    dict of str -> dict
        Per placed station that stores a pose: ``rotation_deg``, ``translation_m`` (its
        disagreement), ``agrees`` (bool; None for the pivot when no other station agrees
        with it: tied on itself, it is neither flagged nor confirmed) and ``pivot`` (the
        station the frames were tied by).
        Empty when fewer than two placed stations store a pose (nothing to compare).
    """
    common = sorted(s for s in poses if s in stored)
    if len(common) < 2:
        return {}
    best: tuple[int, float, str, dict[str, dict[str, float]]] | None = None
    for pivot in common:
        T_ref_world = poses[pivot] @ invert(stored[pivot])
        dev = {s: deviation(poses[s], T_ref_world @ stored[s]) for s in common}
        ok = [d for d in dev.values() if _within(d, max_deg, max_m)]
        spread = float(sum(d["translation_m"] for d in ok))
        if best is None or (len(ok), -spread) > (best[0], -best[1]):
            best = (len(ok), spread, pivot, dev)
    assert best is not None
    agreeing, _, pivot, dev = best
    out: dict[str, dict[str, Any]] = {}
    for s, d in dev.items():
        agrees: bool | None = _within(d, max_deg, max_m) and agreeing >= 2
        if s == pivot and agreeing < 2:
            agrees = None  # tied on itself: it neither agrees nor disagrees with anything
        out[s] = {**d, "agrees": agrees, "pivot": pivot}
    return out


__all__ = ["check_stations", "deviation", "stored_T_target_source"]
