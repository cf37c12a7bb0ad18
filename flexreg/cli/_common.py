"""Shared pieces of the CLI: consoles, progress display, option parsing helpers."""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    SpinnerColumn,
    TextColumn,
    TimeElapsedColumn,
)

from flexreg.io.files import write_all as write_all  # re-exported for the commands

console = Console(highlight=False)
err_console = Console(stderr=True, highlight=False)


@contextmanager
def stage(description: str) -> Iterator[None]:
    """Show a spinner with elapsed time while a stage runs (on stderr), then a done line."""
    t0 = time.perf_counter()
    with Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        TimeElapsedColumn(),
        console=err_console,
        transient=True,
    ) as progress:
        progress.add_task(description, total=None)
        yield
    err_console.print(f"[green]✓[/green] {description} ({time.perf_counter() - t0:.2f} s)")


def progress_bar() -> Progress:
    """A progress bar for loops over files or items (on stderr)."""
    return Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=err_console,
    )


def read_input(
    path: Path,
    *,
    pinhole: tuple[float, float, float, float] | None = None,
    equirect: tuple[float, float] | None = None,
    depth_kind: str | None = None,
    depth_scale: float | None = None,
    all_scans: bool = False,
) -> list[Any]:
    """Read the scans of an input file, building a camera for depth PNGs from the options."""
    from flexreg.errors import InputError
    from flexreg.io import detect_format, read_scans
    from flexreg.io.depth import camera_for_image

    _, fmt = detect_format(path)
    opts: dict[str, Any] = {}
    if fmt == "depth":
        if not path.is_file():
            raise InputError(path, "no such file")
        try:
            opts["camera"] = camera_for_image(path, pinhole=pinhole, equirect=equirect)
        except InputError as e:
            if e.source in ("pinhole camera", "spherical camera"):  # name the option at fault
                raise InputError("--pinhole" if pinhole else "--equirect", e.problem) from None
            raise
        if depth_kind is not None:
            if depth_kind not in ("z", "range"):
                raise InputError("--depth-kind", f"must be z or range, got {depth_kind!r}")
            opts["depth_kind"] = depth_kind
        if depth_scale is not None:
            opts["depth_scale"] = depth_scale
    elif pinhole or equirect or depth_kind or depth_scale is not None:
        raise InputError(
            path, "--pinhole/--equirect/--depth-kind/--depth-scale apply to depth PNGs only"
        )
    scans = read_scans(path, **opts)
    return scans if all_scans else scans[:1]
