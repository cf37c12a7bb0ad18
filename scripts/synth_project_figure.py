"""Figure of docs/synthetic-data.md: plan view of a synthetic multi-station project.

Run: ``.venv/bin/python scripts/synth_project_figure.py [--kind building] [--stations 24]
[--seed 0] [--out docs/figures]``. Writes ``synth_project_KIND.png``: a horizontal section of
the scene (as in ``synth_figures.py``) with every station (numbered in walk order), the links
it was set up along (thick) and every other pair that overlaps by at least the project's
minimal overlap (thin), coloured by their overlap. The data comes from ``flexreg synth`` itself
(a low-resolution run into a temporary folder: placement does not depend on the resolution).
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from synth_figures import height_map

from flexreg.synth import make_project, read_scene

CUT_M = {"building": 2.0, "warehouse": 4.0, "street": 60.0}
TOP_M = {"building": 2.0, "warehouse": 4.0, "street": 4.0}


def project_figure(kind: str, stations: int, seed: int, out: Path) -> Path:
    with tempfile.TemporaryDirectory() as tmp:
        make_project(kind, stations=stations, seed=seed, out=tmp, resolution=(64, 32))
        gt = json.loads((Path(tmp) / "gt.json").read_text())
        scene = read_scene(Path(tmp) / "scene.ply")
    xs, ys, z, shade, cut = height_map(scene, CUT_M[kind], cell=0.05, margin=1.5)
    lo, hi = np.nanmin(z), min(np.nanmax(z), TOP_M[kind])
    grey = 0.55 + 0.4 * np.clip((np.nan_to_num(z, nan=lo) - lo) / max(1e-6, hi - lo), 0, 1)
    rgb = np.repeat((grey * (0.6 + 0.4 * shade))[..., None], 3, axis=2)
    rgb[cut] = 0.12
    rgb[~np.isfinite(z) & ~cut] = 1.0
    aspect = (ys[-1] - ys[0]) / (xs[-1] - xs[0])
    fig, ax = plt.subplots(figsize=(12, 12 * aspect + 1.6), layout="constrained")
    ax.imshow(rgb, origin="lower", extent=[xs[0], xs[-1], ys[0], ys[-1]], interpolation="nearest")
    pos = {s["name"]: np.array(s["T_world_station"])[:2, 3] for s in gt["stations"]}
    parent = {s["name"]: s["parent"] for s in gt["stations"]}
    project = gt["project"]
    cmap = plt.get_cmap("plasma")
    links = sorted(project["overlaps"], key=lambda o: o["overlap"])
    for o in links:
        tree = parent[o["source"]] == o["target"] or parent[o["target"]] == o["source"]
        if o["overlap"] < project["min_overlap"] and not tree:
            continue
        a, b = pos[o["target"]], pos[o["source"]]
        ax.plot(
            [a[0], b[0]],
            [a[1], b[1]],
            "-",
            color=cmap(min(1.0, o["overlap"])),
            lw=3.2 if tree else 1.0,
            alpha=0.95 if tree else 0.7,
            zorder=2 + tree,
        )
    for i, p in enumerate(pos.values()):
        ax.plot(*p, "o", ms=13, mfc="white", mec="black", zorder=4)
        ax.text(*p, str(i), ha="center", va="center", fontsize=7, zorder=5)
    x0, y0, x1, y1 = scene.region
    ax.set_xlim(x0 - 1.5, x1 + 1.5)
    ax.set_ylim(y0 - 1.5, y1 + 1.5)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    n_tree = sum(p is not None for p in parent.values())
    shown = sum(o["overlap"] >= project["min_overlap"] for o in links)
    lay = gt["scene"]["layout"]
    what = f"{lay['rooms']} rooms" if "rooms" in lay else f"{lay.get('rack_rows', 0)} rack rows"
    if kind == "street":
        what = f"{lay['street_length_m']:.0f} m street"
    ax.set_title(
        f"{kind} project, seed {seed}: {len(pos)} stations, {what}; "
        f"thick: the {n_tree} links the walk set stations up along; thin: the other "
        f"{shown - n_tree} pairs with overlap >= {project['min_overlap']:g}",
        fontsize=10,
    )
    sm = plt.cm.ScalarMappable(cmap=cmap, norm=plt.Normalize(0, 1))
    fig.colorbar(sm, ax=ax, shrink=0.6, label="overlap (smaller share of one station's returns)")
    path = out / f"synth_project_{kind}.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kind", default="building", choices=sorted(CUT_M))
    ap.add_argument("--stations", type=int, default=24)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=Path("docs/figures"))
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    print(project_figure(args.kind, args.stations, args.seed, args.out))


if __name__ == "__main__":
    main()
