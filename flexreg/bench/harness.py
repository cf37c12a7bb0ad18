"""What every benchmark script shares: a timestamped results folder, the machine it ran on,
JSON files of its raw results, and its Markdown written next to them and into a section of a
page of ``docs/``.

The scripts of ``benchmarks/`` define their suites and tables and leave the rest to these
functions, so each result folder and each docs section is written the same way.
"""

from __future__ import annotations

import json
from datetime import datetime
from os import PathLike
from pathlib import Path
from typing import Any

from flexreg.bench.measure import machine_info
from flexreg.core.jsonable import to_jsonable

__all__ = [
    "json_text",
    "machine_info",
    "publish",
    "replace_section",
    "results_folder",
    "write_json",
]


def results_folder(parent: str | PathLike[str], name: str, *, when: datetime | None = None) -> Path:
    """``parent/<name>-<YYYYmmdd-HHMMSS>/``, created (with its parents); a run started in the
    same second as another gets ``-2``, ``-3``, ... so that no two runs write one folder."""
    base = Path(parent) / f"{name}-{when or datetime.now():%Y%m%d-%H%M%S}"
    base.parent.mkdir(parents=True, exist_ok=True)
    folder, k = base, 1
    while True:
        try:
            folder.mkdir()
            return folder
        except FileExistsError:
            k += 1
            folder = base.with_name(f"{base.name}-{k}")


def json_text(obj: Any, *, indent: int = 1) -> str:
    """``obj`` as JSON text (:func:`~flexreg.core.jsonable.to_jsonable`: arrays as lists, NaN
    and infinities as null), ending in a newline."""
    return json.dumps(to_jsonable(obj), indent=indent) + "\n"


def write_json(path: str | PathLike[str], obj: Any, *, indent: int = 1) -> Path:
    """Write ``obj`` to ``path`` as JSON (:func:`json_text`)."""
    p = Path(path)
    p.write_text(json_text(obj, indent=indent))
    return p


def replace_section(
    path: str | PathLike[str],
    text: str,
    *,
    heading: str | None = None,
    markers: tuple[str, str] | None = None,
) -> None:
    """Put ``text`` into a Markdown page, leaving the rest of it untouched.

    Parameters
    ----------
    path : path-like
        The page.
    text : str
        The new body.
    heading : str, optional
        A ``## ...`` line: its section's body (up to the next ``## ``) is replaced; a page
        without it gets the section appended.
    markers : (str, str), optional
        Begin and end comments (``<!-- begin -->``): the text between them is replaced.
    Without either, the whole page is ``text``.

    Raises
    ------
    ValueError
        The markers are not both on the page.
    """
    p = Path(path)
    if heading is None and markers is None:
        p.write_text(text)
        return
    doc = p.read_text()
    if markers is not None:
        begin, end = markers
        if begin not in doc or end not in doc:
            raise ValueError(f"{p}: markers {begin} / {end} missing")
        start = doc.index(begin) + len(begin)
        p.write_text(doc[:start] + "\n" + text.rstrip("\n") + "\n" + doc[doc.index(end) :])
        return
    head = f"{heading}\n"
    if head not in doc:
        p.write_text(doc.rstrip("\n") + "\n\n" + head + "\n" + text)
        return
    start = doc.index(head) + len(head)
    nxt = doc.find("\n## ", start)
    end_at = len(doc) if nxt < 0 else nxt + 1
    p.write_text(doc[:start] + "\n" + text + ("\n" if nxt >= 0 else "") + doc[end_at:])


def publish(
    text: str,
    folder: str | PathLike[str],
    *,
    doc: str | PathLike[str] | None = None,
    heading: str | None = None,
    markers: tuple[str, str] | None = None,
    name: str = "results.md",
) -> Path:
    """Print a run's Markdown, write it into its results folder and, with ``doc``, into that
    page of the docs (:func:`replace_section` with ``heading`` or ``markers``). Returns the
    Markdown file of the results folder."""
    out = Path(folder) / name
    out.write_text(text)
    print("\n" + text)
    if doc is not None:
        replace_section(doc, text, heading=heading, markers=markers)
        print(f"updated {doc}")
    return out
