"""Property-based fuzzing of the text parsers (hypothesis).

The property, for every parser of a file a user hands to flexreg: it either returns a valid
value or raises a :class:`~flexreg.errors.FlexregError` subclass (which the command line turns
into one ``error:`` line) -- never another exception (a traceback). Inputs are mutations of a
good file (tokens replaced by hostile ones, lines dropped, repeated or cut, bytes flipped) and
free text.

Profiles (``tests/conftest.py``): ``default`` runs 50 examples per parser with no deadline;
``long`` runs 2,000 (``pytest tests/test_fuzz_parsers.py --hypothesis-profile=long`` or
``HYPOTHESIS_PROFILE=long``).
"""

from __future__ import annotations

import json
import math
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, example, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from flexreg.errors import FlexregError  # noqa: E402

#: tokens a spreadsheet, a careless export or a hostile file puts where numbers belong
HOSTILE = [
    "nan", "NaN", "-nan", "inf", "-Infinity", "1e30", "-1e30", "1e309", "1e-320", "0", "-0",
    "0.0", "1", "-1", "3", "4", "12", "65536", "2147483648", "-2147483649", "1e9", "1.5",
    "", " ", "abc", "1,5", "1.2.3", "--1", "+", "-", ".", "e5", "0x10", "1_000", "١٢",
    "\x00", "\t", "\ufeff", "\"", "'", "#", ",", ";", "[", "]", "{", "}", "=", "true", "null",
    "None", "1e", "9" * 40, "é", "\u2028",
]  # fmt: skip

#: how many examples; the ``long`` profile runs many more (see the module docstring)
FUZZ = settings(suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])


def _lines(text: str) -> list[list[str]]:
    return [line.split(" ") for line in text.split("\n")]


@st.composite
def mutated(draw: st.DrawFn, good: str, *, seps: str = " ") -> str:
    """``good`` with a few random edits: a token replaced, a line dropped, repeated or
    swapped, the text cut at a random byte, or a random character inserted."""
    rows = _lines(good)
    for _ in range(draw(st.integers(1, 4))):
        what = draw(st.sampled_from(["token", "token", "drop", "repeat", "swap", "cut", "char"]))
        if not rows:
            break
        i = draw(st.integers(0, len(rows) - 1))
        if what == "token":
            j = draw(st.integers(0, max(0, len(rows[i]) - 1)))
            tok = draw(st.sampled_from(HOSTILE) | st.text(max_size=6))
            if rows[i]:
                rows[i][j] = tok
            else:
                rows[i] = [tok]
        elif what == "drop":
            del rows[i]
        elif what == "repeat":
            rows.insert(i, list(rows[i]))
        elif what == "swap":
            k = draw(st.integers(0, len(rows) - 1))
            rows[i], rows[k] = rows[k], rows[i]
        elif what == "cut":
            text = "\n".join(" ".join(r) for r in rows)
            return text[: draw(st.integers(0, len(text)))]
        else:
            j = draw(st.integers(0, max(0, len(rows[i]) - 1)))
            if rows[i]:
                rows[i][j] += draw(st.sampled_from([*seps, "x", "\x00", "-", "e", "."]))
    return "\n".join(" ".join(r) for r in rows)


def any_text(good: str, **kw: Any) -> st.SearchStrategy[str]:
    """Mostly mutations of ``good``, sometimes free text."""
    return st.one_of(mutated(good, **kw), mutated(good, **kw), st.text(max_size=200))


def accepts_or_refuses(
    parse: Callable[[Path], Any], path: Path, content: str | bytes, check: Callable[[Any], None]
) -> None:
    """Write ``content`` to ``path``; ``parse(path)`` must return a value passing ``check`` or
    raise a FlexregError."""
    if isinstance(content, str):
        path.write_text(content, encoding="utf-8", errors="surrogatepass")
    else:
        path.write_bytes(content)
    try:
        value = parse(path)
    except FlexregError as e:
        assert str(e).strip() and "\n" not in str(e).strip(), repr(str(e))
        return
    check(value)


@pytest.fixture(scope="module")
def folder() -> Any:
    with tempfile.TemporaryDirectory(prefix="flexreg-fuzz-") as d:
        yield Path(d)


def _finite(*arrays: Any) -> None:
    for a in arrays:
        if a is not None:
            assert np.isfinite(np.asarray(a, dtype=np.float64)).all()


def _rigid(T: Any) -> None:
    T = np.asarray(T, dtype=np.float64)
    assert T.shape == (4, 4) and np.isfinite(T).all()
    np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-3)
    np.testing.assert_array_equal(T[3], [0, 0, 0, 1])


# ------------------------------------------------------------------------------------- PTX
GOOD_PTX = (
    "2\n2\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0.5 -1 2 1\n"
    "1 2 3 0.5\n0 0 0 0\n-1 2.5 3 0.25\n4 -5 6e-1 1\n"
)


@FUZZ
@given(text=any_text(GOOD_PTX))
def test_ptx(folder, text):
    from flexreg.io import ptx

    def check(scans):
        assert scans
        for s in scans:
            _finite(s.points, s.intensity, s.T_world_scanner)
            rows, cols = s.grid_shape
            assert len(s.points) <= rows * cols

    accepts_or_refuses(lambda p: ptx.read(p), folder / "fuzz.ptx", text, check)


@FUZZ
@given(data=st.binary(max_size=300) | any_text(GOOD_PTX).map(lambda t: t.encode()))
@example(data=b"1\n1e20\n0 0 0\n0 0 0\n0 0 0\n0 0 0\n0 0 0 0\n0 0 0 0\n0 0 0 0\n0 0 0 0\n0 0 0")
def test_ptx_bytes(folder, data):
    from flexreg.io import read_scan

    accepts_or_refuses(read_scan, folder / "bytes.ptx", data, lambda s: _finite(s.points))


# ------------------------------------------------------------------------- pairs CSV (calibrate)
GOOD_PAIRS = "u,v,X,Y,Z\n10,20,1.5,0.2,3\n300.5,40,-1,2,8\n# comment\n5,6,7,8,9\n"
GOOD_GRID_PAIRS = "u;v;row;col\n10;20;3;4\n30;40;5;6\n"


@FUZZ
@given(text=any_text(GOOD_PAIRS, seps=",") | any_text(GOOD_GRID_PAIRS, seps=";"))
def test_calibration_pairs_csv(folder, text):
    from flexreg.io.correspondences import read_pairs

    def check(table):
        _finite(table.pixels, table.xyz, table.rowcol)
        assert len(table.pixels) == len(table.lines)

    accepts_or_refuses(read_pairs, folder / "pairs.csv", text, check)


# ------------------------------------------------------------------------- survey --pairs CSV
STEMS = ["s00", "s01", "s02", "s03"]
GOOD_SURVEY = "target,source\ns00,s01\ns01.ptx,s02.ptx\n\ns02, s03\n"


@FUZZ
@given(text=any_text(GOOD_SURVEY, seps=","))
def test_survey_pairs_csv(folder, text):
    from flexreg.survey.pairs import read_pairs_csv

    def check(pairs):
        assert pairs
        for c in pairs:
            assert c.target in STEMS and c.source in STEMS and c.target != c.source

    accepts_or_refuses(lambda p: read_pairs_csv(p, STEMS), folder / "pairs.csv", text, check)


# ---------------------------------------------------------------------- TUM / KITTI trajectories
GOOD_TUM = (
    "# t tx ty tz qx qy qz qw\n0.0 0 0 0 0 0 0 1\n0.1 0.1 0 0 0 0 0.0998334 0.9950042\n"
    "0.2 0.2 0.05 0 0 0 0.1986693 0.9800666\n"
)
GOOD_KITTI = "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0.5 0 1 0 0 0 0 1 0\n0 -1 0 1 1 0 0 0 0 0 1 0.2\n"


@FUZZ
@given(text=any_text(GOOD_TUM) | any_text(GOOD_KITTI), fmt=st.sampled_from(["auto", "tum"]))
def test_trajectory(folder, text, fmt):
    from flexreg.io.trajectory import read_trajectory

    def check(traj):
        assert len(traj.timestamps) >= 1
        _finite(traj.timestamps)
        assert (np.diff(traj.timestamps) > 0).all()
        for T in traj.poses:
            _rigid(T)

    accepts_or_refuses(lambda p: read_trajectory(p, fmt), folder / "traj.txt", text, check)


# ------------------------------------------------------------- intrinsics and camera sidecars
GOOD_INTRINSICS = json.dumps(
    {"K": [[500, 0, 320], [0, 500, 240], [0, 0, 1]], "distortion": [0.1, -0.05, 0, 0],
     "width": 640, "height": 480},
    indent=0,
)  # fmt: skip
GOOD_SIDECAR = json.dumps(
    {"camera": {"model": "pinhole", "fx": 500.0, "fy": 500.0, "cx": 320.0, "cy": 240.0,
                "width": 640, "height": 480},
     "depth_scale": 0.001, "depth_kind": "z", "invalid_values": [0]},
    indent=0,
)  # fmt: skip
GOOD_SPHERICAL = json.dumps(
    {"camera": {"model": "spherical", "width": 360, "height": 180, "phi_min": -3.14159,
                "phi_max": 3.14159, "theta_min": 0.1, "theta_max": 3.0},
     "depth_scale": 0.001},
    indent=0,
)  # fmt: skip
GOOD_OPENCV = (
    "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\ncamera_matrix: !!opencv-matrix\n"
    "   rows: 3\n   cols: 3\n   dt: d\n   data: [ 500., 0., 320., 0., 500., 240., 0., 0., 1. ]\n"
    "distortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: 5\n   dt: d\n"
    "   data: [ 0.1, -0.05, 0., 0., 0. ]\n"
)
GOOD_KITTI_CALIB = (
    "P0: 700 0 600 0 0 700 180 0 0 0 1 0\nP1: 700 0 600 -380 0 700 180 0 0 0 1 0\n"
    "P2: 700 0 600 45 0 700 180 -0.3 0 0 1 0.003\nP3: 700 0 600 -330 0 700 180 2 0 0 1 0.003\n"
    "R0_rect: 1 0 0 0 1 0 0 0 1\nTr_velo_to_cam: 0 -1 0 0 0 0 -1 -0.08 1 0 0 -0.27\n"
)


def _intrinsics_ok(c):
    K = np.asarray(c.K)
    _finite(K, c.distortion)
    assert K.shape == (3, 3) and K[0, 0] > 0 and K[1, 1] > 0


@FUZZ
@given(text=any_text(GOOD_INTRINSICS, seps=",]}"))
def test_intrinsics_json(folder, text):
    from flexreg.io.intrinsics import read_intrinsics

    accepts_or_refuses(read_intrinsics, folder / "cam.json", text, _intrinsics_ok)


@FUZZ
@given(text=any_text(GOOD_OPENCV, seps=",]:"))
def test_intrinsics_opencv_yaml(folder, text):
    from flexreg.io.intrinsics import read_intrinsics

    accepts_or_refuses(read_intrinsics, folder / "cam.yaml", text, _intrinsics_ok)


@FUZZ
@given(text=any_text(GOOD_KITTI_CALIB, seps=":"))
def test_kitti_calibration(folder, text):
    from flexreg.io.intrinsics import read_extrinsic, read_intrinsics

    accepts_or_refuses(read_intrinsics, folder / "calib.txt", text, _intrinsics_ok)
    accepts_or_refuses(read_extrinsic, folder / "calib.txt", text, _rigid)


@FUZZ
@given(text=any_text(GOOD_SIDECAR, seps=",}") | any_text(GOOD_SPHERICAL, seps=",}"))
def test_camera_sidecar(folder, text):
    from flexreg.io.depth import read_sidecar

    def check(opts):
        cam = opts["camera"]
        assert cam.width > 0 and cam.height > 0
        for k in ("fx", "fy"):
            if hasattr(cam, k):
                v = getattr(cam, k)
                assert math.isfinite(v) and v > 0
        scale = opts.get("depth_scale", 1.0)
        assert math.isfinite(scale) and scale > 0

    accepts_or_refuses(
        lambda p: read_sidecar(p.with_name("d.png")), folder / "d.camera.json", text, check
    )


# -------------------------------------------------------------------- 4x4 transform files
GOOD_TXT = "1 0 0 0.5\n0 1 0 -1\n0 0 1 2\n0 0 0 1\n"
GOOD_T_JSON = json.dumps(
    {"T_target_source": [[0, -1, 0, 1], [1, 0, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]]}, indent=0
)
GOOD_GT_JSON = json.dumps(
    {"pairs": [{"target": "a", "source": "b", "T_target_source": np.eye(4).tolist()}]}, indent=0
)


@FUZZ
@given(
    text=any_text(GOOD_TXT) | any_text(GOOD_T_JSON, seps=",]") | any_text(GOOD_GT_JSON, seps=",]"),
    suffix=st.sampled_from([".txt", ".json"]),
)
def test_transform_files(folder, text, suffix):
    from flexreg.io.intrinsics import read_extrinsic
    from flexreg.io.transform_io import read_ground_truth, read_transform

    path = folder / f"T{suffix}"
    accepts_or_refuses(read_transform, path, text, lambda T: _finite(T))
    accepts_or_refuses(lambda p: read_ground_truth(p, target="a", source="b"), path, text, _rigid)
    accepts_or_refuses(read_extrinsic, path, text, _rigid)


# -------------------------------------------------------------------- configs and --set
def _config_classes() -> list[type]:
    from flexreg.bench.config import CompareConfig
    from flexreg.calibration.config import CalibrationConfig
    from flexreg.odometry.config import EvaluationConfig, OdometryConfig
    from flexreg.registration.config import RegistrationConfig
    from flexreg.survey.config import SurveyConfig
    from flexreg.synth.config import SynthConfig

    return [
        RegistrationConfig, CalibrationConfig, OdometryConfig, EvaluationConfig, SurveyConfig,
        SynthConfig, CompareConfig,
    ]  # fmt: skip


def _good_toml(cls: type) -> str:
    from flexreg.config import to_toml

    return to_toml(cls())


@pytest.mark.parametrize("cls", _config_classes(), ids=lambda c: c.__name__)
def test_config_toml(folder, cls):
    from flexreg.config import load_config

    good = _good_toml(cls)

    @FUZZ
    @given(text=any_text(good, seps='=]"'))
    def run(text):
        accepts_or_refuses(
            lambda p: load_config(cls, p), folder / f"{cls.__name__}.toml", text, _valid(cls)
        )

    run()


def _valid(cls: type) -> Callable[[Any], None]:
    def check(config: Any) -> None:
        assert isinstance(config, cls)
        # a valid configuration survives its own round trip through TOML
        from flexreg.config import load_config, to_toml

        with tempfile.TemporaryDirectory() as d:
            p = Path(d) / "round.toml"
            p.write_text(to_toml(config))
            assert load_config(cls, p) == config

    return check


SET_KEYS = ["n", "ratio", "refine", "features", "seed", "threshold", "voxel", "image", "x", ""]


@pytest.mark.parametrize("cls", _config_classes(), ids=lambda c: c.__name__)
def test_config_set(cls):
    from flexreg.config import load_config, parse_sets

    keys = [*SET_KEYS, *cls.model_fields]

    @FUZZ
    @given(
        items=st.lists(
            st.tuples(
                st.sampled_from(keys) | st.text(max_size=5),
                st.sampled_from(["=", "", "==", " = "]),
                st.sampled_from(HOSTILE) | st.text(max_size=8),
            ).map("".join),
            max_size=4,
        )
    )
    def run(items):
        try:
            config = load_config(cls, None, parse_sets(items))
        except FlexregError as e:
            assert str(e).strip() and "\n" not in str(e).strip(), repr(str(e))
            return
        _valid(cls)(config)

    run()


@FUZZ
@given(text=st.text(alphabet=st.characters(blacklist_categories=["Cs"])))
def test_toml_strings_round_trip(text):
    """Every configuration string written to TOML reads back unchanged (non-BMP characters
    and control characters included)."""
    from flexreg.config import _toml_string, tomllib

    assert tomllib.loads(f"v = {_toml_string(text)}")["v"] == text
