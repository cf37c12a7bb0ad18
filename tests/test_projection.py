"""Range images: native grid, z-buffer projection, depth images."""

from __future__ import annotations

import numpy as np
import pytest

from flexreg import Scan
from flexreg.core.camera import PinholeCamera, SphericalCamera
from flexreg.core.range_image import RangeImage, from_depth, from_grid, to_scan
from flexreg.errors import InputError
from flexreg.stages.projection import auto_spherical_camera, project, range_image, with_camera


def _plane_points(distance: float, n: int, rng) -> np.ndarray:
    """Points of the plane x = distance, inside +-45 deg of the +X axis."""
    y = rng.uniform(-distance * 0.9, distance * 0.9, n)
    z = rng.uniform(-distance * 0.9, distance * 0.9, n)
    return np.column_stack([np.full(n, distance), y, z])


def test_plane_at_known_distance_spherical(rng):
    d = 4.25
    scan = Scan(points=_plane_points(d, 200_000, rng))
    img = range_image(scan)  # unstructured -> automatic equirectangular camera
    assert isinstance(img.camera, SphericalCamera)
    r = img.range
    # the range image holds the original points: r = d / cos(angle to the plane normal)
    xyz = img.xyz[img.valid]
    np.testing.assert_allclose(xyz[:, 0], d, atol=1e-12)
    np.testing.assert_allclose(r[img.valid], np.linalg.norm(xyz, axis=1), rtol=1e-6)
    # the pixels facing the plane see it at distance d (within the pixel footprint)
    u, v, _ = img.camera.project(np.array([[1.0, 0.0, 0.0]]))
    iu, iv = round(u[0]), round(v[0])
    window = r[iv - 2 : iv + 3, iu - 2 : iu + 3]
    assert np.isfinite(window).sum() >= 5
    step = max(img.camera.dphi, img.camera.dtheta)
    np.testing.assert_allclose(window[np.isfinite(window)], d, atol=d * (1 / np.cos(4 * step) - 1))
    # everywhere: range = d / cos(angle between the ray and the plane normal)
    ray = xyz / np.linalg.norm(xyz, axis=1, keepdims=True)
    np.testing.assert_allclose(r[img.valid], d / ray[:, 0], rtol=1e-6)


def test_plane_at_known_distance_pinhole():
    cam = PinholeCamera(300.0, 300.0, 159.5, 119.5, 320, 240)
    z = np.full(cam.shape, 2.0)
    img = from_depth(z, cam, depth_kind="z")
    np.testing.assert_allclose(img.xyz[..., 2], 2.0)
    np.testing.assert_allclose(img.depth_z(), 2.0)
    # Euclidean range grows off-axis exactly as r = z sqrt(1 + x^2 + y^2)
    v, u = np.mgrid[0:240, 0:320]
    np.testing.assert_allclose(img.range, cam.z_to_range(u, v, z), rtol=1e-6)


def test_zbuffer_keeps_nearest_return():
    cam = SphericalCamera(36, 18, -np.pi, np.pi, 0.0, np.pi)
    ray = cam.backproject(10.0, 9.0, 1.0)
    pts = np.stack([ray * 5.0, ray * 2.0, ray * 3.0])
    img = project(Scan(points=pts), cam)
    assert img.valid.sum() == 1
    assert img.range[9, 10] == pytest.approx(2.0)
    assert img.index[9, 10] == 1


def test_native_grid_without_resampling():
    xyz = np.full((3, 4, 3), np.nan)
    xyz[0, 1] = [1.0, 2.0, 3.0]
    xyz[2, 3] = [4.0, 5.0, 6.0]
    scan = Scan.from_organized(xyz, intensity=np.arange(12.0).reshape(3, 4))
    assert scan.grid_shape == (3, 4) and len(scan) == 2
    img = from_grid(scan)
    assert img.valid.tolist() == [[False, True, False, False], [False] * 4, [False] * 3 + [True]]
    np.testing.assert_array_equal(img.xyz[0, 1], [1.0, 2.0, 3.0])
    assert img.intensity[2, 3] == 11.0
    assert img.index[2, 3] == 1
    assert range_image(scan).n_valid == 2  # the one call picks the native grid


def test_depth_image_round_trip_through_scan(rng):
    cam = SphericalCamera.from_reference(200, 80, 0.6, 2.5)
    depth = rng.uniform(1, 30, cam.shape)
    depth[rng.random(cam.shape) < 0.2] = 0.0
    img = from_depth(depth, cam)
    scan = to_scan(img)
    back = project(scan, cam)
    np.testing.assert_array_equal(back.valid, depth > 0)
    np.testing.assert_allclose(back.range[back.valid], depth[depth > 0], rtol=1e-6)


def test_auto_camera_matches_native_resolution():
    cam = SphericalCamera.from_reference(720, 240, 0.5, 2.6)
    img = from_depth(np.full(cam.shape, 10.0), cam)
    auto = auto_spherical_camera(to_scan(img).points)
    assert auto.wraps
    assert abs(auto.width - 720) <= 7 and abs(auto.height - 240) <= 3  # within 1 %
    filled = project(to_scan(img), auto).n_valid / (auto.width * auto.height)
    assert filled > 0.9


def test_auto_camera_partial_window_across_cut(rng):
    # a 60 deg wide window centred on azimuth 180 deg (crossing the -pi/pi cut)
    phi = np.radians(rng.uniform(150, 210, 20000))
    theta = np.radians(rng.uniform(60, 120, 20000))
    pts = 5 * np.column_stack(
        [np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]
    )
    cam = auto_spherical_camera(pts)
    assert not cam.wraps
    assert np.degrees(cam.phi_max - cam.phi_min) == pytest.approx(60, abs=2)
    img = project(Scan(points=pts), cam)
    assert img.n_valid > 0.6 * 20000


def test_depth_size_mismatch_raises():
    cam = PinholeCamera(300.0, 300.0, 10.0, 10.0, 20, 20)
    with pytest.raises(InputError, match="does not match"):
        from_depth(np.ones((10, 20)), cam)


def test_gather_and_empty_scan():
    scan = Scan(points=np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]))
    img = range_image(scan, angular_resolution_rad=np.radians(5))
    vals = img.gather(np.array([7.0, 9.0]))
    assert sorted(vals[img.valid].tolist()) == [7.0, 9.0]
    with pytest.raises(InputError, match="no points"):
        range_image(Scan(points=np.zeros((0, 3))))


def _ring_lidar(rings: int, columns: int, fov_deg: tuple[float, float], keep) -> np.ndarray:
    """Directions of a spinning lidar at 10 m: ``rings`` evenly spaced beams over ``fov_deg``
    (polar angles, degrees), ``columns`` firings per turn, only where ``keep(phi, theta)``."""
    theta = np.radians(np.linspace(*fov_deg, rings))
    phi = -np.pi + (np.arange(columns) + 0.5) * 2 * np.pi / columns
    P, T = np.meshgrid(phi, theta)
    P, T = P[keep(P, T)], T[keep(P, T)]
    return 10.0 * np.column_stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)])


@pytest.mark.parametrize("lost", ["none", "sky", "random half"])
def test_lidar_camera_keeps_firing_pitch_when_returns_are_lost(lost):
    """One column per firing and one row per ring, however many returns the scene gives
    back: the sky above the horizon on half the turn, or half of all returns at random."""
    rng = np.random.default_rng(3)
    drop = rng.random((32, 900)) < 0.5
    keep = {
        "none": lambda p, t: np.ones_like(p, dtype=bool),
        "sky": lambda p, t: (t > np.pi / 2) | (p < 0),  # the sky returns nothing
        "random half": lambda p, t: ~drop,
    }[lost]
    cam = auto_spherical_camera(_ring_lidar(32, 900, (70.0, 110.0), keep))
    assert cam.wraps
    assert (cam.width, cam.height) == (900, 32)
    # exact geometry: 0.4 deg firings, 40/31 deg rings (to float64 rounding of the directions)
    assert np.degrees(cam.dphi) == pytest.approx(0.4, rel=1e-9)
    assert np.degrees(cam.dtheta) == pytest.approx(40 / 31, rel=1e-9)


def test_regular_native_grid_keeps_its_pixels_with_a_fitted_camera(rng):
    """A grid written by an equirectangular scanner is its own camera image: with_camera fits
    the camera and keeps every pixel (no re-projection); an irregular grid is re-projected."""
    cam = SphericalCamera.from_reference(360, 120, 0.5, 2.6)
    depth = rng.uniform(2, 20, cam.shape)
    depth[rng.random(cam.shape) < 0.1] = 0.0

    def native(rows):  # the grid a scanner file stores (rows in this order): no camera model
        img = from_depth(depth, cam)
        return from_grid(to_scan(RangeImage(img.xyz[rows], img.valid[rows], img.index)))

    grid = native(np.arange(120))
    assert grid.camera is None
    fitted = with_camera(grid)
    assert isinstance(fitted.camera, SphericalCamera) and fitted.camera.wraps
    assert fitted.xyz is grid.xyz and fitted.index is grid.index  # the same pixels
    u, v, _ = fitted.camera.project(grid.xyz[grid.valid])
    rows, cols = np.nonzero(grid.valid)
    np.testing.assert_array_equal(np.rint(v), rows)
    np.testing.assert_array_equal(np.mod(np.rint(u), 360), cols)
    # the rows shuffled: no camera fits, the points are re-projected through a fitted one
    shuffled = native(rng.permutation(120))
    again = with_camera(shuffled)
    assert again.camera is not None and again.xyz is not shuffled.xyz
    assert again.n_valid > 0.9 * shuffled.n_valid


# ----------------------------------------------------------------------------- float32 scans


def test_scan_keeps_float32_points_and_makes_others_float64():
    p = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.5]])
    assert Scan(points=p.astype(np.float32)).points.dtype == np.float32
    assert Scan(points=p).points.dtype == np.float64
    assert Scan(points=p.astype(np.int32)).points.dtype == np.float64
    with pytest.raises(InputError, match="NaN or Inf"):
        Scan(points=np.float32([[1, 2, np.inf]]))


def test_float32_grid_image_holds_the_points_without_conversion():
    """A float32 gridded scan gives a float32 image whose pixels hold its points exactly,
    NaN at the no-return cell, with the intensities at the same pixels."""
    pts = np.float32([[1.5, 0.25, -2.0], [3.0, -1.0, 0.125], [7.0, 8.0, 9.0]])
    scan = Scan(
        points=pts,
        intensity=np.float32([0.1, 0.2, 0.3]),
        grid_shape=(2, 2),
        grid_index=np.array([[0, 1], [1, 0], [1, 1]], dtype=np.int32),
    )
    img = from_grid(scan)
    assert img.xyz.dtype == np.float32
    np.testing.assert_array_equal(img.xyz[0, 1], pts[0])
    np.testing.assert_array_equal(img.xyz[1, 0], pts[1])
    np.testing.assert_array_equal(img.xyz[1, 1], pts[2])
    assert np.isnan(img.xyz[0, 0]).all() and not img.valid[0, 0]
    np.testing.assert_array_equal(img.index, [[-1, 0], [1, 2]])
    assert img.intensity is not None and np.isnan(img.intensity[0, 0])
    np.testing.assert_array_equal(img.intensity[[0, 1, 1], [1, 0, 1]], np.float32([0.1, 0.2, 0.3]))
    half = from_grid(scan, stride=2)  # every 2nd row and column: only cell (0, 0), empty
    assert half.xyz.dtype == np.float32 and half.shape == (1, 1) and not half.valid.any()


def test_samples_and_voxels_of_float32_points_equal_those_of_their_float64_copy(rng):
    """The samplers read float32 clouds as they are (no float64 copy of the cloud) and give
    exactly what the same values in float64 give: only the samples become float64."""
    from flexreg.stages.sampling import area_sample_cell, voxel_centroids, voxel_count

    p32 = rng.uniform(-20, 20, (50_000, 3)).astype(np.float32)
    p64 = p32.astype(np.float64)
    cell32, s32 = area_sample_cell(p32, 2000)
    cell64, s64 = area_sample_cell(p64, 2000)
    assert cell32 == cell64 and s32.dtype == np.float64
    np.testing.assert_array_equal(s32, s64)
    np.testing.assert_array_equal(voxel_centroids(p32, 1.5), voxel_centroids(p64, 1.5))
    assert voxel_count(p32, 0.7) == voxel_count(p64, 0.7)


@pytest.mark.parametrize("stride", [2, 3, 4])
def test_projecting_into_every_kth_pixel_is_downsampling_the_full_projection(
    rng, monkeypatch, stride
):
    """``project(..., stride=k)`` is exactly ``downsample_image(project(...), k)`` (the
    nearest point wins, the first of equal ranges, the camera scaled), in chunks of any size;
    the angles of an unstructured cloud, computed in chunks, give the same camera; and the
    working image of such a cloud is the full projection's every k-th pixel."""
    import flexreg.core.camera as camera_module
    import flexreg.stages.projection as projection
    from flexreg.core.range_image import downsample_image, working_stride
    from flexreg.stages.projection import working_image

    d = rng.normal(size=(20_000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    P = d * rng.uniform(1, 20, (len(d), 1))
    P = np.concatenate([P, P[:500] * 1.5, P[500:800]]).astype(np.float32)  # farther, equal
    scan = Scan(points=P)
    cam = auto_spherical_camera(P)
    full = project(scan, cam)
    monkeypatch.setattr(projection, "_PROJECT_CHUNK", 1000)
    monkeypatch.setattr(camera_module, "ANGLE_CHUNK", 777)
    monkeypatch.setattr(projection, "ANGLE_CHUNK", 777)
    assert auto_spherical_camera(P) == cam
    got, expected = project(scan, cam, stride=stride), downsample_image(full, stride)
    np.testing.assert_array_equal(got.index, expected.index)
    np.testing.assert_array_equal(got.valid, expected.valid)
    np.testing.assert_array_equal(got.xyz[got.valid], expected.xyz[expected.valid])
    assert got.camera == expected.camera
    budget = full.height * full.width // stride**2
    k = working_stride(full.height, full.width, budget)
    assert k > 1
    np.testing.assert_array_equal(
        working_image(scan, max_pixels=budget).index,
        downsample_image(range_image(scan), k).index,
    )


@pytest.mark.parametrize("wraps", [False, True])
def test_sampling_gaps_counts_the_returns_beside_an_empty_pixel(wraps):
    """The share of returns with an empty pixel among their 8 neighbours (edges repeat, or
    columns wrap), against the 30 % line: a sky band leaves returns at its border beside it, a
    regular lattice of returns leaves every one; large images look at every k-th row."""
    from flexreg.stages.projection import SAMPLING_GAPS_SHARE, sampling_gaps

    grid = np.ones((40, 60), dtype=bool)
    grid[:10] = False  # sky: the returns of row 10 (1 in 30) lie beside it
    assert not sampling_gaps(grid, wraps)
    lattice = np.zeros((40, 60), dtype=bool)
    lattice[::2, ::2] = True
    assert sampling_gaps(lattice, wraps)
    # every third return with an empty pixel beside it, in every row: 1/3 >= 30 %
    stripes = np.ones((600, 60), dtype=bool)
    stripes[:, ::6] = False  # columns 1, 5 (of each 6) lie beside a gap: 2 of 5 returns
    assert sampling_gaps(stripes, wraps) == (2 / 5 >= SAMPLING_GAPS_SHARE)
    assert not sampling_gaps(np.zeros((3, 3), dtype=bool), wraps)
