"""Data safety: all-or-nothing outputs, input protection, clash checks and the memory budget."""

from __future__ import annotations

import os
import resource
import signal
import struct
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from flexreg.core import budget
from flexreg.core.budget import check_memory, format_bytes, memory_budget, parse_size
from flexreg.errors import ConfigError, InputError, MemoryBudgetError
from flexreg.io.files import LOCK, all_or_nothing, atomic_write, discard, protect, write_all
from flexreg.io.safety import find_clash, input_files, same_file, written_files


def _write(text):
    return lambda tmp: tmp.write_text(text)


# ------------------------------------------------------------------------ all or nothing
def test_outputs_appear_together_at_the_end(tmp_path):
    a, b = tmp_path / "a.txt", tmp_path / "sub" / "b.txt"
    with all_or_nothing() as outputs:
        atomic_write(a, _write("A"))
        atomic_write(b, _write("B"))
        assert not a.exists() and not b.exists()
        assert outputs.targets == [a, b]
    assert a.read_text() == "A" and b.read_text() == "B"
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["a.txt", "b.txt", "sub"]


def test_a_failing_second_output_leaves_the_previous_results_byte_identical(tmp_path):
    txt, out = tmp_path / "T.txt", tmp_path / "T.json"
    txt.write_bytes(b"previous matrix")
    out.write_bytes(b"previous json")

    def fail(tmp):
        tmp.write_text("half")
        raise OSError(28, "No space left on device")

    with pytest.raises(InputError, match=r"T\.json: cannot write: No space left on device"):
        write_all(
            [
                (txt, lambda: atomic_write(txt, _write("new"))),
                (out, lambda: atomic_write(out, fail)),
            ]
        )
    assert txt.read_bytes() == b"previous matrix" and out.read_bytes() == b"previous json"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["T.json", "T.txt"]


def test_an_interrupt_removes_every_temporary_and_new_folder(tmp_path):
    with pytest.raises(KeyboardInterrupt), all_or_nothing():
        atomic_write(tmp_path / "new" / "deeper" / "a.txt", _write("A"))
        raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []


def test_nested_blocks_join_the_outer_one(tmp_path):
    a = tmp_path / "a.txt"
    with all_or_nothing():
        with all_or_nothing():
            atomic_write(a, _write("A"))
        assert not a.exists()
    assert a.read_text() == "A"


def test_a_failed_rename_puts_back_what_earlier_renames_replaced(tmp_path, monkeypatch):
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    a.write_text("old a")
    b.write_text("old b")
    real_replace = os.replace

    def flaky(src, dst):
        if str(dst) == str(b):
            raise OSError(5, "Input/output error")
        return real_replace(src, dst)

    with pytest.raises(InputError, match=r"b\.txt: cannot write"), all_or_nothing():
        atomic_write(a, _write("new a"))
        atomic_write(b, _write("new b"))
        monkeypatch.setattr("pathlib.Path.replace", lambda self, t: flaky(self, t))
    monkeypatch.undo()
    assert a.read_text() == "old a" and b.read_text() == "old b"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.txt"]


def test_discard_drops_one_item_of_a_batch(tmp_path):
    with all_or_nothing():
        atomic_write(tmp_path / "keep.png", _write("k"))
        atomic_write(tmp_path / "drop.npz", _write("d"))
        discard(tmp_path / "drop.npz")
    assert [p.name for p in tmp_path.iterdir()] == ["keep.png"]


def test_protected_inputs_are_never_written_whatever_the_spelling(tmp_path):
    src = tmp_path / "scan.png"
    src.write_bytes(b"depth")
    (tmp_path / "link.png").symlink_to(src)
    os.link(src, tmp_path / "hard.png")
    for target in (src, tmp_path / "link.png", tmp_path / "hard.png", tmp_path / "." / "scan.png"):
        with pytest.raises(InputError, match="is also an input"), all_or_nothing():
            protect(src)
            atomic_write(target, _write("overwritten"))
    assert src.read_bytes() == b"depth"


def test_protect_outside_a_block_does_nothing(tmp_path):
    p = tmp_path / "a.txt"
    protect(p)
    atomic_write(p, _write("A"))
    assert p.read_text() == "A"


# --------------------------------------------------------------------------- clash checks
def test_input_files_and_written_files_name_the_companions(tmp_path):
    png = tmp_path / "d.png"
    png.write_bytes(b"x")
    assert input_files(png) == [png]
    (tmp_path / "d.camera.json").write_text("{}")
    assert input_files(png) == [png, tmp_path / "d.camera.json"]
    assert written_files(png, range_image=True) == [
        png,
        tmp_path / "d.npz",
        tmp_path / "d.camera.json",
    ]
    assert written_files(png, keep_float=True) == [png, tmp_path / "d.npz"]


def test_find_clash_compares_files_not_spellings(tmp_path):
    a = tmp_path / "a.txt"
    a.write_text("a")
    (tmp_path / "l.txt").symlink_to(a)
    assert same_file(tmp_path / "l.txt", a)
    assert find_clash([("--out", tmp_path / "l.txt")], [("an input", a)]) == (
        "--out",
        tmp_path / "l.txt",
        "an input",
    )
    assert find_clash([("--out", tmp_path / "b.txt"), ("--txt", tmp_path / "b.txt")], []) == (
        "--txt",
        tmp_path / "b.txt",
        "--out",
    )
    assert find_clash([("--out", tmp_path / "c.txt")], [("an input", a)]) is None


# ------------------------------------------------------------------------------- budget
@pytest.mark.parametrize(
    ("text", "expected"),
    [("512", 512), ("8K", 8192), ("1.5M", int(1.5 * 2**20)), ("2G", 2 * 2**30), ("3gb", 3 * 2**30),
     ("2e9", 2_000_000_000)],
)  # fmt: skip
def test_parse_size(text, expected):
    assert parse_size(text) == expected


def test_parse_size_percent_is_of_physical_memory():
    assert parse_size("50%") == int(budget.physical_memory() * 0.5)


@pytest.mark.parametrize("text", ["", "lots", "-1G", "0", "nan", "150%", "1Q"])
def test_parse_size_refuses_nonsense_naming_the_source(text):
    with pytest.raises(ConfigError, match=r"^FLEXREG_MEMORY_BUDGET: "):
        parse_size(text)


def test_budget_sources_in_order(monkeypatch):
    monkeypatch.delenv(budget.ENV_VAR, raising=False)
    default = memory_budget()
    assert 0 < default <= budget.physical_memory()
    monkeypatch.setenv(budget.ENV_VAR, "3G")
    assert memory_budget() == 3 * 2**30
    budget.set_memory_budget("1G")
    try:
        assert memory_budget() == 2**30
    finally:
        budget.set_memory_budget(None)
    assert memory_budget() == 3 * 2**30


def test_default_budget_follows_the_address_space_limit():
    code = textwrap.dedent(
        """
        import resource
        resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))
        from flexreg.core.budget import memory_budget, physical_memory
        print(memory_budget() == int(0.5 * min(3 << 30, physical_memory())))
        """
    )
    env = {k: v for k, v in os.environ.items() if k != budget.ENV_VAR}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert out.stdout.strip() == "True", out.stderr
    assert resource.getrlimit(resource.RLIMIT_AS)[0] != 3 << 30  # the parent is untouched


def test_check_memory_says_how_big_and_what_the_budget_is(monkeypatch):
    monkeypatch.setenv(budget.ENV_VAR, "1M")
    check_memory(2**20, "fits exactly", source="a.las")
    with pytest.raises(MemoryBudgetError) as e:
        check_memory(5 * 2**30, "400,000,000 points", source="a.las")
    assert str(e.value) == (
        "a.las: 400,000,000 points would need 5.0 GB of memory, more than the memory budget of "
        "1.0 MB (set FLEXREG_MEMORY_BUDGET or flexreg --memory-budget to change it)"
    )
    assert isinstance(e.value, InputError)
    with pytest.raises(MemoryBudgetError, match="an unbounded amount"):
        check_memory(float("inf"), "x", source="s")


def test_format_bytes():
    assert [format_bytes(v) for v in (512, 1536, 3 * 2**30)] == ["512 B", "1.5 KB", "3.0 GB"]


def test_a_gridded_scan_beyond_the_budget_is_refused_before_its_images(monkeypatch):
    from flexreg.core.scan import Scan

    monkeypatch.setenv(budget.ENV_VAR, "10M")
    pts = np.ones((1, 3))
    Scan(points=pts, grid_shape=(100, 100), grid_index=np.zeros((1, 2), np.int32))
    with pytest.raises(MemoryBudgetError, match=r"its 40001 x 40001 grid would need 95\.4 GB"):
        Scan(points=pts, grid_shape=(40001, 40001), grid_index=np.zeros((1, 2), np.int32))


# ------------------------------------------------------------------------------ readers
def test_e57_header_reads_what_the_file_declares(tmp_path):
    from flexreg.core.scan import Scan
    from flexreg.io import write_scan
    from flexreg.io.e57_header import declared_scans

    xyz = np.random.default_rng(0).uniform(-5, 5, (300, 3))
    write_scan(tmp_path / "a.e57", Scan(points=xyz, intensity=np.ones(300, np.float32)))
    (s,) = declared_scans(tmp_path / "a.e57")
    assert s.record_count == 300 and s.fields == 4 and s.bits_per_record == 3 * 64 + 32
    assert 300 * 224 // 8 <= s.section_bytes <= 300 * 224 // 8 + 4096
    assert declared_scans(tmp_path / "a.e57") == [s]
    (tmp_path / "b.e57").write_bytes(b"not an e57")
    assert declared_scans(tmp_path / "b.e57") == []


def test_las_header_with_more_data_than_points_is_refused(tmp_path):
    laspy = pytest.importorskip("laspy")
    from flexreg.io import read_scan

    header = laspy.LasHeader(point_format=0, version="1.2")
    header.scales = np.array([0.01, 0.01, 0.01])
    las = laspy.LasData(header)
    las.x, las.y, las.z = (np.arange(50.0),) * 3
    las.write(str(tmp_path / "a.las"))
    assert len(read_scan(tmp_path / "a.las")) == 50
    data = bytearray((tmp_path / "a.las").read_bytes())
    struct.pack_into("<I", data, 107, 40)
    (tmp_path / "b.las").write_bytes(bytes(data))
    with pytest.raises(InputError, match="declares 40 points but the file holds data for 10 more"):
        read_scan(tmp_path / "b.las")


def test_sigterm_during_a_run_leaves_no_output(tmp_path):
    """A terminated ``flexreg synth`` removes the station files it had staged (the output
    folder it made beforehand may stay, empty); exit status 143."""
    out = tmp_path / "site"
    synth = ["synth", "--stations", "3", "--resolution", "1024x512", "--out", str(out)]
    cmd = [sys.executable, "-c", "from flexreg.cli import main; main()", *synth]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 300

        def staged() -> list[str]:  # what the run wrote, its lock on the folder aside
            return [p.name for p in out.iterdir() if p.name != LOCK] if out.is_dir() else []

        while not staged() and proc.poll() is None:
            assert time.monotonic() < deadline, "synth wrote nothing within 300 s"
            time.sleep(0.05)
        assert proc.poll() is None, proc.stderr.read() if proc.stderr else ""
        names = staged()
        assert names and all(n.startswith(".") and ".partial" in n for n in names), names
        proc.send_signal(signal.SIGTERM)
        rc = proc.wait(timeout=120)
    finally:
        proc.kill()
    assert rc == 143
    assert list(tmp_path.rglob("*")) in ([], [out])
