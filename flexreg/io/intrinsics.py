"""Camera intrinsics (K, lens distortion, image size) and camera-lidar extrinsics on disk.

Readers, dispatched on the suffix by :func:`read_intrinsics`:

=====================  ===================================================================
file                   content
=====================  ===================================================================
``.yaml/.yml/.xml``    OpenCV ``FileStorage`` calibration (``camera_matrix``/``K``,
                       ``distortion_coefficients``/``D``, ``image_width``/``image_height``);
                       ROS ``camera_info`` YAML (``{rows, cols, data}`` matrices) too
``.json``              plain ``{"K", "distortion", "width", "height"}`` (what
                       ``CameraIntrinsics.to_dict()`` writes, also nested under
                       ``"intrinsics"``); flexreg's camera description
                       ``{"model": "pinhole", "fx", "fy", "cx", "cy"[, "skew"], "width",
                       "height"}`` (``PinholeCamera.to_dict()``), also nested under
                       ``"camera"`` as in the ``camera.json`` of ``flexreg synth``; or the
                       PJLab SensorsCalibration intrinsic JSON (``param.cam_K``,
                       ``param.cam_dist``, ``param.img_dist_w/h``)
``.txt``               KITTI calibration (``P0..P3``, ``R0_rect``, ``Tr_velo_to_cam``)
=====================  ===================================================================

Distortion coefficients are OpenCV's, in OpenCV's order ``(k1, k2, p1, p2[, k3[, k4, k5,
k6[, s1, s2, s3, s4[, tx, ty]]]])``; an empty vector means no distortion.

KITTI convention (made explicit here, because the calibration files leave it implicit): the
files give ``x_img = P2 @ R0_rect @ Tr_velo_to_cam @ X_velo`` with ``P2 = K2 [I | t2]``, i.e.
the image-2 camera is the *rectified* reference camera 0 shifted by ``t2 = K2^-1 P2[:, 3]``
(about 6 cm along x). So the image-2 camera frame is::

    T_cam2_velo = [I | t2] @ R0_rect @ Tr_velo_to_cam        (each padded to 4 x 4)

and the intrinsics are ``K2 = P2[:, :3]`` with no distortion (the images are rectified).
KITTI files hold no image size; it comes from the image (:meth:`CameraIntrinsics.for_image`).

Extrinsics (:func:`read_extrinsic`) are 4 x 4 ``T_camera_lidar`` (maps lidar points into the
camera frame): flexreg's calibration JSON, a JSON 4 x 4 list, the PJLab extrinsic JSON
(``param.sensor_calib.data``, which is ``T_camera_lidar``), a KITTI calibration file (see
above), or a 4 x 4 / 3 x 4 text matrix.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.core.camera import PinholeCamera
from flexreg.core.transforms import as_transform, nearest_rotation
from flexreg.errors import InputError
from flexreg.io.files import protect

__all__ = [
    "DISTORTION_LENGTHS",
    "CameraIntrinsics",
    "read_extrinsic",
    "read_intrinsics",
    "read_kitti_calib",
]

#: numbers of distortion coefficients OpenCV accepts
DISTORTION_LENGTHS = (0, 4, 5, 8, 12, 14)

_K_KEYS = ("camera_matrix", "K", "cameraMatrix", "camera_K", "cam_K", "M1", "intrinsic_matrix")
_D_KEYS = (
    "distortion_coefficients",
    "distortion",
    "dist_coeffs",
    "distCoeffs",
    "D",
    "dist",
    "cam_dist",
    "D1",
)
_W_KEYS = ("image_width", "width", "img_dist_w", "imageWidth")
_H_KEYS = ("image_height", "height", "img_dist_h", "imageHeight")
_SIZE_KEYS = ("image_size", "imageSize", "size")


@dataclass(frozen=True, eq=False)
class CameraIntrinsics:
    """Pinhole intrinsics with OpenCV lens distortion (paper eq. 1 plus distortion).

    Attributes
    ----------
    K : (3, 3) float64
        ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` in pixels; pixel centres at integer
        coordinates (OpenCV convention, see :mod:`flexreg.core.camera`).
    distortion : (D,) float64
        OpenCV distortion coefficients, ``D`` in :data:`DISTORTION_LENGTHS` (0: none).
    width, height : int or None
        Image size in pixels; None when the file does not say (KITTI).
    source : str
        File (or option) the intrinsics came from, for messages.

    Raises
    ------
    InputError
        K not an upper-triangular camera matrix with positive focal lengths, a distortion
        vector of a length OpenCV does not know, a non-positive size, or a principal point
        outside the image.

    Examples
    --------
    >>> c = CameraIntrinsics([[500, 0, 320], [0, 500, 240], [0, 0, 1]], [], 640, 480)
    >>> c.pinhole().project(np.array([[0.0, 0.0, 2.0]]))[0].tolist()
    [320.0]
    """

    K: NDArray[np.float64]
    distortion: NDArray[np.float64]
    width: int | None = None
    height: int | None = None
    source: str = "intrinsics"

    def __post_init__(self) -> None:
        src = self.source
        K = np.asarray(self.K, dtype=np.float64)
        if K.shape != (3, 3):
            raise InputError(src, f"K must be 3x3, got shape {K.shape}")
        if not np.isfinite(K).all():
            raise InputError(src, "K holds NaN or Inf")
        if not (K[1, 0] == 0 and K[2, 0] == 0 and K[2, 1] == 0 and abs(K[2, 2] - 1) < 1e-9):
            raise InputError(
                src, f"K must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]], got {K.tolist()}"
            )
        if not (K[0, 0] > 0 and K[1, 1] > 0):
            raise InputError(src, f"focal lengths must be positive, got fx={K[0, 0]}, fy={K[1, 1]}")
        d = np.asarray(self.distortion, dtype=np.float64).reshape(-1)
        if d.size not in DISTORTION_LENGTHS:
            raise InputError(
                src,
                f"{d.size} distortion coefficients; OpenCV takes "
                f"{', '.join(str(n) for n in DISTORTION_LENGTHS)}",
            )
        if not np.isfinite(d).all():
            raise InputError(src, "distortion coefficients hold NaN or Inf")
        if (self.width is None) != (self.height is None):
            raise InputError(src, "give both image width and height, or neither")
        w = h = None
        if self.width is not None and self.height is not None:
            w, h = _size(self.width, src, "width"), _size(self.height, src, "height")
            cx, cy = K[0, 2], K[1, 2]
            if not (-0.5 < cx < w - 0.5 and -0.5 < cy < h - 0.5):
                raise InputError(
                    src,
                    f"principal point ({cx:.1f}, {cy:.1f}) px lies outside the {w}x{h} image",
                )
        K.setflags(write=False)
        d.setflags(write=False)
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "distortion", d)
        object.__setattr__(self, "width", w)
        object.__setattr__(self, "height", h)

    def __repr__(self) -> str:
        size = "size unknown" if self.width is None else f"{self.width}x{self.height}"
        return (
            f"CameraIntrinsics(fx={self.fx:.2f}, fy={self.fy:.2f}, cx={self.K[0, 2]:.2f}, "
            f"cy={self.K[1, 2]:.2f}, {self.distortion.size} distortion coefficients, {size})"
        )

    @property
    def fx(self) -> float:
        """Focal length along u, pixels."""
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        """Focal length along v, pixels."""
        return float(self.K[1, 1])

    @property
    def has_distortion(self) -> bool:
        """True if any distortion coefficient is non-zero."""
        return bool(np.any(self.distortion != 0))

    @property
    def size(self) -> tuple[int, int] | None:
        """``(width, height)`` in pixels, or None when unknown."""
        if self.width is None or self.height is None:
            return None
        return (self.width, self.height)

    def for_image(self, width: int, height: int, *, image: str = "image") -> CameraIntrinsics:
        """These intrinsics checked against an image of ``width x height`` pixels.

        Returns intrinsics with that size (when the file gave none, as KITTI's) or raises
        :class:`InputError` naming ``image`` when the sizes differ.
        """
        if self.size is None:
            return CameraIntrinsics(self.K, self.distortion, int(width), int(height), self.source)
        if self.size != (int(width), int(height)):
            raise InputError(
                image,
                f"image is {width}x{height} px but the intrinsics ({self.source}) are for "
                f"{self.width}x{self.height}",
            )
        return self

    def pinhole(self) -> PinholeCamera:
        """The distortion-free :class:`PinholeCamera` with this K and size (needs the size)."""
        if self.width is None or self.height is None:
            raise InputError(self.source, "image size unknown; check against the image first")
        K = self.K
        return PinholeCamera(
            float(K[0, 0]),
            float(K[1, 1]),
            float(K[0, 2]),
            float(K[1, 2]),
            self.width,
            self.height,
            skew=float(K[0, 1]),
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready ``{"K", "distortion", "width", "height"}`` (what the JSON reader reads)."""
        return {
            "K": self.K.tolist(),
            "distortion": self.distortion.tolist(),
            "distortion_model": "opencv (k1, k2, p1, p2[, k3[, k4, k5, k6[, s1..s4[, tx, ty]]]])",
            "width": self.width,
            "height": self.height,
        }


def _size(value: Any, src: str, what: str) -> int:
    try:
        f = float(value)
    except (TypeError, ValueError):
        raise InputError(src, f"image {what} must be a number, got {value!r}") from None
    if not (math.isfinite(f) and f == int(f) and f > 0):
        raise InputError(src, f"image {what} must be a positive integer, got {value!r}")
    return int(f)


# ----------------------------------------------------------------------------- readers


def read_intrinsics(path: str | PathLike[str], *, kitti_camera: int = 2) -> CameraIntrinsics:
    """Read camera intrinsics from an OpenCV YAML/XML, JSON or KITTI calibration file.

    Parameters
    ----------
    path : path-like
        See the module table for the formats.
    kitti_camera : {0, 1, 2, 3}
        Which KITTI projection matrix ``P<n>`` to use (2: the left colour camera, image_2).

    Returns
    -------
    CameraIntrinsics
        Size None for KITTI files (it comes from the image).

    Raises
    ------
    InputError
        Missing file, unknown suffix, unreadable content, or invalid K / distortion / size.
    """
    p = Path(path)
    protect(p)
    if not p.is_file():
        raise InputError(p, "no such file")
    suffix = p.suffix.lower()
    if suffix in (".yaml", ".yml", ".xml"):
        return _read_opencv(p)
    if suffix == ".json":
        return _intrinsics_from_json(_load_json(p), p)
    if suffix == ".txt":
        return read_kitti_calib(p, camera=kitti_camera)[0]
    raise InputError(p, f"unknown intrinsics suffix {suffix or '(none)'!r}; use .yaml, .json, .txt")


def _load_json(p: Path) -> Any:
    try:
        return json.loads(p.read_text(errors="replace"))
    except json.JSONDecodeError as e:
        raise InputError(p, f"invalid JSON: {e.msg} (line {e.lineno})") from None


def _matrix(value: Any, p: Path, what: str) -> NDArray[np.float64]:
    """A nested list, flat list or ``{"data": ...}`` dict as a float64 array."""
    if isinstance(value, dict):
        if "data" not in value:
            raise InputError(p, f"{what}: expected a list or a dict with 'data'")
        value = value["data"]
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(p, f"{what} must hold only numbers") from None
    return a


def _first(d: dict[str, Any], keys: tuple[str, ...]) -> Any:
    for k in keys:
        if k in d:
            return d[k]
    return None


def _intrinsics_from_json(doc: Any, p: Path) -> CameraIntrinsics:
    if not isinstance(doc, dict):
        raise InputError(p, "expected a JSON object with K (camera matrix)")
    d: dict[str, Any] = doc
    if "intrinsics" in d and isinstance(d["intrinsics"], dict):  # flexreg calibration JSON
        d = d["intrinsics"]
    elif _first(d, _K_KEYS) is None and isinstance(d.get("camera"), dict):  # synth camera.json
        d = {**d, **d["camera"]}
    elif _first(d, _K_KEYS) is None and len(d) == 1:  # PJLab: {"<name>": {"param": {...}}}
        inner = next(iter(d.values()))
        if isinstance(inner, dict):
            param = inner.get("param", inner)
            if isinstance(param, dict):
                d = param
    Kv = _first(d, _K_KEYS)
    if Kv is None and ("model" in d or "fx" in d):
        Kv = _pinhole_matrix(d, p)
    if Kv is None:
        raise InputError(
            p, f"no camera matrix (one of {', '.join(_K_KEYS[:4])}, or fx, fy, cx, cy)"
        )
    K = _matrix(Kv, p, "K")
    if K.size != 9:
        raise InputError(p, f"K must have 9 numbers, got {K.size}")
    Dv = _first(d, _D_KEYS)
    D = np.zeros(0) if Dv is None else _matrix(Dv, p, "distortion").reshape(-1)
    w, h = _first(d, _W_KEYS), _first(d, _H_KEYS)
    sz = _first(d, _SIZE_KEYS)
    if w is None and h is None and sz is not None:
        s = _matrix(sz, p, "image size").reshape(-1)
        if s.size != 2:
            raise InputError(p, "image size must be [width, height]")
        w, h = s[0], s[1]
    return CameraIntrinsics(
        K.reshape(3, 3), D, _opt_size(w, p, "width"), _opt_size(h, p, "height"), str(p)
    )


def _pinhole_matrix(d: dict[str, Any], p: Path) -> list[list[float]]:
    """K of flexreg's camera description (``PinholeCamera.to_dict()``: ``fx, fy, cx, cy`` and
    an optional ``skew``, pixels)."""
    model = d.get("model", "pinhole")
    if model != "pinhole":
        raise InputError(p, f"a {model!r} camera: calibration needs a pinhole camera")
    missing = [k for k in ("fx", "fy", "cx", "cy") if k not in d]
    if missing:
        raise InputError(p, f"pinhole camera without {', '.join(missing)}")
    v = {k: d[k] for k in ("fx", "fy", "cx", "cy")}
    skew = d.get("skew", 0.0)
    for k, x in (*v.items(), ("skew", skew)):
        if isinstance(x, bool) or not isinstance(x, int | float):
            raise InputError(p, f"{k} must be a number, got {x!r}")
    return [[v["fx"], skew, v["cx"]], [0.0, v["fy"], v["cy"]], [0.0, 0.0, 1.0]]


def _opt_size(value: Any, p: Path, what: str) -> int | None:
    return None if value is None else _size(value, str(p), what)


def _read_opencv(p: Path) -> CameraIntrinsics:
    import cv2

    text = p.read_text(errors="replace")
    try:
        if p.suffix.lower() == ".xml":
            fs = cv2.FileStorage(str(p), cv2.FILE_STORAGE_READ)
        else:  # OpenCV needs its %YAML header; plain YAML (ROS camera_info) lacks it
            if not text.lstrip().startswith("%YAML"):
                text = "%YAML:1.0\n---\n" + text
            fs = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    except (cv2.error, SystemError):
        raise InputError(p, "not a readable OpenCV YAML/XML file") from None
    if not fs.isOpened():
        raise InputError(p, "not a readable OpenCV YAML/XML file")
    try:
        root = fs.root()

        def node(keys: tuple[str, ...]) -> Any:
            for k in keys:
                n = root.getNode(k)
                if not n.empty() and not n.isNone():
                    return n
            return None

        Kn = node(_K_KEYS)
        if Kn is None:
            raise InputError(p, f"no camera matrix (one of {', '.join(_K_KEYS[:4])})")
        K = _fs_matrix(Kn, p, "camera matrix")
        if K.size != 9:
            raise InputError(p, f"camera matrix must have 9 numbers, got {K.size}")
        Dn = node(_D_KEYS)
        D = np.zeros(0) if Dn is None else _fs_matrix(Dn, p, "distortion").reshape(-1)
        wn, hn, sn = node(_W_KEYS), node(_H_KEYS), node(_SIZE_KEYS)
        w = h = None
        if wn is not None or hn is not None:
            w = None if wn is None else _fs_number(wn, p, "image width")
            h = None if hn is None else _fs_number(hn, p, "image height")
        elif sn is not None:
            s = _fs_matrix(sn, p, "image size").reshape(-1)
            if s.size != 2:
                raise InputError(p, "image size must be [width, height]")
            w, h = float(s[0]), float(s[1])
    except cv2.error:  # a node of another shape than the keys imply (a list as the root...)
        raise InputError(p, "not an OpenCV calibration (unexpected structure)") from None
    finally:
        fs.release()
    return CameraIntrinsics(
        K.reshape(3, 3), D, _opt_size(w, p, "width"), _opt_size(h, p, "height"), str(p)
    )


def _fs_number(n: Any, p: Path, what: str) -> float:
    if not (n.isInt() or n.isReal()):
        raise InputError(p, f"{what} must be a number")
    return float(n.real())


def _fs_matrix(n: Any, p: Path, what: str) -> NDArray[np.float64]:
    """An OpenCV matrix node, a ``{rows, cols, data}`` map (ROS) or a plain sequence."""
    import cv2

    if n.isMap():
        if not n.getNode("dt").empty():
            try:
                m = n.mat()
            except (cv2.error, SystemError):
                raise InputError(p, f"{what}: malformed opencv-matrix") from None
            if m is None:
                raise InputError(p, f"{what}: malformed opencv-matrix")
            return np.asarray(m, dtype=np.float64)
        n = n.getNode("data")
    if not n.isSeq():
        raise InputError(p, f"{what}: expected a matrix or a list of numbers")
    vals: list[float] = []
    for i in range(n.size()):
        e = n.at(i)
        if e.isSeq():  # nested rows
            vals.extend(e.at(j).real() for j in range(e.size()))
        elif e.isInt() or e.isReal():
            vals.append(e.real())
        else:
            raise InputError(p, f"{what} must hold only numbers")
    return np.asarray(vals, dtype=np.float64)


def _kitti_fields(p: Path) -> dict[str, NDArray[np.float64]]:
    fields: dict[str, NDArray[np.float64]] = {}
    for lineno, line in enumerate(p.read_text(errors="replace").splitlines(), start=1):
        if not line.strip():
            continue
        key, sep, rest = line.partition(":")
        if not sep:
            raise InputError(p, f"line {lineno}: expected 'NAME: numbers'")
        try:
            fields[key.strip()] = np.array([float(x) for x in rest.split()], dtype=np.float64)
        except ValueError:
            raise InputError(p, f"line {lineno}: {key.strip()} must hold only numbers") from None
        if not np.isfinite(fields[key.strip()]).all():
            raise InputError(p, f"line {lineno}: {key.strip()} holds a number that is not finite")
    return fields


def read_kitti_calib(
    path: str | PathLike[str], *, camera: int = 2
) -> tuple[CameraIntrinsics, NDArray[np.float64]]:
    """Read a KITTI calibration file: intrinsics of camera ``camera`` and ``T_camera_lidar``.

    Parameters
    ----------
    path : path-like
        KITTI ``calib/*.txt`` (object benchmark: ``P0..P3``, ``R0_rect``, ``Tr_velo_to_cam``;
        raw data ``calib_cam_to_cam.txt`` style keys ``P_rect_0n``/``R_rect_00`` are accepted).
    camera : {0, 1, 2, 3}
        Camera index; 2 is the left colour camera (``image_2``).

    Returns
    -------
    intrinsics : CameraIntrinsics
        ``K = P<n>[:, :3]``, no distortion (rectified images), size unknown.
    T_camera_lidar : (4, 4) float64
        ``[I | K^-1 P<n>[:, 3]] @ R0_rect @ Tr_velo_to_cam`` (see the module notes); maps
        Velodyne points (metres) into the rectified camera-``n`` frame. NaN-filled when the file
        has no ``Tr_velo_to_cam``.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(p, "no such file")
    if camera not in (0, 1, 2, 3):
        raise InputError("camera", f"KITTI camera index must be 0..3, got {camera}")
    f = _kitti_fields(p)
    P = f.get(f"P{camera}", f.get(f"P_rect_0{camera}"))
    if P is None:
        raise InputError(p, f"no P{camera} projection matrix: not a KITTI calibration file")
    if P.size != 12:
        raise InputError(p, f"P{camera} must have 12 numbers, got {P.size}")
    P = P.reshape(3, 4)
    K = P[:, :3].copy()
    intr = CameraIntrinsics(K, np.zeros(0), None, None, str(p))
    T_cam_rect = np.eye(4)
    T_cam_rect[:3, 3] = np.linalg.solve(K, P[:, 3])
    R0 = f.get("R0_rect", f.get("R_rect_00"))
    T_rect_ref = np.eye(4)
    if R0 is not None:
        if R0.size != 9:
            raise InputError(p, f"R0_rect must have 9 numbers, got {R0.size}")
        T_rect_ref[:3, :3] = R0.reshape(3, 3)
    Tr = f.get("Tr_velo_to_cam", f.get("Tr_velo_cam"))
    if Tr is None:
        return intr, np.full((4, 4), np.nan)
    if Tr.size != 12:
        raise InputError(p, f"Tr_velo_to_cam must have 12 numbers, got {Tr.size}")
    T_ref_velo = np.eye(4)
    T_ref_velo[:3, :] = Tr.reshape(3, 4)
    T = T_cam_rect @ T_rect_ref @ T_ref_velo
    return intr, _rigid(T, p, "KITTI camera-lidar transform")


def _rigid(T: ArrayLike, p: Path, what: str) -> NDArray[np.float64]:
    """Validate a rigid transform; re-orthonormalise rotations stored with ~7 digits."""
    M = np.asarray(T, dtype=np.float64)
    if M.shape != (4, 4) or not np.isfinite(M).all():
        raise InputError(p, f"{what} must be a finite 4x4 matrix")
    R = M[:3, :3]
    if np.allclose(R @ R.T, np.eye(3), atol=1e-3) and np.linalg.det(R) > 0:
        M = M.copy()
        M[:3, :3] = nearest_rotation(R)
    return as_transform(M, name=f"{p}: {what}")


def read_extrinsic(path: str | PathLike[str], *, kitti_camera: int = 2) -> NDArray[np.float64]:
    """Read a camera-lidar extrinsic ``T_camera_lidar`` (maps lidar points into the camera frame).

    Accepted: flexreg's calibration JSON (``T_camera_lidar``), a JSON object with
    ``T_camera_lidar``/``extrinsic`` or a bare 4 x 4 list, the PJLab extrinsic JSON
    (``param.sensor_calib``), a KITTI calibration file (``Tr_velo_to_cam`` with ``R0_rect`` and
    ``P<kitti_camera>``, see the module notes), or a text file of 4 x 4 (or 3 x 4) numbers.
    Rotations stored with few digits (KITTI, PJLab) are re-orthonormalised by SVD.

    Returns
    -------
    (4, 4) float64
    """
    p = Path(path)
    protect(p)
    if not p.is_file():
        raise InputError(p, "no such file")
    suffix = p.suffix.lower()
    if suffix == ".json":
        doc = _load_json(p)
        M = _extrinsic_from_json(doc, p)
        return _rigid(M, p, "T_camera_lidar")
    text = p.read_text(errors="replace")
    if "Tr_velo_to_cam" in text or "Tr_velo_cam" in text:
        T = read_kitti_calib(p, camera=kitti_camera)[1]
        return T
    rows = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        try:
            rows.append([float(x) for x in line.replace(",", " ").split()])
        except ValueError:
            raise InputError(p, f"line {lineno}: expected numbers") from None
    if len(rows) == 3:
        rows.append([0.0, 0.0, 0.0, 1.0])
    if len(rows) != 4 or any(len(r) != 4 for r in rows):
        raise InputError(p, "expected a 4x4 (or 3x4) matrix of numbers")
    return _rigid(rows, p, "T_camera_lidar")


def _as_4x4(value: Any, p: Path, what: str) -> NDArray[np.float64]:
    a = _matrix(value, p, what).reshape(-1)
    if a.size == 12:
        a = np.r_[a, 0.0, 0.0, 0.0, 1.0]
    if a.size != 16:
        raise InputError(p, f"{what} must be a 4x4 (or 3x4) matrix, got {a.size} numbers")
    return a.reshape(4, 4)


def _extrinsic_from_json(doc: Any, p: Path) -> NDArray[np.float64]:
    if isinstance(doc, list):
        return _as_4x4(doc, p, "T_camera_lidar")
    if not isinstance(doc, dict):
        raise InputError(p, "expected a JSON object or a 4x4 list")
    for key in ("T_camera_lidar", "extrinsic", "sensor_calib"):
        if key in doc:
            return _as_4x4(doc[key], p, key)
    if len(doc) == 1:  # PJLab: {"<name>": {"param": {"sensor_calib": {"data": 4x4}}}}
        inner = next(iter(doc.values()))
        if isinstance(inner, dict):
            param = inner.get("param", inner)
            if isinstance(param, dict) and "sensor_calib" in param:
                return _as_4x4(param["sensor_calib"], p, "sensor_calib")
    raise InputError(p, "no T_camera_lidar (or extrinsic / PJLab sensor_calib) entry")
