"""Hostile configurations: deep nesting, huge numbers, oversized files, multi-line ``--set``
values and sizes or steps no stage can afford are refused with one ``error:`` line, before any
scan is read and with nothing written."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import one_error_line, run_cli

from flexreg.config import MAX_CONFIG_BYTES, MAX_CONFIG_DEPTH, load_config, parse_sets
from flexreg.errors import ConfigError
from flexreg.registration.config import (
    SWEEP_RANGE_M,
    SWEEP_STEP_M,
    TWIN_RANGE_M,
    TWIN_STEP_M,
    RegistrationConfig,
)
from flexreg.survey.config import SurveyConfig


@pytest.fixture
def pair(tmp_path: Path) -> tuple[Path, Path]:
    """Two empty scan files: reading either fails ("file is empty"), so an error about the
    configuration shows it was checked first."""
    a, b = tmp_path / "a.ptx", tmp_path / "b.ptx"
    a.touch()
    b.touch()
    return a, b


def _refused(pair: tuple[Path, Path], *extra) -> str:
    """The one error line of ``register`` with ``extra``; asserts exit 1 and no output."""
    out = pair[0].parent / "T.json"
    rc, _, err = run_cli(["register", *pair, "--out", out, *extra])
    assert rc == 1, err
    assert not out.exists()
    assert "file is empty" not in err  # the configuration is checked before any scan is read
    return one_error_line(err)


# ----------------------------------------------------------------------- configuration files


def _deep_json() -> str:
    return '{"a": ' * 100_000


def _deep_toml() -> str:
    return "ratio = " + "[" * 100_000 + "]" * 100_000


@pytest.mark.parametrize(
    ("name", "text", "problem"),
    [
        ("deep.json", _deep_json(), "not valid JSON: nested deeper than 32 levels"),
        ("deep.toml", _deep_toml(), "not valid TOML: nested deeper than 32 levels"),
        ("deep33.toml", "ratio = " + "[" * 33 + "]" * 33, "nested deeper than 32 levels"),
        (
            "digits.json",
            '{"max_features": ' + "9" * 5000 + "}",
            "not valid JSON: a number of more than",
        ),
        ("digits.toml", "max_features = " + "9" * 5000, "not valid TOML: a number of more than"),
        ("big.toml", "# padding\n" * (MAX_CONFIG_BYTES // 10 + 1), "larger than 1 MiB"),
    ],
)
def test_hostile_config_files_give_one_line_naming_the_file(pair, name, text, problem):
    path = pair[0].parent / name
    path.write_text(text)
    line = _refused(pair, "--config", path)
    assert line.startswith(f"error: {path}: ") and problem in line, line


def test_load_config_refuses_deep_files_with_config_error(tmp_path):
    path = tmp_path / "deep.json"
    path.write_text(_deep_json())
    with pytest.raises(ConfigError, match="nested deeper than 32 levels"):
        load_config(RegistrationConfig, path)


def test_nesting_up_to_the_limit_is_parsed(tmp_path):
    """Not a blanket refusal: a value 32 levels deep reaches the model (which refuses a list
    for a number on its own terms)."""
    path = tmp_path / "ok.toml"
    path.write_text("ratio = " + "[" * (MAX_CONFIG_DEPTH - 1) + "]" * (MAX_CONFIG_DEPTH - 1))
    with pytest.raises(ConfigError, match=r"ratio: must be a valid number"):
        load_config(RegistrationConfig, path)


def test_a_long_number_is_shown_short(pair, tmp_path):
    path = tmp_path / "long.json"
    path.write_text(json.dumps({"max_features": int("9" * 4000)}))
    line = _refused(pair, "--config", path)
    assert "max_features: must be in [8, 200000] (got a number of 4000 digits)" in line
    assert len(line) < 200


# ------------------------------------------------------------------------------------ --set


@pytest.mark.parametrize(
    ("item", "message"),
    [
        ("ratio=" + "[" * 5000 + "]" * 5000, "--set ratio: nested deeper than 32 levels"),
        ("ratio=" + "[" * 40 + "]" * 40, "--set ratio: nested deeper than 32 levels"),
        ("max_features=" + "9" * 5000, "--set max_features: a number of more than"),
        ("ratio=0.8\nmax_features = 9", "--set: one KEY=VALUE per option; got a line break"),
        ("ratio=0.8\r\nmax_features = 9", "--set: one KEY=VALUE per option; got a line break"),
        ("ratio=0.8\u2028max_features = 9", "--set: one KEY=VALUE per option; got a line break"),
        ("ratio=0.8\x00", "--set: got a control character"),
        ("features=orb\x1b[31m", "--set: got a control character"),
    ],
)
def test_hostile_set_values_give_one_line(pair, item, message):
    assert message in _refused(pair, "--set", item)


def test_parse_sets_refuses_a_second_line_instead_of_dropping_it():
    with pytest.raises(ConfigError, match="one KEY=VALUE per option; got a line break"):
        parse_sets(["ratio=0.8\nmax_features = 9"])
    assert parse_sets(["ratio=0.8", "max_features=9"]) == {"ratio": 0.8, "max_features": 9}


# ------------------------------------------------------------------- sizes, steps and counts

#: (field, a value no run can afford or resolve, the bounds in the message)
BAD_VALUES = [
    ("prior.plan_cell_m", "0.000001", "[0.1, 2]"),
    ("prior.plan_cell_m", "0.01", "[0.1, 2]"),
    ("prior.plan_cell_m", "100", "[0.1, 2]"),
    ("prior.plan_hypotheses", "100000", "[1, 50]"),
    ("max_iterations", "10000000000", "[1, 1000000]"),
    ("max_features", "100000000", "[8, 200000]"),
    ("max_image_pixels", "1", "[16384, 50000000]"),
    ("max_image_pixels", "1000000000000", "[16384, 50000000]"),
    ("feature_strip_pixels", "1000000000000", "[0, 50000000]"),
    ("feature_tile_pixels", "1000000000000", "[0, 50000000]"),
    ("prior.guided_radius_m", "1000", "(0, 5]"),
    ("prior.guided_radius_per_m", "100", "[0, 1]"),
    ("judge.open_share", "2", "[0, 1]"),
]


@pytest.mark.parametrize(("field", "value", "bounds"), BAD_VALUES)
def test_unaffordable_sizes_and_steps_are_refused_before_reading(pair, field, value, bounds):
    line = _refused(pair, "--set", f"{field}={value}")
    assert line.startswith(f"error: --set {field}: must be in {bounds} (got "), line


@pytest.mark.parametrize(("field", "value", "bounds"), BAD_VALUES[:6])
def test_unaffordable_values_in_a_file_name_the_file(pair, field, value, bounds):
    path = pair[0].parent / "run.toml"
    path.write_text(f"{field} = {value}\n")
    line = _refused(pair, "--config", path)
    assert line.startswith(f"error: {path}: {field}: must be in {bounds}"), line


def test_survey_refine_voxel_is_bounded(tmp_path, pair):
    out = tmp_path / "out"
    rc, _, err = run_cli(["survey", *pair, "--out", out, "--set", "refine_voxel_m=0.0001"])
    assert rc == 1 and not out.exists()
    assert one_error_line(err) == "error: --set refine_voxel_m: must be in [0.01, 10] (got 0.0001)"
    rc, _, err = run_cli(
        ["survey", *pair, "--out", out, "--set", "registration.prior.plan_cell_m=0.000001"]
    )
    assert rc == 1 and not out.exists()
    assert "--set prior.plan_cell_m: must be in [0.1, 2]" in one_error_line(err)


def test_retired_slide_settings_are_refused_at_another_value(pair, tmp_path):
    """The sweep's and the twins' slides are fixed now (module constants): their old keys
    are read at their old values, and refused with one line otherwise."""
    line = _refused(pair, "--set", "twin_step_m=0.000001")
    assert line.startswith("error: --set twin_step_m: no longer a setting (fixed; it was 0.25)")
    assert RegistrationConfig(twin_step_m=0.25, sweep_range_m=20) == RegistrationConfig()


def test_defaults_are_unchanged_and_within_their_bounds():
    r = RegistrationConfig()
    assert (TWIN_STEP_M, TWIN_RANGE_M, SWEEP_STEP_M, SWEEP_RANGE_M) == (0.25, 15.0, 0.5, 20.0)
    assert (r.prior.plan_cell_m, r.prior.plan_hypotheses, r.max_iterations, r.max_features) == (
        0.25,
        3,
        50_000,
        8000,
    )
    assert (r.max_image_pixels, r.feature_strip_pixels, r.feature_tile_pixels) == (
        2_500_000,
        524_288,
        0,
    )
    assert (r.prior.guided_radius_m, r.prior.guided_radius_per_m) == (0.25, 0.02)
    assert SurveyConfig().refine_voxel_m == 0.02 and SurveyConfig().tolerance_mm == 10.0
