"""The ``flexreg`` application object, its root options, and :func:`run` (errors -> one line).

Command modules import :data:`app` from here and register themselves on it; the package face
(``flexreg.cli``) imports them all. Known errors become one line ``error: <file>: <problem>``
and exit status 1.
"""

from __future__ import annotations

import os
import sys

import click
import typer

from flexreg._version import __version__
from flexreg.cli._common import compile_notice, err_console
from flexreg.errors import FlexregError

app = typer.Typer(
    name="flexreg",
    help="Register 3D scans through 2D Flexion images.\n\n"
    "\b\nExit status of the commands:\n"
    "  0  done (register, calibrate: the result is confident; survey: every station\n"
    "     placed through confident links)\n"
    "  3  written, but uncertain (register, calibrate): the reasons are on screen and in\n"
    '     the output JSON under "verdict"; survey: some station unplaced or uncertain\n'
    "  1  failed: one error line, nothing written\n"
    "  2  wrong usage (unknown option, missing argument)",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)


def _version(value: bool) -> None:
    if value:
        print(f"flexreg {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="Print the version and exit."
    ),
    verbose: int = typer.Option(
        0, "--verbose", "-v", count=True, help="More log output (-vv: debug)."
    ),
    overwrite: bool = typer.Option(
        False,
        "--overwrite",
        help="Replace outputs that exist already (a file, or a result folder whose older files "
        "are then removed); without it such an --out is refused. Like -v, it may also be "
        "given after the command.",
    ),
    memory_budget: str | None = typer.Option(
        None,
        "--memory-budget",
        metavar="SIZE",
        help="Most memory the data of one command may take, bytes with K/M/G/T or a "
        "percentage of the machine's memory (e.g. 8G, 50%); files and options that would need "
        "more are refused before reading. [default: $FLEXREG_MEMORY_BUDGET, else half the "
        "machine's memory or of ulimit -v]",
    ),
) -> None:
    """Register 3D scans through 2D Flexion images."""
    import logging

    from flexreg.cli.options import set_overwrite
    from flexreg.core.budget import set_memory_budget
    from flexreg.core.jit import on_first_compile

    set_memory_budget(memory_budget)
    set_overwrite(overwrite)
    on_first_compile(compile_notice)  # one line when a kernel's cache is cold

    from rich.logging import RichHandler

    level = logging.WARNING - 10 * min(verbose, 2)
    logging.basicConfig(
        level=level,
        handlers=[RichHandler(console=err_console, show_path=False)],
        format="%(message)s",
    )


def _click_classes(name: str) -> tuple[type[BaseException], ...]:
    """Click's exception class ``name`` and typer's own copy of it (recent typer releases
    ship their own click), so usage errors from either are caught."""
    classes: list[type[BaseException]] = [getattr(click.exceptions, name)]
    try:
        from typer._click import exceptions as tce

        classes.append(getattr(tce, name))
    except (ImportError, AttributeError):
        pass
    return tuple(classes)


#: root flags that may also be given after the command (they take no value)
ANYWHERE = ("--verbose", "--overwrite")


def _anywhere(token: str) -> bool:
    return token in ANYWHERE or (
        len(token) > 1 and token[0] == "-" and token[1] != "-" and set(token[1:]) == {"v"}
    )


def hoist_root_flags(argv: list[str]) -> list[str]:
    """Move ``-v`` / ``-vv`` / ``--verbose`` / ``--overwrite`` given after the command in front
    of it, so they work in either place (not after ``--``).

    >>> hoist_root_flags(["register", "a", "b", "-v", "--overwrite", "--out", "T.json"])
    ['-v', '--overwrite', 'register', 'a', 'b', '--out', 'T.json']
    """
    front: list[str] = []
    rest: list[str] = []
    seen_command = False
    for i, token in enumerate(argv):
        if token == "--":
            rest += argv[i:]
            break
        if seen_command and _anywhere(token):
            front.append(token)
            continue
        if not token.startswith("-") and not seen_command:
            seen_command = not (rest and rest[-1] == "--memory-budget")
        rest.append(token)
    if not front:
        return list(argv)
    cut = next((i for i, t in enumerate(rest) if not t.startswith("-")), len(rest))
    if cut > 0 and rest[cut - 1] == "--memory-budget":
        cut = next((i for i, t in enumerate(rest) if i > cut and not t.startswith("-")), len(rest))
    return rest[:cut] + front + rest[cut:]


def run(argv: list[str] | None = None) -> int:
    """Run the CLI and return its exit status: 0 done (and confident), 1 known error (nothing
    written), 2 usage error, 3 written but uncertain (``register``, ``calibrate``).

    The command runs inside :func:`flexreg.io.files.all_or_nothing`: its files are renamed into
    place together when it returns, and none is written (earlier results stay untouched) when
    it fails or is interrupted."""
    from flexreg.cli.signals import Terminated, clear, raise_if_signalled
    from flexreg.io.files import all_or_nothing

    argv = hoist_root_flags(sys.argv[1:] if argv is None else [str(a) for a in argv])
    try:
        with all_or_nothing():  # every output of the command is written at its end, or none
            rv = app(args=argv, standalone_mode=False)
            if rv == 130:  # typer turns Ctrl-C into this status: discard the outputs
                raise KeyboardInterrupt
            raise_if_signalled()  # a signal whose first raise a finaliser swallowed
    except FlexregError as e:
        err_console.print(f"error: {e}", markup=False, highlight=False, soft_wrap=True)
        return 1
    except KeyboardInterrupt:
        clear()
        _interrupted("interrupted (Ctrl-C)")
        return 130
    except _click_classes("Abort"):
        clear()
        _interrupted("interrupted (Ctrl-C)")
        return 130
    except Terminated:
        clear()
        _interrupted("terminated (SIGTERM)")
        return 143
    except _click_classes("ClickException") as e:
        e.show()  # type: ignore[attr-defined]
        return int(e.exit_code)  # type: ignore[attr-defined]
    return rv if isinstance(rv, int) else 0


def _interrupted(what: str) -> None:
    err_console.print(
        f"error: {what}: nothing written, earlier results untouched",
        markup=False,
        highlight=False,
        soft_wrap=True,
    )


#: glibc's ``M_MMAP_THRESHOLD`` (``mallopt``) and the size the command line sets it to, bytes
_M_MMAP_THRESHOLD, _MMAP_THRESHOLD = -3, 4 << 20


def _return_large_blocks() -> None:
    """Have glibc allocate blocks of 4 MiB and more with ``mmap`` (returned to the system when
    freed), unless ``MALLOC_MMAP_THRESHOLD_`` already says otherwise.

    By default glibc raises that threshold, up to 32 MiB, each time such a block is freed;
    the image stages' many 8-50 MB temporaries then come from the heap and its high-water
    mark stays in the resident set. Measured on the 2048 x 1024 PTX pair: 1.31 GB peak RSS
    against 1.22 GB; on the 8192 x 4096 pair 3.21 GB against 3.01 GB, for a few tenths of a
    second of system time (fresh pages). Results do not change."""
    if "MALLOC_MMAP_THRESHOLD_" in os.environ or not sys.platform.startswith("linux"):
        return
    import ctypes

    try:
        ctypes.CDLL(None).mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD)
    except (OSError, AttributeError):  # not glibc
        pass


def main() -> None:
    """Console-script entry point. SIGTERM (a scheduler or ``kill``) ends the command like
    Ctrl-C: nothing it was writing is left behind; exit status 143 (130 for Ctrl-C), taken
    without the interpreter's teardown once the command has unwound. Both signals are also
    remembered (:mod:`flexreg.cli.signals`), so one whose first raise a finaliser swallowed
    still ends the command before it writes anything."""
    from flexreg.cli.signals import install

    _return_large_blocks()
    install()
    status = run()
    if status in (130, 143):  # interrupted: its outputs are already discarded. Leave without
        sys.stdout.flush()  # the interpreter's teardown, which may meet a native thread pool
        sys.stderr.flush()  # (numba's, OpenCV's) still winding down and crash (exit -11)
        os._exit(status)
    sys.exit(status)
