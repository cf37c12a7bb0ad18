"""Where numba keeps the compiled kernels, and a hook on their first compilation.

flexreg's kernels are numba functions compiled on first use and cached on disk
(``njit(cache=True)``): the first run of ``register`` on a machine spends most of a minute
compiling, later runs load the machine code in a fraction of a second. numba caches beside
the source (the package's ``__pycache__`` folders) when it may write there. For an install it
may not write to (a system or read-only environment), :func:`cache_env` sends the
cache to the user's cache folder, ``$XDG_CACHE_HOME/flexreg/numba`` (``~/.cache/flexreg/numba``),
so that the compilation is paid once there too; it must run before numba is imported, which
reads ``NUMBA_CACHE_DIR`` then (``flexreg/__init__.py`` sets it first). A ``NUMBA_CACHE_DIR``
set by the user is always kept.

:func:`on_first_compile` registers a callback for the moment a kernel is compiled rather than
loaded from the cache (a cold cache): numba reports each compilation through its event API
(``numba:compile``), and a cache hit reports none, so the callback fires only when the
compilation really happens, once per call of :func:`on_first_compile`.
"""

from __future__ import annotations

import logging
import os
import tempfile
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

__all__ = [
    "CACHE_ENV",
    "KERNEL_DIRS",
    "cache_dir",
    "cache_env",
    "choose_cache_dir",
    "on_first_compile",
    "user_cache_dir",
    "writable",
]

logger = logging.getLogger(__name__)

#: the environment variable numba reads for its cache folder
CACHE_ENV = "NUMBA_CACHE_DIR"
#: the package folders (relative to ``flexreg/``) whose modules hold cached numba kernels
KERNEL_DIRS = ("core", "io", "stages", "stages/refinement", "registration")
#: the package's own folder
PACKAGE_DIR = Path(__file__).resolve().parents[1]


def writable(folder: Path) -> bool:
    """Whether a file can be created in ``folder`` (made if missing), as numba tries it.

    A permission check alone is not enough: a read-only mount refuses even the superuser.
    """
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
    except OSError:
        return False
    return True


def user_cache_dir(environ: Mapping[str, str] | None = None) -> Path:
    """``$XDG_CACHE_HOME/flexreg/numba``, else ``~/.cache/flexreg/numba``."""
    env = os.environ if environ is None else environ
    base = env.get("XDG_CACHE_HOME", "")
    root = Path(base) if base and Path(base).is_absolute() else Path.home() / ".cache"
    return root / "flexreg" / "numba"


def choose_cache_dir(
    package_dir: Path = PACKAGE_DIR,
    *,
    environ: Mapping[str, str] | None = None,
    kernel_dirs: Iterable[str] = KERNEL_DIRS,
    can_write: Callable[[Path], bool] = writable,
) -> Path | None:
    """The folder numba should cache flexreg's kernels in, or None to leave numba's choice.

    Parameters
    ----------
    package_dir : Path
        The installed ``flexreg`` package.
    environ : mapping, optional
        The environment (default ``os.environ``).
    kernel_dirs : iterable of str
        The package folders holding cached kernels (:data:`KERNEL_DIRS`).
    can_write : callable
        Whether a folder can be written (:func:`writable`).

    Returns
    -------
    Path or None
        None when the user set ``NUMBA_CACHE_DIR`` or numba can write each kernel folder's
        ``__pycache__`` (it caches beside the source then); else :func:`user_cache_dir`.
    """
    env = os.environ if environ is None else environ
    if env.get(CACHE_ENV):
        return None
    if all(can_write(package_dir / d / "__pycache__") for d in kernel_dirs):
        return None
    return user_cache_dir(env)


def cache_env(package_dir: Path = PACKAGE_DIR) -> dict[str, str]:
    """``{"NUMBA_CACHE_DIR": folder}`` when :func:`choose_cache_dir` names a folder, else
    ``{}``: what ``flexreg/__init__.py`` adds to the environment before numba is imported
    (numba reads the variable at import; worker processes inherit it)."""
    folder = choose_cache_dir(package_dir)
    if folder is None:
        return {}
    logger.debug("the package folder is not writable: numba caches in %s", folder)
    return {CACHE_ENV: str(folder)}


def cache_dir(package_dir: Path = PACKAGE_DIR) -> Path:
    """Where the kernels are cached: ``NUMBA_CACHE_DIR``, else the package's ``__pycache__``
    folders (named by the package folder)."""
    return Path(os.environ[CACHE_ENV]) if os.environ.get(CACHE_ENV) else package_dir


class _FirstCompile:
    """The state of :func:`on_first_compile`: its callback, and whether it is still armed."""

    def __init__(self) -> None:
        self.callback: Callable[[Path], None] | None = None
        self.armed = False
        self.listening = False

    def started(self, event: Any) -> None:
        """A ``numba:compile`` event started: a dispatcher compiles (a cache miss)."""
        if not self.armed:
            return
        dispatcher = (getattr(event, "data", None) or {}).get("dispatcher")
        module = getattr(getattr(dispatcher, "py_func", None), "__module__", "") or ""
        if not module.startswith("flexreg."):
            return
        self.armed = False
        where = cache_dir()
        logger.info("compiling the image kernels once; later runs reuse them from %s", where)
        if self.callback is not None:
            self.callback(where)


_FIRST = _FirstCompile()


def on_first_compile(callback: Callable[[Path], None] | None = None) -> None:
    """Call ``callback(cache folder)`` at the next compilation of a flexreg kernel: one whose
    cache is cold (a kernel loaded from the cache compiles nothing and calls nothing).

    Each call arms it once: the first compilation after it logs one INFO line and calls
    ``callback`` (possibly in a worker thread); later ones in the same run say nothing. A
    later call replaces the callback.
    """
    from numba.core import event

    if not _FIRST.listening:

        class FirstCompileListener(event.Listener):
            def on_start(self, ev: Any) -> None:
                _FIRST.started(ev)

            def on_end(self, ev: Any) -> None:
                pass

        event.register("numba:compile", FirstCompileListener())
        _FIRST.listening = True
    _FIRST.callback = callback
    _FIRST.armed = True
