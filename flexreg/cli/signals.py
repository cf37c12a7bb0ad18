"""Ctrl-C and SIGTERM for the command line: the signal is remembered as well as raised.

Python raises :class:`KeyboardInterrupt` wherever the main thread happens to be when the
signal arrives. When that is a finaliser (``__del__`` of a native object, run by the garbage
collector in the middle of a stage), the interpreter prints "Exception ignored" and carries
on: the command would finish and write its outputs as though nothing had happened. The
handlers here also note the signal, and :func:`raise_if_signalled` (at the end of every
stage, at each survey progress event, and before the outputs are renamed into place) raises
it again, so a command interrupted at any moment writes nothing and exits 130 / 143.
"""

from __future__ import annotations

import signal
from types import FrameType

__all__ = ["Terminated", "clear", "install", "raise_if_signalled", "signalled"]


class Terminated(BaseException):
    """SIGTERM arrived: unwinds the command like Ctrl-C (a BaseException, so no ``except
    Exception`` of the library swallows it)."""


#: the signal received and not yet acted on (0: none)
_pending: list[int] = [0]


def _raise_for(signum: int) -> None:
    if signum == signal.SIGTERM:
        raise Terminated(signum)
    raise KeyboardInterrupt


def _on_signal(signum: int, frame: FrameType | None) -> None:
    """The handler: remember the signal, then unwind from wherever the command is."""
    _pending[0] = signum
    _raise_for(signum)


def install() -> None:
    """Handle SIGTERM, and SIGINT unless the process was started with SIGINT ignored (a job
    run in the background of a non-interactive shell keeps ignoring Ctrl-C, as Python would)."""
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
