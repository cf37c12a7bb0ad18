"""The :class:`Scan` container: points in the scanner frame plus what the sensor told us."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, overload

import numpy as np
from numpy.typing import NDArray

from flexreg.core.budget import check_memory
from flexreg.core.transforms import as_transform
from flexreg.errors import InputError

if TYPE_CHECKING:
    from flexreg.core.camera import Camera

#: memory per grid cell of the images a gridded scan becomes (xyz float32, range, index, valid,
#: intensity, feature image and its working copies), bytes: what the budget is checked against
GRID_CELL_BYTES = 64
#: memory per point while a scan is read and used (float64 xyz, attributes, working copies)
POINT_BYTES = 64
#: largest |coordinate| a reader may store in float32, metres: float32 keeps about 0.5 mm there
#: (a relative step of 6e-8), below a terrestrial scanner's noise; farther (project or map
#: coordinates) points stay float64
FLOAT32_MAX_M = 8192.0
#: farthest coordinate a measured point may have, metres: beyond any geodetic frame (ECEF,
#: UTM northing), so a larger one is a corrupt file or a unit error (1e30 from a broken export)
MAX_COORDINATE_M = 1e8


@dataclass(eq=False)
class Scan:
    """One scan: points in the scanner's own frame, optional per-point attributes and grid.

    Attributes
    ----------
    points : (N, 3) float32 or float64, metres
        Valid returns only, in the scanner frame. No-return cells are not points. Float32
        points are kept as float32 (the scanner-frame readers store them so: half the memory,
        about 0.5 mm or better within :data:`FLOAT32_MAX_M`); any other type becomes float64.
        Stages that sum or solve (SVD, ICP's normal equations, transforms) do so in float64.
    intensity : (N,) float32 or None
        Return intensity as the file stores it (PTX 0..1, E57/LAS native units).
    colors : (N, 3) uint8 or None
        RGB colour per point.
    grid_shape : (int, int) or None
        ``(rows, cols)`` of the scanner's native grid, if the format has one.
    grid_index : (N, 2) int32 or None
        ``(row, col)`` of each point in that grid; required when ``grid_shape`` is set.
    T_world_scanner : (4, 4) float64
        Sensor pose: maps scanner-frame points into the file's world/registered frame.
        Normally rigid; an affine matrix from a file (e.g. a scaled PTX transform) is kept
        as given.
    camera : Camera or None
        Projection model the grid was made with, when it is known exactly (depth images,
        synthetic stations). ``None`` for native grids whose geometry is only implied.
    path : Path or None
        File the scan came from.
    name : str
        Scan name (file stem, E57 scan name, ``"cloud 2"`` for the third PTX cloud...).
    """

    points: NDArray[np.floating]
    intensity: NDArray[np.float32] | None = None
    colors: NDArray[np.uint8] | None = None
    grid_shape: tuple[int, int] | None = None
    grid_index: NDArray[np.int32] | None = None
    T_world_scanner: NDArray[np.float64] = field(default_factory=lambda: np.eye(4))
    camera: Camera | None = None
    path: Path | None = None
    name: str = ""

    def __post_init__(self) -> None:
        src = self.path if self.path is not None else (self.name or "scan")
        pts = np.asarray(self.points)
        pts = np.ascontiguousarray(pts, dtype=np.float32 if pts.dtype == np.float32 else np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise InputError(src, f"points must have shape (N, 3), got {pts.shape}")
        lo, hi = (float(pts.min()), float(pts.max())) if pts.size else (0.0, 0.0)
        if not (np.isfinite(lo) and np.isfinite(hi)):  # min and max propagate NaN and Inf
            bad = int(np.count_nonzero(~np.isfinite(pts).all(axis=1)))
            raise InputError(src, f"{bad} point(s) have NaN or Inf coordinates")
        if max(-lo, hi) > MAX_COORDINATE_M:
            far = int(np.count_nonzero((np.abs(pts) > MAX_COORDINATE_M).any(axis=1)))
            raise InputError(
                src,
                f"{far} point(s) lie beyond {MAX_COORDINATE_M:g} m of the origin (largest "
                f"|coordinate| {max(-lo, hi):.3g} m): not measured "
                "points (a corrupt file, or a unit error?)",
            )
        self.points = pts
        n = len(pts)
        if self.intensity is not None:
            self.intensity = np.ascontiguousarray(self.intensity, dtype=np.float32).reshape(-1)
            if len(self.intensity) != n:
                raise InputError(src, f"{len(self.intensity)} intensities for {n} points")
        if self.colors is not None:
            self.colors = np.ascontiguousarray(self.colors, dtype=np.uint8)
            if self.colors.shape != (n, 3):
                raise InputError(src, f"colors must have shape ({n}, 3), got {self.colors.shape}")
        if (self.grid_shape is None) != (self.grid_index is None):
            raise InputError(src, "grid_shape and grid_index must be given together")
        if self.grid_shape is not None and self.grid_index is not None:
            rows, cols = (int(v) for v in self.grid_shape)
            if rows <= 0 or cols <= 0:
                raise InputError(src, f"grid shape must be positive, got {rows} x {cols}")
            self.grid_shape = (rows, cols)
            check_memory(rows * cols * GRID_CELL_BYTES, f"its {rows} x {cols} grid", source=src)
            gi = np.ascontiguousarray(self.grid_index, dtype=np.int32)
            if gi.shape != (n, 2):
                raise InputError(src, f"grid_index must have shape ({n}, 2), got {gi.shape}")
            if n and (gi.min() < 0 or gi[:, 0].max() >= rows or gi[:, 1].max() >= cols):
                raise InputError(src, f"grid index outside the {rows} x {cols} grid")
            self.grid_index = gi
        self.T_world_scanner = as_transform(self.T_world_scanner, name=f"{src} pose", rigid=False)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_organized(
        cls,
        xyz: NDArray[np.floating],
        valid: NDArray[np.bool_] | None = None,
        *,
        intensity: NDArray[np.floating] | None = None,
        colors: NDArray[np.uint8] | None = None,
        **kwargs: Any,
    ) -> Scan:
        """Build a scan from an organised (H, W, 3) array.

        Parameters
        ----------
        xyz : (H, W, 3) float, metres
            Organised points; cells that are NaN/Inf, or all zero, or ``~valid`` are no-returns.
        valid : (H, W) bool, optional
            Explicit validity mask, combined with the finiteness test.
        intensity : (H, W) float, optional
        colors : (H, W, 3) uint8, optional
        **kwargs
            Passed to :class:`Scan` (pose, camera, path, name).
        """
        xyz = np.asarray(xyz)
        if xyz.ndim != 3 or xyz.shape[2] != 3:
            raise InputError(
                str(kwargs.get("path", "scan")), f"organised xyz must be (H, W, 3), got {xyz.shape}"
            )
        ok = np.isfinite(xyz).all(axis=2) & np.any(xyz != 0, axis=2)
        if valid is not None:
            ok &= np.asarray(valid, dtype=bool)
        rows, cols = np.nonzero(ok)
        gi = np.stack([rows, cols], axis=1).astype(np.int32)
        return cls(
            points=xyz[ok],
            intensity=None if intensity is None else np.asarray(intensity)[ok],
            colors=None if colors is None else np.asarray(colors)[ok],
            grid_shape=(xyz.shape[0], xyz.shape[1]),
            grid_index=gi,
            **kwargs,
        )

    # ------------------------------------------------------------------ views
    def __len__(self) -> int:
        return len(self.points)

    def __repr__(self) -> str:
        grid = (
            "no grid"
            if self.grid_shape is None
            else f"grid {self.grid_shape[0]}x{self.grid_shape[1]}"
        )
        return f"Scan({self.name!r}, {len(self)} points, {grid})"

    @property
    def has_grid(self) -> bool:
        """True if the scan carries a native (row, col) grid."""
        return self.grid_shape is not None

    def organized(self) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """Return the native grid as ``(xyz (H, W, 3) float64 with NaN holes, valid (H, W) bool)``.

        Raises
        ------
        InputError
            If the scan has no grid.
        """
        if self.grid_shape is None or self.grid_index is None:
            raise InputError(self.path or self.name, "scan has no native grid")
        rows, cols = self.grid_shape
        xyz = np.full((rows, cols, 3), np.nan)
        valid = np.zeros((rows, cols), dtype=bool)
        r, c = self.grid_index[:, 0], self.grid_index[:, 1]
        xyz[r, c] = self.points
        valid[r, c] = True
        return xyz, valid

    def points_world(self) -> NDArray[np.float64]:
        """Points mapped into the world frame with ``T_world_scanner``, (N, 3) float64."""
        T = self.T_world_scanner
        return self.points @ T[:3, :3].T + T[:3, 3]


@overload
def as_points(
    x: Any, *, name: str = ..., keep_float32: Literal[False] = ...
) -> NDArray[np.float64]: ...
@overload
def as_points(x: Any, *, name: str = ..., keep_float32: bool) -> NDArray[np.floating]: ...
def as_points(x: Any, *, name: str = "points", keep_float32: bool = False) -> NDArray[np.floating]:
    """(N, 3) float64 points of a :class:`Scan`, a
    :class:`~flexreg.core.range_image.RangeImage` (its valid pixels) or an array, in metres.

    Parameters
    ----------
    x : Scan, RangeImage or (N, 3) array_like
    name : str
        What to call ``x`` in error messages.
    keep_float32 : bool
        Return float32 points as they are (no float64 copy of a whole cloud); other types
        still become float64.

    Raises
    ------
    InputError
        Not (N, 3), non-finite values, or fewer than 3 points.
    """
    if isinstance(x, Scan):
        P = x.points
    elif hasattr(x, "xyz") and hasattr(x, "valid"):  # a RangeImage (which imports this module)
        P = x.xyz[x.valid]
    else:
        P = np.asarray(x)
    if P.ndim != 2 or P.shape[1] != 3:
        raise InputError(name, f"points must have shape (N, 3), got {P.shape}")
    dtype = np.float32 if keep_float32 and P.dtype == np.float32 else np.float64
    P = np.ascontiguousarray(P, dtype=dtype)
    if len(P) and not (np.isfinite(P.min()) and np.isfinite(P.max())):
        raise InputError(name, "points hold NaN or Inf")
    if len(P) < 3:
        raise InputError(name, f"need at least 3 points, got {len(P)}")
    return P
