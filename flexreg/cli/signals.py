"""Ctrl-C and SIGTERM for the command line: the signal is remembered as well as raised.

Python raises :class:`KeyboardInterrupt` wherever the main thread happens to be when the
signal arrives. When that is a finaliser (``__del__`` of a native object, run by the garbage
collector in the middle of a stage), the interpreter prints "Exception ignored" and carries
on: the command would finish and write its outputs as though nothing had happened. The
handlers here also note the signal, and :func:`raise_if_signalled` (at the end of every
stage, at each survey progress event, and before the outputs are renamed into place) raises
it again, so a command interrupted at any moment writes nothing and exits 130 / 143.
The interpreter's "Exception ignored ... Traceback" report of such a swallowed raise is
silenced (:func:`_unraisable`): the command ends with its one line, as for any signal.
"""

from __future__ import annotations

import signal
import sys
from collections.abc import Callable
from types import FrameType

__all__ = ["Terminated", "clear", "install", "raise_if_signalled", "signalled"]


class Terminated(BaseException):
    """SIGTERM arrived: unwinds the command like Ctrl-C (a BaseException, so no ``except
    Exception`` of the library swallows it)."""


#: the signal received and not yet acted on (0: none)
_pending: list[int] = [0]
#: the unraisable-exception report in place before :func:`install` (the interpreter's own)
_report: list[Callable[[sys.UnraisableHookArgs], object]] = [sys.__unraisablehook__]


def _raise_for(signum: int) -> None:
    if signum == signal.SIGTERM:
        raise Terminated(signum)
    raise KeyboardInterrupt


def _on_signal(signum: int, frame: FrameType | None) -> None:
    """The handler: remember the signal, then unwind from wherever the command is."""
    _pending[0] = signum
    _raise_for(signum)


def _unraisable(unraisable: sys.UnraisableHookArgs) -> None:
    """``sys.unraisablehook``: a raise of this module's handler that landed where Python can
    only drop it (a finaliser, a ctypes callback such as numba's cache writer) is not
    reported, since the signal is still pending and ends the command at its next check;
    anything else goes to the report in place before (the interpreter's own)."""
    if _pending[0] and isinstance(unraisable.exc_value, KeyboardInterrupt | Terminated):
        return
    _report[0](unraisable)


def install() -> None:
    """Handle SIGTERM, and SIGINT unless the process was started with SIGINT ignored (a job
    run in the background of a non-interactive shell keeps ignoring Ctrl-C, as Python would);
    a swallowed raise of either is not reported as "Exception ignored"."""
    if sys.unraisablehook is not _unraisable:
        _report[0] = sys.unraisablehook
        sys.unraisablehook = _unraisable
    signal.signal(signal.SIGTERM, _on_signal)
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _on_signal)


def signalled() -> int:
    """The signal received and not yet acted on, or 0."""
    return _pending[0]


def raise_if_signalled() -> None:
    """Raise :class:`KeyboardInterrupt` (SIGINT) or :class:`Terminated` (SIGTERM) again when a
    signal arrived whose first raise was swallowed; clears it (each signal ends one command)."""
    signum = _pending[0]
    if signum:
        _pending[0] = 0
        _raise_for(signum)


def clear() -> None:
    """Forget a signal already acted on (the command has unwound)."""
    _pending[0] = 0
