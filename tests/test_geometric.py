"""The geometric route: FPFH hypotheses (stages.geometric) and which route a pair takes."""

from __future__ import annotations

import json

import numpy as np
import pytest

from flexreg.core.camera import PinholeCamera, SphericalCamera
from flexreg.core.scan import Scan
from flexreg.core.transforms import rotation_error_deg, translation_error_m
from flexreg.errors import ConfigError, DegenerateGeometryError, InputError, RegistrationError
from flexreg.registration import register
from flexreg.registration.config import RegistrationConfig
from flexreg.registration.geometric import route
from flexreg.stages.geometric import (
    MIN_SUPPORT,
    describe,
    descriptor_voxel,
    hypotheses_from_matches,
)


def _pose(yaw_deg: float, t: tuple[float, float, float]) -> np.ndarray:
    a = np.radians(yaw_deg)
    T = np.eye(4)
    T[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    T[:3, 3] = t
    return T


def _apply(T: np.ndarray, p: np.ndarray) -> np.ndarray:
    return p @ T[:3, :3].T + T[:3, 3]


def test_hypotheses_the_truth_first_and_the_look_alike_second() -> None:
    """40 matches agree with the truth, 25 with a look-alike 3 m along, 60 are random: the
    truth first, the look-alike as the runner-up, each within the noise (1 mm) of its pose."""
    rng = np.random.default_rng(4)
    T_true, T_alias = _pose(30, (1.0, 2.0, 0.5)), _pose(-60, (4.0, -1.0, 0.2))
    src = rng.uniform(-3, 3, (125, 3))
    tgt = np.empty_like(src)
    tgt[:40] = _apply(T_true, src[:40])
    tgt[40:65] = _apply(T_alias, src[40:65])
    tgt[65:] = rng.uniform(-3, 3, (60, 3))
    tgt[:65] += rng.normal(0, 0.001, (65, 3))
    hyps = hypotheses_from_matches(tgt, src, threshold_m=0.01, count=3, rng=0)
    assert len(hyps) >= 2
    assert rotation_error_deg(hyps[0].T_target_source, T_true) < 0.2
    assert translation_error_m(hyps[0].T_target_source, T_true) < 0.005
    assert rotation_error_deg(hyps[1].T_target_source, T_alias) < 0.2
    assert translation_error_m(hyps[1].T_target_source, T_alias) < 0.005
    assert hyps[0].support >= 40 and 25 <= hyps[1].support < 40
    assert len(hyps[0].target_points) == hyps[0].support


def test_hypotheses_same_seed_same_answer_and_none_from_noise() -> None:
    rng = np.random.default_rng(1)
    src = rng.uniform(-3, 3, (80, 3))
    tgt = _apply(_pose(10, (0.2, 0.0, 0.0)), src)
    a = hypotheses_from_matches(tgt, src, threshold_m=0.01, rng=3)
    b = hypotheses_from_matches(tgt, src, threshold_m=0.01, rng=3)
    assert len(a) == len(b) == 1  # one pose explains all; nothing is left for a runner-up
    np.testing.assert_array_equal(a[0].T_target_source, b[0].T_target_source)
    # random correspondences: no pose is supported by MIN_SUPPORT of them within 1 mm
    noise = hypotheses_from_matches(
        rng.uniform(-3, 3, (50, 3)), rng.uniform(-3, 3, (50, 3)), threshold_m=0.001, rng=0
    )
    assert noise == []
    assert (
        hypotheses_from_matches(tgt[: MIN_SUPPORT - 1], src[: MIN_SUPPORT - 1], threshold_m=0.01)
        == []
    )


def test_descriptor_voxel_keeps_about_the_asked_count() -> None:
    """A 4 m x 4 m plane sampled every 1 cm: the voxel that keeps about 2000 points is near
    sqrt(16 m^2 / 2000) = 9 cm."""
    g = np.stack(np.meshgrid(np.arange(400), np.arange(400), [0.0]), -1).reshape(-1, 3) * 0.01
    v = descriptor_voxel(g, keep=2000)
    assert 0.07 < v < 0.11
    # a small cloud keeps every point: the voxel is its spacing
    assert descriptor_voxel(g[:100:1], keep=2000) == pytest.approx(0.01, rel=0.01)


def test_describe_orients_normals_towards_the_viewpoint_and_rejects_bad_voxels() -> None:
    g = np.stack(np.meshgrid(np.arange(60), np.arange(60), [0.0]), -1).reshape(-1, 3) * 0.02
    g[:, 2] = 2.0  # a plane 2 m above the viewpoint
    d = describe(g, voxel_m=0.05, viewpoint=(0, 0, 0))
    assert d.features.shape == (len(d.points), 33) and d.features.dtype == np.float32
    assert d.voxel_m == 0.05
    with pytest.raises(InputError, match="voxel_m"):
        describe(g, voxel_m=0.0)
    with pytest.raises(DegenerateGeometryError):
        describe(g[:2], voxel_m=0.05)


def _image(camera: object) -> object:
    class _Img:
        pass

    img = _Img()
    img.camera = camera  # type: ignore[attr-defined]
    return img


def test_route_per_method_and_scan_kind() -> None:
    sph = SphericalCamera(64, 32, -np.pi, np.pi, 0.0, np.pi)
    pano = [_image(sph), _image(sph)]
    pin = [_image(PinholeCamera(100.0, 100.0, 32.0, 24.0, 64, 48))] * 2
    assert route("flexion", pin, False) == "flexion"
    assert route("init", pin, False) == "flexion"  # the given transform alone
    assert route("geometric", pano, True) == "geometric"
    assert route("auto", pano, True) == "flexion"  # stations: the feature images alone
    assert route("auto", pin, True) == "both"  # a depth image: both routes judged together
    assert route("auto", pano, False) == "both"
    assert route("auto", pin, False) == "both"
    # a cloud the registration projects itself (a fragment, a lidar frame) is no station
    assert route("auto", pano, True, grids=False) == "both"


def test_method_is_validated_and_icp_only_is_method_init() -> None:
    assert RegistrationConfig().method == "auto"
    assert RegistrationConfig(method="init").icp_only
    # the switch of earlier releases (result files, TOML) reads as the method "init"
    assert RegistrationConfig.model_validate({"icp_only": True}).method == "init"
    assert RegistrationConfig.model_validate({"icp_only": False}).method == "auto"
    with pytest.raises((ConfigError, ValueError), match="method"):
        RegistrationConfig(method="fpfh")


# ----------------------------------------------------------------------- register's routes


@pytest.fixture(scope="module")
def views(tmp_path_factory):
    """Three views of the procedural object, 40-60 degrees apart, and their truth."""
    from conftest import run_cli

    out = tmp_path_factory.mktemp("views") / "set"
    args = ["synth", "--scene", "object", "--views", "3", "--view-step-deg", "40,60"]
    rc, _, err = run_cli([*args, "--seed", "5", "--out", out])
    assert rc == 0, err
    from flexreg.io import read_scan

    gt = json.loads((out / "gt.json").read_text())
    p = gt["pairs"][0]
    scans = [read_scan(out / "views" / f"{p[k]}.png") for k in ("target", "source")]
    return scans, np.asarray(p["T_target_source"])


def test_geometric_route_is_judged_and_never_confidently_wrong(views):
    """The geometric hypotheses go through the same verdict: a confident answer lies within
    1 degree and 3 mm (1 % of the 0.3 m range) of the truth; the route's stage is timed."""
    (target, source), T_true = views
    r = register(target, source, RegistrationConfig(method="geometric"))
    assert "geometric" in r.timings_s
    assert r.prior.startswith(("geometric", "alias", "sweep", "slide"))
    if r.verdict.confident:
        assert rotation_error_deg(r.T_target_source, T_true) < 1.0
        assert translation_error_m(r.T_target_source, T_true) < 0.003


def test_unrelated_clouds_are_never_confident_on_any_route(views):
    """An object view against a blob of random points: whatever the descriptors propose, the
    verdict refuses it or leaves it uncertain."""
    (target, _), _ = views
    rng = np.random.default_rng(2)
    blob = Scan(points=rng.normal([0, 0, 0.3], 0.05, (20000, 3)))
    for method in ("auto", "geometric"):
        try:
            r = register(target, blob, RegistrationConfig(method=method))
        except RegistrationError:
            continue
        assert not r.verdict.confident, method


def test_auto_keeps_the_feature_images_alone_on_stations():
    """Two gridded panoramas with a prior of the feature images: ``auto`` is ``flexion`` bit
    for bit, and the geometric route does not run."""
    from flexreg.synth import station_pair

    target, source, _ = station_pair("room", seed=3, resolution=(512, 256))
    assert target.has_grid and source.has_grid
    a = register(target, source, RegistrationConfig(method="auto"))
    f = register(target, source, RegistrationConfig(method="flexion"))
    assert np.array_equal(a.T_target_source, f.T_target_source)
    assert a.verdict.status == f.verdict.status
    assert "geometric" not in a.timings_s


def test_spacing_of_a_cloud_that_holds_every_point_twice() -> None:
    """PCL's room scans hold each point twice: the spacing is that of the distinct points (a
    2 cm grid here), not 0 (which refused the pair: "the target's points coincide")."""
    from flexreg.stages.sampling import median_spacing

    g = np.stack(np.meshgrid(np.arange(50), np.arange(50), [0.0]), -1).reshape(-1, 3) * 0.02
    assert median_spacing(np.concatenate([g, g])) == pytest.approx(0.02)
    assert median_spacing(g) == pytest.approx(0.02)


def test_clouds_with_gaps_between_returns_are_refined_on_nearest_points() -> None:
    """Two stations thinned to a random third of their points, unordered (no grid): their
    images have gaps between the returns, so the refinement pairs nearest points (Open3D)
    rather than pixels, and a confident answer lies within 0.2 degrees and 2 cm of the truth
    (3 mm range noise, points 2-3 cm apart)."""
    from flexreg.stages.projection import sampling_gaps, working_image
    from flexreg.synth import station_pair

    target, source, T_true = station_pair("room", seed=3, resolution=(512, 256))
    rng = np.random.default_rng(0)

    def thinned(s: Scan) -> Scan:
        return Scan(points=s.points[rng.random(len(s.points)) < 1 / 3])

    t, s = thinned(target), thinned(source)
    assert not t.has_grid and sampling_gaps(working_image(t).valid)
    r = register(t, s, RegistrationConfig(method="auto"))
    assert r.verdict.evidence.residual["kind"] == "open3d"  # nearest points, not pixels
    if r.verdict.confident:
        assert rotation_error_deg(r.T_target_source, T_true) < 0.2
        assert translation_error_m(r.T_target_source, T_true) < 0.02
