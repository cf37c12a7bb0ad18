"""Writing files whole or not at all.

- :func:`atomic_write` writes one file through a temporary sibling renamed into place.
- :func:`write_all` runs several writers and removes what it wrote when one of them fails, so a
  command leaves all of its outputs or none.
- :func:`write_png` writes an image as PNG, atomically.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.errors import InputError

__all__ = ["atomic_write", "write_all", "write_png"]


def atomic_write(path: Path, write: Callable[[Path], object]) -> None:
    """Call ``write(tmp)`` on a temporary sibling of ``path``, then rename it into place.

    An :class:`InputError` the writer raises about the temporary file is re-raised naming
    ``path``, the file the caller asked for.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.partial{path.suffix}")
    try:
        write(tmp)
        tmp.replace(path)
    except InputError as e:
        if e.source == str(tmp):
            raise InputError(path, e.problem) from None
        raise
    finally:
        tmp.unlink(missing_ok=True)


def write_all(writers: Sequence[tuple[Path, Callable[[], Any]]]) -> None:
    """Run each ``(path, write)``; if one fails, remove the files already written here, so a
    command leaves all of its outputs or none.

    Raises
    ------
    InputError
        An ``OSError`` of a writer, naming its path (the writer's own errors pass unchanged).
    """
    done: list[Path] = []
    try:
        for path, write in writers:
            try:
                write()
            except OSError as e:
                raise InputError(path, f"cannot write: {e.strerror or e}") from e
            done.append(path)
    except BaseException:
        for p in done:
            p.unlink(missing_ok=True)
        raise


def write_png(path: Path, image: NDArray[np.uint8] | NDArray[np.uint16]) -> Path:
    """Write an 8- or 16-bit image (grey ``(H, W)`` or BGR ``(H, W, 3)``) as PNG, atomically.

    Raises
    ------
    InputError
        OpenCV cannot write the image (naming ``path``).
    """
    import cv2  # heavy: OpenCV loads in about a second

    def write(tmp: Path) -> None:
        if not cv2.imwrite(str(tmp), image):
            raise InputError(tmp, "cannot write the PNG file")

    atomic_write(path, write)
    return path
