"""Correspondence files: write_pairs writes what read_pairs (and calibration's
read_correspondences) reads back exactly; the camera-pose stage on its own."""

from __future__ import annotations

import numpy as np
import pytest

from flexreg import InputError, Scan
from flexreg.calibration import read_correspondences
from flexreg.core.correspondences import Correspondences2D3D
from flexreg.io.correspondences import read_pairs, write_pairs
from flexreg.io.intrinsics import CameraIntrinsics
from flexreg.stages.camera_pose import PnPResult, project_points, solve_pnp


def test_xyz_pairs_round_trip_exactly(tmp_path):
    rng = np.random.default_rng(0)
    uv = rng.uniform(0, 1000, (25, 2))
    xyz = rng.normal(0, 10, (25, 3))
    uv[0] = [12.0, 7.0]  # whole numbers are written without a fraction
    p = write_pairs(tmp_path / "sub" / "pairs.csv", uv, xyz=xyz, comments=["two", "lines\nhere"])
    text = p.read_text().splitlines()
    assert text[:4] == ["# two", "# lines", "# here", "u,v,X,Y,Z"]
    assert text[4].startswith("12,7,")
    t = read_pairs(p)
    assert t.rowcol is None and t.xyz is not None and len(t) == 25 and t.path == p
    np.testing.assert_array_equal(t.pixels, uv)
    np.testing.assert_array_equal(t.xyz, xyz)
    assert t.lines.tolist() == list(range(5, 30))
    c = read_correspondences(p)
    np.testing.assert_array_equal(c.pixels, uv)
    np.testing.assert_array_equal(c.points, xyz)


def test_rowcol_pairs_round_trip_and_lift(tmp_path):
    v, u = np.mgrid[0:20, 0:30].astype(float)
    scan = Scan.from_organized(np.stack([u * 0.1, v * 0.1, np.full_like(u, 5.0)], axis=-1))
    uv = np.array([[100.25, 200.0], [101.0, 201.5]])
    rowcol = np.array([[2, 7], [5.5, 10.25]])
    p = write_pairs(tmp_path / "pairs.csv", uv, rowcol=rowcol)
    assert p.read_text() == "u,v,row,col\n100.25,200,2,7\n101,201.5,5.5,10.25\n"
    t = read_pairs(p)
    assert t.xyz is None
    np.testing.assert_array_equal(t.rowcol, rowcol)
    c = read_correspondences(p, scan=scan)
    np.testing.assert_allclose(c.points, [[0.7, 0.2, 5.0], [1.025, 0.55, 5.0]])


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({}, "not both or neither"),
        ({"xyz": np.zeros((2, 3)), "rowcol": np.zeros((2, 2))}, "not both or neither"),
        ({"xyz": np.zeros((3, 3))}, "2 pixels but 3 lidar coordinates"),
        ({"rowcol": [[1.0, np.nan], [2.0, 3.0]]}, "NaN or Inf"),
    ],
)
def test_write_pairs_refuses_what_it_cannot_read_back(tmp_path, kwargs, message):
    with pytest.raises(InputError, match=message):
        write_pairs(tmp_path / "p.csv", np.zeros((2, 2)), **kwargs)
    assert not (tmp_path / "p.csv").exists()


def test_camera_pose_stage_returns_the_pose_and_inliers():
    rng = np.random.default_rng(4)
    intr = CameraIntrinsics(np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]), [], 640, 480)
    pts = np.column_stack([rng.uniform(-3, 3, 30), rng.uniform(-2, 2, 30), rng.uniform(3, 9, 30)])
    uv, _ = project_points(pts, intr, np.eye(4))
    uv[:5] += 40.0  # outliers
    r = solve_pnp(Correspondences2D3D(uv, pts), intr, threshold_px=2.0)
    assert isinstance(r, PnPResult) and r.inliers == 25 and not r.inlier_mask[:5].any()
    np.testing.assert_allclose(r.T_camera_lidar, np.eye(4), atol=1e-6)
    with pytest.raises(InputError, match="PnP needs at least 6"):
        solve_pnp(Correspondences2D3D(uv[:5], pts[:5]), intr)
