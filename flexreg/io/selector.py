"""The one parser of the ``FILE#N`` / ``FILE#NAME`` setup selector (:mod:`flexreg.io.setups`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from os import PathLike
from pathlib import Path

from flexreg.core.scan import Scan
from flexreg.errors import InputError
from flexreg.io.formats import FORMATS

__all__ = ["ScanRef", "parse_scan_ref", "pick", "select_setup", "setup_choices"]

#: setups a one-line "choose one" message names before "..." (``flexreg info FILE`` lists all)
LISTED = 6


@dataclass(frozen=True)
class ScanRef:
    """A scan as the user named it: a file and an optional setup selector.

    Attributes
    ----------
    path : Path
        The file.
    selector : str or None
        What followed ``#``: an index (digits) or a setup name; None when not given.
    """

    path: Path
    selector: str | None = None

    def __str__(self) -> str:
        return str(self.path) if self.selector is None else f"{self.path}#{self.selector}"

    @property
    def index(self) -> int | None:
        """The selector as an index (None when it is a name or absent)."""
        s = self.selector
        return int(s) if s is not None and s.isdigit() else None


def parse_scan_ref(text: str | PathLike[str]) -> ScanRef:
    """Split ``FILE#N`` / ``FILE#NAME`` into the file and the selector.

    Parameters
    ----------
    text : str or path-like
        What the user gave. When a file exists under the whole name, or the name holds no
        ``#``, or what precedes the last ``#`` has no scan suffix, there is no selector;
        otherwise the text after the last ``#`` is the selector.

    Raises
    ------
    InputError
        ``FILE#`` with nothing after the ``#``.

    Examples
    --------
    >>> parse_scan_ref("site/project.e57#2")
    ScanRef(path=PosixPath('site/project.e57'), selector='2')
    >>> parse_scan_ref("a.ptx").selector is None
    True
    """
    s = str(text)
    p = Path(s)
    if "#" not in p.name or p.exists():
        return ScanRef(p)
    head, _, sel = s.rpartition("#")
    if Path(head).suffix.lower() not in FORMATS:  # "scan#2.ply": a file name with '#'
        return ScanRef(p)
    if not sel.strip():
        raise InputError(s, "nothing after '#': name a setup as FILE#N (index) or FILE#NAME")
    return ScanRef(Path(head), sel)


def select_setup(names: Sequence[str], ref: ScanRef) -> int:
    """Index of the setup ``ref`` selects among a file's setup names.

    Raises
    ------
    InputError
        An index out of range, or a name no setup (or more than one) carries; the message lists
        the setups.
    """
    n = len(names)
    if ref.index is not None:
        if ref.index >= n:
            raise InputError(
                ref.path,
                f"no setup #{ref.index}: the file holds {n} ({setup_choices(ref.path, names)})",
            )
        return ref.index
    hits = [i for i, name in enumerate(names) if name == ref.selector]
    if len(hits) == 1:
        return hits[0]
    why = "no setup is" if not hits else f"{len(hits)} setups are"
    raise InputError(
        ref.path,
        f"{why} named {ref.selector!r}; choose by index: {setup_choices(ref.path, names)}",
    )


def setup_choices(path: Path, names: Sequence[str], counts: Sequence[int] | None = None) -> str:
    """``FILE#0 (name, N points), FILE#1 ...`` for one-line messages (the first
    :data:`LISTED`, then how many more)."""
    items = []
    for i, name in enumerate(names[:LISTED]):
        extra = "" if counts is None else f", {counts[i]:,} points"
        items.append(f"{path}#{i} ({name}{extra})")
    more = len(names) - LISTED
    if more > 0:
        items.append(f"... {more} more (flexreg info {path} lists them)")
    return ", ".join(items)


def pick(scans: list[Scan], ref: ScanRef) -> Scan:
    """The setup of ``scans`` (all of a file, in order) that ``ref`` selects."""
    return scans[select_setup([s.name for s in scans], ref)]
