"""Setups as scans: ``FILE#N`` / ``FILE#NAME`` everywhere a scan is read, :func:`list_setups`,
and the refusals (a multi-setup file without selector, the same setup on both sides)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import one_error_line, run_cli

from flexreg import Scan
from flexreg.core.transforms import make_transform, rotation_about_axis
from flexreg.errors import InputError
from flexreg.io import read_scan, read_scans, write_scan
from flexreg.io.setups import list_setups, parse_scan_ref


def _setups() -> list[Scan]:
    rng = np.random.default_rng(7)
    pose = make_transform(rotation_about_axis([0, 0, 1], 0.3), [1.0, 2.0, 3.0])
    return [
        Scan(points=rng.normal(size=(120, 3)) + 4.0, name="North"),
        Scan(points=rng.normal(size=(80, 3)) - 4.0, name="South", T_world_scanner=pose),
    ]


@pytest.fixture(scope="module", params=["e57", "ptx"])
def two_setup_file(request, tmp_path_factory):
    path = tmp_path_factory.mktemp("setups") / f"project.{request.param}"
    write_scan(path, _setups())
    return path


def test_parse_scan_ref(tmp_path):
    assert parse_scan_ref("a/p.e57#2").path.name == "p.e57"
    assert parse_scan_ref("a/p.e57#2").index == 2
    assert parse_scan_ref("p.e57#Station 7").selector == "Station 7"
    assert parse_scan_ref("p.e57#Station 7").index is None
    assert parse_scan_ref("p.e57").selector is None
    odd = tmp_path / "odd#1.ply"  # an existing file whose name holds '#' is a file
    odd.write_text("x")
    assert parse_scan_ref(odd).selector is None
    assert parse_scan_ref("scan#2.ply").selector is None  # '#' inside a file name
    with pytest.raises(InputError, match="nothing after '#'"):
        parse_scan_ref("p.e57#")


def test_list_setups_names_counts_and_poses(two_setup_file):
    setups = list_setups(two_setup_file)
    assert [s.index for s in setups] == [0, 1]
    assert [s.points for s in setups] == [120, 80]
    assert not setups[0].has_pose and setups[1].has_pose
    np.testing.assert_allclose(setups[1].T_world_scanner, _setups()[1].T_world_scanner, atol=1e-9)
    assert setups[1].ref == f"{two_setup_file}#1"
    assert setups[1].to_dict()["points"] == 80
    if two_setup_file.suffix == ".e57":
        assert [s.name for s in setups] == ["North", "South"]


def test_read_by_index_and_by_name(two_setup_file):
    second = read_scan(f"{two_setup_file}#1")
    assert len(second) == 80
    np.testing.assert_allclose(second.points, _setups()[1].points, atol=1e-5)
    assert len(read_scans(f"{two_setup_file}#0")) == 1
    if two_setup_file.suffix == ".e57":
        assert len(read_scan(f"{two_setup_file}#South")) == 80
    with pytest.raises(InputError, match=r"no setup #5: the file holds 2"):
        read_scan(f"{two_setup_file}#5")
    with pytest.raises(InputError, match=r"no setup is named 'West'.*#0.*#1"):
        read_scan(f"{two_setup_file}#West")


@pytest.mark.parametrize("command", ["project", "convert", "register"])
def test_multi_setup_file_without_selector_lists_its_setups(command, two_setup_file, tmp_path):
    out = tmp_path / ("T.json" if command == "register" else "x.png")
    args = [command, two_setup_file] + ([f"{two_setup_file}#1"] if command == "register" else [])
    kind = ["--kind", "flexion"] if command == "convert" else []
    rc, _, err = run_cli([*args, "--out", out, *kind])
    line = one_error_line(err)
    assert rc == 1 and not out.exists()
    assert "holds 2 setups" in line and f"{two_setup_file}#0" in line and "80 points" in line


def test_same_setup_as_target_and_source_is_refused(two_setup_file, tmp_path):
    rc, _, err = run_cli(
        ["register", f"{two_setup_file}#1", f"{two_setup_file}#1", "--out", tmp_path / "T.json"]
    )
    assert rc == 1 and "same scan as the target" in one_error_line(err)
    assert not (tmp_path / "T.json").exists()


def test_info_lists_every_setup_and_project_takes_one(two_setup_file, tmp_path):
    rc, out, _ = run_cli(["info", two_setup_file])
    assert rc == 0 and f"{two_setup_file}#0" in out and f"{two_setup_file}#1" in out
    rc, out, _ = run_cli(["info", f"{two_setup_file}#1", "--json"])
    assert rc == 0 and '"points": 80' in out and '"points": 120' not in out
    assert f'"setup": "{two_setup_file}#1"' in out
    rc, _, err = run_cli(["project", f"{two_setup_file}#1", "--out", tmp_path / "a.png"])
    assert rc == 0, err
    rc, _, err = run_cli(["project", two_setup_file, "--index", "1", "--out", tmp_path / "b.png"])
    assert rc == 0, err
    rc, _, err = run_cli(
        ["project", f"{two_setup_file}#1", "--index", "1", "--out", tmp_path / "c.png"]
    )
    assert rc == 1 and "give it one way" in one_error_line(err)


def test_ptx_pose_from_the_scanner_registration_lines(tmp_path):
    """Some exporters leave the 4x4 matrix at identity and store the setup's pose only in the
    position and axes lines: the pose comes from those then."""
    R = rotation_about_axis([0, 0, 1], 0.5)[:3, :3]
    head = ["2", "1", "10.0 20.0 1.5"] + [" ".join(f"{v:.17g}" for v in R[:, k]) for k in range(3)]
    head += ["1 0 0 0", "0 1 0 0", "0 0 1 0", "0 0 0 1"]
    path = tmp_path / "reg.ptx"
    path.write_text("\n".join([*head, "1 2 3 0.5", "2 3 4 0.5"]) + "\n")
    T = read_scan(path).T_world_scanner
    np.testing.assert_allclose(T[:3, :3], R, atol=1e-12)
    np.testing.assert_allclose(T[:3, 3], [10.0, 20.0, 1.5])
    (info,) = list_setups(path)
    assert info.has_pose
