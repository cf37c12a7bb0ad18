"""`flexreg register`: two scans -> ``T_target_source`` as JSON (+ 4x4 text, match image, merged
cloud)."""

from __future__ import annotations

from contextlib import AbstractContextManager
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Annotated, Any

import typer

from flexreg.cli._common import (
    about_pair,
    auto_viewpoint,
    console,
    exit_for,
    pair_label,
    print_verdict,
    read_pair,
    read_pair_working,
    scan_file,
    stage,
    write_all,
)
from flexreg.cli.app import app
from flexreg.cli.options import (
    ConfigFileOption,
    SetOption,
    build_config,
    check_outputs,
    with_default,
)
from flexreg.errors import ConfigError, InputError
from flexreg.registration.config import RegistrationConfig

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    from flexreg.core.scan import Scan
    from flexreg.registration.pipeline import RegistrationResult

#: colours of the merged cloud (Okabe-Ito orange and blue, distinguishable when colour-blind)
TARGET_RGB = (230, 159, 0)
SOURCE_RGB = (0, 114, 178)
#: options that set a field of RegistrationConfig (option -> field)
OPTIONS = {
    "--method": "method",
    "--image": "image",
    "--n": "n",
    "--features": "features",
    "--refine": "refine",
    "--icp": "icp",
    "--voxel": "voxel_m",
    "--threshold": "threshold_m",
    "--seed": "seed",
    "--upright": "prior.upright",
}
_C = RegistrationConfig


class _StageSpinners(AbstractContextManager["_StageSpinners"]):
    """``register(progress=...)`` reports each stage as it starts; show each with :func:`stage`
    until the next one starts (or the call returns)."""

    def __init__(self) -> None:
        self._current: AbstractContextManager[None] | None = None

    def __call__(self, name: str) -> None:
        self._close(None, None, None)
        cm = stage(name[:1].upper() + name[1:])
        cm.__enter__()
        self._current = cm

    def _close(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        cm, self._current = self._current, None
        if cm is not None:
            cm.__exit__(exc_type, exc, tb)

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._close(exc_type, exc, tb)


def _match_figure(
    target: Scan, source: Scan, result: RegistrationResult, names: tuple[str, str]
) -> Any:
    """Both feature images (target on top), every lifted match drawn, inliers and outliers
    apart, file names and counts in the title (:func:`flexreg.viz.matches.match_figure`)."""
    from flexreg.registration.pipeline import feature_image
    from flexreg.stages.projection import range_image
    from flexreg.viz.matches import match_figure

    ft, _ = feature_image(range_image(target), result.config)
    fs, _ = feature_image(range_image(source), result.config)
    kt, ks = result.keypoints
    return match_figure(
        ft,
        fs,
        kt,
        ks,
        result.inlier_mask,
        target_name=names[0],
        source_name=names[1],
        threshold_m=result.threshold_m,
    )


def _merged_scan(target: Scan, source: Scan, T: NDArray[np.float64]) -> Scan:
    """Both clouds in the target frame, target and source each in one colour."""
    import numpy as np

    from flexreg.core.scan import Scan
    from flexreg.core.transforms import apply

    colors = np.empty((len(target) + len(source), 3), dtype=np.uint8)
    colors[: len(target)] = TARGET_RGB
    colors[len(target) :] = SOURCE_RGB
    points = np.concatenate([target.points, apply(T, source.points)])
    return Scan(points=points, colors=colors, name="merged")


_TargetArgument = Annotated[
    Path,
    typer.Argument(
        metavar="TARGET",
        help="Target scan: any readable scan file (FILE#N or FILE#NAME for one setup of a "
        "multi-setup PTX/E57), or a depth PNG with its camera sidecar. Points are used in the "
        "scanner frame; a pose stored in the file is used only by --init stored and the "
        "stored-pose check.",
    ),
]
_SourceArgument = Annotated[
    Path,
    typer.Argument(metavar="SOURCE", help="Source scan, mapped onto TARGET by T_target_source."),
]
_OutOption = Annotated[
    Path,
    typer.Option(
        "--out", help="Output .json: T_target_source with inliers, RMSE, timings, config."
    ),
]
_TxtOption = Annotated[
    Path | None,
    typer.Option("--txt", help="Also write the 4x4 matrix as text (CloudCompare style)."),
]
_TxtFrameOption = Annotated[
    str | None,
    typer.Option(
        "--txt-frame",
        metavar="file|scanner",
        help="Coordinates of the --txt matrix when --target-origin/--source-origin are given: "
        "'file' maps the source file's points onto the target file's, to apply to the files "
        "as they are (identity for two files already in one project frame); 'scanner' is "
        "T_target_source between the clouds moved to their origins (the JSON's matrix). "
        "Without origins both are the same. [default: file]",
    ),
]
_ImageOption = Annotated[
    str | None,
    typer.Option(
        "--image",
        help=with_default(
            _C, "image", "Feature image: flexion, bearing-*, range, ... or intensity."
        ),
    ),
]
_NOption = Annotated[
    int | None, typer.Option("--n", help=with_default(_C, "n", "Odd grid size n of Flexion n x n."))
]
_FeaturesOption = Annotated[
    str | None,
    typer.Option(
        "--features",
        help=with_default(
            _C, "features", "Detector/descriptor: sift, orb, akaze, kaze, brisk, surf."
        ),
    ),
]
_RefineOption = Annotated[
    bool | None,
    typer.Option(
        "--refine/--no-refine",
        help=with_default(_C, "refine", "Refine the RANSAC transform with ICP."),
    ),
]
_IcpOption = Annotated[
    str | None,
    typer.Option(
        "--icp",
        help=with_default(_C, "icp", "ICP variant: point-to-plane, gicp or point-to-point."),
    ),
]
_VoxelOption = Annotated[
    float | None,
    typer.Option(
        "--voxel", metavar="METRES", help="ICP voxel size, metres (default: from spacing)."
    ),
]
_ThresholdOption = Annotated[
    float | None,
    typer.Option(
        "--threshold",
        metavar="METRES",
        help="RANSAC inlier distance, metres (default: from the scans' pixel footprint).",
    ),
]
_MatchesOption = Annotated[
    Path | None,
    typer.Option(
        "--matches",
        help="Write a .png of both feature images (target on top) with the matched keypoint "
        "pairs: inliers and outliers in two colours, file names and counts in the title.",
    ),
]
_MergedOption = Annotated[
    Path | None,
    typer.Option(
        "--merged",
        help="Write a .ply of both clouds in the target frame (target orange, source blue).",
    ),
]
_SeedOption = Annotated[
    int | None,
    typer.Option(
        "--seed", help=with_default(_C, "seed", "Random seed; the same seed gives the same T.")
    ),
]
_MethodOption = Annotated[
    str | None,
    typer.Option(
        "--method",
        metavar="auto|flexion|geometric|init",
        help=with_default(
            _C,
            "method",
            "Where the hypotheses come from: flexion (feature images), geometric (FPFH "
            "descriptors of the clouds), auto (feature images for two stations on which "
            "they find a prior, both otherwise) or init (--init alone, as --icp-only); the "
            "same verdict judges them all.",
        ),
    ),
]
_UprightOption = Annotated[
    str | None,
    typer.Option(
        "--upright",
        help=with_default(
            _C,
            "prior.upright",
            "Levelled-scanner plan-view prior: auto (when both scans look levelled), on "
            "(required) or off.",
        ),
    ),
]
_TruthOption = Annotated[
    Path | None,
    typer.Option(
        "--truth",
        help="Known T_target_source (.json or 4x4 .txt; a 'flexreg synth' gt.json works): "
        "report the errors in degrees and metres and store them in the output JSON.",
    ),
]
_InitOption = Annotated[
    str | None,
    typer.Option(
        "--init",
        metavar="T.txt|T.json|stored",
        help="Initial T_target_source: a transform file (4x4 .txt, or .json), or 'stored' for "
        "the relative pose the files store for the two setups (E57 pose, PTX header). It "
        "competes with the global search unless --icp-only.",
    ),
]
_IcpOnlyOption = Annotated[
    bool | None,
    typer.Option(
        "--icp-only/--search",
        help="Refine from --init only, without global search (--method init). [default: no]",
    ),
]

_TargetOriginOption = Annotated[
    tuple[float, float, float] | None,
    typer.Option(
        "--target-origin",
        metavar="X Y Z",
        help="Where the target's scanner stood, in its file's frame, metres: for clouds in "
        "project or map coordinates (LAS/LAZ, PLY exports).",
    ),
]
_SourceOriginOption = Annotated[
    tuple[float, float, float] | None,
    typer.Option(
        "--source-origin",
        metavar="X Y Z",
        help="Where the source's scanner stood, in its file's frame, metres.",
    ),
]


def _method(method: str | None, icp_only: bool | None) -> str | None:
    """The ``method`` field of ``--method`` and ``--icp-only`` (an alias of ``--method init``)."""
    if icp_only and method not in (None, "init"):
        raise ConfigError(f"--icp-only and --method {method} contradict each other: give one")
    return "init" if icp_only else method


@app.command("register")
def register_command(
    target: _TargetArgument,
    source: _SourceArgument,
    out: _OutOption,
    txt: _TxtOption = None,
    txt_frame: _TxtFrameOption = None,
    method: _MethodOption = None,
    image: _ImageOption = None,
    n: _NOption = None,
    features: _FeaturesOption = None,
    refine: _RefineOption = None,
    icp: _IcpOption = None,
    voxel: _VoxelOption = None,
    threshold: _ThresholdOption = None,
    matches: _MatchesOption = None,
    merged: _MergedOption = None,
    seed: _SeedOption = None,
    upright: _UprightOption = None,
    truth: _TruthOption = None,
    init: _InitOption = None,
    icp_only: _IcpOnlyOption = None,
    target_origin: _TargetOriginOption = None,
    source_origin: _SourceOriginOption = None,
    config_file: ConfigFileOption = None,
    sets: SetOption = None,
) -> None:
    """Register SOURCE onto TARGET (feature images, FPFH or both); write T_target_source.

    \b
    Exit status:
      0  written, and the result is confident
      3  written, but uncertain: the reasons and any runner-up transforms are on screen
         and in the output JSON under "verdict"; check the pair before using it
      1  failed: one error line, nothing written
    """
    from flexreg.io.setups import stored_T_target_source
    from flexreg.registration.pipeline import register

    nested: dict[str, Any] = {"prior.upright": upright}  # a key that is not a Python name
    config = build_config(
        RegistrationConfig,
        config_file,
        sets,
        OPTIONS,
        method=_method(method, icp_only),
        image=image,
        n=n,
        features=features,
        refine=refine,
        icp=icp,
        voxel_m=voxel,
        threshold_m=threshold,
        seed=seed,
        **nested,
    )
    frame = _check_options(config, init, txt, txt_frame)
    files = [("--out", out, ".json"), ("--txt", txt, None), ("--matches", matches, ".png")]
    check_outputs(
        [*files, ("--merged", merged, ".ply")],
        inputs=(scan_file(target), scan_file(source)),
        extra_inputs=[
            ("--truth", truth),
            ("--config", config_file),
            ("--init", None if init in (None, "stored") else Path(init)),
        ],
    )
    T_true = None if truth is None else read_truth(truth, target, source)
    T_file = None if init in (None, "stored") else read_truth(Path(init), target, source)
    scans, images, origins = _read(target, source, config, matches, (target_origin, source_origin))
    stored = stored_T_target_source(scans[0], scans[1])
    if init == "stored" and stored is None:
        raise InputError(
            "--init stored", f"neither {target} nor {source} stores a setup pose (both identity)"
        )
    T_init = stored if init == "stored" else T_file
    with _StageSpinners() as spinners, about_pair(target, source):
        result = register(
            scans[0],
            scans[1],
            config,
            progress=spinners,
            init=T_init,
            images=images,  # handed over
        )
    errors = None if T_true is None else _errors(result, T_true)
    check = None if stored is None or init is not None else _stored_check(result, stored)
    meta: dict[str, Any] = {
        "target": str(target),
        "source": str(source),
        "truth": truth,
        "errors": errors,
        "init": None if init is None else {"from": init, "T_target_source": T_init},
        "stored_pose_check": check,
        "origins": origins,
        "txt_frame": frame,
    }
    writers = _writers(scans[0], scans[1], result, meta, out, txt, matches, merged)
    write_all(writers)
    _print_summary(result, config, target, source, errors, check)
    print_verdict(result.verdict, result.T_target_source)
    note = "" if txt is None else _txt_note(frame, result.T_target_source, scans[1], meta)
    for path, _ in writers:
        console.print(f"wrote {path}{note if path == txt else ''}", markup=False, soft_wrap=True)
    look = f"{merged} shows" if merged is not None else "--merged merged.ply would show"
    exit_for(result.verdict, out, extra=f"; {look} both clouds as registered")


#: what the --txt matrix maps, said after its "wrote" line in a run with scanner origins
_FRAME_NOTE = {
    "file": " (in the files' coordinates: apply it to the source file as it is)",
    "scanner": (
        " (between the clouds moved to --target-origin/--source-origin, not the files' "
        "coordinates: --txt-frame file gives those)"
    ),
}


def _txt_note(frame: str, T: NDArray[np.float64], source: Scan, meta: dict[str, Any]) -> str:
    """What the --txt matrix of a run with scanner origins maps, after its "wrote" line: in the
    files' coordinates, with how far it moves the source file's points (median over at most
    10^5 of them)."""
    import numpy as np

    from flexreg.core.transforms import apply
    from flexreg.io.origin import in_file_frame

    origins = meta["origins"]
    if not any(origins):
        return ""
    if frame != "file" or len(source) == 0:
        return _FRAME_NOTE[frame]
    o_s = np.zeros(3) if origins[1] is None else np.asarray(origins[1], dtype=np.float64)
    points = source.points[:: max(1, len(source) // 100_000)].astype(np.float64) + o_s
    moved = np.linalg.norm(apply(in_file_frame(T, *origins), points) - points, axis=1)
    return f"{_FRAME_NOTE[frame][:-1]}; it moves its points by {np.median(moved):.3f} m)"


def _check_options(
    config: RegistrationConfig, init: str | None, txt: Path | None, frame: str | None
) -> str:
    """Refuse options that do not go together (before any file is read); the frame of the
    ``--txt`` matrix: ``file`` (the default) or ``scanner``."""
    if config.icp_only and init is None:
        raise InputError("--icp-only", "needs --init T.txt or --init stored")
    if frame is None:
        return "file"
    if frame not in _FRAME_NOTE:
        raise InputError("--txt-frame", f"must be file or scanner, got {frame!r}")
    if txt is None:
        raise InputError("--txt-frame", "applies to the --txt matrix: give --txt as well")
    return frame


def _origins_meta(T: NDArray[np.float64], inputs: dict[str, Any]) -> dict[str, Any]:
    """The JSON's account of a run with scanner origins: the origins, what its matrix maps,
    the same transform in the files' coordinates, and the frame of the --txt matrix."""
    from flexreg.io.origin import in_file_frame

    o_t, o_s = inputs["origins"]
    return {
        "origins": {
            "target": None if o_t is None else list(o_t),
            "source": None if o_s is None else list(o_s),
        },
        "frame": "T_target_source maps source points relative to the source origin onto target "
        "points relative to the target origin (the files' coordinates minus each origin)",
        "T_target_source_in_files": in_file_frame(T, o_t, o_s).tolist(),
    }


def _read(
    target: Path,
    source: Path,
    config: RegistrationConfig,
    matches: Path | None,
    origins: tuple[Any, Any],
) -> tuple[list[Scan], list[Any] | None, tuple[Any, Any]]:
    """Both scans, read for what the call and the outputs need: their points and working
    images straight from a PTX file unless the match figure needs the scans' grids, the
    intensity image their intensities, or a scanner position moves their points. A cloud
    not centred on its scanner and without its position given is seen from a virtual
    viewpoint (:func:`~flexreg.cli._common.auto_viewpoint`). Returns the scans, their
    working images (None: made by the call) and the origins used (given or chosen)."""
    names = ("--target-origin", "--source-origin")
    options = (
        names[0] if origins[0] is not None else None,
        names[1] if origins[1] is not None else None,
    )
    images: list[Any] | None = None
    if matches is None and config.image != "intensity" and not any(origins):
        pixels = config.max_image_pixels
        working = read_pair_working(target, source, max_pixels=pixels)
        scans, images = working.scans, working.take_images()
    else:
        intensity = config.image == "intensity"  # no other stage or output reads it
        scans = read_pair(target, source, origins, options, intensity=intensity)
    used = list(origins)
    for k, file in enumerate((target, source)):
        if origins[k] is None:
            scans[k], chosen = auto_viewpoint(scan_file(file), scans[k], names[k])
            if chosen is not None:
                used[k] = tuple(float(v) for v in chosen)
                if images is not None:
                    images[k] = None  # made from the points as read: made again
    return scans, images, (used[0], used[1])


def _writers(
    tscan: Scan,
    sscan: Scan,
    result: RegistrationResult,
    inputs: dict[str, Any],
    out: Path,
    txt: Path | None,
    matches: Path | None,
    merged: Path | None,
) -> list[tuple[Path, Any]]:
    """Compute every output (before the first file is written); the JSON comes last."""
    from flexreg._version import __version__
    from flexreg.io import atomic_write, write_scan, write_transform_json, write_transform_txt

    T = result.T_target_source
    moved = any(inputs["origins"])
    T_txt = T
    if moved and inputs["txt_frame"] == "file":
        from flexreg.io.origin import in_file_frame

        T_txt = in_file_frame(T, *inputs["origins"])
    writers: list[tuple[Path, Any]] = []
    if merged is not None:
        with stage("Merging clouds"):
            cloud = _merged_scan(tscan, sscan, T)
        writers.append((merged, lambda: write_scan(merged, cloud)))
    if matches is not None:
        from flexreg.viz.matches import save_figure

        with stage("Drawing matches"):
            names = (Path(inputs["target"]).name, Path(inputs["source"]).name)
            fig = _match_figure(tscan, sscan, result, names)
        writers.append((matches, lambda: atomic_write(matches, lambda tmp: save_figure(fig, tmp))))
    if txt is not None:
        writers.append((txt, lambda: write_transform_txt(txt, T_txt)))
    meta = result.to_dict()
    meta.pop("T_target_source", None)
    meta = {"target": inputs["target"], "source": inputs["source"], **meta}
    meta["inliers_of"] = "matched keypoint pairs (RANSAC of the coarse stage)"
    meta["flexreg_version"] = __version__
    if inputs["errors"] is not None:
        meta["error_vs_truth"] = {"truth": str(inputs["truth"]), **inputs["errors"]}
    if inputs["init"] is not None:
        meta["init"] = {
            "from": inputs["init"]["from"],
            "T_target_source": inputs["init"]["T_target_source"].tolist(),
        }
    if inputs["stored_pose_check"] is not None:
        meta["stored_pose_check"] = inputs["stored_pose_check"]
    if moved:
        meta.update(_origins_meta(T, inputs))
    if txt is not None:
        frame = inputs["txt_frame"] if moved else "file"  # without origins: one and the same
        meta["txt"] = {"path": str(txt), "frame": frame}
    writers.append((out, lambda: write_transform_json(out, T, **meta)))
    return writers


def read_truth(path: Path, target: Path, source: Path) -> NDArray[np.float64]:
    """A known ``T_target_source``: a transform file, or the pair ``target``/``source`` (by
    file stem, either order) of a ``flexreg synth`` gt.json
    (:func:`flexreg.io.transform_io.read_pair_transform`)."""
    from flexreg.io.transform_io import read_pair_transform

    return read_pair_transform(path, target.stem, source.stem)


def _errors(result: RegistrationResult, T_true: NDArray[np.float64]) -> dict[str, float]:
    from flexreg.core.transforms import rotation_error_deg, translation_error_m

    return {
        "coarse_rotation_deg": rotation_error_deg(result.T_coarse, T_true),
        "coarse_translation_m": translation_error_m(result.T_coarse, T_true),
        "rotation_deg": rotation_error_deg(result.T_target_source, T_true),
        "translation_m": translation_error_m(result.T_target_source, T_true),
    }


def _stored_check(result: RegistrationResult, stored: NDArray[np.float64]) -> dict[str, Any]:
    """How far the result is from the relative pose the files store (degrees, metres)."""
    from flexreg.core.transforms import rotation_error_deg, translation_error_m

    return {
        "rotation_deg": rotation_error_deg(result.T_target_source, stored),
        "translation_m": translation_error_m(result.T_target_source, stored),
        "T_target_source_stored": stored.tolist(),
    }


def _mm(m: float) -> str:
    import math

    return f"{1000 * m:.2f} mm" if math.isfinite(m) else "n/a"


def keypoints_line(result: RegistrationResult, config: RegistrationConfig) -> str:
    """The summary's keypoint line: how many matched pairs are inliers, and, when the pose
    was not fitted to them (found from the plan view), that it was not.

    >>> from types import SimpleNamespace as NS
    >>> cfg = NS(features="sift", image="flexion")
    >>> r = NS(inliers=0, matches=1, threshold_m=0.05,
    ...        verdict=NS(evidence={"inliers": {"fit_to_matches": False}}))
    >>> keypoints_line(r, cfg)  # doctest: +NORMALIZE_WHITESPACE
    '0 of 1 matched keypoint pairs are inliers (0.0 %) within 50.0 mm (sift on flexion);
     the pose is from the plan view, not fitted to them'
    >>> r.verdict.evidence["inliers"]["fit_to_matches"] = True
    >>> keypoints_line(r, cfg).endswith("(sift on flexion)")
    True
    """
    r = result
    share = 100 * r.inliers / r.matches if r.matches else 0.0
    ev = r.verdict.evidence.get("inliers") if r.verdict is not None else None
    from_matches = not isinstance(ev, dict) or ev.get("fit_to_matches", True)
    return (
        f"{r.inliers:,} of {r.matches:,} matched keypoint pairs are inliers ({share:.1f} %) "
        f"within {1000 * r.threshold_m:.1f} mm ({config.features} on {config.image})"
        + ("" if from_matches else "; the pose is from the plan view, not fitted to them")
    )


def _print_summary(
    result: RegistrationResult,
    config: RegistrationConfig,
    target: Path,
    source: Path,
    errors: dict[str, float] | None = None,
    stored: dict[str, Any] | None = None,
) -> None:
    import numpy as np
    from rich.table import Table

    from flexreg.core.transforms import rotation_error_deg, translation_error_m

    def motion(T: NDArray[np.float64]) -> str:
        rot, dist = rotation_error_deg(T, np.eye(4)), float(np.linalg.norm(T[:3, 3]))
        return f"rotation {rot:.3f}°, translation {dist:.3f} m"

    r = result
    final = "ICP " + config.icp if config.refine else "keypoint inliers, not refined"
    t = Table(
        title=f"T_target_source: {pair_label(target, source)}",
        show_header=False,
        title_justify="left",
    )
    t.add_column(style="bold")
    t.add_column()
    if r.overlap is not None:
        o = r.overlap
        t.add_row("overlap", o.headline())
        if o.open3d_fitness is not None and o.open3d_inlier_rmse_m is not None:
            t.add_row(
                "open3d",
                f"fitness {o.open3d_fitness:.4f}, inlier_rmse {_mm(o.open3d_inlier_rmse_m)} "
                f"(evaluate_registration at {_mm(o.distance_m)}, the same clouds)",
            )
    t.add_row("keypoints", keypoints_line(r, config))
    t.add_row("inlier RMSE", f"{_mm(r.inlier_rmse_m)} ({final})")
    t.add_row("stage fitness", f"{r.fitness:.3f} of {r.fitness_denominator}")
    t.add_row("prior", r.prior)
    t.add_row("coarse", motion(r.T_coarse))
    t.add_row("final", motion(r.T_target_source))
    if errors is not None:
        t.add_row(
            "error vs truth",
            f"coarse {errors['coarse_rotation_deg']:.3f}°, "
            f"{1000 * errors['coarse_translation_m']:.1f} mm; final "
            f"{errors['rotation_deg']:.4f}°, {1000 * errors['translation_m']:.2f} mm",
        )
    if stored is not None:
        t.add_row(
            "vs stored poses",
            f"{stored['rotation_deg']:.3f}°, {stored['translation_m']:.3f} m from the relative "
            "pose the files store (--init stored uses it)",
        )
    if config.refine:
        dr = rotation_error_deg(r.T_target_source, r.T_coarse)
        dt = translation_error_m(r.T_target_source, r.T_coarse)
        t.add_row("refinement moved", f"{dr:.3f}°, {1000 * dt:.1f} mm")
    timings = ", ".join(f"{k} {v:.2f}" for k, v in r.timings_s.items())
    t.add_row(
        "timings s",
        f"{timings}; total {r.wall_s:.2f} (plan views and preparation run beside the "
        "feature stages)",
    )
    console.print(t)
    with np.printoptions(precision=6, suppress=True):
        console.print(str(r.T_target_source), markup=False)
