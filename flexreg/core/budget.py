"""The memory budget: how much one flexreg process may allocate for data a file or option asks
for, checked *before* the allocation.

A file's header declares counts and grid sizes; an option declares an image resolution. A
small hostile or broken file (a 137 KiB LAS that claims 400 million points, an E57 whose grid
bounds claim 40001 x 40001) must not take a shared machine down, so readers and stages compare
what such a declaration would cost with the budget and refuse it in one line when it does not
fit (:func:`check_memory`).

The budget is, first match wins:

1. the value set for this process with :func:`set_memory_budget` (the command line's
   ``flexreg --memory-budget SIZE``);
2. the environment variable ``FLEXREG_MEMORY_BUDGET``;
3. :data:`DEFAULT_FRACTION` of the machine's physical memory, or of the process's address-space
   limit (``ulimit -v``) when that is smaller.

A size is bytes, with an optional unit (``K``, ``M``, ``G``, ``T``, powers of 1024), or a
percentage of the machine's memory (``"25%"``): ``"8G"``, ``"512M"``, ``"2.5e9"``, ``"50%"``.
"""

from __future__ import annotations

import math
import os
import re
import resource

from flexreg.errors import ConfigError, MemoryBudgetError

__all__ = [
    "DEFAULT_FRACTION",
    "ENV_VAR",
    "check_memory",
    "format_bytes",
    "memory_budget",
    "parse_size",
    "physical_memory",
    "set_memory_budget",
]

#: environment variable holding the budget (a size, see :func:`parse_size`)
ENV_VAR = "FLEXREG_MEMORY_BUDGET"
#: share of the machine's memory (or of ``ulimit -v``) allowed when nothing else is set
DEFAULT_FRACTION = 0.5
_UNITS = {"": 1, "B": 1, "K": 1024, "M": 1024**2, "G": 1024**3, "T": 1024**4}
_override: int | None = None


def physical_memory() -> int:
    """The machine's physical memory in bytes (``os.sysconf``; 8 GiB if it cannot be read)."""
    try:
        pages, size = os.sysconf("SC_PHYS_PAGES"), os.sysconf("SC_PAGE_SIZE")
        if pages > 0 and size > 0:
            return int(pages) * int(size)
    except (ValueError, OSError, AttributeError):
        pass
    return 8 * 1024**3


def parse_size(text: str | float, *, name: str = ENV_VAR) -> int:
    """A size in bytes from ``"8G"``, ``"512M"``, ``"2.5e9"``, ``"50%"`` (of physical memory).

    Raises
    ------
    ConfigError
        Not a positive size, naming ``name`` (the option or variable it came from).
    """
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        value = float(text)
    else:
        s = str(text).strip().upper().removesuffix("IB").removesuffix("B")
        m = re.fullmatch(r"([0-9.eE+-]+)\s*([KMGT%]?)", s)
        if m is None:
            raise ConfigError(
                f"{name}: {text!r} is not a size (bytes, or a number with K, M, G, T, or a "
                "percentage of the machine's memory such as 50%)"
            )
        try:
            number = float(m.group(1))
        except ValueError:
            raise ConfigError(f"{name}: {text!r} is not a size") from None
        unit = m.group(2)
        if unit == "%":
            if not 0 < number <= 100:
                raise ConfigError(f"{name}: {text!r}: a percentage must be in (0, 100]")
            value = physical_memory() * number / 100
        else:
            value = number * _UNITS[unit]
    if not (math.isfinite(value) and value >= 1):
        raise ConfigError(f"{name}: {text!r}: the budget must be a positive size")
    return int(value)


def set_memory_budget(size: str | float | None) -> None:
    """Set the budget of this process (``None``: back to the variable or the default)."""
    global _override
    _override = None if size is None else parse_size(size, name="--memory-budget")


def _address_space_limit() -> int | None:
    try:
        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    except (ValueError, OSError):
        return None
    return None if soft in (resource.RLIM_INFINITY, -1) or soft <= 0 else int(soft)


def memory_budget() -> int:
    """The budget in bytes (see the module docstring for where it comes from)."""
    if _override is not None:
        return _override
    env = os.environ.get(ENV_VAR, "").strip()
    if env:
        return parse_size(env)
    limit = _address_space_limit()
    total = physical_memory() if limit is None else min(physical_memory(), limit)
    return int(DEFAULT_FRACTION * total)


def format_bytes(n: float) -> str:
    """``"7.5 GB"``-style size (powers of 1024, one decimal)."""
    for unit in ("B", "KB", "MB", "GB", "TB", "PB"):
        if abs(n) < 1024 or unit == "PB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} PB"  # pragma: no cover


def check_memory(nbytes: float, what: str, *, source: object) -> None:
    """Refuse an allocation of ``nbytes`` that does not fit the budget.

    Parameters
    ----------
    nbytes : float
        What the data would take in memory, bytes (an estimate from declared sizes).
    what : str
        What it is, for the message (``"4000 x 2000 range image"``).
    source : str or path-like
        The file or option at fault; it leads the message.

    Raises
    ------
    MemoryBudgetError
        ``<source>: <what> would need 7.5 GB, more than the memory budget of 3.9 GB (set
        FLEXREG_MEMORY_BUDGET or flexreg --memory-budget to change it)``.
    """
    budget = memory_budget()
    if not math.isfinite(nbytes) or nbytes > budget:
        need = "an unbounded amount" if not math.isfinite(nbytes) else format_bytes(nbytes)
        raise MemoryBudgetError(
            str(source),
            f"{what} would need {need} of memory, more than the memory budget of "
            f"{format_bytes(budget)} (set {ENV_VAR} or flexreg --memory-budget to change it)",
        )
