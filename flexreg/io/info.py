"""Summaries and file outputs: scan facts as dicts and tables, range images as files."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from flexreg.core.camera import PinholeCamera, SphericalCamera, azimuth_polar_extent
from flexreg.core.range_image import RangeImage
from flexreg.core.scan import Scan
from flexreg.core.transforms import is_rigid, rotation_error_deg
from flexreg.errors import InputError
from flexreg.io import atomic_write, detect_format
from flexreg.io.origin import centring_problem, origin_hint
from flexreg.io.threedtk import pose_file

PNG_SCALES_M = (1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 5e-3, 1e-2, 2e-2, 5e-2, 0.1)


def field_of_view_deg(scan: Scan) -> dict[str, Any]:
    """Field of view in degrees: from the camera when known, else from the points' directions.

    Returns ``{"model": ..., "horizontal_deg": ..., "vertical_deg": ...}`` plus the azimuth and
    polar bounds for spherical views.
    """
    cam = scan.camera
    if isinstance(cam, PinholeCamera):
        return {
            "model": "pinhole",
            "horizontal_deg": math.degrees(2 * math.atan2(cam.width / 2, cam.fx)),
            "vertical_deg": math.degrees(2 * math.atan2(cam.height / 2, cam.fy)),
        }
    if isinstance(cam, SphericalCamera):
        pmin, pmax, tmin, tmax = cam.phi_min, cam.phi_max, cam.theta_min, cam.theta_max
        model = "spherical (camera)"
    else:
        pmin, pmax, tmin, tmax, _ = azimuth_polar_extent(scan.points)
        model = "spherical (from points)"
    return {
        "model": model,
        "horizontal_deg": math.degrees(pmax - pmin),
        "vertical_deg": math.degrees(tmax - tmin),
        "azimuth_deg": [math.degrees(pmin), math.degrees(pmax)],
        "polar_deg": [math.degrees(tmin), math.degrees(tmax)],
    }


def pose_stored(scan: Scan, fmt: str | None = None) -> bool:
    """Whether the scan's file stores a pose for it.

    A 3DTK scan stores one when its ``.pose`` file exists, identity or not
    (:func:`flexreg.io.threedtk.pose_file`); other formats write the identity when they store
    none (E57 without ``pose``, a PTX header of an unregistered setup), so there an identity
    pose counts as none.
    """
    if fmt is None and scan.path is not None:
        fmt = detect_format(scan.path)[1]
    if fmt == "3dtk" and scan.path is not None:
        return pose_file(scan.path) is not None
    return not np.allclose(scan.T_world_scanner, np.eye(4), rtol=0.0, atol=1e-12)


def scan_summary(scan: Scan) -> dict[str, Any]:
    """JSON-ready facts about a scan (what ``flexreg info`` shows).

    A cloud not centred on its scanner (project or map coordinates,
    :func:`flexreg.io.origin.centring_problem`) has no field of view or ranges worth showing:
    they are None, and ``not_centred`` says why, with the option to give (``hint``).
    """
    fmt = None if scan.path is None else detect_format(scan.path)[1]
    why = centring_problem(scan)
    d: dict[str, Any] = {
        "path": None if scan.path is None else str(scan.path),
        "name": scan.name,
        "format": fmt,
        "points": len(scan),
        "grid": None,
        "field_of_view": field_of_view_deg(scan) if len(scan) and why is None else None,
        "range_m": None,
        "bounds_m": None,
        "not_centred": why,
        "hint": None if why is None else origin_hint(why, "--origin"),
        "intensity": None,
        "colors": scan.colors is not None,
        "camera": None if scan.camera is None else scan.camera.to_dict(),
    }
    if scan.grid_shape is not None:
        rows, cols = scan.grid_shape
        d["grid"] = {
            "rows": rows,
            "cols": cols,
            "valid_cells": len(scan),
            "valid_fraction": len(scan) / (rows * cols),
        }
    if len(scan):
        lo, hi = scan.points.min(axis=0), scan.points.max(axis=0)
        d["bounds_m"] = {"min": lo.tolist(), "max": hi.tolist()}
    if len(scan) and why is None:
        q = np.percentile(np.linalg.norm(scan.points, axis=1), [0, 1, 50, 99, 100])
        d["range_m"] = {"min": q[0], "p1": q[1], "median": q[2], "p99": q[3], "max": q[4]}
    if scan.intensity is not None and len(scan):
        d["intensity"] = {"min": float(scan.intensity.min()), "max": float(scan.intensity.max())}
    T = scan.T_world_scanner
    d["pose"] = {
        "T_world_scanner": T.tolist(),
        "position_m": T[:3, 3].tolist(),
        "rotation_deg": rotation_error_deg(T, np.eye(4)) if is_rigid(T) else None,
        "rigid": is_rigid(T),
        "stored": pose_stored(scan, fmt),
    }
    return json.loads(json.dumps(d, default=float))


def _grid_text(g: dict[str, Any] | None) -> str:
    return "none" if g is None else f"{g['rows']} x {g['cols']}"


def _pose_text(p: dict[str, Any]) -> str:
    """``no`` (none stored), ``yes`` or ``yes (identity)``: an explicit identity pose."""
    if not p["stored"]:
        return "no"
    identity = np.allclose(p["T_world_scanner"], np.eye(4), rtol=0.0, atol=1e-12)
    return "yes (identity)" if identity else "yes"


def render_setup_list(summaries: list[dict[str, Any]]) -> Any:
    """A rich table of several :func:`scan_summary` outputs, one line per setup: how to name
    it, its name, points, grid and whether its file stores a pose."""
    from rich import box
    from rich.table import Table

    t = Table(box=box.SIMPLE_HEAD, title_justify="left", pad_edge=False)
    for name, justify in (
        ("setup", "left"),
        ("name", "left"),
        ("points", "right"),
        ("grid", "right"),
        ("pose", "left"),
    ):
        t.add_column(name, justify=justify)  # type: ignore[arg-type]
    for d in summaries:
        name = d["name"] if d["not_centred"] is None else f"{d['name']} (not centred)"
        t.add_row(
            d["setup"], name, f"{d['points']:,}", _grid_text(d["grid"]), _pose_text(d["pose"])
        )
    return t


def render_scan_summary(d: dict[str, Any]) -> Any:
    """A rich table of :func:`scan_summary` output (and, for a cloud not centred on its
    scanner, the line that says which option gives the scanner position)."""
    from rich.table import Table  # heavy: rich loads only for the console table

    t = Table(title=f"{d['name']}  ({d['format']})", show_header=False, title_justify="left")
    t.add_column(style="bold")
    t.add_column()
    t.add_row("file", str(d["path"]))
    t.add_row("points", f"{d['points']:,}")
    g = d["grid"]
    t.add_row(
        "grid",
        "none (unstructured)"
        if g is None
        else f"{g['rows']} rows x {g['cols']} cols, {g['valid_cells']:,} valid "
        f"({100 * g['valid_fraction']:.1f} %)",
    )
    if d["not_centred"] is not None:
        lo, hi = d["bounds_m"]["min"], d["bounds_m"]["max"]
        t.add_row(
            "extent",
            ", ".join(f"{a} {lo[k]:.3f}..{hi[k]:.3f}" for k, a in enumerate("xyz")) + " m",
        )
        t.add_row("scanner", "not at the file's origin: no field of view or ranges (see below)")
    fov = d["field_of_view"]
    if fov:
        extra = ""
        if "azimuth_deg" in fov:
            extra = (
                f"  (azimuth {fov['azimuth_deg'][0]:.2f}..{fov['azimuth_deg'][1]:.2f}°, "
                f"polar {fov['polar_deg'][0]:.2f}..{fov['polar_deg'][1]:.2f}°)"
            )
        t.add_row(
            "field of view",
            f"{fov['horizontal_deg']:.2f}° x {fov['vertical_deg']:.2f}° [{fov['model']}]{extra}",
        )
    r = d["range_m"]
    if r:
        t.add_row(
            "range",
            f"min {r['min']:.3f} m, median {r['median']:.3f} m, "
            f"p99 {r['p99']:.3f} m, max {r['max']:.3f} m",
        )
    if d["intensity"]:
        t.add_row("intensity", f"{d['intensity']['min']:.4g} .. {d['intensity']['max']:.4g}")
    t.add_row("colour", "yes" if d["colors"] else "no")
    p = d["pose"]
    rot = "non-rigid (affine)" if not p["rigid"] else f"rotated {p['rotation_deg']:.3f}°"
    where = f"position ({', '.join(f'{v:.3f}' for v in p['position_m'])}) m, {rot}"
    if not p["stored"]:
        t.add_row("pose", "none stored (taken as the identity)")
    elif d["format"] == "3dtk":
        t.add_row("pose", f"{where} (from {Path(d['path']).with_suffix('.pose').name})")
    else:
        t.add_row("pose", where)
    if d["camera"]:
        t.add_row("camera", json.dumps(d["camera"]))
    if d["hint"] is None:
        return t
    from rich.console import Group
    from rich.text import Text

    hint = f"{d['path']}: {d['hint']}; register takes it as --target-origin / --source-origin"
    return Group(t, Text(hint, no_wrap=False))


def choose_png_scale(max_range_m: float) -> float:
    """Finest metres-per-unit from :data:`PNG_SCALES_M` that fits ``max_range_m`` in 16 bits."""
    for s in PNG_SCALES_M:
        if max_range_m <= 65535 * s:
            return s
    raise InputError("range image", f"ranges up to {max_range_m:.1f} m do not fit a 16-bit PNG")


def write_range_image(
    out: Path, image: RangeImage, *, png_scale_m: float | None = None
) -> dict[str, Any]:
    """Write a range image as 16-bit PNG (0 = no return), float32 npz and camera sidecar.

    Parameters
    ----------
    out : Path
        ``.png`` path; ``<stem>.npz`` (range, xyz, valid, intensity, camera) and, when the
        camera is known, ``<stem>.camera.json`` (so ``read_scan(out)`` reads it back) go
        beside it.
    image : RangeImage
    png_scale_m : float, optional
        Metres per PNG unit; chosen by :func:`choose_png_scale` when not given.

    Returns
    -------
    dict
        ``{"png_scale_m": float, "files": [paths written]}``.
    """
    import cv2  # heavy: OpenCV loads only when a PNG is written

    rng = image.range
    if image.n_valid == 0:
        raise InputError(out, "range image has no valid pixel; nothing to write")
    rmax = float(np.nanmax(rng))
    if png_scale_m is None:
        png_scale_m = choose_png_scale(rmax)
    elif not png_scale_m > 0:
        raise InputError("--png-scale", f"must be positive, got {png_scale_m}")
    elif rmax > 65535 * png_scale_m:
        raise InputError(
            out, f"max range {rmax:.2f} m does not fit 16 bits at {png_scale_m} m per unit"
        )
    png = np.zeros(rng.shape, dtype=np.uint16)
    v = image.valid
    png[v] = np.clip(np.rint(rng[v] / png_scale_m), 1, 65535).astype(np.uint16)
    out = Path(out)
    npz = out.with_suffix(".npz")
    files = [out, npz]
    arrays: dict[str, Any] = {
        "range": rng,
        "xyz": image.xyz.astype(np.float32),
        "valid": image.valid,
        "png_scale_m": np.float64(png_scale_m),
        "camera": np.array(json.dumps(None if image.camera is None else image.camera.to_dict())),
    }
    if image.intensity is not None:
        arrays["intensity"] = image.intensity

    def write_png(tmp: Path) -> None:
        if not cv2.imwrite(str(tmp), png):
            raise InputError(out, "could not write PNG")

    atomic_write(npz, lambda tmp: np.savez_compressed(tmp, **arrays))
    atomic_write(out, write_png)
    if image.camera is not None:
        side = out.with_name(out.stem + ".camera.json")
        doc = {
            "camera": image.camera.to_dict(),
            "depth_scale": png_scale_m,
            "depth_kind": "range",
            "invalid_values": [0],
        }
        atomic_write(side, lambda tmp: tmp.write_text(json.dumps(doc, indent=2) + "\n"))
        files.append(side)
    return {"png_scale_m": png_scale_m, "files": [str(f) for f in files]}
