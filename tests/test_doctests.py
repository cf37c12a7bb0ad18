"""The examples in the docstrings of the survey's final alignment and of the command line's
summary lines run as written (the suite collects tests/ only, so they are run here)."""

from __future__ import annotations

import doctest
import importlib

import pytest

MODULES = ["flexreg.survey.c2c", "flexreg.survey.links", "flexreg.cli.register"]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name: str) -> None:
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0 and result.failed == 0
