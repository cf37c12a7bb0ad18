"""Print the bad-input corpus's summary line at the end of the run (see test_corpus.py)."""

from __future__ import annotations


def pytest_terminal_summary(terminalreporter, exitstatus, config) -> None:
    from test_corpus import SUMMARY

    text = config.stash.get(SUMMARY, None)
    if text is not None:
        terminalreporter.write_sep("-", "bad-input corpus")
        terminalreporter.write_line(text)
