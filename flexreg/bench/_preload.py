"""Start-up work that numba defers to the first call of a compiled function.

numba imports its NumPy support (and SciPy's BLAS bindings) and fills its typing and target
registries the first time any compiled function runs, which costs about 0.25 s in every new
process; and it loads each kernel's machine code from its on-disk cache on that kernel's first
call, tens of milliseconds apiece. Importing this module does both at import time instead, the
way Open3D and OpenCV load their compiled code when they are imported. The comparison's fork
server imports it with the other libraries (:func:`flexreg.bench.measure.preload_modules`), so
that a method's measured call excludes its libraries' start-up alike.

Parallel kernels are left to their first call: loading one starts numba's OpenMP thread pool,
and a process with running OpenMP threads must not fork.
"""

from __future__ import annotations

import importlib
import logging
import pkgutil
from pathlib import Path

from numba.core.registry import CPUDispatcher, cpu_target

log = logging.getLogger(__name__)

#: the folder of the flexreg package, whose modules are searched for kernels
_PACKAGE = Path(__file__).resolve().parents[1]

cpu_target.target_context.refresh()
cpu_target.typing_context.refresh()


def load_cached_kernels() -> int:
    """Load the cached machine code of every serial flexreg kernel already compiled on this
    machine (nothing is compiled). Returns how many kernel signatures were loaded.

    Uses numba's cache index, which is not public API: on any surprise it stops quietly and
    the kernels load on first call as usual.
    """
    magic = cpu_target.target_context.codegen().magic_tuple()
    loaded = 0
    try:
        for info in pkgutil.walk_packages([str(_PACKAGE)], "flexreg."):
            if info.name == __name__:
                continue
            module = importlib.import_module(info.name)
            for obj in list(vars(module).values()):
                if (
                    not isinstance(obj, CPUDispatcher)
                    or obj.__module__ != module.__name__
                    or obj.targetoptions.get("parallel")
                    or getattr(obj, "_cache", None) is None
                ):
                    continue
                index = obj._cache._cache_file._load_index()  # type: ignore[attr-defined]
                for sig, key_magic, _ in index:
                    if key_magic == magic:
                        obj.compile(sig)
                        loaded += 1
    except Exception as e:  # pragma: no cover - numba internals changed
        log.debug("cached kernels not preloaded: %s", e)
    return loaded


load_cached_kernels()
