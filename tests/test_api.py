"""The public Python API: every name the top-level facade promises resolves, and the README's
"Python API" example runs as written (a doctest)."""

from __future__ import annotations

import doctest
from pathlib import Path

import flexreg

README = Path(__file__).resolve().parents[1] / "README.md"


def test_every_public_name_resolves():
    missing = [name for name in flexreg.__all__ if getattr(flexreg, name, None) is None]
    assert not missing
    assert set(flexreg._LAZY) <= set(dir(flexreg))


def test_unknown_attribute_is_an_attribute_error():
    import pytest

    with pytest.raises(AttributeError, match="no attribute 'nothing_here'"):
        flexreg.nothing_here  # noqa: B018


def test_readme_python_api_example_runs():
    result = doctest.testfile(
        str(README),
        module_relative=False,
        optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE,
    )
    assert result.attempted >= 5, "the README lost its Python API example"
    assert result.failed == 0
