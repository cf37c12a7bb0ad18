"""Depth sequences on disk: TUM RGB-D, 7-Scenes, a folder of depth PNGs, or a folder of scans.

:func:`read_sequence` looks at a folder, decides which layout it holds, checks every list file
and every frame file named in it, and returns a :class:`Sequence`: the frames in time order
with their timestamps, the camera, the depth scale and (when the folder has one) the ground
truth trajectory. Frames are loaded one at a time (:meth:`Sequence.range_image`,
:meth:`Sequence.color_image`), so long sequences never sit in memory at once.

==================  ==========================================================================
layout              what the folder holds
==================  ==========================================================================
``tum``             ``depth.txt`` (+ ``rgb.txt``, ``groundtruth.txt``), lines ``timestamp
                    file``; depth PNGs in 1/5000 m; colour associated to depth by timestamp
                    (:func:`flexreg.core.trajectory.associate`: nearest first, less than
                    ``max_dt_s`` apart, each used once). ``flexreg synth --rgbd-frames N``
                    writes this layout to ``<out>/rgbd`` (with a ``camera.json``); its
                    output folder itself is accepted too.
``7scenes``         ``frame-XXXXXX.depth.png`` in millimetres (65535 = no reading),
                    ``frame-XXXXXX.pose.txt`` (4x4 camera-to-world), ``frame-XXXXXX.color.*``
``depth-folder``    depth PNGs (+ intrinsics file, optional ``groundtruth.txt``)
``scans``           scan files of any format :func:`flexreg.io.read_scan` reads
==================  ==========================================================================

Intrinsics (pinhole, pixels) come from, in this order: the ``intrinsics`` argument; a
``camera.json`` in the folder (``{"camera": {...}}`` as ``flexreg synth`` and ``flexreg
project`` write it); ``camera-intrinsics.txt`` / ``intrinsics.txt`` (a 3x3 matrix K, or
``fx fy cx cy``); per-image ``<stem>.camera.json`` sidecars; and finally the published
defaults of the layout: TUM's recommended ``525 525 319.5 239.5`` and the 7-Scenes
``585 585 320 240``. A plain depth folder without intrinsics is an error.
"""

from __future__ import annotations

import itertools
import json
import logging
import math
import re
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from flexreg.core.camera import Camera, DepthKind, PinholeCamera, camera_from_dict
from flexreg.core.range_image import RangeImage, from_depth, from_grid
from flexreg.core.scan import Scan
from flexreg.core.trajectory import MAX_DT_S, Trajectory, associate
from flexreg.core.transforms import as_transform, nearest_rotation
from flexreg.errors import InputError
from flexreg.io.depth import TUM_DEPTH_SCALE, read_depth_png, read_sidecar
from flexreg.io.formats import FORMATS
from flexreg.io.scans import read_scan
from flexreg.io.trajectory import read_trajectory

log = logging.getLogger(__name__)

SequenceKind = Literal["tum", "7scenes", "depth-folder", "scans"]
KINDS: tuple[str, ...] = ("tum", "7scenes", "depth-folder", "scans")

#: TUM RGB-D: the intrinsics the benchmark recommends for its (registered) depth images when
#: no calibration is given (metres per depth unit: :data:`flexreg.io.depth.TUM_DEPTH_SCALE`)
TUM_DEFAULT_INTRINSICS = (525.0, 525.0, 319.5, 239.5)
#: 7-Scenes: millimetres, 65535 = no reading, intrinsics published with the data set
SEVEN_SCENES_DEPTH_SCALE = 1.0e-3
SEVEN_SCENES_INVALID = 65535
SEVEN_SCENES_INTRINSICS = (585.0, 585.0, 320.0, 240.0)
#: frame rate assumed where a layout has no timestamps (7-Scenes: Kinect at 30 Hz)
DEFAULT_RATE_HZ = 30.0

_SEVEN = re.compile(r"^frame-(\d+)\.depth\.png$", re.IGNORECASE)
_COLOR_SUFFIXES = (".color.png", ".color.jpg", ".color.jpeg")
_INTRINSICS_FILES = ("camera-intrinsics.txt", "intrinsics.txt")


@dataclass(frozen=True)
class Frame:
    """One frame of a sequence.

    Attributes
    ----------
    index : int
        Position in the sequence (0-based, time order).
    timestamp : float, seconds
    depth : Path
        Depth PNG (or scan file, for a folder of scans).
    color : Path or None
        Colour image of the same instant, if the sequence has one.
    source : str
        Where the frame was listed, for error messages: ``"depth.txt line 7"`` or the file name.
    """

    index: int
    timestamp: float
    depth: Path
    color: Path | None = None
    source: str = ""


@dataclass(eq=False)
class Sequence:
    """A depth sequence: frames in time order, how to read them, and the ground truth.

    Attributes
    ----------
    root : Path
        The folder.
    kind : {"tum", "7scenes", "depth-folder", "scans"}
    frames : tuple of Frame
    camera : PinholeCamera or None
        Intrinsics of the depth images (None for a folder of scans: each scan brings its grid).
    depth_scale : float
        Metres per stored depth unit.
    depth_kind : {"z", "range"}
        What the depth PNGs store.
    invalid_values : tuple of int
        Stored depth values meaning no reading (0 always).
    groundtruth : Trajectory or None
        ``T_world_camera`` poses with timestamps, when the folder has them.
    intrinsics_source : str
        Where the intrinsics came from (file name, ``"argument"`` or ``"default"``).
    """

    root: Path
    kind: str
    frames: tuple[Frame, ...]
    camera: PinholeCamera | None
    depth_scale: float = 1.0
    depth_kind: DepthKind = "z"
    invalid_values: tuple[int, ...] = (0,)
    groundtruth: Trajectory | None = None
    intrinsics_source: str = ""

    def __len__(self) -> int:
        return len(self.frames)

    def __repr__(self) -> str:
        gt = "with" if self.groundtruth is not None else "no"
        colour = "colour" if self.has_color else "no colour"
        return f"Sequence({self.kind}, {len(self)} frames, {colour}, {gt} ground truth)"

    @property
    def timestamps(self) -> NDArray[np.float64]:
        """(N,) float64 frame timestamps, seconds."""
        return np.array([f.timestamp for f in self.frames], dtype=np.float64)

    @property
    def has_color(self) -> bool:
        """True when every frame has a colour image."""
        return bool(self.frames) and all(f.color is not None for f in self.frames)

    def frame(self, i: int) -> RangeImage | Scan:
        """Frame ``i`` as it is stored: the organised points of a depth image
        (:meth:`range_image`) or, for a folder of scans, the :class:`Scan` itself (readers do
        not project; :func:`flexreg.stages.projection.range_image` does)."""
        if self.kind == "scans":
            return read_scan(self.frames[i].depth)
        return self.range_image(i)

    def range_image(self, i: int) -> RangeImage:
        """The organised 3D points of depth frame ``i`` (camera frame, metres), or of a scan
        frame with a native grid.

        Raises
        ------
        InputError
            The depth file is missing or unreadable, or its size disagrees with the camera; a
            scan frame without a grid (project it, or use :meth:`frame`).
        """
        frame = self.frames[i]
        if self.kind == "scans":
            scan = read_scan(frame.depth)
            if not scan.has_grid:
                raise InputError(
                    frame.depth,
                    "an unstructured scan has no range image of its own: project it "
                    "(flexreg.stages.projection.range_image(sequence.frame(i)))",
                )
            return from_grid(scan)
        assert self.camera is not None
        d = read_depth_png(
            frame.depth, depth_scale=self.depth_scale, invalid_values=self.invalid_values
        )
        if d.shape != self.camera.shape:
            raise InputError(
                frame.depth,
                f"image is {d.shape[1]}x{d.shape[0]} but the intrinsics are for "
                f"{self.camera.width}x{self.camera.height}",
            )
        return from_depth(d, self.camera, depth_kind=self.depth_kind)

    def color_image(self, i: int) -> NDArray[np.uint8]:
        """(H, W) uint8 grey version of frame ``i``'s colour image.

        Raises
        ------
        InputError
            The frame has no colour image, or it cannot be read.
        """
        import cv2

        frame = self.frames[i]
        if frame.color is None:
            raise InputError(
                frame.source or frame.depth, "frame has no colour image in this sequence"
            )
        if not frame.color.is_file():
            raise InputError(frame.color, "no such file")
        img = cv2.imread(str(frame.color), cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise InputError(frame.color, "not a readable image")
        return np.asarray(img, dtype=np.uint8)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description (no per-frame data)."""
        return {
            "root": str(self.root),
            "kind": self.kind,
            "frames": len(self),
            "camera": None if self.camera is None else self.camera.to_dict(),
            "intrinsics_source": self.intrinsics_source,
            "depth_scale_m_per_unit": self.depth_scale,
            "depth_kind": self.depth_kind,
            "invalid_values": list(self.invalid_values),
            "color": self.has_color,
            "groundtruth": self.groundtruth is not None,
            "duration_s": float(self.frames[-1].timestamp - self.frames[0].timestamp)
            if self.frames
            else 0.0,
        }


# ------------------------------------------------------------------------------ reading


def read_sequence(
    path: str | PathLike[str],
    *,
    kind: str | None = None,
    intrinsics: tuple[float, float, float, float] | None = None,
    depth_scale: float | None = None,
    rate_hz: float | None = None,
    max_dt_s: float = MAX_DT_S,
    max_frames: int | None = None,
) -> Sequence:
    """Read (and check) a depth sequence folder.

    Parameters
    ----------
    path : path-like
        The folder (see the module table for the layouts).
    kind : {"tum", "7scenes", "depth-folder", "scans"}, optional
        Force a layout instead of detecting it.
    intrinsics : (fx, fy, cx, cy), optional
        Pinhole intrinsics in pixels; override what the folder says. The size comes from the
        first depth image.
    depth_scale : float, optional
        Metres per stored depth unit (default: 1/5000 TUM, 1/1000 7-Scenes, the
        ``camera.json``'s, else 1/1000 for a depth folder).
    rate_hz : float, optional
        Frame rate for layouts without timestamps (default 30 Hz).
    max_dt_s : float, seconds
        Largest timestamp difference for associating colour and depth (and the ground truth).
    max_frames : int, optional
        Keep only the first frames.

    Returns
    -------
    Sequence

    Raises
    ------
    InputError
        Not a folder, no recognisable layout, a malformed list line (file and line named), a
        listed or numbered frame file that is missing, timestamps that do not associate,
        missing intrinsics, or a malformed pose or ground-truth file.
    """
    root = Path(path)
    if not root.exists():
        raise InputError(root, "no such folder")
    if not root.is_dir():
        raise InputError(root, "a sequence is a folder (TUM RGB-D, 7-Scenes, depth PNGs, scans)")
    if depth_scale is not None and not (math.isfinite(depth_scale) and depth_scale > 0):
        raise InputError("depth_scale", f"must be a positive number of metres, got {depth_scale}")
    rate = DEFAULT_RATE_HZ if rate_hz is None else float(rate_hz)
    if not (math.isfinite(rate) and rate > 0):
        raise InputError("rate_hz", f"must be a positive frame rate, got {rate_hz}")
    if not (math.isfinite(max_dt_s) and max_dt_s > 0):
        raise InputError("max_dt_s", f"must be a positive number of seconds, got {max_dt_s}")
    if max_frames is not None and max_frames < 2:
        raise InputError("max_frames", f"odometry needs at least 2 frames, got {max_frames}")
    root = _synth_root(root)
    k = detect_kind(root) if kind is None else kind
    if k not in KINDS:
        raise InputError("kind", f"unknown sequence layout {kind!r}; known: {', '.join(KINDS)}")
    if k == "tum":
        seq = _read_tum(root, intrinsics, depth_scale, max_dt_s, max_frames)
    elif k == "7scenes":
        seq = _read_7scenes(root, intrinsics, depth_scale, rate, max_frames)
    elif k == "depth-folder":
        seq = _read_depth_folder(root, intrinsics, depth_scale, rate, max_frames)
    else:
        seq = _read_scans(root, rate, max_frames)
    if len(seq) < 2:
        raise InputError(root, f"a sequence needs at least 2 frames, found {len(seq)}")
    if seq.groundtruth is not None:
        _check_groundtruth(seq, max_dt_s)
    log.info("%s: %r", root, seq)
    return seq


def detect_kind(root: Path) -> str:
    """The layout of a sequence folder (see the module table).

    Raises
    ------
    InputError
        When the folder matches none of them.
    """
    if (root / "depth.txt").is_file():
        return "tum"
    names = [p.name for p in root.iterdir() if p.is_file()]
    if any(_SEVEN.match(n) for n in names):
        return "7scenes"
    if any(n.lower().endswith(".png") for n in names):
        return "depth-folder"
    scan_suffixes = set(FORMATS) - {".png"}
    if any(Path(n).suffix.lower() in scan_suffixes for n in names):
        return "scans"
    raise InputError(
        root,
        "not a sequence folder: expected depth.txt (TUM RGB-D), frame-XXXXXX.depth.png "
        "(7-Scenes), depth PNGs with intrinsics, or scan files",
    )


def _synth_root(root: Path) -> Path:
    """A ``flexreg synth`` output folder with an RGB-D sequence -> its ``rgbd`` subfolder."""
    gt = root / "gt.json"
    if not (root / "depth.txt").is_file() and (root / "rgbd" / "depth.txt").is_file():
        if gt.is_file():
            try:
                doc = json.loads(gt.read_text(errors="replace"))
            except json.JSONDecodeError:
                doc = {}
            if isinstance(doc, dict) and isinstance(doc.get("rgbd"), dict):
                return root / str(doc["rgbd"].get("folder", "rgbd"))
        return root / "rgbd"
    return root


def _natural_key(name: str) -> tuple[Any, ...]:
    """Sort key that orders embedded numbers by value (``f2`` before ``f10``)."""
    return tuple(int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name))


# ------------------------------------------------------------------------------ TUM


def read_list(path: Path) -> list[tuple[float, str, int]]:
    """Read a TUM list file (``rgb.txt``, ``depth.txt``): ``timestamp filename`` per line.

    Returns
    -------
    list of (timestamp s, file name, line number)

    Raises
    ------
    InputError
        Naming the file and line of a malformed entry (not two fields, a timestamp that is
        not a finite number, timestamps that go backwards).
    """
    if not path.is_file():
        raise InputError(path, "no such file")
    out: list[tuple[float, str, int]] = []
    for no, raw in enumerate(path.read_text(errors="replace").splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.split()
        if len(parts) != 2:
            raise InputError(path, f"line {no}: expected 'timestamp filename', got {line!r}")
        try:
            t = float(parts[0])
        except ValueError:
            raise InputError(path, f"line {no}: timestamp {parts[0]!r} is not a number") from None
        if not math.isfinite(t):
            raise InputError(path, f"line {no}: timestamp {parts[0]!r} is not finite")
        if out and t <= out[-1][0]:
            raise InputError(
                path, f"line {no}: timestamp {t:.6f} does not increase (previous {out[-1][0]:.6f})"
            )
        out.append((t, parts[1], no))
    if not out:
        raise InputError(path, "lists no frame")
    return out


def _read_tum(
    root: Path,
    intrinsics: tuple[float, float, float, float] | None,
    depth_scale: float | None,
    max_dt_s: float,
    max_frames: int | None,
) -> Sequence:
    depth_list = root / "depth.txt"
    depth = read_list(depth_list)
    if max_frames is not None:
        depth = depth[:max_frames]
    for _, name, no in depth:
        _require(root / name, depth_list, no)
    colour: dict[int, Path] = {}
    rgb_list = root / "rgb.txt"
    if rgb_list.is_file():
        rgb = read_list(rgb_list)
        i_depth, i_rgb = associate([d[0] for d in depth], [r[0] for r in rgb], max_dt_s=max_dt_s)
        if len(i_depth) == 0:
            raise InputError(
                rgb_list,
                f"no timestamp associates with depth.txt within {max_dt_s} s (rgb "
                f"{rgb[0][0]:.3f}..{rgb[-1][0]:.3f} s, depth {depth[0][0]:.3f}.."
                f"{depth[-1][0]:.3f} s)",
            )
        for i, j in zip(i_depth.tolist(), i_rgb.tolist(), strict=True):
            _require(root / rgb[j][1], rgb_list, rgb[j][2])
            colour[i] = root / rgb[j][1]
        if len(colour) < len(depth):
            log.info(
                "%s: %d of %d depth frames have a colour image within %g s",
                root,
                len(colour),
                len(depth),
                max_dt_s,
            )
    side = _camera_json(root)
    scale = depth_scale
    if scale is None:
        scale = float(side.get("depth_scale", TUM_DEPTH_SCALE)) if side else TUM_DEPTH_SCALE
    first = root / depth[0][1]
    camera, source = _intrinsics(root, first, intrinsics, side, TUM_DEFAULT_INTRINSICS)
    frames = tuple(
        Frame(i, t, root / name, colour.get(i), f"depth.txt line {no}")
        for i, (t, name, no) in enumerate(depth)
    )
    gt = None
    gt_file = root / "groundtruth.txt"
    if gt_file.is_file():
        gt = read_trajectory(gt_file, "tum", strict=False)
    return Sequence(
        root=root,
        kind="tum",
        frames=frames,
        camera=camera,
        depth_scale=scale,
        depth_kind=side.get("depth_kind", "z") if side else "z",
        invalid_values=(0,),
        groundtruth=gt,
        intrinsics_source=source,
    )


def _require(path: Path, listed_in: Path, line: int) -> None:
    if not path.is_file():
        raise InputError(listed_in, f"line {line}: {path.name}: no such file ({path})")


# ------------------------------------------------------------------------------ 7-Scenes


def _read_7scenes(
    root: Path,
    intrinsics: tuple[float, float, float, float] | None,
    depth_scale: float | None,
    rate_hz: float,
    max_frames: int | None,
) -> Sequence:
    numbered: dict[int, Path] = {}
    width = 6
    for p in root.iterdir():
        m = _SEVEN.match(p.name)
        if m and p.is_file():
            numbered[int(m.group(1))] = p
            width = len(m.group(1))
    ids = sorted(numbered)
    first_id = ids[0]
    expected = range(first_id, ids[-1] + 1)
    if len(ids) != len(expected):
        missing = sorted(set(expected) - set(ids))
        shown = ", ".join(f"frame-{k:0{width}d}.depth.png" for k in missing[:5])
        more = f" and {len(missing) - 5} more" if len(missing) > 5 else ""
        raise InputError(
            root / f"frame-{missing[0]:0{width}d}.depth.png",
            f"missing frame: the sequence numbers frames {first_id}..{ids[-1]} but "
            f"{shown}{more} do not exist",
        )
    if max_frames is not None:
        ids = ids[:max_frames]
    poses: list[NDArray[np.float64]] = []
    pose_files = [root / f"frame-{k:0{width}d}.pose.txt" for k in ids]
    have_poses = [p.is_file() for p in pose_files]
    if any(have_poses) and not all(have_poses):
        missing_pose = pose_files[have_poses.index(False)]
        raise InputError(missing_pose, "no such file (other frames have their pose file)")
    if all(have_poses):
        poses = [_read_pose_txt(p) for p in pose_files]
    frames = []
    for i, k in enumerate(ids):
        stem = f"frame-{k:0{width}d}"
        color = next(
            (root / (stem + s) for s in _COLOR_SUFFIXES if (root / (stem + s)).is_file()), None
        )
        frames.append(Frame(i, (k - first_id) / rate_hz, numbered[k], color, numbered[k].name))
    side = _camera_json(root)
    camera, source = _intrinsics(root, numbered[ids[0]], intrinsics, side, SEVEN_SCENES_INTRINSICS)
    gt = None
    if poses:
        gt = Trajectory(
            timestamps=np.array([f.timestamp for f in frames], dtype=np.float64),
            poses=np.stack(poses),
        )
    return Sequence(
        root=root,
        kind="7scenes",
        frames=tuple(frames),
        camera=camera,
        depth_scale=SEVEN_SCENES_DEPTH_SCALE if depth_scale is None else depth_scale,
        depth_kind="z",
        invalid_values=(0, SEVEN_SCENES_INVALID),
        groundtruth=gt,
        intrinsics_source=source,
    )


def _read_pose_txt(path: Path) -> NDArray[np.float64]:
    """A 4x4 camera-to-world matrix as 4 lines of 4 numbers (7-Scenes ``pose.txt``)."""
    rows: list[list[float]] = []
    for no, raw in enumerate(path.read_text(errors="replace").splitlines(), start=1):
        if not raw.strip():
            continue
        try:
            row = [float(x) for x in raw.split()]
        except ValueError:
            raise InputError(path, f"line {no}: expected 4 numbers, got {raw.strip()!r}") from None
        if len(row) != 4:
            raise InputError(path, f"line {no}: expected 4 numbers, got {len(row)}")
        rows.append(row)
    if len(rows) != 4:
        raise InputError(path, f"expected a 4x4 matrix (4 lines), got {len(rows)} lines")
    # KinectFusion poses are orthonormal to about 1e-6; re-orthonormalise what is close
    M = np.asarray(rows, dtype=np.float64)
    R = nearest_rotation(M[:3, :3])
    if np.linalg.det(R) < 0 or not np.allclose(M[:3, :3], R, atol=1e-3):
        raise InputError(path, "the 3x3 block is not a rotation")
    M[:3, :3] = R
    return as_transform(M, name=str(path))


# ------------------------------------------------------------------------------ depth PNGs


def _read_depth_folder(
    root: Path,
    intrinsics: tuple[float, float, float, float] | None,
    depth_scale: float | None,
    rate_hz: float,
    max_frames: int | None,
) -> Sequence:
    files = sorted(
        (
            p
            for p in root.iterdir()
            if p.is_file()
            and p.suffix.lower() == ".png"
            and not p.name.lower().endswith(_COLOR_SUFFIXES)
        ),
        key=lambda p: _natural_key(p.name),
    )
    if max_frames is not None:
        files = files[:max_frames]
    side = _camera_json(root)
    if not side and intrinsics is None and not _has_intrinsics_file(root):
        sidecar = files[0].with_name(files[0].stem + ".camera.json")
        if sidecar.is_file():
            opts = read_sidecar(files[0])
            side = dict(opts)
            side["source"] = sidecar.name
    camera, source = _intrinsics(root, files[0], intrinsics, side, None)
    named = [_stamp_from_name(p.stem) for p in files]
    stamps = [s for s in named if s is not None]
    if len(stamps) == len(files) and all(b > a for a, b in itertools.pairwise(stamps)):
        times = stamps
    else:
        times = [i / rate_hz for i in range(len(files))]
    frames = tuple(
        Frame(i, t, p, None, p.name) for i, (t, p) in enumerate(zip(times, files, strict=True))
    )
    scale = depth_scale
    if scale is None:
        scale = float(side.get("depth_scale", 1.0e-3)) if side else 1.0e-3
    gt = None
    gt_file = root / "groundtruth.txt"
    if gt_file.is_file():
        gt = read_trajectory(gt_file, "tum", strict=False)
    return Sequence(
        root=root,
        kind="depth-folder",
        frames=frames,
        camera=camera,
        depth_scale=scale,
        depth_kind=side.get("depth_kind", "z") if side else "z",
        invalid_values=tuple(side.get("invalid_values", (0,))) if side else (0,),
        groundtruth=gt,
        intrinsics_source=source,
    )


def _stamp_from_name(stem: str) -> float | None:
    """A timestamp in seconds when the file stem is a plain number (``1305031102.175304``)."""
    try:
        v = float(stem)
    except ValueError:
        return None
    return v if math.isfinite(v) else None


# ------------------------------------------------------------------------------ scans


def _read_scans(root: Path, rate_hz: float, max_frames: int | None) -> Sequence:
    suffixes = set(FORMATS) - {".png"}
    files = sorted(
        (p for p in root.iterdir() if p.is_file() and p.suffix.lower() in suffixes),
        key=lambda p: _natural_key(p.name),
    )
    if max_frames is not None:
        files = files[:max_frames]
    frames = tuple(Frame(i, i / rate_hz, p, None, p.name) for i, p in enumerate(files))
    gt = None
    gt_file = root / "groundtruth.txt"
    if gt_file.is_file():
        gt = read_trajectory(gt_file, "tum", strict=False)
    else:
        gt = _synth_lidar_truth(root, frames)
    return Sequence(root=root, kind="scans", frames=frames, camera=None, groundtruth=gt)


def _synth_lidar_truth(root: Path, frames: tuple[Frame, ...]) -> Trajectory | None:
    """Sensor poses of a ``flexreg synth --lidar-frames`` folder, from the ``gt.json`` beside
    it (or one level up), in frame order; None when there is none."""
    for gt_path in (root / "gt.json", root.parent / "gt.json"):
        if not gt_path.is_file():
            continue
        try:
            doc = json.loads(gt_path.read_text(errors="replace"))
        except json.JSONDecodeError as e:
            raise InputError(gt_path, f"invalid JSON: {e.msg} (line {e.lineno})") from None
        lidar = doc.get("lidar") if isinstance(doc, dict) else None
        if not isinstance(lidar, dict):
            continue
        by_name = {Path(str(f.get("file", ""))).name: f for f in lidar.get("frames", [])}
        if not all(f.depth.name in by_name for f in frames):
            continue
        poses = np.stack(
            [
                as_transform(by_name[f.depth.name]["T_world_sensor"], name=str(gt_path))
                for f in frames
            ]
        )
        return Trajectory(
            timestamps=np.array([f.timestamp for f in frames], dtype=np.float64), poses=poses
        )
    return None


# ------------------------------------------------------------------------------ intrinsics


def _camera_json(root: Path) -> dict[str, Any]:
    """Options of a ``camera.json`` in the folder: ``camera`` plus ``depth_scale``,
    ``depth_kind``, ``invalid_values`` when given; empty when there is no such file."""
    p = root / "camera.json"
    if not p.is_file():
        return {}
    try:
        doc = json.loads(p.read_text(errors="replace"))
        cam = camera_from_dict(doc["camera"])
    except json.JSONDecodeError as e:
        raise InputError(p, f"invalid JSON: {e.msg} (line {e.lineno})") from None
    except (KeyError, TypeError, ValueError) as e:
        raise InputError(p, f"not a camera description ({e})") from None
    if not isinstance(cam, PinholeCamera):
        raise InputError(p, "a depth sequence needs a pinhole camera")
    out: dict[str, Any] = {"camera": cam, "source": p.name}
    for key in ("depth_scale_m_per_unit", "depth_scale"):
        if key in doc:
            out["depth_scale"] = float(doc[key])
    if doc.get("depth_kind") in ("z", "range"):
        out["depth_kind"] = doc["depth_kind"]
    if "invalid_values" in doc:
        out["invalid_values"] = tuple(int(v) for v in doc["invalid_values"])
    return out


def _has_intrinsics_file(root: Path) -> bool:
    return any((root / n).is_file() for n in _INTRINSICS_FILES)


def read_intrinsics_txt(path: Path) -> tuple[float, float, float, float]:
    """``(fx, fy, cx, cy)`` from a text file holding a 3x3 matrix K or the four numbers."""
    try:
        vals = [float(x) for x in path.read_text(errors="replace").split()]
    except ValueError:
        raise InputError(path, "intrinsics must be numbers (a 3x3 K or fx fy cx cy)") from None
    if len(vals) == 9:
        K = np.asarray(vals).reshape(3, 3)
        if not np.allclose(K[2], [0.0, 0.0, 1.0]) or K[1, 0] != 0:
            raise InputError(path, f"not a camera matrix K: last row {K[2].tolist()}")
        return float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])
    if len(vals) == 4:
        return vals[0], vals[1], vals[2], vals[3]
    raise InputError(path, f"expected a 3x3 K or fx fy cx cy, got {len(vals)} numbers")


def _intrinsics(
    root: Path,
    first_depth: Path,
    given: tuple[float, float, float, float] | None,
    side: dict[str, Any],
    default: tuple[float, float, float, float] | None,
) -> tuple[PinholeCamera, str]:
    """The pinhole camera of the sequence and where it came from."""
    import cv2

    img = cv2.imread(str(first_depth), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise InputError(first_depth, "not a readable PNG image")
    h, w = img.shape[:2]

    def make(v: tuple[float, float, float, float], source: str) -> PinholeCamera:
        try:
            return PinholeCamera(float(v[0]), float(v[1]), float(v[2]), float(v[3]), w, h)
        except InputError as e:
            raise InputError(source, e.problem) from None

    if given is not None:
        if len(given) != 4:
            raise InputError("intrinsics", f"expected fx fy cx cy, got {len(given)} numbers")
        return make(given, "intrinsics"), "argument"
    if side:
        cam: Camera = side["camera"]
        if not isinstance(cam, PinholeCamera):
            raise InputError(root, "a depth sequence needs a pinhole camera")
        if cam.shape != (h, w):
            raise InputError(
                root / str(side.get("source", "camera.json")),
                f"intrinsics are for {cam.width}x{cam.height} but {first_depth.name} is {w}x{h}",
            )
        return cam, str(side.get("source", "camera.json"))
    for name in _INTRINSICS_FILES:
        p = root / name
        if p.is_file():
            return make(read_intrinsics_txt(p), str(p)), name
    if default is None:
        raise InputError(
            root,
            "no intrinsics: add camera.json or camera-intrinsics.txt (3x3 K or fx fy cx cy) "
            "or give them (--intrinsics FX FY CX CY)",
        )
    log.info("%s: no intrinsics file, using the data set's published %s", root, default)
    return make(default, "default"), "default"


def _check_groundtruth(seq: Sequence, max_dt_s: float) -> None:
    """The ground truth must associate with at least 3 frames, or it is of no use."""
    assert seq.groundtruth is not None
    ig, _ = associate(seq.groundtruth, seq.timestamps, max_dt_s=max_dt_s)
    if len(ig) < min(3, len(seq)):
        src = seq.root / "groundtruth.txt" if seq.kind != "7scenes" else seq.root
        raise InputError(
            src,
            f"ground truth associates with only {len(ig)} of {len(seq)} frames within "
            f"{max_dt_s} s (need at least 3): timestamps do not match",
        )
