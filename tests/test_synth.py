"""Synthetic scanner: scenes, sensor models against analytic geometry, placement, ground truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flexreg.core.camera import SphericalCamera
from flexreg.core.transforms import apply, invert, make_transform, rotation_about_axis
from flexreg.errors import ConfigError, DegenerateGeometryError
from flexreg.synth import (
    AMBIGUOUS_SCENE_KINDS,
    CUE_SCENE_KINDS,
    SCENE_KINDS,
    RGBDConfig,
    Scene,
    TLSConfig,
    add_mesh_objects,
    free_map,
    lidar_config,
    look_at,
    make_scene,
    place_stations,
    read_scene,
    render_rgbd,
    scan_lidar,
    scan_tls,
    scene_from_mesh,
    station_overlap,
    station_pair,
    write_tum_sequence,
)
from flexreg.synth.mesh import arch, box, cylinder, ellipsoid, profile_slabs, tube, wall_boxes

SIGMA = 0.003
CLEAN = dict(dropout_rate=0.0, mixed_pixel_prob=0.0, tripod_cone_rad=0.0, min_intensity=0.0)


def _pose(yaw_deg: float, tilt_deg: float, t: tuple[float, float, float]) -> np.ndarray:
    R = rotation_about_axis([1.0, 1.0, 0.0], math.radians(tilt_deg)) @ rotation_about_axis(
        [0, 0, 1], math.radians(yaw_deg)
    )
    return make_transform(R, t)


def _plane_scene(z: float = 0.0, half: float = 200.0) -> Scene:
    V = np.array([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]])
    return Scene(V, np.array([[0, 1, 2], [0, 2, 3]]), 0.5, (128, 128, 128), name="plane")


# ------------------------------------------------------------------------------ primitives
@pytest.mark.parametrize(
    "mesh",
    [
        box([0, 0, 0], [1, 2, 3]),
        cylinder([0, 0, 0], [0.3, 0.2, 2.0], 0.4),
        tube([[0, 0, 0], [1, 0, 0], [1, 1, 0.5]], 0.1),
        ellipsoid([1, 2, 3], [1.0, 2.0, 0.5], subdivisions=2),
        *arch(1.0, 0.0, 0.4, 2.0, 1.5, 0.3, segments=3),
        *profile_slabs([[0, -0.3], [0, 2], [1, 3], [2, 2], [2, -0.3]], 0.0, 5.0, 0.3),
    ],
    ids=["box", "cylinder", "bent tube", "ellipsoid"]
    + [f"arch voussoir {i}" for i in range(3)]
    + [f"tunnel slab {i}" for i in range(4)],
)
def test_primitives_face_outward(mesh):
    V, F = mesh
    s = Scene(V, F, 0.5, (0, 0, 0))
    n = s.triangle_normals()
    # rays cast from just inside every face along its normal leave the object (hit nothing
    # or a back face), and from just outside against the normal they hit the face
    c = V[F].mean(axis=1)
    hits = s.cast(c - 1e-3 * n, n)
    assert np.all(~hits.hit | (np.einsum("ij,ij->i", hits.normal, n) > 0))
    out = s.cast(c + 1e-2 * n, -n)
    assert out.hit.all()
    assert np.all(np.einsum("ij,ij->i", out.normal, n) > 0.99)


def test_wall_boxes_leave_openings_open():
    boxes = wall_boxes(5.0, 3.0, 0.2, [(1.0, 2.0, 0.0, 2.1), (3.0, 4.5, 0.9, 2.4)])
    inside = [(1.5, 0.1, 1.0), (3.7, 0.1, 1.5)]
    solid = [(0.5, 0.1, 1.0), (1.5, 0.1, 2.5), (3.7, 0.1, 0.5), (3.7, 0.1, 2.7), (2.5, 0.1, 1.5)]

    def covered(p):
        return any(np.all(p >= lo) and np.all(p <= hi) for lo, hi in boxes)

    assert not any(covered(np.array(p)) for p in inside)
    assert all(covered(np.array(p)) for p in solid)


# ------------------------------------------------------------------------------ scenes
@pytest.mark.parametrize("kind", ["room", "courtyard", "hall"])
def test_scenes_are_seeded_and_rich(kind):
    a, b, c = make_scene(kind, 7), make_scene(kind, 7), make_scene(kind, 8)
    for name in ("vertices", "triangles", "reflectance", "colors"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.objects == b.objects
    assert a.n_triangles != c.n_triangles or not np.array_equal(a.vertices, c.vertices)
    x0, y0, x1, y1 = a.region
    lo, hi = {"room": (8, 20.5), "courtyard": (22, 60.5), "hall": (20, 50.5)}[kind]
    assert lo <= x1 - x0 <= hi and lo - 2 <= y1 - y0 <= hi
    assert sum(a.objects.values()) >= 25  # many distinct objects
    assert a.n_triangles >= 10000
    # detail from a few centimetres to metres: triangle edge lengths span that range
    V, F = a.vertices, a.triangles
    edge = np.linalg.norm(V[F[:, 1]] - V[F[:, 0]], axis=1)
    assert np.percentile(edge, 10) < 0.06 and edge.max() > 8.0


def test_make_scene_rejects_bad_input():
    with pytest.raises(ConfigError, match="unknown scene kind"):
        make_scene("garden", 0)
    with pytest.raises(ConfigError, match="room size"):
        make_scene("room", 0, size_m=(2.0, 9.0))
    with pytest.raises(ConfigError, match="rng"):
        make_scene("room", -3)


def test_scene_ply_round_trip(tmp_path):
    import open3d as o3d

    s = make_scene("room", 2)
    p = s.write(tmp_path / "scene.ply")
    back = read_scene(p)
    for name in ("vertices", "triangles", "reflectance", "colors"):
        assert np.array_equal(getattr(back, name), getattr(s, name)), name
    assert back.kind == "room" and back.seed == 2 and back.region == s.region
    m = o3d.io.read_triangle_mesh(str(p))  # other tools read it too
    assert len(m.triangles) == s.n_triangles


def test_mesh_as_scene_and_as_objects(shared_data):
    bunny = shared_data / "mesh_models" / "bun_zipper_res3.ply"
    s = scene_from_mesh(bunny, scale=20.0, up_axis="y")
    lo, hi = s.bounds
    assert lo[2] == pytest.approx(-0.3) and hi[2] == pytest.approx(20.0 * 0.1514, rel=1e-3)
    T = make_transform(np.eye(3), [s.region[0] + 1.0, 0.0, 1.6])
    scan = scan_tls(s, T, config=TLSConfig(width=128, height=64), rng=0)
    assert len(scan) > 1000
    room = make_scene("room", 1)
    with_bunnies = add_mesh_objects(room, bunny, count=3, size_m=0.6, rng=4)
    assert with_bunnies.n_triangles == room.n_triangles + 3 * 3851
    assert with_bunnies.objects["bun_zipper_res3"] == 3


# ------------------------------------------------------------------------------ TLS model
def test_tls_range_matches_analytic_plane():
    z_plane = -1.5
    scene = _plane_scene(z_plane)
    T = _pose(30.0, 4.0, (0.3, -0.2, 0.0))
    cfg = TLSConfig(width=512, height=256, max_range_m=60.0, **CLEAN)
    scan = scan_tls(scene, T, config=cfg, rng=1)
    assert len(scan) > 20000
    r = np.linalg.norm(scan.points, axis=1)
    d_world = (scan.points / r[:, None]) @ T[:3, :3].T
    r_true = (z_plane - T[2, 3]) / d_world[:, 2]
    sigma = cfg.range_noise_m + cfg.range_noise_per_m * r_true
    z = (r - r_true) / sigma
    assert abs(z.mean()) < 0.05
    assert z.std() == pytest.approx(1.0, abs=0.05)
    assert np.abs(z).max() < 6.0
    # world points lie on the plane (pose convention) within the noise
    assert np.abs(scan.points_world()[:, 2] - z_plane).max() < 6 * SIGMA
    # without noise the ray cast is exact to float32 rounding
    exact = scan_tls(
        scene,
        T,
        config=TLSConfig(
            width=512,
            height=256,
            max_range_m=60.0,
            range_noise_m=0.0,
            range_noise_per_m=0.0,
            **CLEAN,
        ),
    )
    r0 = np.linalg.norm(exact.points, axis=1)
    d0 = (exact.points / r0[:, None]) @ T[:3, :3].T
    np.testing.assert_allclose(r0, (z_plane - T[2, 3]) / d0[:, 2], atol=2e-5)


def test_tls_range_matches_analytic_sphere():
    import open3d as o3d

    R = 5.0
    sphere = o3d.geometry.TriangleMesh.create_sphere(radius=R, resolution=400)
    scene = scene_from_mesh(sphere, ground=False)  # centred on x, y; lowest point at z = 0
    c = np.array([0.0, 0.0, R])
    T = _pose(-70.0, 3.0, (0.8, -0.5, R + 0.3))
    cfg = TLSConfig(width=512, height=256, **CLEAN)
    scan = scan_tls(scene, T, config=cfg, rng=2)
    assert len(scan) == 512 * 256  # the inside of a sphere: every ray returns
    res = np.linalg.norm(scan.points_world() - c, axis=1) - R
    r = np.linalg.norm(scan.points, axis=1)
    sigma = cfg.range_noise_m + cfg.range_noise_per_m * r
    assert abs(np.median(res)) < 0.3e-3  # tessellation bias < 0.1 mm
    assert (res / sigma).std() == pytest.approx(1.0, abs=0.05)


def test_tls_grid_camera_and_intensity():
    scene = make_scene("room", 3)
    (T,) = place_stations(scene, 1, rng=3)
    cfg = TLSConfig(width=400, height=200)
    scan = scan_tls(scene, T, config=cfg, rng=0, name="s")
    assert scan.grid_shape == (200, 400) and isinstance(scan.camera, SphericalCamera)
    assert scan.camera.shape == (200, 400) and scan.camera.wraps
    u, v, _ = scan.camera.project(scan.points)
    np.testing.assert_allclose(v, scan.grid_index[:, 0], atol=1e-3)
    du = (u - scan.grid_index[:, 1] + 200) % 400 - 200
    np.testing.assert_allclose(du[scan.grid_index[:, 0] > 0], 0.0, atol=1e-3)  # row 0: zenith
    assert scan.intensity is not None and scan.intensity.dtype == np.float32
    assert 0.0 < scan.intensity.min() and scan.intensity.max() <= 1.0
    np.testing.assert_array_equal(scan.T_world_scanner, T)
    # intensity follows reflectance x cos(incidence): a wall seen head-on is brighter than
    # the same material at 70 deg
    plane = _plane_scene(-1.5)
    s = scan_tls(
        plane,
        np.eye(4),
        config=TLSConfig(width=360, height=180, intensity_speckle=0.0, **CLEAN),
        rng=0,
    )
    pol = np.arccos(-s.points[:, 2] / np.linalg.norm(s.points, axis=1))  # incidence angle
    steep, flat = (
        s.intensity[pol < np.radians(10)],
        s.intensity[np.abs(pol - np.radians(70)) < 0.02],
    )
    assert steep.mean() > 2.5 * flat.mean()


def test_tls_no_return_rules():
    scene = _plane_scene(-1.5)
    base = dict(
        width=720,
        height=360,
        tripod_cone_rad=math.radians(25),
        dropout_rate=0.0,
        mixed_pixel_prob=0.0,
        min_intensity=0.0,
    )

    def incidence(scan):  # angle between the ray and the plane normal
        return np.arccos(-scan.points[:, 2] / np.linalg.norm(scan.points, axis=1))

    # range limit binds: 1.5 m / cos(incidence) <= 10 m
    near = scan_tls(
        scene,
        np.eye(4),
        config=TLSConfig(max_range_m=10.0, max_incidence_rad=math.radians(89), **base),
        rng=0,
    )
    assert np.linalg.norm(near.points, axis=1).max() < 10.0 + 0.02
    assert incidence(near).max() == pytest.approx(math.acos(1.5 / 10.0), abs=math.radians(0.6))
    # grazing limit binds
    cfg = TLSConfig(max_range_m=150.0, max_incidence_rad=math.radians(80), **base)
    scan = scan_tls(scene, np.eye(4), config=cfg, rng=0)
    assert incidence(scan).max() <= math.radians(80) + 1e-6
    assert incidence(scan).max() == pytest.approx(math.radians(80), abs=math.radians(0.6))
    # tripod cone: nothing within 25 deg of straight down
    assert incidence(scan).min() >= math.radians(25) - 1e-6
    # random dropouts: the requested share of otherwise valid returns is lost
    drop = scan_tls(
        scene, np.eye(4), config=TLSConfig(**{**cfg.to_dict(), "dropout_rate": 0.1}), rng=0
    )
    assert 1 - len(drop) / len(scan) == pytest.approx(0.1, abs=0.01)


def test_tls_mixed_pixels_only_at_depth_edges():
    b = box([2.0, -0.5, -0.5], [2.5, 0.5, 0.5])  # a block 2 m in front of a wall at 6 m
    wall = box([6.0, -10, -10], [6.5, 10, 10])
    V = np.vstack([b[0], wall[0]])
    F = np.vstack([b[1], wall[1] + 8])
    scene = Scene(V, F, 0.6, (100, 100, 100))
    base = dict(
        width=720,
        height=360,
        phi_min=-0.6,
        phi_max=0.6,
        theta_min=1.0,
        theta_max=2.1,
        range_noise_m=0.0,
        range_noise_per_m=0.0,
        dropout_rate=0.0,
        min_intensity=0.0,
    )
    plain = scan_tls(scene, np.eye(4), config=TLSConfig(**base, mixed_pixel_prob=0.0), rng=0)
    mixed = scan_tls(scene, np.eye(4), config=TLSConfig(**base, mixed_pixel_prob=1.0), rng=0)
    off_plain = scene.distance(plain.points)
    off_mixed = scene.distance(mixed.points)
    assert off_plain.max() < 1e-4
    stray = off_mixed > 0.05
    assert 100 < stray.sum() < 0.05 * len(mixed)
    # every stray point sits between the block and the wall, next to the block's silhouette
    r = np.linalg.norm(mixed.points[stray], axis=1)
    assert r.min() > 2.0 and r.max() < 6.5 / 0.9


def test_tls_is_deterministic():
    scene = make_scene("hall", 1)
    (T,) = place_stations(scene, 1, rng=1)
    cfg = TLSConfig(width=600, height=300)
    a = scan_tls(scene, T, config=cfg, rng=11)
    b = scan_tls(scene, T, config=cfg, rng=11)
    c = scan_tls(scene, T, config=cfg, rng=12)
    assert a.points.tobytes() == b.points.tobytes()
    assert a.intensity.tobytes() == b.intensity.tobytes()
    assert a.grid_index.tobytes() == b.grid_index.tobytes()
    assert len(a) != len(c) or a.points.tobytes() != c.points.tobytes()
    # the multi-threaded ray caster itself is deterministic ray by ray
    d = np.random.default_rng(0).normal(size=(50000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    h1, h2 = scene.cast(T[:3, 3], d), scene.cast(T[:3, 3], d)
    assert h1.t.tobytes() == h2.t.tobytes() and np.array_equal(h1.primitive, h2.primitive)


def test_spinning_lidar():
    scene = make_scene("courtyard", 0)
    (T,) = place_stations(scene, 1, rng=0, max_tilt_rad=0.0)
    cfg = lidar_config(rings=32, columns=512)
    scan = scan_lidar(scene, T, config=cfg, rng=0)
    assert scan.grid_shape == (32, 512)
    elev = np.degrees(np.arcsin(scan.points[:, 2] / np.linalg.norm(scan.points, axis=1)))
    assert -25.5 < elev.min() and elev.max() < 15.5


# ------------------------------------------------------------------------------ RGB-D
def test_rgbd_depth_matches_analytic_plane(tmp_path):
    from flexreg.io.depth import TUM_DEPTH_SCALE, read_depth_png

    scene = _plane_scene(0.0)
    cfg = RGBDConfig(
        width=160,
        height=120,
        fx=130.0,
        fy=130.0,
        cx=79.5,
        cy=59.5,
        dropout_rate=0.0,
        edge_dropout_prob=0.0,
    )
    T = look_at([0.0, 0.0, 1.5], [2.0, 0.3, 0.0])
    f = render_rgbd(scene, T, config=cfg, rng=0)
    assert f.image.shape == (120, 160, 3) and f.image.dtype == np.uint8
    valid = np.isfinite(f.depth)
    assert valid.mean() > 0.95
    rays = cfg.camera().rays()  # z = 1
    d_world = rays @ T[:3, :3].T
    z_true = -T[2, 3] / d_world[..., 2]  # depth along the optical axis to z = 0
    sigma = cfg.depth_noise_m + cfg.depth_noise_quadratic * z_true**2
    err = (f.depth - z_true)[valid] / sigma[valid]
    assert abs(err.mean()) < 0.1 and err.std() == pytest.approx(1.0, abs=0.1)
    # TUM sequence on disk: 16-bit depth at 5000 units per metre and the pose file
    files = write_tum_sequence(tmp_path, scene, [T, T], config=cfg, rng=0)
    assert (tmp_path / "groundtruth.txt") in files
    back = read_depth_png(tmp_path / "depth" / "0.000000.png", depth_scale=TUM_DEPTH_SCALE)
    np.testing.assert_allclose(back[valid], f.depth[valid], atol=1e-4)
    gt = [
        ln.split()
        for ln in (tmp_path / "groundtruth.txt").read_text().splitlines()
        if not ln.startswith("#")
    ]
    assert len(gt) == 2 and len(gt[0]) == 8
    np.testing.assert_allclose([float(v) for v in gt[0][1:4]], T[:3, 3], atol=1e-9)


# ------------------------------------------------------------------------------ placement
def test_place_stations_meets_every_constraint():
    scene = make_scene("room", 5)
    tilt = math.radians(5.0)
    poses = place_stations(
        scene, 4, min_overlap=0.5, distance_range_m=(2.0, 8.0), max_tilt_rad=tilt, rng=5
    )
    assert len(poses) == 4
    fm = free_map(scene)
    P = np.array([T[:3, 3] for T in poses])
    free, gz = fm.lookup(P[:, :2])
    assert free.all()
    assert np.all((P[:, 2] - gz >= 1.3 - 1e-9) & (P[:, 2] - gz <= 1.8 + 1e-9))
    assert scene.distance(P).min() >= 0.3
    for T in poses:
        assert math.acos(np.clip(T[2, 2], -1, 1)) <= tilt + 1e-12
    for k in range(1, 4):
        ok = [
            2.0 <= np.linalg.norm(P[k] - P[j]) <= 8.0
            and station_overlap(scene, poses[j], poses[k]) >= 0.5
            for j in range(k)
        ]
        assert any(ok), k
    assert (
        place_stations(
            scene, 4, min_overlap=0.5, distance_range_m=(2.0, 8.0), max_tilt_rad=tilt, rng=5
        )[3].tobytes()
        == poses[3].tobytes()
    )


def test_place_stations_fails_cleanly():
    scene = make_scene("room", 0)
    with pytest.raises(DegenerateGeometryError, match="could not place station 1"):
        place_stations(scene, 2, distance_range_m=(40.0, 50.0), rng=0, max_tries=256)
    with pytest.raises(ConfigError):
        place_stations(scene, 2, distance_range_m=(5.0, 2.0))
    with pytest.raises(ConfigError):
        place_stations(scene, 0)


@pytest.mark.parametrize("kind", ["room", "courtyard", "hall"])
def test_station_pair_ground_truth_aligns_source_on_target_surfaces(kind):
    pair = station_pair(kind, seed=4, resolution=(512, 256), max_tilt_rad=math.radians(5.0))
    target, source, T = pair
    assert T.dtype == np.float64 and T.shape == (4, 4)
    np.testing.assert_allclose(T, invert(target.T_world_scanner) @ source.T_world_scanner)
    assert 2.0 <= pair.distance_m <= 10.0 and pair.overlap >= 0.5
    # source points, mapped with the ground truth into the target frame and then into the world,
    # lie on the scene surfaces: median point-to-mesh distance below the range noise
    in_target = apply(T, source.points)
    d = pair.scene.distance(apply(target.T_world_scanner, in_target))
    assert np.median(d) < SIGMA
    # ... and they land on surfaces the target scanned: most have a target point nearby
    from scipy.spatial import cKDTree

    nn, _ = cKDTree(target.points).query(in_target, distance_upper_bound=0.2)
    assert np.mean(np.isfinite(nn)) > 0.4
    # a slightly wrong transform does not pass the same test
    wrong = (
        make_transform(rotation_about_axis([1, 1, 0], math.radians(0.5)), [0.02, 0.02, 0.02]) @ T
    )
    d_wrong = pair.scene.distance(apply(target.T_world_scanner @ wrong, source.points))
    assert np.median(d_wrong) > 3 * SIGMA


# ------------------------------------------------------------------------------ ambiguous scenes
def _pairs_up(A: np.ndarray, B: np.ndarray, tol: float = 1e-6) -> np.ndarray:
    """(len(A),) bool: each point of A has a point of B within ``tol``."""
    from scipy.spatial import cKDTree

    d, _ = cKDTree(B).query(A, distance_upper_bound=tol)
    return np.isfinite(d)


def _range_grid(scan) -> np.ndarray:
    """Range of every grid pixel (NaN without a return)."""
    r = np.full(scan.grid_shape, np.nan)
    r[scan.grid_index[:, 0], scan.grid_index[:, 1]] = np.linalg.norm(scan.points, axis=1)
    return r


def test_scene_kinds_list_the_ambiguous_scenes():
    assert SCENE_KINDS[:3] == ("room", "courtyard", "hall")
    assert set(SCENE_KINDS[3:]) == set(AMBIGUOUS_SCENE_KINDS) | set(CUE_SCENE_KINDS)
    assert CUE_SCENE_KINDS == tuple(f"{k}-cue" for k in AMBIGUOUS_SCENE_KINDS)


@pytest.mark.parametrize("kind", AMBIGUOUS_SCENE_KINDS + CUE_SCENE_KINDS)
def test_ambiguous_scenes_build_deterministically_and_take_stations(kind):
    a, b = make_scene(kind, 3), make_scene(kind, 3)
    for name in ("vertices", "triangles", "reflectance", "colors"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.kind == kind and a.objects == b.objects and a.name == f"{kind}-3"
    assert not np.array_equal(make_scene(kind, 4).vertices, a.vertices)
    # the cue variant is the base scene plus one object, drawn after everything else
    base = make_scene(kind.removesuffix("-cue"), 3)
    assert len(base.symmetries) > 0 and (len(a.symmetries) == 0) == kind.endswith("-cue")
    if kind.endswith("-cue"):
        assert _pairs_up(base.vertices, a.vertices).mean() > 0.9
        assert {k: a.objects[k] for k in base.objects} == base.objects  # plus the cue's parts
        assert set(a.objects) > set(base.objects)
    for S in base.symmetries:
        np.testing.assert_allclose(S[:3, :3] @ S[:3, :3].T, np.eye(3), atol=1e-12)
    lo, hi = a.bounds
    x0, y0, x1, y1 = a.region
    assert lo[0] < x0 < x1 < hi[0] and lo[1] < y0 < y1 < hi[1]
    poses = place_stations(a, 2, rng=3)
    assert 2.0 <= np.linalg.norm(poses[1][:3, 3] - poses[0][:3, 3]) <= 10.0
    assert station_overlap(a, poses[0], poses[1]) >= 0.5
    doc = a.to_dict()
    assert ("symmetries" in doc) == bool(a.symmetries)


def test_make_scene_checks_ambiguous_sizes():
    with pytest.raises(ConfigError, match="symmetric room size"):
        make_scene("symmetric-room", 0, size_m=(6.0, 9.0))
    with pytest.raises(ConfigError, match="tunnel size"):
        make_scene("tunnel-cue", 0, size_m=(30.0, 8.0))
    with pytest.raises(ConfigError, match="bays width"):
        make_scene("bays", 0, size_m=(100.0, 5.0))


def test_symmetric_room_maps_onto_itself_and_its_cue_does_not():
    room_ = make_scene("symmetric-room", 1)
    cue = make_scene("symmetric-room-cue", 1)
    lo, hi = room_.bounds
    assert hi[0] - lo[0] == pytest.approx(hi[1] - lo[1])  # square: quarter turns
    assert len(room_.symmetries) == 3
    for S in room_.symmetries:
        V = apply(S, room_.vertices)
        assert _pairs_up(V, room_.vertices).all()
        # the cue's bookshelf, turned, stands in open space (the surfaces themselves are compared
        # by ray casting in test_a_station_moved_by_a_symmetry_measures_the_same_scan)
        Cc = cue.vertices[cue.triangles].mean(axis=1)
        assert np.mean(cue.distance(apply(S, Cc)) > 0.01) > 0.05
        # the cue's vertices (its bookshelf) have no partner after the turn
        assert not _pairs_up(apply(S, cue.vertices), cue.vertices).all()
    # a rectangle keeps only the half turn
    rect = make_scene("symmetric-room", 1, size_m=(9.0, 7.0))
    (half,) = rect.symmetries
    np.testing.assert_allclose(half[:2, :2], -np.eye(2))
    assert _pairs_up(apply(half, rect.vertices), rect.vertices).all()


@pytest.mark.parametrize("kind", AMBIGUOUS_SCENE_KINDS)
def test_a_station_moved_by_a_symmetry_measures_the_same_scan(kind):
    """The ambiguity itself: a station at ``S @ T`` gets the scan of ``T``, not in the cue
    variant."""
    cfg = TLSConfig(width=256, height=128, range_noise_m=0.0, range_noise_per_m=0.0, **CLEAN)
    scene, cue = make_scene(kind, 2), make_scene(f"{kind}-cue", 2)
    (T,) = place_stations(cue, 1, rng=2)
    for S in scene.symmetries:
        a, b = scan_tls(scene, T, config=cfg, rng=0), scan_tls(scene, S @ T, config=cfg, rng=0)
        ra, rb = _range_grid(a), _range_grid(b)
        same = (np.isnan(ra) & np.isnan(rb)) | (np.abs(ra - rb) < 0.01)
        assert same.mean() > 0.995, (kind, S[:3, 3])
        ca, cb = scan_tls(cue, T, config=cfg, rng=0), scan_tls(cue, S @ T, config=cfg, rng=0)
        rca, rcb = _range_grid(ca), _range_grid(cb)
        differ = ~((np.isnan(rca) & np.isnan(rcb)) | (np.abs(rca - rcb) < 0.05))
        # noise-free, so any return that moves is the cue; how many depends on where the
        # station landed, which ray casts decide (rays a few float32 ulps off: 16 for bays)
        assert differ.any(), (kind, S[:3, 3])


def test_tunnel_is_longer_than_the_scanner_reaches():
    max_range = TLSConfig().max_range_m
    for kind in ("tunnel", "tunnel-cue"):
        s = make_scene(kind, 0)
        lo, hi = s.bounds
        x0, _, x1, _ = s.region
        assert hi[0] - lo[0] > 2 * max_range
        assert x0 - lo[0] > max_range and hi[0] - x1 > max_range  # no station sees an end
    s = make_scene("tunnel", 0)
    # the cross-section never changes: the tube is built of pieces with the same vertices in
    # (y, z) at every joint
    inside = (s.vertices[:, 0] > 0.0) & (s.vertices[:, 0] < hi[0] - 0.3)
    xs = np.unique(np.round(s.vertices[inside, 0], 9))
    assert len(xs) >= 40
    sections = [
        np.unique(np.round(s.vertices[np.isclose(s.vertices[:, 0], x), 1:], 9), axis=0) for x in xs
    ]
    assert all(np.array_equal(sec, sections[0]) for sec in sections)
    assert any(np.allclose(S, make_transform(np.eye(3), [1.0, 0, 0])) for S in s.symmetries)
    # a station in the middle measures nothing beyond its range
    (T,) = place_stations(s, 1, rng=0)
    scan = scan_tls(s, T, config=TLSConfig(width=256, height=128), rng=0)
    assert np.linalg.norm(scan.points, axis=1).max() < max_range


def test_bays_repeat_with_their_period():
    s = make_scene("bays", 5)
    shift = s.symmetries[0]
    period = shift[0, 3]
    assert 3.2 <= period <= 3.8 and np.allclose(shift[:3, :3], np.eye(3))
    lo, hi = s.bounds
    x0, _, x1, _ = s.region
    assert x0 - lo[0] > TLSConfig().max_range_m and hi[0] - x1 > TLSConfig().max_range_m
    # away from the ends, the bays shifted by one period lie on the bays
    V = s.vertices
    mid = (V[:, 0] > x0 - 40) & (V[:, 0] < x1 + 40)
    for k in (1, -1, 2):
        assert _pairs_up(V[mid] + [k * period, 0, 0], V).all()
    assert s.objects["column"] == 2 * (round((hi[0] - lo[0] - 0.6) / period) - 1)
    # ... and not by a fraction of it
    assert _pairs_up(V[mid] + [0.5 * period, 0, 0], V).mean() < 0.5
    cue = make_scene("bays-cue", 5)
    Vc = cue.vertices
    midc = (Vc[:, 0] > x0 - 40) & (Vc[:, 0] < x1 + 40)
    assert not _pairs_up(Vc[midc] + [period, 0, 0], Vc).all()
