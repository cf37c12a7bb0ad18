"""Results kept by the content they were computed from.

A survey worker loads a station again for each of its dozen links, so what a stage derives
from one scan alone (a plan view's self-overlays, a cloud's scale voxel and voxel centroids)
would be computed a dozen times over equal arrays. :class:`Kept` keeps the last results under
a key built from :func:`digest` of their inputs: equal values give equal keys whatever array
objects hold them, and a kept result is exactly what computing it again would give.
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Any, Generic, TypeVar

import numpy as np

T = TypeVar("T")


def digest(*arrays: Any) -> bytes:
    """A 20-byte digest of arrays' types, shapes and values, in order.

    Parameters
    ----------
    *arrays : array_like
        What a result is computed from (scalars too: ``np.asarray`` of each).

    Returns
    -------
    bytes
    """
    h = hashlib.blake2b(digest_size=20)
    for a in arrays:
        p = np.ascontiguousarray(a)
        h.update(f"{p.dtype.str}{p.shape}".encode())
        h.update(p.data)
    return h.digest()


class Kept(Generic[T]):
    """The last ``limit`` results, by key, shared by the threads of a process.

    Parameters
    ----------
    limit : int
        How many results are kept (the least recently used goes first).
    """

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self._items: OrderedDict[Hashable, T] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, key: Hashable, make: Callable[[], T], limit: int | None = None) -> T:
        """The result kept under ``key``, else ``make()`` (computed outside the lock, then
        kept; ``limit``, when given, instead of the one set at construction)."""
        with self._lock:
            hit = self._items.get(key)
            if hit is not None:
                self._items.move_to_end(key)
                return hit
        value = make()
        with self._lock:
            self._items[key] = value
            while len(self._items) > (self.limit if limit is None else limit):
                self._items.popitem(last=False)
        return value

    def clear(self) -> None:
        """Forget every kept result."""
        with self._lock:
            self._items.clear()

    def __len__(self) -> int:
        return len(self._items)


__all__ = ["Kept", "digest"]
