"""Scan readers and writers for E57, PLY/PCD, LAS/LAZ, KITTI .bin and 3DTK .3d.

Real facts come from ../shared/data (see each folder's README.txt); round-trips write to
tmp_path; every malformed input must raise InputError naming the file.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from flexreg.core.scan import Scan
from flexreg.core.transforms import invert, make_transform, rotation_error_deg
from flexreg.errors import FlexregError, InputError
from flexreg.io import read_scan, read_scans, write_scan
from flexreg.io.threedtk import S_RH_FROM_LH, pose_to_transform, read_pose

PUMP = "e57_pump_gridded/pumpAVisualReferenceImage.e57"
KURT = "tls_3dtk_kurt3d"
KINECT = "pcl_organized_kinect_pairwise"


def _raises_naming(path: Path, call: Callable[[], object], *, match: str | None = None) -> str:
    """Run ``call``, require an InputError whose message names ``path``; return the message."""
    with pytest.raises(InputError) as info:
        call()
    msg = str(info.value)
    assert isinstance(info.value, FlexregError)
    assert str(path) in msg, msg
    if match is not None:
        assert match in msg, msg
    return msg


# ====================================================================================== E57
def test_e57_pump_grid_and_attributes(shared_data: Path) -> None:
    scans = read_scans(shared_data / PUMP)
    assert len(scans) == 1
    s = scans[0]
    assert s.name == "pumpA"
    assert s.grid_shape == (1074, 345)
    assert len(s) == 155_201
    assert s.grid_index is not None
    # every point sits in its own cell: 155,201 valid cells of 370,530
    _, valid = s.organized()
    assert int(valid.sum()) == 155_201 and valid.size == 370_530
    assert s.points.dtype == np.float32  # scanner frame: float32 unless precise=True
    assert s.intensity is not None and s.intensity.dtype == np.float32
    assert 0.38 < s.intensity.min() and s.intensity.max() < 0.70
    assert s.colors is not None and s.colors.dtype == np.uint8 and s.colors.shape == (155_201, 3)
    np.testing.assert_array_equal(s.T_world_scanner, np.eye(4))
    rng = np.linalg.norm(s.points, axis=1)
    assert 1.98 < rng.min() < 1.99 and 5.42 < rng.max() < 5.43
    # README: rows run with elevation, columns against azimuth (kept as stored)
    elev = np.arctan2(s.points[:, 2], np.hypot(s.points[:, 0], s.points[:, 1]))
    azim = np.arctan2(s.points[:, 1], s.points[:, 0])
    assert np.corrcoef(s.grid_index[:, 0], elev)[0, 1] > 0.999
    assert np.corrcoef(s.grid_index[:, 1], azim)[0, 1] < -0.999


def test_e57_pump_rewrite_is_exact(shared_data: Path, tmp_path: Path) -> None:
    s = read_scan(shared_data / PUMP)
    out = write_scan(tmp_path / "pump.e57", s)
    b = read_scan(out)
    assert b.grid_shape == s.grid_shape and b.name == s.name
    np.testing.assert_array_equal(b.points, s.points)
    np.testing.assert_array_equal(b.grid_index, s.grid_index)
    np.testing.assert_array_equal(b.intensity, s.intensity)
    np.testing.assert_array_equal(b.colors, s.colors)


def _random_grid_scan(rng: np.random.Generator, name: str, shape: tuple[int, int], n: int) -> Scan:
    H, W = shape
    cells = rng.choice(H * W, n, replace=False)
    R = Rotation.from_rotvec(rng.normal(size=3)).as_matrix()
    return Scan(
        points=rng.normal(size=(n, 3)) * 7.0,
        intensity=rng.random(n).astype(np.float32),
        colors=rng.integers(0, 256, (n, 3)).astype(np.uint8),
        grid_shape=shape,
        grid_index=np.stack([cells // W, cells % W], axis=1),
        T_world_scanner=make_transform(R, rng.normal(size=3) * 20.0),
        name=name,
    )


def test_e57_roundtrip_two_scans_exact(tmp_path: Path, rng: np.random.Generator) -> None:
    scans = [
        _random_grid_scan(rng, "north", (40, 90), 1500),
        _random_grid_scan(rng, "south", (31, 17), 200),
    ]
    # make the last row/column empty: the grid size must still survive (indexBounds)
    scans[1].grid_index[:, 0] = np.minimum(scans[1].grid_index[:, 0], 29)
    scans[1].grid_index[:, 1] = np.minimum(scans[1].grid_index[:, 1], 15)
    p = write_scan(tmp_path / "two.e57", scans)
    back = read_scans(p, precise=True)  # float64: the file's values exactly
    assert [b.name for b in back] == ["north", "south"]
    for a, b in zip(scans, back, strict=True):
        assert b.grid_shape == a.grid_shape
        np.testing.assert_array_equal(b.points, a.points)
        np.testing.assert_array_equal(b.grid_index, a.grid_index)
        np.testing.assert_array_equal(b.intensity, a.intensity)
        np.testing.assert_array_equal(b.colors, a.colors)
        np.testing.assert_allclose(b.T_world_scanner, a.T_world_scanner, atol=1e-12, rtol=0)
        assert b.path == p
    assert read_scan(p, index=1).name == "south"


def test_e57_roundtrip_plain_scan(tmp_path: Path, rng: np.random.Generator) -> None:
    s = Scan(points=rng.normal(size=(50, 3)), name="bare")
    b = read_scan(write_scan(tmp_path / "bare.e57", s), precise=True)
    np.testing.assert_array_equal(b.points, s.points)
    assert b.grid_shape is None and b.intensity is None and b.colors is None
    np.testing.assert_allclose(b.T_world_scanner, np.eye(4), atol=1e-15)


def _raw_e57(path: Path, fields: dict[str, np.ndarray], *, name: str | None = None) -> Path:
    """E57 with one scan holding exactly ``fields`` (floats as doubles, ints as integers)."""
    import pye57
    from pye57 import libe57

    e = pye57.E57(str(path), mode="w")
    imf = e.image_file
    node = libe57.StructureNode(imf)
    node.set("guid", libe57.StringNode(imf, "{00000000-0000-0000-0000-000000000001}"))
    if name is not None:
        node.set("name", libe57.StringNode(imf, name))
    proto = libe57.StructureNode(imf)
    for key, arr in fields.items():
        if arr.dtype.kind == "f":
            proto.set(key, libe57.FloatNode(imf, 0.0, libe57.E57_DOUBLE))
        else:
            proto.set(key, libe57.IntegerNode(imf, 0, 0, 65535))
    points = libe57.CompressedVectorNode(imf, proto, libe57.VectorNode(imf, True))
    node.set("points", points)
    e.data3d.append(node)
    n = len(next(iter(fields.values())))
    buffers = libe57.VectorSourceDestBuffer()
    for key, arr in fields.items():
        buffers.append(libe57.SourceDestBuffer(imf, key, np.ascontiguousarray(arr), n, True, True))
    writer = points.writer(buffers)
    if n:
        writer.write(n)
    writer.close()
    e.close()
    return path


def test_e57_spherical_and_invalid_states(tmp_path: Path) -> None:
    rng_m = np.array([2.0, 3.0, 4.0, 5.0])
    az = np.radians([0.0, 90.0, 180.0, 45.0])
    el = np.radians([0.0, 0.0, 30.0, -10.0])
    state = np.array([0, 0, 1, 0], dtype=np.int8)  # 1: direction only -> not a point
    p = _raw_e57(
        tmp_path / "sph.e57",
        {
            "sphericalRange": rng_m,
            "sphericalAzimuth": az,
            "sphericalElevation": el,
            "sphericalInvalidState": state,
        },
        name="sph",
    )
    s = read_scan(p)
    assert s.name == "sph" and len(s) == 3 and s.grid_shape is None
    expected = np.array(
        [
            [2.0, 0.0, 0.0],
            [0.0, 3.0, 0.0],
            [
                5 * np.cos(el[3]) * np.cos(az[3]),
                5 * np.cos(el[3]) * np.sin(az[3]),
                5 * np.sin(el[3]),
            ],
        ]
    )
    np.testing.assert_allclose(s.points, expected, atol=1e-12)


def test_e57_invalid_cells_of_a_grid_are_dropped(tmp_path: Path) -> None:
    x = np.array([1.0, 2.0, np.nan, 4.0, 0.0])
    p = _raw_e57(
        tmp_path / "grid.e57",
        {
            "cartesianX": x,
            "cartesianY": np.ones(5),
            "cartesianZ": np.ones(5),
            "cartesianInvalidState": np.array([0, 2, 0, 0, 0], dtype=np.int8),
            "rowIndex": np.array([0, 0, 1, 1, 2], dtype=np.uint16),
            "columnIndex": np.array([0, 1, 0, 1, 3], dtype=np.uint16),
        },
    )
    s = read_scan(p)
    # state 2 dropped, NaN cell dropped; (0, 1, 1) is a real point (not the origin)
    assert len(s) == 3 and s.grid_shape == (3, 4)
    np.testing.assert_array_equal(s.grid_index, [[0, 0], [1, 1], [2, 3]])
    np.testing.assert_array_equal(s.points[:, 0], [1.0, 4.0, 0.0])


E57_BAD: dict[str, Callable[[Path, Path], Path]] = {}


def _e57_case(fn: Callable[[Path, Path], Path]) -> Callable[[Path, Path], Path]:
    E57_BAD[fn.__name__.removeprefix("_bad_e57_")] = fn
    return fn


@_e57_case
def _bad_e57_truncated(tmp: Path, data: Path) -> Path:
    b = (data / PUMP).read_bytes()
    (tmp / "trunc.e57").write_bytes(b[: len(b) // 2])
    return tmp / "trunc.e57"


@_e57_case
def _bad_e57_garbage(tmp: Path, data: Path) -> Path:
    (tmp / "garbage.e57").write_bytes(b"ASTM-E57" + bytes(range(256)) * 20)
    return tmp / "garbage.e57"


@_e57_case
def _bad_e57_corrupt_page(tmp: Path, data: Path) -> Path:
    b = bytearray((data / PUMP).read_bytes())
    b[len(b) // 3 : len(b) // 3 + 4096] = bytes(4096)
    (tmp / "corrupt.e57").write_bytes(bytes(b))
    return tmp / "corrupt.e57"


@_e57_case
def _bad_e57_no_scans(tmp: Path, data: Path) -> Path:
    import pye57

    pye57.E57(str(tmp / "noscans.e57"), mode="w").close()
    return tmp / "noscans.e57"


@_e57_case
def _bad_e57_zero_points(tmp: Path, data: Path) -> Path:
    return _raw_e57(
        tmp / "zero.e57", {k: np.zeros(0) for k in ("cartesianX", "cartesianY", "cartesianZ")}
    )


@_e57_case
def _bad_e57_all_invalid(tmp: Path, data: Path) -> Path:
    f = {k: np.ones(4) for k in ("cartesianX", "cartesianY", "cartesianZ")}
    f["cartesianInvalidState"] = np.full(4, 2, dtype=np.int8)
    return _raw_e57(tmp / "invalid.e57", f)


@_e57_case
def _bad_e57_nan_unorganised(tmp: Path, data: Path) -> Path:
    f = {k: np.ones(4) for k in ("cartesianX", "cartesianY", "cartesianZ")}
    f["cartesianY"][2] = np.inf
    return _raw_e57(tmp / "nan.e57", f)


@_e57_case
def _bad_e57_no_coordinates(tmp: Path, data: Path) -> Path:
    return _raw_e57(tmp / "nocoords.e57", {"intensity": np.ones(3)})


@pytest.mark.parametrize("case", sorted(E57_BAD))
def test_e57_bad_input(case: str, tmp_path: Path, shared_data: Path) -> None:
    p = E57_BAD[case](tmp_path, shared_data)
    _raises_naming(p, lambda: read_scans(p))


def test_e57_write_refuses_empty(tmp_path: Path) -> None:
    p = tmp_path / "empty.e57"
    _raises_naming(p, lambda: write_scan(p, Scan(points=np.zeros((0, 3)))), match="no points")
    assert not p.exists() and not list(tmp_path.iterdir())


# ================================================================================ PLY / PCD
KINECT_VALID = {1: 249_647, 2: 249_931, 3: 248_494, 4: 244_573, 5: 244_977}


@pytest.mark.parametrize("k", sorted(KINECT_VALID))
def test_pcd_organised_kinect(shared_data: Path, k: int) -> None:
    s = read_scan(shared_data / KINECT / f"capture000{k}.pcd")
    assert s.grid_shape == (480, 640)  # 640 x 480 (W x H) organised cloud, rows = image v
    assert len(s) == KINECT_VALID[k]
    assert 0.17 < 1 - len(s) / 307_200 < 0.21  # ~19 % NaN (no depth)
    # VIEWPOINT 0 0 0 0 1 0 0: quaternion w=0 x=1 -> 180 deg about x
    np.testing.assert_allclose(s.T_world_scanner, np.diag([1.0, -1.0, -1.0, 1.0]), atol=1e-15)
    if k == 1:  # pinhole grid: x/z grows with the column, y/z with the row
        assert s.grid_index is not None
        u, v = s.grid_index[:, 1], s.grid_index[:, 0]
        x, y, z = s.points.T
        assert np.corrcoef(u, x / z)[0, 1] > 0.99 and np.corrcoef(v, y / z)[0, 1] > 0.99


@pytest.mark.parametrize(
    ("name", "records", "points", "has_intensity", "max_range_m"),
    [
        ("pcl_room_scans/room_scan1.pcd", 112_586, 112_586, False, 15.61),
        ("pcl_room_scans/room_scan2.pcd", 112_624, 112_624, False, 15.79),
        # fast_gicp scans keep no-returns as (0, 0, 0): 5,032 and 5,107 of them
        ("lidar_pair_fast_gicp/251370668.pcd", 69_088, 64_056, True, 77.57),
        ("lidar_pair_fast_gicp/251371071.pcd", 69_792, 64_685, True, 52.56),
        ("camlidar_pjlab/scene_a_calib.pcd", 85_546, 85_546, True, 129.92),
    ],
)
def test_pcd_unorganised(
    shared_data: Path,
    name: str,
    records: int,
    points: int,
    has_intensity: bool,
    max_range_m: float,
) -> None:
    s = read_scan(shared_data / name)
    assert s.grid_shape is None
    assert len(s) == points
    assert (s.intensity is not None) == has_intensity
    header = (shared_data / name).read_bytes()[:400].decode("latin-1")
    assert f"POINTS {records}" in header
    assert not np.any(np.all(s.points == 0, axis=1))
    assert np.linalg.norm(s.points, axis=1).max() == pytest.approx(max_range_m, abs=0.01)
    if name.endswith("room_scan1.pcd"):  # README: extent ~29 m x 15 m x 3 m
        np.testing.assert_allclose(np.ptp(s.points, axis=0), [29, 15, 3], atol=0.6)


def test_pcd_format_override_on_odd_suffix(shared_data: Path, tmp_path: Path) -> None:
    p = tmp_path / "scan.dat"
    shutil.copy(shared_data / "lidar_pair_fast_gicp/251370668.pcd", p)
    assert len(read_scan(p, format="pcd")) == 64_056


def test_pcd_ascii_organised_with_holes(tmp_path: Path) -> None:
    rows = ["1 0 2 5", "nan nan nan 0", "1 1 2 7", "0 0 0 0", "2 1 2 9", "2 2 2 10"]
    p = tmp_path / "org.pcd"
    p.write_text(
        "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\n"
        "COUNT 1 1 1 1\nWIDTH 3\nHEIGHT 2\nVIEWPOINT 1 2 3 1 0 0 0\nPOINTS 6\nDATA ascii\n"
        + "\n".join(rows)
        + "\n"
    )
    s = read_scan(p)
    assert s.grid_shape == (2, 3) and len(s) == 4  # a NaN cell and an all-zero cell
    np.testing.assert_array_equal(s.grid_index, [[0, 0], [0, 2], [1, 1], [1, 2]])
    np.testing.assert_array_equal(s.intensity, [5, 7, 9, 10])
    np.testing.assert_array_equal(s.T_world_scanner[:3, 3], [1, 2, 3])


def test_ply_roundtrip_with_intensity(tmp_path: Path, rng: np.random.Generator) -> None:
    s = Scan(
        points=rng.normal(size=(500, 3)) * 30.0,
        intensity=rng.random(500).astype(np.float32) * 4000,
        colors=rng.integers(0, 256, (500, 3)).astype(np.uint8),
        T_world_scanner=make_transform(np.eye(3), [5.0, 0.0, 0.0]),
        name="s",
    )
    b = read_scan(write_scan(tmp_path / "s.ply", s), precise=True)
    np.testing.assert_array_equal(b.points, s.points)
    np.testing.assert_array_equal(b.intensity, s.intensity)
    np.testing.assert_array_equal(b.colors, s.colors)
    np.testing.assert_array_equal(b.T_world_scanner, np.eye(4))  # PLY has no pose
    w = read_scan(write_scan(tmp_path / "w.ply", s, world=True))
    np.testing.assert_allclose(w.points, s.points_world(), atol=1e-12)
    a = read_scan(write_scan(tmp_path / "a.ply", s, ascii=True))
    np.testing.assert_allclose(a.points, s.points, rtol=1e-5)


def test_ply_write_refuses_several_scans(tmp_path: Path, rng: np.random.Generator) -> None:
    s = Scan(points=rng.normal(size=(5, 3)))
    p = tmp_path / "two.ply"
    _raises_naming(p, lambda: write_scan(p, [s, s]), match="one scan")
    assert not list(tmp_path.iterdir())


def _ply_bytes(rows: np.ndarray, *, ascii: bool = False, count: int | None = None) -> bytes:
    n = len(rows) if count is None else count
    fmt = "ascii" if ascii else "binary_little_endian"
    props = "".join(f"property float {c}\n" for c in "xyz")
    head = f"ply\nformat {fmt} 1.0\nelement vertex {n}\n{props}end_header\n"
    if ascii:
        body = "".join(" ".join(f"{v:g}" for v in r) + "\n" for r in rows).encode()
    else:
        body = np.asarray(rows, dtype="<f4").tobytes()
    return head.encode() + body


PC_BAD: dict[str, Callable[[Path, Path], Path]] = {}


def _pc_case(fn: Callable[[Path, Path], Path]) -> Callable[[Path, Path], Path]:
    PC_BAD[fn.__name__.removeprefix("_bad_pc_")] = fn
    return fn


def _write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


_PTS = np.arange(30, dtype=np.float64).reshape(10, 3) + 1.0


@_pc_case
def _bad_pc_ply_nan(tmp: Path, data: Path) -> Path:
    rows = _PTS.copy()
    rows[4, 1] = np.nan
    return _write(tmp / "nan.ply", _ply_bytes(rows))


@_pc_case
def _bad_pc_ply_inf_ascii(tmp: Path, data: Path) -> Path:
    rows = _PTS.copy()
    rows[0, 2] = np.inf
    return _write(tmp / "inf.ply", _ply_bytes(rows, ascii=True))


@_pc_case
def _bad_pc_ply_truncated_binary(tmp: Path, data: Path) -> Path:
    return _write(tmp / "trunc.ply", _ply_bytes(_PTS)[:-20])


@_pc_case
def _bad_pc_ply_count_mismatch(tmp: Path, data: Path) -> Path:
    return _write(tmp / "count.ply", _ply_bytes(_PTS, ascii=True, count=12))


@_pc_case
def _bad_pc_ply_short_row(tmp: Path, data: Path) -> Path:
    return _write(tmp / "short.ply", _ply_bytes(_PTS, ascii=True)[:-3] + b"\n")


@_pc_case
def _bad_pc_ply_not_numeric(tmp: Path, data: Path) -> Path:
    b = _ply_bytes(_PTS, ascii=True).replace(b"\n7 8 9\n", b"\n7 eight 9\n")
    return _write(tmp / "text.ply", b)


@_pc_case
def _bad_pc_ply_zero_vertices(tmp: Path, data: Path) -> Path:
    return _write(tmp / "zero.ply", _ply_bytes(_PTS[:0]))


@_pc_case
def _bad_pc_ply_no_xyz(tmp: Path, data: Path) -> Path:
    b = _ply_bytes(_PTS).replace(b"property float z", b"property float w")
    return _write(tmp / "noz.ply", b)


@_pc_case
def _bad_pc_ply_bad_header(tmp: Path, data: Path) -> Path:
    b = _ply_bytes(_PTS).replace(b"element vertex 10", b"element vertex ten")
    return _write(tmp / "header.ply", b)


@_pc_case
def _bad_pc_not_a_cloud(tmp: Path, data: Path) -> Path:
    return _write(tmp / "words.ply", b"hello\nthis is not a point cloud\n")


@_pc_case
def _bad_pc_pcd_truncated_binary(tmp: Path, data: Path) -> Path:
    b = (data / "lidar_pair_fast_gicp/251370668.pcd").read_bytes()
    return _write(tmp / "trunc.pcd", b[: len(b) - 1000])


@_pc_case
def _bad_pc_pcd_truncated_compressed(tmp: Path, data: Path) -> Path:
    b = (data / KINECT / "capture0001.pcd").read_bytes()
    return _write(tmp / "trunc_c.pcd", b[: len(b) // 2])


@_pc_case
def _bad_pc_pcd_points_mismatch(tmp: Path, data: Path) -> Path:
    b = (data / "pcl_room_scans/room_scan1.pcd").read_bytes()
    return _write(tmp / "points.pcd", b.replace(b"POINTS 112586", b"POINTS 112587", 1))


_PCD_XYZ3 = (
    "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
    "WIDTH 3\nHEIGHT 1\nPOINTS 3\nDATA ascii\n"
)


@_pc_case
def _bad_pc_pcd_nan_unorganised(tmp: Path, data: Path) -> Path:
    head = _PCD_XYZ3
    return _write(tmp / "nan.pcd", (head + "1 2 3\nnan nan nan\n4 5 6\n").encode())


@_pc_case
def _bad_pc_pcd_ascii_truncated(tmp: Path, data: Path) -> Path:
    head = _PCD_XYZ3
    return _write(tmp / "short.pcd", (head + "1 2 3\n4 5 6\n7 8").encode())


@pytest.mark.parametrize("case", sorted(PC_BAD))
def test_ply_pcd_bad_input(case: str, tmp_path: Path, shared_data: Path) -> None:
    p = PC_BAD[case](tmp_path, shared_data)
    _raises_naming(p, lambda: read_scans(p))


# ================================================================================= LAS / LAZ
@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_las_laz_roundtrip(tmp_path: Path, rng: np.random.Generator, suffix: str) -> None:
    import laspy

    n = 1000
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.array([412_000.0, 5_316_000.0, 250.0])  # UTM-like coordinates
    las = laspy.LasData(header)
    las.x = 412_000.0 + rng.random(n) * 100
    las.y = 5_316_000.0 + rng.random(n) * 100
    las.z = 250.0 + rng.random(n) * 10
    las.intensity = rng.integers(0, 65536, n).astype(np.uint16)
    rgb16 = rng.integers(0, 65536, (n, 3)).astype(np.uint16)
    las.red, las.green, las.blue = rgb16.T
    p = tmp_path / f"cloud{suffix}"
    las.write(p)

    ref = laspy.read(p)
    s = read_scan(p)
    assert len(s) == n and s.grid_shape is None and s.name == "cloud"
    np.testing.assert_array_equal(s.points, np.stack([ref.x, ref.y, ref.z], axis=1))
    np.testing.assert_allclose(s.points[:, 0], np.asarray(las.x), atol=5e-4)
    np.testing.assert_array_equal(s.intensity, np.asarray(las.intensity, dtype=np.float32))
    np.testing.assert_array_equal(s.colors, (rgb16 >> 8).astype(np.uint8))


def test_las_eight_bit_colours_kept(tmp_path: Path, rng: np.random.Generator) -> None:
    import laspy

    las = laspy.LasData(laspy.LasHeader(point_format=2, version="1.2"))
    las.x, las.y, las.z = rng.random((3, 20))
    rgb8 = rng.integers(0, 256, (20, 3)).astype(np.uint16)
    las.red, las.green, las.blue = rgb8.T
    las.write(tmp_path / "c8.las")
    np.testing.assert_array_equal(read_scan(tmp_path / "c8.las").colors, rgb8.astype(np.uint8))


def _small_las(path: Path, n: int = 30) -> bytes:
    import laspy

    las = laspy.LasData(laspy.LasHeader(point_format=3, version="1.2"))
    las.x, las.y, las.z = np.arange(3 * n, dtype=np.float64).reshape(3, n)
    las.write(path)
    return path.read_bytes()


@pytest.mark.parametrize(
    "case", ["truncated_records", "truncated_midrecord", "garbage", "laz_truncated", "zero_points"]
)
def test_las_bad_input(case: str, tmp_path: Path) -> None:
    b = _small_las(tmp_path / "ok.las")
    if case == "truncated_records":  # whole records missing: laspy alone returns fewer points
        p = _write(tmp_path / "short.las", b[: -34 * 3])
    elif case == "truncated_midrecord":
        p = _write(tmp_path / "mid.las", b[:-50])
    elif case == "garbage":
        p = _write(tmp_path / "junk.las", b"LASF" + bytes(400))
    elif case == "laz_truncated":
        _small_las(tmp_path / "ok.laz", 3000)
        laz = (tmp_path / "ok.laz").read_bytes()
        p = _write(tmp_path / "short.laz", laz[: len(laz) // 2])
    else:
        _small_las(tmp_path / "z.las", 0)
        p = tmp_path / "z.las"
    _raises_naming(p, lambda: read_scans(p))


# ===================================================================================== KITTI
def test_kitti_velodyne(shared_data: Path) -> None:
    p = shared_data / "camlidar_kitti_object/velodyne_000000.bin"
    s = read_scan(p)
    assert p.stat().st_size == 1_846_144 and len(s) == 1_846_144 // 16 == 115_384
    raw = np.fromfile(p, dtype="<f4").reshape(-1, 4)
    np.testing.assert_array_equal(s.points, raw[:, :3].astype(np.float64))
    np.testing.assert_array_equal(s.intensity, raw[:, 3])
    assert 0.0 <= s.intensity.min() and s.intensity.max() <= 1.0
    assert s.grid_shape is None and s.name == "velodyne_000000"


@pytest.mark.parametrize("case", ["size", "nan", "zeros"])
def test_kitti_bad_input(case: str, tmp_path: Path) -> None:
    rec = np.ones((8, 4), dtype="<f4")
    if case == "size":
        p = _write(tmp_path / "odd.bin", rec.tobytes()[:-6])
        msg = _raises_naming(p, lambda: read_scans(p), match="122")
        assert "multiple of 16" in msg
        return
    if case == "nan":
        rec[3, 0] = np.nan
    else:
        rec[:, :3] = 0
    p = _write(tmp_path / f"{case}.bin", rec.tobytes())
    _raises_naming(p, lambda: read_scans(p))


# ====================================================================================== 3DTK
@pytest.fixture(scope="module")
def kurt(request: pytest.FixtureRequest) -> list[Scan]:
    data: Path = request.getfixturevalue("shared_data")
    return [read_scan(data / KURT / f"scan00{i}.3d") for i in range(3)]


KURT_VALID = [79_955, 80_126, 79_743]


def test_3dtk_grid_and_valid_cells(kurt: list[Scan], shared_data: Path) -> None:
    for i, s in enumerate(kurt):
        assert s.grid_shape == (226, 360)
        assert s.name == f"scan00{i}"
        raw = np.loadtxt(shared_data / KURT / f"scan00{i}.3d")
        assert raw.shape == (81_360, 3)
        no_return = np.linalg.norm(raw, axis=1) >= 3276.0  # SICK max range, cm
        assert len(s) == KURT_VALID[i] == 81_360 - int(no_return.sum())
        # the points are the file's points, in metres, right-handed (X=z, Y=-x, Z=y)
        expected = (raw[~no_return] @ S_RH_FROM_LH.T) / 100.0
        got = s.points[np.lexsort(s.points.T)]
        np.testing.assert_allclose(got, expected[np.lexsort(expected.T)], atol=1e-12)


def test_3dtk_grid_is_upright_with_azimuth_along_columns(kurt: list[Scan]) -> None:
    for s in kurt:
        xyz, _ = s.organized()
        with np.errstate(invalid="ignore"):
            elev = np.degrees(np.arctan2(xyz[..., 2], np.hypot(xyz[..., 0], xyz[..., 1])))
            phi = np.degrees(np.arctan2(xyz[..., 1], xyz[..., 0]))
        row_elev = np.nanmedian(elev, axis=1)
        assert row_elev[0] > 35 and row_elev[-1] < -25  # top row looks up, bottom row down
        assert np.corrcoef(np.arange(226), row_elev)[0, 1] < -0.99
        assert abs(np.nanmedian(phi[:, 0]) + 90) < 1 and abs(np.nanmedian(phi[:, -1]) - 89.5) < 1
        assert np.nanmedian(np.diff(phi, axis=1)) == pytest.approx(0.5, abs=0.05)  # 0.5 deg steps


def test_3dtk_relative_poses(kurt: list[Scan]) -> None:
    np.testing.assert_allclose(kurt[0].T_world_scanner, np.eye(4), atol=1e-15)
    for s, dist in ((kurt[1], 1.571), (kurt[2], 3.384)):
        rel = invert(kurt[0].T_world_scanner) @ s.T_world_scanner
        t = rel[:3, 3]
        assert np.linalg.norm(t) == pytest.approx(dist, abs=0.002)
        assert t[0] > 0.99 * np.linalg.norm(t)  # straight ahead (+X, 3DTK's z)
        assert rotation_error_deg(rel, np.eye(4)) < 2.0


def test_3dtk_pose_matches_euler_to_matrix4(shared_data: Path) -> None:
    pos, ang = [-7.99848, -15.3529, 337.973], [1.11333, -0.470508, -0.479231]
    T = read_pose(shared_data / KURT / "scan002.pose")
    np.testing.assert_allclose(T, pose_to_transform(pos, ang), atol=1e-15)
    # 3DTK: R = Rx Ry Rz (intrinsic XYZ), alignxf[8] = sin(ry) is row 0, column 2
    R_lh = Rotation.from_euler("XYZ", ang, degrees=True).as_matrix()
    assert R_lh[0, 2] == pytest.approx(np.sin(np.radians(ang[1])), abs=1e-15)
    np.testing.assert_allclose(T[:3, :3], S_RH_FROM_LH @ R_lh @ S_RH_FROM_LH.T, atol=1e-15)
    np.testing.assert_allclose(T[:3, 3], [3.37973, 0.0799848, -0.153529], atol=1e-12)
    # a point transformed in 3DTK's frame lands where flexreg's frame puts it
    p_lh = np.array([120.0, -35.0, 410.0])
    world_lh = R_lh @ p_lh + np.asarray(pos)
    np.testing.assert_allclose(
        T[:3, :3] @ (S_RH_FROM_LH @ p_lh / 100) + T[:3, 3],
        S_RH_FROM_LH @ world_lh / 100,
        atol=1e-12,
    )


def _nn_stats(target: Scan, source: Scan, T_world_source: np.ndarray) -> tuple[float, float]:
    d, _ = cKDTree(target.points_world()).query(
        source.points @ T_world_source[:3, :3].T + T_world_source[:3, 3]
    )
    return float(np.median(d)), float(np.mean(d < 0.05))


def test_3dtk_poses_bring_consecutive_scans_together(shared_data: Path) -> None:
    # drop the robot's own body (< 48 cm, as the data's config.ini does): it never moves
    # relative to the scanner and would favour "no motion"
    s = [read_scan(shared_data / KURT / f"scan00{i}.3d", min_range_m=0.48) for i in range(3)]
    for a, b in ((0, 1), (1, 2)):
        med, frac = _nn_stats(s[a], s[b], s[b].T_world_scanner)
        med0, frac0 = _nn_stats(s[a], s[b], s[a].T_world_scanner)  # pretend no motion
        # measured: medians 3.1 / 3.2 cm; 73 % / 71 % within 5 cm (47 % / 53 % without motion)
        assert med < 0.05, (a, b, med)
        assert frac > 0.65 and frac > frac0 + 0.1, (a, b, frac, frac0)
        assert med < med0


def test_3dtk_min_range_and_grid_options(kurt: list[Scan], shared_data: Path) -> None:
    p = shared_data / KURT / "scan000.3d"
    raw = np.loadtxt(p)
    r = np.linalg.norm(raw, axis=1)
    near = read_scan(p, min_range_m=0.48)
    assert len(near) == int(np.sum((r >= 48) & (r < 3276))) == len(kurt[0]) - int(np.sum(r < 48))
    flat = read_scan(p, grid=False)
    assert flat.grid_shape is None and len(flat) == len(kurt[0])
    explicit = read_scan(p, grid=(226, 360))
    np.testing.assert_array_equal(explicit.grid_index, kurt[0].grid_index)


def test_3dtk_pose_options(shared_data: Path, tmp_path: Path, kurt: list[Scan]) -> None:
    src = shared_data / KURT / "scan001.3d"
    assert np.array_equal(read_scan(src, pose=False).T_world_scanner, np.eye(4))
    T = make_transform(Rotation.from_rotvec([0, 0, 0.3]).as_matrix(), [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(read_scan(src, pose=T).T_world_scanner, T)
    other = read_scan(src, pose=shared_data / KURT / "scan002.pose")
    np.testing.assert_allclose(other.T_world_scanner, kurt[2].T_world_scanner, atol=1e-15)
    lone = tmp_path / "scan001.3d"
    shutil.copy(src, lone)  # no .pose beside it -> identity
    s = read_scan(lone)
    assert np.array_equal(s.T_world_scanner, np.eye(4)) and s.grid_shape == (226, 360)


def _kurt_lines(shared_data: Path) -> list[str]:
    return (shared_data / KURT / "scan000.3d").read_text().splitlines()


@pytest.mark.parametrize(
    "case",
    [
        "two_values",
        "not_numeric",
        "line_missing",
        "explicit_grid",
        "pose_short",
        "pose_missing",
        "nan",
        "no_returns",
    ],
)
def test_3dtk_bad_input(case: str, shared_data: Path, tmp_path: Path) -> None:
    lines = _kurt_lines(shared_data)
    p = tmp_path / "scan000.3d"
    options: dict[str, object] = {}
    named = p
    if case == "two_values":
        lines[500] = "12.5 3.25"
        match = "line 501"
    elif case == "not_numeric":
        lines[700] = "12.5 abc 3.0"
        match = "line 701"
    elif case == "line_missing":  # one profile comes out one point short
        del lines[1000]
        match = "unequal lengths"
    elif case == "explicit_grid":
        del lines[-1]
        options["grid"] = (226, 360)
        match = "226 x 360"
    elif case == "pose_short":
        named = tmp_path / "scan000.pose"
        named.write_text("1 2 3\n4 5\n")
        match = "six"
    elif case == "pose_missing":
        named = tmp_path / "nowhere.pose"
        options["pose"] = named
        match = "no such pose file"
    elif case == "nan":
        lines[10] = "nan 1 2"
        match = "NaN"
    else:
        lines = ["3276.7 0 0"] * 360
        match = "none of the 360 points"
    p.write_text("\n".join(lines) + "\n")
    _raises_naming(named, lambda: read_scans(p, **options), match=match)


def test_3dtk_uos_header_line_is_skipped(
    shared_data: Path, tmp_path: Path, kurt: list[Scan]
) -> None:
    p = tmp_path / "scan000.3d"
    p.write_text("360 x 226\n" + (shared_data / KURT / "scan000.3d").read_text())
    s = read_scan(p)
    assert s.grid_shape == (226, 360)
    np.testing.assert_array_equal(s.points, kurt[0].points)


# ==================================================================================== options
@pytest.mark.parametrize("suffix", [".e57", ".ply", ".las", ".bin"])
def test_unknown_option_is_an_input_error(
    suffix: str, tmp_path: Path, rng: np.random.Generator
) -> None:
    s = Scan(points=rng.normal(size=(20, 3)))
    p = tmp_path / f"x{suffix}"
    if suffix in (".e57", ".ply"):
        write_scan(p, s)
    elif suffix == ".las":
        _small_las(p)
    else:
        p.write_bytes(np.ones((4, 4), dtype="<f4").tobytes())
    _raises_naming(p, lambda: read_scans(p, colour_space="srgb"), match="colour_space")


def test_e57_same_scans_give_identical_bytes(tmp_path):
    rng = np.random.default_rng(3)
    scans = [Scan(points=rng.random((50, 3)), name=f"s{i}") for i in range(2)]
    write_scan(tmp_path / "a.e57", scans)
    write_scan(tmp_path / "b.e57", scans)
    assert (tmp_path / "a.e57").read_bytes() == (tmp_path / "b.e57").read_bytes()
    scans[1].points[0, 0] += 1.0  # different content -> different file GUIDs
    write_scan(tmp_path / "c.e57", scans)
    assert (tmp_path / "c.e57").read_bytes() != (tmp_path / "a.e57").read_bytes()


def test_readers_keep_float64_for_project_coordinates(tmp_path):
    """A PLY cloud within 8192 m of its origin is read as float32 (within float32's rounding),
    one in map coordinates (a UTM northing) stays float64: float32 would round it to 0.5 m."""
    near = np.array([[1.25, -3.5, 0.123456789], [100.0, 20.0, -3.0], [5.0, 6.0, 7.0]])
    far = near + [512_345.678901, 5_412_345.678901, 0.0]
    write_scan(tmp_path / "near.ply", Scan(points=near))
    write_scan(tmp_path / "far.ply", Scan(points=far))
    a, b = read_scan(tmp_path / "near.ply"), read_scan(tmp_path / "far.ply")
    assert a.points.dtype == np.float32 and b.points.dtype == np.float64
    np.testing.assert_array_equal(a.points, near.astype(np.float32))
    np.testing.assert_array_equal(b.points, far)
    assert read_scan(tmp_path / "near.ply", precise=True).points.dtype == np.float64
