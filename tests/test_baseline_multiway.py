"""Open3D's multiway registration baseline: a small synthetic project, the pose graph on a
hand-built graph, pairs, seeds and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from flexreg.baselines.multiway import (
    EDGE_PRUNE_THRESHOLD,
    MultiwayLink,
    MultiwayResult,
    initial_poses,
    link_seed,
    multiway,
    optimise,
    pair_list,
)
from flexreg.core.transforms import (
    invert,
    make_transform,
    rotation_about_axis,
    rotation_error_deg,
    translation_error_m,
)
from flexreg.errors import ConfigError, InputError
from flexreg.synth import TLSConfig, make_scene, place_stations, scan_tls


@pytest.fixture(scope="module")
def room_project():
    """Three stations of a seeded room at 256 x 128 and their true poses (world frame)."""
    scene = make_scene("room", 1)
    cfg = TLSConfig(width=256, height=128)
    poses = place_stations(
        scene,
        3,
        min_overlap=0.6,
        distance_range_m=(2.0, 4.0),
        max_tilt_rad=0.03,
        config=cfg,
        rng=np.random.default_rng(0),
    )
    scans = [scan_tls(scene, T, config=cfg, rng=k) for k, T in enumerate(poses)]
    return scans, poses


@pytest.fixture(scope="module")
def room_result(room_project):
    scans, _ = room_project
    return multiway(scans, seed=0, max_points=5000)


def test_multiway_places_every_station_of_a_small_room(room_project, room_result):
    _, truth = room_project
    r = room_result
    assert isinstance(r, MultiwayResult)
    assert r.names == ["station_0", "station_1", "station_2"]
    assert r.groups.tolist() == [0, 0, 0] and r.placed.all()
    assert [(lk.target, lk.source, lk.kind) for lk in r.links] == [
        (1, 0, "odometry"),
        (2, 0, "loop"),
        (2, 1, "odometry"),
    ]
    # the voxel (about 0.24 m here) limits the accuracy: a few cm and a fraction of a degree
    for k, pose in enumerate(r.poses):
        assert pose is not None and pose.shape == (4, 4) and pose.dtype == np.float64
        T = invert(truth[0]) @ truth[k]
        assert rotation_error_deg(pose, T) < 0.5
        assert translation_error_m(pose, T) < 0.05
    np.testing.assert_allclose(r.poses[0], np.eye(4), atol=1e-9)
    for lk in r.links:
        assert lk.status == "accepted" and lk.information is not None
        assert lk.information.shape == (6, 6) and lk.fitness > 0.5
    d = r.to_dict()
    assert d["reference"] == "station_0" and set(d["stations"]) == set(r.names)
    assert d["stations"]["station_2"]["placed"] is True
    assert d["groups"] == [{"id": 0, "reference": "station_0", "stations": r.names, "placed": True}]
    assert {"ransac", "icp", "optimisation", "total"} <= set(r.timings_s)


def test_multiway_is_repeatable_with_a_seed(room_project, room_result):
    scans, _ = room_project
    again = multiway(scans, seed=0, max_points=5000, pairs=[(1, 0), (2, 1)])
    # the same seed per link whatever the pairs: the odometry links are bit-identical
    first = {(lk.target, lk.source): lk.T_target_source for lk in room_result.links}
    for lk in again.links:
        np.testing.assert_array_equal(lk.T_target_source, first[(lk.target, lk.source)])


def test_pair_lists():
    assert pair_list(4, "sequential") == [(1, 0), (2, 1), (3, 2)]
    assert len(pair_list(5, "all")) == 10
    assert pair_list(3, [(0, 2)]) == [(0, 2)]
    with pytest.raises(ConfigError):
        pair_list(3, [(0, 3)])
    with pytest.raises(ConfigError):
        pair_list(3, [(0, 1), (1, 0)])
    with pytest.raises(ConfigError):
        pair_list(3, "some")
    assert link_seed(0, 2, 1) == link_seed(0, 2, 1) != link_seed(0, 1, 2)


def test_one_station_is_refused(room_project):
    with pytest.raises(InputError, match="at least 2 stations"):
        multiway(room_project[0][:1])


def test_an_unreadable_station_names_its_file(tmp_path, room_project):
    bad = tmp_path / "broken.ptx"
    bad.write_text("not a ptx file\n")
    with pytest.raises(InputError, match=r"broken\.ptx"):
        multiway([room_project[0][0], bad])


def _information(seed: int = 0) -> np.ndarray:
    """A point-to-point information matrix of 400 points spread over a 10 m box."""
    p = np.random.default_rng(seed).uniform(-5, 5, (400, 3))
    info = np.zeros((6, 6))
    for x, y, z in p:
        G = np.array([[0, z, -y, 1, 0, 0], [-z, 0, x, 0, 1, 0], [y, -x, 0, 0, 0, 1]], float)
        info += G.T @ G
    return info


def _link(truth, t, s, kind, *, error=None):
    T = invert(truth[t]) @ truth[s]
    if error is not None:
        T = T @ error
    return MultiwayLink(
        target=t,
        source=s,
        kind=kind,
        status="accepted",
        T_target_source=T,
        T_coarse=T,
        information=_information(t * 10 + s),
        ransac_inliers=100,
        fitness=0.8,
        inlier_rmse_m=0.01,
        seed=0,
        seconds=0.0,
        distance_m=0.05,
    )


def test_pose_graph_prunes_a_planted_wrong_loop_closure():
    # five stations on a line, 4 m apart, turned about z
    truth = [
        make_transform(rotation_about_axis([0, 0, 1], 0.3 * k), [4.0 * k, 0.5 * k, 0.0])
        for k in range(5)
    ]
    wrong = make_transform(rotation_about_axis([0, 0, 1], 0.5), [2.0, -1.0, 0.0])
    links = [_link(truth, k + 1, k, "odometry") for k in range(4)]
    links += [_link(truth, 2, 0, "loop"), _link(truth, 4, 2, "loop")]
    links.append(_link(truth, 4, 0, "loop", error=wrong))
    failed = MultiwayLink(3, 1, "loop", "failed", None, None, None, 0, 0.0, np.nan, 0, 0.0)
    links.append(failed)
    poses, out, groups = optimise(links, 5, fine_distance_m=0.05)
    assert [lk.status for lk in out] == ["accepted"] * 6 + ["rejected", "failed"]
    assert groups.tolist() == [0] * 5
    for k in range(5):
        T = invert(truth[0]) @ truth[k]
        assert rotation_error_deg(poses[k], T) < 1e-4  # arccos near 1: ~1e-6 deg of noise
        assert translation_error_m(poses[k], T) < 1e-6
    assert EDGE_PRUNE_THRESHOLD == 0.25


def test_a_station_no_link_reaches_is_left_unplaced():
    truth = [make_transform(np.eye(3), [3.0 * k, 0, 0]) for k in range(4)]
    links = [_link(truth, 1, 0, "odometry"), _link(truth, 3, 1, "loop")]
    start = initial_poses(links, 4)
    assert start[2] is None and start[3] is not None
    poses, _, groups = optimise(links, 4, fine_distance_m=0.05)
    assert poses[2] is None and groups.tolist() == [0, 0, -1, 0]
    np.testing.assert_allclose(poses[3], truth[3], atol=1e-9)
