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


def pytest_addoption(parser) -> None:
    parser.addoption(
        "--ray-ulp",
        type=int,
        default=0,
        help="move every synthetic ray direction by this many float32 ulps (towards +inf when "
        "positive): the last-bit differences another CPU's ray caster makes (make test-variants)",
    )


def pytest_configure(config) -> None:
    """``--ray-ulp N``: wrap the synthetic scenes' ray casts so that every direction moves by
    N ulps. Another CPU (Embree picks its kernels at run time) makes such last-bit changes to
    the rays it casts; tests of seeded synthetic data must hold through them."""
    n = config.getoption("--ray-ulp", 0)
    if not n:
        return
    import numpy as np

    from flexreg.synth.scene import Scene

    cast = Scene.cast
    towards = np.float32(np.inf if n > 0 else -np.inf)

    def perturbed(self, origins, directions):
        d = np.asarray(directions, dtype=np.float32)
        for _ in range(abs(n)):
            d = np.nextafter(d, towards)
        return cast(self, origins, d)

    Scene.cast = perturbed  # type: ignore[method-assign]


def pytest_report_header(config) -> list[str]:
    """Name the machine in the header: results may differ across CPUs within the tolerances
    of docs/determinism.md, so a failure must say where it ran."""
    import numba

    try:  # numpy's runtime SIMD dispatch (no public accessor)
        from numpy._core._multiarray_umath import __cpu_features__ as features
    except ImportError:
        features = {}
    levels = [k for k, v in features.items() if v and k.startswith("X86_V")]
    variant = [
        f"{k}={os.environ[k]}"
        for k in ("NUMBA_CPU_NAME", "OPENBLAS_CORETYPE", "NPY_DISABLE_CPU_FEATURES")
        if os.environ.get(k)
    ]
    ulp = config.getoption("--ray-ulp", 0)
    if ulp:
        variant.append(f"rays moved {ulp:+d} ulp")
    return [
        f"cpu: {_cpu_model()} ({platform.machine()}), {os.cpu_count()} logical cores, "
        f"numba threads {numba.config.NUMBA_NUM_THREADS}, numpy SIMD {' '.join(levels) or '-'}"
    ] + ([f"cpu variant: {', '.join(variant)}"] if variant else [])


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


@pytest.fixture(autouse=True)
def _wide_consoles(monkeypatch):
    """The command line's consoles wide for every test: what a test reads in a table must
    not depend on the COLUMNS the test run inherited (long temporary paths are cut or
    wrapped at 80 columns)."""
    from flexreg.cli import _common

    monkeypatch.setattr(_common.console, "width", 400)
    monkeypatch.setattr(_common.err_console, "width", 400)


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


#: Four stations in ``make_scene("room", 0)`` (the room of ``flexreg synth --scene room --seed
#: 0``): rotation vector (radians) and position (metres) of each scanner in the world, where that
#: command once placed them. Fixed here because seeded placement depends on ray-cast ties that
#: another CPU breaks the other way (docs/determinism.md): tests that need these views get them
#: on every machine.
ROOM_STATIONS = (
    ((-0.0313, 0.0089, -0.6835), (10.291, 7.192, 1.356)),
    ((0.0024, 0.0011, 1.154), (8.773, 2.975, 1.761)),
    ((-0.0022, -0.0204, 1.5412), (13.812, 2.383, 1.514)),
    ((-0.0453, -0.0321, -2.1461), (14.707, 4.806, 1.978)),
)


#: ``station_pair("room", seed=S)``'s two stations where that seed once placed them (rotation
#: vector in radians, position in metres; see :data:`ROOM_STATIONS` for why they are fixed)
ROOM_PAIRS = {
    2: (((0.0277, 0.0032, 0.3797), (8.327, 2.816, 1.422)),
        ((-0.0492, 0.034, 0.0499), (10.911, 4.838, 1.334))),
    4: (((-0.0337, 0.0534, 1.627), (6.526, 2.965, 1.513)),
        ((0.0396, 0.0471, -2.033), (5.38, 5.625, 1.635))),
}  # fmt: skip


def pose(rotvec, position):
    """(4, 4) float64 ``T_world_scanner`` from a rotation vector (radians) and a position (m)."""
    import numpy as np
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = position
    return T


def room_pair(seed: int, resolution: tuple[int, int]):
    """``station_pair("room", seed=seed)`` at :data:`ROOM_PAIRS`' fixed poses."""
    from flexreg.synth import station_pair

    poses = tuple(pose(*p) for p in ROOM_PAIRS[seed])
    return station_pair("room", seed=seed, resolution=resolution, poses=poses)


def room_project(folder: Path, stations: int = 4, *, width: int = 512, height: int = 256,
                 fmt: str = "ptx") -> Path:  # fmt: skip
    """``flexreg synth --scene room --seed 0 --stations N`` into ``folder`` (PTX files,
    gt.json, scene.ply), with the stations at :data:`ROOM_STATIONS` instead of placed."""
    from flexreg.synth import SynthConfig, synthesize

    poses = [pose(*p) for p in ROOM_STATIONS[:stations]]
    cfg = SynthConfig(
        scene="room", stations=stations, width=width, height=height, seed=0, format=fmt
    )
    synthesize(folder, cfg, poses=poses)
    return folder


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
