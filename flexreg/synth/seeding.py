"""The one way synthetic data turns an ``rng`` argument into a generator."""

from __future__ import annotations

import numpy as np

from flexreg.errors import ConfigError


def as_rng(rng: np.random.Generator | int | None) -> tuple[np.random.Generator, int | None]:
    """Return ``(generator, seed or None)`` for an ``rng`` argument (Generator, int or None)."""
    if isinstance(rng, np.random.Generator):
        return rng, None
    if rng is None:
        return np.random.default_rng(), None
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool) and int(rng) >= 0:
        return np.random.default_rng(int(rng)), int(rng)
    raise ConfigError(
        f"rng must be a numpy Generator, a non-negative int seed or None, got {rng!r}"
    )
