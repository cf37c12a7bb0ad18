"""Full-resolution duels: the compiled checks give exactly what the camera models and the
tests of the module notes give, evaluated point by point in numpy; a pose's masks are kept."""

from __future__ import annotations

import numba
import numpy as np
import pytest

from flexreg.core.camera import PinholeCamera, SphericalCamera
from flexreg.core.range_image import from_depth
from flexreg.core.transforms import invert, make_transform, rotation_about_axis
from flexreg.registration.check import TOLERANCE
from flexreg.registration.fullres import (
    BEHIND_COS,
    FullPair,
    FullView,
    even_solid_angle,
    full_masks,
    full_score,
    full_scores,
    full_view,
    pose_masks,
)
from flexreg.stages.refinement.projective import camera_params, spherical_pixel
from flexreg.stages.verification import measured_image, range_slack

CAMERAS = {
    "full turn": SphericalCamera.from_reference(96, 48, 0.2, 2.9),
    "part turn": SphericalCamera(80, 40, -1.0, 2.0, 0.4, 2.4),
    "pinhole": PinholeCamera(60.0, 55.0, 40.0, 30.0, 80, 60),
}


def _view(camera, rng):
    """A range image of smooth random ranges (2-12 m, a few holes) and its full view."""
    H, W = camera.shape
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    d = 6.0 + 3.0 * np.sin(u / 7.0) * np.cos(v / 5.0) + rng.uniform(0, 0.05, (H, W))
    d[rng.random((H, W)) < 0.05] = np.nan
    image = from_depth(d, camera)
    return full_view(image, measured_image(image), range_slack(image))


def _reference(view, points, own, T, thr, coarse, normals=None):
    """The module's tests, point by point through the camera model's own projection."""
    q = points @ T[:3, :3].T + T[:3, 3]
    behind = np.zeros(len(points), bool)
    if normals is not None:  # turned normals pointing away from the view's scanner
        n = normals @ T[:3, :3].T
        with np.errstate(invalid="ignore"):
            behind = np.einsum("ij,ij->i", n, q) > BEHIND_COS * np.linalg.norm(q, axis=1)
    u, v, d = view.image.camera.project(q)
    W, H = view.image.width, view.image.height
    explained = np.zeros(len(points), bool)
    open_space = np.zeros(len(points), bool)
    score = 0.0
    for i in range(len(points)):
        if not (np.isfinite(u[i]) and np.isfinite(v[i]) and d[i] > 0):
            continue
        iu, iv = int(np.floor(u[i] + 0.5)), int(np.floor(v[i] + 0.5))
        if view.image.wraps and iu >= W:
            iu -= W
        if not (0 <= iu < W and 0 <= iv < H):
            continue
        e = d[i] - float(view.measured[iv, iu])
        base, rel = TOLERANCE.free(thr) if coarse else TOLERANCE.fine(thr)
        tol = base + rel * d[i] + float(view.slack[iv, iu])
        free_m, free_rel = TOLERANCE.free(thr)
        free = free_m + free_rel * d[i] + own[i]
        explained[i] = abs(e) < tol and not behind[i]
        open_space[i] = d[i] < view.nearest[iv, iu] - free
        score += (1.0 - (e / tol) ** 2 if explained[i] else 0.0) - 3.0 * open_space[i]
    return explained, open_space, score


def _pose(rng, scale=0.3):
    axis = rng.normal(size=3)
    R = rotation_about_axis(axis / np.linalg.norm(axis), rng.normal() * scale)
    return make_transform(R, rng.normal(size=3) * scale)


@pytest.mark.parametrize("name", list(CAMERAS))
def test_compiled_checks_equal_the_camera_models_tests(name):
    rng = np.random.default_rng(7)
    target, source = _view(CAMERAS[name], rng), _view(CAMERAS[name], rng)
    tested = behind = 0
    for _ in range(4):
        T = _pose(rng)
        args = (source.points, source.point_slack, T, 0.05)
        # the normals as they are, and turned round: the points seen from behind
        for normals in (None, source.normals, -source.normals):
            ok, bad = full_masks(target, *args, normals=normals)
            ok_ref, bad_ref, _ = _reference(target, *args, False, normals)
            np.testing.assert_array_equal(ok, ok_ref)
            np.testing.assert_array_equal(bad, bad_ref)
            for coarse in (False, True):
                s = full_score(target, *args, coarse=coarse, normals=normals)
                ref = _reference(target, *args, coarse, normals)[2]
                assert s == pytest.approx(ref, rel=1e-12, abs=1e-9)
            tested += int(ok.sum()) + int(bad.sum())
        behind += int(full_masks(target, *args)[0].sum() - ok.sum())
    assert tested > 100  # the poses put points on both tests
    assert behind > 50  # and turned round, many explained ones are seen from behind


def test_no_points_and_no_camera_score_nothing():
    rng = np.random.default_rng(1)
    view = _view(CAMERAS["full turn"], rng)
    none = np.zeros((0, 3))
    assert full_score(view, none, np.zeros(0), np.eye(4), 0.05) == 0.0
    ok, bad = full_masks(view, none, np.zeros(0), np.eye(4), 0.05)
    assert ok.shape == bad.shape == (0,)


@numba.njit
def _pixels(P, cam, W):  # pragma: no cover
    out = np.empty((P.shape[0], 2))
    for i in range(P.shape[0]):
        x, y, z = P[i, 0], P[i, 1], P[i, 2]
        r = np.sqrt(x * x + y * y + z * z)
        u, v = spherical_pixel(x, y, z, r, cam[0], cam[1], cam[2], cam[3], cam[4], W)
        out[i, 0], out[i, 1] = np.floor(u + 0.5), np.floor(v + 0.5)
    return out


@pytest.mark.parametrize("name", ["full turn", "part turn"])
def test_spherical_pixel_is_the_camera_models_pixel_at_edges_and_seams(name):
    """Points on pixel edges (to a nanometre), on the seam (x < 0, y = +-0) and at the poles
    fall on the pixel the camera model's projection gives."""
    cam = CAMERAS[name]
    rng = np.random.default_rng(3)
    n = 20_000
    u = rng.integers(-1, cam.width + 1, n) + rng.normal(0, 1e-9, n)
    v = rng.uniform(0, cam.height, n)
    P = cam.backproject(u, v, rng.uniform(0.5, 30, n)).reshape(-1, 3)
    seam = np.array([[-1.0, 0.0, 0.2], [-1.0, -0.0, 0.2], [-2.0, 1e-300, 0], [-2.0, -1e-300, 0]])
    poles = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [1e-12, 0.0, 3.0]])
    P = np.ascontiguousarray(np.concatenate([P, seam, poles]))
    uu, vv, _ = cam.project(P)
    expect = np.stack([np.floor(uu + 0.5), np.floor(vv + 0.5)], axis=1)
    got = _pixels(P, camera_params(from_depth(np.ones(cam.shape), cam))[1], cam.width)
    if cam.wraps:
        for a in (expect, got):
            a[:, 0] = np.where(a[:, 0] >= cam.width, a[:, 0] - cam.width, a[:, 0])
    np.testing.assert_array_equal(got, expect)


def test_pose_masks_are_kept_packed_per_pose_and_threshold_within_a_budget(monkeypatch):
    rng = np.random.default_rng(5)
    pair = FullPair(_view(CAMERAS["full turn"], rng), _view(CAMERAS["full turn"], rng))
    T = _pose(rng)
    first = pose_masks(pair, T, 0.05)
    assert len(pair.masks) == 1
    with monkeypatch.context() as m:  # a kept pose is not computed again
        m.setattr("flexreg.registration.fullres.full_masks", _refuse)
        again = pose_masks(pair, T.copy(), 0.05)
    for x, y in zip(first, again, strict=True):
        for a, b in zip(x, y, strict=True):
            assert a.dtype == b.dtype == bool
            np.testing.assert_array_equal(a, b)
    assert first[0][0].any() and first[1][1].shape == (len(pair.target.points),)
    pose_masks(pair, T, 0.02)  # another threshold: another entry
    assert len(pair.masks) == 2
    one = sum(p.nbytes for p in pair.masks[next(iter(pair.masks))])
    monkeypatch.setattr("flexreg.registration.fullres.MASKS_BUDGET_BYTES", 3 * one)
    for _ in range(5):
        pose_masks(pair, _pose(rng), 0.05)
    assert len(pair.masks) == 3  # the oldest went
    fresh = full_masks(pair.source, pair.target.points, pair.target.point_slack, invert(T), 0.05)
    np.testing.assert_array_equal(pose_masks(pair, T, 0.05)[1][0], fresh[0])


def _refuse(*args, **kwargs):
    raise AssertionError("computed again")


@pytest.mark.parametrize("coarse", [False, True])
def test_scores_of_shifted_poses_equal_each_pose_scored_alone(coarse):
    """A sweep's scores in one pass are, bit for bit, those of each slid pose alone."""
    rng = np.random.default_rng(11)
    target, source = _view(CAMERAS["full turn"], rng), _view(CAMERAS["full turn"], rng)
    T = _pose(rng)
    u = np.array([0.6, -0.8, 0.0])
    offsets = np.arange(-10, 11) * 0.05
    many = full_scores(
        target, source.points, source.point_slack, T, offsets[:, None] * u, 0.05, coarse=coarse
    )
    for x, got in zip(offsets, many, strict=True):
        moved = T.copy()
        moved[:3, 3] += x * u
        alone = full_score(target, source.points, source.point_slack, moved, 0.05, coarse=coarse)
        assert got == alone
    assert np.ptp(many) > 1.0  # the slide changes what fits


def test_wrap_is_pythons_modulo_in_every_turn():
    """The projection's wrap (selects within one turn either side, ``%`` beyond) gives what
    Python's floating-point modulo gives, on the edges of each turn too."""
    from flexreg.stages.refinement import projective

    W = 1024.0
    tiny = np.nextafter(0.0, 1.0)
    us = [0.0, -0.0, tiny, -tiny, 0.5, W - 1e-9, W, W + 1e-9, 2 * W - 1e-9, 2 * W, 5.5 * W]
    us += [-1e-9, -0.5, -W + 1e-9, -W, -W - 1e-9, -3.25 * W, 1e300, -1e300]
    for u in us:
        got = projective._wrap(u, W)
        assert got == u % W, u  # -0.0 stays -0.0 (the same number, the same pixel)
    assert np.isnan(projective._wrap(float("nan"), W))


def test_open_space_between_a_clouds_returns_is_bounded_by_the_returns():
    """A wall 10 m in front of a pinhole camera, seen on every other pixel of every other row
    (a cloud projected with gaps between its returns) or on every pixel but a band of sky (a
    sensor's grid). A point 5 m out on a returned pixel: in open space among the sparse
    returns (the empty pixels were never sampled), unknown beside the grid's sky (its ray may
    have met something dark); on an empty pixel: never in open space."""
    from flexreg.stages.projection import sampling_gaps

    cam = PinholeCamera(50.0, 50.0, 20.0, 20.0, 41, 41)
    sparse = np.full((41, 41), np.nan)
    sparse[::2, ::2] = 10.0
    grid = np.full((41, 41), 10.0)
    grid[:, 22:] = np.nan  # no return right of the pixel column 21
    views = {}
    assert sampling_gaps(np.isfinite(sparse)) and not sampling_gaps(np.isfinite(grid))
    for name, d in (("sparse", sparse), ("grid", grid)):
        image = from_depth(d, cam)
        gaps = sampling_gaps(image.valid)  # as a cloud's prepared view finds them
        views[name] = full_view(image, measured_image(image), range_slack(image), gaps=gaps)

    def ray(u, v, depth):  # camera-frame point on pixel (u, v) at this depth
        return np.array([[(u - 20.0) / 50.0 * depth, (v - 20.0) / 50.0 * depth, depth]])

    def opens(view, u, v):
        _, o = full_masks(view, ray(u, v, 5.0), np.zeros(1), np.eye(4), 0.05)
        return bool(o[0])

    assert opens(views["sparse"], 20, 20)  # a returned pixel: the returns around bound it
    assert not opens(views["sparse"], 21, 20)  # an empty pixel: nothing measured there
    assert opens(views["grid"], 10, 20)  # the wall all around
    assert not opens(views["grid"], 20, 20)  # the sky two columns away: unknown
    explained, _ = full_masks(views["sparse"], ray(20, 20, 10.0), np.zeros(1), np.eye(4), 0.05)
    assert explained[0]


def _facing_wall(x_m: float, side: float) -> FullView:
    """A panorama of one wall, the plane ``x = x_m`` (own frame), seen where the rays head
    its way (``side`` +1: towards +x)."""
    cam = SphericalCamera.from_reference(256, 128, 0.3, np.pi - 0.3)
    rays = cam.rays()
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(side * rays[..., 0] > 0.3, x_m / rays[..., 0], np.nan)
    image = from_depth(r, cam)
    return full_view(image, measured_image(image), range_slack(image))


def test_a_walls_two_faces_do_not_explain_a_pose_slid_by_its_thickness():
    # a 14 cm wall between two rooms: the target scanner 2 m before its face at x = 2, the
    # source 2 m beyond its other face at x = 2.14 (the truth: the source at x = 4.14).
    # Slid 14 cm, the source's face lands on the target's: every point fits in range, but
    # each faces away from the scanner that would see it
    target, source = _facing_wall(2.0, +1.0), _facing_wall(-2.0, -1.0)
    pair = FullPair(target, source)
    truth, slid = make_transform(np.eye(3), [4.14, 0, 0]), make_transform(np.eye(3), [4.0, 0, 0])
    n = len(source.points)
    assert n > 1000
    bare, _ = full_masks(target, source.points, source.point_slack, slid, 0.05)
    assert bare.mean() > 0.9  # without the side test the slid pose explains the wall
    known = [np.isfinite(v.normals).all(axis=1) for v in (source, target)]
    assert known[0].mean() > 0.95  # the image's border rows and columns have no normal
    for T in (truth, slid):
        (fwd, fwd_open), (bwd, bwd_open) = pose_masks(pair, T, 0.05)
        assert not fwd[known[0]].any() and not bwd[known[1]].any()
        assert not fwd_open.any() and not bwd_open.any()  # behind a wall is not open space
    for coarse in (False, True):
        args = (target, source.points, source.point_slack, slid, 0.05)
        sided = full_score(*args, coarse=coarse, normals=source.normals)
        assert sided < 0.05 * full_score(*args, coarse=coarse)


def test_panorama_rows_keep_their_share_of_solid_angle_evenly_spaced():
    # rows at 30, 60 and 90 degrees from the zenith: pixels of sin(theta) = 1/2, 0.87 and 1 of
    # an equator pixel's solid angle, so 4 (every other), 6 or 7, and all 8 of each row
    cam = SphericalCamera(8, 3, -np.pi, np.pi, np.pi / 6, 2 * np.pi / 3)
    image = from_depth(np.full((3, 8), 5.0), cam)
    keep = even_solid_angle(image).reshape(3, 8)
    assert keep[0].sum() == 4 and set(np.diff(np.flatnonzero(keep[0]))) == {2}
    assert keep[1].sum() in (6, 7) and keep[2].all()
    # a pinhole's pixels off its axis cover less: the centre keeps all, the corners fewer
    pin = from_depth(np.full((60, 80), 3.0), CAMERAS["pinhole"])
    kept = even_solid_angle(pin).reshape(60, 80)
    assert kept[25:35, 35:45].mean() > 0.97 and kept[:10, :10].mean() < 0.6
    # an image of no pixels keeps none; the full view's points are the kept ones
    assert even_solid_angle(from_depth(np.full((3, 8), np.nan), cam)).shape == (0,)
    assert len(full_view(image, measured_image(image), range_slack(image)).points) <= 19
