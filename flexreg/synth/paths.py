"""Smooth sensor paths through a scene's free space: a walk (:func:`smooth_path`), a hand-held
camera's poses along it (:func:`camera_trajectory`) and a level lidar's
(:func:`lidar_trajectory`)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.errors import ConfigError, InputError
from flexreg.synth.placement import free_map
from flexreg.synth.scene import Scene
from flexreg.synth.seeding import as_rng
from flexreg.synth.sensors import look_at

__all__ = ["camera_trajectory", "lidar_trajectory", "smooth_path"]


def _catmull_rom(p0: Any, p1: Any, p2: Any, p3: Any) -> NDArray[np.float64]:
    """Catmull-Rom spline from ``p1`` to ``p2`` (excluding ``p2``), ~5 cm spacing."""
    n = max(4, int(np.linalg.norm(p2 - p1) / 0.05))
    t = np.linspace(0, 1, n, endpoint=False)[:, None]
    return 0.5 * (
        2 * p1
        + (-p0 + p2) * t
        + (2 * p0 - 5 * p1 + 4 * p2 - p3) * t**2
        + (-p0 + 3 * p1 - 3 * p2 + p3) * t**3
    )


def smooth_path(
    scene: Scene,
    n_frames: int,
    *,
    step_m: float,
    height_range_m: tuple[float, float] = (1.2, 1.7),
    clearance_m: float = 0.5,
    rng: np.random.Generator | int | None = 0,
    tries: int = 200,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Positions and headings of a smooth walk through free space.

    A random walk over free floor (steps of 0.8-2.5 m with gentle turns, stepping back out of
    dead ends) is smoothed by a Catmull-Rom spline and sampled every ``step_m`` metres. Each new
    waypoint is accepted only if the spline piece it completes stays on free floor and
    ``clearance_m`` away from all surfaces.

    Returns
    -------
    positions : (n_frames, 3) float64, metres
    heading : (n_frames,) float64, radians
        Direction of travel (azimuth from +X).
    """
    gen, _ = as_rng(rng)
    if step_m <= 0:
        raise ConfigError(f"step must be positive, got {step_m}")
    fm = free_map(scene)
    fy, fx = np.nonzero(fm.free)
    if len(fx) == 0:
        raise InputError(scene.name or "scene", "no free floor for a sensor path")
    length = max(n_frames, 2) * step_m + 0.5
    h0, h1 = height_range_m

    def clear(pts: NDArray[np.float64]) -> bool:
        return bool(fm.lookup(pts[:, :2])[0].all() and scene.distance(pts).min() >= clearance_m)

    for _ in range(tries):
        # a random walk over free floor (steps of 0.8-2.5 m, gentle turns); each new waypoint
        # must keep the spline piece it completes on free floor and clear of all surfaces
        c = gen.integers(0, len(fx))
        xy0 = np.array([fm.x0 + fx[c] * fm.cell_m, fm.y0 + fy[c] * fm.cell_m])
        W = [np.array([*xy0, fm.lookup(xy0[None])[1][0] + gen.uniform(h0, h1)])]
        if not clear(W[0][None]):
            continue
        heading = gen.uniform(-math.pi, math.pi)
        pieces: list[NDArray[np.float64]] = []
        lengths: list[float] = []
        stuck = backtracks = 0
        while sum(lengths) < length and backtracks < 200:
            if stuck >= 48:  # dead end: step back one waypoint and try elsewhere
                if len(W) < 3:
                    break
                W.pop()
                pieces.pop()
                lengths.pop()
                heading = gen.uniform(-math.pi, math.pi)
                stuck = 0
                backtracks += 1
                continue
            turn = gen.normal(0.0, 0.5) if stuck < 24 else gen.uniform(-math.pi, math.pi)
            step = gen.uniform(0.8, 2.5)
            h = heading + turn
            qxy = W[-1][:2] + step * np.array([math.cos(h), math.sin(h)])
            free, gz = fm.lookup(qxy[None])
            if not free[0]:
                stuck += 1
                continue
            q = np.array([*qxy, gz[0] + gen.uniform(h0, h1)])
            if len(W) == 1:
                seg = W[0] + np.linspace(0, 1, max(2, int(step / 0.05)))[:, None] * (q - W[0])
                new = None
                ok = clear(seg)
            else:
                p0 = W[-3] if len(W) >= 3 else 2 * W[-2] - W[-1]
                new = _catmull_rom(p0, W[-2], W[-1], q)
                ok = clear(new) and clear(q[None])
            if not ok:
                stuck += 1
                continue
            if new is not None:
                pieces.append(new)
                lengths.append(
                    float(np.linalg.norm(np.diff(np.vstack([new, W[-1]]), axis=0), axis=1).sum())
                )
            W.append(q)
            heading = h
            stuck = 0
        if sum(lengths) < length:
            continue
        dense = np.vstack(pieces)
        cum = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(dense, axis=0), axis=1))]
        s = np.arange(n_frames) * step_m
        P = np.column_stack([np.interp(s, cum, dense[:, i]) for i in range(3)])
        ahead = np.column_stack([np.interp(s + 0.3, cum, dense[:, i]) for i in range(3)])
        return P, np.arctan2(ahead[:, 1] - P[:, 1], ahead[:, 0] - P[:, 0])
    raise InputError(
        scene.name or "scene",
        f"could not find a clear sensor path of {length:.1f} m in {tries} tries; use fewer frames "
        "or a larger scene",
    )


def camera_trajectory(
    scene: Scene,
    n_frames: int,
    *,
    step_m: float,
    rng: np.random.Generator | int | None = 0,
) -> list[NDArray[np.float64]]:
    """Hand-held RGB-D camera poses (x right, y down, z forward) along :func:`smooth_path`,
    looking ahead with a slow pan (+-23 deg) and a downward tilt (11 +- 6 deg)."""
    gen, _ = as_rng(rng)
    P, heading = smooth_path(scene, n_frames, step_m=step_m, rng=gen)
    phase = gen.uniform(0, 2 * math.pi, size=2)
    poses = []
    for i in range(n_frames):
        s = i * step_m
        yaw = heading[i] + 0.4 * math.sin(s / 2.0 + phase[0])
        pitch = -0.2 + 0.1 * math.sin(s / 3.1 + phase[1])
        d = [math.cos(yaw) * math.cos(pitch), math.sin(yaw) * math.cos(pitch), math.sin(pitch)]
        poses.append(look_at(P[i], P[i] + d))
    return poses


def lidar_trajectory(
    scene: Scene,
    n_frames: int,
    *,
    step_m: float = 0.5,
    rng: np.random.Generator | int | None = 0,
) -> list[NDArray[np.float64]]:
    """Level spinning-lidar poses (x forward, z up) every ``step_m`` along :func:`smooth_path`
    (0.5 m: a 10 Hz lidar moving at 5 m/s)."""
    P, heading = smooth_path(
        scene, n_frames, step_m=step_m, height_range_m=(1.7, 1.9), clearance_m=0.3, rng=rng
    )
    poses = []
    for p, h in zip(P, heading, strict=True):
        T = np.eye(4)
        c, s_ = math.cos(h), math.sin(h)
        T[:3, :3] = [[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]]
        T[:3, 3] = p
        poses.append(T)
    return poses
