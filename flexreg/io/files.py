"""Writing files whole or not at all, and never over an input.

- :func:`all_or_nothing` opens the set of outputs of one command (:class:`Outputs`): every
  :func:`atomic_write` inside it writes a temporary sibling of its target, and the temporaries
  are renamed into place together when the block ends without an error; on an error (or
  Ctrl-C) they are removed, and the files already at the targets stay byte-identical. The
  command line runs every command inside one such block.
- :func:`replace_folder` makes a folder of results the block's own: when the block commits,
  the files an earlier run recorded as its own in the folder's manifest
  (:data:`MANIFEST`) and this block did not write again are removed, after the new ones are
  in place, and the manifest lists this block's files; anything else in the folder (a user's
  notes, photos, scans; an earlier result without a manifest) is left alone, and said so; on
  an error nothing is removed.
- :func:`protect` marks a file as an input of the running command: an output that resolves to
  it (symbolic links, hard links) is refused, whatever the command.
- :func:`atomic_write` writes one file through a temporary sibling renamed into place (at once
  outside a block, at the block's end inside one).
- :func:`write_all` runs several writers all or none (a block of its own outside a command).
- :func:`write_png` writes an image as PNG, atomically.
"""

from __future__ import annotations

import contextlib
import fcntl
import itertools
import json
import logging
import os
from collections.abc import Callable, Iterator, Sequence
from contextvars import ContextVar
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.errors import InputError

__all__ = [
    "LOCK",
    "MANIFEST",
    "Outputs",
    "all_or_nothing",
    "atomic_write",
    "discard",
    "protect",
    "read_manifest",
    "replace_folder",
    "superseded",
    "write_all",
    "write_png",
]

log = logging.getLogger(__name__)

#: the file in a folder of results that lists, relative to it, the files flexreg wrote there
MANIFEST = ".flexreg-outputs.json"
#: the file a run holds locked in its folder of results while it writes there
LOCK = ".flexreg.lock"

_ACTIVE: ContextVar[Outputs | None] = ContextVar("flexreg_outputs", default=None)
_COUNTER = itertools.count()


def _key(path: Path) -> tuple[int, int] | Path:
    """Identity of a file: (device, inode) when it exists (hard links, symbolic links and
    relative spellings all agree), else its resolved path."""
    try:
        st = path.stat()
    except OSError:
        return path.resolve()
    return (st.st_dev, st.st_ino)


def _temporary(path: Path) -> Path:
    """A fresh hidden sibling of ``path`` keeping its suffix (writers pick formats by it)."""
    return path.with_name(f".{path.stem}.{os.getpid()}-{next(_COUNTER)}.partial{path.suffix}")


class Outputs:
    """The outputs of one command: staged as temporaries, renamed into place together.

    Use through :func:`all_or_nothing`; library writers join it through :func:`atomic_write`.
    """

    def __init__(self) -> None:
        self._staged: dict[Path, Path] = {}  # target (absolute) -> temporary
        self._created: list[Path] = []  # folders made for the targets, outermost first
        self._inputs: dict[tuple[int, int] | Path, Path] = {}
        self._owned: dict[Path, tuple[str, ...]] = {}  # folder -> top-level names to keep
        self._locks: dict[Path, int] = {}  # folder -> descriptor of its held LOCK file

    @property
    def targets(self) -> list[Path]:
        """The files staged so far, in order."""
        return list(self._staged)

    def own(self, folder: str | os.PathLike[str], keep: tuple[str, ...] = ()) -> None:
        """Hold ``folder`` (:meth:`lock`) and, at :meth:`commit`, remove the files its
        manifest lists that this block did not write (never the top-level entries named in
        ``keep`` or the command's inputs), then the emptied folders."""
        path = Path(os.path.abspath(folder))
        self.lock(path)
        self._owned[path] = tuple(keep)

    def lock(self, folder: Path) -> None:
        """Hold ``folder`` for this block: an exclusive lock on its :data:`LOCK` file (the
        folder made if missing, as for an output), released when the block ends. Another run
        writing into the same folder meanwhile is refused.

        Raises
        ------
        InputError
            Another process holds the folder, or the lock file cannot be made.
        """
        if folder in self._locks:
            return
        path = folder / LOCK
        self._make_parent(path)
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as e:
            raise InputError(folder, f"cannot write here: {e.strerror or e}") from e
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            if os.fstat(fd).st_ino != os.stat(path).st_ino:  # released and removed meanwhile
                raise BlockingIOError
        except OSError:
            holder = os.read(fd, 32).decode("ascii", "replace").strip() or "?"
            os.close(fd)
            raise InputError(
                folder,
                f"another flexreg run (process {holder}) is writing its results here; wait "
                "for it to end or choose another output folder",
            ) from None
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        self._locks[folder] = fd

    def _unlock(self) -> None:
        """Release every held folder (the lock file removed while still held)."""
        for folder, fd in self._locks.items():
            with contextlib.suppress(OSError):
                (folder / LOCK).unlink()
            os.close(fd)
        self._locks.clear()

    def superseded(self, folder: str | os.PathLike[str]) -> list[str]:
        """The files (relative POSIX paths) of an owned ``folder``'s manifest that
        :meth:`commit` will remove as things stand: those an earlier run wrote that this block
        has not staged again (never a ``keep`` entry or an input); [] for a folder the block
        does not own."""
        path = Path(os.path.abspath(folder))
        if path not in self._owned:
            return []
        stale = self._stale(path, self._owned[path], set(self._staged))
        return [p.relative_to(path).as_posix() for p in stale if p.is_file() or p.is_symlink()]

    def _stale(self, folder: Path, keep: tuple[str, ...], written: set[Path]) -> list[Path]:
        """The files an earlier run recorded in ``folder``'s manifest that are not in
        ``written``, ``keep`` or the inputs, deepest first."""
        if not folder.is_dir():
            return []
        return [
            folder / rel
            for rel in sorted(read_manifest(folder), key=lambda r: -r.count("/"))
            if rel.split("/", 1)[0] not in keep
            and folder / rel not in written
            and not self._is_input(folder / rel)
        ]

    def _sweep(self, written: list[Path]) -> None:
        """In every owned folder: remove what the earlier run's manifest lists and this block
        did not write again (then the folders that emptied), leave everything else, and
        record this block's files in a new manifest."""
        keep_files = set(written)
        for folder, keep in self._owned.items():
            if not folder.is_dir():
                continue
            ours = sorted(p.relative_to(folder).as_posix() for p in written if folder in p.parents)
            for p in self._stale(folder, keep, keep_files):
                with contextlib.suppress(OSError):
                    if p.is_file() or p.is_symlink():
                        p.unlink()
                        log.info("removed %s (written by an earlier run)", p)
                    parent = p.parent
                    while parent != folder and not any(parent.iterdir()):
                        parent.rmdir()
                        parent = parent.parent
            mine = {*keep, MANIFEST, LOCK, *(r.split("/", 1)[0] for r in ours)}
            others = [e.name for e in sorted(folder.iterdir()) if e.name not in mine]
            if others:
                log.warning(
                    "%s: left %d entr%s flexreg did not write (%s)",
                    folder, len(others), "y" if len(others) == 1 else "ies",
                    ", ".join(others[:5]) + (", ..." if len(others) > 5 else ""),
                )  # fmt: skip
            tmp = _temporary(folder / MANIFEST)
            try:
                tmp.write_text(json.dumps({"files": ours}, indent=1) + "\n", encoding="utf-8")
                tmp.replace(folder / MANIFEST)
            except OSError as e:  # the results are in place; a later run then removes less
                tmp.unlink(missing_ok=True)
                log.warning("%s: cannot record the files written (%s)", folder / MANIFEST, e)
        self._owned.clear()

    def _is_input(self, path: Path) -> bool:
        return any(key in self._inputs for key in (_key(path), path.resolve()))

    def protect(self, path: str | os.PathLike[str]) -> None:
        """Refuse any output that is the file ``path`` (an input of the command)."""
        p = Path(path)
        self._inputs.setdefault(_key(p), p)
        if p.exists():  # also the spelling, for a file an output would create anew
            self._inputs.setdefault(p.resolve(), p)

    def check(self, path: Path) -> None:
        """Raise :class:`InputError` when ``path`` is an input of the command."""
        for key in (_key(path), path.resolve()):
            if key in self._inputs:
                raise InputError(
                    path, f"is also an input ({self._inputs[key]}); refusing to overwrite it"
                )

    def stage(self, path: Path, write: Callable[[Path], object]) -> None:
        """Call ``write(tmp)`` on a temporary sibling of ``path``; rename it at :meth:`commit`.

        Raises
        ------
        InputError
            ``path`` is an input, its folder cannot be made, or the writer fails with an
            ``OSError`` (naming ``path``); an :class:`InputError` about the temporary is
            re-raised naming ``path``.
        """
        path = Path(os.path.abspath(path))
        self.check(path)
        if path.is_dir():
            raise InputError(path, "is a folder, not a file")
        self._make_parent(path)
        tmp = _temporary(path)
        try:
            write(tmp)
        except InputError as e:
            tmp.unlink(missing_ok=True)
            if e.source == str(tmp):
                raise InputError(path, e.problem) from None
            raise
        except OSError as e:
            tmp.unlink(missing_ok=True)
            raise InputError(path, f"cannot write: {e.strerror or e}") from e
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
        if not tmp.is_file():
            raise InputError(path, "the writer produced no file")
        old = self._staged.pop(path, None)
        if old is not None:
            old.unlink(missing_ok=True)
        self._staged[path] = tmp

    def discard(self, path: Path) -> None:
        """Forget a staged output (its temporary is removed; the target stays as it was)."""
        tmp = self._staged.pop(Path(os.path.abspath(path)), None)
        if tmp is not None:
            tmp.unlink(missing_ok=True)

    def _make_parent(self, path: Path) -> None:
        missing = [d for d in (path.parent, *path.parent.parents) if not d.exists()]
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise InputError(path, f"cannot make its folder: {e.strerror or e}") from e
        self._created += [d for d in reversed(missing) if d not in self._created]

    def commit(self) -> list[Path]:
        """Rename every temporary into place; if one rename fails, put back what the earlier
        ones replaced (the previous files, kept as hard links meanwhile) and raise."""
        done: list[tuple[Path, Path | None]] = []  # target, backup of its previous content
        try:
            for path, tmp in self._staged.items():
                backup = None
                if path.exists():
                    backup = path.with_name(f".{path.name}.{os.getpid()}.previous")
                    try:
                        os.link(path, backup)
                    except OSError:
                        backup = None
                try:
                    tmp.replace(path)
                except OSError as e:
                    if backup is not None:
                        backup.unlink(missing_ok=True)
                    raise InputError(path, f"cannot write: {e.strerror or e}") from e
                done.append((path, backup))
        except BaseException:
            for path, backup in reversed(done):
                with contextlib.suppress(OSError):
                    if backup is not None:
                        backup.replace(path)
                    else:
                        path.unlink()
            self.abort()
            raise
        for _, backup in done:
            if backup is not None:
                backup.unlink(missing_ok=True)
        written = list(self._staged)
        self._staged.clear()
        self._created.clear()
        self._sweep(written)
        self._unlock()
        return written

    def abort(self) -> None:
        """Remove the temporaries and the folders made for them (when empty)."""
        self._unlock()
        for tmp in self._staged.values():
            with contextlib.suppress(OSError):
                tmp.unlink(missing_ok=True)
        self._staged.clear()
        for d in reversed(self._created):  # innermost first
            with contextlib.suppress(OSError):
                d.rmdir()
        self._created.clear()
        self._owned.clear()


def active_outputs() -> Outputs | None:
    """The :class:`Outputs` of the running :func:`all_or_nothing` block, if any."""
    return _ACTIVE.get()


@contextlib.contextmanager
def all_or_nothing() -> Iterator[Outputs]:
    """Write every output of the block at its end, or none of them.

    Nested blocks join the outermost one (its end renames everything). On an exception
    (including ``KeyboardInterrupt``) every temporary is removed and the targets keep their
    previous content.

    Examples
    --------
    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> with all_or_nothing():
    ...     atomic_write(d / "a.txt", lambda tmp: tmp.write_text("a"))
    ...     (d / "a.txt").exists()
    False
    >>> (d / "a.txt").read_text()
    'a'
    """
    outer = _ACTIVE.get()
    if outer is not None:
        yield outer
        return
    outputs = Outputs()
    token = _ACTIVE.set(outputs)
    try:
        yield outputs
    except BaseException:
        outputs.abort()
        raise
    finally:
        _ACTIVE.reset(token)
    outputs.commit()


def protect(*paths: str | os.PathLike[str] | None) -> None:
    """Mark input files of the running command: no output of it may overwrite them.

    Does nothing outside an :func:`all_or_nothing` block (a library call).
    """
    outputs = _ACTIVE.get()
    if outputs is None:
        return
    for p in paths:
        if p is not None:
            outputs.protect(p)


def read_manifest(folder: Path) -> list[str]:
    """The files (relative POSIX paths) an earlier run recorded in ``folder``'s
    :data:`MANIFEST`; none when there is no manifest or it is unreadable (then nothing is
    taken as flexreg's). Paths that leave the folder are ignored."""
    try:
        doc = json.loads((folder / MANIFEST).read_text(encoding="utf-8"))
        files = doc["files"] if isinstance(doc, dict) else []
    except (OSError, ValueError, KeyError, RecursionError):
        return []
    return [
        f
        for f in files
        if isinstance(f, str) and f and not f.startswith("/") and ".." not in f.split("/")
    ]


def replace_folder(folder: str | os.PathLike[str], keep: tuple[str, ...] = ()) -> None:
    """Make ``folder`` the running block's own (:meth:`Outputs.own`): when the block commits,
    files an earlier run left in it (and did not get written again) are removed; top-level
    entries named in ``keep`` (a cache) stay. Nothing happens outside a block.

    Examples
    --------
    >>> import json, tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> _ = (d / "frame_0009.png").write_text("old")
    >>> _ = (d / MANIFEST).write_text(json.dumps({"files": ["frame_0009.png"]}))
    >>> with all_or_nothing():
    ...     replace_folder(d)
    ...     atomic_write(d / "frame_0000.png", lambda tmp: tmp.write_text("new"))
    >>> sorted(p.name for p in d.iterdir())
    ['.flexreg-outputs.json', 'frame_0000.png']
    """
    outputs = _ACTIVE.get()
    if outputs is not None:
        outputs.own(folder, keep)


def superseded(folder: str | os.PathLike[str]) -> list[str]:
    """The files an earlier run wrote into ``folder`` that the running block will remove when
    it ends, as things stand (:meth:`Outputs.superseded`): those the block has not written
    again, after :func:`replace_folder` made the folder its own; none outside a block.

    Examples
    --------
    >>> import json, tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> for name in ("poses.json", "merged.ply", MANIFEST):
    ...     _ = (d / name).write_text(json.dumps({"files": ["poses.json", "merged.ply"]}))
    >>> with all_or_nothing():
    ...     replace_folder(d)
    ...     atomic_write(d / "poses.json", lambda tmp: tmp.write_text("{}"))
    ...     superseded(d)
    ['merged.ply']
    >>> sorted(p.name for p in d.iterdir())
    ['.flexreg-outputs.json', 'poses.json']
    """
    outputs = _ACTIVE.get()
    return [] if outputs is None else outputs.superseded(folder)


def discard(*paths: str | os.PathLike[str]) -> None:
    """Drop staged outputs of the running block (one item of a batch that failed halfway);
    nothing happens outside a block or for paths not staged."""
    outputs = _ACTIVE.get()
    if outputs is not None:
        for p in paths:
            outputs.discard(Path(p))


def atomic_write(path: Path, write: Callable[[Path], object]) -> None:
    """Call ``write(tmp)`` on a temporary sibling of ``path``, then rename it into place.

    Inside an :func:`all_or_nothing` block the rename waits for the block's end. An
    :class:`InputError` the writer raises about the temporary file is re-raised naming
    ``path``, the file the caller asked for; an ``OSError`` becomes an :class:`InputError`
    naming ``path``.
    """
    with all_or_nothing() as outputs:
        outputs.stage(Path(path), write)


def write_all(writers: Sequence[tuple[Path, Callable[[], Any]]]) -> None:
    """Run each ``(path, write)`` inside one :func:`all_or_nothing` block, so a command leaves
    all of its outputs or none (and earlier results untouched).

    Raises
    ------
    InputError
        An ``OSError`` of a writer, naming its path (the writer's own errors pass unchanged).
    """
    with all_or_nothing():
        for path, write in writers:
            try:
                write()
            except OSError as e:
                raise InputError(path, f"cannot write: {e.strerror or e}") from e


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
