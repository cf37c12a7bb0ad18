"""The one overlap figure of a registered pair, with Open3D's fitness and inlier RMSE beside it.

``register``, ``compare`` and ``survey`` all state the overlap of a transform the same way:

    overlap = share of the source points, mapped by ``T_target_source``, that have a target
    point within ``d`` -- both clouds voxelised at ``v`` (one centroid per occupied voxel,
    Open3D's ``voxel_down_sample``), ``d = v`` unless given; the denominator is the number of
    voxelised source points. ``rmse_m`` is the RMS distance of those points to their nearest
    target point.

The voxelisation is :func:`~flexreg.stages.sampling.voxel_centroids` (Open3D's voxels and
centroids, computed without copying the clouds into Open3D).
``v`` is the scale voxel (:func:`scale_voxel`: twice the target's median point spacing,
enlarged until the voxelised target keeps at most 20,000 points), the same voxel the baselines
and ``compare`` use, so the figure depends only on the two clouds and the transform. This is
what Open3D's ``evaluate_registration`` calls ``fitness`` and ``inlier_rmse`` on the same clouds
at the same distance; both are computed -- ours with SciPy's exact k-d tree, Open3D's by its own
call -- and reported side by side under Open3D's names (``open3d_fitness``,
``open3d_inlier_rmse_m``), so that a reader can check one against the other. Open3D's call
needs Open3D loaded (0.2 GB and 0.6 s of a process that had no other use for it): with
``open3d_check=False`` its two figures are None.

Keypoint *inliers* are another thing: the share of matched keypoint pairs that RANSAC kept,
reported as such and never as an overlap.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from flexreg.core.kept import Kept, digest
from flexreg.core.results import Overlap
from flexreg.errors import ConfigError, RegistrationError
from flexreg.stages.sampling import median_spacing, thin, to_open3d, voxel_centroids, voxel_count

__all__ = [
    "KEEP_ARRAYS",
    "KEEP_CLOUDS",
    "MAX_INPUT_POINTS",
    "SCALE_MAX_POINTS",
    "SPACINGS_PER_VOXEL",
    "Overlap",
    "OverlapMeter",
    "keep_overlap_inputs",
    "measure_overlap",
    "scale_voxel",
]

#: default point budget of the scale voxel: it is enlarged until the voxelised target keeps at
#: most this many points
SCALE_MAX_POINTS = 20_000
#: the scale voxel in median point spacings of the target (before the point budget applies)
SPACINGS_PER_VOXEL = 2.0
#: at most this many points of each cloud (every k-th) are voxelised: voxels of the scale size
#: hold many points of a large scan, so the voxel centroids hardly change
MAX_INPUT_POINTS = 4_000_000
#: clouds whose scale voxel is kept, by content: a survey station takes part in a dozen
#: links, and its scale voxel (median spacing and voxel counts, 0.1-0.2 s at 2 M points) was
#: found again for each; a kept cloud costs a digest of its points instead (about 0.01 s per
#: million points)
KEEP_CLOUDS = 256
#: voxel centroids and k-d trees kept, by cloud content and voxel (up to about 1 MB each)
KEEP_ARRAYS = 32
_KEPT: Kept[tuple[float, str]] = Kept(KEEP_CLOUDS)
_KEPT_ARRAYS: Kept[Any] = Kept(KEEP_ARRAYS)


def _kept(key: tuple[Any, ...], make: Any, arrays: bool = False) -> Any:
    """``make()``, kept under ``key`` (the last :data:`KEEP_CLOUDS` scale voxels, the last
    :data:`KEEP_ARRAYS` centroids and trees)."""
    if arrays:
        return _KEPT_ARRAYS.get(key, make, KEEP_ARRAYS)
    return _KEPT.get(key, make, KEEP_CLOUDS)


def scale_voxel(
    target: NDArray[np.floating], *, max_points: int = SCALE_MAX_POINTS
) -> tuple[float, str]:
    """The scale parameter from the scan resolution: ``(voxel_m, how)``.

    ``SPACINGS_PER_VOXEL`` (2) times the target's median nearest-neighbour spacing
    (:func:`flexreg.stages.sampling.median_spacing`), enlarged until the voxel-downsampled
    target keeps at most ``max_points`` points. Deterministic (fixed subsample seeds). The
    last :data:`KEEP_CLOUDS` clouds' voxels are kept by content (a survey station is the
    target of several links): the same points give the same voxel without the search.

    Parameters
    ----------
    target : (N, 3) float32 or float64, metres
    max_points : int
        Point budget after downsampling.

    Returns
    -------
    voxel_m : float, metres
    how : str
        Which rule set the value (for the record).

    Raises
    ------
    ConfigError
        ``max_points`` below 100.
    RegistrationError
        The target's points coincide.
    """
    if max_points < 100:
        raise ConfigError(f"max_points must be at least 100, got {max_points}")
    return _scale_voxel_of(target, digest(target), max_points)


def _scale_voxel_of(
    target: NDArray[np.floating], content: bytes, max_points: int
) -> tuple[float, str]:
    """:func:`scale_voxel` of a cloud whose :func:`~flexreg.core.kept.digest` is ``content``
    (kept by it)."""
    key = ("scale voxel", content, max_points)
    return _kept(key, lambda: _find_scale_voxel(target, max_points))


def _find_scale_voxel(target: NDArray[np.floating], max_points: int) -> tuple[float, str]:
    spacing = median_spacing(target, tree_points=200_000)
    if not spacing > 0:
        raise RegistrationError("cannot derive a voxel size: the target's points coincide")
    voxel = SPACINGS_PER_VOXEL * spacing
    how = f"{SPACINGS_PER_VOXEL:g} x median spacing {spacing:.4g} m"
    base = thin(target, 2_000_000)
    n = voxel_count(base, voxel)
    for _ in range(12):  # the count falls roughly with the square of the voxel (surfaces)
        if n <= max_points:
            break
        voxel *= 1.05 * math.sqrt(n / max_points)
        n = voxel_count(base, voxel)
        how = f"enlarged until at most {max_points:,} target points remain"
    return float(voxel), how


class OverlapMeter:
    """The overlap of any number of transforms of one pair (voxelised and indexed once).

    Parameters
    ----------
    target, source : (N, 3) float32 or float64, metres
        Each in its own frame.
    voxel_m : float, optional, metres
        The voxel (default :func:`scale_voxel` of the target; both clouds' voxel centroids
        and the target's k-d tree are then kept by content with it).
    distance_m : float, optional, metres
        Inlier distance (default ``voxel_m``).
    open3d_check : bool
        Also compute Open3D's ``evaluate_registration`` on the same clouds (loads Open3D);
        else ``open3d_fitness`` and ``open3d_inlier_rmse_m`` are None.

    Examples
    --------
    >>> g = np.stack(np.meshgrid(np.arange(20.0), np.arange(20.0), [0.0]), -1).reshape(-1, 3)
    >>> meter = OverlapMeter(g, g + [10.0, 0.0, 0.0], voxel_m=1.0)
    >>> T = np.eye(4); T[0, 3] = -10.0
    >>> round(meter(T).share, 3), round(meter(np.eye(4)).share, 3)
    (1.0, 0.5)
    """

    def __init__(
        self,
        target: NDArray[np.floating],
        source: NDArray[np.floating],
        *,
        voxel_m: float | None = None,
        distance_m: float | None = None,
        open3d_check: bool = True,
    ) -> None:
        content = None
        if voxel_m is None:
            content = digest(target)
            voxel_m, how = _scale_voxel_of(target, content, SCALE_MAX_POINTS)
        else:
            how = "given"
        distance_m = voxel_m if distance_m is None else distance_m
        for name, value in (("voxel", voxel_m), ("overlap distance", distance_m)):
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f"{name} must be a positive number of metres, got {value}")
        self.voxel_m, self.voxel_source, self.distance_m = float(voxel_m), how, float(distance_m)
        if content is None:
            self.target_points = _centroids(target, voxel_m)
            self.source_points = _centroids(source, voxel_m)
            self._tree = cKDTree(self.target_points)
        else:  # the scale voxel's centroids and tree, kept by content (see keep_overlap_inputs)
            v = float(voxel_m)
            self.target_points = _kept(
                ("centroids", content, v), lambda: _centroids(target, v), arrays=True
            )
            self.source_points = _kept(
                ("centroids", digest(source), v), lambda: _centroids(source, v), arrays=True
            )
            pts = self.target_points
            self._tree = _kept(("tree", content, v), lambda: cKDTree(pts), arrays=True)
        self._open3d = (
            (to_open3d(self.source_points), to_open3d(self.target_points)) if open3d_check else None
        )

    def distances(self, T: NDArray[np.float64]) -> NDArray[np.float64]:
        """(M,) float64, metres: each voxelised source point mapped by ``T`` to its nearest
        voxelised target point, however far."""
        q = self.source_points @ T[:3, :3].T + T[:3, 3]
        d, _ = self._tree.query(q)
        return np.asarray(d, dtype=np.float64)

    def __call__(self, T: NDArray[np.float64]) -> Overlap:
        """The :class:`Overlap` of ``T_target_source``."""
        T = np.asarray(T, dtype=np.float64)
        q = self.source_points @ T[:3, :3].T + T[:3, 3]
        d, _ = self._tree.query(q, distance_upper_bound=self.distance_m)
        ok = np.isfinite(d)
        n = len(q)
        fitness = rmse = None
        if self._open3d is not None:
            import open3d as o3d  # heavy: loaded by to_open3d already

            ev = o3d.pipelines.registration.evaluate_registration(*self._open3d, self.distance_m, T)
            fitness = float(ev.fitness)
            rmse = float(ev.inlier_rmse) if ok.any() else math.nan
        return Overlap(
            share=float(ok.sum() / n) if n else 0.0,
            rmse_m=float(np.sqrt(np.mean(d[ok] ** 2))) if ok.any() else math.nan,
            source_points=n,
            target_points=len(self.target_points),
            distance_m=self.distance_m,
            voxel_m=self.voxel_m,
            voxel_source=self.voxel_source,
            open3d_fitness=fitness,
            open3d_inlier_rmse_m=rmse,
        )


def _centroids(points: NDArray[np.floating], voxel_m: float) -> NDArray[np.float64]:
    """The voxel centroids of a cloud (every k-th point of a large one), read-only (they may
    be kept and shared)."""
    c = voxel_centroids(thin(points, MAX_INPUT_POINTS), voxel_m)
    c.flags.writeable = False
    return c


def keep_overlap_inputs(target: NDArray[np.floating], source: NDArray[np.floating]) -> None:
    """Compute ahead what :func:`measure_overlap` of these two clouds at the scale voxel needs
    whatever the transform, and keep it by content (:data:`KEEP_CLOUDS`, :data:`KEEP_ARRAYS`):
    the target's scale voxel, both clouds' voxel centroids and the target's k-d tree. A caller
    with a spare thread runs this beside other work; the later :func:`measure_overlap` of the
    same clouds (the same values, any arrays) then finds them, and gives exactly what it gives
    without them.

    Parameters
    ----------
    target, source : (N, 3) float32 or float64, metres

    Raises
    ------
    RegistrationError
        As :func:`scale_voxel` (the target's points coincide).
    """
    OverlapMeter(target, source, open3d_check=False)


def measure_overlap(
    target: NDArray[np.floating],
    source: NDArray[np.floating],
    T_target_source: NDArray[np.float64],
    *,
    voxel_m: float | None = None,
    distance_m: float | None = None,
    open3d_check: bool = True,
) -> Overlap:
    """The :class:`Overlap` of one transform (:class:`OverlapMeter` for several).

    Parameters
    ----------
    target, source : (N, 3) float32 or float64, metres
    T_target_source : (4, 4) float64
    voxel_m, distance_m : float, optional, metres
    open3d_check : bool
        See :class:`OverlapMeter`.
    """
    meter = OverlapMeter(
        target, source, voxel_m=voxel_m, distance_m=distance_m, open3d_check=open3d_check
    )
    return meter(T_target_source)
