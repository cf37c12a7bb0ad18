"""Baselines: each recovers a known motion within stated tolerances, from the identity or a
given start; results carry honest counts; bad input is refused; imports stay light."""

from __future__ import annotations

import importlib.util
import subprocess
import sys

import numpy as np
import pytest
from conftest import REPO

from flexreg import ConfigError, InputError, RegistrationError, read_scans
from flexreg.baselines import (
    BASELINES,
    BaselineConfig,
    available_baselines,
    default_voxel,
    get_baseline,
)
from flexreg.baselines.open3d_icp import icp
from flexreg.core.transforms import (
    apply,
    invert,
    make_transform,
    rotation_about_axis,
    rotation_error_deg,
    translation_error_m,
)


def corner_cloud(rng: np.random.Generator, n: int = 6000) -> np.ndarray:
    """Random points on a floor, two walls and a box standing in the corner (all six degrees
    of freedom constrained), about 3 m across."""
    u = rng.uniform(0.0, 3.0, size=(n, 2))
    floor = np.column_stack([u[:, 0], u[:, 1], np.zeros(n)])
    wall_x = np.column_stack([np.zeros(n), u[:, 0], u[:, 1]])
    wall_y = np.column_stack([u[:, 0], np.zeros(n), u[:, 1]])
    b = rng.uniform(0.0, 0.6, size=(n, 2))
    box_top = np.column_stack([0.8 + b[:, 0], 1.1 + b[:, 1], np.full(n, 0.6)])
    box_side = np.column_stack([np.full(n, 1.4), 1.1 + b[:, 0], b[:, 1]])
    return np.concatenate([floor, wall_x, wall_y, box_top, box_side])


@pytest.fixture(scope="module")
def corner():
    """Target cloud, a source seeing the same surfaces (other samples) and the true
    T_target_source: 3° about a tilted axis and 6 cm."""
    rng = np.random.default_rng(7)
    target = corner_cloud(rng)
    T = make_transform(rotation_about_axis([0.2, -0.1, 1.0], np.radians(3.0)), [0.04, -0.03, 0.02])
    source = apply(invert(T), corner_cloud(rng))
    return target, source, T


@pytest.fixture(scope="module")
def bunny(shared_data):
    a, b = read_scans(shared_data / "bunny_range_scans_gt" / "derived_bunny_grids_and_gt.npz")
    return a, b, invert(a.T_world_scanner) @ b.T_world_scanner


def test_registry_names_and_errors():
    assert set(BASELINES) == {
        "icp-point",
        "icp-plane",
        "gicp",
        "fpfh-ransac",
        "kiss-icp",
        "small-gicp",
    }
    assert {"icp-point", "icp-plane", "gicp", "fpfh-ransac", "kiss-icp"} <= set(
        available_baselines()
    )
    assert ("small-gicp" in available_baselines()) == (
        importlib.util.find_spec("small_gicp") is not None
    )
    with pytest.raises(ConfigError, match="unknown baseline 'icp-foo'"):
        get_baseline("icp-foo")


def test_heavy_libraries_load_only_when_a_baseline_runs():
    code = (
        "import sys, flexreg.baselines, flexreg.bench.compare, flexreg.bench.suite, "
        "flexreg.cli.compare; print(sorted(m for m in ('open3d', 'kiss_icp', 'small_gicp') "
        "if m in sys.modules))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True
    )
    assert out.stdout.strip() == "[]"


def test_default_voxel_is_twice_the_spacing_of_a_regular_grid():
    # a 2 cm grid: the median nearest-neighbour spacing is exactly 0.02 m
    g = np.stack(np.meshgrid(np.arange(60), np.arange(60), indexing="ij"), -1).reshape(-1, 2)
    pts = np.column_stack([0.02 * g, np.zeros(len(g))])
    v, how = default_voxel(pts)
    assert v == pytest.approx(0.04, abs=1e-12)
    assert "median spacing" in how


def test_default_voxel_keeps_the_point_budget(corner):
    import open3d as o3d

    target, _, _ = corner
    v, how = default_voxel(target, max_points=2000)
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(target))
    assert len(pc.voxel_down_sample(v).points) <= 2000
    assert "at most 2,000" in how


@pytest.mark.parametrize("name", ["icp-point", "icp-plane", "gicp"])
def test_icp_from_identity_recovers_a_small_motion(corner, name):
    target, source, T = corner
    r = get_baseline(name)(target, source, voxel_m=0.1)
    assert rotation_error_deg(r.T_target_source, T) < 0.1
    assert translation_error_m(r.T_target_source, T) < 0.003
    np.testing.assert_array_equal(r.T_coarse, np.eye(4))
    assert r.prior == "identity"
    assert 0 < r.inliers <= r.matches
    assert r.correspondences.shape == (r.inliers, 2, 3)
    assert r.fitness == pytest.approx(r.inliers / r.matches)
    assert f"{r.matches} source points" in r.fitness_denominator
    cfg = r.config.to_dict()
    assert cfg["method"] == name and cfg["voxel_m"] == 0.1 and cfg["start"] == "identity"
    assert isinstance(r.config, BaselineConfig)
    # deterministic: the same call gives the same matrix, bit for bit
    np.testing.assert_array_equal(
        get_baseline(name)(target, source, voxel_m=0.1).T_target_source, r.T_target_source
    )


def test_icp_from_a_given_start(corner):
    target, _, _ = corner
    rng = np.random.default_rng(3)
    T = make_transform(rotation_about_axis([0, 0, 1], np.radians(70.0)), [2.0, -1.0, 0.1])
    source = apply(invert(T), corner_cloud(rng))
    start = make_transform(rotation_about_axis([0, 0, 1], np.radians(68.0)), [1.95, -1.02, 0.1])
    r = icp(target, source, variant="point-to-plane", T_init=start, voxel_m=0.1)
    assert rotation_error_deg(r.T_target_source, T) < 0.1
    assert translation_error_m(r.T_target_source, T) < 0.003
    np.testing.assert_array_equal(r.T_coarse, start)
    assert r.prior == "initial guess"


def test_icp_without_overlap_fails_clearly(corner):
    target, source, _ = corner
    with pytest.raises(RegistrationError, match="no correspondence within"):
        get_baseline("icp-point")(target, source + [100.0, 0.0, 0.0], voxel_m=0.1)


def test_fpfh_ransac_registers_the_bunny_without_a_start(bunny):
    a, b, T = bunny
    r = get_baseline("fpfh-ransac")(a, b, seed=1)
    # Stanford ground truth; limits of the registration benchmark for this 15 cm object
    assert rotation_error_deg(r.T_target_source, T) < 1.0
    assert translation_error_m(r.T_target_source, T) < 0.005
    assert rotation_error_deg(r.T_coarse, T) < 5.0  # the RANSAC estimate before ICP
    assert r.prior == "fpfh-ransac" and 3 <= r.inliers <= r.matches
    p = r.config.to_dict()["parameters"]
    v = r.config.voxel_m
    assert p["normal_radius_m"] == pytest.approx(2 * v) and p["fpfh_radius_m"] == pytest.approx(
        5 * v
    )
    assert p["ransac_distance_m"] == pytest.approx(1.5 * v)
    assert p["ransac_threads"] == 1
    # one RANSAC thread (the default): the seed alone decides the result
    again = get_baseline("fpfh-ransac")(a, b, seed=1)
    np.testing.assert_array_equal(again.T_coarse, r.T_coarse)
    np.testing.assert_array_equal(again.T_target_source, r.T_target_source)


def test_kiss_icp_starts_from_identity_and_recovers_a_lidar_motion(shared_data):
    scans = read_scans(
        shared_data / "lidar_ouster_os1_128_3scans" / "derived_destaggered_3scans.npz"
    )
    target = scans[0].points
    T = make_transform(rotation_about_axis([0, 0, 1], np.radians(2.0)), [0.3, 0.05, 0.0])
    source = apply(invert(T), target)
    r = get_baseline("kiss-icp")(target, source)
    # KISS-ICP's own voxel rule gives 2.5 m voxels for this 247 m scan: centimetre accuracy
    assert rotation_error_deg(r.T_target_source, T) < 0.05
    assert translation_error_m(r.T_target_source, T) < 0.03
    np.testing.assert_array_equal(r.T_coarse, np.eye(4))
    kc = r.config.to_dict()["parameters"]["kiss_config"]
    assert kc["data"]["deskew"] is False
    assert kc["data"]["max_range"] >= np.linalg.norm(target, axis=1).max()
    assert kc["mapping"]["voxel_size"] == pytest.approx(kc["data"]["max_range"] / 100)
    # a given start: the source is pre-moved by it and the result composed with it
    start = make_transform(np.eye(3), [0.25, 0.0, 0.0])
    r2 = get_baseline("kiss-icp")(target, source, T_init=start)
    np.testing.assert_array_equal(r2.T_coarse, start)
    assert translation_error_m(r2.T_target_source, T) < 0.03


def test_small_gicp_when_installed(corner):
    pytest.importorskip("small_gicp")
    target, source, T = corner
    r = get_baseline("small-gicp")(target, source, voxel_m=0.1)
    assert rotation_error_deg(r.T_target_source, T) < 0.1
    assert translation_error_m(r.T_target_source, T) < 0.003


def test_bad_input_is_refused(corner):
    target, source, _ = corner
    with pytest.raises(InputError, match="shape"):
        get_baseline("icp-plane")(target[:, :2], source)
    bad = source.copy()
    bad[0, 0] = np.nan
    with pytest.raises(InputError, match="NaN"):
        get_baseline("gicp")(target, bad)
    with pytest.raises(ConfigError, match="voxel"):
        get_baseline("icp-point")(target, source, voxel_m=-1.0)
    with pytest.raises(ConfigError, match="unknown ICP variant"):
        icp(target, source, variant="plane-to-point")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="T_init"):
        get_baseline("icp-plane")(target, source, T_init=np.diag([1.0, 1.0, 2.0, 1.0]))
