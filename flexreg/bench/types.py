"""What a benchmark run (``flexreg bench``) is made of: its configuration, its pairs and its
records."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import Field, field_validator

from flexreg.bench.compare import SuccessCriteria
from flexreg.bench.methods import DEFAULT_METHODS, parse_methods
from flexreg.config import Config

if TYPE_CHECKING:
    from flexreg.core.scan import Scan

__all__ = ["QUICK_REAL_PAIRS", "REAL_PAIRS", "SUITES", "BenchConfig", "BenchResult", "Case"]

SUITES = ("synthetic", "real", "all")

#: real pairs: name -> (folder, what the reference is)
REAL_PAIRS: dict[str, tuple[str, str]] = {
    "bunny bun000 <- bun045": ("bunny_range_scans_gt", "ground truth (bun.conf)"),
    "3DMatch ref <- src": ("reg_3dmatch_geotransformer_demo", "ground truth (gt.npy)"),
    "Velodyne 251370668 <- 251371071": (
        "lidar_pair_fast_gicp",
        "fast_gicp relative.txt (a registration; small_gicp's differs by 0.22° / 1.9 cm)",
    ),
    "Ouster frame 0 <- 1": ("lidar_ouster_os1_128_3scans", "SDK reference poses"),
    "Ouster frame 1 <- 2": ("lidar_ouster_os1_128_3scans", "SDK reference poses"),
    "3DTK scan000 <- scan001": ("tls_3dtk_kurt3d", "odometry prior (gross limits)"),
    "3DTK scan001 <- scan002": ("tls_3dtk_kurt3d", "odometry prior (gross limits)"),
    "3DTK scan000 <- scan002": ("tls_3dtk_kurt3d", "odometry prior (gross limits)"),
}
QUICK_REAL_PAIRS: tuple[str, ...] = ("bunny bun000 <- bun045", "Ouster frame 0 <- 1")

Bins = tuple[tuple[float, float], ...]
Resolution = tuple[int, int]


class BenchConfig(Config):
    """Everything a benchmark run depends on; written next to its results.

    Attributes
    ----------
    suite : {"synthetic", "real", "all"}
        Which pairs run: the synthetic station pairs, the real pairs with a reference, or both.
    quick : bool
        The short variant (fewer, smaller pairs; see :meth:`make`).
    methods : tuple of str
        Methods compared (see :func:`flexreg.bench.methods.parse_methods`).
    seed : int
        Seeds the synthetic pairs and every method's randomness.
    pairs : int
        Synthetic pairs.
    resolution : (int, int), pixels
        Synthetic station grid (width, height).
    distance_bins_m : tuple of (float, float), metres
        Station distance bins of the synthetic pairs (pair i takes bin i mod their number).
    yaw_bins_deg : tuple of (float, float), degrees
        Relative-yaw bins of the synthetic pairs (a Latin square with the distance bins).
    max_tilt_deg : float, degrees
        Largest tilt of each synthetic station, about a random horizontal axis.
    noise_mm : tuple of float, millimetres
        Range noise sigma, cycled over the pairs.
    min_overlap : float
        Mutual visibility overlap of the stations (0..1).
    sweep_resolutions : tuple of (int, int), pixels
        Resolutions of the time / memory sweep (empty: no sweep).
    real_pairs : tuple of str
        Names of the real pairs to run (see :data:`REAL_PAIRS`).
    timeout_s : float, seconds
        Time limit per method and pair.
    criteria : SuccessCriteria
        Success limits of the synthetic pairs (the real pairs state their own).
    data_dir : str
        Folder of the real data.
    """

    suite: Literal["synthetic", "real", "all"] = "all"
    quick: bool = False
    methods: tuple[str, ...] = DEFAULT_METHODS
    seed: int = Field(0, ge=0, strict=True)
    pairs: int = Field(16, ge=1)
    resolution: Resolution = (1024, 512)
    distance_bins_m: Bins = Field(((1, 4), (4, 8), (8, 12), (12, 15)), min_length=1)
    yaw_bins_deg: Bins = Field(((0, 45), (45, 90), (90, 135), (135, 180)), min_length=1)
    max_tilt_deg: float = Field(5.0, ge=0, le=30)
    noise_mm: tuple[float, ...] = Field((1.0, 3.0, 6.0), min_length=1)
    min_overlap: float = Field(0.3, ge=0, lt=1)
    sweep_resolutions: tuple[Resolution, ...] = (
        (1024, 512),
        (2048, 1024),
        (4096, 2048),
        (8192, 4096),
    )
    real_pairs: tuple[str, ...] = ()
    timeout_s: float = Field(300.0, gt=0, allow_inf_nan=False)
    criteria: SuccessCriteria = SuccessCriteria()
    data_dir: str = "../shared/data"

    @field_validator("methods")
    @classmethod
    def _known_methods(cls, v: tuple[str, ...]) -> tuple[str, ...]:
        parse_methods(v)
        return v

    @field_validator("resolution")
    @classmethod
    def _resolution(cls, v: Resolution) -> Resolution:
        w, h = v
        if not (16 <= w <= 20000 and 8 <= h <= 10000):
            raise ValueError(f"{w}x{h} is not within 16x8 .. 20000x10000")
        return v

    @field_validator("sweep_resolutions")
    @classmethod
    def _resolutions(cls, v: tuple[Resolution, ...]) -> tuple[Resolution, ...]:
        for res in v:
            cls._resolution(res)
        return v

    @field_validator("distance_bins_m")
    @classmethod
    def _distance_bins(cls, v: Bins) -> Bins:
        for lo, hi in v:
            if not 0 < lo < hi:
                raise ValueError(f"bin {lo:g}..{hi:g} m does not satisfy 0 < min < max")
        return v

    @field_validator("yaw_bins_deg")
    @classmethod
    def _yaw_bins(cls, v: Bins) -> Bins:
        for lo, hi in v:
            if not 0 <= lo < hi <= 180:
                raise ValueError(f"bin {lo:g}..{hi:g} deg does not lie within 0..180")
        return v

    @field_validator("noise_mm")
    @classmethod
    def _noise(cls, v: tuple[float, ...]) -> tuple[float, ...]:
        if any(not (0 <= n <= 1000) for n in v):
            raise ValueError("must be 0..1000 mm")
        return v

    @field_validator("real_pairs")
    @classmethod
    def _known_pairs(cls, v: tuple[str, ...]) -> tuple[str, ...]:
        unknown = [n for n in v if n not in REAL_PAIRS]
        if unknown:
            raise ValueError(
                f"unknown real pair(s) {', '.join(unknown)}; known: {', '.join(REAL_PAIRS)}"
            )
        return v

    @classmethod
    def make(cls, suite: str = "all", *, quick: bool = False, **overrides: Any) -> BenchConfig:
        """The full or quick configuration of a suite, with ``overrides``.

        Quick: 4 synthetic pairs at 384x192 (one per distance bin and one per yaw bin), a
        256x128 / 384x192 sweep, two small real pairs (bunny, Ouster), 120 s per method.
        """
        base: dict[str, Any] = {"suite": suite, "quick": quick}
        if quick:
            base |= {
                "pairs": 4,
                "resolution": (384, 192),
                "sweep_resolutions": ((256, 128), (384, 192)),
                "real_pairs": QUICK_REAL_PAIRS,
                "timeout_s": 120.0,
            }
        else:
            base |= {"real_pairs": tuple(REAL_PAIRS)}
        return cls(**(base | overrides))

    @property
    def runs_synthetic(self) -> bool:
        return self.suite in ("synthetic", "all")

    @property
    def runs_real(self) -> bool:
        return self.suite in ("real", "all")


@dataclass(eq=False)
class Case:
    """One pair of the benchmark.

    Attributes
    ----------
    suite : {"synthetic", "real", "resolution"}
    name : str
    target, source : Scan
    T_gt : (4, 4) float64
        Reference ``T_target_source``.
    criteria : SuccessCriteria
    params : dict
        What describes the pair (distance, yaw, tilt, noise, resolution, overlap, scene,
        seed, reference, ...).
    """

    suite: str
    name: str
    target: Scan
    source: Scan
    T_gt: NDArray[np.float64]
    criteria: SuccessCriteria
    params: dict[str, Any] = field(default_factory=dict)


@dataclass(eq=False)
class BenchResult:
    """Every record of a run.

    Attributes
    ----------
    config : BenchConfig
    records : list of dict
        One per (case, method): the case's parameters and the method's row.
    cases : list of dict
        One per case: suite, name, parameters, success limits.
    started, finished : str
        Local times, ISO format.
    elapsed_s : float, seconds
    machine : dict
    command : str
    memory_note : str
        How peak memory was measured.
    """

    config: BenchConfig
    records: list[dict[str, Any]]
    cases: list[dict[str, Any]]
    started: str
    finished: str
    elapsed_s: float
    machine: dict[str, Any]
    command: str
    memory_note: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "command": self.command,
            "started": self.started,
            "finished": self.finished,
            "elapsed_s": self.elapsed_s,
            "machine": self.machine,
            "config": self.config.to_dict(),
            "cases": self.cases,
            "records": self.records,
            "memory_note": self.memory_note,
        }
