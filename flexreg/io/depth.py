"""16-bit depth / range PNG images with a camera (TUM: 5000 units per metre; Kinect: mm)."""

from __future__ import annotations

import json
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.core.budget import check_memory
from flexreg.core.camera import Camera, DepthKind, PinholeCamera, SphericalCamera, camera_from_dict
from flexreg.core.range_image import from_depth, to_scan
from flexreg.core.scan import GRID_CELL_BYTES, Scan
from flexreg.errors import InputError
from flexreg.io.files import atomic_write, protect, write_png

TUM_DEPTH_SCALE = 1.0 / 5000.0  # metres per unit of TUM RGB-D depth PNGs
MM_DEPTH_SCALE = 1.0e-3


def read_depth_png(
    path: str | PathLike[str], *, depth_scale: float = 1.0, invalid_values: tuple[int, ...] = (0,)
) -> NDArray[np.float64]:
    """Read a single-channel 16-bit depth PNG into metres (an 8-bit image is refused).

    Parameters
    ----------
    path : path-like
    depth_scale : float
        Metres per stored unit (1/5000 for TUM, 0.001 for millimetres).
    invalid_values : tuple of int
        Stored values meaning "no reading" (0 always; 7-Scenes also uses 65535).

    Returns
    -------
    (H, W) float64, metres; NaN where there is no reading.
    """
    import cv2

    p = Path(path)
    if not p.is_file():
        raise InputError(p, "no such file")
    if not (np.isfinite(depth_scale) and depth_scale > 0):
        raise InputError(
            p, f"depth scale must be a positive number of metres per unit, got {depth_scale}"
        )
    check_image_size(p)
    raw = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
    if raw is None:
        raise InputError(p, "not a readable PNG image")
    if raw.ndim != 2:
        raise InputError(p, f"depth image must have one channel, got {raw.shape[2]}")
    if raw.dtype == np.uint8:  # 255 levels: a picture (or a Flexion image), not depths
        raise InputError(
            p,
            "an 8-bit image, not a depth image: depth PNGs hold 16-bit values (an image "
            "written by 'flexreg convert' or a photo?)",
        )
    if raw.dtype != np.uint16:
        raise InputError(p, f"depth image must be 16 bit, got {raw.dtype}")
    d = raw.astype(np.float64) * depth_scale
    bad = np.isin(raw, np.asarray((*invalid_values, 0), dtype=raw.dtype))
    d[bad] = np.nan
    return d


def image_size(path: Path) -> tuple[int, int] | None:
    """``(width, height)`` a PNG's header declares (None: not a PNG; its reader decides)."""
    try:
        with open(path, "rb") as f:
            head = f.read(24)
    except OSError as e:
        raise InputError(path, f"cannot read: {e.strerror or e}") from None
    if len(head) < 24 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        return None
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")


def check_image_size(path: Path) -> None:
    """Refuse a PNG whose declared size would not fit the memory budget, before decoding it."""
    size = image_size(path)
    if size is None:
        return
    w, h = size
    if w == 0 or h == 0:
        raise InputError(path, f"PNG header declares an empty {w} x {h} image")
    check_memory(w * h * GRID_CELL_BYTES, f"its {w} x {h} image", source=path)


def sidecar_path(path: Path) -> Path:
    """The camera sidecar of a depth image: ``<stem>.camera.json`` beside it."""
    return path.with_name(path.stem + ".camera.json")


def read_sidecar(path: Path) -> dict[str, Any]:
    """Read a depth image's camera sidecar.

    The JSON holds ``camera`` (``PinholeCamera``/``SphericalCamera.to_dict()``) and optionally
    ``depth_scale`` (metres per unit), ``depth_kind`` (``"z"``/``"range"``) and
    ``invalid_values`` (stored values meaning no return).

    Returns
    -------
    dict
        Keyword arguments for :func:`read`: ``camera`` and whichever of the others are given.
    """
    side = sidecar_path(path)
    protect(side)
    try:
        doc = json.loads(side.read_text())
    except OSError as e:
        raise InputError(side, f"cannot read: {e.strerror or e}") from None
    except ValueError as e:
        raise InputError(side, f"not valid JSON ({e})") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("camera"), dict):
        raise InputError(side, "a camera sidecar needs a 'camera' object (the intrinsics)")
    try:
        opts: dict[str, Any] = {"camera": camera_from_dict(doc["camera"])}
    except InputError as e:
        raise InputError(side, f"camera: {e.problem}") from None
    except (ValueError, KeyError, TypeError) as e:
        what = f"missing field {e}" if isinstance(e, KeyError) else str(e)
        raise InputError(side, f"camera: not a valid camera ({what})") from None
    if "depth_scale" in doc:
        scale = doc["depth_scale"]
        if (
            isinstance(scale, bool)
            or not isinstance(scale, (int, float))
            or not (np.isfinite(scale) and scale > 0)
        ):
            raise InputError(
                side, f"depth_scale must be a positive number of metres per unit, got {scale!r}"
            )
        opts["depth_scale"] = float(scale)
    if "depth_kind" in doc:
        if doc["depth_kind"] not in ("z", "range"):
            raise InputError(side, f'depth_kind must be "z" or "range", got {doc["depth_kind"]!r}')
        opts["depth_kind"] = doc["depth_kind"]
    if "invalid_values" in doc:
        vals = doc["invalid_values"]
        if not isinstance(vals, list) or not all(
            isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= 65535 for v in vals
        ):
            raise InputError(
                side, f"invalid_values must be a list of integers 0..65535, got {vals!r}"
            )
        opts["invalid_values"] = tuple(vals)
    return opts


def read(
    path: Path,
    *,
    camera: Camera | None = None,
    depth_scale: float | None = None,
    depth_kind: DepthKind | None = None,
    invalid_values: tuple[int, ...] | None = None,
) -> list[Scan]:
    """Read a depth/range PNG as a gridded :class:`Scan` (``read_scan`` entry point).

    Parameters
    ----------
    camera : PinholeCamera or SphericalCamera, optional
        A depth image is not a point cloud without its intrinsics: when not given they come
        from the sidecar ``<stem>.camera.json`` (see :func:`read_sidecar`), whose other
        settings then serve as defaults. The image size must match the camera's.
    depth_scale : float
        Metres per stored unit (default 1, or the sidecar's).
    depth_kind : {"z", "range"}, optional
        Default ``"z"`` for pinhole, ``"range"`` for equirectangular.
    invalid_values : tuple of int
        Stored values meaning no return (0 always).
    """
    if camera is None:
        if not sidecar_path(path).is_file():
            raise InputError(
                path,
                "a depth image needs its camera intrinsics (--pinhole or --equirect, or a "
                f"{sidecar_path(path).name} sidecar)",
            )
        side = read_sidecar(path)
        camera = side["camera"]
        depth_scale = side.get("depth_scale", 1.0) if depth_scale is None else depth_scale
        depth_kind = side.get("depth_kind") if depth_kind is None else depth_kind
        if invalid_values is None:
            invalid_values = side.get("invalid_values", (0,))
    depth_scale = 1.0 if depth_scale is None else depth_scale
    invalid_values = (0,) if invalid_values is None else invalid_values
    assert camera is not None
    d = read_depth_png(path, depth_scale=depth_scale, invalid_values=invalid_values)
    if d.shape != camera.shape:
        raise InputError(
            path,
            f"image is {d.shape[1]}x{d.shape[0]} but the intrinsics are for "
            f"{camera.width}x{camera.height}",
        )
    if isinstance(camera, SphericalCamera) and depth_kind == "z":
        raise InputError(
            path, "an equirectangular image stores range; depth kind 'z' is pinhole-only"
        )
    if isinstance(camera, PinholeCamera) and depth_kind not in (None, "z", "range"):
        raise InputError(path, f"depth kind must be 'z' or 'range', got {depth_kind!r}")
    img = from_depth(d, camera, depth_kind=depth_kind)
    return [to_scan(img, path=path, name=path.stem)]


def write_depth_png(
    path: str | PathLike[str],
    depth_m: NDArray[np.floating],
    camera: PinholeCamera,
    *,
    depth_scale: float,
) -> list[Path]:
    """Write a pinhole depth image as a 16-bit PNG with its camera sidecar, so that
    :func:`read` (``read_scan``, ``flexreg register``) reads it back as a gridded scan.

    Parameters
    ----------
    path : path-like
        The ``.png``; ``<stem>.camera.json`` (camera, ``depth_scale``, ``depth_kind = "z"``)
        goes beside it.
    depth_m : (H, W) float, metres
        Orthographic depth ``z`` (paper eq. 2); NaN, 0 or negative: no reading (stored 0).
    camera : PinholeCamera
        Its size must be the image's.
    depth_scale : float
        Metres per stored unit (1e-5: 10 µm steps up to 0.65 m; TUM 2e-4; Kinect 1e-3).

    Returns
    -------
    list of Path
        The PNG and the sidecar.

    Raises
    ------
    InputError
        A size that does not match the camera, a bad scale, or a depth beyond 65535 units.
    """
    p = Path(path)
    d = np.asarray(depth_m, dtype=np.float64)
    if d.shape != camera.shape:
        raise InputError(
            p,
            f"depth is {d.shape[1]}x{d.shape[0]} but the camera is {camera.width}x{camera.height}",
        )
    if not (np.isfinite(depth_scale) and depth_scale > 0):
        raise InputError(p, f"depth scale must be a positive number of metres, got {depth_scale}")
    valid = np.isfinite(d) & (d > 0)
    units = np.zeros(d.shape, dtype=np.uint16)
    if valid.any():
        top = float(d[valid].max())
        if top / depth_scale > 65535:
            raise InputError(
                p, f"depth {top:.4g} m does not fit 16 bits at {depth_scale:g} m per unit"
            )
        units[valid] = np.clip(np.rint(d[valid] / depth_scale), 1, 65535).astype(np.uint16)
    write_png(p, units)
    side = sidecar_path(p)
    doc = {"camera": camera.to_dict(), "depth_scale": float(depth_scale), "depth_kind": "z"}
    text = json.dumps(doc, indent=2) + "\n"
    atomic_write(side, lambda tmp: tmp.write_text(text))
    return [p, side]


def camera_for_image(
    path: str | PathLike[str],
    *,
    pinhole: tuple[float, float, float, float] | None = None,
    equirect: tuple[float, float] | None = None,
) -> Camera | None:
    """Camera for a depth image from command-line style intrinsics; size from the image.

    Parameters
    ----------
    path : path-like
        The PNG (only its header is needed for the size).
    pinhole : (fx, fy, cx, cy), optional
        Pixels.
    equirect : (theta_min, theta_max), optional
        Polar range in radians; the azimuth spans a full turn (reference convention).

    Returns
    -------
    PinholeCamera, SphericalCamera or None (neither given).
    """
    import cv2

    if pinhole is not None and equirect is not None:
        raise InputError(path, "give either pinhole or equirectangular intrinsics, not both")
    if pinhole is None and equirect is None:
        return None
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise InputError(path, "not a readable PNG image")
    h, w = img.shape[:2]
    if pinhole is not None:
        fx, fy, cx, cy = (float(x) for x in pinhole)
        return PinholeCamera(fx, fy, cx, cy, w, h)
    assert equirect is not None
    return SphericalCamera.from_reference(w, h, float(equirect[0]), float(equirect[1]))
