"""Figures of a trajectory evaluation: top view of ground truth and estimate, errors over time."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from flexreg.core.trajectory import Trajectory
from flexreg.odometry.evaluation import EvaluationResult, interval_label

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["plot_evaluation"]


def _top_axes(points: NDArray[np.float64]) -> tuple[int, int]:
    """The two coordinate axes along which ``points`` extend most (the plan view; KITTI's
    camera frame has y down, so this picks x and z there)."""
    extent = np.ptp(points, axis=0)
    a, b = sorted(np.argsort(extent)[::-1][:2].tolist())
    return int(a), int(b)


def plot_evaluation(
    result: EvaluationResult,
    gt: Trajectory,
    est: Trajectory,
    *,
    time_unit: str = "s",
) -> Figure:
    """Figure: top view of the ground truth and the aligned estimate, and errors over time.

    Left: both trajectories projected on the two world axes along which the ground truth
    extends most, the estimate mapped by the ATE alignment (``scale``, ``T_gt_est``). Right,
    top: ATE per associated pose; bottom: RPE translation (and rotation, right axis) per pair,
    both against time since the first ground-truth pose.

    Parameters
    ----------
    result : EvaluationResult
        From :func:`evaluate` on ``gt`` and ``est``.
    gt, est : Trajectory
        The trajectories evaluated.
    time_unit : str
        Label of the time axis (``"s"``, or ``"frame"`` for KITTI files).

    Returns
    -------
    matplotlib.figure.Figure
        Drawn with the Agg canvas; save it with ``fig.savefig(path)``.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # heavy: matplotlib
    from matplotlib.figure import Figure

    a, r = result.ate, result.rpe
    names = "xyz"
    fig = Figure(figsize=(12.0, 6.0), layout="constrained")
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(2, 2, width_ratios=(1.1, 1.0))
    top = fig.add_subplot(grid[:, 0])
    ax0, ax1 = _top_axes(gt.positions)
    est_aligned = a.scale * est.positions @ a.T_gt_est[:3, :3].T + a.T_gt_est[:3, 3]
    top.plot(
        gt.positions[:, ax0],
        gt.positions[:, ax1],
        color="0.15",
        lw=2.4,
        alpha=0.45,
        label="ground truth",
    )
    top.plot(
        est_aligned[:, ax0],
        est_aligned[:, ax1],
        color="#0072B2",
        lw=1.0,
        label="estimate (aligned" + (f", scale {a.scale:.4g})" if a.with_scale else ")"),
    )
    top.plot(*gt.positions[0, [ax0, ax1]], "o", color="0.2", ms=5, label="start")
    top.set_xlabel(f"{names[ax0]} [m]")
    top.set_ylabel(f"{names[ax1]} [m]")
    top.set_aspect("equal", adjustable="datalim")
    top.set_title(f"Top view ({names[ax0]}-{names[ax1]}), ATE rmse {a.rmse_m:.4g} m")
    top.legend(loc="best", fontsize="small")
    top.grid(True, lw=0.3)

    t0 = gt.timestamps[0]
    e1 = fig.add_subplot(grid[0, 1])
    e1.plot(a.timestamps - t0, a.errors_m, color="#D55E00", lw=0.9)
    e1.axhline(a.rmse_m, color="0.4", ls="--", lw=0.8, label=f"rmse {a.rmse_m:.4g} m")
    e1.set_ylabel("ATE [m]")
    e1.set_title("Absolute trajectory error")
    e1.legend(loc="upper right", fontsize="small")
    e1.grid(True, lw=0.3)

    e2 = fig.add_subplot(grid[1, 1], sharex=e1)
    e2.plot(r.timestamps - t0, r.errors_trans_m, color="#009E73", lw=0.9, label="translation")
    e2.set_ylabel("RPE translation [m]", color="#009E73")
    e2.set_xlabel(f"time since start [{time_unit}]")
    unit = "frames" if time_unit == "frame" and r.delta_unit == "seconds" else r.delta_unit
    e2.set_title(f"Relative pose error over {interval_label(r.delta, unit)}")
    e2.grid(True, lw=0.3)
    e3 = e2.twinx()
    e3.plot(r.timestamps - t0, r.errors_rot_deg, color="#CC79A7", lw=0.7, alpha=0.8)
    e3.set_ylabel("RPE rotation [deg]", color="#CC79A7")
    return fig
