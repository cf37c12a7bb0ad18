"""What a survey writes: poses.json, stations/STEM.txt, report.html, a merged cloud, an E57.

Every file is written whole or not at all (temporary sibling renamed into place), and the set
of files is all-or-nothing (:func:`flexreg.io.files.write_all`); poses.json comes last, so its
presence means the rest was written.

The merged cloud is built one station at a time: each placed station is read, reduced to one
point per ``voxel_m`` voxel, moved into the reference frame and folded into a running
per-voxel sum (mean position and colour), then dropped; memory holds the merged voxels, never
all stations. The E57 holds every placed station with its pose (``T_reference_station`` as
the E57 pose, points in the scanner frame, as surveyors exchange registered projects); the
stations are read one at a time as the file is written.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable, Iterator, Sequence
from functools import partial
from pathlib import Path
from typing import Any, overload

import numpy as np
from numpy.typing import NDArray

from flexreg.core.scan import Scan
from flexreg.core.transforms import apply, invert, rotation_error_deg, translation_error_m
from flexreg.errors import InputError
from flexreg.io import atomic_write, read_scan, write_scan, write_transform_txt
from flexreg.io.e57 import write as write_e57
from flexreg.io.files import write_all
from flexreg.survey.project import SurveyResult
from flexreg.survey.report import write_report
from flexreg.survey.stations import unchanged

log = logging.getLogger(__name__)


def _write_json(path: Path, doc: dict[str, Any]) -> None:
    def write(tmp: Path) -> None:
        tmp.write_text(json.dumps(doc, indent=1, allow_nan=False) + "\n", encoding="utf-8")

    atomic_write(path, write)


def _finite(doc: Any) -> Any:
    """NaN and infinities as null (JSON has neither)."""
    if isinstance(doc, float):
        return doc if np.isfinite(doc) else None
    if isinstance(doc, dict):
        return {k: _finite(v) for k, v in doc.items()}
    if isinstance(doc, list):
        return [_finite(v) for v in doc]
    return doc


class _Voxels:
    """Running per-voxel sums of positions (and colours) in the reference frame."""

    def __init__(self, voxel_m: float) -> None:
        self.voxel = voxel_m
        self.keys = np.zeros((0, 3), dtype=np.int64)
        self.sums = np.zeros((0, 3), dtype=np.float64)
        self.rgb = np.zeros((0, 3), dtype=np.float64)
        self.count = np.zeros(0, dtype=np.int64)

    def add(self, points: NDArray[np.float64], colors: NDArray[np.uint8]) -> None:
        keys = np.floor(points / self.voxel).astype(np.int64)
        all_keys = np.concatenate([self.keys, keys])
        uniq, inv = np.unique(all_keys, axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        n = len(uniq)
        sums = np.zeros((n, 3))
        rgb = np.zeros((n, 3))
        count = np.zeros(n, dtype=np.int64)
        old, new = inv[: len(self.keys)], inv[len(self.keys) :]
        np.add.at(sums, old, self.sums)
        np.add.at(rgb, old, self.rgb)
        np.add.at(count, old, self.count)
        np.add.at(sums, new, points)
        np.add.at(rgb, new, colors.astype(np.float64))
        np.add.at(count, new, 1)
        self.keys, self.sums, self.rgb, self.count = uniq, sums, rgb, count

    def scan(self) -> Scan:
        c = np.maximum(self.count, 1)[:, None]
        colors = np.clip(np.rint(self.rgb / c), 0, 255).astype(np.uint8)
        return Scan(points=self.sums / c, colors=colors, name="merged")


#: one colour per station in the merged cloud (Okabe-Ito, cycled)
PALETTE = np.array(
    [
        (230, 159, 0),
        (86, 180, 233),
        (0, 158, 115),
        (240, 228, 66),
        (0, 114, 178),
        (213, 94, 0),
        (204, 121, 167),
        (120, 120, 120),
    ],
    dtype=np.uint8,
)


def _station_points(path: Path | str, voxel_m: float) -> Scan:
    import open3d as o3d

    scan = read_scan(path)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(scan.points))
    if scan.colors is not None:
        pcd.colors = o3d.utility.Vector3dVector(scan.colors.astype(np.float64) / 255.0)
    down = pcd.voxel_down_sample(voxel_m)
    colors = (
        np.clip(np.rint(np.asarray(down.colors) * 255), 0, 255).astype(np.uint8)
        if scan.colors is not None
        else None
    )
    return Scan(points=np.asarray(down.points), colors=colors, name=scan.name)


def merged_cloud(files: Sequence[tuple[Path | str, NDArray[np.float64]]], voxel_m: float) -> Scan:
    """Placed stations ``(FILE or FILE#N, T_reference_station)`` merged into one cloud, one
    point per ``voxel_m`` voxel (mean position; the stations' own colours, else one colour each)."""
    if voxel_m <= 0:
        raise InputError("--voxel", f"must be a positive number of metres (got {voxel_m})")
    acc = _Voxels(voxel_m)
    for i, (path, T) in enumerate(files):
        s = _station_points(path, voxel_m)
        colors = (
            s.colors
            if s.colors is not None
            else np.broadcast_to(PALETTE[i % len(PALETTE)], (len(s), 3))
        )
        acc.add(apply(T, s.points), np.asarray(colors))
    return acc.scan()


class _LazyScans(Sequence[Scan]):
    """The placed stations with their poses, each read from its file when asked for (the E57
    writer walks them one at a time; the last one read is kept)."""

    def __init__(self, files: Sequence[tuple[Path | str, str, NDArray[np.float64]]]) -> None:
        self.files = list(files)
        self._last: tuple[int, Scan] | None = None

    def __len__(self) -> int:
        return len(self.files)

    @overload
    def __getitem__(self, i: int) -> Scan: ...
    @overload
    def __getitem__(self, i: slice) -> Sequence[Scan]: ...
    def __getitem__(self, i: int | slice) -> Scan | Sequence[Scan]:
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        if self._last is not None and self._last[0] == i:
            return self._last[1]
        path, stem, T = self.files[i]
        s = read_scan(path)
        scan = Scan(
            points=s.points,
            intensity=s.intensity,
            colors=s.colors,
            grid_shape=s.grid_shape,
            grid_index=s.grid_index,
            T_world_scanner=T,
            name=stem,
        )
        self._last = (i, scan)
        return scan

    def __iter__(self) -> Iterator[Scan]:
        for i in range(len(self)):
            yield self[i]


def _check_unchanged(result: SurveyResult) -> None:
    """Refuse to read a placed station again from a file that no longer holds what was
    prepared (replaced or rewritten during the run): its points would be merged at a pose
    registered for other points.

    Raises
    ------
    InputError
        Naming the file.
    """
    placed = set(result.placed)
    for st in result.stations:
        p = result.prepared.get(st.stem)
        if st.stem in placed and p is not None and p.fingerprint is not None:
            if not unchanged(st.path, p.fingerprint):
                raise InputError(
                    st.path,
                    "changed since the survey prepared it: its points would be merged at a pose "
                    "registered for others; survey again to register what it holds now",
                )


def write_outputs(
    result: SurveyResult,
    out_dir: Path,
    *,
    merged: Path | None = None,
    voxel_m: float = 0.02,
    e57: Path | None = None,
    report: bool = True,
) -> list[Path]:
    """Write poses.json, stations/STEM.txt (placed stations), report.html and, when asked, the
    merged PLY and the E57; all or nothing. Returns the paths written.

    Stale ``stations/STEM.txt`` of this project's stations that are no longer placed are
    removed.
    """
    doc = _finite(result.to_dict())
    placed = result.placed
    if merged is not None or e57 is not None:  # the placed stations are read again
        _check_unchanged(result)
    # what each placed station's file needs to land in the poses' frame (the reference's, the
    # stored site frame, or the files' own coordinates: :mod:`flexreg.survey.frames`)
    poses = {s: np.asarray(doc["stations"][s]["T_site_file"], dtype=np.float64) for s in placed}
    paths: dict[str, Path | str] = {st.stem: st.ref for st in result.stations}
    names = {st.stem: st.setup_name or st.stem for st in result.stations}
    writers: list[tuple[Path, Callable[[], Any]]] = []
    for s in placed:
        txt = out_dir / "stations" / f"{s}.txt"
        writers.append((txt, partial(write_transform_txt, txt, poses[s])))
    if merged is not None:
        items = [(paths[s], poses[s]) for s in placed]
        writers.append((merged, lambda: write_scan(merged, merged_cloud(items, voxel_m))))
        # .ply, .las / .laz (integer coordinates with an offset: site coordinates keep their
        # millimetres) or .e57, by suffix
    if e57 is not None:
        lazy = _LazyScans([(paths[s], names[s], poses[s]) for s in placed])
        writers.append((e57, lambda: atomic_write(e57, lambda tmp: write_e57(tmp, lazy))))
    if report:
        html = out_dir / "report.html"
        writers.append((html, lambda: write_report(doc, html)))
    pj = out_dir / "poses.json"
    writers.append((pj, lambda: _write_json(pj, doc)))
    write_all(writers)
    for st in result.stations:
        stale = out_dir / "stations" / f"{st.stem}.txt"
        if st.stem not in placed and stale.exists():
            stale.unlink()
    return [p for p, _ in writers]


def evaluate(
    poses_doc: dict[str, Any],
    gt: dict[str, Any],
    *,
    within: tuple[float, float] = (0.05, 0.01),
    wrong: tuple[float, float] = (1.0, 0.10),
) -> dict[str, Any]:
    """Each station's error against a ``flexreg synth`` gt.json (``stations`` with
    ``T_world_scanner``), in its group's frame.

    Parameters
    ----------
    poses_doc : dict
        poses.json.
    gt : dict
        gt.json.
    within : (degrees, metres)
        A station this close to the truth counts as accurate.
    wrong : (degrees, metres)
        A station further than this (either) counts as placed wrongly.

    Returns
    -------
    dict
        ``stations`` (per STEM: ``rotation_deg``, ``translation_m``, ``group``, each in its
        group's frame), ``placed``, ``accurate``, ``wrong`` (lists of stems; a group's own
        reference station is not counted), and ``reachable``: the most stations one choice
        among the links' poses could place, the largest group joined by links one of whose
        poses (answer or alternative) is within ``wrong`` of the truth — what the graph can
        do at best with the links it was given.
    """
    world = {s["name"]: np.asarray(s["T_world_scanner"], dtype=np.float64) for s in gt["stations"]}
    out: dict[str, Any] = {"stations": {}, "placed": [], "accurate": [], "wrong": []}
    for stem, st in poses_doc["stations"].items():
        T = st.get("T_group_station")
        ref = st.get("group_reference")
        if T is None or ref is None or stem not in world or ref not in world:
            continue
        truth = invert(world[ref]) @ world[stem]
        rot = rotation_error_deg(np.asarray(T), truth)
        tr = translation_error_m(np.asarray(T), truth)
        out["stations"][stem] = {"rotation_deg": rot, "translation_m": tr, "group": st["group"]}
        if stem == ref:
            continue
        if st.get("placed"):
            out["placed"].append(stem)
        if rot <= within[0] and tr <= within[1]:
            out["accurate"].append(stem)
        if rot > wrong[0] or tr > wrong[1]:
            out["wrong"].append(stem)
    out["reachable"] = _reachable(poses_doc.get("links", []), world, wrong)
    return out


def _reachable(
    links: list[dict[str, Any]], world: dict[str, Any], wrong: tuple[float, float]
) -> int:
    """Size of the largest group of stations joined by links with a right pose."""
    up = {s: s for s in world}

    def find(x: str) -> str:
        while up[x] != x:
            up[x] = up[up[x]]
            x = up[x]
        return x

    for lk in links:
        t, s = lk.get("target"), lk.get("source")
        if lk.get("T_target_source") is None or t not in world or s not in world:
            continue
        truth = invert(world[t]) @ world[s]
        poses = [
            lk["T_target_source"],
            *(a["T_target_source"] for a in lk.get("alternatives") or []),
        ]
        if any(
            rotation_error_deg(np.asarray(T), truth) <= wrong[0]
            and translation_error_m(np.asarray(T), truth) <= wrong[1]
            for T in poses
        ):
            up[find(t)] = find(s)
    sizes: dict[str, int] = {}
    for x in world:
        sizes[find(x)] = sizes.get(find(x), 0) + 1
    return max(sizes.values(), default=0)


__all__ = ["PALETTE", "evaluate", "merged_cloud", "write_outputs"]
