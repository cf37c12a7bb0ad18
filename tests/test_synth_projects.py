"""Synthetic multi-station projects: building, warehouse, street; disconnected groups.

Placement is seeded, but which exact spots it picks may differ across CPUs (docs/determinism.md),
so these tests assert what holds for any placement: stations on free floor, clear of surfaces,
linked by overlapping views, groups that never see each other, and exact ground truth.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from flexreg.cli import run
from flexreg.core.transforms import invert
from flexreg.errors import ConfigError
from flexreg.synth import (
    PROJECT_SCENE_KINDS,
    make_project,
    make_project_scene,
    overlap_components,
    read_scene,
    scan_tls,
    station_overlap,
    visible_fraction,
    zone_free_map,
)
from flexreg.synth.config import PROJECT_MIN_OVERLAP, TLSConfig

RES = (64, 32)


def _files(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


@pytest.fixture(scope="module", params=PROJECT_SCENE_KINDS)
def project(request, tmp_path_factory):
    out = tmp_path_factory.mktemp(request.param)
    res = make_project(
        request.param, stations=6, out=out, resolution=RES, seed=1, max_tilt_rad=math.radians(4)
    )
    return request.param, out, res, json.loads((out / "gt.json").read_text())


def test_project_ground_truth_fields(project):
    kind, out, _res, gt = project
    assert gt["config"]["scene"] == kind and gt["config"]["stations"] == 6
    assert gt["config"]["min_overlap"] == PROJECT_MIN_OVERLAP  # the project default
    names = [s["name"] for s in gt["stations"]]
    assert names == [f"station_{i:02d}" for i in range(6)]
    for s in gt["stations"]:
        assert s["file"] == f"{s['name']}.ptx" and (out / s["file"]).is_file()  # name = stem
        assert s["T_world_station"] == s["T_world_scanner"] and s["group"] == 0
    assert gt["stations"][0]["parent"] is None
    assert all(s["parent"] in names[:i] for i, s in enumerate(gt["stations"]) if i)
    p = gt["project"]
    assert p["groups"] == [names] and p["components"] == [names]
    assert len(p["spacing_m"]) == 1 and 2.0 <= p["spacing_m"][0] <= 8.0
    assert gt["scene"]["zones_m"] and gt["scene"]["layout"]
    poses = {s["name"]: np.array(s["T_world_scanner"]) for s in gt["stations"]}
    for o in p["overlaps"]:
        assert names.index(o["target"]) < names.index(o["source"])
        assert o["overlap"] == min(o["seen_by_target"], o["seen_by_source"]) > 0
        d = np.linalg.norm(poses[o["source"]][:3, 3] - poses[o["target"]][:3, 3])
        assert o["distance_m"] == pytest.approx(d, abs=1e-6)
    for pair in gt["pairs"]:
        T = invert(poses[pair["target"]]) @ poses[pair["source"]]
        np.testing.assert_allclose(pair["T_target_source"], T, atol=1e-12)
        assert pair["overlap"] >= PROJECT_MIN_OVERLAP


def test_project_stations_stand_free_and_tilted_within_limit(project):
    kind, _out, res, gt = project
    scene = res.scene
    fm = zone_free_map(scene, 0)
    P = np.array([s.T_world_scanner[:3, 3] for s in res.stations])
    free, ground = fm.lookup(P[:, :2])
    assert free.all(), f"{kind}: a station off the free floor"
    assert np.all((P[:, 2] - ground >= 1.3 - 1e-9) & (P[:, 2] - ground <= 1.8 + 1e-9))
    assert scene.distance(P).min() >= 0.3 - 1e-6
    tilts = [math.degrees(math.acos(np.clip(s.T_world_scanner[2, 2], -1, 1))) for s in res.stations]
    assert max(tilts) <= 4.0 + 1e-9 and max(tilts) > 0.2
    # stations spread over the site: not all within one spacing
    d = np.linalg.norm(P[:, None] - P[None], axis=2)
    assert d.max() > 2 * gt["project"]["spacing_m"][0]


def test_project_overlap_graph_is_connected_through_the_walk(project):
    kind, out, _res, gt = project
    scene = read_scene(out / "scene.ply")
    poses = {s["name"]: np.array(s["T_world_scanner"]) for s in gt["stations"]}
    cfg = TLSConfig(width=RES[0], height=RES[1])
    for s in gt["stations"][1:]:  # every station overlaps the one it was set up from
        ov = station_overlap(scene, poses[s["parent"]], poses[s["name"]], config=cfg)
        assert ov >= PROJECT_MIN_OVERLAP - 0.02, (kind, s["name"], ov)
    assert len(gt["project"]["components"]) == 1


def test_disconnected_groups_share_no_view(tmp_path, capsys):
    out = tmp_path / "two"
    argv = ["synth", "--scene", "warehouse", "--stations", "5", "--groups", "2"]
    assert run([*argv, "--resolution", "64x32", "--seed", "3", "--out", str(out)]) == 0
    assert "project: 2 group(s) of 3, 2 stations" in " ".join(capsys.readouterr().out.split())
    gt = json.loads((out / "gt.json").read_text())
    groups = gt["project"]["groups"]
    assert [len(g) for g in groups] == [3, 2]
    assert [s["group"] for s in gt["stations"]] == [0, 0, 0, 1, 1]
    assert sorted(map(sorted, gt["project"]["components"])) == sorted(map(sorted, groups))
    for o in gt["project"]["overlaps"]:  # no pair across the groups shares anything
        assert (o["target"] in groups[0]) == (o["source"] in groups[0])
    assert gt["stations"][3]["parent"] is None  # each group's walk starts afresh
    scene = read_scene(out / "scene.ply")
    a, b = (np.array(gt["stations"][i]["T_world_scanner"]) for i in (0, 3))
    assert visible_fraction(scene, a, b) == 0.0 and visible_fraction(scene, b, a) == 0.0
    assert np.linalg.norm(a[:3, 3] - b[:3, 3]) > 160.0


def test_project_files_are_identical_for_the_same_seed(tmp_path):
    args = ["synth", "--scene", "street", "--stations", "4", "--resolution", "64x32"]
    assert run([*args, "--seed", "5", "--out", str(tmp_path / "a")]) == 0
    assert run([*args, "--seed", "5", "--out", str(tmp_path / "b")]) == 0
    a, b = _files(tmp_path / "a"), _files(tmp_path / "b")
    assert sorted(a) == sorted(b) and "station_03.ptx" in a
    for name in a:
        assert a[name] == b[name], name


def test_project_scenes_grow_with_the_stations():
    for kind in PROJECT_SCENE_KINDS:
        small, large = (make_project_scene(kind, 2, stations=n) for n in (10, 40))

        def area(s):
            return sum((z[2] - z[0]) * (z[3] - z[1]) for z in s.zones)

        assert area(large) > 2.5 * area(small), kind
    b = make_project_scene("building", 2, stations=64)
    assert b.layout["strips"] == 2 and b.layout["rooms"] >= 16 and b.layout["doors"] > 20


def test_overlap_components_of_a_hand_made_matrix():
    S = np.array(
        [
            [1.0, 0.5, 0.1, 0.0],
            [0.3, 1.0, 0.0, 0.0],
            [0.9, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )
    # mutual overlap = min of both shares: 0-1 is 0.3, 0-2 only 0.1
    assert overlap_components(S, 0.2).tolist() == [0, 0, 1, 2]
    assert overlap_components(S, 0.05).tolist() == [0, 0, 0, 1]
    assert overlap_components(S, 0.0).tolist() == [0, 0, 0, 1]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--scene", "building", "--stations", "1"], "--stations: a building project needs"),
        (["--scene", "campsite", "--stations", "4"], "--scene: scene must be one of"),
        (["--scene", "street", "--stations", "3", "--groups", "2"], "at least 2 stations per"),
        (["--scene", "room", "--stations", "2", "--groups", "2"], "groups apply to project"),
        (["--scene", "warehouse", "--stations", "8", "--groups", "5"], "--groups"),
    ],
)
def test_bad_project_options_fail_in_one_line(tmp_path, capsys, extra, message):
    out = tmp_path / "bad"
    assert run(["synth", *extra, "--resolution", "64x32", "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
    assert not out.exists()


def test_make_project_refuses_other_kinds(tmp_path):
    with pytest.raises(ConfigError, match="unknown project kind"):
        make_project("room", stations=4, out=tmp_path / "x")
    with pytest.raises(ConfigError, match="at least 2 stations per group"):
        make_project_scene("building", 0, stations=3, groups=2)
    assert not (tmp_path / "x").exists()


def _ranges(scene, T, cfg):
    return np.linalg.norm(scan_tls(scene, T, config=cfg, rng=0).organized()[0], axis=2)


def test_warehouse_bays_repeat_so_a_shifted_station_sees_the_same():
    scene = make_project_scene("warehouse", 0, stations=40)
    p = scene.layout["period_m"]
    fm = zone_free_map(scene, 0)
    x0, y0, x1, y1 = scene.region
    cfg = TLSConfig(
        width=128,
        height=64,
        range_noise_m=0.0,
        range_noise_per_m=0.0,
        dropout_rate=0.0,
        mixed_pixel_prob=0.0,
        intensity_speckle=0.0,
    )
    mid = (x0 + x1) / 2
    xs = np.arange(mid, mid + p, 0.2)
    spots = [(x, y) for y in np.linspace(y0 + 2, y1 - 2, 9) for x in xs]
    ok = [fm.lookup(np.array([[x, y], [x + p, y]]))[0].all() for x, y in spots]
    x, y = spots[int(np.argmax(ok))]
    assert any(ok)
    T = np.eye(4)
    T[:3, 3] = [x, y, 1.5]
    T2 = T.copy()
    T2[0, 3] += p
    a, b = (_ranges(scene, M, cfg) for M in (T, T2))
    both = (a > 0) & (b > 0)
    assert np.mean(np.abs(a[both] - b[both]) < 0.02) > 0.9
    half = T.copy()
    half[0, 3] += p / 2  # half a period on: a different view
    c = _ranges(scene, half, cfg)
    both = (a > 0) & (c > 0)
    assert np.mean(np.abs(a[both] - c[both]) < 0.02) < 0.8
