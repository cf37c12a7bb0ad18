"""Camera models: paper eq. 1-8, exact round trips, the reference convention."""

from __future__ import annotations

import numpy as np
import pytest

from flexreg.core.camera import PinholeCamera, SphericalCamera, camera_from_dict
from flexreg.errors import InputError


def test_pinhole_hand_computed_with_skew():
    cam = PinholeCamera(fx=500.0, fy=400.0, cx=320.0, cy=240.0, width=640, height=480, skew=2.0)
    # eq. 1: u = fx X/Z + s Y/Z + cx, v = fy Y/Z + cy
    u, v, z = cam.project(np.array([[1.0, 2.0, 4.0]]))
    assert u[0] == pytest.approx(500 * 0.25 + 2 * 0.5 + 320)
    assert v[0] == pytest.approx(400 * 0.5 + 240)
    assert z[0] == 4.0
    # eq. 2 with the matrix written out
    Kinv = np.array(
        [
            [1 / 500, -2 / (500 * 400), (240 * 2 - 320 * 400) / (500 * 400)],
            [0, 1 / 400, -240 / 400],
            [0, 0, 1],
        ]
    )
    expect = Kinv @ np.array([u[0], v[0], 1.0]) * 4.0
    np.testing.assert_allclose(cam.backproject(u, v, z)[0], expect, atol=1e-12)
    np.testing.assert_allclose(np.linalg.inv(cam.K), Kinv, atol=1e-15)


def test_pinhole_round_trip_exact(rng):
    cam = PinholeCamera(525.0, 520.5, 319.5, 239.5, 640, 480, skew=0.3)
    P = np.column_stack(
        [rng.uniform(-3, 3, 1000), rng.uniform(-2, 2, 1000), rng.uniform(0.2, 9, 1000)]
    )
    u, v, z = cam.project(P)
    np.testing.assert_allclose(cam.backproject(u, v, z), P, rtol=0, atol=1e-9)
    r = np.linalg.norm(P, axis=1)
    np.testing.assert_allclose(cam.z_to_range(u, v, z), r, atol=1e-9)
    np.testing.assert_allclose(cam.range_to_z(u, v, r), z, atol=1e-9)
    np.testing.assert_allclose(cam.backproject(u, v, r, depth_kind="range"), P, atol=1e-9)


def test_pinhole_behind_camera_is_nan():
    cam = PinholeCamera(500.0, 500.0, 320.0, 240.0, 640, 480)
    u, v, _ = cam.project(np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 0.0]]))
    assert np.isnan(u).all() and np.isnan(v).all()


def test_spherical_reference_convention():
    # conversions/README.txt: phi(u) = u 2pi/W - pi ; theta(v) = tmin + v (tmax - tmin)/H
    cam = SphericalCamera.from_reference(1799, 397, 0.87, 2.27)
    phi, theta = cam.angles(np.array([0.0, 100.0]), np.array([0.0, 50.0]))
    np.testing.assert_allclose(phi, [-np.pi, 100 * 2 * np.pi / 1799 - np.pi], atol=1e-15)
    np.testing.assert_allclose(theta, [0.87, 0.87 + 50 * 1.4 / 397], atol=1e-15)
    # eq. 8: ray = (sin t cos p, sin t sin p, cos t)
    p = cam.backproject(100.0, 50.0, 2.5)
    t, f = theta[1], phi[1]
    np.testing.assert_allclose(
        p, 2.5 * np.array([np.sin(t) * np.cos(f), np.sin(t) * np.sin(f), np.cos(t)]), atol=1e-15
    )
    assert cam.wraps


def test_spherical_round_trip_exact(rng):
    cam = SphericalCamera(4096, 2048, -np.pi, np.pi, 0.0, np.pi)
    u = rng.uniform(0, 4096, 5000)
    v = rng.uniform(0.01, 2047.99, 5000)
    r = rng.uniform(0.5, 300, 5000)
    P = cam.backproject(u, v, r)
    u2, v2, r2 = cam.project(P)
    np.testing.assert_allclose(u2, u, atol=1e-9)
    np.testing.assert_allclose(v2, v, atol=1e-9)
    np.testing.assert_allclose(r2, r, atol=1e-9)
    np.testing.assert_allclose(cam.backproject(u2, v2, r2), P, atol=1e-9)


def test_spherical_partial_fov_round_trip_across_cut(rng):
    # a window whose azimuth crosses the -pi/pi cut
    cam = SphericalCamera(
        300, 200, np.radians(150), np.radians(240), np.radians(40), np.radians(120)
    )
    assert not cam.wraps
    u = rng.uniform(0, 299, 500)
    v = rng.uniform(0, 199, 500)
    P = cam.backproject(u, v, 7.0)
    u2, v2, _ = cam.project(P)
    np.testing.assert_allclose(u2, u, atol=1e-9)
    np.testing.assert_allclose(v2, v, atol=1e-9)


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(width=0, height=10, phi_min=-1, phi_max=1, theta_min=0.1, theta_max=1),
        dict(width=10, height=10, phi_min=1, phi_max=-1, theta_min=0.1, theta_max=1),
        dict(width=10, height=10, phi_min=-4, phi_max=4, theta_min=0.1, theta_max=1),
        dict(width=10, height=10, phi_min=-1, phi_max=1, theta_min=1, theta_max=0.5),
    ],
)
def test_spherical_rejects_bad_parameters(kwargs):
    with pytest.raises(InputError):
        SphericalCamera(**kwargs)


def test_pinhole_rejects_bad_parameters():
    with pytest.raises(InputError):
        PinholeCamera(0.0, 500.0, 1, 1, 10, 10)
    with pytest.raises(InputError):
        PinholeCamera(500.0, 500.0, 1, 1, 0, 10)


def test_camera_dict_round_trip():
    for cam in (
        PinholeCamera(1.0, 2.0, 3.0, 4.0, 5, 6, 0.5),
        SphericalCamera.from_reference(10, 5, 0.2, 2.9),
    ):
        assert camera_from_dict(cam.to_dict()) == cam


def _extent_by_sorting(P):
    """The azimuth/polar extent from every sorted azimuth (the definition)."""
    P = np.asarray(P, dtype=np.float64)
    r = np.linalg.norm(P, axis=1)
    P, r = P[r > 0], r[r > 0]
    phi = np.sort(np.arctan2(P[:, 1], P[:, 0]))
    theta = np.arccos(np.clip(P[:, 2] / r, -1.0, 1.0))
    gaps = np.diff(np.concatenate([phi, [phi[0] + 2 * np.pi]]))
    k = int(np.argmax(gaps))
    if gaps[k] < np.radians(5.0):
        return -np.pi, np.pi, theta.min(), theta.max(), True
    lo, hi = phi[(k + 1) % len(phi)], phi[k]
    return lo, hi + 2 * np.pi if hi < lo else hi, theta.min(), theta.max(), False


@pytest.mark.parametrize(
    "sectors_deg",
    [
        [(-180, 180)],  # a full turn
        [(10, 100)],  # a quarter
        [(150, 180), (-180, -120)],  # across the -180/180 cut
        [(0, 100), (104.9, 250)],  # a 4.9 degree gap, and 110 degrees empty
        [(-180, 30), (34.9, 180)],  # a 4.9 degree gap only: a full turn
        [(-180, 30), (35.1, 180)],  # a 5.1 degree gap: not a full turn
    ],
)
def test_azimuth_extent_in_buckets_is_that_of_the_sorted_azimuths(rng, monkeypatch, sectors_deg):
    """The bucketed extent (no per-point array) equals the one from every sorted azimuth,
    points at the origin ignored, whatever the chunk size."""
    import flexreg.core.camera as camera_module
    from flexreg.core.camera import azimuth_polar_extent

    phi = np.concatenate([np.radians(rng.uniform(a, b, 3000)) for a, b in sectors_deg])
    phi = np.concatenate(
        [phi, np.radians([a for a, _ in sectors_deg] + [b for _, b in sectors_deg])]
    )
    phi = np.clip(phi, -np.pi, np.pi)
    th = rng.uniform(0.3, 2.8, len(phi))
    P = np.stack([np.sin(th) * np.cos(phi), np.sin(th) * np.sin(phi), np.cos(th)], 1) * 7.0
    P = np.concatenate([P, np.zeros((5, 3))])
    for chunk in (1 << 18, 1000):
        monkeypatch.setattr(camera_module, "ANGLE_CHUNK", chunk)
        got = azimuth_polar_extent(P)
        want = _extent_by_sorting(P)
        assert got[4] == want[4]
        np.testing.assert_array_equal(np.array(got[:4]), np.array(want[:4], dtype=np.float64))
