"""Shared pieces of the CLI: consoles, progress display, option parsing helpers."""

from __future__ import annotations

import math
import os
import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

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

if TYPE_CHECKING:
    from flexreg.core.results import Verdict

#: console width when the output is not a terminal (a pipe, a log file) and COLUMNS is not set:
#: wide enough that progress lines and tables are not cut at 80 columns
PIPED_WIDTH = 160


def make_console(*, stderr: bool = False, environ: Mapping[str, str] | None = None) -> Console:
    """A console on stdout (or stderr): as wide as the terminal, or ``COLUMNS`` when set, or
    :data:`PIPED_WIDTH` when the output is not a terminal (rich's default would be 80)."""
    env = os.environ if environ is None else environ
    wide = Console(stderr=stderr, highlight=False)
    if wide.is_terminal or env.get("COLUMNS", "").strip().isdigit():
        return wide
    return Console(stderr=stderr, highlight=False, width=PIPED_WIDTH)


console = make_console()
err_console = make_console(stderr=True)


def compile_notice(cache: Path) -> None:
    """The one line shown when the first compiled kernel is built (its cache was cold):
    :func:`flexreg.core.jit.on_first_compile` calls it."""
    from flexreg.core.jit import PACKAGE_DIR

    where = "" if cache == PACKAGE_DIR else f" (cached in {cache})"
    err_console.print(
        f"compiling the image kernels once (~40 s); later runs reuse them{where}",
        markup=False,
        highlight=False,
        soft_wrap=True,
    )


@contextmanager
def stage(description: str) -> Iterator[None]:
    """Show a spinner with elapsed time while a stage runs (on stderr), then a done line; when
    stderr is not a terminal, the done line only (never cut: it wraps softly). A Ctrl-C or
    SIGTERM whose first raise was swallowed (by a finaliser) ends the command here."""
    from rich.text import Text

    from flexreg.cli.signals import raise_if_signalled

    t0 = time.perf_counter()
    if err_console.is_terminal:
        with Progress(
            SpinnerColumn(),
            TextColumn("{task.description}", markup=False),
            TimeElapsedColumn(),
            console=err_console,
            transient=True,
        ) as progress:
            progress.add_task(description, total=None)
            yield
    else:
        yield
    raise_if_signalled()
    done = Text.assemble(("✓", "green"), f" {description} ({time.perf_counter() - t0:.2f} s)")
    err_console.print(done, highlight=False, soft_wrap=True)


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


def scan_file(path: Path) -> Path:
    """The file of a scan argument (``FILE#N`` / ``FILE#NAME`` -> ``FILE``)."""
    from flexreg.io.selector import parse_scan_ref

    return parse_scan_ref(path).path


def read_input(
    path: Path,
    *,
    pinhole: tuple[float, float, float, float] | None = None,
    equirect: tuple[float, float] | None = None,
    depth_kind: str | None = None,
    depth_scale: float | None = None,
    all_scans: bool = False,
    origin: tuple[float, float, float] | None = None,
    origin_option: str | None = None,
    intensity: bool = True,
) -> list[Any]:
    """Read the scans of an input (``FILE``, ``FILE#N`` or ``FILE#NAME``), building a camera for
    depth PNGs from the options.

    With a setup selector, that setup alone. Without one, every setup when ``all_scans``, else
    the file's only setup: a file holding several is refused with a line that names them.
    With ``origin_option`` (the command's option for the scanner position), a cloud in
    project coordinates is refused with a line that names that option, and ``origin`` moves
    the points to the scanner (:mod:`flexreg.io.origin`). ``intensity=False``: without
    intensities (a command that never reads them keeps 4 bytes per point less).
    """
    from flexreg.errors import InputError
    from flexreg.io import detect_format, read_scans
    from flexreg.io.depth import camera_for_image
    from flexreg.io.selector import parse_scan_ref

    ref = parse_scan_ref(path)
    file = ref.path
    _, fmt = detect_format(file)
    opts: dict[str, Any] = {}
    if fmt == "depth":
        if not file.is_file():
            raise InputError(file, "no such file")
        try:
            opts["camera"] = camera_for_image(file, pinhole=pinhole, equirect=equirect)
        except InputError as e:
            if e.source in ("pinhole camera", "spherical camera"):  # name the option at fault
                raise InputError("--pinhole" if pinhole else "--equirect", e.problem) from None
            raise
        if depth_kind is not None:
            if depth_kind not in ("z", "range"):
                raise InputError("--depth-kind", f"must be z or range, got {depth_kind!r}")
            opts["depth_kind"] = depth_kind
        if depth_scale is not None:
            if not (math.isfinite(depth_scale) and depth_scale > 0):
                raise InputError(
                    "--depth-scale",
                    f"must be a positive number of metres per unit, got {depth_scale}",
                )
            opts["depth_scale"] = depth_scale
    elif pinhole or equirect or depth_kind or depth_scale is not None:
        raise InputError(
            file, "--pinhole/--equirect/--depth-kind/--depth-scale apply to depth PNGs only"
        )
    if fmt == "e57" and ref.selector is None and not all_scans:
        from flexreg.io.setups import list_setups

        setups = list_setups(file)  # headers only: refuse a project file before reading it
        if len(setups) > 1:
            raise _several(file, [s.name for s in setups], [s.points for s in setups])
    if not intensity:
        opts["intensity"] = False
    scans = read_scans(path, **opts)
    if len(scans) > 1 and ref.selector is None and not all_scans:
        raise _several(file, [s.name for s in scans], [len(s) for s in scans])
    if origin_option is not None:
        scans = [_centred(file, s, origin, origin_option) for s in scans]
    return scans


def _centred(file: Path, scan: Any, origin: Any, option: str) -> Any:
    """The scan moved to ``origin``, or as it is when centred (else an error naming
    ``option``)."""
    from flexreg.errors import InputError
    from flexreg.io.origin import centring_problem, origin_hint, recentre
    from flexreg.io.scans import single_precision

    _refuse_one_point(file, scan)
    if origin is not None:
        try:
            moved = recentre(scan, origin)  # in float64
        except InputError as e:
            raise InputError(option, e.problem) from None
        return single_precision(moved)  # near its scanner now: float32, as read_scan gives
    why = centring_problem(scan)
    if why is not None:
        raise InputError(file, origin_hint(why, option))
    return scan


def _refuse_one_point(file: Path, scan: Any) -> None:
    """A scan of one point, or of copies of one, has nothing to make an image of."""
    from flexreg.errors import InputError

    if len(scan) and (scan.points.min(axis=0) == scan.points.max(axis=0)).all():
        what = "a single point" if len(scan) == 1 else f"{len(scan)} copies of one point"
        raise InputError(file, f"holds {what}: nothing to make an image of")


def auto_viewpoint(file: Path, scan: Any, option: str) -> tuple[Any, Any]:
    """A cloud not centred on its scanner (:func:`flexreg.io.origin.centring_problem`), moved
    to a virtual viewpoint chosen where it hides least of itself
    (:func:`flexreg.stages.viewpoint.choose_viewpoint`), said in one line naming ``option``
    (which gives the scanner's real position); a centred scan as it is.

    Returns
    -------
    scan : Scan
        Float32 near its viewpoint, as :func:`read_input` gives a recentred cloud.
    origin : (3,) float64 or None
        The viewpoint in the file's frame (None: the scan is as it was).
    """
    from flexreg.io.origin import centring_problem, recentre
    from flexreg.io.scans import single_precision
    from flexreg.stages.viewpoint import choose_viewpoint

    _refuse_one_point(file, scan)
    why = centring_problem(scan)
    if why is None:
        return scan, None
    origin, hidden = choose_viewpoint(scan.points)
    err_console.print(
        f"{file}: not centred on its scanner ({why}): seen from a viewpoint chosen where it "
        f"hides least of itself, ({origin[0]:.3f}, {origin[1]:.3f}, {origin[2]:.3f}) in the "
        f"file's frame ({100 * hidden:.0f}% of its points behind its own there); {option} "
        "X Y Z gives the scanner's position",
        markup=False,
        soft_wrap=True,
    )
    return single_precision(recentre(scan, origin)), origin


def read_pair(
    target: Path,
    source: Path,
    origins: tuple[Any, Any] | None = None,
    options: tuple[str | None, str | None] | None = None,
    *,
    intensity: bool = True,
) -> list[Any]:
    """Read the target and the source scan (one setup each, see :func:`read_input`; with
    ``options``, the scanner position options of each and ``origins`` their values); the same
    setup of the same file on both sides is refused. ``intensity=False``: without
    intensities."""

    def read(k: int) -> Any:
        (scan,) = read_input(
            (target, source)[k],
            origin=None if origins is None else origins[k],
            origin_option=None if options is None else options[k],
            intensity=intensity,
        )
        return scan

    return _read_both(target, source, read, lambda scan: scan)


class WorkingPair:
    """Two scans read with their working images (:func:`read_pair_working`).

    Attributes
    ----------
    scans : list of Scan
        Target and source; a PTX scan keeps its points only (no grid, no attributes).
    """

    def __init__(self, scans: list[Any], images: list[Any]) -> None:
        self.scans = scans
        self._images: list[Any] | None = images

    def take_images(self) -> list[Any]:
        """The working images (None for a scan read without one), handed over: this object
        keeps no reference, so the call they are given to can let go of them."""
        images, self._images = self._images, None
        if images is None:
            raise RuntimeError("the working images were taken already")
        return images


def read_pair_working(target: Path, source: Path, *, max_pixels: int) -> WorkingPair:
    """:func:`read_pair` for a command that needs each scan's points and working image only:
    a PTX or E57 file is read straight into both (:func:`flexreg.io.read_working_scan`: no
    grid index, intensity or colour, 12 bytes per point instead of 24); another file as
    :func:`read_input` reads it without intensities, and no image. The points are as the
    files hold them (a cloud in project coordinates is the caller's to place)."""
    from flexreg.io import detect_format
    from flexreg.io.scans import read_working_scans
    from flexreg.io.selector import parse_scan_ref

    def read(k: int) -> Any:
        path = (target, source)[k]
        ref = parse_scan_ref(path)
        if detect_format(ref.path)[1] not in ("ptx", "e57"):
            (scan,) = read_input(path, intensity=False)
            return scan, None
        pairs = read_working_scans(path, max_pixels=max_pixels)
        if len(pairs) > 1:  # without a selector: refused as read_input refuses it
            raise _several(ref.path, [s.name for s, _ in pairs], [len(s) for s, _ in pairs])
        return pairs[0]

    pairs = _read_both(target, source, read, lambda pair: pair[0])
    return WorkingPair([p[0] for p in pairs], [p[1] for p in pairs])


def _read_both(target: Path, source: Path, read: Any, scan_of: Any) -> list[Any]:
    """``read(0)`` and ``read(1)`` at once (the parsers' serial parts, file reads and copying
    the valid points, overlap; the target's error, if any, is the one reported); the same
    setup of the same file on both sides is refused (``scan_of`` finds the scan in what
    ``read`` returns)."""
    from concurrent.futures import ThreadPoolExecutor

    import numpy as np

    from flexreg.errors import InputError

    pool = ThreadPoolExecutor(2)
    try:
        with stage(f"Reading {target.name} and {source.name}"):
            jobs = [pool.submit(read, k) for k in (0, 1)]
            got = [job.result() for job in jobs]
    finally:  # on an error or Ctrl-C, do not wait here for the other file
        pool.shutdown(wait=False, cancel_futures=True)
    t, s = (scan_of(g) for g in got)
    same_file = scan_file(target).resolve() == scan_file(source).resolve()
    if same_file and len(t) == len(s) and np.array_equal(t.points, s.points):
        raise InputError(
            source,
            f"is the same scan as the target {target}: name two setups (FILE#N) or two files",
        )
    return got


def _several(file: Path, names: list[str], counts: list[int]) -> Exception:
    from flexreg.errors import InputError
    from flexreg.io.selector import setup_choices

    return InputError(
        file,
        f"holds {len(names)} setups; name one as FILE#N or FILE#NAME: "
        f"{setup_choices(file, names, counts)}",
    )


@contextmanager
def about_file(path: Path) -> Iterator[None]:
    """Name ``path`` in an error of a call that uses that one file (``"a.bin: the points lie on
    one ray ..."``); an error that already names a file passes unchanged."""
    from flexreg.errors import FlexregError, InputError

    try:
        yield
    except InputError as e:
        if e.source is not None and e.source not in ("points", "scan"):
            raise
        raise InputError(path, e.problem) from e
    except FlexregError as e:
        raise InputError(path, str(e)) from e


@contextmanager
def about_pair(first: Path, second: Path) -> Iterator[None]:
    """Name both files in an error of a call that uses two of them (``"a.ptx ↔ b.ptx: too few
    inliers"``); an error about one named file passes unchanged."""
    from flexreg.errors import FlexregError, InputError, RegistrationError

    try:
        yield
    except FlexregError as e:
        names = {str(first), str(second)}
        if isinstance(e, InputError) and e.source in names:
            raise
        pair = f"{first} ↔ {second}"
        if isinstance(e, InputError):
            raise InputError(pair, str(e)) from e
        try:
            again = type(e)(f"{pair}: {e}")
        except TypeError:
            again = RegistrationError(f"{pair}: {e}")
        raise again from e


def pair_label(
    target: object, source: object, first: str = "target", second: str = "source"
) -> str:
    """``"target = a.ptx, source = b.ptx"``: every table of a pair says which file is which
    (Open3D and CloudCompare put the source first; flexreg puts the target first)."""
    return f"{first} = {target}, {second} = {source}"


#: exit status of a command that wrote its result but does not trust it (see ``flexreg --help``)
EXIT_UNCERTAIN = 3

#: what to do about each reason code, in words (codes not listed get the general advice)
ADVICE = {
    "ambiguous": "check which of the listed poses is right (a known rough position decides)",
    "low_overlap": "check that the scans see the same place; a station between them helps",
    "weak_axis": "the geometry holds the pose weakly along one axis: check the link along it",
    "few_inliers": "too little agrees: inspect the pair before using it",
    "clustered_inliers": "the agreeing points lie in one small area: inspect the pair",
    "free_space": "parts of one scan lie where the other scanner saw through: inspect the pair",
    "high_residual": "the surfaces do not meet closely: inspect the pair",
    "coplanar_points": "add pairs whose lidar points lie off that plane",
    "collinear_points": "add pairs whose lidar points lie off that line",
    "clustered_pixels": "add pairs spread over the whole camera image",
}


def _along(delta: Any) -> str:
    """``" (mostly along x)"`` when one axis carries most of a translation."""
    import numpy as np

    d = np.abs(np.asarray(delta, dtype=np.float64))
    n = float(np.linalg.norm(d))
    if n <= 0 or not np.isfinite(n):
        return ""
    k = int(np.argmax(d))
    return f" (mostly along {'xyz'[k]})" if d[k] >= 0.9 * n else ""


def versus_answer(ratio: float) -> str:
    """A runner-up's score ratio (its score over the answer's; the score counts agreeing
    points less three times the contradicting ones) in words.

    >>> versus_answer(0.86)
    'explains 14 % less of the data than the answer'
    >>> versus_answer(1.0), versus_answer(1.05)
    ('explains the data as well as the answer', 'explains 5 % more of the data than the answer')
    >>> versus_answer(-0.14)
    'the data contradict it: it fits far worse than the answer'
    """
    if ratio < 0:
        return "the data contradict it: it fits far worse than the answer"
    pct = round(100 * abs(1 - ratio))
    if ratio < 1 and pct >= 100:
        return "explains next to nothing of what the answer explains"
    if pct == 0:
        return "explains the data as well as the answer"
    return f"explains {pct} % {'less' if ratio < 1 else 'more'} of the data than the answer"


def verdict_lines(verdict: Verdict | None, T: Any = None) -> list[str]:
    """The verdict in words: status, one line per reason, one per runner-up pose.

    ``T`` (the winning transform) lets a runner-up's offset name its main axis.
    """
    import numpy as np

    if verdict is None:
        return []
    notes = [f"  note: {r.message} [{r.code}]" for r in getattr(verdict, "notes", ())]
    if verdict.confident:
        return ["verdict: confident", *notes]
    lines = ["verdict: UNCERTAIN -- written, but do not use it unchecked"]
    lines += [f"  - {r.message} [{r.code}]" for r in verdict.reasons]
    for i, h in enumerate(verdict.runner_up, 1):
        where = ""
        if T is not None:
            where = _along(np.asarray(h.T_target_source)[:3, 3] - np.asarray(T)[:3, 3])
        origin = f", from {h.origin}" if h.origin else ""
        lines.append(
            f"  runner-up {i}: {h.rotation_deg:.1f}° and {h.translation_m:.2f} m away{where}, "
            f"{versus_answer(h.score_ratio)} (score ratio {h.score_ratio:.2f}){origin}"
        )
    return lines + notes


def what_to_do(verdict: Verdict, output: Path, *, extra: str = "") -> str:
    """The last line of an uncertain run: what was written and what to do next."""
    seen = dict.fromkeys(ADVICE[r.code] for r in verdict.reasons if r.code in ADVICE)
    steps = "; ".join(seen) or "inspect the result before using it"
    if verdict.runner_up:
        steps += f"; the runner-up transforms are in {output} under verdict.runner_up"
    return (
        f"uncertain (exit status {EXIT_UNCERTAIN}): {output} was written with the reasons; "
        f"{steps}{extra}."
    )


def print_verdict(verdict: Verdict | None, T: Any = None) -> None:
    """Print :func:`verdict_lines` on the console (nothing without a verdict)."""
    for line in verdict_lines(verdict, T):
        console.print(line, markup=False, highlight=False, soft_wrap=True)


def exit_for(verdict: Verdict | None, output: Path, *, extra: str = "") -> None:
    """Leave with :data:`EXIT_UNCERTAIN` after the advice line when the verdict is uncertain;
    return (exit 0) when it is confident or there is none."""
    import typer

    if verdict is None or verdict.confident:
        return
    err_console.print(
        what_to_do(verdict, output, extra=extra), markup=False, highlight=False, soft_wrap=True
    )
    raise typer.Exit(EXIT_UNCERTAIN)
