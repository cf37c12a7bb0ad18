"""The PTX reader parses a file chunk by chunk: any chunk size gives the same scans and the same
error messages (line numbers included) as one chunk holding the whole file."""

from __future__ import annotations

import numpy as np
import pytest

from flexreg import Scan, read_scans, write_scan
from flexreg.core.camera import SphericalCamera
from flexreg.errors import InputError
from flexreg.io import ptx


def _scan(rng, rows: int, cols: int, *, colors: bool) -> Scan:
    cam = SphericalCamera(cols, rows, -0.5, 0.5, 1.2, 1.9)
    xyz = cam.backproject(
        *np.meshgrid(np.arange(cols), np.arange(rows)), rng.uniform(1, 40, (rows, cols))
    )
    return Scan.from_organized(
        np.round(xyz, 6),
        rng.random((rows, cols)) > 0.3,
        intensity=np.round(rng.random((rows, cols)), 6),
        colors=rng.integers(0, 256, (rows, cols, 3)).astype(np.uint8) if colors else None,
        name="s",
    )


def _same(a: Scan, b: Scan) -> None:
    assert a.grid_shape == b.grid_shape and a.name == b.name
    for x, y in [
        (a.points, b.points),
        (a.intensity, b.intensity),
        (a.colors, b.colors),
        (a.grid_index, b.grid_index),
        (a.T_world_scanner, b.T_world_scanner),
    ]:
        assert (x is None) == (y is None)
        if x is not None:
            assert x.dtype == y.dtype
            np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("chunk", [7, 64, 1000])
def test_chunked_reading_equals_whole_file(tmp_path, rng, monkeypatch, chunk):
    p = tmp_path / "multi.ptx"
    write_scan(p, [_scan(rng, 9, 6, colors=True), _scan(rng, 4, 5, colors=True)])
    whole = read_scans(p)
    assert [len(s) for s in whole] == [int(s.grid_index.shape[0]) for s in whole]
    monkeypatch.setattr(ptx, "_CHUNK_BYTES", chunk)
    parts = read_scans(p)
    assert len(parts) == len(whole) == 2
    for a, b in zip(whole, parts, strict=True):
        _same(a, b)


def test_chunked_reading_keeps_only_valid_points(tmp_path, monkeypatch):
    header = "2\n3\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"
    body = "1 2 3 0.25\n0 0 0 0.5\n4 5 6 0.75\n0 0 0 0.5\n0 0 0 0.5\n-1 -2 -3 1\n"
    p = tmp_path / "holes.ptx"
    p.write_text(header + body)
    monkeypatch.setattr(ptx, "_CHUNK_BYTES", 16)
    (s,) = read_scans(p)
    np.testing.assert_array_equal(s.points, [[1, 2, 3], [4, 5, 6], [-1, -2, -3]])
    np.testing.assert_array_equal(s.grid_index, [[0, 0], [2, 0], [2, 1]])  # line k: k%3, k//3
    np.testing.assert_array_equal(s.intensity, np.float32([0.25, 0.75, 1.0]))


HEADER = "2\n2\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"
BAD = {
    "truncated": (HEADER + "1 2 3 0.5\n" * 3, "only 3 lines follow"),
    "bad number late": (HEADER + "1 2 3 0.5\n" * 3 + "1 2 x 0.5\n", "line 14: not a valid"),
    "bad number before ragged line": (
        HEADER + "1 2 3 0.5\n1 2 3\n1 2 3 0.5\n1 2 3 y\n",
        "line 14: not a valid",
    ),
    "ragged line": (HEADER + "1 2 3 0.5\n1 2 3 0.5\n1 2 3\n1 2 3 0.5\n", "line 13: expected 4"),
    "second cloud truncated header": (HEADER + "1 2 3 0.5\n" * 4 + "2\n2\n0 0 0\n", "cloud 1"),
}


@pytest.mark.parametrize("case", sorted(BAD))
@pytest.mark.parametrize("chunk", [5, 23, 1 << 20])
def test_chunked_errors_name_the_same_line(tmp_path, monkeypatch, case, chunk):
    text, fragment = BAD[case]
    p = tmp_path / "bad.ptx"
    p.write_text(text)
    monkeypatch.setattr(ptx, "_CHUNK_BYTES", chunk)
    with pytest.raises(InputError) as e:
        read_scans(p)
    assert str(p) in str(e.value) and fragment in str(e.value)


@pytest.mark.parametrize("chunk", [7, 1000])
def test_reading_without_intensity_keeps_everything_else(tmp_path, rng, monkeypatch, chunk):
    """``intensity=False`` stores no intensities; points, colours, grid and pose are those of
    a full read, and a bad line is still found."""
    p = tmp_path / "multi.ptx"
    write_scan(p, [_scan(rng, 9, 6, colors=True), _scan(rng, 4, 5, colors=False)])
    monkeypatch.setattr(ptx, "_CHUNK_BYTES", chunk)
    full, lean = read_scans(p), read_scans(p, intensity=False)
    for a, b in zip(full, lean, strict=True):
        assert a.intensity is not None and b.intensity is None
        a.intensity = None
        _same(a, b)
    npz = tmp_path / "s.npz"
    write_scan(npz, _scan(rng, 3, 3, colors=False))
    assert read_scans(npz)[0].intensity is not None
    assert read_scans(npz, intensity=False)[0].intensity is None  # other readers: dropped
    lines = p.read_text().splitlines()
    lines[11] = "1 2 zz 0.5"
    bad = tmp_path / "bad.ptx"
    bad.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match="line 12: not a valid number"):
        read_scans(bad, intensity=False)


@pytest.mark.parametrize("max_pixels", [10_000, 20, 8])
def test_reading_straight_into_the_working_image(tmp_path, rng, monkeypatch, max_pixels):
    """``read_working_scan``: the points of a full read in the same order, without grid index
    or attributes, and the working image that :func:`working_image` makes of the full read
    (every k-th row and column), for the setup a selector names; other formats fall back to
    a plain read."""
    from flexreg.io import read_working_scan
    from flexreg.stages.projection import working_image

    p = tmp_path / "multi.ptx"
    write_scan(p, [_scan(rng, 9, 6, colors=True), _scan(rng, 7, 5, colors=False)])
    monkeypatch.setattr(ptx, "_CHUNK_BYTES", 64)
    for ref, k in [(p, 0), (f"{p}#1", 1)]:
        full = read_scans(p)[k]
        scan, image = read_working_scan(ref, max_pixels=max_pixels)
        assert scan.grid_index is None and scan.intensity is None and scan.colors is None
        np.testing.assert_array_equal(scan.points, full.points)
        np.testing.assert_array_equal(scan.T_world_scanner, full.T_world_scanner)
        expected = working_image(full, max_pixels=max_pixels)
        assert image.shape == expected.shape and image.camera is None
        np.testing.assert_array_equal(image.valid, expected.valid)
        np.testing.assert_array_equal(image.xyz, expected.xyz)
        assert (image.index == -1).all() and image.xyz.dtype == np.float32
    npz = tmp_path / "s.npz"
    write_scan(npz, _scan(rng, 3, 3, colors=False))
    scan, image = read_working_scan(npz, max_pixels=max_pixels)
    assert image is None and scan.intensity is None and scan.grid_index is not None
    lines = p.read_text().splitlines()
    lines[11] = "1 2 zz 0.5"
    bad = tmp_path / "bad.ptx"
    bad.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match="line 12: not a valid number"):
        read_working_scan(bad, max_pixels=max_pixels)
