"""Reading depth sequences: TUM RGB-D lists, 7-Scenes folders (the real data), plain depth PNG
folders, folders of scans and `flexreg synth` output; every kind of bad input is one clear
error naming the file (and line)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from flexreg import InputError, Scan, range_image, write_scan
from flexreg.io.sequence import (
    SEVEN_SCENES_INTRINSICS,
    TUM_DEFAULT_INTRINSICS,
    read_intrinsics_txt,
    read_list,
    read_sequence,
)

W, H = 40, 30


def _depth_png(path: Path, metres: float, scale: float = 5000.0) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    d = np.full((H, W), round(metres * scale), dtype=np.uint16)
    d[0, 0] = 0  # a pixel without reading
    assert cv2.imwrite(str(path), d)


def _tum(folder: Path, n: int = 4, rgb_offset: float = 0.01, gt: bool = True) -> Path:
    """A TUM RGB-D folder: depth at t = 0.1 k, colour 10 ms later, ground truth at 100 Hz."""
    lines_d = ["# depth maps", "# timestamp filename"]
    lines_c = ["# color images"]
    for k in range(n):
        t = 10.0 + 0.1 * k
        _depth_png(folder / "depth" / f"{t:.6f}.png", 1.0 + 0.1 * k)
        img = np.full((H, W, 3), 40 * k, dtype=np.uint8)
        (folder / "rgb").mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(folder / "rgb" / f"{t + rgb_offset:.6f}.png"), img)
        lines_d.append(f"{t:.6f} depth/{t:.6f}.png")
        lines_c.append(f"{t + rgb_offset:.6f} rgb/{t + rgb_offset:.6f}.png")
    (folder / "depth.txt").write_text("\n".join(lines_d) + "\n")
    (folder / "rgb.txt").write_text("\n".join(lines_c) + "\n")
    if gt:
        rows = ["# timestamp tx ty tz qx qy qz qw"]
        for k in range(int(n * 10) + 1):
            t = 10.0 + 0.01 * k
            rows.append(f"{t:.4f} {0.01 * k:.4f} 0 0 0 0 0 1")
        (folder / "groundtruth.txt").write_text("\n".join(rows) + "\n")
    return folder


# ------------------------------------------------------------------------------ TUM


def test_tum_folder(tmp_path):
    seq = read_sequence(_tum(tmp_path))
    assert seq.kind == "tum" and len(seq) == 4 and seq.has_color
    np.testing.assert_allclose(seq.timestamps, [10.0, 10.1, 10.2, 10.3])
    assert seq.frames[2].color == tmp_path / "rgb" / "10.210000.png"
    assert seq.frames[1].source == "depth.txt line 4"
    # no camera.json: the intrinsics TUM recommends, at the image size
    assert seq.intrinsics_source == "default"
    assert (seq.camera.fx, seq.camera.fy, seq.camera.cx, seq.camera.cy) == TUM_DEFAULT_INTRINSICS
    assert seq.camera.shape == (H, W)
    img = seq.range_image(1)  # 1.1 m at 5000 units per metre
    assert img.shape == (H, W) and not img.valid[0, 0]
    np.testing.assert_allclose(img.xyz[15, 20, 2], 1.1, atol=1e-9)
    grey = seq.color_image(2)
    assert grey.shape == (H, W) and grey.dtype == np.uint8 and int(grey[0, 0]) == 80
    assert len(seq.groundtruth) == 41
    assert seq.to_dict()["frames"] == 4


def test_tum_camera_json_and_options(tmp_path):
    _tum(tmp_path)
    cam = {"model": "pinhole", "fx": 50.0, "fy": 51.0, "cx": 19.5, "cy": 14.5, "width": W,
           "height": H}  # fmt: skip
    doc = {"camera": cam, "depth_scale_m_per_unit": 0.0004}
    (tmp_path / "camera.json").write_text(json.dumps(doc))
    seq = read_sequence(tmp_path)
    assert seq.camera.fy == 51.0 and seq.depth_scale == 0.0004
    assert seq.intrinsics_source == "camera.json"
    np.testing.assert_allclose(seq.range_image(0).xyz[15, 20, 2], 2.0, atol=1e-9)
    seq = read_sequence(tmp_path, intrinsics=(60.0, 60.0, 20.0, 15.0), depth_scale=1 / 5000)
    assert seq.camera.fx == 60.0 and seq.intrinsics_source == "argument"
    assert len(read_sequence(tmp_path, max_frames=2)) == 2


def test_tum_missing_frame_names_the_list_and_line(tmp_path):
    _tum(tmp_path)
    (tmp_path / "depth" / "10.200000.png").unlink()
    with pytest.raises(InputError, match=r"depth\.txt: line 5: 10\.200000\.png: no such file"):
        read_sequence(tmp_path)


def test_tum_malformed_list_lines(tmp_path):
    _tum(tmp_path)
    p = tmp_path / "depth.txt"
    text = p.read_text()
    p.write_text(text + "10.4 depth/a.png extra\n")
    with pytest.raises(InputError, match=r"depth\.txt: line 7: expected 'timestamp filename'"):
        read_sequence(tmp_path)
    p.write_text(text + "ten depth/a.png\n")
    with pytest.raises(InputError, match=r"line 7: timestamp 'ten' is not a number"):
        read_list(p)
    p.write_text(text + "10.05 depth/10.000000.png\n")
    with pytest.raises(InputError, match=r"line 7: timestamp 10\.050000 does not increase"):
        read_list(p)


def test_tum_timestamps_that_do_not_associate(tmp_path):
    _tum(tmp_path, rgb_offset=0.05)  # colour 50 ms after depth: nothing within 20 ms
    with pytest.raises(InputError, match=r"rgb\.txt: no timestamp associates with depth\.txt"):
        read_sequence(tmp_path)
    assert len(read_sequence(tmp_path, max_dt_s=0.06)) == 4
    _tum(tmp_path / "b", gt=False)
    gt = ["99.0 0 0 0 0 0 0 1", "99.1 0 0 0 0 0 0 1", "99.2 0 0 0 0 0 0 1"]
    (tmp_path / "b" / "groundtruth.txt").write_text("\n".join(gt) + "\n")
    with pytest.raises(InputError, match=r"groundtruth\.txt: ground truth associates with only 0"):
        read_sequence(tmp_path / "b")


def test_tum_malformed_ground_truth_line(tmp_path):
    _tum(tmp_path)
    p = tmp_path / "groundtruth.txt"
    lines = p.read_text().splitlines()
    lines[3] = "10.02 0 0 0 0 0 1"  # seven values
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"groundtruth\.txt: line 4: expected 8 values"):
        read_sequence(tmp_path)


def test_unreadable_depth_file_is_named(tmp_path):
    _tum(tmp_path)
    bad = tmp_path / "depth" / "10.100000.png"
    bad.write_bytes(b"this is not a PNG")
    seq = read_sequence(tmp_path)  # the list is fine; the file fails when it is read
    with pytest.raises(InputError, match=r"10\.100000\.png: not a readable PNG image"):
        seq.range_image(1)
    cv2.imwrite(str(bad), np.zeros((H + 2, W, 3), np.uint8))  # colour, wrong size
    with pytest.raises(InputError, match=r"10\.100000\.png: depth image must have one channel"):
        seq.range_image(1)


def test_synth_output_folder_is_its_rgbd_sequence(tmp_path):
    _tum(tmp_path / "rgbd")
    (tmp_path / "gt.json").write_text(json.dumps({"rgbd": {"folder": "rgbd", "frames": 4}}))
    seq = read_sequence(tmp_path)
    assert seq.kind == "tum" and seq.root == tmp_path / "rgbd"


# ------------------------------------------------------------------------------ 7-Scenes


def test_7scenes_real_data(shared_data):
    folder = shared_data / "rgbd_7scenes_redkitchen"
    seq = read_sequence(folder)
    assert seq.kind == "7scenes" and len(seq) == 60 and seq.has_color
    assert seq.intrinsics_source == "camera-intrinsics.txt"
    assert (seq.camera.fx, seq.camera.cx, seq.camera.cy) == (585.0, 320.0, 240.0)
    assert seq.depth_scale == 1e-3 and 65535 in seq.invalid_values
    np.testing.assert_allclose(seq.timestamps[:3], [0.0, 1 / 30, 2 / 30])
    img = seq.range_image(0)
    assert float(np.median(img.xyz[img.valid][:, 2])) == pytest.approx(1.88, abs=0.01)
    first = np.loadtxt(folder / "frame-000000.pose.txt")
    # translation as stored; the rotation made exactly orthonormal (KinectFusion's is to ~5e-5)
    np.testing.assert_array_equal(seq.groundtruth.poses[0][:3, 3], first[:3, 3])
    np.testing.assert_allclose(seq.groundtruth.poses[0], first, atol=1e-4)
    assert seq.color_image(0).shape == (480, 640)


def _seven(folder: Path, ids=(0, 1, 2, 3), pose=True) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for k in ids:
        _depth_png(folder / f"frame-{k:06d}.depth.png", 1.5, scale=1000.0)
        if pose:
            T = np.eye(4)
            T[0, 3] = 0.01 * k
            np.savetxt(folder / f"frame-{k:06d}.pose.txt", T)
    return folder


def test_7scenes_defaults_and_bad_input(tmp_path):
    seq = read_sequence(_seven(tmp_path / "ok"))
    assert seq.intrinsics_source == "default"
    assert (seq.camera.fx, seq.camera.fy, seq.camera.cx, seq.camera.cy) == SEVEN_SCENES_INTRINSICS
    np.testing.assert_allclose(seq.groundtruth.positions[:, 0], [0, 0.01, 0.02, 0.03])
    np.testing.assert_allclose(seq.range_image(0).xyz[10, 10, 2], 1.5)
    with pytest.raises(InputError, match=r"frame-000002\.depth\.png: missing frame"):
        read_sequence(_seven(tmp_path / "gap", ids=(0, 1, 3, 4)))
    gappy = _seven(tmp_path / "nopose")
    (gappy / "frame-000001.pose.txt").unlink()
    with pytest.raises(InputError, match=r"frame-000001\.pose\.txt: no such file"):
        read_sequence(gappy)
    bad = _seven(tmp_path / "badpose")
    (bad / "frame-000002.pose.txt").write_text("1 0 0 0\n0 1 0 0\n0 0 1 x\n0 0 0 1\n")
    with pytest.raises(InputError, match=r"frame-000002\.pose\.txt: line 3: expected 4 numbers"):
        read_sequence(bad)
    assert read_sequence(_seven(tmp_path / "noposes", pose=False)).groundtruth is None


# ------------------------------------------------------------------------------ PNGs, scans


def test_depth_folder_with_intrinsics_file(tmp_path):
    for k, t in enumerate((5.0, 5.5, 6.25)):
        _depth_png(tmp_path / f"{t:.2f}.png", 2.0 + k, scale=1000.0)
    with pytest.raises(InputError, match="no intrinsics"):
        read_sequence(tmp_path)
    (tmp_path / "intrinsics.txt").write_text("45 46 19.5 14.5\n")
    seq = read_sequence(tmp_path)
    assert seq.kind == "depth-folder" and seq.camera.fy == 46.0
    np.testing.assert_allclose(seq.timestamps, [5.0, 5.5, 6.25])  # from the file names
    np.testing.assert_allclose(seq.range_image(2).xyz[3, 3, 2], 4.0)  # millimetres by default
    K = np.array([[45.0, 0, 19.5], [0, 46.0, 14.5], [0, 0, 1]])
    np.savetxt(tmp_path / "k.txt", K)
    assert read_intrinsics_txt(tmp_path / "k.txt") == (45.0, 46.0, 19.5, 14.5)
    (tmp_path / "k.txt").write_text("1 2 3\n")
    with pytest.raises(InputError, match="expected a 3x3 K or fx fy cx cy"):
        read_intrinsics_txt(tmp_path / "k.txt")


def test_folder_of_scans(tmp_path):
    rng = np.random.default_rng(0)
    for k in range(3):
        pts = rng.normal(size=(500, 3)) + [5.0, 0, 0]
        write_scan(tmp_path / f"scan{k + 8}.npz", Scan(points=pts))
    seq = read_sequence(tmp_path, rate_hz=10.0)
    assert seq.kind == "scans" and seq.camera is None
    assert [f.depth.name for f in seq.frames] == ["scan8.npz", "scan9.npz", "scan10.npz"]
    np.testing.assert_allclose(seq.timestamps, [0.0, 0.1, 0.2])
    img = range_image(seq.frame(1))  # z-buffered through an automatic spherical camera
    assert img.n_valid > 100 and np.isfinite(img.xyz[img.valid]).all()


def test_not_a_sequence(tmp_path):
    with pytest.raises(InputError, match="no such folder"):
        read_sequence(tmp_path / "missing")
    (tmp_path / "notes.md").write_text("hello")
    with pytest.raises(InputError, match="not a sequence folder"):
        read_sequence(tmp_path)
    with pytest.raises(InputError, match="is a folder"):
        read_sequence(tmp_path / "notes.md")
    one = _seven(tmp_path / "one", ids=(0,))
    with pytest.raises(InputError, match="at least 2 frames"):
        read_sequence(one)
    src = _tum(tmp_path / "t")
    shutil.rmtree(src / "rgb")
    with pytest.raises(InputError, match=r"rgb\.txt: line 2: 10\.010000\.png: no such file"):
        read_sequence(src)
