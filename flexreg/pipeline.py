"""``register(target, source, config)``: the whole chain from two scans to ``T_target_source``.

Stages (each public and usable alone): range image (:mod:`flexreg.projection`) -> feature image
(:func:`feature_image`) -> keypoints and descriptors (:func:`flexreg.features.detect_and_describe`)
-> matches (:func:`flexreg.matching.match`) -> 3D correspondences
(:func:`flexreg.correspondences.lift`) -> consistency pruning and RANSAC
(:mod:`flexreg.alignment`) -> ICP refinement (:func:`flexreg.refine.refine_icp`).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .alignment import consistent_subset, ransac_rigid, squared_residuals
from .correspondences import lift
from .errors import DegenerateGeometryError, RegistrationError
from .features import Features, detect_and_describe
from .matching import match
from .projection import RangeImage, range_image
from .scan import Scan

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RegistrationConfig:
    """Every knob of :func:`register`; saved with each result.

    Attributes
    ----------
    image : str
        Feature image kind (see :data:`flexreg.images.KINDS`), or ``"intensity"``.
    n : int
        Flexion / Bearing Angle neighbourhood size (odd).
    median : int
        Median pre-filter window (0, 3 or 5).
    stretch : str or None
        Contrast normalisation before detection: ``"clahe"``, ``"percentile"`` or None.
    features : str
        Detector/descriptor: sift, orb, akaze, kaze, brisk (surf on nonfree OpenCV).
    max_features : int
        Strongest keypoints kept per image.
    ratio : float
        Lowe's ratio-test threshold.
    mutual : bool
        Mutual nearest-neighbour check.
    threshold_m : float or None
        RANSAC inlier distance; derived from the scans' pixel footprint when None.
    threshold_px : float
        Derived threshold in pixel footprints (keypoint localisation error).
    consistency : bool
        Prune correspondences by pairwise-distance consistency before RANSAC.
    min_inliers : int
        Fewer RANSAC inliers raise :class:`RegistrationError`.
    confidence, max_iterations : float, int
        RANSAC stopping.
    refine : bool
        Refine with ICP.
    icp : str
        ``"point-to-plane"``, ``"gicp"`` or ``"point-to-point"``.
    voxel_m : float or None
        ICP voxel; derived from point spacing when None.
    seed : int
        Randomness (RANSAC sampling); same seed, same transform.
    """

    image: str = "flexion"
    n: int = 5
    median: int = 3
    stretch: str | None = "clahe"
    features: str = "sift"
    max_features: int = 8000
    ratio: float = 0.85
    mutual: bool = True
    threshold_m: float | None = None
    threshold_px: float = 3.0
    consistency: bool = True
    min_inliers: int = 10
    confidence: float = 0.9999
    max_iterations: int = 50_000
    refine: bool = True
    icp: str = "point-to-plane"
    voxel_m: float | None = None
    seed: int = 0

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(eq=False)
class RegistrationResult:
    """What :func:`register` found.

    Attributes
    ----------
    T_target_source : (4, 4) float64
        Final transform (refined when ``config.refine``).
    T_coarse : (4, 4) float64
        The RANSAC transform before refinement.
    matches : int
        Putative 2D matches lifted to 3D.
    inliers : int
        RANSAC inliers among them.
    inlier_rmse_m : float
        RMSE of the final stage's inliers (ICP when refined, else RANSAC), metres.
    fitness : float
        Final-stage overlap: ICP fitness (fraction of downsampled source points with a target
        point within the ICP distance) or, unrefined, inliers / matches.
    fitness_denominator : str
        What ``fitness`` divides by.
    information : (6, 6) float64
        Information matrix (rotation, translation) for pose graphs.
    timings_s : dict
        Seconds per stage.
    threshold_m : float
        RANSAC inlier threshold used.
    config : RegistrationConfig
    correspondences : (Q, 2, 3) float64
        Lifted ``[target point, source point]`` pairs (RANSAC input).
    inlier_mask : (Q,) bool
    keypoints : tuple of (K, 2) arrays
        Target and source keypoint positions of the lifted matches (for drawing).
    """

    T_target_source: NDArray[np.float64]
    T_coarse: NDArray[np.float64]
    matches: int
    inliers: int
    inlier_rmse_m: float
    fitness: float
    fitness_denominator: str
    information: NDArray[np.float64]
    timings_s: dict[str, float]
    threshold_m: float
    config: RegistrationConfig
    correspondences: NDArray[np.float64] = field(repr=False)
    inlier_mask: NDArray[np.bool_] = field(repr=False)
    keypoints: tuple[NDArray[np.float64], NDArray[np.float64]] = field(repr=False)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (no per-match arrays)."""
        return {
            "T_target_source": self.T_target_source.tolist(),
            "T_coarse": self.T_coarse.tolist(),
            "matches": self.matches,
            "inliers": self.inliers,
            "inlier_rmse_m": self.inlier_rmse_m,
            "fitness": self.fitness,
            "fitness_denominator": self.fitness_denominator,
            "information": self.information.tolist(),
            "threshold_m": self.threshold_m,
            "timings_s": self.timings_s,
            "seed": self.config.seed,
            "config": self.config.to_dict(),
        }


# ------------------------------------------------------------------------------ stages


def feature_image(
    image: RangeImage, config: RegistrationConfig = RegistrationConfig()
) -> tuple[NDArray[np.uint8], NDArray[np.bool_]]:
    """The 8-bit image features are detected on, and its valid mask.

    Flexion (or another conversion) of the range image, contrast-normalised as configured;
    ``"intensity"`` uses the scan's intensity instead.
    """
    from . import images

    if config.image == "intensity":
        if image.intensity is None:
            raise RegistrationError("the scan has no intensity for an intensity feature image")
        val = image.intensity.astype(np.float64)
        lo, hi = np.nanpercentile(val, [1, 99])
        f = ((val - lo) / max(hi - lo, 1e-12)).astype(np.float32)
        f[~image.valid] = np.nan
    else:
        f = images.convert(image, config.image, n=config.n, median=config.median)
    mask = np.isfinite(f)
    q, qmask = images.quantize(
        f,
        bits=8,
        value_range=images.value_range(config.image, f) if config.image != "intensity" else (0, 1),
        stretch=config.stretch,  # type: ignore[arg-type]
    )
    return np.asarray(q, dtype=np.uint8), mask & np.asarray(qmask, dtype=bool)


def pixel_footprint(image: RangeImage) -> NDArray[np.float32]:
    """(H, W) metric size of each pixel: the smaller of its horizontal and vertical
    neighbour distances (NaN where unknown). Used to derive thresholds from resolution."""
    xyz = image.xyz
    dh = np.full(image.shape, np.nan, dtype=np.float32)
    dv = np.full(image.shape, np.nan, dtype=np.float32)
    nxt = (
        np.roll(xyz, -1, axis=1)
        if image.wraps
        else np.pad(xyz, ((0, 0), (0, 1), (0, 0)), constant_values=np.nan)[:, 1:]
    )
    dh[:] = np.linalg.norm(nxt - xyz, axis=2)
    dv[:-1] = np.linalg.norm(xyz[1:] - xyz[:-1], axis=2)
    with np.errstate(invalid="ignore"):
        return np.fmin(dh, dv)


@contextmanager
def _timed(timings: dict[str, float], name: str) -> Iterator[None]:
    t = time.perf_counter()
    yield
    timings[name] = timings.get(name, 0.0) + time.perf_counter() - t


def _as_image(x: Scan | RangeImage) -> RangeImage:
    return x if isinstance(x, RangeImage) else range_image(x)


def _points(x: Scan | RangeImage) -> NDArray[np.float64]:
    return x.points if isinstance(x, Scan) else x.xyz[x.valid]


def _information_from_points(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """Information matrix of point correspondences (Open3D's convention: rotation first)."""
    info = np.zeros((6, 6))
    for x, y, z in points:
        G = np.array(
            [[0, z, -y, 1, 0, 0], [-z, 0, x, 0, 1, 0], [y, -x, 0, 0, 0, 1]], dtype=np.float64
        )
        info += G.T @ G
    return info


def register(
    target: Scan | RangeImage,
    source: Scan | RangeImage,
    config: RegistrationConfig = RegistrationConfig(),
    *,
    progress: Callable[[str], None] | None = None,
) -> RegistrationResult:
    """Register ``source`` onto ``target``: returns ``T_target_source``.

    Parameters
    ----------
    target, source : Scan or RangeImage
        Scans in their own scanner frames (a gridded scan keeps its native grid).
    config : RegistrationConfig
    progress : callable, optional
        Called with the name of each stage as it starts.

    Raises
    ------
    RegistrationError
        Too few matches or inliers, degenerate (collinear) inliers, or ICP without overlap;
        the message gives the counts. No transform is returned then.
    """
    timings: dict[str, float] = {}

    def stage(name: str) -> Any:
        if progress is not None:
            progress(name)
        return _timed(timings, name)

    with stage("range images"):
        ti, si = _as_image(target), _as_image(source)
    with stage("feature images"):
        fti, mt = feature_image(ti, config)
        fsi, ms = feature_image(si, config)
    with stage("features"):
        ft = detect_and_describe(
            fti, config.features, mt, max_features=config.max_features, wrap=ti.wraps
        )
        fs = detect_and_describe(
            fsi, config.features, ms, max_features=config.max_features, wrap=si.wraps
        )
    with stage("matching"):
        pairs = match(ft, fs, ratio=config.ratio, mutual=config.mutual)
    with stage("lifting"):
        pt, okt = lift(ti, ft.xy[pairs[:, 0]])
        ps, oks = lift(si, fs.xy[pairs[:, 1]])
        ok = okt & oks
        pt, ps, pairs = pt[ok], ps[ok], pairs[ok]
    log.info("%d/%d keypoints, %d matches lifted", len(ft), len(fs), len(pairs))
    if len(pairs) < max(3, config.min_inliers):
        raise RegistrationError(
            f"only {len(pairs)} lifted matches ({len(ft)} target / {len(fs)} source keypoints); "
            f"need at least {max(3, config.min_inliers)}"
        )
    with stage("estimation"):
        if config.threshold_m is not None:
            thr = float(config.threshold_m)
        else:
            fp_t = pixel_footprint(ti)
            fp_s = pixel_footprint(si)
            xt = np.clip(np.rint(ft.xy[pairs[:, 0]]).astype(int), 0, [ti.width - 1, ti.height - 1])
            xs = np.clip(np.rint(fs.xy[pairs[:, 1]]).astype(int), 0, [si.width - 1, si.height - 1])
            f = np.r_[fp_t[xt[:, 1], xt[:, 0]], fp_s[xs[:, 1], xs[:, 0]]]
            thr = float(config.threshold_px * np.nanmedian(f)) if np.isfinite(f).any() else 0.05
            thr = max(thr, 0.005)
        idx = np.arange(len(pairs))
        if config.consistency:
            idx = consistent_subset(pt, ps, threshold_m=2 * thr, relative=0.01)
            if len(idx) < max(3, config.min_inliers):
                raise RegistrationError(
                    f"only {len(idx)} of {len(pairs)} matches are mutually consistent "
                    f"(threshold {thr:.3g} m); need {max(3, config.min_inliers)}"
                )
        try:
            rr = ransac_rigid(
                pt[idx],
                ps[idx],
                threshold_m=thr,
                confidence=config.confidence,
                max_iterations=config.max_iterations,
                min_inliers=config.min_inliers,
                rng=config.seed,
            )
        except DegenerateGeometryError as e:
            raise RegistrationError(f"{e} ({len(pairs)} matches)") from None
        T = rr.T_target_source
        d2 = squared_residuals(T, pt, ps)
        inl = d2 < thr * thr
    T_coarse = T.copy()
    rmse = float(np.sqrt(d2[inl].mean()))
    fitness, denom = float(inl.sum() / len(pairs)), "lifted matches"
    info = _information_from_points(pt[inl])
    if config.refine:
        from .refine import refine_icp

        with stage("refinement"):
            icp = refine_icp(
                _points(target),
                _points(source),
                T,
                method=config.icp,  # type: ignore[arg-type]
                voxel_m=config.voxel_m,
            )
        T, rmse, fitness, info = (
            icp.T_target_source,
            icp.inlier_rmse_m,
            icp.fitness,
            icp.information,
        )
        denom = f"source points after {icp.voxel_m:.3g} m voxel downsampling"
    return RegistrationResult(
        T_target_source=T,
        T_coarse=T_coarse,
        matches=len(pairs),
        inliers=int(inl.sum()),
        inlier_rmse_m=rmse,
        fitness=fitness,
        fitness_denominator=denom,
        information=info,
        timings_s=timings,
        threshold_m=thr,
        config=config,
        correspondences=np.stack([pt, ps], axis=1),
        inlier_mask=inl,
        keypoints=(ft.xy[pairs[:, 0]], fs.xy[pairs[:, 1]]),
    )


__all__ = [
    "Features",
    "RegistrationConfig",
    "RegistrationResult",
    "feature_image",
    "pixel_footprint",
    "register",
]
