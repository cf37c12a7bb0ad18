"""`flexreg survey`: register a whole project of stations -> poses.json, stations/, report."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from typer.core import TyperCommand

from flexreg.cli._common import EXIT_UNCERTAIN, console, err_console, pair_label
from flexreg.cli.app import app
from flexreg.cli.config_cmd import add_config
from flexreg.cli.options import (
    ConfigFileOption,
    SetOption,
    build_config,
    check_out_folder,
    check_outputs,
    removed_line,
)
from flexreg.config import did_you_mean
from flexreg.errors import ConfigError, RegistrationError
from flexreg.registration.config import AS_CHECKS, RENAMED, RETIRED, RegistrationConfig, leaf_fields
from flexreg.survey.config import SurveyConfig

if TYPE_CHECKING:
    from rich.progress import Progress

    from flexreg.survey.execute import ProgressEvent
    from flexreg.survey.project import SurveyResult

#: options that set a field of SurveyConfig (option -> field)
OPTIONS = {"--pairs": "pairs", "--refine": "joint_refine", "--stored-sigma": "stored_sigma_m"}
MERGED_SUFFIXES = (".ply", ".las", ".laz", ".e57")
add_config("survey", SurveyConfig)

PHASES = {
    "prepare": "Preparing stations",
    "links": "Registering links",
    "positions": "Links the positions bring near",
    "map check": "Checking the map",
    "refine": "Final alignment",
}

#: the phases whose tasks are links (confident, uncertain or failed); in the others a task
#: that fails is a station that could not be read
LINK_PHASES = ("links", "positions")

_ScansArgument = Annotated[
    list[Path],
    typer.Argument(
        metavar="SCAN...",
        help="Scan files, or folders (every .ptx .e57 .ply .pcd .las .laz .npz .3d file in "
        "them). Each file is one station, named by its file name without extension; an E57 or "
        "PTX file holding several setups gives one station per setup, named STEM#N. Poses "
        "the files store seed the links and are checked against the result (--set "
        "stored_poses=check|ignore to change that).",
    ),
]
_OutOption = Annotated[
    Path,
    typer.Option(
        "--out",
        metavar="DIR",
        help="Output folder: poses.json, stations/STEM.txt, report.html; prepared stations "
        "are cached in DIR/cache/ (a re-run prepares only new or changed scans).",
    ),
]
_PairsOption = Annotated[
    str | None,
    typer.Option(
        "--pairs",
        metavar="auto|all|sequential|[+]FILE.csv",
        help="Links to try: place recognition + file-order neighbours (auto), every pair, "
        "file-order neighbours, or the target,source rows of a CSV (+FILE.csv: those rows "
        "as well as the automatic candidates). [default: auto]",
    ),
]
_LinkOption = Annotated[
    list[Any] | None,
    typer.Option(
        "--link",
        metavar="TARGET SOURCE T.txt",
        help="A link given by hand (repeatable): two stations (stems or file names) and their "
        "T_target_source (a 4x4 text matrix, or a JSON with T_target_source, as register "
        "--init reads it). It is registered like any other link, seeded with that pose "
        "(refined and checked), in place of any other candidate of the pair.",
    ),
]
_WorkersOption = Annotated[
    int | None,
    typer.Option(
        "--workers",
        help="Worker processes of the local Dask cluster [default: the machine's cores; 1 "
        "runs without Dask].",
    ),
]
_SchedulerOption = Annotated[
    str | None,
    typer.Option(
        "--scheduler",
        metavar="tcp://HOST:8786",
        help="Run on an existing Dask cluster (see docs/survey.md: every worker needs "
        "flexreg, the scans and DIR at the same paths).",
    ),
]
_DashboardOption = Annotated[
    str | None,
    typer.Option(
        "--dashboard",
        metavar="[HOST:]PORT",
        help="Serve the local Dask cluster's dashboard (not authenticated) at this address, "
        "on loopback unless a host is named [default: no dashboard].",
    ),
]
_ReferenceOption = Annotated[
    str | None,
    typer.Option(
        "--reference",
        metavar="STEM",
        help="Station whose frame the poses are in [default: the first station by name of "
        "the largest group].",
    ),
]
_RefineOption = Annotated[
    bool | None,
    typer.Option(
        "--refine/--no-refine",
        help="The final joint alignment: every placed station refined on its overlapping "
        "points, with its accuracy and status (--no-refine: poses of the links alone, "
        "accuracy unchecked). [default: yes]",
    ),
]
_FrameOption = Annotated[
    str,
    typer.Option(
        "--frame",
        metavar="reference|stored",
        help="Frame of the written poses, station matrices and clouds: the reference "
        "station's, or 'stored': the site frame the files store their setups in (E57 poses, "
        "PTX headers). poses.json holds both.",
    ),
]
_OriginsOption = Annotated[
    Path | None,
    typer.Option(
        "--origins",
        metavar="FILE.csv",
        help="Scanner positions of stations whose points are in project coordinates "
        "(georeferenced LAS/LAZ): rows stem,x,y,z in metres, in each file's frame; the "
        "stations are registered about them and the results come out in the files' "
        "coordinates.",
    ),
]
_PositionsOption = Annotated[
    Path | None,
    typer.Option(
        "--positions",
        metavar="FILE.csv",
        help="Rough station positions (a field sketch, GNSS): header "
        "stem,x,y,z,heading_deg,sigma_m (metres and degrees; z, heading_deg, sigma_m may be "
        "empty, sigma 1 m by default; heading: the scanner's x axis from the site's x axis). "
        "Of each link they pick the one pose within 3 sigma (look-alike bays, turned rooms); "
        "the poses also come out in their site frame.",
    ),
]
_StoredSigmaOption = Annotated[
    float | None,
    typer.Option(
        "--stored-sigma",
        metavar="METRES",
        help="The poses the files store are rough (a field software's or a sketch's), their "
        "positions good to this 1-sigma in metres: they decide between each link's poses "
        "like --positions, and a station is flagged only beyond 3 sigma (default: they are "
        "an earlier registration, flagged beyond 1 degree / 10 cm).",
    ),
]
_MergedOption = Annotated[
    Path | None,
    typer.Option(
        "--merged",
        help="Write all placed stations as one cloud in the poses' frame: .ply, .las, .laz "
        "(site coordinates keep their millimetres) or .e57.",
    ),
]
_VoxelOption = Annotated[
    float,
    typer.Option("--voxel", metavar="METRES", help="Voxel of the merged cloud, metres."),
]
_E57Option = Annotated[
    Path | None,
    typer.Option("--e57", help="Write every placed station with its pose to one .e57 file."),
]
_SeedOption = Annotated[
    int | None,
    typer.Option("--seed", help="Random seed of every link (same seed, same poses). [default: 0]"),
]


def _configs(
    config_file: Path | None,
    sets: list[str] | None,
    pairs: str | None,
    refine: bool | None,
    seed: int | None,
    stored_sigma: float | None = None,
) -> tuple[SurveyConfig, Path | None, bool]:
    """The survey configuration (``--set`` keys of the registration go to its nested
    ``registration``; ``registration.KEY`` works too, and ``judge.KEY`` for a table of it),
    the pairs CSV, if any, and whether its pairs are added to the automatic ones (``+``)."""
    survey_sets, reg_sets = [], []
    for item in sets or ():
        key = item.partition("=")[0].strip()
        if key.startswith("registration."):
            reg_sets.append(item.removeprefix("registration."))
        elif key.partition(".")[0] in SurveyConfig.model_fields:
            survey_sets.append(item)
        elif key.partition(".")[0] in RegistrationConfig.model_fields or key in OLD_KEYS:
            reg_sets.append(item)
        else:
            known = [*leaf_fields(SurveyConfig), *leaf_fields(RegistrationConfig)]
            raise ConfigError(
                f"--set {key}: no such field of the survey or the registration"
                + did_you_mean(key, known)
            )
    pairs_file, add = None, False
    if pairs is not None and pairs not in ("auto", "all", "sequential"):
        add = pairs.startswith("+")
        pairs_file = Path(pairs.removeprefix("+"))
        if pairs_file.suffix.lower() != ".csv":
            raise ConfigError(
                f"--pairs: {pairs}: must be auto, all, sequential, a .csv file or +FILE.csv"
            )
        pairs = None
    cfg = build_config(
        SurveyConfig,
        config_file,
        survey_sets,
        OPTIONS,
        pairs=pairs,
        joint_refine=refine,
        stored_sigma_m=stored_sigma,
    )
    reg = build_config(
        RegistrationConfig, None, reg_sets, {"--seed": "seed"}, base=cfg.registration, seed=seed
    )
    return cfg.replace(registration=reg), pairs_file, add


#: keys of the registration's flat layout before its tables, still read for one release
OLD_KEYS = frozenset([*RENAMED, *AS_CHECKS, *RETIRED, "icp_only"])  # icp_only: method "init"


class _Bars:
    """Draws the library's progress events: one bar per phase with its counts and ETA."""

    def __init__(self, progress: Progress) -> None:
        self.progress = progress
        self.tasks: dict[str, Any] = {}

    def __call__(self, ev: ProgressEvent) -> None:
        from flexreg.cli.signals import raise_if_signalled

        raise_if_signalled()  # a Ctrl-C whose first raise a finaliser swallowed ends it here
        if ev.phase not in self.tasks or self.progress.tasks[self.tasks[ev.phase]].finished:
            self.tasks[ev.phase] = self.progress.add_task(
                PHASES.get(ev.phase, ev.phase), total=0, counts=""
            )
        counts = ""
        if ev.phase in LINK_PHASES:
            counts = f"confident {ev.confident}, uncertain {ev.uncertain}, failed {ev.failed}"
        elif ev.failed:
            counts = f"unreadable {ev.failed}"
        self.progress.update(self.tasks[ev.phase], completed=ev.done, total=ev.total, counts=counts)


def _progress() -> Progress:
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    return Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[counts]}"),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
        console=err_console,
    )


def _stored_note(check: dict[str, Any] | None) -> str:
    if check is None or check["agrees"] is not False:
        return ""
    return f"stored pose disagrees by {check['rotation_deg']:.2f}° / {check['translation_m']:.3f} m"


def _sigma(acc: dict[str, Any]) -> str:
    """A station's 1-sigma figures, marked unchecked where no independent route checks the
    links it rests on (they do not cover a wrong one)."""
    text = ", ".join(f"{v:.1f}" for v in acc["sigma_mm"].values())
    return text if acc.get("checked", True) else f"{text} (unchecked)"


def _summary(result: SurveyResult, doc: dict[str, Any]) -> None:
    from rich.table import Table

    s = doc["summary"]
    t = Table(
        title=f"Survey: reference {doc['reference']} (links in poses.json: target, source, "
        "T_target_source maps the source onto the target)",
        title_justify="left",
    )
    for col in ("station", "status", "group", "links", "1σ mm (x, y, z)", "note"):
        t.add_column(col)
    for stem, st in doc["stations"].items():
        acc = st.get("accuracy")
        t.add_row(
            stem,
            st["status"].replace("_", " "),
            "-" if st["group"] is None else str(st["group"]),
            f"{st['degree']}/{st['links_attempted']}",
            "-" if acc is None else _sigma(acc),
            st["error"]
            or st.get("status_why")
            or st["reason"]
            or _stored_note(st.get("stored_pose_check")),
        )
    console.print(t)
    fa = doc.get("final_alignment")
    bundle = (
        "final alignment off (accuracy unchecked)"
        if fa is None
        else "bundle error unchecked (no pair closes a loop)"
        if fa["bundle_error_mm"] is None
        else f"bundle error {fa['bundle_error_mm']:.2f} mm / {fa['bundle_error_deg']:.4f}° over "
        f"the {fa['pairs_checked']} cloud-to-cloud pairs that close loops "
        f"({fa['pairs_unchecked']} unchecked)"
    )
    console.print(
        f"{s['status_line']} (tolerance {s['tolerance_mm']:g} mm) of {s['stations']} stations "
        f"in {s['groups']} group(s); links {s['links_attempted']} tried: {s['links_accepted']} "
        f"accepted, {s['links_rejected']} rejected, {s['links_failed']} failed; {bundle}; "
        f"{s['prepared']} station(s) prepared, {s['from_cache']} from the cache; "
        f"{s['wall_s']:.1f} s on {s['workers']} worker(s)",
        markup=False,
        soft_wrap=True,
    )
    for line in rejected_lines(doc["links"]):
        console.print(line, markup=False, soft_wrap=True)


def rejected_lines(links: list[dict[str, Any]]) -> list[str]:
    """The console's lines on links a loop refuted: one per confident or hand-given link (news:
    two registrations the survey trusted disagree), and one counting the uncertain ones (the
    graph at work: a look-alike pose left out), each with its loop error in poses.json."""
    looped = [e for e in links if e["status"] == "rejected" and e["loop_error_deg"] is not None]
    news = [e for e in looped if e["verdict"] == "confident" or e["origin"] == "hand"]
    lines = [
        f"rejected link {pair_label(e['target'], e['source'])}: {e['why']} (loop error "
        f"{e['loop_error_deg']:.2f}°, {e['loop_error_m']:.3f} m)"
        for e in news
    ]
    if len(looped) > len(news):
        lines.append(
            f"{len(looped) - len(news)} uncertain link(s) disagreed with the loops they close "
            "and were left out (each with its loop error in poses.json and the report)"
        )
    return lines


class _SurveyCommand(TyperCommand):
    """The survey command, whose ``--link`` takes three values each time it is given (typer
    reads a repeatable option as one value per occurrence)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        for param in self.params:
            if param.name == "link":
                param.nargs = 3


@app.command("survey", cls=_SurveyCommand)
def survey_command(
    scans: _ScansArgument,
    out: _OutOption,
    pairs: _PairsOption = None,
    link: _LinkOption = None,
    workers: _WorkersOption = None,
    scheduler: _SchedulerOption = None,
    dashboard: _DashboardOption = None,
    reference: _ReferenceOption = None,
    refine: _RefineOption = None,
    stored_sigma: _StoredSigmaOption = None,
    merged: _MergedOption = None,
    voxel: _VoxelOption = 0.02,
    e57: _E57Option = None,
    frame: _FrameOption = "reference",
    origins: _OriginsOption = None,
    positions: _PositionsOption = None,
    seed: _SeedOption = None,
    config_file: ConfigFileOption = None,
    sets: SetOption = None,
) -> None:
    """Register a whole project: every station placed in one frame, every link checked.

    \b
    Exit status:
      0  every station verified: within the tolerance (--set tolerance_mm=, default 10)
         and confirmed by an independent route
      3  written, but some station is only placed, outside the tolerance, unplaced or
         unreadable (the count per status on one line, one line per station on screen, and
         in poses.json under summary.problems)
      1  failed: nothing could be registered (one error line; nothing written
         but the cache)
    """
    from flexreg.survey.outputs import write_outputs
    from flexreg.survey.project import run_survey

    cfg, pairs_file, add_pairs = _configs(config_file, sets, pairs, refine, seed, stored_sigma)
    if voxel <= 0:
        raise ConfigError(f"--voxel: must be a positive number of metres (got {voxel})")
    if merged is not None and merged.suffix.lower() not in MERGED_SUFFIXES:
        raise ConfigError(f"--merged: {merged}: must be a .ply, .las, .laz or .e57 file")
    if frame not in ("reference", "stored"):
        raise ConfigError(f"--frame: must be reference or stored (got {frame!r})")
    check_out_folder(
        "--out",
        out,
        scans,
        keep=("cache",),
        kept="(prepared stations and links) is kept either way and reused: only new or "
        "changed scans are prepared again",
    )
    check_outputs(
        [("--merged", merged, None), ("--e57", e57, ".e57")],
        inputs=[p for p in scans if p.is_file()],
        input_folders=[p for p in scans if p.is_dir()],
    )
    with _progress() as bar:
        result = run_survey(
            scans,
            out,
            cfg,
            workers=workers,
            scheduler=scheduler,
            dashboard=dashboard,
            reference=reference,
            pairs_file=pairs_file,
            add_pairs=add_pairs,
            links=[(t, s, Path(f)) for t, s, f in link or ()],
            origins_file=origins,
            positions_file=positions,
            frame=frame,  # type: ignore[arg-type]
            progress=_Bars(bar),
        )
    if result.exit_status == 1:
        problems = result.problems()
        raise RegistrationError(
            f"no station could be placed: no link was accepted ({len(result.links)} tried)"
            + (f"; {problems[0]}" if problems else "")
        )
    written = write_outputs(result, out, merged=merged, voxel_m=voxel, e57=e57)
    doc = result.to_dict()
    _summary(result, doc)
    for p in written:
        if p.parent.name != "stations":
            console.print(f"wrote {p}", markup=False, soft_wrap=True)
    console.print(f"wrote {len(result.placed)} station matrices to {out / 'stations'}")
    if gone := removed_line(out, " (made from its poses: stale now)"):
        console.print(gone, markup=False, highlight=False, soft_wrap=True)
    if result.exit_status == EXIT_UNCERTAIN:
        for line in result.problems():
            err_console.print(line, markup=False, highlight=False, soft_wrap=True)
        err_console.print(
            f"partial or uncertain (exit status {EXIT_UNCERTAIN}): {out / 'poses.json'} and "
            f"{out / 'report.html'} say which stations and links to check.",
            markup=False,
            soft_wrap=True,
        )
        raise typer.Exit(EXIT_UNCERTAIN)
