"""Kabsch/Umeyama, RANSAC and consistency pruning: known transforms, outliers, degeneracy."""

from __future__ import annotations

import numpy as np
import pytest

from flexreg.core.transforms import (
    apply,
    make_transform,
    rotation_about_axis,
    rotation_error_deg,
    translation_error_m,
)
from flexreg.errors import DegenerateGeometryError
from flexreg.stages.alignment import consistent_subset, kabsch, ransac_rigid


@pytest.fixture()
def T_true():
    return make_transform(
        rotation_about_axis([0.3, -0.5, 0.8], np.radians(137.0)), [4.0, -2.5, 0.7]
    )


def test_kabsch_exact(T_true, rng):
    src = rng.uniform(-10, 10, (50, 3))
    T = kabsch(apply(T_true, src), src)
    np.testing.assert_allclose(T, T_true, atol=1e-12)


def test_kabsch_hand_computed_90deg():
    src = np.array([[1.0, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0]])
    tgt = np.array([[0.0, 1, 0], [-1, 0, 0], [0, 0, 1], [0, 0, 0]]) + [1.0, 0, 0]
    T = kabsch(tgt, src)
    np.testing.assert_allclose(T[:3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    np.testing.assert_allclose(T[:3, 3], [1, 0, 0], atol=1e-12)


def test_kabsch_weights_and_scale(T_true, rng):
    src = rng.uniform(-5, 5, (40, 3))
    tgt = apply(T_true, src)
    tgt[:10] += rng.normal(0, 3.0, (10, 3))  # gross errors with zero weight
    w = np.r_[np.zeros(10), np.ones(30)]
    np.testing.assert_allclose(kabsch(tgt, src, w), T_true, atol=1e-10)
    S = T_true.copy()
    S[:3, :3] *= 2.5
    T = kabsch(apply(S, src), src, with_scale=True)
    np.testing.assert_allclose(T, S, atol=1e-10)


def test_kabsch_noisy_is_least_squares(T_true, rng):
    src = rng.uniform(-5, 5, (2000, 3))
    tgt = apply(T_true, src) + rng.normal(0, 0.01, (2000, 3))
    T = kabsch(tgt, src)
    assert rotation_error_deg(T, T_true) < 0.02
    assert translation_error_m(T, T_true) < 0.002


@pytest.mark.parametrize(
    "src",
    [
        np.array([[0.0, 0, 0], [1, 0, 0]]),  # too few
        np.array([[0.0, 0, 0], [1, 1, 1], [2, 2, 2], [5, 5, 5]]),  # collinear
        np.zeros((5, 3)),  # coincident
    ],
)
def test_kabsch_degenerate_raises(src):
    with pytest.raises(DegenerateGeometryError):
        kabsch(src + 1.0, src)


def test_ransac_recovers_with_80_percent_outliers(T_true, rng):
    n = 600
    src = rng.uniform(-20, 20, (n, 3))
    tgt = apply(T_true, src) + rng.normal(0, 0.005, (n, 3))
    out = rng.random(n) < 0.8
    tgt[out] = rng.uniform(-20, 20, (int(out.sum()), 3))
    r = ransac_rigid(tgt, src, threshold_m=0.03, rng=7)
    assert rotation_error_deg(r.T_target_source, T_true) < 0.05
    assert translation_error_m(r.T_target_source, T_true) < 0.01
    # the inliers it reports are (nearly) exactly the true ones
    assert (r.inliers & out).sum() <= 2 and (r.inliers & ~out).sum() >= 0.98 * (~out).sum()
    assert r.rmse_m < 0.015


def test_ransac_deterministic(T_true, rng):
    src = rng.uniform(-20, 20, (300, 3))
    tgt = apply(T_true, src)
    tgt[::2] = rng.uniform(-20, 20, (150, 3))
    a = ransac_rigid(tgt, src, threshold_m=0.05, rng=3)
    b = ransac_rigid(tgt, src, threshold_m=0.05, rng=3)
    assert np.array_equal(a.T_target_source, b.T_target_source) and a.iterations == b.iterations


def test_ransac_too_few_inliers_raises(rng):
    src = rng.uniform(-20, 20, (100, 3))
    tgt = rng.uniform(-20, 20, (100, 3))  # no consistent motion at all
    with pytest.raises(DegenerateGeometryError, match=r"inliers|sample"):
        ransac_rigid(tgt, src, threshold_m=0.01, min_inliers=10, rng=0)


def test_ransac_collinear_inliers_raise(T_true, rng):
    t = rng.uniform(-10, 10, 50)
    src = np.column_stack([t, 2 * t, -t])
    with pytest.raises(DegenerateGeometryError):
        ransac_rigid(apply(T_true, src), src, threshold_m=0.01, rng=0)


def test_consistent_subset_removes_outliers(T_true, rng):
    n = 400
    src = rng.uniform(-15, 15, (n, 3))
    tgt = apply(T_true, src) + rng.normal(0, 0.01, (n, 3))
    out = rng.random(n) < 0.9  # 90 % outliers
    tgt[out] = rng.uniform(-15, 15, (int(out.sum()), 3))
    keep = consistent_subset(tgt, src, threshold_m=0.06)
    kept_out = out[keep].sum()
    assert kept_out <= 2 and len(keep) >= 0.9 * (~out).sum()
    T = (
        kabsch(tgt[keep], src[keep])
        if kept_out == 0
        else ransac_rigid(tgt[keep], src[keep], threshold_m=0.05, rng=0).T_target_source
    )
    assert rotation_error_deg(T, T_true) < 0.1


def test_ransac_few_correspondences_tries_every_triplet_once():
    """6 correspondences (one wrong): all C(6, 3) = 20 triplets, then the exact transform."""
    src = np.array(
        [[0, 0, 0], [2, 0, 0], [0, 3, 0], [0, 0, 1.5], [1, 1, 1], [2, 2, 0.5]], dtype=float
    )
    T_true = make_transform(rotation_about_axis([0.2, 0.1, 1.0], np.radians(40.0)), [1, -2, 0.5])
    tgt = apply(T_true, src)
    tgt[5] += [0.0, 0.0, 0.8]  # an outlier
    r = ransac_rigid(tgt, src, threshold_m=0.01, rng=0)
    assert r.iterations == 20
    assert r.inliers.tolist() == [True] * 5 + [False]
    assert np.allclose(r.T_target_source, T_true, atol=1e-9)
