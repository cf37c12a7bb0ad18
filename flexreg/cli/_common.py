"""Shared pieces of the CLI: consoles, progress display, option parsing helpers."""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    SpinnerColumn,
    TextColumn,
    TimeElapsedColumn,
)

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
