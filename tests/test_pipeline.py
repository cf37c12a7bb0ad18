"""register(): the whole chain on a real scan seen from a second, displaced station."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import REPO, room_pair

from flexreg import Scan, read_scan
from flexreg.core.camera import SphericalCamera
from flexreg.core.range_image import to_scan
from flexreg.core.transforms import (
    apply,
    invert,
    make_transform,
    rotation_about_axis,
    rotation_error_deg,
    translation_error_m,
)
from flexreg.errors import RegistrationError
from flexreg.registration import RegistrationConfig, register
from flexreg.stages.projection import project


@pytest.fixture(scope="module")
def mine_pair():
    target = read_scan(REPO / "data" / "laserscan" / "laserscan-depth.png")
    T_source_target = make_transform(
        rotation_about_axis([0.05, 0.02, 1.0], np.radians(75.0)), [0.6, -0.3, 0.05]
    )
    cam = SphericalCamera.from_reference(1799, 397, 0.80, 2.34)
    source = to_scan(project(Scan(points=apply(T_source_target, target.points)), cam))
    return target, source, invert(T_source_target)


def test_register_recovers_displaced_station(mine_pair):
    target, source, gt = mine_pair
    cfg = RegistrationConfig(features="sift", voxel_m=0.08, seed=1)
    r = register(target, source, cfg)
    assert r.inliers >= 50 and r.matches >= r.inliers
    assert rotation_error_deg(r.T_coarse, gt) < 0.5
    assert translation_error_m(r.T_coarse, gt) < 0.05
    assert rotation_error_deg(r.T_target_source, gt) < 0.05
    assert translation_error_m(r.T_target_source, gt) < 0.01
    assert "voxel" in r.fitness_denominator and 0.5 < r.fitness <= 1.0
    d = r.to_dict()
    assert d["seed"] == 1 and d["config"]["features"] == "sift" and len(d["timings_s"]) >= 6
    # deterministic: same inputs and seed, bit-identical transform
    r2 = register(target, source, cfg)
    assert np.array_equal(r.T_target_source, r2.T_target_source)


def test_register_unrelated_scans_raises(mine_pair):
    target, _, _ = mine_pair
    rng = np.random.default_rng(0)
    cam = SphericalCamera.from_reference(600, 200, 0.8, 2.3)
    noise = to_scan(project(Scan(points=rng.normal(0, 5, (60000, 3))), cam))
    with pytest.raises(RegistrationError, match=r"\d+"):
        register(target, noise, RegistrationConfig(refine=False))


def test_register_stanford_bunny_within_1_deg_and_5_mm(shared_data):
    """Real structured scans (400 x 512 grids, no camera model) with ground truth."""
    from flexreg import read_scans

    a, b = read_scans(shared_data / "bunny_range_scans_gt" / "derived_bunny_grids_and_gt.npz")
    gt = invert(a.T_world_scanner) @ b.T_world_scanner
    r = register(a, b, RegistrationConfig(seed=0))
    assert "plan" not in r.prior  # not a levelled panorama: descriptors alone
    for T in (r.T_coarse, r.T_target_source):
        assert rotation_error_deg(T, gt) < 1.0
        assert translation_error_m(T, gt) < 0.005


@pytest.fixture(scope="module")
def kurt3d(shared_data):
    """The three 3DTK Kurt3D scans (robot body cut off as the data's config.ini does)."""
    folder = shared_data / "tls_3dtk_kurt3d"
    return [read_scan(folder / f"scan00{i}.3d", min_range_m=0.48) for i in range(3)]


@pytest.mark.parametrize("i, j", [(0, 1), (0, 2)])
def test_register_3dtk_agrees_with_odometry(kurt3d, i, j):
    """No ground truth: the odometry prior is good to a degree or two and some centimetres.
    scan000 <- scan002 (3.4 m apart in a corridor whose near walls fit any shift along it)
    used to end at "no motion"; area-weighted checks and refinement keep it near odometry."""
    odometry = invert(kurt3d[i].T_world_scanner) @ kurt3d[j].T_world_scanner
    r = register(kurt3d[i], kurt3d[j], RegistrationConfig(seed=0))
    for T in (r.T_coarse, r.T_target_source):
        assert rotation_error_deg(T, odometry) < 2.5
        assert translation_error_m(T, odometry) < 0.2


def test_prepare_without_overlap_is_bit_for_bit_the_same():
    """``prepare(overlap=False)`` (what a survey worker runs: the checks' inputs and the plan
    views after the feature stages, a lower peak memory) gives exactly what the overlapped
    preparation gives, and so the same alignment."""
    import pickle
    from dataclasses import replace

    from flexreg.registration import Registration

    pair = room_pair(4, (512, 256))
    reg = Registration(RegistrationConfig())
    one = [reg.prepare(s) for s in (pair.target, pair.source)]
    two = [reg.prepare(s, overlap=False) for s in (pair.target, pair.source)]
    for a, b in zip(one, two, strict=True):
        assert a.plan is not None and set(a.timings_s) == set(b.timings_s)
        assert pickle.dumps(replace(a, timings_s={})) == pickle.dumps(replace(b, timings_s={}))
    Ta, Tb = reg.align(*one).T_target_source, reg.align(*two).T_target_source
    np.testing.assert_array_equal(Ta, Tb)
    assert rotation_error_deg(Ta, pair.T_target_source) < 0.1


def test_prepare_lets_go_of_the_scan_before_the_feature_stages(monkeypatch):
    """``prepare(keep_scan=False)`` (a survey worker with the projective refinement): the scan
    is freed once its working image and the refinement's sample exist, before SIFT; the
    prepared scan is what a survey caches (its ``scan`` the working image, whose index is one
    repeated value and pickles as such) and aligns as the kept one does."""
    import gc
    import pickle
    import weakref
    from dataclasses import replace

    from flexreg.registration import Registration
    from flexreg.registration import preparation as pl

    pair = room_pair(4, (512, 256))
    reg = Registration(RegistrationConfig())
    kept = [reg.prepare(s, overlap=False) for s in (pair.target, pair.source)]
    alive: list[object] = []
    detect = pl.detect_and_describe

    def watching(*args, **kwargs):
        gc.collect()
        alive.append(ref())
        return detect(*args, **kwargs)

    monkeypatch.setattr(pl, "detect_and_describe", watching)
    lean = []
    for s in (pair.target, pair.source):
        held = [replace(s)]  # a copy only this list holds, as a survey worker's read scan
        ref = weakref.ref(held[0])
        lean.append(reg.prepare(held.pop(), overlap=False, keep_scan=False))
    assert alive == [None, None]
    for a, b in zip(kept, lean, strict=True):
        assert b.scan is b.image and not any(b.image.index.strides)
        np.testing.assert_array_equal(a.view.refine_sample[1], b.view.refine_sample[1])
        np.testing.assert_array_equal(a.image.xyz, b.image.xyz)
        full = replace(b.image, index=np.full(b.image.shape, -1, dtype=np.int64))
        saved = len(pickle.dumps(full)) - len(pickle.dumps(b.image))
        assert saved > full.index.nbytes - 1000  # the index is not stored pixel by pixel
        back = pickle.loads(pickle.dumps(b))
        assert not any(back.image.index.strides) and (back.image.index == -1).all()
    Ta, Tb = reg.align(*kept).T_target_source, reg.align(*lean).T_target_source
    assert rotation_error_deg(Ta, Tb) < 1e-3 and translation_error_m(Ta, Tb) < 1e-4
    assert rotation_error_deg(Tb, pair.T_target_source) < 0.1
