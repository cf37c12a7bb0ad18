"""Point correspondences between sensors: :class:`Correspondences2D3D` (camera pixel <-> lidar
point), the input of camera-lidar calibration (:mod:`flexreg.calibration`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.errors import InputError

__all__ = ["Correspondences2D3D"]


@dataclass(frozen=True, eq=False)
class Correspondences2D3D:
    """Pairs of a camera pixel and a lidar point.

    Attributes
    ----------
    pixels : (N, 2) float64, pixels
        ``(u, v)`` in the camera image (distorted, as the camera took it).
    points : (N, 3) float64, metres
        The same feature's point in the lidar frame.
    lines : (N,) int64
        Line of each pair in its CSV file (1-based); 0 for pairs not read from a file
        (automatic proposals).
    source : str or None
        The CSV file, for messages.

    Examples
    --------
    >>> c = Correspondences2D3D([[10.0, 20.0], [30.0, 40.0]], [[0, 0, 5.0], [1, 0, 5.0]])
    >>> len(c), c.lines.tolist(), c.where(1)
    (2, [0, 0], 'pair 2')
    """

    pixels: NDArray[np.float64]
    points: NDArray[np.float64]
    lines: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    source: str | None = None

    def __post_init__(self) -> None:
        px = np.asarray(self.pixels, dtype=np.float64).reshape(-1, 2)
        pt = np.asarray(self.points, dtype=np.float64).reshape(-1, 3)
        if len(px) != len(pt):
            raise InputError(
                self.source or "correspondences", f"{len(px)} pixels but {len(pt)} points"
            )
        if not (np.isfinite(px).all() and np.isfinite(pt).all()):
            raise InputError(self.source or "correspondences", "NaN or Inf in pixels or points")
        ln = np.asarray(self.lines, dtype=np.int64).reshape(-1)
        if ln.size == 0:
            ln = np.zeros(len(px), dtype=np.int64)
        if len(ln) != len(px):
            raise InputError(self.source or "correspondences", "one line number per pair needed")
        object.__setattr__(self, "pixels", px)
        object.__setattr__(self, "points", pt)
        object.__setattr__(self, "lines", ln)

    def __len__(self) -> int:
        return len(self.pixels)

    def __repr__(self) -> str:
        src = f" from {self.source}" if self.source else ""
        return f"Correspondences2D3D({len(self)} pairs{src})"

    def subset(self, mask: ArrayLike) -> Correspondences2D3D:
        """The pairs selected by a boolean mask or index array."""
        m = np.asarray(mask)
        return Correspondences2D3D(self.pixels[m], self.points[m], self.lines[m], self.source)

    def concat(self, other: Correspondences2D3D) -> Correspondences2D3D:
        """These pairs followed by ``other``'s (source kept from ``self``)."""
        return Correspondences2D3D(
            np.concatenate([self.pixels, other.pixels]),
            np.concatenate([self.points, other.points]),
            np.concatenate([self.lines, other.lines]),
            self.source or other.source,
        )

    def where(self, i: int) -> str:
        """Where pair ``i`` came from: ``"line 12"`` or ``"pair 3"``."""
        return f"line {self.lines[i]}" if self.lines[i] > 0 else f"pair {i + 1}"
