"""`flexreg synth --fragments`: 3DMatch-style fused fragments with exact truth and overlaps."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import one_error_line, run_cli

from flexreg.core.transforms import apply, invert
from flexreg.io import read_scan
from flexreg.io.transform_io import read_pair_transform
from flexreg.synth import make_scene, read_scene
from flexreg.synth.config import FragmentConfig, RGBDConfig
from flexreg.synth.fragments import (
    FRAGMENT_WALK_M,
    OVERLAP_VOXELS,
    fragment_overlap,
    voxel_downsample,
    write_fragments,
)

#: a 160 x 120 depth camera (the default's field of view) for quick fragments
SMALL_CAMERA = RGBDConfig(
    width=160, height=120, fx=131.25, fy=131.25, cx=79.5, cy=59.5, max_depth_m=4.0
)


def test_voxel_means_and_overlap_shares_by_hand():
    pts = np.array([[0.01, 0.0, 0.0], [0.03, 0.0, 0.0], [0.25, 0.0, 0.0], [-0.01, 0.0, 0.0]])
    means, counts = voxel_downsample(pts, 0.1)
    np.testing.assert_allclose(means, [[-0.01, 0, 0], [0.02, 0, 0], [0.25, 0, 0]], atol=1e-15)
    assert counts.tolist() == [1.0, 2.0, 1.0]
    # weights carry the counts of points that are already voxel means
    m, w = voxel_downsample(means[1:], 1.0, counts[1:])
    np.testing.assert_allclose(m, [pts[:3].mean(axis=0)], atol=1e-15)
    assert w.tolist() == [3.0]
    a = np.array([[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0], [3.0, 0, 0]])
    T = np.eye(4)
    T[0, 3] = 2.0  # the source's first two points land on the target's last two
    assert fragment_overlap(a, a[:3], T, radius_m=0.1) == (2 / 3, 0.5)


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    out = tmp_path_factory.mktemp("fragments") / "fragments"
    cfg = FragmentConfig(frames=4, overlap=(0.35, 0.65))
    res = write_fragments(out, make_scene("room", 2), 3, config=cfg, camera=SMALL_CAMERA, rng=7)
    return out, cfg, res


def test_fragments_overlap_within_the_asked_range(made):
    out, cfg, (files, entries, pairs) = made
    assert [p.name for p in files] == [f"fragment_00{k}.ply" for k in range(3)]
    clouds = [read_scan(out / f"{e['name']}.ply", precise=True).points for e in entries]
    for k, pair in enumerate(pairs):
        assert (pair["target"], pair["source"]) == (entries[k]["name"], entries[k + 1]["name"])
        Ta, Tb = (np.array(entries[i]["T_world_fragment"]) for i in (k, k + 1))
        np.testing.assert_allclose(pair["T_target_source"], invert(Ta) @ Tb, atol=1e-12)
        # recomputed from the files: the shares gt.json states, the smaller one in range
        shares = fragment_overlap(
            clouds[k],
            clouds[k + 1],
            pair["T_target_source"],
            radius_m=OVERLAP_VOXELS * cfg.voxel_m,
        )
        assert shares == (pair["seen_by_target"], pair["seen_by_source"])
        assert 0.35 <= pair["overlap"] == min(shares) <= 0.65
        assert entries[k + 1]["frames"][0] > entries[k]["frames"][1]  # no frame in both


def test_fragments_are_fused_voxel_means_on_the_scene_surfaces(made):
    out, cfg, (_, entries, _) = made
    scene = make_scene("room", 2)
    for e in entries:
        pts = read_scan(out / f"{e['name']}.ply", precise=True).points
        assert len(pts) == e["points"] > 1000
        keys = np.floor(pts / cfg.voxel_m).astype(np.int64)
        assert len(np.unique(keys, axis=0)) == len(pts)  # one point per voxel
        d = scene.distance(apply(np.array(e["T_world_fragment"]), pts))
        assert np.median(d) < 0.01  # Kinect-like noise (2.5 cm at 4 m), averaged per voxel
        # the cameras that made it, in its frame: the first at its origin, then walking on
        cams = np.array(e["camera_positions_m"])
        assert len(cams) == cfg.frames and e["frames"][1] - e["frames"][0] == cfg.frames - 1
        np.testing.assert_allclose(cams[0], 0.0, atol=1e-12)
        steps = np.linalg.norm(np.diff(cams, axis=0), axis=1)
        np.testing.assert_allclose(steps, FRAGMENT_WALK_M / cfg.frames, rtol=0.05)


@pytest.fixture(scope="module")
def cli_set(tmp_path_factory):
    root = tmp_path_factory.mktemp("cli")
    args = ["synth", "--scene", "room", "--stations", "0", "--fragments", "2"]
    args += ["--set", "fragment.frames=3", "--seed", "1"]
    for name in ("a", "b"):
        rc, printed, err = run_cli([*args, "--out", root / name])
        assert rc == 0, err
    assert "fragments: 2 fragments of 3 depth frames" in printed
    return root


def test_cli_writes_ply_fragments_and_their_truth(cli_set):
    out = cli_set / "a"
    gt = json.loads((out / "gt.json").read_text())
    frag = gt["fragments"]
    assert frag["frames_per_fragment"] == 3 and frag["voxel_m"] == 0.01
    assert [f["file"] for f in frag["fragments"]] == [
        "fragments/fragment_000.ply",
        "fragments/fragment_001.ply",
    ]
    (pair,) = gt["pairs"]
    assert pair["kind"] == "fragment" and 0.3 <= pair["overlap"] <= 0.7
    T = read_pair_transform(out / "gt.json", "fragment_000", "fragment_001")
    Ta, Tb = (np.array(f["T_world_fragment"]) for f in frag["fragments"])
    np.testing.assert_allclose(T, invert(Ta) @ Tb)
    scene = read_scene(out / "scene.ply")
    src = read_scan(out / "fragments" / "fragment_001.ply", precise=True).points
    assert np.median(scene.distance(apply(Ta @ T, src))) < 0.01  # noise 2.5 cm at 4 m


def test_the_same_seed_gives_identical_files(cli_set):
    files = sorted(p.relative_to(cli_set / "a") for p in (cli_set / "a").rglob("*.*"))
    assert files and all(
        (cli_set / "a" / f).read_bytes() == (cli_set / "b" / f).read_bytes() for f in files
    )


def test_register_reads_a_pair_of_fragments(cli_set, tmp_path):
    out = cli_set / "a"
    a, b = out / "fragments" / "fragment_000.ply", out / "fragments" / "fragment_001.ply"
    rc, _, err = run_cli(
        ["register", a, b, "--out", tmp_path / "T.json", "--truth", out / "gt.json"]
    )
    assert rc in (0, 3) or "cannot read" not in err, err


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--fragments", "2", "--set", "fragment.overlap=[0.7,0.3]"], "overlap range"),
        (["--fragments", "2", "--set", "fragment.overlap=[0.4,0.42]"], "overlap range"),
        (["--fragments", "2", "--set", "fragment.frames=0"], "fragment.frames"),
        (["--fragments", "2", "--set", "fragment.voxel_m=0"], "fragment.voxel_m"),
        (["--fragments", "-1"], "--fragments"),
        (["--scene", "object", "--fragments", "2"], "object views come alone"),
    ],
)
def test_bad_options_one_line_error_nothing_written(tmp_path, extra, message):
    out = tmp_path / "never"
    rc, _, err = run_cli(["synth", "--stations", "0", "--out", out, *extra])
    assert rc == 1
    line = one_error_line(err)
    assert message in line, line
    assert not out.exists()
