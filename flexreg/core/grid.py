"""Pixel-grid helpers shared by every kernel that walks a range image's neighbourhoods."""

from __future__ import annotations

import numba

__all__ = ["wrap_col"]


@numba.njit(cache=True, nogil=True, inline="always")
def wrap_col(j: int, W: int, wrap: bool) -> int:  # pragma: no cover - compiled
    """Column ``j`` wrapped into ``[0, W)`` for a wrapping image (a full-turn panorama whose
    first and last columns are neighbours), else -1 when outside.

    >>> wrap_col(-1, 8, True), wrap_col(8, 8, True), wrap_col(8, 8, False), wrap_col(3, 8, False)
    (7, 0, -1, 3)
    """
    if 0 <= j < W:
        return j
    if wrap:
        j = j % W
        return j
    return -1
