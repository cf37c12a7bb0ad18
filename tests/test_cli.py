"""`flexreg --version`, `info`, `project`: outputs, exit codes, one-line errors, nothing written."""

from __future__ import annotations

import json
import subprocess
import sys

import cv2
import numpy as np
import pytest
from conftest import REPO

from flexreg import __version__, read_scan
from flexreg.cli import run

LASERSCAN = REPO / "data" / "laserscan" / "laserscan-depth.png"


def test_version(capsys):
    assert run(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"flexreg {__version__}"


def test_info_json_on_real_scans(capsys, shared_data):
    assert run(["info", str(LASERSCAN), "--json"]) == 0
    (d,) = json.loads(capsys.readouterr().out)
    assert d["grid"]["rows"] == 397 and d["grid"]["cols"] == 1799
    assert d["field_of_view"]["horizontal_deg"] == pytest.approx(360.0)
    assert d["field_of_view"]["vertical_deg"] == pytest.approx(np.degrees(2.27 - 0.87))
    assert 10 < d["range_m"]["median"] < 20

    ptx = shared_data / "ptx_pdal_fixtures" / "multiple-and-transform.ptx"
    assert run(["info", str(ptx), "--json"]) == 0
    clouds = json.loads(capsys.readouterr().out)
    assert [c["points"] for c in clouds] == [4, 4]
    assert clouds[0]["pose"]["position_m"] == [600000.0, 800000.0, 400.0]
    assert clouds[0]["pose"]["rigid"] is False


def test_info_table(capsys):
    assert run(["info", str(LASERSCAN)]) == 0
    out = capsys.readouterr().out
    assert "397 rows x 1799 cols" in out and "360.00°" in out


def test_project_writes_png_npz_and_sidecar(tmp_path, capsys):
    out = tmp_path / "range.png"
    assert run(["project", str(LASERSCAN), "--out", str(out)]) == 0
    png = cv2.imread(str(out), cv2.IMREAD_UNCHANGED)
    raw = cv2.imread(str(LASERSCAN), cv2.IMREAD_UNCHANGED)
    assert png.dtype == np.uint16 and png.shape == (397, 1799)
    valid = (raw > 0) & (raw < 65535)
    np.testing.assert_array_equal(png > 0, valid)
    np.testing.assert_array_equal(png[valid], raw[valid])  # 1 mm per unit, as the source
    with np.load(tmp_path / "range.npz") as z:
        assert z["range"].dtype == np.float32
        np.testing.assert_allclose(z["range"][valid], raw[valid] / 1000.0, rtol=1e-6)
        assert float(z["png_scale_m"]) == 0.001
    back = read_scan(out)  # sidecar makes the output a readable scan again
    assert back.grid_shape == (397, 1799) and len(back) == int(valid.sum())


def test_project_unstructured_cloud(tmp_path, shared_data):
    src = shared_data / "reg_3dmatch_geotransformer_demo" / "src.npy"
    out = tmp_path / "p.png"
    assert run(["project", str(src), "--out", str(out), "--resolution-deg", "0.5"]) == 0
    img = cv2.imread(str(out), cv2.IMREAD_UNCHANGED)
    assert img.dtype == np.uint16 and (img > 0).sum() > 1000


def _write_bad_ptx(path):
    path.write_text(
        "2\n2\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n1 2 3 1\n"
    )


@pytest.mark.parametrize(
    "args_fn",
    [
        lambda d: ["info", str(d / "missing.ptx")],
        lambda d: ["info", str(d / "bad.ptx")],
        lambda d: ["project", str(d / "bad.ptx"), "--out", str(d / "out" / "r.png")],
        lambda d: ["project", str(LASERSCAN), "--out", str(d / "out" / "r.jpg")],
        lambda d: [
            "project",
            str(LASERSCAN),
            "--out",
            str(d / "out" / "r.png"),
            "--png-scale",
            "0.0001",
        ],
        lambda d: ["info", str(d / "depth.png"), "--pinhole", "500", "500", "320", "240"],
        lambda d: ["info", str(d / "sized.png")],
        lambda d: ["info", str(d / "bad.ptx"), "--pinhole", "500", "500", "320", "240"],
    ],
)
def test_bad_input_one_line_exit_1_nothing_written(tmp_path, capsys, args_fn):
    _write_bad_ptx(tmp_path / "bad.ptx")
    cv2.imwrite(str(tmp_path / "depth.png"), np.zeros((5, 7), dtype=np.uint16))  # no valid depth
    cv2.imwrite(str(tmp_path / "sized.png"), np.ones((5, 7), dtype=np.uint16))
    cam = {
        "model": "pinhole",
        "fx": 500,
        "fy": 500,
        "cx": 320,
        "cy": 240,
        "width": 640,
        "height": 480,
    }
    (tmp_path / "sized.camera.json").write_text(json.dumps({"camera": cam}))  # size mismatch
    before = sorted(tmp_path.rglob("*"))
    assert run(args_fn(tmp_path)) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err[-1]) > 10 and err[-1].startswith("error: ")
    assert sum(line.startswith("error:") for line in err) == 1
    assert sorted(tmp_path.rglob("*")) == before  # nothing written


def test_console_script_exit_status(tmp_path):
    _write_bad_ptx(tmp_path / "bad.ptx")
    exe = [sys.executable, "-c", "from flexreg.cli import main; main()"]
    r = subprocess.run([*exe, "info", str(tmp_path / "bad.ptx")], capture_output=True, text=True)
    assert r.returncode == 1
    assert r.stderr.strip().splitlines()[-1].startswith(f"error: {tmp_path / 'bad.ptx'}: ")
    assert "Traceback" not in r.stderr
    r = subprocess.run([*exe, "--version"], capture_output=True, text=True)
    assert r.returncode == 0 and __version__ in r.stdout
