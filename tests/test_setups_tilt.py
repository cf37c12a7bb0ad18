"""Tilted scanners: a station 15° off level is levelled and registered with the plan-view prior
required (``--upright on``; the former 10° limit refused it); beyond the limit the error says
"tilt" and gives the measured angle."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from conftest import one_error_line, run_cli
from test_setups_register import LASERSCAN, _stations

from flexreg import Scan, read_scan, write_scan
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
from flexreg.registration.config import RegistrationConfig
from flexreg.stages.priors import MAX_TILT_RAD, plan_view
from flexreg.stages.projection import fill_holes, project, working_image

TILT_DEG = 15.0


def _tilted(tilt_deg: float) -> tuple[Scan, np.ndarray]:
    """The laser scan seen from a second station turned 75° and tilted ``tilt_deg`` about a
    horizontal axis, and the true T_target_source."""
    tilt = rotation_about_axis([1.0, 0.3, 0.0], math.radians(tilt_deg))
    yaw = rotation_about_axis([0.0, 0.0, 1.0], math.radians(75.0))
    T = make_transform(yaw @ tilt, [0.6, -0.3, 0.05])
    cam = SphericalCamera.from_reference(900, 260, 0.4, 2.74)
    scan = to_scan(project(Scan(points=apply(invert(T), read_scan(LASERSCAN).points)), cam))
    return scan, T


@pytest.fixture(scope="module")
def tilted_pair(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tilt")
    second, T = _tilted(TILT_DEG)
    write_scan(folder / "pair.e57", [_stations()[0], second])
    np.savetxt(folder / "truth.txt", T)
    return folder


def test_default_limit_is_documented_and_covers_15_degrees():
    assert math.degrees(MAX_TILT_RAD) == pytest.approx(25.0)
    assert RegistrationConfig().prior.max_tilt_rad == pytest.approx(MAX_TILT_RAD)


def test_the_vertical_of_a_15_degree_tilted_scan_is_measured(tilted_pair):
    second = read_scan(f"{tilted_pair / 'pair.e57'}#1")
    lev = plan_view(fill_holes(working_image(second))).levelling
    # the scan itself stands about 2° off level: within 2° of the tilt we applied
    assert math.degrees(lev.tilt_rad) == pytest.approx(TILT_DEG, abs=2.0)


def test_15_degree_tilted_pair_registers_with_the_plan_prior_required(tilted_pair):
    e57, out = tilted_pair / "pair.e57", tilted_pair / "T.json"
    rc, _, err = run_cli(["register", f"{e57}#0", f"{e57}#1", "--out", out, "--upright", "on"])
    assert rc in (0, 3), err
    T = np.asarray(json.loads(out.read_text())["T_target_source"])
    truth = np.loadtxt(tilted_pair / "truth.txt")
    assert rotation_error_deg(T, truth) < 0.5 and translation_error_m(T, truth) < 0.05


def test_beyond_the_limit_the_error_says_tilt_and_the_angle(tilted_pair, tmp_path):
    e57 = tilted_pair / "pair.e57"
    argv = ["register", f"{e57}#0", f"{e57}#1", "--out", tmp_path / "T.json", "--upright", "on"]
    rc, _, err = run_cli([*argv, "--set", f"prior.max_tilt_rad={math.radians(10.0)}"])
    line = one_error_line(err)
    assert rc == 1 and not (tmp_path / "T.json").exists()
    assert "tilt" in line and "limit" in line
    measured = float(line.split("tilt ")[1].split("°")[0])
    assert measured == pytest.approx(TILT_DEG, abs=2.0)
