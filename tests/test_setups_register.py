"""Setup-to-setup registration from the command line: a two-setup E57 and a two-cloud PTX
(written by flexreg's own writers) from the real laser scan and a second station 0.67 m away,
turned 75°; the stored poses as ``--init`` and as a free check of the result."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import REPO, one_error_line, run_cli

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
from flexreg.stages.projection import project

LASERSCAN = REPO / "data" / "laserscan" / "laserscan-depth.png"
#: the site frame's pose of the first station (what field software stores)
T_WORLD_1 = make_transform(rotation_about_axis([0, 0, 1], 0.4), [5.0, -2.0, 1.0])
#: the true T_target_source (station 1 <- station 2)
T_TRUE = invert(
    make_transform(rotation_about_axis([0.05, 0.02, 1.0], np.radians(75.0)), [0.6, -0.3, 0.05])
)


def _stations() -> list[Scan]:
    """Both stations at a quarter of the scan's pixels (900 x 199), to keep the tests short."""
    full = read_scan(LASERSCAN)
    c = full.camera
    cam = SphericalCamera(
        width=900,
        height=199,
        phi_min=c.phi_min,
        phi_max=c.phi_max,
        theta_min=c.theta_min,
        theta_max=c.theta_max,
    )
    first = to_scan(project(Scan(points=full.points), cam))
    cam2 = SphericalCamera.from_reference(900, 199, 0.80, 2.34)
    second = to_scan(project(Scan(points=apply(invert(T_TRUE), full.points)), cam2))
    first.name, second.name = "Station 1", "Station 2"
    return [first, second]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """``project.e57`` with the true stored poses; ``clouds.ptx`` with a stored pose 1.5° and
    0.15 m off (a rough field registration)."""
    folder = tmp_path_factory.mktemp("setups-register")
    first, second = _stations()
    first.T_world_scanner = T_WORLD_1
    second.T_world_scanner = T_WORLD_1 @ T_TRUE
    write_scan(folder / "project.e57", [first, second])
    off = make_transform(rotation_about_axis([0.3, -0.2, 1.0], np.radians(1.5)), [0.1, 0.1, 0.05])
    second.T_world_scanner = T_WORLD_1 @ off @ T_TRUE
    write_scan(folder / "clouds.ptx", [first, second])
    return folder


def _errors(doc: dict) -> tuple[float, float]:
    T = np.asarray(doc["T_target_source"])
    return rotation_error_deg(T, T_TRUE), translation_error_m(T, T_TRUE)


def test_two_setup_e57_registered_setup_to_setup_and_checked_against_stored(files):
    e57 = files / "project.e57"
    out = files / "e57.json"
    rc, stdout, err = run_cli(["register", f"{e57}#0", f"{e57}#Station 2", "--out", out])
    assert rc == 0, err
    doc = json.loads(out.read_text())
    rot, trans = _errors(doc)
    assert rot < 0.3 and trans < 0.03
    check = doc["stored_pose_check"]  # the stored poses are the truth here
    assert check["rotation_deg"] == pytest.approx(rot, abs=1e-6)
    assert check["translation_m"] == pytest.approx(trans, abs=1e-6)
    np.testing.assert_allclose(check["T_target_source_stored"], T_TRUE, atol=1e-9)
    assert "vs stored poses" in stdout


def test_stored_pose_as_init_with_icp_only_on_a_two_cloud_ptx(files):
    ptx = files / "clouds.ptx"
    out = files / "ptx.json"
    argv = ["register", f"{ptx}#0", f"{ptx}#1", "--out", out, "--init", "stored", "--icp-only"]
    rc, _, err = run_cli(argv)
    assert rc == 0, err
    doc = json.loads(out.read_text())
    assert doc["prior"].startswith("init") and doc["config"]["method"] == "init"
    assert doc["init"]["from"] == "stored"
    init = np.asarray(doc["init"]["T_target_source"])
    assert rotation_error_deg(init, T_TRUE) > 1.0  # the rough stored pose ...
    rot, trans = _errors(doc)
    assert rot < 0.3 and trans < 0.03  # ... refined onto the truth
    assert "stored_pose_check" not in doc  # the stored pose was the input, not a check


def test_init_needs_a_pose_and_icp_only_needs_init(files, tmp_path):
    ptx = files / "clouds.ptx"
    rc, _, err = run_cli(
        ["register", f"{ptx}#0", f"{ptx}#1", "--out", tmp_path / "a.json", "--icp-only"]
    )
    assert rc == 1 and "--icp-only: needs --init" in one_error_line(err)
    plain = [Scan(points=s.points, name=s.name) for s in _stations()]
    write_scan(tmp_path / "plain.e57", plain)
    rc, _, err = run_cli(
        [
            "register",
            f"{tmp_path / 'plain.e57'}#0",
            f"{tmp_path / 'plain.e57'}#1",
            "--out",
            tmp_path / "b.json",
            "--init",
            "stored",
        ]
    )
    assert rc == 1 and "stores a setup pose" in one_error_line(err)
    assert not (tmp_path / "a.json").exists() and not (tmp_path / "b.json").exists()
