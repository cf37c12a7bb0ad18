"""Time-stamped poses: the :class:`Trajectory` type and the association of timestamps.

A :class:`Trajectory` is a sequence of poses ``T_world_frame`` (4x4 float64, mapping points of
frame ``i`` into the world frame; the camera-to-world convention of the TUM RGB-D and KITTI
formats, read and written by :mod:`flexreg.io.trajectory`).

:func:`associate` pairs two sets of timestamps as the TUM RGB-D benchmark's ``associate.py``
does (Sturm et al., IROS 2012): all pairs closer than ``max_dt_s`` are candidates, taken
greedily by smallest time difference, each used once. Depth sequences use it to pair colour
and depth frames, the evaluation to pair estimate and ground-truth poses.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.errors import ConfigError, InputError

__all__ = ["MAX_CANDIDATES", "MAX_DT_S", "POSE_TOL", "Trajectory", "associate", "check_window"]

#: tolerance on orthonormality of the poses a :class:`Trajectory` is built from
POSE_TOL = 1e-6
#: largest time difference of associated timestamps, seconds (TUM ``associate.py``): colour /
#: depth frames of a sequence, estimate / ground-truth poses of the ATE
MAX_DT_S = 0.02
#: most candidate pairs :func:`associate` examines (about 32 bytes each)
MAX_CANDIDATES = 20_000_000


@dataclass(frozen=True, eq=False, repr=False)
class Trajectory:
    """Time-stamped rigid poses ``T_world_frame``.

    The arrays are copied to float64 and made read-only. There is at least one pose, and the
    timestamps increase strictly.

    Parameters
    ----------
    timestamps : (N,) float64, seconds
        Time of each pose (for KITTI files: the frame index).
    poses : (N, 4, 4) float64
        ``T_world_frame``: maps points of frame ``i`` into the world frame (metres); each a
        proper rigid transform (orthonormal rotation block with det +1, to 1e-6).
    name : str
        Where the trajectory came from (the file it was read from), used in messages.

    Examples
    --------
    >>> poses = np.tile(np.eye(4), (3, 1, 1))
    >>> poses[:, 0, 3] = [0.0, 1.0, 2.0]
    >>> traj = Trajectory(np.array([0.0, 0.1, 0.2]), poses, name="walk")
    >>> len(traj), traj.positions[-1].tolist()
    (3, [2.0, 0.0, 0.0])
    """

    timestamps: NDArray[np.float64]
    poses: NDArray[np.float64]
    name: str = field(default="")

    def __post_init__(self) -> None:
        who = self.name or "trajectory"
        t = np.array(self.timestamps, dtype=np.float64, copy=True)
        T = np.array(self.poses, dtype=np.float64, copy=True)
        if t.ndim != 1:
            raise InputError(who, f"timestamps must be a 1-D array, got shape {t.shape}")
        if T.shape != (len(t), 4, 4):
            raise InputError(
                who,
                f"poses must have shape ({len(t)}, 4, 4) to match the timestamps, got {T.shape}",
            )
        if len(t) == 0:
            raise InputError(who, "no poses")
        if not (np.isfinite(t).all() and np.isfinite(T).all()):
            raise InputError(who, "timestamps or poses hold NaN or Inf")
        steps = np.diff(t)
        if (steps <= 0).any():
            k = int(np.argmax(steps <= 0))
            raise InputError(
                who,
                f"timestamps must increase strictly: pose {k + 1} at t = {float(t[k + 1])!r} s "
                f"follows t = {float(t[k])!r} s",
            )
        bad = ~_is_rigid(T, POSE_TOL)
        if bad.any():
            k = int(np.argmax(bad))
            raise InputError(
                who,
                f"pose {k} is not a rigid transform (last row 0 0 0 1, orthonormal rotation "
                "block with det +1)",
            )
        t.setflags(write=False)
        T.setflags(write=False)
        object.__setattr__(self, "timestamps", t)
        object.__setattr__(self, "poses", T)

    def __len__(self) -> int:
        return len(self.timestamps)

    @property
    def positions(self) -> NDArray[np.float64]:
        """(N, 3) float64, metres: the frame origins in the world frame."""
        return self.poses[:, :3, 3]

    @property
    def duration_s(self) -> float:
        """Time from the first to the last pose, seconds (0 for fewer than 2 poses)."""
        return float(self.timestamps[-1] - self.timestamps[0]) if len(self) > 1 else 0.0

    @property
    def path_length_m(self) -> float:
        """Length of the polyline through the positions, metres."""
        return float(np.linalg.norm(np.diff(self.positions, axis=0), axis=1).sum())

    def subset(self, index: ArrayLike) -> Trajectory:
        """The poses at ``index`` (an increasing integer index array or boolean mask)."""
        i = np.asarray(index)
        return Trajectory(self.timestamps[i], self.poses[i], name=self.name)

    def __repr__(self) -> str:
        label = f"{self.name!r}, " if self.name else ""
        t0, t1 = self.timestamps[0], self.timestamps[-1]
        return (
            f"Trajectory({label}{len(self)} poses, t = {t0:.6f} .. {t1:.6f} s "
            f"({self.duration_s:.3f} s), path {self.path_length_m:.3f} m)"
        )


def _is_rigid(T: NDArray[np.float64], atol: float) -> NDArray[np.bool_]:
    """(N,) bool: which of the (N, 4, 4) matrices are proper rigid transforms (to ``atol``)."""
    R = T[:, :3, :3]
    ortho = np.abs(R @ R.transpose(0, 2, 1) - np.eye(3)).max(axis=(1, 2), initial=0.0) <= atol
    last = np.abs(T[:, 3] - [0.0, 0.0, 0.0, 1.0]).max(axis=1, initial=0.0) <= 1e-12
    return ortho & last & (np.linalg.det(R) > 0)


# ------------------------------------------------------------------------------ association


def _times(x: Trajectory | ArrayLike, name: str) -> NDArray[np.float64]:
    t = np.asarray(x.timestamps if isinstance(x, Trajectory) else x, dtype=np.float64)
    if t.ndim != 1 or not np.isfinite(t).all():
        raise InputError(name, "timestamps must be a 1-D array of finite seconds")
    return t


def check_window(max_dt_s: float, offset_s: float) -> None:
    """Raise :class:`~flexreg.errors.ConfigError` unless ``max_dt_s`` is a positive and
    ``offset_s`` a finite number of seconds (an association window and a clock offset)."""
    if not (math.isfinite(max_dt_s) and max_dt_s > 0):
        raise ConfigError(f"max_dt_s: must be a positive number of seconds, got {max_dt_s}")
    if not math.isfinite(offset_s):
        raise ConfigError(f"offset_s: must be a finite number of seconds, got {offset_s}")


def associate(
    gt: Trajectory | ArrayLike,
    est: Trajectory | ArrayLike,
    *,
    max_dt_s: float = MAX_DT_S,
    offset_s: float = 0.0,
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Pair ground-truth and estimate poses by timestamp (TUM ``associate.py`` semantics).

    Every pair with ``|t_gt - (t_est + offset_s)| < max_dt_s`` is a candidate; candidates are
    taken in order of increasing time difference (ties: earlier ground truth, then earlier
    estimate), skipping any whose poses are already used, so each pose is used at most once.

    Parameters
    ----------
    gt, est : Trajectory or (N,) array_like of float, seconds
        The two trajectories (or their timestamps).
    max_dt_s : float, seconds
        Largest time difference of a pair (exclusive), default 0.02 s as in the TUM tools.
    offset_s : float, seconds
        Added to the estimate's timestamps before comparing (sensor delay).

    Returns
    -------
    index_gt, index_est : (M,) intp
        The associated poses, ordered by ground-truth time.

    Raises
    ------
    ConfigError
        ``max_dt_s`` not positive, ``offset_s`` not finite, or a window so wide that it holds
        more than 20 million candidate pairs.

    Examples
    --------
    >>> ig, ie = associate([0.0, 0.01, 0.02, 0.03], [0.012, 0.014, 0.5], max_dt_s=0.005)
    >>> ig.tolist(), ie.tolist()
    ([1], [0])
    """
    check_window(max_dt_s, offset_s)
    tg = _times(gt, "gt")
    te = _times(est, "est") + offset_s
    og = np.argsort(tg, kind="stable")
    tgs = tg[og]
    lo = np.searchsorted(tgs, te - max_dt_s, side="left")
    hi = np.searchsorted(tgs, te + max_dt_s, side="right")
    counts = hi - lo
    total = int(counts.sum())
    if total > MAX_CANDIDATES:
        raise ConfigError(
            f"max_dt_s: a window of {max_dt_s} s gives {total:,} candidate pairs; use a smaller one"
        )
    ie = np.repeat(np.arange(len(te)), counts)
    start = np.repeat(np.cumsum(counts) - counts, counts)
    ig = og[lo[ie] + (np.arange(total) - start)]
    diff = np.abs(tg[ig] - te[ie])
    ok = diff < max_dt_s
    ig, ie, diff = ig[ok], ie[ok], diff[ok]
    # TUM sorts (diff, t_gt, t_est) tuples; with time-ordered indices this is the same order
    rank_g = np.empty(len(tg), dtype=np.intp)
    rank_g[og] = np.arange(len(tg))
    rank_e = np.empty(len(te), dtype=np.intp)
    rank_e[np.argsort(te, kind="stable")] = np.arange(len(te))
    order = np.lexsort((rank_e[ie], rank_g[ig], diff))
    used_g = np.zeros(len(tg), dtype=bool)
    used_e = np.zeros(len(te), dtype=bool)
    out_g: list[int] = []
    out_e: list[int] = []
    room = min(len(tg), len(te))
    for g, e in zip(ig[order].tolist(), ie[order].tolist(), strict=True):
        if used_g[g] or used_e[e]:
            continue
        used_g[g] = used_e[e] = True
        out_g.append(g)
        out_e.append(e)
        if len(out_g) == room:
            break
    ag = np.asarray(out_g, dtype=np.intp)
    ae = np.asarray(out_e, dtype=np.intp)
    by_gt = np.argsort(rank_g[ag], kind="stable")
    return ag[by_gt], ae[by_gt]
