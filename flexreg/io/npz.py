"""NumPy ``.npy`` / ``.npz`` scans.

flexreg's own ``.npz`` layout (written by :func:`write`, read back exactly): ``points`` (N, 3)
float64, ``T_world_scanner`` (4, 4), optional ``intensity`` (N,), ``colors`` (N, 3) uint8,
``grid_shape`` (2,) and ``grid_index`` (N, 2), ``camera`` (JSON text) and ``name``. Several
scans in one file carry the prefix ``scan<i>/`` on every key.

Foreign layouts are accepted too:

- an ``.npy`` (or a single-array ``.npz``) holding (N, 3) or (N, 4+) points (fourth column =
  intensity) or an organised (H, W, 3) grid with NaN or zeros for no return;
- an ``.npz`` with one organised ``xyz*`` array, (H, W, 3) or a stack (F, H, W, 3) of frames
  (e.g. destaggered lidar sweeps), with an optional same-shaped ``intensity*`` /
  ``reflectivity*`` array;
- an ``.npz`` with ``<name>_vertices`` (N, 3) and ``<name>_grid_index`` (H, W) int (-1 = empty)
  pairs, one scan each, posed by an optional ``<name>_T_world_scan`` (4, 4).
"""

from __future__ import annotations

import json
import math
import zipfile
import zlib
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.core.budget import check_memory
from flexreg.core.camera import camera_from_dict
from flexreg.core.scan import Scan
from flexreg.errors import InputError

FORMAT_VERSION = 1


def _from_array(path: Path, a: NDArray[Any], name: str) -> Scan:
    if not np.issubdtype(a.dtype, np.number):
        raise InputError(path, f"array {name!r} is not numeric ({a.dtype})")
    _check_real(path, name, a.dtype)
    if a.ndim == 3 and a.shape[2] == 3:
        return Scan.from_organized(a.astype(np.float64), path=path, name=path.stem)
    if a.ndim == 2 and a.shape[1] >= 3:
        if len(a) == 0:
            raise InputError(path, "array holds no points")
        return Scan(
            points=a[:, :3],
            intensity=a[:, 3] if a.shape[1] >= 4 else None,
            path=path,
            name=path.stem,
        )
    raise InputError(path, f"array {name!r} of shape {a.shape} is neither (N, 3+) nor (H, W, 3)")


def _check_real(path: Path, name: str, dtype: np.dtype[Any]) -> None:
    """Refuse complex arrays: casting them to coordinates would drop their imaginary part."""
    if dtype.kind == "c":
        raise InputError(path, f"{name}: holds complex numbers ({dtype}); scans need real values")


def _array_bytes(path: Path, name: str, fh: Any, stored: int) -> int:
    """Bytes the ``.npy`` header read from ``fh`` declares; refuses object arrays and arrays
    larger than the ``stored`` bytes that follow the header."""
    try:
        major, _ = np.lib.format.read_magic(fh)
        read_header = (
            np.lib.format.read_array_header_1_0
            if major == 1
            else np.lib.format.read_array_header_2_0
        )
        shape, _, dtype = read_header(fh)
    except (ValueError, OSError, EOFError, SyntaxError) as e:
        raise InputError(path, f"not a readable NumPy file ({name}: {e})") from None
    if dtype.hasobject:
        raise InputError(path, f"{name}: holds Python objects, which are never loaded")
    _check_real(path, name, dtype)
    nbytes = math.prod(shape) * dtype.itemsize
    if nbytes > stored:
        raise InputError(
            path,
            f"{name}: the header declares shape {tuple(shape)} ({nbytes:,} bytes) but only "
            f"{max(stored, 0):,} bytes of data are stored (truncated or corrupt)",
        )
    return int(nbytes)


def check_declared(path: Path) -> None:
    """Compare every array header of a ``.npy`` / ``.npz`` with the bytes stored for it and
    with the memory budget, before any array is loaded.

    Raises
    ------
    InputError
        A header declaring more data than is stored, object arrays, or a corrupt archive;
        :class:`~flexreg.errors.MemoryBudgetError` when the arrays would not fit the budget.
    """
    total = 0
    if zipfile.is_zipfile(path):
        try:
            with zipfile.ZipFile(path) as z:
                for info in z.infolist():
                    if not info.filename.endswith(".npy"):
                        continue
                    with z.open(info) as fh:
                        total += _array_bytes(path, info.filename[:-4], fh, info.file_size)
        except (zipfile.BadZipFile, zlib.error, OSError, EOFError, NotImplementedError) as e:
            raise InputError(path, f"corrupt npz archive ({e})") from None
    else:
        with open(path, "rb") as fh:
            total = _array_bytes(path, "array", fh, path.stat().st_size)
    check_memory(2 * total, "loading its arrays", source=path)


def read(path: Path, **_: Any) -> list[Scan]:
    """Read scans from ``.npy`` / ``.npz`` (see the module docstring for the layouts)."""
    check_declared(path)
    try:
        data = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as e:
        raise InputError(path, f"not a readable NumPy file ({e})") from None
    if isinstance(data, np.ndarray):
        return [_from_array(path, data, "array")]
    try:
        return _read_npz(path, data)
    except (zipfile.BadZipFile, zlib.error, EOFError, OSError) as e:
        raise InputError(path, f"corrupt npz member ({e})") from None


def _read_npz(path: Path, data: Any) -> list[Scan]:
    with data:
        keys = set(data.files)
        prefixes = sorted(
            {k.split("/", 1)[0] + "/" for k in keys if "/" in k and k.endswith("/points")},
            key=lambda p: int(p[4:-1]) if p[4:-1].isdigit() else 0,
        )
        if "points" in keys:
            prefixes = [""]
        if not prefixes:
            if len(keys) == 1:
                (k,) = keys
                return [_from_array(path, data[k], k)]
            foreign = _foreign_npz(path, data)
            if foreign is not None:
                return foreign
            raise InputError(
                path,
                f"no 'points', organised 'xyz' or '<name>_vertices' + '<name>_grid_index' arrays "
                f"(keys: {', '.join(sorted(keys))})",
            )
        try:
            return [_scan_from_npz(path, data, p) for p in prefixes]
        except (KeyError, ValueError, TypeError) as e:
            if isinstance(e, InputError):
                raise
            raise InputError(path, f"inconsistent flexreg npz ({e})") from None


def _foreign_npz(path: Path, data: Any) -> list[Scan] | None:
    """Organised ``xyz`` stacks and ``vertices`` + ``grid_index`` pairs (module docstring)."""
    keys = sorted(data.files)
    names = [k[: -len("_vertices")] for k in keys if k.endswith("_vertices")]
    names = [n for n in names if f"{n}_grid_index" in keys]
    if names:
        scans = []
        for n in names:
            v = np.asarray(data[f"{n}_vertices"], dtype=np.float64)
            g = np.asarray(data[f"{n}_grid_index"])
            if (
                v.ndim != 2
                or v.shape[1] != 3
                or g.ndim != 2
                or not np.issubdtype(g.dtype, np.integer)
            ):
                raise InputError(path, f"{n}: vertices must be (N, 3) and grid_index (H, W) int")
            if g.max() >= len(v):
                raise InputError(path, f"{n}: grid index {g.max()} beyond {len(v)} vertices")
            rows, cols = np.nonzero(g >= 0)
            pose = data[f"{n}_T_world_scan"] if f"{n}_T_world_scan" in keys else np.eye(4)
            scans.append(
                Scan(
                    points=v[g[rows, cols]],
                    grid_shape=g.shape,
                    grid_index=np.stack([rows, cols], axis=1),
                    T_world_scanner=pose,
                    path=path,
                    name=n,
                )
            )
        return scans
    xyz_keys = [
        k
        for k in keys
        if k.lower().startswith("xyz") and data[k].ndim in (3, 4) and data[k].shape[-1] == 3
    ]
    if len(xyz_keys) != 1:
        return None
    xyz = np.asarray(data[xyz_keys[0]], dtype=np.float64)
    frames = xyz[None] if xyz.ndim == 3 else xyz
    inten = None
    for k in keys:
        if k.lower().startswith(("intensity", "reflectivity")) and data[k].shape == xyz.shape[:-1]:
            inten = np.asarray(data[k], dtype=np.float32)
            inten = inten[None] if xyz.ndim == 3 else inten
            break
    return [
        Scan.from_organized(
            f,
            intensity=None if inten is None else inten[i],
            path=path,
            name=path.stem if len(frames) == 1 else f"{path.stem}#{i}",
        )
        for i, f in enumerate(frames)
    ]


def _scan_from_npz(path: Path, data: Any, p: str) -> Scan:
    keys = set(data.files)

    def get(k: str) -> Any:
        return data[p + k] if p + k in keys else None

    grid_shape = _grid_shape(path, p + "grid_shape", get("grid_shape"))
    camera = get("camera")
    name = get("name")
    pose = get("T_world_scanner")
    return Scan(
        points=data[p + "points"],
        intensity=get("intensity"),
        colors=get("colors"),
        grid_shape=grid_shape,
        grid_index=get("grid_index"),
        T_world_scanner=np.eye(4) if pose is None else pose,
        camera=None if camera is None else camera_from_dict(json.loads(str(camera))),
        path=path,
        name=str(name) if name is not None else path.stem,
    )


def _grid_shape(path: Path, key: str, a: Any) -> tuple[int, int] | None:
    """``(rows, cols)`` from a ``grid_shape`` member (None when absent); refuses anything but
    two integers."""
    if a is None:
        return None
    if a.shape != (2,) or not np.issubdtype(a.dtype, np.integer):
        raise InputError(path, f"{key} must be two integers (rows, cols), got {a.dtype} {a.shape}")
    return int(a[0]), int(a[1])


def write(path: Path, scans: list[Scan], *, compress: bool = True, **_: Any) -> None:
    """Write scans in flexreg's ``.npz`` layout (compressed unless ``compress=False``)."""
    arrays: dict[str, Any] = {"format_version": np.array(FORMAT_VERSION)}
    for i, s in enumerate(scans):
        p = "" if len(scans) == 1 else f"scan{i}/"
        arrays[p + "points"] = s.points
        arrays[p + "T_world_scanner"] = s.T_world_scanner
        arrays[p + "name"] = np.array(s.name)
        if s.intensity is not None:
            arrays[p + "intensity"] = s.intensity
        if s.colors is not None:
            arrays[p + "colors"] = s.colors
        if s.grid_shape is not None:
            arrays[p + "grid_shape"] = np.array(s.grid_shape, dtype=np.int64)
            arrays[p + "grid_index"] = s.grid_index
        if s.camera is not None:
            arrays[p + "camera"] = np.array(json.dumps(s.camera.to_dict()))
    with open(path, "wb") as f:
        (np.savez_compressed if compress else np.savez)(f, **arrays)
