"""Package faces that load on first use.

A package face (``flexreg/<package>/__init__.py``) hands on its public names. Importing any
module of a package runs its face first, so a face that imported its whole package would make
``from flexreg.registration.config import RegistrationConfig`` (what the command line needs at
start-up) load the registration pipeline, SciPy and the ray caster too. With :func:`lazy`, a
face maps each name to the module that defines it, and the module is imported when the name is
first used (PEP 562).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["lazy"]


def lazy(
    namespace: dict[str, Any], where: Mapping[str, str]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``__getattr__`` and ``__dir__`` for a package face.

    Parameters
    ----------
    namespace : dict
        The face's ``globals()``; a name, once loaded, is stored there.
    where : mapping
        Public name -> the module that defines it (absolute).

    Examples
    --------
    >>> getattr_, dir_ = lazy({"__name__": "demo"}, {"sqrt": "math"})
    >>> getattr_("sqrt")(9.0), "sqrt" in dir_()
    (3.0, True)
    """
    package = namespace["__name__"]

    def __getattr__(name: str) -> Any:
        module = where.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        namespace[name] = value  # later look-ups skip this function
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(where))

    return __getattr__, __dir__
