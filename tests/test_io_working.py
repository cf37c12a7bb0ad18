"""Scans read for a survey worker, block by block: E57 into their points and working image
(:func:`flexreg.io.e57.read_working`), LAS/LAZ into their points
(:func:`flexreg.io.las.read_working`) -- the points of a full read, in the same order, and
the working image :func:`working_image` makes of it, whatever the block size; the same
errors as a full read."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_io_formats import E57_BAD, PUMP, _raw_e57, _small_las, _write

from flexreg import Scan, read_scan, read_scans, write_scan
from flexreg.core.camera import SphericalCamera
from flexreg.core.scan import FLOAT32_MAX_M
from flexreg.errors import InputError
from flexreg.io import e57, las, read_working_scan
from flexreg.io.scans import read_working_scans
from flexreg.stages.projection import working_image


def _station(rng: np.random.Generator, rows: int, cols: int, name: str) -> Scan:
    cam = SphericalCamera(cols, rows, -np.pi, np.pi, 0.2, 2.9)
    xyz = cam.backproject(
        *np.meshgrid(np.arange(cols), np.arange(rows)), rng.uniform(1, 40, (rows, cols))
    )
    return Scan.from_organized(xyz, rng.random((rows, cols)) > 0.3, name=name)


def _same_as_full(path: Path | str, max_pixels: int) -> None:
    full = read_scan(path, intensity=False)
    scan, image = read_working_scan(path, max_pixels=max_pixels)
    assert scan.grid_index is None and scan.intensity is None and scan.colors is None
    assert scan.points.dtype == full.points.dtype
    np.testing.assert_array_equal(scan.points, full.points)
    np.testing.assert_array_equal(scan.T_world_scanner, full.T_world_scanner)
    assert scan.name == full.name
    expected = working_image(full, max_pixels=max_pixels)
    assert image is not None and image.shape == expected.shape and image.camera is None
    np.testing.assert_array_equal(image.valid, expected.valid)
    np.testing.assert_array_equal(image.xyz, expected.xyz)
    assert (image.index == -1).all()


@pytest.mark.parametrize("block", [7, 50, 1 << 20])
@pytest.mark.parametrize("max_pixels", [10_000, 30, 8])
def test_blocks_give_the_full_read_and_its_working_image(
    tmp_path, rng, monkeypatch, block, max_pixels
):
    """Two setups, the second with a pose; each read alone by its selector."""
    monkeypatch.setattr(e57, "WORKING_BLOCK_POINTS", block)
    b = _station(rng, 7, 12, "b")
    b.T_world_scanner = np.array(
        [[0.0, -1.0, 0.0, 3.0], [1.0, 0.0, 0.0, -2.0], [0.0, 0.0, 1.0, 0.5], [0, 0, 0, 1]]
    )
    p = write_scan(tmp_path / "two.e57", [_station(rng, 9, 16, "a"), b])
    for ref in (f"{p}#0", f"{p}#1", f"{p}#b"):
        _same_as_full(ref, max_pixels)
    assert [s.name for s, _ in read_working_scans(p, max_pixels=max_pixels)] == ["a", "b"]


def test_a_real_gridded_scan(shared_data, monkeypatch):
    """The pump sample (rows upwards, columns against the azimuth) in blocks of 10,000."""
    monkeypatch.setattr(e57, "WORKING_BLOCK_POINTS", 10_000)
    _same_as_full(shared_data / PUMP, 50_000)


def test_without_index_bounds_the_indices_size_the_grid(tmp_path, monkeypatch):
    """No ``indexBounds``: the grid is the one the indices span, as a full read sizes it;
    invalid cells (state 2, NaN) are dropped, ``(0, 1, 1)`` is a point, a later point wins
    a shared cell."""
    monkeypatch.setattr(e57, "WORKING_BLOCK_POINTS", 2)
    p = _raw_e57(
        tmp_path / "grid.e57",
        {
            "cartesianX": np.array([1.0, 2.0, np.nan, 4.0, 0.0, 5.0]),
            "cartesianY": np.ones(6),
            "cartesianZ": np.ones(6),
            "cartesianInvalidState": np.array([0, 2, 0, 0, 0, 0], dtype=np.int8),
            "rowIndex": np.array([0, 0, 1, 1, 2, 2], dtype=np.uint16),
            "columnIndex": np.array([0, 1, 0, 1, 3, 3], dtype=np.uint16),
        },
    )
    scan, image = read_working_scan(p, max_pixels=100)
    np.testing.assert_array_equal(scan.points[:, 0], [1.0, 4.0, 0.0, 5.0])
    assert image is not None and image.shape == (3, 4)
    np.testing.assert_array_equal(np.argwhere(image.valid), [[0, 0], [1, 1], [2, 3]])
    np.testing.assert_array_equal(image.xyz[2, 3], [5.0, 1.0, 1.0])
    _same_as_full(p, 4)


def test_spherical_points_without_grid_have_no_image(tmp_path):
    """Spherical coordinates become the full read's cartesian points; no grid: no image."""
    el, az = np.radians([0.0, 30.0, -10.0]), np.radians([0.0, 180.0, 45.0])
    p = _raw_e57(
        tmp_path / "sph.e57",
        {
            "sphericalRange": np.array([2.0, 4.0, 5.0]),
            "sphericalAzimuth": az,
            "sphericalElevation": el,
            "sphericalInvalidState": np.array([0, 1, 0], dtype=np.int8),
        },
    )
    scan, image = read_working_scan(p, max_pixels=100)
    assert image is None
    np.testing.assert_array_equal(scan.points, read_scans(p)[0].points)
    assert len(scan) == 2


def test_far_coordinates_keep_double_precision(tmp_path, monkeypatch):
    """A coordinate beyond the float32 range (project coordinates) keeps the scan float64,
    found in a later block than the first."""
    monkeypatch.setattr(e57, "WORKING_BLOCK_POINTS", 2)
    x = np.array([1.0, 2.0, 3.0, FLOAT32_MAX_M + 12345.678901])
    p = _raw_e57(
        tmp_path / "far.e57", {"cartesianX": x, "cartesianY": np.ones(4), "cartesianZ": np.ones(4)}
    )
    scan, _ = read_working_scan(p, max_pixels=100)
    assert scan.points.dtype == np.float64
    np.testing.assert_array_equal(scan.points[:, 0], x)


@pytest.mark.parametrize("case", sorted(E57_BAD))
def test_bad_files_are_refused_naming_the_file(case, tmp_path, shared_data):
    p = E57_BAD[case](tmp_path, shared_data)
    with pytest.raises(InputError) as info:
        read_working_scan(p, max_pixels=100)
    assert str(p) in str(info.value)


@pytest.mark.parametrize("suffix", [".las", ".laz"])
@pytest.mark.parametrize("chunk", [7, 1 << 20])
def test_las_in_chunks_gives_the_full_reads_points(tmp_path, rng, monkeypatch, suffix, chunk):
    """Local coordinates become float32 as a full read makes them; project coordinates
    (beyond the float32 range) stay float64; no image (LAS has no grid)."""
    import laspy

    monkeypatch.setattr(las, "WORKING_CHUNK_POINTS", chunk)
    for offset, dtype in ((0.0, np.float32), (5_316_000.0, np.float64)):
        header = laspy.LasHeader(point_format=3, version="1.2")
        header.scales, header.offsets = np.full(3, 0.001), np.array([0.0, offset, 0.0])
        data = laspy.LasData(header)
        data.x, data.y, data.z = rng.uniform(-30, 30, (3, 50)) + np.array([[0], [offset], [0]])
        p = tmp_path / f"c{int(offset)}{suffix}"
        data.write(p)
        scan, image = read_working_scan(p, max_pixels=100)
        full = read_scan(p, intensity=False)
        assert image is None and scan.points.dtype == full.points.dtype == dtype
        np.testing.assert_array_equal(scan.points, full.points)
        assert scan.intensity is None and scan.colors is None and scan.name == full.name


@pytest.mark.parametrize("case", ["truncated_records", "truncated_midrecord", "garbage", "zero"])
def test_las_bad_files_are_refused_naming_the_file(case, tmp_path, monkeypatch):
    monkeypatch.setattr(las, "WORKING_CHUNK_POINTS", 7)
    b = _small_las(tmp_path / "ok.las")
    if case == "truncated_records":
        p = _write(tmp_path / "short.las", b[: -34 * 3])
    elif case == "truncated_midrecord":
        p = _write(tmp_path / "mid.las", b[:-50])
    elif case == "garbage":
        p = _write(tmp_path / "junk.las", b"LASF" + bytes(400))
    else:
        _small_las(tmp_path / "z.las", 0)
        p = tmp_path / "z.las"
    with pytest.raises(InputError) as info:
        read_working_scan(p, max_pixels=100)
    assert str(p) in str(info.value)
