"""The speed paths give exactly what the plain computations give: voxel sums from a grown hash
table, scale voxels and centroids kept by content."""

from __future__ import annotations

import numpy as np
import pytest

from flexreg.stages import overlap
from flexreg.stages.overlap import OverlapMeter, measure_overlap, scale_voxel
from flexreg.stages.sampling import voxel_centroids, voxel_count


def _reference_voxels(points: np.ndarray, voxel_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Sums and counts per voxel in the order of each voxel's first point, by numpy alone (the
    points added one by one in input order, as the compiled pass adds them)."""
    p = np.asarray(points)
    lo = p.min(axis=0).astype(np.float64) - voxel_m / 2
    keys = np.floor((p.astype(np.float64) - lo) / voxel_m).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")  # voxels by their first point
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    v = rank[inverse.reshape(-1)]
    sums = np.zeros((len(first), 3))
    for i in range(len(p)):  # sequential float64 sums, in input order
        sums[v[i]] += p[i]
    return sums, np.bincount(v, minlength=len(first))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("voxel_m", [0.05, 0.3, 2.0, 50.0])
def test_voxel_sums_match_a_plain_reference(dtype, voxel_m):
    rng = np.random.default_rng(3)
    # many more cells than the table starts with at the small voxels: the table grows
    pts = (rng.normal(size=(6000, 3)) * [4.0, 3.0, 1.0]).astype(dtype)
    sums, counts = _reference_voxels(pts, voxel_m)
    centroids = voxel_centroids(pts, voxel_m)
    np.testing.assert_array_equal(centroids, sums / counts[:, None])
    assert voxel_count(pts, voxel_m) == len(counts)


def test_voxel_sums_of_identical_points():
    pts = np.ones((5000, 3))
    np.testing.assert_array_equal(voxel_centroids(pts, 0.1), [[1.0, 1.0, 1.0]])


@pytest.fixture
def room(rng):
    """A box of walls with 20,000 points (metres)."""
    n = 20_000
    face = rng.integers(0, 6, n)
    p = rng.uniform(-1, 1, (n, 3))
    axis = face // 2
    p[np.arange(n), axis] = np.where(face % 2 == 0, -1.0, 1.0)
    return p * [5.0, 4.0, 1.5]


def test_scale_voxel_is_kept_by_content(room, monkeypatch):
    overlap._KEPT.clear()
    first = scale_voxel(room, max_points=500)
    calls = []
    real = overlap.median_spacing
    monkeypatch.setattr(overlap, "median_spacing", lambda *a, **k: calls.append(1) or real(*a, **k))
    assert scale_voxel(room.copy(), max_points=500) == first  # same values, another array
    assert calls == []
    moved = room + [0.0, 0.0, 1e-3]  # other values: searched again
    scale_voxel(moved, max_points=500)
    assert calls == [1]
    scale_voxel(room.astype(np.float32), max_points=500)  # another type: searched again
    assert calls == [1, 1]


def test_kept_overlap_equals_a_fresh_one(room):
    T = np.eye(4)
    T[:3, 3] = [0.3, -0.2, 0.0]
    source = room[::2] - T[:3, 3]
    overlap._KEPT.clear()
    fresh = measure_overlap(room, source, T, open3d_check=False)
    kept = measure_overlap(room.copy(), source, T, open3d_check=False)
    assert kept == fresh
    assert fresh.share > 0.5
    meter = OverlapMeter(room, source, open3d_check=False)
    assert not meter.target_points.flags.writeable  # shared by the links of this cloud
    explicit = measure_overlap(room, source, T, voxel_m=fresh.voxel_m, open3d_check=False)
    assert explicit.share == fresh.share and explicit.rmse_m == fresh.rmse_m


def test_kept_clouds_are_bounded(rng, monkeypatch):
    monkeypatch.setattr(overlap, "KEEP_CLOUDS", 3)
    overlap._KEPT.clear()
    for k in range(6):
        scale_voxel(rng.normal(size=(300, 3)) + k, max_points=100)
    assert len(overlap._KEPT) == 3


def _tree_spacing(points: np.ndarray, sample: int = 5000, seed: int = 0) -> float:
    """The median spacing by SciPy's k-d tree (the former computation)."""
    from scipy.spatial import cKDTree

    P = np.asarray(points, dtype=np.float64)
    idx = np.random.default_rng(seed).choice(len(P), min(sample, len(P)), replace=False)
    d, _ = cKDTree(P).query(P[idx], k=2)
    return float(np.median(d[:, 1]))


@pytest.mark.parametrize(
    "make",
    [
        lambda g: g.normal(size=(4000, 3)),
        lambda g: np.vstack([g.normal(size=(999, 3)), [[1e4, 0.0, 0.0]]]),  # an isolated point
        lambda g: np.c_[g.normal(size=(3000, 2)), np.zeros(3000)],  # a plane
        lambda g: np.c_[g.uniform(0, 100, 3000), np.zeros((3000, 2))],  # a line
        lambda g: g.normal(size=(2, 3)),
        lambda g: (g.normal(size=(20_000, 3)) * [20.0, 10.0, 2.0]).astype(np.float32),
    ],
)
def test_median_spacing_equals_the_k_d_trees(make):
    from flexreg.stages.sampling import median_spacing

    pts = make(np.random.default_rng(11))
    assert median_spacing(pts) == _tree_spacing(pts)
    assert median_spacing(pts, sample=100, seed=4) == _tree_spacing(pts, sample=100, seed=4)


def test_median_spacing_of_repeated_points_is_that_of_the_distinct_ones():
    """Every point three times (a k-d tree's median is 0 then): the spacing of the distinct
    points, bit for bit as the k-d tree gives it on them."""
    from flexreg.stages.sampling import median_spacing

    pts = np.repeat(np.random.default_rng(11).normal(size=(60, 3)), 3, axis=0)
    assert _tree_spacing(pts) == 0.0
    assert median_spacing(pts) == _tree_spacing(np.unique(pts, axis=0)) > 0
    one = np.zeros((5, 3))  # a single point repeated: no spacing to find
    assert median_spacing(one) == 0.0


def _numpy_quantize(img: np.ndarray, bits: int, lo: float, hi: float) -> tuple:
    """The quantisation as numpy evaluates it (the former computation)."""
    top = float(2**bits - 1)
    valid = np.isfinite(img)
    with np.errstate(invalid="ignore"):
        g = (img.astype(np.float64) - lo) * (top / (hi - lo))
        g = np.rint(np.clip(np.where(valid, g, 0.0), 0.0, top))
    return g.astype(np.uint8 if bits == 8 else np.uint16), valid


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("bits", [8, 16])
@pytest.mark.parametrize("value_range", [(0.0, 1.0), (-0.3, 2.5), (0.0, np.pi)])
def test_quantize_in_one_pass_equals_numpys(dtype, bits, value_range):
    from flexreg.stages.feature_images import quantize

    rng = np.random.default_rng(7)
    img = rng.uniform(-0.5, 3.5, (64, 80))
    top = 2**bits - 1
    lo, hi = value_range
    img[:8] = (np.arange(8 * 80).reshape(8, 80) % (top + 1) + 0.5) / top * (hi - lo) + lo  # ties
    img[8, :4] = [np.nan, np.inf, -np.inf, 0.0]
    img = img.astype(dtype)
    q, valid = quantize(img, bits, value_range=value_range)
    ref_q, ref_valid = _numpy_quantize(img, bits, lo, hi)
    assert q.dtype == ref_q.dtype
    np.testing.assert_array_equal(q, ref_q)
    np.testing.assert_array_equal(valid, ref_valid)
    q2, v2 = quantize(img, bits, value_range=value_range, stretch="percentile")
    p_lo, p_hi = (float(x) for x in np.percentile(img[ref_valid], [1.0, 99.0]))
    np.testing.assert_array_equal(q2, _numpy_quantize(img, bits, p_lo, p_hi)[0])
    np.testing.assert_array_equal(v2, ref_valid)
    q3, v3 = quantize(img, bits, value_range=value_range, stretch="clahe")
    assert not q3[~ref_valid].any()
    np.testing.assert_array_equal(v3, ref_valid)


def test_overlap_inputs_kept_ahead_give_the_same_figure(room, monkeypatch):
    from flexreg.stages.overlap import keep_overlap_inputs

    T = np.eye(4)
    T[:3, 3] = [0.2, 0.1, 0.0]
    source = (room[1::2] - T[:3, 3]).astype(np.float32)
    overlap._KEPT.clear()
    overlap._KEPT_ARRAYS.clear()
    fresh = measure_overlap(room, source, T, open3d_check=False)
    overlap._KEPT.clear()
    overlap._KEPT_ARRAYS.clear()
    keep_overlap_inputs(room, source)
    monkeypatch.setattr(overlap, "median_spacing", None)  # nothing left to search
    monkeypatch.setattr(overlap, "voxel_centroids", None)
    ahead = measure_overlap(room.copy(), source.copy(), T, open3d_check=False)
    assert ahead == fresh


def test_register_overlap_is_the_same_with_inputs_kept_ahead():
    """register computes the overlap's inputs beside its feature stages; its figure is the one
    measured afterwards from nothing."""
    from pathlib import Path

    from flexreg.core.camera import SphericalCamera
    from flexreg.core.range_image import to_scan
    from flexreg.core.scan import Scan
    from flexreg.core.transforms import apply, make_transform, rotation_about_axis
    from flexreg.io import read_scan
    from flexreg.registration import RegistrationConfig, register
    from flexreg.stages.projection import project

    target = read_scan(Path(__file__).resolve().parents[1] / "data/laserscan/laserscan-depth.png")
    T_st = make_transform(rotation_about_axis([0.0, 0.0, 1.0], np.radians(30.0)), [0.4, -0.2, 0])
    cam = SphericalCamera.from_reference(1799, 397, 0.80, 2.34)
    source = to_scan(project(Scan(points=apply(T_st, target.points)), cam))
    res = register(target, source, RegistrationConfig(voxel_m=0.08, seed=1))
    assert res.overlap is not None and res.overlap.share > 0.5
    assert overlap._KEPT and overlap._KEPT_ARRAYS  # computed ahead, beside the features
    overlap._KEPT.clear()
    overlap._KEPT_ARRAYS.clear()
    t32, s32 = (np.ascontiguousarray(x.points) for x in (target, source))
    again = measure_overlap(t32, s32, res.T_target_source, open3d_check=False)
    assert res.overlap == again
