"""The first run on a machine: where the compiled kernels are cached (the user's cache folder
when the package cannot be written), one line when a kernel's cache is cold, and a console
that does not cut its lines at 80 columns when its output is piped."""

from __future__ import annotations

import importlib.util
import io
import re
import sys
from pathlib import Path

from conftest import REPO, run_cli

from flexreg.cli import _common
from flexreg.core import jit

LASERSCAN = REPO / "data" / "laserscan" / "laserscan-depth.png"


def test_read_only_package_caches_in_the_user_folder(tmp_path):
    read_only = lambda folder: False  # noqa: E731
    env = {"XDG_CACHE_HOME": str(tmp_path / "xdg")}
    chosen = jit.choose_cache_dir(tmp_path / "pkg", environ=env, can_write=read_only)
    assert chosen == tmp_path / "xdg" / "flexreg" / "numba"
    home = jit.choose_cache_dir(tmp_path / "pkg", environ={}, can_write=read_only)
    assert home == Path.home() / ".cache" / "flexreg" / "numba"
    relative = {"XDG_CACHE_HOME": "cache"}  # not absolute: ignored, as the XDG spec says
    assert jit.choose_cache_dir(tmp_path, environ=relative, can_write=read_only) == home


def test_writable_package_or_user_setting_leaves_numba_its_choice(tmp_path):
    assert jit.choose_cache_dir(tmp_path / "pkg", environ={}, can_write=lambda f: True) is None
    env = {jit.CACHE_ENV: str(tmp_path / "mine")}
    assert jit.choose_cache_dir(tmp_path, environ=env, can_write=lambda f: False) is None
    asked: list[Path] = []
    jit.choose_cache_dir(tmp_path, environ={}, can_write=lambda f: asked.append(f) or True)
    assert asked == [tmp_path / d / "__pycache__" for d in jit.KERNEL_DIRS]


def test_writable_tries_to_create_a_file(tmp_path):
    assert jit.writable(tmp_path / "new" / "__pycache__")  # made when missing
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    assert not jit.writable(blocker / "__pycache__")  # cannot exist below a file


def test_kernel_dirs_are_the_folders_with_cached_kernels():
    package = REPO / "flexreg"
    folders = {
        path.parent.relative_to(package).as_posix()
        for path in package.rglob("*.py")
        if "cache=True" in path.read_text() and path.name != "jit.py"
    }
    assert folders == set(jit.KERNEL_DIRS)


def _kernels(tmp_path: Path, module: str) -> object:
    """A module named ``module`` (from a file in ``tmp_path``) with two cached numba kernels."""
    tmp_path.mkdir(exist_ok=True)
    path = tmp_path / "probe_kernels.py"
    if not path.exists():
        path.write_text(
            "import numba\n\n\n@numba.njit(cache=True)\ndef add(a, b):\n    return a + b\n\n\n"
            "@numba.njit(cache=True)\ndef twice(a):\n    return 2 * a\n"
        )
    spec = importlib.util.spec_from_file_location(module, path)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_a_cold_cache_calls_back_once_and_a_warm_one_never(tmp_path):
    calls: list[Path] = []
    jit.on_first_compile(calls.append)
    try:
        first = _kernels(tmp_path, "flexreg.probe_kernels")
        assert first.add(1, 2) == 3 and first.twice(2.5) == 5.0 and first.add(1.0, 2.0) == 3.0
        assert len(calls) == 1  # three compilations, one line
        jit.on_first_compile(calls.append)  # armed again: the next run in this process
        again = _kernels(tmp_path, "flexreg.probe_kernels")  # new dispatchers, same files
        assert again.add(1, 2) == 3 and again.twice(2.5) == 5.0
        assert len(calls) == 1  # loaded from the cache: nothing compiled, nothing said
    finally:
        jit.on_first_compile(None)
        sys.modules.pop("flexreg.probe_kernels", None)


def test_kernels_outside_flexreg_say_nothing(tmp_path):
    calls: list[Path] = []
    jit.on_first_compile(calls.append)
    try:
        foreign = _kernels(tmp_path / "foreign", "someone_else.kernels")
        assert foreign.add(1, 2) == 3
        assert calls == []
    finally:
        jit.on_first_compile(None)


def test_the_command_line_says_it_once_on_stderr(tmp_path, capsys):
    """The root of every command arms the notice; the first kernel compiled prints one line."""
    rc, _, _ = run_cli(["info", LASERSCAN])
    assert rc == 0
    capsys.readouterr()
    try:
        probe = _kernels(tmp_path, "flexreg.probe_cli")
        assert probe.add(2, 3) == 5 and probe.twice(1) == 2
        err = capsys.readouterr().err
        assert err.count("compiling the image kernels once") == 1, err
        assert "later runs reuse them" in err
    finally:
        jit.on_first_compile(None)
        sys.modules.pop("flexreg.probe_cli", None)


def test_cache_dir_names_the_user_setting(monkeypatch, tmp_path):
    monkeypatch.setenv(jit.CACHE_ENV, str(tmp_path))
    assert jit.cache_dir() == tmp_path
    monkeypatch.delenv(jit.CACHE_ENV)
    assert jit.cache_dir() == jit.PACKAGE_DIR


def test_piped_console_is_wide_unless_columns_says_otherwise(monkeypatch):
    monkeypatch.delenv("COLUMNS", raising=False)
    assert _common.make_console(environ={}).width == _common.PIPED_WIDTH  # pytest: no tty
    monkeypatch.setenv("COLUMNS", "100")
    assert _common.make_console().width == 100


def test_piped_stage_line_is_one_uncut_line(monkeypatch):
    """Not a terminal: no spinner (its blank lines), the done line whole however long."""
    buffer = io.StringIO()
    console = _common.Console(file=buffer, width=80, highlight=False)
    monkeypatch.setattr(_common, "err_console", console)
    name = "Reading " + "a_very_long_station_name_" * 8 + ".ptx"
    with _common.stage(name):
        pass
    lines = buffer.getvalue().splitlines()
    assert len(lines) == 1 and re.fullmatch(rf"✓ {re.escape(name)} \(\d+\.\d\d s\)", lines[0])
