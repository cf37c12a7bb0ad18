"""Shared test fixtures: paths to the real data beside the checkout."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data`` (present beside the checkout in development and CI)."""
    if not SHARED_DATA.is_dir():
        pytest.fail(f"real data folder missing: {SHARED_DATA} (clone with ../shared beside it)")
    return SHARED_DATA


@pytest.fixture()
def rng():
    import numpy as np

    return np.random.default_rng(12345)
