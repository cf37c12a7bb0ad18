"""Shared test fixtures: paths to the real data beside the checkout."""

from __future__ import annotations

import contextlib
import io
import os
import platform
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def pytest_report_header(config) -> list[str]:
    """Name the machine in the header: results may differ across CPUs within the tolerances
    of docs/determinism.md, so a failure must say where it ran."""
    import numba

    try:  # numpy's runtime SIMD dispatch (no public accessor)
        from numpy._core._multiarray_umath import __cpu_features__ as features
    except ImportError:
        features = {}
    levels = [k for k, v in features.items() if v and k.startswith("X86_V")]
    return [
        f"cpu: {_cpu_model()} ({platform.machine()}), {os.cpu_count()} logical cores, "
        f"numba threads {numba.config.NUMBA_NUM_THREADS}, numpy SIMD {' '.join(levels) or '-'}"
    ]


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data`` (present beside the checkout in development and CI; a user's clone
    without it skips the tests that read it)."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data folder {SHARED_DATA} not present (clone ../shared beside it)")
    return SHARED_DATA


@pytest.fixture()
def rng():
    import numpy as np

    return np.random.default_rng(12345)


def run_cli(argv: list) -> tuple[int, str, str]:
    """Run ``flexreg`` in-process: (exit status, stdout, stderr)."""
    from flexreg.cli import run

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = run([str(a) for a in argv])
    return rc, out.getvalue(), err.getvalue()


def one_error_line(err: str) -> str:
    """The single ``error: ...`` line a failed command printed (asserts there is exactly one
    and no traceback)."""
    lines = [line for line in err.strip().splitlines() if line.strip()]
    assert sum(line.startswith("error:") for line in lines) == 1, err
    assert lines[-1].startswith("error: ") and "Traceback" not in err, err
    return lines[-1]


def room_walk(n_frames: int) -> list:
    """``n_frames`` camera poses 2 cm apart in ``make_scene("room", 3)``, walking towards a
    view with plenty of structure (some 50 AKAZE inliers per frame pair). Fixed poses, not
    ``synth.camera_trajectory``: that path starts in the scene's free map, which ray casts
    decide, and a tie between coplanar faces that another CPU breaks the other way moved it
    to a view too bare to track."""
    import numpy as np

    from flexreg.synth import look_at

    start = np.array([7.3, 7.3, 1.32])
    view = np.array([-0.948, 0.12, -0.295])
    step = np.array([-0.95, 0.12, 0.0]) / np.hypot(0.95, 0.12)
    return [look_at(start + 0.02 * k * step, start + 3.0 * view) for k in range(n_frames)]


#: the bad-input corpus's summary line (tests/badinput/test_corpus.py), printed at the end
BADINPUT_SUMMARY = pytest.StashKey[str]()


def pytest_terminal_summary(terminalreporter, exitstatus, config) -> None:
    text = config.stash.get(BADINPUT_SUMMARY, None)
    if text is not None:
        terminalreporter.write_sep("-", "bad-input corpus")
        terminalreporter.write_line(text)


# property-based fuzzing (tests/test_fuzz_parsers.py): a bounded default run; the long profile
# behind `--hypothesis-profile=long` or HYPOTHESIS_PROFILE=long
try:
    from hypothesis import settings as _hsettings
except ImportError:  # pragma: no cover - hypothesis is in the dev extra
    pass
else:
    _hsettings.register_profile("default", max_examples=50, deadline=None, print_blob=True)
    _hsettings.register_profile("long", max_examples=2000, deadline=None, print_blob=True)
    _hsettings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))
