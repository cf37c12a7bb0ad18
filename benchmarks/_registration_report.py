"""The Markdown and the figure of ``benchmarks/registration.py``, made from its records.

Tables of the synthetic suite, the speed run and the real pairs with their verdicts against
the criteria of ``_registration_runs``, the notes on the real data, and the error scatter of
the synthetic pairs.

``registration.py`` imports this module as a sibling: ``python benchmarks/registration.py``
puts ``benchmarks/`` on ``sys.path``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from _registration_runs import (
    BUNNY_ROT_DEG,
    BUNNY_TRANS_M,
    COARSE_ROT_DEG,
    COARSE_TRANS_M,
    KURT_GROSS_ROT_DEG,
    KURT_GROSS_TRANS_M,
    KURT_MIN_RANGE_M,
    NN_WITHIN_M,
    SCENES,
    TARGET_ROT_DEG,
    TARGET_SPEED_S,
    TARGET_SUCCESS,
    TARGET_TRANS_M,
    VELODYNE_REF_ROT_DEG,
    VELODYNE_REF_TRANS_M,
    median,
    summarise,
)

from flexreg.core.transforms import rotation_error_deg, translation_error_m

# ------------------------------------------------------------------ tables


def stage_names(records: list[dict[str, Any]]) -> list[str]:
    """The stages of the ``timings_s`` of ``records``, in the order they first appear."""
    names: dict[str, None] = {}
    for r in records:
        names |= dict.fromkeys(r.get("timings_s", {}))
    return list(names)


def _f(x: float, fmt: str, scale: float = 1.0) -> str:
    """A table cell: ``x * scale`` formatted, ``–`` for None or NaN, ``∞`` for infinity.

    Parameters
    ----------
    x : float or None
        The value.
    fmt : str
        Its format specification (``".2f"``).
    scale : float
        Factor applied before formatting (1000: metres to millimetres).

    Returns
    -------
    str
    """
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "–"
    if math.isinf(x):
        return "∞"
    return format(x * scale, fmt)


def _verdict(ok: bool) -> str:
    """``**met**`` if ``ok`` (the target is met), else ``**NOT met**``."""
    return "**met**" if ok else "**NOT met**"


def render_synthetic(records: list[dict[str, Any]], resolution: tuple[int, int]) -> list[str]:
    """The synthetic section: set-up, summary against the targets, stage medians, one row per
    pair and the stage times per pair.

    Parameters
    ----------
    records : list of dict
        Records of the synthetic suite.
    resolution : (int, int)
        Width and height of the stations.

    Returns
    -------
    list of str
        Markdown lines.
    """
    w, h = resolution
    kinds = [s for s in SCENES if any(r["scene"] == s for r in records)]
    groups = [("all", records)] + [(s, [r for r in records if r["scene"] == s]) for s in kinds]
    sums = {name: summarise(rs) for name, rs in groups}
    seeds = sorted({r["seed"] for r in records})
    lines = [
        "### Synthetic station pairs",
        "",
        f"{' + '.join(f'{len(rs)} {s}' for s, rs in groups[1:])} pairs (seeds "
        f"{seeds[0]}..{seeds[-1]}) from `flexreg.synth.station_pair` at {w} x {h}: stations "
        "2–10 m apart, any yaw, tilt up to 5°, 3 mm range noise, mutual visibility overlap at "
        "least 0.5 (the smaller of the two stations' shares of rays that see the other's "
        "surfaces). One `register` call per pair (ICP refinement on) gives both the coarse "
        "transform (`T_coarse`, before ICP) and the refined one. **Success before refinement** "
        f"= `T_coarse` within {COARSE_ROT_DEG}° and {100 * COARSE_TRANS_M:.0f} cm of the truth. "
        "A pair whose `register` raises counts as a failure and as an infinite error in the "
        "medians. Time = the `register` call alone (the scans are already in memory).",
        "",
        "| | " + " | ".join(name for name, _ in groups) + " | target |",
        "|---|" + "---:|" * len(groups) + "---|",
    ]
    s_all = sums["all"]

    def row(label: str, cell: Callable[[dict[str, Any]], str], target: str) -> str:
        """A summary row: ``cell`` of each group's summary, then the target."""
        return f"| {label} | " + " | ".join(cell(sums[n]) for n, _ in groups) + f" | {target} |"

    lines += [
        row(
            "success before refinement",
            lambda s: (
                f"{s['coarse_successes']}/{s['pairs']} ({_f(s['coarse_success_rate'], '.0%')})"
            ),
            f"≥ {TARGET_SUCCESS:.0%}: {_verdict(s_all['coarse_success_rate'] >= TARGET_SUCCESS)}",
        ),
        row("registered (no error raised)", lambda s: f"{s['registered']}/{s['pairs']}", ""),
        row(
            "median rotation error before refinement (°)",
            lambda s: _f(s["median_rot_coarse_deg"], ".3f"),
            "",
        ),
        row(
            "median translation error before refinement (mm)",
            lambda s: _f(s["median_trans_coarse_m"], ".2f", 1000),
            "",
        ),
        row(
            "median rotation error after refinement (°)",
            lambda s: _f(s["median_rot_deg"], ".4f"),
            f"< {TARGET_ROT_DEG}: {_verdict(s_all['median_rot_deg'] < TARGET_ROT_DEG)}",
        ),
        row(
            "median translation error after refinement (mm)",
            lambda s: _f(s["median_trans_m"], ".2f", 1000),
            f"< {1000 * TARGET_TRANS_M:.0f}: {_verdict(s_all['median_trans_m'] < TARGET_TRANS_M)}",
        ),
        row("median time per pair (s)", lambda s: _f(s["median_total_s"], ".1f"), ""),
        row("slowest pair (s)", lambda s: _f(s["max_total_s"], ".1f"), ""),
    ]

    return lines + _stage_medians(records) + _pair_rows(records) + _stage_rows(records)


def _stage_medians(records: list[dict[str, Any]]) -> list[str]:
    """Median and slowest time of each stage over the registered pairs.

    Parameters
    ----------
    records : list of dict
        Records of the synthetic suite.

    Returns
    -------
    list of str
        Markdown lines: an introduction and the table.
    """
    stages = stage_names(records)
    ok = [r for r in records if r["ok"]]
    lines = [
        "",
        f"Median time per stage over the {len(ok)} registered pairs (`timings_s`; the plan views "
        "and the preparation of the checks run in background threads beside the feature stages, "
        "so the stages add up to more than the total):",
        "",
        "| stage | median s | max s | pairs |",
        "|---|---:|---:|---:|",
    ]
    for st in [*stages, "total"]:
        if st == "total":
            vals = [r["total_s"] for r in ok]
        else:
            vals = [r["timings_s"][st] for r in ok if st in r["timings_s"]]
        lines.append(
            f"| {st} | {_f(median(vals), '.2f')} | {_f(max(vals, default=math.nan), '.2f')} "
            f"| {len(vals)} |"
        )

    return lines


def _share(x: Any) -> str:
    return "–" if x is None else f"{x:.3f}"


def _o3d_cells(r: dict[str, Any]) -> str:
    """``| overlap | Open3D fitness | overlap RMSE mm | Open3D inlier RMSE mm |`` of a record
    (``–`` for runs made before these figures were recorded)."""
    o = r.get("overlap_result")
    if not o:
        return "| – | – | – | – "

    def mm(x: Any) -> str:
        return "–" if x is None else f"{1000 * x:.1f}"

    return (
        f"| {o['share']:.3f} | {_share(o.get('open3d_fitness'))} | {mm(o['rmse_m'])} "
        f"| {mm(o['open3d_inlier_rmse_m'])} "
    )


#: what the four columns of :func:`_o3d_cells` are
O3D_NOTE = (
    "*overlap* = share of the voxelised source points within one scale voxel of a voxelised "
    "target point after alignment (`flexreg.stages.overlap`, the figure `register` and "
    "`compare` print); *o3d fitness* / *o3d RMSE* = Open3D's `evaluate_registration` fitness "
    "and inlier RMSE on the same clouds at the same distance; *ours RMSE* = RMS distance of "
    "our overlapping points. `–`: a run recorded before these columns existed."
)
O3D_HEAD = "| overlap | o3d fitness | ours RMSE mm | o3d RMSE mm "


def _pair_rows(records: list[dict[str, Any]]) -> list[str]:
    """One row per synthetic pair, then the failures' messages.

    Parameters
    ----------
    records : list of dict
        Records of the synthetic suite.

    Returns
    -------
    list of str
        Markdown lines.
    """
    lines = [
        "",
        "Per pair (errors against the exact `T_target_source`; *prior* = which prior led to the "
        "estimate; inliers / matches of the final guided matching; *visible* = the pair's "
        "mutual visibility overlap from the scene; " + O3D_NOTE + "):",
        "",
        "| scene | seed | distance m | visible | prior | inliers / matches | coarse ° "
        "| coarse mm | success before refinement | refined ° | refined mm "
        + O3D_HEAD
        + "| time s |",
        "|---|---:|---:|---:|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in records:
        head = f"| {r['scene']} | {r['seed']} | {r['distance_m']:.2f} | {r['overlap']:.2f} "
        if not r["ok"]:
            lines.append(head + f"| **failed** | | | | no | | | | | | | {r['total_s']:.1f} |")
            continue
        lines.append(
            head + f"| {r['prior']} | {r['inliers']} / {r['matches']} "
            f"| {r['rot_coarse_deg']:.3f} | {1000 * r['trans_coarse_m']:.1f} "
            f"| {'yes' if r['coarse_success'] else '**no**'} "
            f"| {r['rot_deg']:.4f} | {1000 * r['trans_m']:.2f} "
            + _o3d_cells(r)
            + f"| {r['total_s']:.1f} |"
        )
    failed = [r for r in records if not r["ok"]]
    if failed:
        lines += ["", "Failures (the message `register` raised):", ""]
        lines += [
            f"- {r['scene']} seed {r['seed']}: `{r['error_type']}: {r['error']}`" for r in failed
        ]

    return lines


def _stage_rows(records: list[dict[str, Any]]) -> list[str]:
    """Every stage's time, one row per synthetic pair.

    Parameters
    ----------
    records : list of dict
        Records of the synthetic suite.

    Returns
    -------
    list of str
        Markdown lines.
    """
    stages = stage_names(records)
    lines = [
        "",
        "Stage timings per pair (s):",
        "",
        "| scene | seed | " + " | ".join(stages) + " | total |",
        "|---|---:|" + "---:|" * (len(stages) + 1),
    ]
    for r in records:
        cells = [_f(r["timings_s"].get(st, math.nan), ".2f") for st in stages]
        cells.append(f"{r['total_s']:.2f}")
        lines.append(f"| {r['scene']} | {r['seed']} | " + " | ".join(cells) + " |")
    return lines


def render_speed(speed: dict[str, Any]) -> list[str]:
    """The speed section: the best and all calls of each setting, the stage times of the best
    calls and the verdict on the time target.

    Parameters
    ----------
    speed : dict
        The speed run's record.

    Returns
    -------
    list of str
        Markdown lines.
    """
    w, h = speed["resolution"]
    runs = speed["runs"]

    def best(label: str) -> dict[str, Any] | None:
        """The fastest successful call of a setting, None if all failed."""
        ok = [r for r in runs.get(label, []) if r["ok"]]
        return min(ok, key=lambda r: r["total_s"]) if ok else None

    n_runs = max(len(v) for v in runs.values())
    lines = [
        f"### Speed: two {w} x {h} stations",
        "",
        f"`station_pair('room', seed=0, resolution=({w}, {h}))`: {speed['points'][0]:,} + "
        f"{speed['points'][1]:,} points, stations {speed['distance_m']:.2f} m apart, overlap "
        f"{speed['overlap']:.2f}. Only the `register` call is timed (the stations are in "
        f"memory; simulating them took {speed['synth_s']:.0f} s); best of {n_runs} "
        f"call{'s' if n_runs > 1 else ''} (all calls listed), machine as above.",
        "",
        "| register | best s | all calls s | rotation error ° | translation error mm | prior |",
        "|---|---:|---|---:|---:|---|",
    ]
    for label, rs in runs.items():
        b = best(label)
        times = ", ".join(f"{r['total_s']:.2f}" + ("" if r["ok"] else " (failed)") for r in rs)
        if b is None:
            lines.append(f"| {label} | **failed** | {times} | | | |")
        else:
            lines.append(
                f"| {label} | {b['total_s']:.2f} | {times} | {b['rot_deg']:.4f} "
                f"| {1000 * b['trans_m']:.2f} | {b['prior']} |"
            )
    chosen = {label: best(label) for label in runs}
    ok_runs = [r for r in chosen.values() if r is not None]
    stages = stage_names(ok_runs)
    lines += [
        "",
        "Stage timings of the best calls (s):",
        "",
        "| stage | " + " | ".join(runs) + " |",
        "|---|" + "---:|" * len(runs),
    ]
    for st in [*stages, "total"]:
        cells = []
        for r in chosen.values():
            if r is None:
                cells.append("")
            elif st == "total":
                cells.append(f"{r['total_s']:.2f}")
            else:
                cells.append(_f(r["timings_s"].get(st, math.nan), ".2f"))
        lines.append(f"| {st} | " + " | ".join(cells) + " |")
    b = chosen.get("with refinement")
    nb = chosen.get("without refinement")
    lines += [
        "",
        f"Target (at most {TARGET_SPEED_S:.0f} s with refinement, loading excluded): "
        + (
            f"{_verdict(b['total_s'] <= TARGET_SPEED_S)} -- {b['total_s']:.1f} s"
            if b is not None
            else "**NOT met** -- the registration failed"
        )
        + (f"; {nb['total_s']:.1f} s without refinement." if nb is not None else "."),
    ]
    for label, rs in runs.items():
        for r in rs:
            if not r["ok"]:
                lines.append(f"\n{label}: `{r['error_type']}: {r['error']}`")
                break
    return lines


def render_real(records: list[dict[str, Any]]) -> list[str]:
    """The real-pairs section: one row per pair with its verdict, the failures, the 3DTK fits
    and loop check, and the notes on the data (:func:`real_notes`).

    Parameters
    ----------
    records : list of dict
        Records of the real pairs.

    Returns
    -------
    list of str
        Markdown lines.
    """
    lines = [
        "### Real scan pairs",
        "",
        "Data in `../shared/data` (provenance and licences in each folder's README). Each pair is "
        "one `register` call with the same configuration; poses stored with the scans are never "
        "given to it. Errors are the rotation angle and translation distance between the result "
        "and the reference `T_target_source`; *coarse* = before ICP; " + O3D_NOTE,
        "",
        "| pair (target <- source) | reference | points | range image (target) | prior "
        "| inliers / matches | coarse ° | coarse m | refined ° | refined m "
        + O3D_HEAD
        + "| time s | verdict |",
        "|---|---|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for r in records:
        if "skipped" in r:
            lines.append(f"| {r['pair']} | | | | skipped: {r['skipped']} | | | | | | | | | | | |")
            continue
        img = r["range_images"][0]
        head = (
            f"| {r['pair']} | {r['reference']} | {r['points'][0]:,} / {r['points'][1]:,} "
            f"| {img['width']}x{img['height']}, {img['valid']:.0%} valid "
        )
        if not r["ok"]:
            lines.append(
                head + f"| **failed** | | | | | | | | | | {r['total_s']:.1f} | **failed** |"
            )
            continue
        lines.append(
            head + f"| {r['prior']} | {r['inliers']} / {r['matches']} "
            f"| {r['rot_coarse_deg']:.3f} | {r['trans_coarse_m']:.4f} "
            f"| {r['rot_deg']:.3f} | {r['trans_m']:.4f} "
            + _o3d_cells(r)
            + f"| {r['total_s']:.1f} | {real_verdict(r)} |"
        )
    failed = [r for r in records if "skipped" not in r and not r["ok"]]
    if failed:
        lines += ["", "Failures (the message `register` raised):", ""]
        lines += [f"- {r['pair']}: `{r['error_type']}: {r['error']}`" for r in failed]

    kurt = [r for r in records if r["pair"].startswith("3DTK") and "skipped" not in r]
    if kurt:
        lines += _kurt_fit_rows(kurt)
    lines += ["", *real_notes(records)]
    return lines


def _kurt_fit_rows(kurt: list[dict[str, Any]]) -> list[str]:
    """How well the result, the odometry and the odometry refined by ICP lay each 3DTK source
    onto its target, and the loop check.

    Parameters
    ----------
    kurt : list of dict
        The records of the 3DTK pairs that ran.

    Returns
    -------
    list of str
        Markdown lines.
    """
    lines = [
        "",
        "3DTK: how well each transform lays the source onto the target (median "
        "nearest-neighbour distance of the source points to the target, and the share within "
        f"{100 * NN_WITHIN_M:.0f} cm). *odometry + ICP* = the odometry pose refined by the "
        "same refinement `register` uses (`flexreg.registration.pipeline.refine`), the local "
        "optimum "
        "nearest to it. Source points are sampled evenly over the surfaces. Without ground "
        "truth this shows which transform the data favour, and the last column how far the "
        "result is from where the odometry leads:",
        "",
        "| pair | odometry distance m | result | odometry | odometry + ICP "
        "| result vs odometry + ICP |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for r in kurt:
        diff = "–"
        if r["ok"] and "T_prior_icp" in r:
            T, T_icp = np.asarray(r["T_target_source"]), np.asarray(r["T_prior_icp"])
            diff = f"{rotation_error_deg(T, T_icp):.2f}° / {translation_error_m(T, T_icp):.3f} m"
        lines.append(
            f"| {r['pair']} | {r['prior_distance_m']:.2f} | "
            + (_fit_cell(r.get("nn_result")) if r["ok"] else "failed")
            + f" | {_fit_cell(r['nn_prior'])} | {_fit_cell(r.get('nn_prior_icp'))} | {diff} |"
        )
    loop = next((r["loop_vs_chain"] for r in kurt if "loop_vs_chain" in r), None)
    if loop is not None:
        lines += [
            "",
            "Loop check (no reference needed): the result scan000 <- scan001 composed with "
            "scan001 <- scan002 differs from the direct scan000 <- scan002 result by "
            f"{loop['rot_deg']:.2f}° / {loop['trans_m']:.3f} m.",
        ]
    return lines


def _fit_cell(x: Any) -> str:
    """A fit cell: median distance in mm and share within ``NN_WITHIN_M`` of a fit of
    ``_nn_fit`` (``x``), ``–`` for None (a fit that was not made)."""
    return "–" if x is None else f"{1000 * x[0]:.1f} mm, {x[1]:.0%}"


def real_verdict(r: dict[str, Any]) -> str:
    """A real pair's verdict: against the targets (bunny), the reference's uncertainty
    (Velodyne) or the gross-error limits (3DTK).

    Parameters
    ----------
    r : dict
        A registered real pair's record.

    Returns
    -------
    str
        The verdict cell, empty for other pairs.
    """
    if r["pair"].startswith("bunny"):
        ok = r["rot_deg"] < BUNNY_ROT_DEG and r["trans_m"] < BUNNY_TRANS_M
        return f"< {BUNNY_ROT_DEG:.0f}° and < {1000 * BUNNY_TRANS_M:.0f} mm: {_verdict(ok)}"
    if r["pair"].startswith("Velodyne"):
        ok = r["rot_deg"] < VELODYNE_REF_ROT_DEG and r["trans_m"] < VELODYNE_REF_TRANS_M
        return ("within" if ok else "outside") + " the reference's uncertainty"
    if r["pair"].startswith("3DTK"):
        gross = r["rot_deg"] > KURT_GROSS_ROT_DEG or r["trans_m"] > KURT_GROSS_TRANS_M
        return "**wrong solution**" if gross else "near odometry"
    return ""


def real_notes(records: list[dict[str, Any]]) -> list[str]:
    """What the real data are and what their references can show: the bunny's ground truth,
    the 3DTK odometry (and the ambiguity of scan000 <- scan002), the Velodyne reference.

    Parameters
    ----------
    records : list of dict
        Records of the real pairs.

    Returns
    -------
    list of str
        Markdown list items.
    """
    by = {r["pair"]: r for r in records}
    notes = []
    b = by.get("bunny bun000 <- bun045")
    if b is not None and "skipped" not in b:
        chk = b["gt_check_vs_bun_conf"]
        notes.append(
            "- **Bunny**: Cyberware triangulation scans (400 x 512 grids, about 0.6-0.8 mm "
            "spacing) of a 15 cm object, not TLS. Ground truth = `inv(T_world_bun000) @ "
            "T_world_bun045` from the poses `read_scans` returns for "
            "`derived_bunny_grids_and_gt.npz`; recomputed here from `bun.conf` (conjugate of the "
            "written xyzw quaternion) it "
            + (
                "agrees to rounding"
                if chk["rot_deg"] < 1e-6 and chk["trans_m"] < 1e-9
                else f"differs by {chk['rot_deg']:.1e}° / {chk['trans_m']:.1e} m"
            )
            + f". Targets: {BUNNY_ROT_DEG:.0f}° and {1000 * BUNNY_TRANS_M:.0f} mm."
        )
    moves = [
        (
            rotation_error_deg(r["T_prior_icp"], r["T_reference"]),
            translation_error_m(r["T_prior_icp"], r["T_reference"]),
        )
        for r in records
        if r.get("pair", "").startswith("3DTK") and "T_prior_icp" in r and "T_reference" in r
    ]
    shift = (
        f" (ICP started from it moves it by up to {max(m[0] for m in moves):.1f}° / "
        f"{max(m[1] for m in moves):.2f} m)"
        if moves
        else ""
    )
    notes.append(
        "- **3DTK Kurt3D**: SICK line scanner turned by a robot (226 x 360 grid, 0.5° steps), "
        "stop-and-go. **No ground truth**: the reference is the odometry prior "
        "`inv(T_world_target) @ T_world_source` from the `.pose` files, itself approximate"
        + shift
        + ", so differences of centimetres and about a degree are not necessarily errors of "
        "`register`. "
        f"Points nearer than {KURT_MIN_RANGE_M} m are dropped (`min_range_m`, as the data's "
        "`config.ini` does): the robot's own body moves with the scanner and favours \"no "
        f'motion". A difference above {KURT_GROSS_ROT_DEG:.0f}° or {KURT_GROSS_TRANS_M} m is '
        "taken as a wrong solution."
    )
    r02 = by.get("3DTK scan000 <- scan002")
    if r02 is not None and "skipped" not in r02 and real_verdict(r02) != "near odometry":
        near_zero = r02["ok"] and np.linalg.norm(np.asarray(r02["T_target_source"])[:3, 3]) < 0.5
        text = (
            "  scan002 against scan000 is close to ambiguous: the two stations are "
            f"{r02['prior_distance_m']:.1f} m apart and the scene's arches repeat about every "
            "3.4 m, so a solution shifted by one arch period"
            + (" (here: close to no motion)" if near_zero else "")
            + " lays as much of the source onto the target as the right one, or more"
        )
        res, icp = r02.get("nn_result"), r02.get("nn_prior_icp")
        if res is not None and icp is not None:
            text += (
                f" ({res[1]:.0%} of the points within {100 * NN_WITHIN_M:.0f} cm, against "
                f"{icp[1]:.0%} at the odometry pose refined by ICP)"
            )
        notes.append(text + ".")
    v = by.get("Velodyne 251370668 <- 251371071")
    if v is not None and "skipped" not in v:
        spread = v["reference_spread"]
        img = v["range_images"][0]
        notes.append(
            "- **Velodyne** (fast_gicp test pair): unorganised outdoor spinning-lidar clouds, "
            "turned by `register` (`flexreg.stages.projection.range_image`) into a "
            f"{img['width']}x{img['height']} range image ({img['valid']:.0%} of the pixels hold "
            "a point). "
            "The reference `relative.txt` is a registration result, not survey ground truth: "
            f"small_gicp's matrix for the same scans differs from it by {spread['rot_deg']:.2f}° "
            f"/ {spread['trans_m']:.3f} m, so agreement within about "
            f"{VELODYNE_REF_ROT_DEG}° / {100 * VELODYNE_REF_TRANS_M:.0f} cm is all it can show."
        )
    return notes


def markdown(state: dict[str, Any], figure: str | None) -> str:
    """The Markdown of a run: command, machine and load, then each section it ran.

    Parameters
    ----------
    state : dict
        The run (``results.json``), with the synthetic ``summary``.
    figure : str, optional
        Path of the figure relative to the page; None leaves it out.

    Returns
    -------
    str
        The Markdown, ending in a newline.
    """
    m = state["machine"]
    load = state["load_average"]
    lines = [
        f"Command: `{state['command']}` ({m['cores']} cores, {m['cpu']}, Python {m['python']}, "
        f"numpy {m['numpy']}, OpenCV {m['opencv']}, Open3D {m['open3d']}; default "
        f"`RegistrationConfig` with `refine=True`, `seed={state['config']['seed']}`; one warm-up "
        "call first, not counted). 1-minute load average "
        f"{load['start'][0]:.1f} at the start of the run, {load['end'][0]:.1f} at the end"
        + (
            ": other jobs shared the machine, so the times are pessimistic"
            if max(load["start"][0], load["end"][0]) > 0.5 * m["cores"] + 0.5
            else ""
        )
        + ". Raw per-pair results: `benchmarks/results/registration-*/results.json`.",
        "",
    ]
    if state.get("synthetic"):
        lines += render_synthetic(state["synthetic"], tuple(state["resolution"]))
        if figure:
            lines += [
                "",
                f"![Per-pair rotation and translation errors, before and after refinement]"
                f"({figure})",
            ]
        lines.append("")
    if state.get("speed"):
        lines += [*render_speed(state["speed"]), ""]
    if state.get("real"):
        lines += [*render_real(state["real"]), ""]
    return "\n".join(lines).rstrip("\n") + "\n"


def plot_synthetic(records: list[dict[str, Any]], path: Path) -> None:
    """Rotation vs translation error of each pair, before (hollow) and after (filled)
    refinement, with the success box and the targets.

    Parameters
    ----------
    records : list of dict
        Records of the synthetic suite (failed pairs are not drawn, only counted).
    path : Path
        The PNG file (its folder is created).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    floor_deg, floor_mm = 1e-5, 1e-3  # exact zeros and tiny errors sit on the axes' floor
    fig, ax = plt.subplots(figsize=(6.4, 4.8), dpi=120)
    colours = {"room": "#E69F00", "courtyard": "#0072B2"}
    for scene in SCENES:
        rs = [r for r in records if r["scene"] == scene and r["ok"]]
        if not rs:
            continue
        c = colours[scene]
        rot_c = np.maximum([r["rot_coarse_deg"] for r in rs], floor_deg)
        tr_c = np.maximum([1000 * r["trans_coarse_m"] for r in rs], floor_mm)
        rot_f = np.maximum([r["rot_deg"] for r in rs], floor_deg)
        tr_f = np.maximum([1000 * r["trans_m"] for r in rs], floor_mm)
        for a, b, x, y in zip(rot_c, tr_c, rot_f, tr_f, strict=True):
            ax.plot([a, x], [b, y], color=c, lw=0.5, alpha=0.4)
        ax.scatter(rot_c, tr_c, facecolors="none", edgecolors=c, label=f"{scene}: coarse")
        ax.scatter(rot_f, tr_f, color=c, label=f"{scene}: refined")
    ax.axvline(COARSE_ROT_DEG, color="0.4", ls="--", lw=0.8)
    ax.axhline(1000 * COARSE_TRANS_M, color="0.4", ls="--", lw=0.8)
    ax.axvline(TARGET_ROT_DEG, color="0.4", ls=":", lw=0.8)
    ax.axhline(1000 * TARGET_TRANS_M, color="0.4", ls=":", lw=0.8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("rotation error (°)")
    ax.set_ylabel("translation error (mm)")
    n_fail = sum(not r["ok"] for r in records)
    ax.set_title(
        f"{len(records)} synthetic pairs: dashed = coarse success limits, dotted = targets"
        + (f"\n({n_fail} failed pairs not shown)" if n_fail else ""),
        fontsize=9,
    )
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(True, which="major", alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
