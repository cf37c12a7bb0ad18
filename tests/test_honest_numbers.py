"""One overlap figure everywhere: ``register`` and ``compare`` state the same overlap (and
Open3D's fitness / inlier RMSE) for the same transform; the match figure says what it shows."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import REPO, run_cli
from scipy.spatial import cKDTree

from flexreg import Scan, read_scan, write_scan
from flexreg.core.camera import SphericalCamera
from flexreg.core.range_image import to_scan
from flexreg.core.transforms import apply, make_transform, rotation_about_axis
from flexreg.registration.config import DEFAULT_CHECKS
from flexreg.stages.overlap import measure_overlap
from flexreg.stages.projection import project
from flexreg.stages.sampling import to_open3d, voxel_centroids, voxel_count
from flexreg.viz.matches import INLIER_COLOUR, OUTLIER_COLOUR, match_figure

LASERSCAN = REPO / "data" / "laserscan" / "laserscan-depth.png"

#: every check of the judge, the optional Open3D figures included
ALL_CHECKS = "judge.checks=" + json.dumps([*DEFAULT_CHECKS, "open3d"])


def _texts(fig) -> str:
    """Every text object of a figure (title, labels, legend), joined."""
    from matplotlib.text import Text

    return " | ".join(t.get_text() for t in fig.findobj(Text))


def test_match_figure_names_the_files_counts_and_both_kinds():
    from matplotlib.collections import LineCollection
    from matplotlib.colors import to_rgba

    rng = np.random.default_rng(0)
    a = rng.integers(0, 255, (40, 120), dtype=np.uint8)
    b = rng.integers(0, 255, (30, 100), dtype=np.uint8)
    kt, ks = rng.random((10, 2)) * [100, 30], rng.random((10, 2)) * [100, 30]
    inl = np.array([True] * 7 + [False] * 3)
    fig = match_figure(
        a, b, kt, ks, inl, target_name="st_00.ptx", source_name="st_01.ptx", threshold_m=0.05
    )
    text = _texts(fig)
    assert "target = st_00.ptx" in text and "source = st_01.ptx" in text
    assert "10 matched keypoint pairs: 7 inliers (70.0 %) within 50.0 mm, 3 outliers" in text
    assert "inliers (7)" in text and "outliers (3)" in text  # the legend
    lines = fig.axes[0].findobj(LineCollection)
    colours = {tuple(np.round(c.get_colors()[0], 3)): len(c.get_segments()) for c in lines}
    assert colours == {
        tuple(np.round(to_rgba(INLIER_COLOUR, 0.8), 3)): 7,
        tuple(np.round(to_rgba(OUTLIER_COLOUR, 0.8), 3)): 3,
    }
    # at most max_lines of each kind are drawn, and the legend says so
    fig = match_figure(a, b, kt, ks, inl, target_name="t", source_name="s", max_lines=2)
    assert "inliers (7, 2 drawn)" in _texts(fig)
    with pytest.raises(Exception, match="flags"):
        match_figure(a, b, kt, ks, inl[:5], target_name="t", source_name="s")


def test_overlap_is_open3d_fitness_on_the_same_clouds(rng):
    """Two noisy samples of one plane, half of the source moved off it: the overlap is the
    share on the plane, and Open3D's evaluate_registration says the same."""
    plane = np.column_stack([rng.random((20000, 2)) * 10, np.zeros(20000)])
    target = plane + rng.normal(0, 0.002, plane.shape)
    source = np.column_stack([rng.random((20000, 2)) * 10, np.zeros(20000)])
    source[source[:, 0] > 5, 2] += 3.0  # this half is 3 m above the target
    ov = measure_overlap(target, source, np.eye(4), voxel_m=0.1)
    assert ov.share == pytest.approx(0.5, abs=0.02)
    assert ov.open3d_fitness == pytest.approx(ov.share, abs=1e-3)
    assert ov.open3d_inlier_rmse_m == pytest.approx(ov.rmse_m, rel=1e-3)
    assert "source points within 10 cm of a target point after alignment" in ov.headline()
    # without Open3D's check: the same figures of ours, Open3D's left out (None, JSON null)
    bare = measure_overlap(target, source, np.eye(4), voxel_m=0.1, open3d_check=False)
    assert (bare.share, bare.rmse_m) == (ov.share, ov.rmse_m)
    assert bare.open3d_fitness is None and bare.to_dict()["open3d_inlier_rmse_m"] is None


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    """The real laser scan and a second station 0.5 m away, turned 40 degrees."""
    folder = tmp_path_factory.mktemp("honest")
    target = read_scan(LASERSCAN)
    T_source_target = make_transform(
        rotation_about_axis([0, 0, 1.0], np.radians(40)), [0.4, 0.3, 0]
    )
    cam = SphericalCamera.from_reference(1799, 397, 0.80, 2.34)
    source = to_scan(project(Scan(points=apply(T_source_target, target.points)), cam))
    write_scan(folder / "target.npz", target)
    write_scan(folder / "source.npz", source)
    return folder / "target.npz", folder / "source.npz"


def test_register_and_compare_report_the_same_overlap(pair, tmp_path):
    target, source = pair
    rc, out, err = run_cli(
        ["register", target, source, "--out", tmp_path / "T.json"]
        + [
            "--set",
            ALL_CHECKS,
        ]
    )
    assert rc in (0, 3), err
    reg = json.loads((tmp_path / "T.json").read_text())
    rc, out, err = run_cli(
        ["compare", target, source, "--methods", "flexreg", "--out", tmp_path / "cmp"]
    )
    assert rc == 0, err
    cmp = json.loads((tmp_path / "cmp" / "comparison.json").read_text())
    (row,) = cmp["methods"]
    # the same seed and configuration give the same transform in both commands ...
    np.testing.assert_allclose(row["T_target_source"], reg["T_target_source"], atol=1e-9)
    # ... and then the same overlap, RMSE and Open3D figures, with the same denominator
    assert row["overlap"] == pytest.approx(reg["overlap"]["share"], abs=1e-12)
    assert row["overlap_rmse_m"] == pytest.approx(reg["overlap"]["rmse_m"], rel=1e-9)
    assert row["open3d_fitness"] == pytest.approx(reg["open3d_fitness"], abs=1e-12)
    assert row["open3d_inlier_rmse_m"] == pytest.approx(reg["open3d_inlier_rmse_m"], rel=1e-9)
    assert f"{reg['overlap']['source_points']:,} source points" in cmp["fit_denominator"]
    assert reg["overlap"]["share"] > 0.5
    flat = " ".join(out.split())
    assert f"target = {target}, source = {source}" in flat
    assert "overlap" in flat and "o3d fitness" in flat


def test_voxel_centroids_are_open3ds_voxel_down_sample(rng):
    """The overlap's voxelisation without Open3D: the same voxels and centroids as Open3D's
    voxel_down_sample (in another order), far from the origin too; a hand-made case exactly."""
    cloud = rng.normal(size=(50_000, 3)) * [4.0, 2.0, 0.5] + [3.5e5, 5.6e6, 120.0]
    for voxel in (0.05, 0.3):
        ours = voxel_centroids(cloud, voxel)
        theirs = np.asarray(to_open3d(cloud).voxel_down_sample(voxel).points)
        assert len(ours) == len(theirs) == voxel_count(cloud, voxel)
        d, _ = cKDTree(theirs).query(ours)
        assert d.max() < 1e-6
    pts = np.array([[0.0, 0, 0], [0.2, 0, 0], [0.4, 0, 0], [1.0, 1, 0]])
    np.testing.assert_allclose(voxel_centroids(pts, 0.5), [[0.1, 0, 0], [0.4, 0, 0], [1, 1, 0]])
    assert voxel_centroids(np.zeros((0, 3)), 1.0).shape == (0, 3)
