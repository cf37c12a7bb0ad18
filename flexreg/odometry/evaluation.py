"""Trajectory accuracy: absolute trajectory error (ATE) and relative pose error (RPE).

The definitions are those of the TUM RGB-D benchmark (Sturm et al., *A Benchmark for the
Evaluation of RGB-D SLAM Systems*, IROS 2012, eqs. 1-5) and of its published tools
``associate.py``, ``evaluate_ate.py`` and ``evaluate_rpe.py``:

- :func:`~flexreg.core.trajectory.associate` pairs estimate and ground-truth poses by
  timestamp: all pairs closer than ``max_dt_s`` are candidates, taken greedily by smallest time
  difference, each pose used once.
- :func:`~flexreg.stages.alignment.umeyama` finds the least-squares rigid (or similarity)
  transform between the associated positions (Horn 1987; Umeyama 1991, eqs. 38-42).
- :func:`ate` is the RMSE (and mean/median/std/min/max) of the position differences after that
  alignment, ``F_i = Q_i^-1 S P_i`` (benchmark eqs. 4-5).
- :func:`rpe` compares motions over a fixed interval ``delta``: with ``A = P_i^-1 P_{i+delta}``
  and ``B = Q_i^-1 Q_{i+delta}``, the error is ``E = A B^-1`` as ``evaluate_rpe.py`` composes
  it (default) or ``E = B^-1 A``, benchmark eq. 1 as printed; reported in metres (its
  translation) and degrees (its rotation angle).
- :func:`evaluate` runs both, as ``flexreg evaluate`` does;
  :func:`flexreg.odometry.plots.plot_evaluation` draws the top view and the errors over time.

``Q`` is the ground truth and ``P`` the estimate, both ``T_world_frame`` poses
(:class:`~flexreg.core.trajectory.Trajectory`). Distances are metres, angles in results degrees.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from flexreg.core.trajectory import MAX_DT_S, Trajectory, associate, check_window
from flexreg.core.transforms import rotation_error_deg
from flexreg.errors import ConfigError, InputError
from flexreg.odometry.config import DELTA_UNITS, RPE_CONVENTIONS
from flexreg.stages.alignment import umeyama

log = logging.getLogger(__name__)

__all__ = [
    "DELTA_UNITS",
    "MIN_ASSOCIATED",
    "RPE_CONVENTIONS",
    "AssociationError",
    "AteResult",
    "EvaluationResult",
    "RpeResult",
    "ate",
    "check_interval",
    "evaluate",
    "interval_label",
    "nearest_partner",
    "rpe",
]

#: fewest associated poses an evaluation accepts
MIN_ASSOCIATED = 3


class AssociationError(InputError):
    """Estimate and ground truth do not share enough timestamps (or pose pairs) to evaluate."""


def _stats(x: NDArray[np.float64]) -> dict[str, float]:
    """RMSE, mean, median, standard deviation (population, as numpy's default), min, max."""
    return {
        "rmse": float(np.sqrt(np.mean(x * x))),
        "mean": float(np.mean(x)),
        "median": float(np.median(x)),
        "std": float(np.std(x)),
        "min": float(np.min(x)),
        "max": float(np.max(x)),
    }


def _association_error(
    gt: Trajectory, est: Trajectory, n: int, max_dt_s: float, offset_s: float
) -> AssociationError:
    shift = f" after adding {offset_s} s" if offset_s else ""
    return AssociationError(
        est.name or "est",
        f"only {n} of its {len(est)} poses have a ground-truth pose within {max_dt_s} s"
        f"{shift} (at least {MIN_ASSOCIATED} are needed); the estimate spans t = "
        f"{est.timestamps[0]:.6f} .. {est.timestamps[-1]:.6f} s, the ground truth "
        f"{gt.name + ' ' if gt.name else ''}t = {gt.timestamps[0]:.6f} .. "
        f"{gt.timestamps[-1]:.6f} s",
    )


@dataclass(frozen=True, eq=False, repr=False)
class AteResult:
    """Absolute trajectory error: position differences after aligning the estimate.

    Attributes
    ----------
    rmse_m, mean_m, median_m, std_m, min_m, max_m : float, metres
        Statistics of :attr:`errors_m` (``std`` is the population standard deviation).
    errors_m : (M,) float64, metres
        ``|q_k - (s R p_k + t)|`` for each associated pair, in ground-truth time order.
    T_gt_est : (4, 4) float64
        Rigid part of the alignment (estimate world frame -> ground-truth world frame).
    scale : float
        Scale applied to the estimate's positions before ``T_gt_est`` (1.0 unless estimated).
    with_scale : bool
        Whether the scale was estimated (similarity alignment).
    index_gt, index_est : (M,) intp
        The associated poses of each trajectory.
    timestamps : (M,) float64, seconds
        Estimate timestamps of the associated pairs.
    positions_gt, positions_est : (M, 3) float64, metres
        Ground-truth positions and aligned estimate positions of the pairs.
    n_est, n_gt : int
        Poses in the estimate and in the ground truth.
    max_dt_s, offset_s : float, seconds
        The association window and time offset used.
    """

    rmse_m: float
    mean_m: float
    median_m: float
    std_m: float
    min_m: float
    max_m: float
    errors_m: NDArray[np.float64]
    T_gt_est: NDArray[np.float64]
    scale: float
    with_scale: bool
    index_gt: NDArray[np.intp]
    index_est: NDArray[np.intp]
    timestamps: NDArray[np.float64]
    positions_gt: NDArray[np.float64]
    positions_est: NDArray[np.float64]
    n_est: int
    n_gt: int
    max_dt_s: float
    offset_s: float

    @property
    def n_associated(self) -> int:
        """Number of associated pose pairs the statistics are taken over."""
        return len(self.errors_m)

    def to_dict(self) -> dict[str, Any]:
        """The summary (statistics, alignment, counts) as JSON-serialisable values."""
        return {
            "rmse_m": self.rmse_m,
            "mean_m": self.mean_m,
            "median_m": self.median_m,
            "std_m": self.std_m,
            "min_m": self.min_m,
            "max_m": self.max_m,
            "n_associated": self.n_associated,
            "n_est": self.n_est,
            "n_gt": self.n_gt,
            "max_dt_s": self.max_dt_s,
            "offset_s": self.offset_s,
            "with_scale": self.with_scale,
            "scale": self.scale,
            "T_gt_est": self.T_gt_est.tolist(),
        }

    def __repr__(self) -> str:
        sc = f", scale {self.scale:.6g}" if self.with_scale else ""
        return (
            f"AteResult(rmse {self.rmse_m:.6g} m, mean {self.mean_m:.6g} m, median "
            f"{self.median_m:.6g} m, max {self.max_m:.6g} m; {self.n_associated} of "
            f"{self.n_est} poses associated{sc})"
        )


def ate(
    gt: Trajectory,
    est: Trajectory,
    *,
    scale: bool = False,
    max_dt_s: float = MAX_DT_S,
    offset_s: float = 0.0,
) -> AteResult:
    """Absolute trajectory error (TUM benchmark eqs. 4-5, ``evaluate_ate.py``).

    Associates the poses by timestamp (:func:`associate`), aligns the estimate's positions to
    the ground truth's (:func:`~flexreg.stages.alignment.umeyama`, rigid unless ``scale``) and
    measures the remaining position differences ``|trans(Q_k^-1 S P_k)| = |q_k - (s R p_k + t)|``.

    Parameters
    ----------
    gt, est : Trajectory
        Ground truth and estimate, poses ``T_world_frame``.
    scale : bool
        Also estimate a scale (similarity alignment, for monocular estimates).
    max_dt_s, offset_s : float, seconds
        Association window and time offset added to the estimate (see :func:`associate`).

    Returns
    -------
    AteResult

    Raises
    ------
    AssociationError
        Fewer than 3 poses associate (naming the estimate and both time spans).
    ConfigError
        Invalid ``max_dt_s`` or ``offset_s``.

    Examples
    --------
    >>> poses = np.tile(np.eye(4), (4, 1, 1))
    >>> poses[:, :3, 3] = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 1.0]]
    >>> gt = Trajectory(np.arange(4.0), poses)
    >>> moved = poses.copy()
    >>> moved[:, :3, 3] += [5.0, -2.0, 0.5]
    >>> round(ate(gt, Trajectory(np.arange(4.0), moved)).rmse_m, 12)
    0.0
    """
    ig, ie = associate(gt, est, max_dt_s=max_dt_s, offset_s=offset_s)
    if len(ig) < MIN_ASSOCIATED:
        raise _association_error(gt, est, len(ig), max_dt_s, offset_s)
    Q = gt.positions[ig]
    P = est.positions[ie]
    T, s = umeyama(Q, P, with_scale=scale)
    aligned = s * P @ T[:3, :3].T + T[:3, 3]
    e = np.linalg.norm(Q - aligned, axis=1)
    st = _stats(e)
    log.info("ATE over %d associated poses: rmse %.6g m", len(e), st["rmse"])
    return AteResult(
        rmse_m=st["rmse"],
        mean_m=st["mean"],
        median_m=st["median"],
        std_m=st["std"],
        min_m=st["min"],
        max_m=st["max"],
        errors_m=e,
        T_gt_est=T,
        scale=s,
        with_scale=scale,
        index_gt=ig,
        index_est=ie,
        timestamps=est.timestamps[ie].copy(),
        positions_gt=Q.copy(),
        positions_est=aligned,
        n_est=len(est),
        n_gt=len(gt),
        max_dt_s=max_dt_s,
        offset_s=offset_s,
    )


def check_interval(
    delta: float, delta_unit: str, *, names: tuple[str, str] = ("delta", "delta_unit")
) -> None:
    """Raise :class:`ConfigError` unless ``delta`` in ``delta_unit`` is a usable RPE interval
    (positive; whole frames). ``names`` are how the two values are called in the message (the
    CLI passes its option names)."""
    d, unit = names
    if delta_unit not in DELTA_UNITS:
        raise ConfigError(f"{unit}: must be one of {', '.join(DELTA_UNITS)}, got {delta_unit!r}")
    if not (math.isfinite(delta) and delta > 0):
        raise ConfigError(f"{d}: must be a positive number of {delta_unit}, got {delta}")
    if delta_unit == "frames" and delta != int(delta):
        raise ConfigError(f"{d}: must be a whole number of frames, got {delta}")


def _check_convention(convention: str) -> None:
    if convention not in RPE_CONVENTIONS:
        raise ConfigError(
            f"convention: must be one of {', '.join(RPE_CONVENTIONS)}, got {convention!r}"
        )


def _pair_ends(values: NDArray[np.float64], delta: float) -> NDArray[np.intp]:
    """For each ``i``, the index ``j`` whose value is nearest to ``values[i] + delta``
    (``values`` non-decreasing, at least 2; ties go to the lower index)."""
    target = values + delta
    k = np.clip(np.searchsorted(values, target, side="left"), 1, len(values) - 1)
    j = np.where(np.abs(target - values[k - 1]) <= np.abs(values[k] - target), k - 1, k)
    return j.astype(np.intp)


def nearest_partner(
    gt: Trajectory, est: Trajectory, *, max_dt_s: float | None = None, offset_s: float = 0.0
) -> tuple[NDArray[np.intp], float]:
    """For each estimate pose, the ground-truth pose nearest in time (``evaluate_rpe.py``'s rule).

    Unlike :func:`associate`, a ground-truth pose may serve several estimate poses.

    Parameters
    ----------
    gt, est : Trajectory
        Ground truth (at least 2 poses) and estimate.
    max_dt_s : float or None, seconds
        Largest accepted time difference (inclusive); ``None``: twice the median sampling
        interval of the ground truth, as ``evaluate_rpe.py`` uses.
    offset_s : float, seconds
        Added to the estimate's timestamps before comparing.

    Returns
    -------
    partner : (N_est,) intp
        Index of the ground-truth pose of each estimate pose, -1 where none is close enough.
    max_dt_s : float
        The window used.

    Examples
    --------
    >>> poses = np.tile(np.eye(4), (4, 1, 1))
    >>> gt = Trajectory(np.array([0.0, 0.1, 0.2, 0.3]), poses)
    >>> est = Trajectory(np.array([0.04, 0.16, 0.9]), poses[:3])
    >>> partner, window = nearest_partner(gt, est)
    >>> partner.tolist(), round(window, 12)
    ([0, 2, -1], 0.2)
    """
    tg = gt.timestamps
    if max_dt_s is None:
        if len(tg) < 2:
            raise AssociationError(gt.name or "gt", "needs at least 2 poses")
        max_dt_s = 2.0 * float(np.median(np.diff(tg)))
    check_window(max_dt_s, offset_s)
    te = est.timestamps + offset_s
    if len(tg) == 1:
        j = np.zeros(len(te), dtype=np.intp)
    else:
        k = np.clip(np.searchsorted(tg, te), 1, len(tg) - 1)
        j = np.where(np.abs(te - tg[k - 1]) <= np.abs(tg[k] - te), k - 1, k).astype(np.intp)
    partner = np.where(np.abs(tg[j] - te) <= max_dt_s, j, -1).astype(np.intp)
    return partner, max_dt_s


@dataclass(frozen=True, eq=False, repr=False)
class RpeResult:
    """Relative pose error over a fixed interval ``delta``.

    Attributes
    ----------
    trans_rmse_m, trans_mean_m, trans_median_m, trans_std_m, trans_min_m, trans_max_m : float
        Statistics of :attr:`errors_trans_m`, metres (``std``: population).
    rot_rmse_deg, rot_mean_deg, rot_median_deg, rot_std_deg, rot_min_deg, rot_max_deg : float
        Statistics of :attr:`errors_rot_deg`, degrees.
    errors_trans_m : (K,) float64, metres
        ``|trans(E_k)|`` per pose pair.
    errors_rot_deg : (K,) float64, degrees
        ``angle(rot(E_k))`` per pose pair.
    pairs : (K, 2) intp
        Estimate indices ``(i, j)`` of each pair (``j`` is ``delta`` after ``i``).
    pairs_gt : (K, 2) intp
        The ground-truth poses matched to them.
    timestamps : (K,) float64, seconds
        Estimate time of the first pose of each pair.
    delta : float
        The interval, in ``delta_unit``.
    delta_unit : str
        ``frames``, ``seconds`` or ``metres``.
    convention : str
        ``tools`` or ``paper`` (see :func:`rpe`).
    scale : float
        Factor applied to the estimate's relative translations.
    max_dt_s : float, seconds
        Window within which an estimate pose found its ground-truth pose.
    n_est, n_matched : int
        Poses in the estimate, and how many of them have a ground-truth pose.
    """

    trans_rmse_m: float
    trans_mean_m: float
    trans_median_m: float
    trans_std_m: float
    trans_min_m: float
    trans_max_m: float
    rot_rmse_deg: float
    rot_mean_deg: float
    rot_median_deg: float
    rot_std_deg: float
    rot_min_deg: float
    rot_max_deg: float
    errors_trans_m: NDArray[np.float64]
    errors_rot_deg: NDArray[np.float64]
    pairs: NDArray[np.intp]
    pairs_gt: NDArray[np.intp]
    timestamps: NDArray[np.float64]
    delta: float
    delta_unit: str
    convention: str
    scale: float
    max_dt_s: float
    n_est: int
    n_matched: int

    @property
    def n_pairs(self) -> int:
        """Number of pose pairs the statistics are taken over."""
        return len(self.errors_trans_m)

    def to_dict(self) -> dict[str, Any]:
        """The summary (statistics, interval, counts) as JSON-serialisable values."""
        keys = ("rmse", "mean", "median", "std", "min", "max")
        out: dict[str, Any] = {f"trans_{k}_m": getattr(self, f"trans_{k}_m") for k in keys}
        out.update({f"rot_{k}_deg": getattr(self, f"rot_{k}_deg") for k in keys})
        out.update(
            n_pairs=self.n_pairs,
            delta=self.delta,
            delta_unit=self.delta_unit,
            convention=self.convention,
            scale=self.scale,
            max_dt_s=self.max_dt_s,
            n_est=self.n_est,
            n_matched=self.n_matched,
        )
        return out

    def __repr__(self) -> str:
        return (
            f"RpeResult(delta {self.delta:g} {self.delta_unit}: translation rmse "
            f"{self.trans_rmse_m:.6g} m, mean {self.trans_mean_m:.6g} m; rotation rmse "
            f"{self.rot_rmse_deg:.6g} deg, mean {self.rot_mean_deg:.6g} deg; "
            f"{self.n_pairs} pairs, {self.convention} convention)"
        )


def rpe(
    gt: Trajectory,
    est: Trajectory,
    *,
    delta: float = 1,
    delta_unit: Literal["frames", "seconds", "metres"] | str = "frames",
    max_dt_s: float | None = None,
    offset_s: float = 0.0,
    scale: float = 1.0,
    convention: Literal["tools", "paper"] | str = "tools",
) -> RpeResult:
    """Relative pose error over a fixed interval (TUM benchmark eqs. 1-2, ``evaluate_rpe.py``).

    Pairs: for each estimate pose ``i``, ``j`` is the estimate pose whose frame index,
    timestamp or distance travelled along the estimate (``delta_unit`` frames / seconds /
    metres) is nearest to ``i``'s plus ``delta``; pairs whose target lies beyond the end of the
    estimate are skipped, and so are pairs with an end that has no ground-truth pose within
    ``max_dt_s`` (:func:`nearest_partner`). This is ``evaluate_rpe.py --fixed_delta``.

    Error of a pair, with ``Q`` the ground truth, ``P`` the estimate (its relative translation
    multiplied by ``scale``), ``A = P_i^-1 P_j`` and ``B = Q_i^-1 Q_j``:

    - ``convention="tools"`` (default): ``E = A B^-1``, the composition ``evaluate_rpe.py``
      computes (``ominus(ominus(P_j, P_i), ominus(Q_j, Q_i))``);
      ``|trans(E)| = |t_A - R_A R_B^T t_B|``.
    - ``convention="paper"``: ``E = B^-1 A = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j)``, eq. 1 of the
      benchmark paper as printed (also evo's and the KITTI devkit's); ``|trans(E)| =
      |t_A - t_B|``.

    The rotation angle of ``E`` is the same in both (the geodesic angle between ``R_A`` and
    ``R_B``); the translations differ by a term of the order of the rotation error times the
    motion over ``delta`` (0.1 % to 2 % on the TUM and KITTI sequences, docs/evaluation.md).
    RPE does not depend on the world frames of the trajectories, so no alignment is needed.

    Parameters
    ----------
    gt, est : Trajectory
        Ground truth and estimate, poses ``T_world_frame``.
    delta : float
        The interval, in ``delta_unit`` (a whole number for frames).
    delta_unit : {"frames", "seconds", "metres"}
        ``frames`` counts estimate poses (KITTI-style; the default); ``seconds`` uses the
        estimate's timestamps (the unit of ``evaluate_rpe.py``); ``metres`` the distance
        travelled along the (scaled) estimate.
    max_dt_s : float or None, seconds
        Time window for the ground-truth pose of an estimate pose (the nearest one); ``None``:
        twice the ground truth's median sampling interval, as ``evaluate_rpe.py``.
    offset_s : float, seconds
        Added to the estimate's timestamps before matching.
    scale : float
        Factor for the estimate's relative translations (e.g. the ATE similarity scale of a
        monocular estimate).
    convention : {"tools", "paper"}
        Order of the error composition (above).

    Returns
    -------
    RpeResult

    Raises
    ------
    AssociationError
        Fewer than 3 estimate poses have a ground-truth pose, or no pair is ``delta`` apart.
    ConfigError
        Invalid ``delta``, ``delta_unit``, ``scale``, ``max_dt_s``, ``offset_s`` or
        ``convention``.

    Examples
    --------
    >>> poses = np.tile(np.eye(4), (5, 1, 1))
    >>> poses[:, 0, 3] = np.arange(5.0)
    >>> gt = Trajectory(np.arange(5.0), poses)
    >>> stretched = poses.copy()
    >>> stretched[:, 0, 3] *= 1.1  # every 1 m step estimated as 1.1 m
    >>> r = rpe(gt, Trajectory(np.arange(5.0), stretched))
    >>> r.n_pairs, round(r.trans_rmse_m, 12), r.rot_max_deg
    (4, 0.1, 0.0)
    """
    check_interval(delta, delta_unit)
    _check_convention(convention)
    if not (math.isfinite(scale) and scale > 0):
        raise ConfigError(f"scale: must be a positive number, got {scale}")
    partner, window = nearest_partner(gt, est, max_dt_s=max_dt_s, offset_s=offset_s)
    n_matched = int(np.count_nonzero(partner >= 0))
    if n_matched < MIN_ASSOCIATED:
        raise _association_error(gt, est, n_matched, window, offset_s)
    n = len(est)
    if delta_unit == "frames":
        values = np.arange(n, dtype=np.float64)
    elif delta_unit == "seconds":
        values = est.timestamps
    else:
        steps = np.linalg.norm(np.diff(est.positions, axis=0), axis=1) * scale
        values = np.concatenate([[0.0], np.cumsum(steps)])
    i = np.arange(n, dtype=np.intp)
    j = _pair_ends(values, delta)
    keep = (j > i) & (values + delta <= values[-1]) & (partner[i] >= 0) & (partner[j] >= 0)
    i, j = i[keep], j[keep]
    if len(i) == 0:
        span = {"frames": f"{n} poses", "seconds": f"{est.duration_s:.6g} s"}.get(
            delta_unit, f"{values[-1]:.6g} m travelled"
        )
        raise AssociationError(
            est.name or "est",
            f"no pose pair {delta:g} {delta_unit} apart with ground truth at both ends "
            f"(the estimate has {span}; {n_matched} poses have ground truth within "
            f"{window:.6g} s)",
        )
    A = _invert_all(est.poses[i]) @ est.poses[j]  # P_i^-1 P_j
    A[:, :3, 3] *= scale
    B = _invert_all(gt.poses[partner[i]]) @ gt.poses[partner[j]]  # Q_i^-1 Q_j
    E = A @ _invert_all(B) if convention == "tools" else _invert_all(B) @ A
    et = np.linalg.norm(E[:, :3, 3], axis=1)
    er = np.array([rotation_error_deg(a, b) for a, b in zip(A, B, strict=True)])
    ts, rs = _stats(et), _stats(er)
    log.info(
        "RPE over %d pairs (delta %g %s): translation rmse %.6g m, rotation rmse %.6g deg",
        len(et),
        delta,
        delta_unit,
        ts["rmse"],
        rs["rmse"],
    )
    return RpeResult(
        trans_rmse_m=ts["rmse"],
        trans_mean_m=ts["mean"],
        trans_median_m=ts["median"],
        trans_std_m=ts["std"],
        trans_min_m=ts["min"],
        trans_max_m=ts["max"],
        rot_rmse_deg=rs["rmse"],
        rot_mean_deg=rs["mean"],
        rot_median_deg=rs["median"],
        rot_std_deg=rs["std"],
        rot_min_deg=rs["min"],
        rot_max_deg=rs["max"],
        errors_trans_m=et,
        errors_rot_deg=er,
        pairs=np.column_stack([i, j]),
        pairs_gt=np.column_stack([partner[i], partner[j]]),
        timestamps=est.timestamps[i].copy(),
        delta=float(delta),
        delta_unit=delta_unit,
        convention=convention,
        scale=float(scale),
        max_dt_s=window,
        n_est=n,
        n_matched=n_matched,
    )


def _invert_all(T: NDArray[np.float64]) -> NDArray[np.float64]:
    """Inverse of each rigid transform of a (K, 4, 4) stack (``R^T``, ``-R^T t``; as
    :func:`flexreg.core.transforms.invert` does for one)."""
    Rt = T[:, :3, :3].transpose(0, 2, 1)
    out = np.zeros_like(T)
    out[:, :3, :3] = Rt
    out[:, :3, 3] = -np.einsum("kab,kb->ka", Rt, T[:, :3, 3])
    out[:, 3, 3] = 1.0
    return out


@dataclass(frozen=True, eq=False, repr=False)
class EvaluationResult:
    """ATE and RPE of one estimate against its ground truth (what ``flexreg evaluate`` reports).

    Attributes
    ----------
    ate : AteResult
    rpe : RpeResult
    """

    ate: AteResult
    rpe: RpeResult

    def to_dict(self) -> dict[str, Any]:
        """Flat JSON-serialisable summary: ``ate_*`` and ``rpe_*`` keys with their units
        (``ate_rmse_m``, ``rpe_trans_rmse_m``, ``rpe_trans_mean_m``, ``rpe_rot_mean_deg``, ...)."""
        out: dict[str, Any] = {}
        for k, v in self.ate.to_dict().items():
            out[f"ate_{k}"] = v
        for k, v in self.rpe.to_dict().items():
            out[f"rpe_{k}"] = v
        return out

    def __repr__(self) -> str:
        return f"EvaluationResult({self.ate!r}, {self.rpe!r})"


def evaluate(
    gt: Trajectory,
    est: Trajectory,
    *,
    scale: bool = False,
    delta: float = 1,
    delta_unit: Literal["frames", "seconds", "metres"] | str = "frames",
    max_dt_s: float | None = None,
    offset_s: float = 0.0,
    convention: Literal["tools", "paper"] | str = "tools",
) -> EvaluationResult:
    """ATE and RPE of ``est`` against ``gt`` in one call (what ``flexreg evaluate`` runs).

    Parameters
    ----------
    gt, est : Trajectory
        Ground truth and estimate.
    scale : bool
        Estimate a scale in the ATE alignment (monocular); the RPE then multiplies the
        estimate's relative translations by that scale too.
    delta, delta_unit, convention
        RPE interval and composition (see :func:`rpe`).
    max_dt_s : float or None, seconds
        Time window for matching poses. ``None`` uses each TUM tool's own rule: 0.02 s for
        the ATE association (``associate.py``) and twice the ground truth's median sampling
        interval for the RPE (``evaluate_rpe.py``); a number applies to both.
    offset_s : float, seconds
        Added to the estimate's timestamps before matching.

    Returns
    -------
    EvaluationResult
    """
    check_interval(delta, delta_unit)
    _check_convention(convention)
    a = ate(
        gt,
        est,
        scale=scale,
        max_dt_s=MAX_DT_S if max_dt_s is None else max_dt_s,
        offset_s=offset_s,
    )
    r = rpe(
        gt,
        est,
        delta=delta,
        delta_unit=delta_unit,
        max_dt_s=max_dt_s,
        offset_s=offset_s,
        scale=a.scale,
        convention=convention,
    )
    return EvaluationResult(ate=a, rpe=r)


def interval_label(delta: float, unit: str) -> str:
    """``"1 frame"``, ``"2 frames"``, ``"0.5 seconds"``, ``"1 metre"``: an RPE interval as text.

    >>> interval_label(1, "frames"), interval_label(2.5, "metres")
    ('1 frame', '2.5 metres')
    """
    return f"{delta:g} {unit[:-1] if delta == 1 and unit.endswith('s') else unit}"
