"""The survey cache holds data only: nothing in it is unpickled or executed, and a damaged,
altered or foreign entry is prepared again with one warning, never trusted."""

from __future__ import annotations

import json
import logging
import pickle
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
from conftest import room_project

from flexreg.io import read_scan
from flexreg.registration.pipeline import Registration
from flexreg.survey import run_survey
from flexreg.survey.stations import read_entry, read_prepared, save_prepared

STATIONS = ["station_00", "station_01", "station_02"]


@pytest.fixture(scope="module")
def project(tmp_path_factory) -> Path:
    return room_project(tmp_path_factory.mktemp("project"), 3)


def _files(project: Path) -> list[Path]:
    return [project / f"{n}.ptx" for n in STATIONS]


@pytest.fixture(scope="module")
def first(project, tmp_path_factory):
    """A first survey: its output folder and its poses."""
    out = tmp_path_factory.mktemp("survey") / "run"
    doc = run_survey(_files(project), out, workers=1).to_dict()
    return out, _poses(doc)


def _poses(doc: dict) -> dict:
    return {s: doc["stations"][s]["T_reference_station"] for s in STATIONS}


def _copy(first_out: Path, dst: Path) -> Path:
    """``dst`` with the first run's prepared stations (no links: each link is aligned again,
    from the prepared stations as the cache gives them)."""
    shutil.copytree(first_out / "cache", dst / "cache", ignore=shutil.ignore_patterns("links"))
    return dst


def _entries(out: Path, kind: str) -> list[Path]:
    found = sorted((out / "cache").glob(f"*.{kind}.*"))
    assert found, f"no {kind} entries in {out / 'cache'}"
    return found


def _cache_warnings(caplog) -> list[str]:
    return [
        r.getMessage()
        for r in caplog.records
        if r.levelno == logging.WARNING and "cache entry" in r.getMessage()
    ]


def _rerun(project: Path, out: Path, caplog):
    with caplog.at_level("WARNING", logger="flexreg"):
        result = run_survey(_files(project), out, workers=1)
    return result, _poses(result.to_dict()), _cache_warnings(caplog)


class _Payload:
    """Creates ``marker`` when unpickled (what a crafted cache entry would do)."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (open, (str(self.marker), "w"))


def test_a_crafted_pickle_in_the_cache_is_never_executed(project, first, tmp_path, caplog):
    out = _copy(first[0], tmp_path / "out")
    marker = tmp_path / "pwned"
    crafted = pickle.dumps(_Payload(marker))
    assert len(crafted) < 200
    for f in _entries(out, "prepared"):  # where the entry is, under the old and new names
        base = f.name.split(".")[0]
        for name in (f.name, f"{base}.prepared.pkl", f"{base}.prepared.npz"):
            (f.parent / name).write_bytes(crafted)
    result, poses, warnings = _rerun(project, out, caplog)
    assert not marker.exists()
    assert [p.computed for p in result.prepared.values()] == [True] * 3
    assert poses == first[1]
    assert all("preparing the station again" in w for w in warnings) and len(warnings) == 3


def test_a_crafted_pickle_as_a_cached_link_is_never_executed(project, first, tmp_path, caplog):
    """The links' cache (``cache/links/``) holds data only too: a crafted pickle where a
    link's entry is, under its old or new name, is registered again, not loaded."""
    out = tmp_path / "out"
    shutil.copytree(first[0] / "cache", out / "cache")
    marker = tmp_path / "pwned"
    crafted = pickle.dumps(_Payload(marker))
    links = sorted((out / "cache" / "links").glob("*.link.npz"))
    assert links
    for f in links:
        f.write_bytes(crafted)
        f.with_name(f.name.removesuffix(".npz") + ".pkl").write_bytes(crafted)
    with caplog.at_level("WARNING", logger="flexreg"):
        result = run_survey(_files(project), out, workers=1)
    assert not marker.exists()
    assert _poses(result.to_dict()) == first[1]
    assert result.to_dict()["summary"]["links_from_cache"] == 0
    warned = [w for w in _cache_warnings(caplog) if "registering the link again" in w]
    assert len(warned) == len(links)


def test_a_truncated_prepared_entry_is_prepared_again_with_one_warning(
    project, first, tmp_path, caplog
):
    out = _copy(first[0], tmp_path / "out")
    bad = _entries(out, "prepared")[0]
    bad.write_bytes(bad.read_bytes()[: bad.stat().st_size // 2])
    result, poses, warnings = _rerun(project, out, caplog)
    assert len(warnings) == 1 and str(bad) in warnings[0], warnings
    assert sum(p.computed for p in result.prepared.values()) == 1
    assert poses == first[1]
    read_prepared(bad)  # whole again


def test_a_truncated_global_descriptor_is_prepared_again_with_one_warning(
    project, first, tmp_path, caplog
):
    out = _copy(first[0], tmp_path / "out")
    bad = _entries(out, "global")[1]
    bad.write_bytes(bad.read_bytes()[:100])
    result, poses, warnings = _rerun(project, out, caplog)
    assert len(warnings) == 1 and str(bad) in warnings[0], warnings
    assert sum(p.computed for p in result.prepared.values()) == 1
    assert poses == first[1]
    read_entry(bad, "global")  # whole again


def _altered(path: Path) -> None:
    """Rewrite an entry with one value of its largest array changed, keeping its stored
    metadata and digest (a well-formed archive whose digest no longer matches)."""
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    key = max((k for k in arrays if not k.startswith("__")), key=lambda k: arrays[k].nbytes)
    a = arrays[key].copy()
    flat = a.reshape(-1).view(np.uint8)
    flat[len(flat) // 2] ^= 0xFF
    arrays[key] = a
    np.savez(path, allow_pickle=False, **arrays)


def test_entries_whose_bytes_were_changed_are_prepared_again(project, first, tmp_path, caplog):
    out = _copy(first[0], tmp_path / "out")
    altered, flipped, glance = (
        _entries(out, "prepared")[0],
        _entries(out, "prepared")[2],
        _entries(out, "glance")[1],
    )
    _altered(altered)
    data = bytearray(flipped.read_bytes())
    data[len(data) // 2 : len(data) // 2 + 8] = bytes(b ^ 0xFF for b in data[len(data) // 2 :][:8])
    flipped.write_bytes(bytes(data))  # the archive's own CRC no longer matches either
    glance.write_bytes(glance.read_bytes()[:-50])
    result, poses, warnings = _rerun(project, out, caplog)
    assert sorted(warnings) == sorted(
        w for w in warnings if any(str(f) in w for f in (altered, flipped, glance))
    )
    assert len(warnings) == 3, warnings
    assert any(str(altered) in w and "digest" in w for w in warnings)
    assert sum(p.computed for p in result.prepared.values()) == 2
    assert poses == first[1]


def test_a_saved_station_aligns_bit_for_bit_like_the_prepared_one(project, tmp_path):
    reg = Registration()
    fresh = [reg.prepare(read_scan(project / f"{s}.ptx")) for s in STATIONS[:2]]
    for k, p in enumerate(fresh):
        save_prepared(p, tmp_path / f"{k}.prepared.npz", note="test")
    loaded = [read_prepared(tmp_path / f"{k}.prepared.npz") for k in range(2)]
    assert [meta["note"] for _, meta in loaded] == ["test", "test"]
    with zipfile.ZipFile(tmp_path / "0.prepared.npz") as z:  # plain arrays and JSON only
        meta = json.loads(np.load(tmp_path / "0.prepared.npz")["__meta__"].tobytes())
        assert meta["schema"] == "flexreg.cache/1" and meta["kind"] == "prepared"
        assert all(n.endswith(".npy") for n in z.namelist())
    a = reg.align(fresh[0], fresh[1])
    b = reg.align(loaded[0][0], loaded[1][0])
    assert np.array_equal(a.T_target_source, b.T_target_source)
    for x, y in zip(fresh, (p for p, _ in loaded), strict=True):
        assert np.array_equal(x.image.xyz, y.image.xyz, equal_nan=True)
        assert np.array_equal(x.keypoints.features.descriptors, y.keypoints.features.descriptors)
        assert x.config == y.config and x.timings_s == y.timings_s
        assert np.array_equal(x.scan.points, y.scan.points)
