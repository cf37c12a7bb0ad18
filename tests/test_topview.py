"""Levelling and plan views (flexreg.stages.priors), and hole filling of range images.

Hand-made organised grids give exact normals, areas and verticals; synthetic TLS stations with a
known pose give the true vertical and the true plan transform.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from flexreg.core.camera import PinholeCamera, SphericalCamera
from flexreg.core.range_image import from_depth
from flexreg.core.scan import Scan
from flexreg.core.transforms import rotation_about_axis
from flexreg.errors import DegenerateGeometryError
from flexreg.stages import plan_correlation as plancorr
from flexreg.stages import priors as topview
from flexreg.stages.priors import Levelling, PlanMatch, TopView, match_top_views
from flexreg.stages.projection import fill_holes, project, range_image
from flexreg.synth import TLSConfig, scan_tls, station_pair

Z = np.array([0.0, 0.0, 1.0])
LEVEL = Levelling(Z.copy(), np.eye(3), 0.0, 0.0, 0.0)  # an already levelled scanner


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(min(1.0, abs(float(a @ b)))))


def _wrap_deg(a: float) -> float:
    return (a + 180.0) % 360.0 - 180.0


def _box_ranges(
    cam: SphericalCamera,
    R_world_scanner: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    keep: tuple[str, ...] = ("floor", "ceiling", "walls"),
) -> np.ndarray:
    """Ranges of a scanner at the origin, rotated by ``R_world_scanner``, inside the box
    ``lo..hi`` (world frame, axis-aligned); surfaces not in ``keep`` give no return (0)."""
    d = cam.rays() @ R_world_scanner.T
    t = np.full(d.shape[:2], np.inf)
    face = np.full(d.shape[:2], -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        for axis in range(3):
            for side, bound in enumerate((lo[axis], hi[axis])):
                tt = bound / d[..., axis]
                tt = np.where(tt > 0, tt, np.inf)
                nearer = tt < t
                t = np.where(nearer, tt, t)
                face = np.where(nearer, 2 * axis + side, face)
    faces = {"floor": [4], "ceiling": [5], "walls": [0, 1, 2, 3], "wall x": [1]}
    ok = np.isin(face, [f for name in keep for f in faces[name]])
    return np.where(ok, t, 0.0)


BOX_LO, BOX_HI = np.array([-3.0, -4.0, -1.5]), np.array([5.0, 2.5, 1.5])
PANO = SphericalCamera.from_reference(360, 180, 0.0, math.pi)


# ---------------------------------------------------------------------------- surface_normals


def test_surface_normals_fronto_parallel_plane_exact():
    # plane Z = 2 through a pinhole camera with f = 100 px: each pixel is 2 cm x 2 cm
    cam = PinholeCamera(100.0, 100.0, 19.5, 14.5, 40, 30)
    for z, pixel_m in ((2.0, 0.02), (4.0, 0.04)):
        img = from_depth(np.full(cam.shape, z), cam)
        for k in (1, 2, 3):
            pts, nrm, area = topview.surface_normals(img, k=k)
            # pixels within k of the border lack a neighbour
            assert len(pts) == len(nrm) == len(area) == (30 - 2 * k) * (40 - 2 * k)
            np.testing.assert_allclose(pts[:, 2], z)
            np.testing.assert_allclose(nrm, np.tile([0.0, 0.0, -1.0], (len(nrm), 1)), atol=1e-12)
            np.testing.assert_allclose(area, pixel_m**2, rtol=1e-9)


def test_surface_normals_drop_depth_discontinuities():
    cam = PinholeCamera(100.0, 100.0, 19.5, 14.5, 40, 30)
    depth = np.full(cam.shape, 2.0)
    depth[:, 20:] = 3.0  # step between columns 19 and 20
    k = 2
    pts, nrm, _ = topview.surface_normals(from_depth(depth, cam), k=k)
    # columns whose neighbours at +-k straddle the step (2k of them) are dropped, besides the
    # border; all others see a plane facing the scanner
    assert len(pts) == (30 - 2 * k) * (40 - 2 * k - 2 * k)
    np.testing.assert_allclose(nrm[:, 2], -1.0, atol=1e-12)
    assert set(np.round(pts[:, 2], 12)) == {2.0, 3.0}


def test_surface_normals_area_independent_of_stride():
    cam = PinholeCamera(100.0, 100.0, 19.5, 14.5, 40, 30)
    img = from_depth(np.full(cam.shape, 2.0), cam)
    for s in (2, 3):
        _, _, area = topview.surface_normals(img, k=2, stride=s)
        # each kept pixel stands for s x s image pixels of 2 cm x 2 cm
        np.testing.assert_allclose(area, (s * 0.02) ** 2, rtol=1e-9)


def test_surface_normals_of_a_box_point_towards_the_scanner():
    R = rotation_about_axis([1.0, 2.0, 0.0], math.radians(4.0))
    img = from_depth(_box_ranges(PANO, R, BOX_LO, BOX_HI), PANO)
    pts, nrm, area = topview.surface_normals(img)
    assert len(pts) > 0.8 * img.n_valid
    np.testing.assert_allclose(np.linalg.norm(nrm, axis=1), 1.0, atol=1e-12)
    assert (np.einsum("ij,ij->i", nrm, pts) < 0).all()
    assert (area > 0).all()
    world = pts @ R.T
    # faces away (1 m) from the room's edges, where a pixel's neighbours lie on the next face
    x, y, z = world.T
    floor = (np.abs(z - BOX_LO[2]) < 1e-9) & (np.abs(x - 1.0) < 3.0) & (np.abs(y + 0.75) < 2.25)
    wall = (np.abs(x - BOX_HI[0]) < 1e-9) & (np.abs(y) < 2.0) & (np.abs(z) < 1.0)
    assert floor.sum() > 1000 and wall.sum() > 300
    # the floor's normal points up, the far x wall's back towards -x (world frame)
    np.testing.assert_allclose(nrm[floor] @ R.T, np.tile(Z, (floor.sum(), 1)), atol=1e-9)
    np.testing.assert_allclose(nrm[wall] @ R.T, np.tile([-1.0, 0, 0], (wall.sum(), 1)), atol=1e-9)


# ---------------------------------------------------------------------------- estimate_up


@pytest.mark.parametrize(
    ("axis", "tilt_deg"),
    [
        ((1.0, 2.0, 0.0), 4.0),
        ((1.0, 0.0, 0.0), 12.0),
        ((0.0, 1.0, 0.0), 0.0),
        ((1.0, 1.0, 0.0), 20.0),  # tilted scanners: the search over verticals finds these
        ((0.3, 1.0, 0.0), 24.0),
    ],
)
def test_estimate_up_box_room_recovers_tilt(axis, tilt_deg):
    R = rotation_about_axis(axis, math.radians(tilt_deg))
    img = from_depth(_box_ranges(PANO, R, BOX_LO, BOX_HI), PANO)
    pts, nrm, area = topview.surface_normals(img)
    lev = topview.estimate_up(nrm, area, points=pts)  # the floor test passes a tilted room
    up_true = R.T @ Z
    assert _angle_deg(lev.up, up_true) < 0.05
    assert lev.up[2] > 0 and abs(np.linalg.norm(lev.up) - 1.0) < 1e-12
    assert abs(math.degrees(lev.tilt_rad) - tilt_deg) < 0.05
    # R_level takes the vertical onto +Z, is a rotation, and keeps the heading
    np.testing.assert_allclose(lev.R_level @ lev.up, Z, atol=1e-12)
    np.testing.assert_allclose(lev.R_level @ lev.R_level.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(lev.R_level) == pytest.approx(1.0)
    # the levelled frame differs from the true world frame by a yaw only (here: none)
    assert _angle_deg(lev.R_level @ R.T @ [1.0, 0, 0], np.array([1.0, 0, 0])) < 0.05
    assert lev.horizontal_area_m2 > 0.2 * area.sum() and lev.vertical_area_m2 > 0.2 * area.sum()


@pytest.mark.parametrize("keep", [("floor",), ("walls",), ("floor", "walls")])
def test_estimate_up_from_floor_or_walls_alone(keep):
    R = rotation_about_axis([1.0, -1.0, 0.0], math.radians(4.0))
    img = from_depth(_box_ranges(PANO, R, BOX_LO, BOX_HI, keep), PANO)
    _, nrm, area = topview.surface_normals(img)
    lev = topview.estimate_up(nrm, area)
    assert _angle_deg(lev.up, R.T @ Z) < 0.1
    assert (lev.horizontal_area_m2 > 0) == ("floor" in keep)
    assert (lev.vertical_area_m2 > 0) == ("walls" in keep)


def _vault_like(facet_m2: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Hand-made normals (towards the scanner), areas and points: a floor of 80 m² under the
    scanner, side walls of 60 m² each, a wall of 60 m² across the axis, and one ceiling facet
    of ``facet_m2`` inclined 40° (a tunnel's vault) above and beside the scanner."""
    s, c = math.sin(math.radians(40.0)), math.cos(math.radians(40.0))
    nrm = np.array([[0, 0, 1.0], [0, 1.0, 0], [0, -1.0, 0], [1.0, 0, 0], [0, -s, -c]])
    area = np.array([80.0, 60.0, 60.0, 60.0, facet_m2])
    pts = np.array([[0, 0, -1.5], [0, -4.0, 0], [0, 4.0, 0], [-9.0, 0, 0], [0, 3.0, 4.0]])
    return np.repeat(nrm, 10, axis=0), np.repeat(area / 10, 10), np.repeat(pts, 10, axis=0)


def test_estimate_up_a_vault_facet_without_floor_is_no_vertical():
    # under Z: floor + walls + cross wall = 260 m² explained; under the facet's normal: the
    # facet + the cross wall = 310 m² (> 1.1 x 260), but no floor below the scanner
    nrm, area, pts = _vault_like(250.0)
    with pytest.raises(DegenerateGeometryError, match=r"not levelled: tilt 40\.0°"):
        topview.estimate_up(nrm, area)  # without points the floor test is skipped
    lev = topview.estimate_up(nrm, area, points=pts)
    assert math.degrees(lev.tilt_rad) < 1e-6
    assert lev.horizontal_area_m2 == pytest.approx(80.0)
    assert lev.vertical_area_m2 == pytest.approx(180.0)


def test_estimate_up_needs_a_floor_below_the_scanner():
    """The same room seen without its floor (a camera facing a wall and a ceiling, an object
    seen from outside): walls and a ceiling give a vertical, but nothing below the scanner
    faces up, so with points there is no levelling; a floor of 8 m² under 60 m² of ceiling is
    enough."""
    nrm = np.repeat(np.array([[0, 0, -1.0], [0, 1.0, 0], [0, -1.0, 0], [1.0, 0, 0]]), 10, 0)
    area = np.repeat(np.array([60.0, 60.0, 60.0, 60.0]) / 10, 10)
    pts = np.repeat(np.array([[0, 0, 2.5], [0, -4.0, 0], [0, 4.0, 0], [-9.0, 0, 0]]), 10, 0)
    assert topview.estimate_up(nrm, area).tilt_rad < 1e-6  # without points: not tested
    with pytest.raises(DegenerateGeometryError, match="no floor below the scanner"):
        topview.estimate_up(nrm, area, points=pts)
    floor = (np.repeat([[0, 0, 1.0]], 10, 0), np.full(10, 0.8), np.repeat([[0, 0, -1.5]], 10, 0))
    lev = topview.estimate_up(
        np.vstack([nrm, floor[0]]),
        np.concatenate([area, floor[1]]),
        points=np.vstack([pts, floor[2]]),
    )
    assert lev.tilt_rad < 1e-6 and lev.horizontal_area_m2 == pytest.approx(68.0)


def test_estimate_up_tilt_beyond_limit_raises():
    R = rotation_about_axis([1.0, 0.0, 0.0], math.radians(12.0))
    img = from_depth(_box_ranges(PANO, R, BOX_LO, BOX_HI), PANO)
    _, nrm, area = topview.surface_normals(img)
    with pytest.raises(DegenerateGeometryError, match=r"not levelled: tilt 12\.0°.*10\.0° limit"):
        topview.estimate_up(nrm, area, max_tilt_rad=math.radians(10.0))


def test_estimate_up_single_plane_at_45_degrees_raises():
    # plane n . x = 3 with n 45 degrees from the scanner's Z axis: neither floor nor wall
    n = np.array([math.sqrt(0.5), 0.0, math.sqrt(0.5)])
    with np.errstate(divide="ignore"):
        t = 3.0 / (PANO.rays() @ n)
    img = from_depth(np.where((t > 0) & (t < 15.0), t, 0.0), PANO)
    _, nrm, area = topview.surface_normals(img)
    assert len(nrm) > 1000
    np.testing.assert_allclose(nrm, np.tile(-n, (len(nrm), 1)), atol=1e-9)
    with pytest.raises(DegenerateGeometryError, match="cannot tell the vertical"):
        topview.estimate_up(nrm, area)


def test_estimate_up_single_wall_raises():
    # one vertical plane leaves the vertical free to turn within it
    img = from_depth(_box_ranges(PANO, np.eye(3), BOX_LO, BOX_HI, ("wall x",)), PANO)
    _, nrm, area = topview.surface_normals(img)
    assert len(nrm) > 1000
    with pytest.raises(DegenerateGeometryError):
        topview.estimate_up(nrm, area)


def test_estimate_up_random_cloud_raises(rng):
    img = project(Scan(points=rng.normal(0.0, 5.0, (60000, 3))), PANO)
    _, nrm, area = topview.surface_normals(img)
    with pytest.raises(DegenerateGeometryError, match="cannot tell the vertical"):
        topview.estimate_up(nrm, area)


def test_estimate_up_nothing_raises():
    with pytest.raises(DegenerateGeometryError):
        topview.estimate_up(np.zeros((0, 3)), np.zeros(0))


@pytest.fixture(scope="module")
def room_pair():
    """Two 512 x 256 stations of a synthetic room (random tilts up to 5°)."""
    return station_pair("room", seed=0, resolution=(512, 256))


@pytest.fixture(scope="module")
def room_views(room_pair):
    """Per station: levelling, coarse (25 cm) and fine (6.25 cm) plan, and normals data."""
    out = []
    for scan in (room_pair.target, room_pair.source):
        pts, nrm, area = topview.surface_normals(range_image(scan))
        lev = topview.estimate_up(nrm, area)
        out.append(
            (
                lev,
                topview.top_view(pts, nrm, area, lev, cell_m=0.25),
                topview.top_view(pts, nrm, area, lev, cell_m=0.0625),
                (pts, nrm, area),
            )
        )
    return out


def test_uncompacted_normals_give_the_same_levelling_and_plans(room_pair, room_views):
    # every pixel, area 0 where unusable: the same vertical and the same plans
    lev, coarse, fine, _ = room_views[0]
    pts, nrm, area = topview.surface_normals(range_image(room_pair.target), compact=False)
    img = range_image(room_pair.target)
    assert len(area) == img.height * img.width and (area == 0).any()
    lev2 = topview.estimate_up(nrm, area)
    np.testing.assert_allclose(lev2.up, lev.up, atol=1e-12)
    c2, f2 = topview.top_views(pts, nrm, area, lev2, [(0.25, 40.0), (0.0625, 40.0)])
    for a, b in ((coarse, c2), (fine, f2)):
        np.testing.assert_array_equal(a.cells, b.cells)
        np.testing.assert_allclose(a.values, b.values, rtol=1e-12)
        np.testing.assert_allclose(a.heights, b.heights, rtol=1e-12)


def test_rotated_rasters_hand_made():
    # (0.5, 0) and (0, 1) turned by 90 degrees: (0, 0.5) and (-1, 0); 0.5 m cells (0, 1) and
    # (-2, 0), stored at [iy + 3, ix + 3]; with bound 1 the second is left out
    xy = np.array([[0.5, 0.0], [0.0, 1.0]])
    vals = np.array([1.0, 2.0])
    yaws = np.array([math.pi / 2, 0.0])
    r = plancorr.rotated_rasters(xy, vals, yaws, 0.0, 0.0, 0.5, 3, 8, -1)
    assert r.shape == (2, 8, 8) and r.dtype == np.float32
    assert r[0, 4, 3] == 1.0 and r[0, 3, 1] == 2.0 and r[0].sum() == 3.0
    assert r[1, 3, 4] == 1.0 and r[1, 5, 3] == 2.0  # yaw 0: cells (1, 0) and (0, 2)
    # shifted by (-0.5, 0): (-0.5, 0.5) -> cell (-1, 1) kept; (-1.5, 0) -> cell (-3, 0) beyond
    shifted = plancorr.rotated_rasters(xy, vals, yaws[:1], -0.5, 0.0, 0.5, 3, 8, 1)
    assert shifted[0, 4, 2] == 1.0 and shifted[0].sum() == 1.0


def test_window_scores_hand_made():
    # one source cell of value 2 at (1, 0) (0.5 m cells), yaw 0, no shift; the target raster
    # holds 3 at its cell (0, 0) and 5 at (1, 1) (stored at [iy + 2, ix + 2]); offset d puts
    # the source cell on target cell (1, 0) - d: d = (1, 0) meets (0, 0), d = (0, -1) meets (1, 1)
    T = np.zeros((5, 5), np.float32)
    T[2, 2], T[3, 3] = 3.0, 5.0
    xy, vals = np.array([[0.5, 0.0]]), np.array([2.0])
    out = plancorr.window_scores(xy, vals, np.zeros(1), 0.0, 0.0, 0.5, T, 2, 1, 1)
    want = np.zeros((3, 3))
    want[1, 2] = 6.0  # [iy, ix] = [dy + 1, dx + 1]
    want[0, 1] = 10.0
    np.testing.assert_array_equal(out[0], want)


@pytest.mark.parametrize("shift_m", [0.4, 1.5])
def test_offsets_summed_in_a_window_equal_the_fft_products(room_views, shift_m):
    """The refinement's few offsets summed cell by cell give the FFT correlation's values
    (which the whole-plan products give in single precision)."""
    _, tv, tvf, _ = room_views[0]
    _, sv, svf, _ = room_views[1]
    for t, s in ((tv, sv), (tvf, svf)):
        off = plancorr.Offsets.of(t.cells, t.values, t.cell_m, shift_m)
        yaws = np.radians([-1.0, 0.0, 2.5, 91.0])
        t0 = np.array([0.3, -0.2])
        direct = plancorr.window_scores(
            s.xy, s.values, yaws, 0.3, -0.2, off.cell_m, off.T, off.rt + off.w, off.w, off.rt
        )
        near = np.arange(-off.w, off.w + 1) % off.n
        rasters = plancorr.rotated_rasters(
            s.xy, s.values, yaws, 0.3, -0.2, off.cell_m, off.rt + off.w, off.n, off.rt
        )
        fft = np.stack(
            [c[np.ix_(near, near)] for c in plancorr.correlation(rasters, off.FT, (off.n,) * 2)]
        )
        scale = float(np.abs(fft).max())
        assert scale > 0
        np.testing.assert_allclose(direct, fft, atol=1e-4 * scale)
        np.testing.assert_allclose(off.near(s.xy, s.values, t0, yaws), direct, atol=1e-4 * scale)


@pytest.mark.parametrize("seed", range(6))
def test_top_local_maxima_equal_the_maximum_filter(seed):
    from scipy import ndimage

    rng = np.random.default_rng(seed)
    corr = rng.normal(size=(40, 48))
    corr = ndimage.gaussian_filter(corr, 1.5, mode="wrap")  # smooth peaks, as correlations
    if seed % 2:
        corr = np.round(corr, 1)  # ties
    sep, k = 9, 3 + seed
    top = (corr == ndimage.maximum_filter(corr, size=sep, mode="wrap")) & (corr > 0)
    flat = np.flatnonzero(top)
    want = flat[np.argsort(-corr.ravel()[flat], kind="stable")][:k]
    np.testing.assert_array_equal(plancorr.top_local_maxima(corr, sep, k), want)
    assert len(plancorr.top_local_maxima(-np.abs(corr), sep, k)) == 0  # nothing positive


def test_estimate_up_synthetic_stations(room_pair, room_views):
    for scan, (lev, *_) in zip((room_pair.target, room_pair.source), room_views, strict=True):
        up_true = scan.T_world_scanner[:3, :3].T @ Z
        assert _angle_deg(lev.up, up_true) < 0.3
        assert abs(lev.tilt_rad - math.acos(up_true[2])) < math.radians(0.3)


@pytest.mark.parametrize(
    ("axis_deg", "tilt_deg", "yaw_deg"), [(30.0, 6.0, 70.0), (200.0, 9.0, -140.0)]
)
def test_estimate_up_synthetic_scan_at_known_tilt(room_pair, axis_deg, tilt_deg, yaw_deg):
    a = math.radians(axis_deg)
    R = rotation_about_axis([math.cos(a), math.sin(a), 0.0], math.radians(tilt_deg))
    T = np.eye(4)
    T[:3, :3] = R @ rotation_about_axis(Z, math.radians(yaw_deg))
    T[:3, 3] = room_pair.target.T_world_scanner[:3, 3]  # a free spot in the room
    scan = scan_tls(room_pair.scene, T, config=TLSConfig(width=512, height=256), rng=3)
    np.testing.assert_array_equal(scan.T_world_scanner, T)
    _, nrm, area = topview.surface_normals(range_image(scan))
    lev = topview.estimate_up(nrm, area)
    assert _angle_deg(lev.up, T[:3, :3].T @ Z) < 0.3
    assert abs(math.degrees(lev.tilt_rad) - tilt_deg) < 0.3
    with pytest.raises(DegenerateGeometryError, match="not levelled"):
        topview.estimate_up(nrm, area, max_tilt_rad=math.radians(tilt_deg - 2.0))


# ---------------------------------------------------------------------------- top_view


def test_top_view_hand_made_cells_and_heights():
    wall = [-1.0, 0.0, 0.0]
    up = [0.0, 0.0, 1.0]
    pts = np.array(
        [
            [1.0, 0.1, 0.3],  # cell (2, 0): two wall pixels, 0.025 m² each
            [1.1, -0.2, 1.0],
            [-0.9, 1.6, 0.0],  # cell (-2, 3): 0.9 m² -> 1.8 m, clipped to 0.25 m
            [3.0, 3.0, 0.0],  # cell (6, 6): 0.002 m² -> 4 mm of wall, below 5 mm: dropped
            [0.4, 0.4, 0.0],  # oblique (|n_z| = 0.7): neither wall nor floor
            [0.0, 1.0, -1.5],  # floor, 2 m²
            [1.0, 0.0, 1.2],  # table top, 1 m²
            [50.0, 0.0, 0.0],  # wall beyond radius_m
            [0.0, 50.0, 2.0],  # ceiling beyond radius_m
        ]
    )
    oblique = [0.0, -math.sqrt(0.51), math.sqrt(0.49)]
    nrm = np.array([wall, wall, [1.0, 0, 0], wall, oblique, up, up, wall, [0, 0, -1.0]])
    area = np.array([0.025, 0.025, 0.9, 0.002, 5.0, 2.0, 1.0, 5.0, 5.0])
    tv = topview.top_view(pts, nrm, area, LEVEL, cell_m=0.5, radius_m=40.0, height_bin_m=0.01)
    assert isinstance(tv, TopView) and tv.cell_m == 0.5 and tv.dz_m == 0.01
    got = {tuple(c): v for c, v in zip(tv.cells.tolist(), tv.values, strict=True)}
    assert got.keys() == {(2, 0), (-2, 3)}
    assert got[(2, 0)] == pytest.approx(0.05 / 0.5)
    assert got[(-2, 3)] == pytest.approx(0.25)  # max_surface_m
    np.testing.assert_allclose(tv.xy, tv.cells * 0.5)
    # heights: floor and table top only, area-weighted
    assert tv.heights.sum() == pytest.approx(3.0)
    zs = tv.z0_m + (np.flatnonzero(tv.heights) + 0.5) * tv.dz_m
    np.testing.assert_allclose(zs, [-1.5, 1.2], atol=0.01)
    np.testing.assert_allclose(tv.heights[tv.heights > 0], [2.0, 1.0])


def test_top_view_applies_the_levelling():
    # the same plan seen by a scanner tilted 7 degrees: the levelling undoes the tilt
    pts = np.array([[2.1, 0.1, 0.5], [2.1, -0.1, -0.5], [-1.1, 3.1, 0.2], [0.1, 0.2, -1.4]])
    nrm = np.array([[-1.0, 0, 0], [-1.0, 0, 0], [0, -1.0, 0], [0, 0, 1.0]])
    area = np.array([0.1, 0.1, 0.2, 1.0])
    R = rotation_about_axis([0.3, 1.0, 0.0], math.radians(7.0))  # scanner -> world
    lev = Levelling(R.T @ Z, R, math.radians(7.0), 1.0, 0.4)
    a = topview.top_view(pts, nrm, area, LEVEL, cell_m=0.5)
    b = topview.top_view(pts @ R, nrm @ R, area, lev, cell_m=0.5)
    np.testing.assert_array_equal(a.cells, b.cells)
    np.testing.assert_allclose(a.values, b.values)
    assert np.flatnonzero(a.heights).tolist() == np.flatnonzero(b.heights).tolist()


def test_top_view_without_walls_raises():
    pts = np.array([[0.0, 1.0, -1.5], [1.0, 0.0, -1.5]])
    nrm = np.tile(Z, (2, 1))
    with pytest.raises(DegenerateGeometryError, match="no vertical surfaces"):
        topview.top_view(pts, nrm, np.ones(2), LEVEL)


# ---------------------------------------------------------------------------- plan matching


def _moved_views(room_views, yaw_deg, t_xy, dz, cell_m):
    """Target plan of the levelled target station, and a source plan of the same points with
    ``p_s = Rz(yaw)^T (p_t - t)``, so the true overlay is ``p_t = Rz(yaw) p_s + t``."""
    lev, _, _, (pts, nrm, area) = room_views[0]
    pl, nl = pts @ lev.R_level.T, nrm @ lev.R_level.T
    Rz = rotation_about_axis(Z, math.radians(yaw_deg))
    t = np.array([t_xy[0], t_xy[1], dz])
    ps, ns = (pl - t) @ Rz, nl @ Rz
    return (
        topview.top_view(pl, nl, area, LEVEL, cell_m=cell_m),
        topview.top_view(ps, ns, area, LEVEL, cell_m=cell_m),
    )


MOVES = [(37.0, (1.3, -0.7), 0.237), (-123.4, (-0.45, 2.1), -0.41)]


@pytest.mark.parametrize(("yaw_deg", "t_xy", "dz"), MOVES)
def test_match_and_refine_recover_known_plan_move(room_views, yaw_deg, t_xy, dz):
    tv, sv = _moved_views(room_views, yaw_deg, t_xy, dz, 0.25)
    matches = topview.match_top_views(tv, sv, yaw_step_rad=math.radians(2.0), top_k=3)
    assert 1 <= len(matches) <= 3 and all(isinstance(m, PlanMatch) for m in matches)
    assert [m.score for m in matches] == sorted((m.score for m in matches), reverse=True)
    best = matches[0]
    assert abs(_wrap_deg(math.degrees(best.yaw_rad) - yaw_deg)) < 1.5
    assert math.dist(best.t_xy, t_xy) < 0.3
    tvf, svf = _moved_views(room_views, yaw_deg, t_xy, dz, 0.0625)
    ref = topview.refine_plan_match(tvf, svf, best)
    assert abs(_wrap_deg(math.degrees(ref.yaw_rad) - yaw_deg)) < 0.3
    assert math.dist(ref.t_xy, t_xy) < 0.05
    # z_t - z_s of the same horizontal surfaces
    assert topview.height_offset(tv, sv) == pytest.approx(dz, abs=0.02)
    assert topview.height_offset(sv, tv) == pytest.approx(-dz, abs=0.02)


def test_identical_plans_overlay_at_zero(room_views):
    _, tv, tvf, _ = room_views[0]
    best = topview.match_top_views(tv, tv, yaw_step_rad=math.radians(2.0), top_k=1)
    assert len(best) == 1
    assert abs(math.degrees(best[0].yaw_rad)) < 0.5 and math.hypot(*best[0].t_xy) < 0.05
    ref = topview.refine_plan_match(tvf, tvf, best[0])
    assert abs(math.degrees(ref.yaw_rad)) < 0.1 and math.hypot(*ref.t_xy) < 0.02
    assert topview.height_offset(tv, tv) == 0.0


def test_plan_match_between_two_stations(room_pair, room_views):
    """The real second station: its plan overlay equals the levelled ground truth."""
    (lt, tv, tvf, _), (ls, sv, svf, _) = room_views
    T = room_pair.T_target_source
    R = lt.R_level @ T[:3, :3] @ ls.R_level.T  # levelled source -> levelled target
    t = lt.R_level @ T[:3, 3]
    yaw_true = math.degrees(math.atan2(R[1, 0], R[0, 0]))
    best = topview.match_top_views(tv, sv, yaw_step_rad=math.radians(2.0), top_k=3)[0]
    assert abs(_wrap_deg(math.degrees(best.yaw_rad) - yaw_true)) < 1.5
    assert math.dist(best.t_xy, t[:2]) < 0.3
    ref = topview.refine_plan_match(tvf, svf, best)
    assert abs(_wrap_deg(math.degrees(ref.yaw_rad) - yaw_true)) < 0.5
    assert math.dist(ref.t_xy, t[:2]) < 0.1
    assert topview.height_offset(tv, sv) == pytest.approx(t[2], abs=0.03)


def test_plans_of_different_cell_sizes_raise(room_views):
    _, tv, tvf, _ = room_views[0]
    with pytest.raises(ValueError, match="cell size"):
        topview.match_top_views(tv, tvf)
    with pytest.raises(ValueError, match="cell size"):
        topview.refine_plan_match(tv, tvf, PlanMatch(0.0, (0.0, 0.0), 1.0))


# ---------------------------------------------------------------------------- fill_holes


@pytest.fixture()
def plane_7x7():
    cam = PinholeCamera(100.0, 100.0, 3.0, 3.0, 7, 7)
    return from_depth(np.full(cam.shape, 2.0), cam)


def _with_holes(img, holes):
    xyz, valid, index = img.xyz.copy(), img.valid.copy(), img.index.copy()
    for r, c in holes:
        xyz[r, c], valid[r, c], index[r, c] = np.nan, False, -1
    return type(img)(xyz=xyz, valid=valid, index=index, camera=img.camera)


def test_fill_holes_isolated_pixel_gets_neighbour_mean(plane_7x7):
    img = _with_holes(plane_7x7, [(3, 3)])
    before = img.xyz.copy()
    out = fill_holes(img)
    assert out.valid.all() and out.index[3, 3] == -1
    nb = [plane_7x7.xyz[3 + dr, 3 + dc] for dr in (-1, 0, 1) for dc in (-1, 0, 1) if dr or dc]
    np.testing.assert_allclose(out.xyz[3, 3], np.mean(nb, axis=0), rtol=0, atol=1e-12)
    # on a plane facing a pinhole camera that mean is the missing point itself: (0, 0, 2)
    np.testing.assert_allclose(out.xyz[3, 3], [0.0, 0.0, 2.0], atol=1e-15)
    np.testing.assert_array_equal(out.xyz[img.valid], img.xyz[img.valid])
    np.testing.assert_array_equal(out.index[img.valid], img.index[img.valid])
    np.testing.assert_array_equal(img.xyz, before)  # the input is left alone
    assert not img.valid[3, 3]


def test_fill_holes_hole_at_depth_step_stays_invalid():
    cam = PinholeCamera(100.0, 100.0, 3.0, 3.0, 7, 7)
    depth = np.full(cam.shape, 2.0)
    depth[:, 4:] = 3.0
    depth[3, 3] = 0.0  # hole next to the step: its neighbours span 2 m to 3 m
    img = from_depth(depth, cam)
    assert not fill_holes(img).valid[3, 3]
    # the spread is the only reason: a permissive max_jump fills it
    assert fill_holes(img, max_jump=0.5).valid[3, 3]


def test_fill_holes_3x3_block(plane_7x7):
    block = [(r, c) for r in (2, 3, 4) for c in (2, 3, 4)]
    out = fill_holes(_with_holes(plane_7x7, block))
    # one pass: the centre (0 valid neighbours) and the edge middles (3) stay empty, the
    # corners (5 valid neighbours >= min_neighbours) are filled
    for r, c in [(3, 3), (2, 3), (3, 2), (3, 4), (4, 3)]:
        assert not out.valid[r, c]
    for r, c in [(2, 2), (2, 4), (4, 2), (4, 4)]:
        assert out.valid[r, c] and out.index[r, c] == -1
    assert out.valid.sum() == 49 - 5
    out6 = fill_holes(_with_holes(plane_7x7, block), min_neighbours=6)
    assert out6.valid.sum() == 49 - 9


def test_fill_holes_wraps_on_full_turn_panorama():
    cam = SphericalCamera.from_reference(36, 18, 0.0, math.pi)
    full = from_depth(np.full(cam.shape, 5.0), cam)
    out = fill_holes(_with_holes(full, [(9, 0)]), min_neighbours=8)
    assert out.valid[9, 0] and out.index[9, 0] == -1
    nb = [full.xyz[9 + dr, dc % 36] for dr in (-1, 0, 1) for dc in (-1, 0, 1) if dr or dc]
    assert any(np.array_equal(p, full.xyz[9, 35]) for p in nb)  # column W-1 takes part
    np.testing.assert_allclose(out.xyz[9, 0], np.mean(nb, axis=0), atol=1e-12)
    # a panorama short of a full turn does not wrap: column 0 has only 5 neighbours
    part = SphericalCamera(36, 18, -math.pi, math.pi - 0.5, 0.0, math.pi)
    img = _with_holes(from_depth(np.full(part.shape, 5.0), part), [(9, 0)])
    assert not fill_holes(img, min_neighbours=8).valid[9, 0]
    assert fill_holes(img, min_neighbours=5).valid[9, 0]


def _racks(xs: list[float], cell_m: float = 0.25) -> TopView:
    """A plan of racks: 4 m bars along y at the given x (metres), 2 m of wall per cell."""
    cells = np.array([(round(x / cell_m), iy) for x in xs for iy in range(-8, 8)], dtype=np.int64)
    return TopView(
        cells=cells,
        values=np.full(len(cells), 2.0),
        cell_m=cell_m,
        xy=cells * cell_m,
        heights=np.ones(8),
        z0_m=0.0,
        dz_m=0.1,
    )


def test_a_turn_keeps_the_overlays_a_bay_beside_its_best():
    """Five racks 8 m apart, the source seen from 8 m further along the row: it sees the
    same five-rack plan as the target. The true offset (8 m) overlays four racks, the one a
    bay off (0 m) all five and correlates better (as does the row turned end for end). With
    one offset per turn the truth is never a candidate; with three per turn it is, beside
    its mirror a bay the other way."""
    target = source = _racks([0, 8, 16, 24, 32])
    found = {}
    for peaks in (1, 3):
        plans = match_top_views(
            target, source, yaw_step_rad=np.radians(2.0), top_k=10, coarse_candidates=6,
            peaks=peaks,
        )  # fmt: skip
        found[peaks] = [
            (round(abs(_wrap_deg(np.degrees(m.yaw_rad)))), round(m.t_xy[0]), round(m.t_xy[1]))
            for m in plans
        ]
    # a bay off, or the row turned end for end: the two five-rack overlays come first
    assert set(found[1][:2]) == set(found[3][:2]) == {(0, 0, 0), (180, 32, 0)}
    assert (0, 8, 0) in found[3] and (0, -8, 0) in found[3]
    assert (0, 8, 0) not in found[1] and (0, -8, 0) not in found[1]
