"""One picking session: the pairs a user clicked, the live solution, suggestions, saving.

Every change (a pair added, moved or deleted, a suggestion accepted) re-solves with the solver
of ``flexreg calibrate --pairs`` (:func:`flexreg.calibration.solve_pnp`: MAGSAC++ RANSAC,
Levenberg-Marquardt, the verdict) from :data:`~flexreg.stages.camera_pose.MIN_CORRESPONDENCES`
pairs on. Nothing is written until :meth:`PickSession.save`, which writes its files at once
(each complete on disk or not replaced), not at the end of the command. A session is shared by
the web server's worker threads; its public methods hold its lock.
"""

from __future__ import annotations

import contextvars
import functools
import logging
import math
import os
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg._version import __version__
from flexreg.calibration.auto import propose_correspondences
from flexreg.calibration.config import CalibrationConfig
from flexreg.calibration.pnp import solve_pnp
from flexreg.calibration.types import CalibrationResult
from flexreg.core.correspondences import Correspondences2D3D
from flexreg.core.scan import Scan
from flexreg.core.transforms import (
    as_transform,
    rotation_error_deg,
    translation_error_m,
)
from flexreg.errors import CalibrationError, FlexregError, InputError
from flexreg.io import write_transform_json
from flexreg.io.correspondences import write_pairs
from flexreg.io.files import Outputs, active_outputs
from flexreg.io.intrinsics import CameraIntrinsics
from flexreg.picker.views import LidarViews, encode_png, overlay_rgba, preview
from flexreg.stages.camera_pose import MIN_CORRESPONDENCES, project_points, to_rvec_tvec

log = logging.getLogger(__name__)

__all__ = ["Pair", "PickSession"]

#: most lidar points drawn on the camera image (a regular subsample beyond)
OVERLAY_POINTS = 300_000
#: most suggestions offered at once
MAX_SUGGESTIONS = 20


@dataclass
class Pair:
    """A camera pixel and the lidar return paired with it.

    Attributes
    ----------
    id : int
        Stable identifier in the session (never reused).
    u, v : float, pixels
        Camera pixel (distorted image, as taken).
    point : (3,) float64, metres, lidar frame
    index : int
        The scan point (-1 when it is not one, e.g. a loaded ``X,Y,Z`` far from every point).
    line : int
        Its line in the loaded ``--pairs`` file, 0 for pairs made in the session.
    """

    id: int
    u: float
    v: float
    point: NDArray[np.float64]
    index: int = -1
    line: int = 0


def _finite(name: str, value: Any) -> float:
    """``value`` as a finite float, or an :class:`InputError` naming ``name``."""
    if isinstance(value, bool):
        raise InputError(name, f"expected a number, got {value!r}")
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(name, f"expected a number, got {value!r}") from None
    if not math.isfinite(x):
        raise InputError(name, f"expected a finite number, got {value!r}")
    return x


class PickSession:
    """State of ``flexreg pick``: pairs, live solution, suggestions, and the files it saves.

    Parameters
    ----------
    image : (H, W, 3) uint8
        Camera image, BGR.
    scan : Scan
    intrinsics : CameraIntrinsics
        For this image (size known).
    out : Path
        Where :meth:`save` writes the pairs (``u,v,X,Y,Z``, read by ``calibrate --pairs``).
    result_out : Path
        Where :meth:`save` writes the calibration JSON.
    T_init : (4, 4) float, optional
        Initial guess: shows the projection before 6 pairs exist, the perspective view and
        suggestions.
    config : CalibrationConfig
        Solver settings (those of ``calibrate``).
    inputs : dict, optional
        Input paths recorded in the result JSON.
    preview_px : int
        Longer side of the images served at first (the full size is served on zoom).
    """

    def __init__(
        self,
        image: NDArray[np.uint8],
        scan: Scan,
        intrinsics: CameraIntrinsics,
        *,
        out: Path,
        result_out: Path,
        T_init: ArrayLike | None = None,
        config: CalibrationConfig = CalibrationConfig(),
        inputs: dict[str, Any] | None = None,
        preview_px: int = 2048,
    ) -> None:
        self.image = np.asarray(image, dtype=np.uint8)
        H, W = self.image.shape[:2]
        self.intrinsics = intrinsics.for_image(W, H)
        self.scan = scan
        self.config = config
        self.out, self.result_out = Path(out), Path(result_out)
        self.T_init = None if T_init is None else as_transform(T_init, name="initial guess")
        self.inputs = dict(inputs or {})
        self.preview_px = int(preview_px)
        self.views = LidarViews(scan, self.intrinsics, self.T_init, n=config.flexion_n)
        self.pairs: dict[int, Pair] = {}
        self.suggestions: dict[int, Pair] = {}
        self.result: CalibrationResult | None = None
        self.error: str | None = None
        self.change: dict[str, float] | None = None
        self.revision = 0
        self.saved_revision: int | None = None
        self.saved: list[str] = []
        self._next_id = 1
        self._lock = threading.RLock()
        self._step = max(1, math.ceil(len(scan) / OVERLAY_POINTS))
        self._overlay_points = scan.points[:: self._step]
        self._projected: tuple[int, Any, NDArray[np.float64], NDArray[np.int64]] | None = None
        #: (revision, camera box on the panorama, mirror or None, the pose's source) under
        #: the current pose (or the rough one of the pairs)
        self._box: tuple[int, list[float] | None, bool | None, str | None] | None = None

    # ------------------------------------------------------------------ pose and solving

    @property
    def pose(self) -> NDArray[np.float64] | None:
        """The current ``T_camera_lidar``: the last solution, else the initial guess."""
        return self.result.T_camera_lidar if self.result is not None else self.T_init

    def correspondences(self) -> Correspondences2D3D:
        """The pairs in order; their "line numbers" are the pair ids the page shows."""
        ps = list(self.pairs.values())
        return Correspondences2D3D(
            np.array([[p.u, p.v] for p in ps]).reshape(-1, 2),
            np.array([p.point for p in ps]).reshape(-1, 3),
            np.array([p.id for p in ps], dtype=np.int64),
            "picked pairs",
        )

    def _solve(self) -> None:
        """Re-solve after a change (6 pairs on); keeps the error text when it fails."""
        self.revision += 1
        before = self.pose
        self.result, self.error = None, None
        if len(self.pairs) >= MIN_CORRESPONDENCES:
            try:
                self.result = solve_pnp(self.correspondences(), self.intrinsics, config=self.config)
            except FlexregError as e:
                self.error = str(e)
        after = self.pose
        self.change = None
        if self.result is not None and before is not None and after is not None:
            self.change = {
                "rotation_deg": rotation_error_deg(after, before),
                "translation_m": translation_error_m(after, before),
            }

    # ------------------------------------------------------------------ edits

    def _pixel(self, u: Any, v: Any) -> tuple[float, float]:
        uu, vv = _finite("u", u), _finite("v", v)
        W, H = self.image.shape[1], self.image.shape[0]
        if not (-0.5 <= uu <= W - 0.5 and -0.5 <= vv <= H - 0.5):
            raise InputError("camera click", f"({uu:g}, {vv:g}) lies outside the {W}x{H} image")
        return uu, vv

    def add_pair(self, u: Any, v: Any, mode: str, x: Any, y: Any) -> Pair:
        """Pair camera pixel ``(u, v)`` with the return nearest ``(x, y)`` on lidar view
        ``mode``; re-solve."""
        with self._lock:
            uu, vv = self._pixel(u, v)
            snap = self.views.snap(mode, _finite("x", x), _finite("y", y))
            pair = Pair(self._next_id, uu, vv, snap.point, snap.index)
            self._next_id += 1
            self.pairs[pair.id] = pair
            self._solve()
            return pair

    def _pair(self, pair_id: Any) -> Pair:
        try:
            return self.pairs[int(pair_id)]
        except (KeyError, ValueError, TypeError):
            raise InputError("pair", f"no pair with id {pair_id!r}") from None

    def move_pair(self, pair_id: Any, body: dict[str, Any]) -> Pair:
        """Move a pair's camera end (``u``, ``v``) and/or lidar end (``mode``, ``x``, ``y``)."""
        with self._lock:
            pair = self._pair(pair_id)
            if not ({"u", "v"} <= body.keys() or {"mode", "x", "y"} <= body.keys()):
                raise InputError("move", "give u,v (camera) and/or mode,x,y (lidar)")
            u, v = pair.u, pair.v
            if "u" in body or "v" in body:
                u, v = self._pixel(body.get("u"), body.get("v"))
            snap = None
            if "x" in body or "y" in body:
                snap = self.views.snap(
                    str(body.get("mode")), _finite("x", body.get("x")), _finite("y", body.get("y"))
                )
            pair.u, pair.v = u, v
            if snap is not None:
                pair.point, pair.index = snap.point, snap.index
            self._solve()
            return pair

    def delete_pair(self, pair_id: Any) -> None:
        """Remove a pair; re-solve."""
        with self._lock:
            del self.pairs[self._pair(pair_id).id]
            self._solve()

    def load_pairs(self, correspondences: Correspondences2D3D) -> None:
        """Start from the pairs of a ``--pairs`` file (all of them, in file order)."""
        with self._lock:
            idx = self.views.index_of(correspondences.points)
            for k in range(len(correspondences)):
                u, v = correspondences.pixels[k]
                pt = correspondences.points[k]
                near = np.linalg.norm(self.scan.points[idx[k]] - pt) < 1e-6
                pair = Pair(
                    self._next_id,
                    float(u),
                    float(v),
                    pt.copy(),
                    int(idx[k]) if near else -1,
                    int(correspondences.lines[k]),
                )
                self.pairs[pair.id] = pair
                self._next_id += 1
            self._solve()
            self.saved_revision = self.revision  # as on disk

    # ------------------------------------------------------------------ hover aids

    def snap(self, mode: str, x: Any, y: Any) -> dict[str, Any]:
        """Where a lidar click lands, and where the current pose predicts its camera partner."""
        with self._lock:
            s = self.views.snap(mode, _finite("x", x), _finite("y", y))
            predicted = None
            T = self.pose
            if T is not None:
                uv, z = project_points(s.point, self.intrinsics, T)
                if z[0] > 0 and np.isfinite(uv).all():
                    predicted = [float(uv[0, 0]), float(uv[0, 1])]
            return {
                "x": s.x,
                "y": s.y,
                "index": s.index,
                "point": s.point.tolist(),
                "range_m": s.range_m,
                "predicted_uv": predicted,
            }

    def predict_lidar(self, u: Any, v: Any, mode: str, *, radius_px: float = 8.0) -> Any:
        """The front-most lidar point projected within ``radius_px`` of camera pixel
        ``(u, v)`` under the current pose, located on view ``mode``; None without one."""
        from scipy.spatial import cKDTree  # heavy: ~0.1 s at import

        with self._lock:
            uu, vv = self._pixel(u, v)
            grid = self.views.grid(mode)
            T = self.pose
            if T is None:
                return None
            if self._projected is None or self._projected[0] != self.revision:
                P = self._overlay_points
                uv, z = project_points(P, self.intrinsics, T)
                ok = np.flatnonzero((z > 0) & np.isfinite(uv).all(axis=1))
                self._projected = (self.revision, cKDTree(uv[ok]), z[ok], ok)
            _, tree, z, ok = self._projected
            near = tree.query_ball_point([uu, vv], radius_px)
            if not near:
                return None
            k = int(ok[near[int(np.argmin(z[near]))]])
            point = self._overlay_points[k]
            xy = self.views.locate(point, [k * self._step], grid)[0]
            if not np.isfinite(xy).all():
                return None
            return {"x": float(xy[0]), "y": float(xy[1]), "point": point.tolist()}

    # ------------------------------------------------------------------ suggestions

    def suggest(self) -> list[Pair]:
        """Automatic proposals (:func:`flexreg.calibration.propose_correspondences`) around the
        current pose that agree with it and with the picked pairs, spread over the image.

        Raises
        ------
        InputError
            No pose yet (no initial guess and fewer than 6 solved pairs).
        """
        with self._lock:
            T = self.pose
            if T is None:
                raise InputError(
                    "suggestions", f"need an initial guess or {MIN_CORRESPONDENCES} solved pairs"
                )
            proposals = self._proposals(T)
            self.suggestions = {}
            for k in _spread(proposals.pixels, MAX_SUGGESTIONS):
                idx = int(self.views.index_of(proposals.points[k])[0])
                u, v = (float(x) for x in proposals.pixels[k])
                s = Pair(self._next_id, u, v, proposals.points[k], idx)
                self._next_id += 1
                self.suggestions[s.id] = s
            return list(self.suggestions.values())

    def _proposals(self, T: NDArray[np.float64]) -> Correspondences2D3D:
        """Proposals that agree with the current pose.

        Solved: searched within 4 x ``threshold_px`` (at least 10 px) of each point's projection
        and kept when within 2 x ``threshold_px`` of it. Initial guess only: searched within
        its stated uncertainty (``init_rotation_deg``, ``init_translation_m`` at the median
        depth), solved jointly with any picked pairs, and kept when they are inliers of a joint
        pose within twice that uncertainty of the guess (the plausibility test of the
        automatic mode); none otherwise.
        """
        cfg = self.config
        f = max(self.intrinsics.fx, self.intrinsics.fy)
        empty = Correspondences2D3D(np.zeros((0, 2)), np.zeros((0, 3)))
        if self.result is not None:
            radius = max(4.0 * cfg.threshold_px, 10.0)
        else:
            uv, z = project_points(self._overlay_points, self.intrinsics, T)
            zf = z[(z > 0) & np.isfinite(uv).all(axis=1)]
            z_med = float(np.median(zf)) if zf.size else 10.0
            radius = (
                1.25 * f * (math.radians(cfg.init_rotation_deg) + cfg.init_translation_m / z_med)
            )
        prop, _ = propose_correspondences(
            self.image, self.scan, self.intrinsics, T, radius_px=radius, config=cfg
        )
        if self.result is not None or len(prop) < MIN_CORRESPONDENCES:
            uv, z = project_points(prop.points, self.intrinsics, T)
            err = np.linalg.norm(uv - prop.pixels, axis=1)
            return prop.subset((z > 0) & (err <= 2.0 * cfg.threshold_px))
        joint = self.correspondences().concat(prop) if self.pairs else prop
        try:
            res = solve_pnp(joint, self.intrinsics, config=cfg)
        except (CalibrationError, InputError) as e:
            log.info("suggestions: no joint solution (%s)", e)
            return empty
        Tj = res.T_camera_lidar
        if (
            rotation_error_deg(Tj, T) > 2.0 * cfg.init_rotation_deg
            or translation_error_m(Tj, T) > 2.0 * cfg.init_translation_m
        ):
            log.info("suggestions: the proposals' joint pose is too far from the guess")
            return empty
        uv, z = project_points(prop.points, self.intrinsics, Tj)
        err = np.linalg.norm(uv - prop.pixels, axis=1)
        return prop.subset((z > 0) & (err <= res.threshold_px))

    def accept(self, suggestion_id: Any) -> Pair:
        """Make a suggestion a pair; re-solve."""
        with self._lock:
            try:
                s = self.suggestions.pop(int(suggestion_id))
            except (KeyError, ValueError, TypeError):
                raise InputError("suggestion", f"no suggestion with id {suggestion_id!r}") from None
            self.pairs[s.id] = s
            self._solve()
            return s

    def reject(self, suggestion_id: Any) -> None:
        """Drop a suggestion."""
        with self._lock:
            try:
                del self.suggestions[int(suggestion_id)]
            except (KeyError, ValueError, TypeError):
                raise InputError("suggestion", f"no suggestion with id {suggestion_id!r}") from None

    # ------------------------------------------------------------------ pictures

    def camera_png(self, *, full: bool = False) -> bytes:
        """The camera image as PNG (a preview unless ``full``)."""
        return encode_png(self.image if full else preview(self.image, self.preview_px))

    def lidar_png(self, mode: str, *, full: bool = False) -> bytes:
        """A lidar view as PNG (a preview unless ``full``)."""
        pic = self.views.picture(mode)
        return encode_png(pic if full else preview(pic, self.preview_px))

    def overlay_png(self, zoom: Any = 1.0) -> bytes:
        """The lidar points projected with the current pose (transparent PNG at the camera
        preview's size; fully transparent without a pose), drawn for ``zoom`` screen pixels
        per preview pixel (:func:`~flexreg.picker.views.overlay_rgba`)."""
        z = _finite("zoom", zoom)
        if not 1e-3 <= z <= 1e3:
            raise InputError("zoom", f"must be within 0.001 and 1000, got {zoom!r}")
        with self._lock:
            h, w = preview(self.image, self.preview_px).shape[:2]
            T = self.pose
            if T is None:
                return encode_png(np.zeros((h, w, 4), dtype=np.uint8))
            return encode_png(
                overlay_rgba(self._overlay_points, self.intrinsics, T, (w, h), zoom=z)
            )

    # ------------------------------------------------------------------ state and saving

    def _pair_dicts(self, pairs: list[Pair]) -> list[dict[str, Any]]:
        """The pairs (or suggestions) as the page shows them: both ends, the position on
        each lidar grid, residual and projection under the current pose, inlier flag."""
        res = self._residuals(pairs)
        pts = np.array([p.point for p in pairs]).reshape(-1, 3)
        idx = np.array([p.index for p in pairs], dtype=np.int64)
        grids = {g: self.views.locate(pts, idx, g) for g in ("panorama", "perspective")}
        inlier: dict[int, bool] = {}
        if self.result is not None:  # by pair id (the solver's line numbers)
            lines = self.result.correspondences.lines.tolist()
            inlier = dict(zip(lines, self.result.inlier_mask.tolist(), strict=True))
        out = []
        for k, p in enumerate(pairs):
            r = None if res is None else float(res[0][k])
            proj = None if res is None or not np.isfinite(res[1][k]).all() else res[1][k].tolist()
            out.append(
                {
                    "id": p.id,
                    "u": p.u,
                    "v": p.v,
                    "point": p.point.tolist(),
                    "range_m": float(np.linalg.norm(p.point)),
                    "line": p.line or None,
                    "lidar": {
                        g: xy[k].tolist() if np.isfinite(xy[k]).all() else None
                        for g, xy in grids.items()
                    },
                    "residual_px": r if r is not None and math.isfinite(r) else None,
                    "projected_uv": proj,
                    "inlier": inlier.get(p.id) if p.id in self.pairs else None,
                }
            )
        return out

    def _residuals(
        self, pairs: list[Pair]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
        """Reprojection error (pixels, inf behind the camera) and projected pixel of each
        pair under the current pose; None without a pose."""
        T = self.pose
        if T is None or not pairs:
            return None
        pts = np.array([p.point for p in pairs]).reshape(-1, 3)
        uv, z = project_points(pts, self.intrinsics, T)
        err = np.linalg.norm(uv - np.array([[p.u, p.v] for p in pairs]), axis=1)
        err[~(z > 0)] = np.inf
        return err, uv

    def state(self) -> dict[str, Any]:
        """Everything the page shows, JSON-ready."""
        with self._lock:
            pairs = list(self.pairs.values())
            sugg = list(self.suggestions.values())
            H, W = self.image.shape[:2]
            ph, pw = preview(self.image, self.preview_px).shape[:2]
            return {
                "revision": self.revision,
                "camera": {"width": W, "height": H, "preview": [pw, ph]},
                "lidar": {
                    "modes": self.views.modes,
                    "sizes": {m: list(self.views.size(m)) for m in self.views.modes},
                    "aspect": {
                        m: (1.0 if self.views.grid(m) == "perspective" else self.views.aspect)
                        for m in self.views.modes
                    },
                    "points": len(self.scan),
                    "camera_box": self._camera_box(),
                    "camera_view": self._camera_view(),
                    "mirror": self._mirror(),
                },
                "pairs": self._pair_dicts(pairs),
                "suggestions": self._pair_dicts(sugg),
                "preview_px": self.preview_px,
                "min_pairs": MIN_CORRESPONDENCES,
                "solution": self._solution(),
                "has_init": self.T_init is not None,
                "saved": self.saved_revision == self.revision,
                "saved_files": self.saved,
                "out": str(self.out),
                "result_out": str(self.result_out),
            }

    def _mirror(self) -> bool:
        """Whether the panorama should be shown left-right reversed to match the camera: with
        a pose, when the columns of the returns the camera sees run against their image ``u``;
        without one, for an equirectangular panorama (its columns turn counter-clockwise about
        +Z, the other way than an upright camera's ``u``)."""
        self._camera_box()
        assert self._box is not None
        return self._box[2] if self._box[2] is not None else self.views.mirror

    def rough_pose(self) -> NDArray[np.float64] | None:
        """Where the camera probably looks before a pose exists: the rotation that best turns
        the picked returns' directions onto their pixels' rays, with the camera at the
        lidar's centre (Wahba's problem, solved by SVD as Kabsch's; a camera a few
        centimetres from the scanner sees the scene at nearly the same bearings). None with
        fewer than 2 pairs or pairs whose returns lie in one direction."""
        if len(self.pairs) < 2:
            return None
        ps = list(self.pairs.values())
        uv = np.array([[p.u, p.v, 1.0] for p in ps])
        rays = uv @ np.linalg.inv(self.intrinsics.K).T
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        P = np.array([p.point for p in ps])
        n = np.linalg.norm(P, axis=1)
        if not (n > 0).all():
            return None
        P = P / n[:, None]
        if np.linalg.norm(np.cross(P[:, None], P[None]), axis=2).max() < math.radians(1.0):
            return None  # all returns in one direction: the turn about it is unknown
        U, _, Vt = np.linalg.svd(P.T @ rays)  # rays ~ R P
        d = np.sign(np.linalg.det(Vt.T @ U.T))
        T = np.eye(4)
        T[:3, :3] = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T
        return T

    def _view_pose(self) -> tuple[NDArray[np.float64] | None, str | None]:
        """The pose that places the camera's view on the panorama, and where it comes from:
        ``"solution"``, ``"initial guess"``, ``"pairs"`` (:meth:`rough_pose`) or None."""
        if self.pose is not None:
            return self.pose, "solution" if self.result is not None else "initial guess"
        T = self.rough_pose()
        return (T, "pairs") if T is not None else (None, None)

    def _camera_view(self) -> dict[str, Any]:
        """What the page says about where in the panorama the camera looks: the box of
        :meth:`_camera_box`, where it comes from and a sentence for the page."""
        box = self._camera_box()
        source = self._box[3] if self._box is not None else None
        n = len(self.pairs)
        if box is None and source is None:
            note = (
                "where the camera looks is not known yet: start with --init, or pick 2 pairs "
                "(a rough view is then outlined here)"
            )
        elif box is None:
            note = f"the {source} puts too few lidar returns into the camera image"
        elif source == "pairs":
            note = (
                f"camera's probable view from {n} pairs (camera taken at the scanner's "
                f"centre); solved from {MIN_CORRESPONDENCES} pairs"
            )
        else:
            note = f"camera's view under the {source}"
        return {"box": box, "source": source, "note": note}

    def _camera_box(self) -> list[float] | None:
        """``[x0, y0, x1, y1]`` on the panorama around the returns the current pose (or
        before one, :meth:`rough_pose`) puts in the camera image (1st to 99th percentile),
        for the page to outline and zoom to; None without a pose or such returns."""
        T, source = self._view_pose()
        if T is None:
            self._box = (self.revision, None, None, None)
            return None
        if self._box is not None and self._box[0] == self.revision:
            return self._box[1]
        self._box = (self.revision, None, None, source)
        W, H = self.image.shape[1], self.image.shape[0]
        uv, z = project_points(self._overlay_points, self.intrinsics, T)
        seen = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < W) & (uv[:, 1] >= 0) & (uv[:, 1] < H)
        k = np.flatnonzero(seen)
        xy = self.views.locate(self._overlay_points[k], k * self._step, "panorama")
        ok = np.isfinite(xy).all(axis=1)
        xy, u = xy[ok], uv[k[ok], 0]
        box, mirror = None, None
        if len(xy) >= 10:
            lo, hi = np.percentile(xy, [1, 99], axis=0)
            box = [float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])]
            if np.std(xy[:, 0]) > 0 and np.std(u) > 0:
                mirror = bool(np.corrcoef(xy[:, 0], u)[0, 1] < 0)
        self._box = (self.revision, box, mirror, source)
        return box

    def _solution(self) -> dict[str, Any] | None:
        T = self.pose
        if T is None:
            return {"error": self.error} if self.error else None
        rvec, _ = to_rvec_tvec(T)
        doc: dict[str, Any] = {
            "source": "solution" if self.result is not None else "initial guess",
            "T_camera_lidar": T.tolist(),
            "rotation_vector_deg": np.degrees(rvec).tolist(),
            "rotation_angle_deg": float(np.degrees(np.linalg.norm(rvec))),
            "translation_m": T[:3, 3].tolist(),
            "change": self.change,
            "error": self.error,
        }
        r = self.result
        if r is not None:
            doc["inliers"] = r.inliers
            doc["pairs"] = len(r.correspondences)
            doc["rmse_px"] = r.reprojection_rmse_px
            doc["threshold_px"] = r.threshold_px
            doc["quaternion_xyzw"] = r.quaternion_xyzw.tolist()
            doc["verdict"] = None if r.verdict is None else r.verdict.to_dict()
        return doc

    def save(self) -> list[Path]:
        """Write the pairs (``u,v,X,Y,Z``) and, when solved, the calibration JSON, now (also
        inside the command line's all-or-nothing block: a closed terminal loses nothing
        saved); both or neither, each complete on disk (:func:`_write_now`).

        Raises
        ------
        InputError
            No pairs yet; a file cannot be written (the files on disk stay as they were).
        """
        with self._lock:
            if not self.pairs:
                raise InputError(self.out, "no pairs to save yet")
            c = self.correspondences()
            comments = [
                f"flexreg pick {__version__}: {len(c)} pairs; camera pixel u,v (image as taken), "
                "lidar point X,Y,Z (metres, lidar frame)",
                *(f"{k}: {v}" for k, v in self.inputs.items() if v is not None),
            ]
            writers: list[tuple[Path, Callable[[Path], object]]] = [
                (self.out, lambda p: write_pairs(p, c.pixels, xyz=c.points, comments=comments))
            ]
            if self.result is not None:
                meta = self.result.to_dict()
                T = meta.pop("T_camera_lidar")
                meta = {
                    **self.inputs,
                    "pairs_file": str(self.out),
                    **meta,
                    "flexreg_version": __version__,
                }
                writers.append(
                    (
                        self.result_out,
                        lambda p: write_transform_json(p, T, key="T_camera_lidar", **meta),
                    )
                )
            _write_now(writers)
            self.saved_revision = self.revision
            self.saved = [str(p) for p, _ in writers]
            return [p for p, _ in writers]


def _write_now(writers: Sequence[tuple[Path, Callable[[Path], object]]]) -> list[Path]:
    """Write every ``(path, write)`` at once, all or none, durably: ``write(tmp)`` fills a
    temporary sibling of ``path``, which is flushed to disk (fsync) before the temporaries are
    renamed into place together (:class:`~flexreg.io.files.Outputs`, which puts back the
    earlier files when a rename fails); then the folders are flushed.

    Inside the command line's :func:`~flexreg.io.files.all_or_nothing` block the files are
    still written now, not at the block's end (the picker's Save must survive the terminal
    closing); the block's inputs stay protected.
    """
    outer = active_outputs()
    outputs = Outputs()
    try:
        for path, write in writers:
            if outer is not None:
                outer.check(Path(os.path.abspath(path)))
            outputs.stage(path, functools.partial(_write_synced, write))
        written = outputs.commit()
    except BaseException:
        outputs.abort()
        raise
    for folder in dict.fromkeys(p.parent for p in written):
        _fsync(folder)
    return written


def _write_synced(write: Callable[[Path], object], tmp: Path) -> None:
    """``write(tmp)`` outside any all-or-nothing block (its own atomic write lands on ``tmp``
    at once), then ``tmp`` flushed to disk."""
    contextvars.Context().run(write, tmp)
    _fsync(tmp)


def _fsync(path: Path) -> None:
    """Flush a file, or a folder's entries, to disk (folders: where the system allows it)."""
    flags = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) if path.is_dir() else os.O_RDONLY
    try:
        fd = os.open(path, flags)
    except OSError:
        if path.is_dir():  # folders cannot be opened on every system (Windows)
            return
        raise
    try:
        os.fsync(fd)
    except OSError:
        if not path.is_dir():
            raise
    finally:
        os.close(fd)


def _spread(pixels: NDArray[np.float64], k: int) -> list[int]:
    """Indices of up to ``k`` pixels picked greedily farthest from those already picked."""
    n = len(pixels)
    if n <= k:
        return list(range(n))
    centre = pixels.mean(axis=0)
    chosen = [int(np.argmax(np.linalg.norm(pixels - centre, axis=1)))]
    d = np.linalg.norm(pixels - pixels[chosen[0]], axis=1)
    while len(chosen) < k:
        j = int(np.argmax(d))
        chosen.append(j)
        d = np.minimum(d, np.linalg.norm(pixels - pixels[j], axis=1))
    return chosen
