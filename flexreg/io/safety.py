"""Which files an input brings along, and whether an output would land on one of them.

A scan file is not always alone: a depth PNG is read with its ``<stem>.camera.json`` sidecar,
a 3DTK ``.3d`` with its ``.pose``. An output must never replace any of them, however it is
spelled (relative path, symbolic link, hard link): :func:`same_file` compares files by identity,
:func:`input_files` lists a scan input with its companions, and :func:`find_clash` names the
first output that would overwrite an input. Commands check this before any work; the command
line's :func:`flexreg.io.files.all_or_nothing` block refuses such a write again, as a backstop.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

__all__ = ["find_clash", "input_files", "same_file", "written_files"]


def same_file(a: Path, b: Path) -> bool:
    """True when ``a`` and ``b`` are the same file (symbolic or hard links included), or the
    same path once resolved when either does not exist yet."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return Path(a).resolve() == Path(b).resolve()


def input_files(path: Path) -> list[Path]:
    """A scan input and the companion files its reader uses (that exist).

    ``.png``: ``<stem>.camera.json``; ``.3d``: ``<stem>.pose``.
    """
    p = Path(path)
    found = [p]
    suffix = p.suffix.lower()
    if suffix == ".png":
        found.append(p.with_name(p.stem + ".camera.json"))
    elif suffix == ".3d":
        found.append(p.with_suffix(".pose"))
    return [found[0], *(c for c in found[1:] if c.is_file())]


def written_files(path: Path, *, range_image: bool = False, keep_float: bool = False) -> list[Path]:
    """Every file an output option writes: ``path``, and with ``range_image`` (``flexreg
    project``) its ``.npz`` and ``.camera.json``, with ``keep_float`` (``flexreg convert``) its
    ``.npz``."""
    p = Path(path)
    files = [p]
    if range_image or keep_float:
        files.append(p.with_suffix(".npz"))
    if range_image:
        files.append(p.with_name(p.stem + ".camera.json"))
    return files


def find_clash(
    outputs: Iterable[tuple[str, Path]], inputs: Iterable[tuple[str, Path]]
) -> tuple[str, Path, str] | None:
    """The first output that is an input (or another output), if any.

    Parameters
    ----------
    outputs : iterable of (option, path)
        Each file a command would write, with the option that names it.
    inputs : iterable of (label, path)
        Each file it reads (label: ``"an input"``, ``"--truth"``, ``"the camera sidecar of
        a.png"``...).

    Returns
    -------
    (option, path, what) or None
        ``what`` is the label of the input (or the option of the earlier output) it clashes
        with.
    """
    seen = [(label, Path(p)) for label, p in inputs]
    for option, path in outputs:
        for label, other in seen:
            if same_file(path, other):
                return option, path, label
        seen.append((option, Path(path)))
    return None
