"""Configurations: `flexreg config show` round-trips, `--config FILE` and `--set KEY=VALUE` on
every command, result files rerun bit for bit, and one `error:` line for every bad value."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO, one_error_line, run_cli

from flexreg import Scan, read_scan, write_scan
from flexreg.calibration.config import CalibrationConfig
from flexreg.cli.config_cmd import CONFIGS
from flexreg.config import load_config, parse_sets, to_toml
from flexreg.core.camera import SphericalCamera
from flexreg.core.range_image import to_scan
from flexreg.core.transforms import apply, make_transform, rotation_about_axis
from flexreg.errors import ConfigError
from flexreg.odometry.config import EvaluationConfig, OdometryConfig
from flexreg.registration.config import RegistrationConfig
from flexreg.stages.projection import project

LASERSCAN = REPO / "data" / "laserscan" / "laserscan-depth.png"


def _files(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.rglob("*") if p.is_file())


# ----------------------------------------------------------------------------- the models


@pytest.mark.parametrize("name", sorted(CONFIGS))
def test_config_show_toml_loads_back_to_the_defaults(name, tmp_path):
    rc, out, err = run_cli(["config", "show", name])
    assert rc == 0, err
    path = tmp_path / f"{name}.toml"
    path.write_text(out)
    default = CONFIGS[name]()
    cls = type(default)
    assert load_config(cls, path) == default
    rc, out, _ = run_cli(["config", "show", name, "--json"])
    assert rc == 0 and load_config(cls, overrides=json.loads(out)) == default
    rc, out, _ = run_cli(["config", "show", name, "--schema"])
    assert rc == 0 and set(json.loads(out)["properties"]) == set(cls.model_fields)


def test_config_show_unknown_name_is_one_line():
    rc, _, err = run_cli(["config", "show", "registr"])
    assert rc == 1 and "unknown command 'registr'; known: register" in one_error_line(err)


def test_floats_round_trip_exactly_through_toml(tmp_path):
    cfg = RegistrationConfig(ratio=0.1 + 0.2, prior={"max_tilt_rad": 1 / 3}, threshold_m=1e-7)
    path = tmp_path / "r.toml"
    path.write_text(to_toml(cfg))
    back = load_config(RegistrationConfig, path)
    assert back == cfg and back.ratio == 0.1 + 0.2 and back.threshold_m == 1e-7


@pytest.mark.parametrize(
    ("cls", "changes", "message"),
    [
        (RegistrationConfig, {"n": 4}, "n: must be an odd grid size 3, 5, 7, ... 99 (got 4)"),
        (RegistrationConfig, {"ratio": 1.5}, "ratio: must be in (0, 1] (got 1.5)"),
        (RegistrationConfig, {"voxel_m": 0}, "voxel_m: must be in [0.0001, 10] (got 0"),
        (RegistrationConfig, {"seed": -1}, "seed: must be a non-negative integer (got -1)"),
        (RegistrationConfig, {"icp": "p2p"}, "icp: unknown method 'p2p'; known: point-to-plane"),
        (
            RegistrationConfig,
            {"prior": {"upright": "yes"}},
            "prior.upright: must be one of auto, on, off",
        ),
        (RegistrationConfig, {"median": 7}, "median: must be one of 0, 3, 5 (got 7)"),
        (RegistrationConfig, {"nn": 5}, "nn: unknown setting; did you mean n?"),
        (CalibrationConfig, {"patch_px": 20}, "patch_px: must be an odd size 7, 9, 11, ..."),
        (CalibrationConfig, {"confidence": 1.0}, "confidence: must be in (0, 1) (got 1.0)"),
        (OdometryConfig, {"min_inliers": 2}, "min_inliers: must be at least 5 (got 2)"),
        (EvaluationConfig, {"delta": 1.5}, "delta: must be a whole number of frames"),
        (EvaluationConfig, {"offset_s": float("nan")}, "offset_s: must be a finite number"),
    ],
)
def test_each_rule_is_one_line_naming_the_field_and_the_range(cls, changes, message):
    with pytest.raises(ConfigError) as e:
        cls(**changes)
    assert str(e.value).startswith(message), str(e.value)
    assert "\n" not in str(e.value)


def test_replace_validates_and_none_words():
    cfg = RegistrationConfig()
    assert cfg.replace(n=7).n == 7 and cfg.n == 5
    with pytest.raises(ConfigError, match="n: must be an odd"):
        cfg.replace(n=8)
    assert load_config(RegistrationConfig, overrides=parse_sets(["stretch=none"])).stretch is None


def test_an_old_flat_result_file_loads(tmp_path):
    """Result files store the flat fields under "config" (written before the models)."""
    doc = {"T_target_source": np.eye(4).tolist(), "config": RegistrationConfig(n=7).to_dict()}
    doc["config"]["threshold_m"] = None
    path = tmp_path / "old.json"
    path.write_text(json.dumps(doc))
    assert load_config(RegistrationConfig, path) == RegistrationConfig(n=7)


# ---------------------------------------------------------------------------- register runs


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    """The real laser scan and a second station 0.67 m away, turned 75°."""
    folder = tmp_path_factory.mktemp("pair")
    target = read_scan(LASERSCAN)
    T = make_transform(rotation_about_axis([0.05, 0.02, 1.0], np.radians(75.0)), [0.6, -0.3, 0.05])
    cam = SphericalCamera.from_reference(1799, 397, 0.80, 2.34)
    source = to_scan(project(Scan(points=apply(T, target.points)), cam))
    write_scan(folder / "target.npz", target)
    write_scan(folder / "source.npz", source)
    return folder / "target.npz", folder / "source.npz"


def _register(pair, out: Path, *extra) -> dict:
    rc, _, err = run_cli(["register", *pair, "--out", out, *extra])
    assert rc == 0, err
    return json.loads(out.read_text())


def test_config_file_and_result_json_reproduce_the_default_run(pair, tmp_path):
    """`config show register > r.toml; register --config r.toml` is the default run, bit for
    bit; so is `--config` of that run's result JSON."""
    default = _register(pair, tmp_path / "default.json")
    rc, toml, _ = run_cli(["config", "show", "register"])
    assert rc == 0
    (tmp_path / "r.toml").write_text(toml)
    from_toml = _register(pair, tmp_path / "toml.json", "--config", tmp_path / "r.toml")
    rerun = _register(pair, tmp_path / "rerun.json", "--config", tmp_path / "default.json")
    T = np.array(default["T_target_source"])
    for doc in (from_toml, rerun):
        assert np.array_equal(np.array(doc["T_target_source"]), T)
        assert doc["config"] == default["config"] == RegistrationConfig().to_dict()
        assert doc["inliers"] == default["inliers"] and doc["matches"] == default["matches"]


def test_options_and_set_override_the_file(pair, tmp_path):
    (tmp_path / "r.toml").write_text('features = "orb"\nseed = 3\nrefine = false\n')
    doc = _register(
        pair,
        tmp_path / "T.json",
        "--config",
        tmp_path / "r.toml",
        "--seed",
        "4",
        "--set",
        "max_features=5000",
    )
    c = doc["config"]
    assert (c["features"], c["seed"], c["refine"], c["max_features"]) == ("orb", 4, False, 5000)


@pytest.mark.parametrize(
    ("toml", "extra", "message"),
    [
        ("n = 4\n", [], "error: {toml}: n: must be an odd grid size 3, 5, 7, ... 99 (got 4)"),
        ("nn = 5\n", [], "error: {toml}: nn: unknown setting; did you mean n?"),
        ('ratio = "high"\n', [], "error: {toml}: ratio: must be a valid number"),
        ("n = [\n", [], "error: {toml}: not valid TOML"),
        ("", ["--set", "n=4"], "error: --set n: must be an odd grid size"),
        ("", ["--set", "voxel=0.1"], "error: --set voxel: unknown setting"),
        ("", ["--set", "n"], "error: --set 'n': expected KEY=VALUE"),
        ("", ["--n", "4"], "error: --n: must be an odd grid size"),
        ("", ["--seed", "1", "--set", "seed=2"], "error: --seed: also given as --set seed="),
    ],
)
def test_bad_config_values_give_one_line_and_write_nothing(tmp_path, toml, extra, message):
    path = tmp_path / "r.toml"
    path.write_text(toml)
    out = tmp_path / "out" / "T.json"
    argv = ["register", tmp_path / "a.ptx", tmp_path / "b.ptx", "--out", out, "--config", path]
    rc, _, err = run_cli([*argv, *extra])
    assert rc == 1
    assert one_error_line(err).startswith(message.format(toml=path)), err
    assert not (tmp_path / "out").exists()


def test_a_missing_config_file_is_one_line(tmp_path):
    missing = tmp_path / "none.toml"
    rc, _, err = run_cli(["register", "a.ptx", "b.ptx", "--out", "T.json", "--config", missing])
    assert rc == 1 and one_error_line(err) == f"error: {missing}: no such file"


# ------------------------------------------------------------------ every command, the same way


@pytest.mark.parametrize(
    ("argv", "key"),
    [
        (["register", "a.ptx", "b.ptx", "--out", "T.json"], "seed"),
        (["calibrate", "--image", "i.png", "--scan", "s.bin", "--camera", "c.yaml"], "seed"),
        (["odometry", "seq", "--out", "traj.txt"], "seed"),
        (["evaluate", "--gt", "gt.txt", "--est", "est.txt"], "delta"),
        (["compare", "a.ptx", "b.ptx", "--out", "report"], "seed"),
        (["bench", "--out", "bench"], "seed"),
        (["synth", "--out", "synth"], "seed"),
    ],
)
def test_every_command_takes_config_and_set(argv, key, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the inputs do not exist: the configuration comes first
    rc, _, err = run_cli([*argv, "--set", f"{key}=-1"])
    assert rc == 1
    assert one_error_line(err).startswith(f"error: --set {key}: must be a "), err
    (tmp_path / "c.toml").write_text(f"{key} = -1\n")
    rc, _, err = run_cli([*argv, "--config", "c.toml"])
    assert rc == 1
    assert one_error_line(err).startswith(f"error: c.toml: {key}: must be a "), err
    assert _files(tmp_path) == ["c.toml"]
