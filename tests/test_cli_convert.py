"""`flexreg convert`: the documented commands against the authors' references, folders,
--keep-float, and bad input (one error line, exit 1, no file written)."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from flexreg.cli import run
from flexreg.core.camera import PinholeCamera, SphericalCamera
from flexreg.core.range_image import from_depth
from flexreg.io.depth import read_depth_png
from flexreg.io.files import MANIFEST
from flexreg.stages import feature_images as I

LASER_ARGS = ["--equirect", "0.87", "2.27", "--depth-kind", "range"]
KINECT_ARGS = ["--pinhole", "519.226", "479.462", "522.23", "272.737", "--depth-kind", "z"]


@pytest.fixture(scope="module")
def conv(shared_data) -> Path:
    return shared_data / "conversions"


def _read(path: Path) -> np.ndarray:
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert img is not None, path
    return img


def _valid3x3(depth_png: Path) -> np.ndarray:
    """Pixels whose whole 3x3 neighbourhood has a depth reading (border excluded)."""
    v = _read(depth_png) > 0
    out = np.zeros_like(v)
    H, W = v.shape
    out[1:-1, 1:-1] = np.logical_and.reduce(
        [v[1 + di : H - 1 + di, 1 + dj : W - 1 + dj] for di in (-1, 0, 1) for dj in (-1, 0, 1)]
    )
    return out


def _max_lsb(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> int:
    return int(np.abs(a.astype(np.int64) - b.astype(np.int64))[mask].max())


def _no_outputs(folder: Path) -> bool:
    return not any(p.suffix in (".png", ".npz") for p in folder.rglob("*"))


# ------------------------------------------------------------------ the documented commands


def test_exact_command_bearing_diagonal_kinect(conv, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    argv = [
        "convert",
        str(conv / "data0-depth.png"),
        *KINECT_ARGS,
        "--kind",
        "bearing-diagonal",
        "--bits",
        "16",
        "--out",
        "b.png",
    ]
    assert run(argv) == 0
    out = _read(tmp_path / "b.png")
    ref = _read(conv / "bearing-diagonal.png")
    assert out.dtype == np.uint16 and out.shape == ref.shape
    assert _max_lsb(out, ref, _valid3x3(conv / "data0-depth.png")) <= 2


def test_exact_command_flexion_laserscan(conv, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    depth = conv / "laserscan-depth.png"
    argv = [
        "convert",
        str(depth),
        *LASER_ARGS,
        "--kind",
        "flexion",
        "--bits",
        "16",
        "--out",
        "f.png",
    ]
    assert run(argv) == 0
    out = _read(tmp_path / "f.png")
    ref = _read(conv / "flexion-laserscan-reference.png")
    mask = _valid3x3(depth)
    assert out.dtype == np.uint16 and out.shape == ref.shape
    # the command is the library on the README's camera, bit for bit
    d = read_depth_png(depth)
    cam = SphericalCamera.from_reference(d.shape[1], d.shape[0], 0.87, 2.27)
    expected, _ = I.quantize(I.convert(from_depth(d, cam), "flexion"), 16)
    np.testing.assert_array_equal(out, expected)
    # laser_intrinsic.txt rounds the polar range to "0.87 2.27"; the reference PNG was made
    # with exactly 50 and 130 degrees. The 0.3% shorter polar step changes the shape of every
    # neighbourhood slightly: measured 207 LSB at worst (0.3% of full scale), 42 on average.
    diff = np.abs(out.astype(np.int64) - ref)[mask]
    assert diff.max() <= 230 and diff.mean() < 60
    # with the exact angles the same command reproduces the reference within 2 LSB
    exact = [str(math.radians(50.0)), str(math.radians(130.0))]
    argv = [
        "convert",
        str(depth),
        "--equirect",
        *exact,
        "--depth-kind",
        "range",
        "--kind",
        "flexion",
        "--bits",
        "16",
        "--out",
        "f_exact.png",
    ]
    assert run(argv) == 0
    assert _max_lsb(_read(tmp_path / "f_exact.png"), ref, mask) <= 2


@pytest.mark.parametrize(
    ("kind", "bits", "name", "tol"),
    [
        ("flexion", 16, "flexion-reference.png", 2),
        ("bearing-vertical", 8, "bearing-vertical.png", 1),
        ("bearing-antidiagonal", 8, "bearing-antidiagonal.png", 2),  # see test_images.py
    ],
)
def test_kinect_references_through_cli(conv, tmp_path, kind, bits, name, tol):
    out = tmp_path / f"{kind}.png"
    argv = [
        "convert",
        str(conv / "data0-depth.png"),
        *KINECT_ARGS,
        "--kind",
        kind,
        "--bits",
        str(bits),
        "--out",
        str(out),
    ]
    assert run(argv) == 0
    img, ref = _read(out), _read(conv / name)
    assert img.dtype == ref.dtype
    assert _max_lsb(img, ref, _valid3x3(conv / "data0-depth.png")) <= tol


# ------------------------------------------------------------------ options and folders


def test_keep_float_median_and_other_kinds(conv, tmp_path):
    out = tmp_path / "deep" / "k.png"
    argv = [
        "convert",
        str(conv / "data0-depth.png"),
        "--pinhole",
        "519.226",
        "479.462",
        "522.23",
        "272.737",
        "--depth-scale",
        "0.001",
        "--kind",
        "flexion-angle",
        "--n",
        "5",
        "--median",
        "3",
        "--keep-float",
        "--out",
        str(out),
    ]
    assert run(argv) == 0
    png = _read(out)
    assert png.dtype == np.uint8 and png.shape == (540, 960)
    with np.load(out.with_suffix(".npz")) as z:
        image, valid = z["image"], z["valid"]
        assert str(z["kind"]) == "flexion-angle" and int(z["n"]) == 5 and int(z["median"]) == 3
    assert image.dtype == np.float32 and image.shape == (540, 960)
    d = read_depth_png(conv / "data0-depth.png", depth_scale=0.001)
    rimg = from_depth(d, PinholeCamera(519.226, 479.462, 522.23, 272.737, 960, 540))
    rimg.xyz = rimg.xyz.astype(np.float32)  # the command reads scans as float32 points
    np.testing.assert_array_equal(image, I.convert(rimg, "flexion-angle", n=5, median=3))
    np.testing.assert_array_equal(valid, np.isfinite(image))
    np.testing.assert_array_equal(png, I.quantize(image, 8)[0])
    for kind in ("range", "curvature-mean", "bearing-horizontal"):
        o = tmp_path / f"{kind}.png"
        assert (
            run(
                [
                    "convert",
                    str(conv / "laserscan-depth.png"),
                    "--equirect",
                    "0.87",
                    "2.27",
                    "--kind",
                    kind,
                    "--stretch",
                    "clahe",
                    "--out",
                    str(o),
                ]
            )
            == 0
        )
        assert _read(o).shape == (397, 1799)


def test_folder_input(conv, tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    shutil.copy(conv / "laserscan-depth.png", src / "a.png")
    shutil.copy(conv / "laserscan-depth.png", src / "b.png")
    (src / "notes.txt").write_text("not a scan")
    out = tmp_path / "out"
    argv = [
        "convert",
        str(src),
        *LASER_ARGS,
        "--kind",
        "flexion",
        "--bits",
        "16",
        "--keep-float",
        "--out",
        str(out),
    ]
    assert run(argv) == 0
    assert sorted(p.name for p in out.iterdir() if p.name != MANIFEST) == [
        "a.npz", "a.png", "b.npz", "b.png",
    ]  # fmt: skip
    single = tmp_path / "single.png"
    assert (
        run(
            [
                "convert",
                str(src / "a.png"),
                *LASER_ARGS,
                "--kind",
                "flexion",
                "--bits",
                "16",
                "--out",
                str(single),
            ]
        )
        == 0
    )
    np.testing.assert_array_equal(_read(out / "a.png"), _read(single))
    np.testing.assert_array_equal(_read(out / "b.png"), _read(single))


def test_folder_with_a_bad_file(conv, tmp_path, capsys):
    src = tmp_path / "in"
    src.mkdir()
    shutil.copy(conv / "laserscan-depth.png", src / "good.png")
    (src / "broken.png").write_bytes(b"\x89PNG not really")
    out = tmp_path / "out"
    argv = ["convert", str(src), *LASER_ARGS, "--kind", "flexion", "--out", str(out)]
    assert run(argv) == 1
    assert [p.name for p in out.iterdir() if p.name != MANIFEST] == ["good.png"]
    err = capsys.readouterr().err
    assert f"error: {src / 'broken.png'}: " in err


# ------------------------------------------------------------------ bad input


@pytest.mark.parametrize(
    ("args", "culprit"),
    [
        (["missing.png", *LASER_ARGS, "--kind", "flexion"], "missing.png"),
        (["{laser}", "--kind", "flexion"], "laserscan-depth.png"),  # no intrinsics
        (["{laser}", *LASER_ARGS, "--kind", "sobel"], "--kind"),
        (["{laser}", *LASER_ARGS, "--kind", "flexion", "--n", "4"], "--n"),
        (["{laser}", *LASER_ARGS, "--kind", "flexion", "--median", "4"], "--median"),
        (["{laser}", *LASER_ARGS, "--kind", "flexion", "--bits", "12"], "--bits"),
        (
            ["{laser}", "--equirect", "0.87", "2.27", "--depth-kind", "z", "--kind", "flexion"],
            "--depth-kind",
        ),
        (["{laser}", *LASER_ARGS, *KINECT_ARGS[:5], "--kind", "flexion"], "--pinhole/--equirect"),
        (["{laser}", "--equirect", "2.27", "0.87", "--kind", "flexion"], "--equirect"),
        (["{laser}", "--pinhole", "-5", "5", "1", "1", "--kind", "flexion"], "--pinhole"),
        (["{rgb}", "--pinhole", "5", "5", "1", "1", "--kind", "flexion"], "rgb.png"),
        (["{broken}", *LASER_ARGS, "--kind", "flexion"], "broken.png"),
    ],
)
def test_bad_input_exits_1_and_writes_nothing(conv, tmp_path, capsys, args, culprit):
    rgb = tmp_path / "rgb.png"
    cv2.imwrite(str(rgb), np.zeros((4, 5, 3), np.uint8))
    broken = tmp_path / "broken.png"
    broken.write_bytes(b"\x89PNG\r\n\x1a\n truncated")
    subs = {
        "{laser}": str(conv / "laserscan-depth.png"),
        "{rgb}": str(rgb),
        "{broken}": str(broken),
    }
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    argv = ["convert", *[subs.get(a, a) for a in args], "--out", str(out_dir / "o.png")]
    assert run(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and culprit in err[0], err
    assert not any(out_dir.iterdir())


def test_bad_output_name(conv, tmp_path, capsys):
    argv = [
        "convert",
        str(conv / "laserscan-depth.png"),
        *LASER_ARGS,
        "--kind",
        "flexion",
        "--out",
        str(tmp_path / "o.jpg"),
    ]
    assert run(argv) == 1
    assert "o.jpg: output must be a .png file" in capsys.readouterr().err
    assert _no_outputs(tmp_path) and not (tmp_path / "o.jpg").exists()


def test_convert_uses_camera_sidecar(tmp_path):
    """A depth PNG with a ``<stem>.camera.json`` needs no intrinsics options (the demo data)."""
    from conftest import REPO

    from flexreg.io import read_scan
    from flexreg.stages.feature_images import convert
    from flexreg.stages.projection import range_image

    src = REPO / "data" / "laserscan" / "laserscan-depth.png"
    out = tmp_path / "f.png"
    assert (
        run(
            [
                "convert",
                str(src),
                "--kind",
                "flexion",
                "--n",
                "5",
                "--bits",
                "16",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    expect = convert(range_image(read_scan(src)), "flexion", n=5)
    got = cv2.imread(str(out), cv2.IMREAD_UNCHANGED)
    valid = np.isfinite(expect)
    np.testing.assert_array_equal(got[~valid], 0)
    assert np.abs(got[valid].astype(np.int64) - np.rint(expect[valid] * 65535)).max() <= 1


# ------------------------------------------------------------------ the configuration


def test_config_show_convert_round_trip(tmp_path, capsys):
    from flexreg.cli.convert import ConvertConfig
    from flexreg.config import load_config

    assert run(["config", "show", "convert"]) == 0
    path = tmp_path / "c.toml"
    path.write_text(capsys.readouterr().out)
    config = load_config(ConvertConfig, path)
    assert config == ConvertConfig(kind="flexion")
    assert (config.n, config.median, config.bits, config.stretch) == (3, 0, 8, "none")


def test_kinds_are_the_stage_kinds():
    """The configuration accepts exactly the kinds ``convert`` knows, and nothing else."""
    from flexreg.cli.convert import ConvertConfig
    from flexreg.errors import ConfigError

    for kind in I.KINDS:
        assert ConvertConfig(kind=kind).kind == kind
    schema = ConvertConfig.model_json_schema()["properties"]["kind"]
    assert schema["enum"] == list(I.KINDS)
    with pytest.raises(ConfigError, match="unknown kind 'intensity'"):
        ConvertConfig(kind="intensity")


def test_config_file_gives_the_same_image_as_the_options(conv, tmp_path):
    settings = {"kind": "bearing-vertical", "n": 5, "median": 3, "bits": 16, "stretch": "clahe"}
    by_options = tmp_path / "options.png"
    argv = ["convert", str(conv / "laserscan-depth.png"), *LASER_ARGS, "--keep-float"]
    options = [a for k, v in settings.items() for a in (f"--{k}", str(v))]
    assert run([*argv, *options, "--out", str(by_options)]) == 0
    toml = tmp_path / "c.toml"
    toml.write_text("".join(f"{k} = {v!r}\n".replace("'", '"') for k, v in settings.items()))
    by_file = tmp_path / "file.png"
    assert run([*argv, "--config", str(toml), "--out", str(by_file)]) == 0
    a, b = _read(by_options), _read(by_file)
    assert a.dtype == np.uint16
    np.testing.assert_array_equal(a, b)
    # the .npz stores the effective configuration; --set overrides the file
    with np.load(by_file.with_suffix(".npz")) as z:
        assert json.loads(str(z["config"])) == settings
    by_set = tmp_path / "set.png"
    assert run([*argv, "--config", str(toml), "--set", "bits=8", "--out", str(by_set)]) == 0
    assert _read(by_set).dtype == np.uint8


def test_set_reaches_every_field_and_stretch_none(conv, tmp_path):
    src = str(conv / "laserscan-depth.png")
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    assert run(["convert", src, *LASER_ARGS, "--kind", "flexion", "--out", str(a)]) == 0
    sets = ["--set", "kind=flexion", "--set", "stretch=none", "--set", "n=3"]
    assert run(["convert", src, *LASER_ARGS, *sets, "--out", str(b)]) == 0
    np.testing.assert_array_equal(_read(a), _read(b))


@pytest.mark.parametrize(
    ("toml", "extra", "message"),
    [
        ('kind = "flexion"\nn = 4\n', [], "error: {toml}: n: must be an odd grid size"),
        ('kind = "flexion"\nbits = 12\n', [], "error: {toml}: bits: must be one of 8, 16"),
        ('kind = "sobel"\n', [], "error: {toml}: kind: unknown kind 'sobel'; known: flexion"),
        ('kind = "flexion"\nnn = 5\n', [], "error: {toml}: nn: unknown setting; did you mean n?"),
        ('kind = "flexion"\nn = \n', [], "error: {toml}: not valid TOML"),
        ("", ["--set", "median=4"], "error: --set median: must be one of 0, 3, 5 (got 4)"),
        ("", ["--set", "stretch=hist"], "error: --set stretch: must be one of none, percentile"),
        ("", ["--set", "nn=5"], "error: --set nn: unknown setting"),
        ("", ["--set", "bits"], "error: --set 'bits': expected KEY=VALUE"),
        ("", ["--set", "n=5", "--n", "5"], "error: --n: also given as --set n=...; give it one"),
        (None, [], "error: --kind: required"),
    ],
)
def test_bad_config_is_one_line_and_writes_nothing(conv, tmp_path, capsys, toml, extra, message):
    path = tmp_path / "c.toml"
    if toml is not None:
        path.write_text(toml)
    args = ["--config", str(path)] if toml else (["--kind", "flexion"] if toml == "" else [])
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    argv = ["convert", str(conv / "laserscan-depth.png"), *LASER_ARGS, *args, *extra]
    assert run([*argv, "--out", str(out_dir / "o.png")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(message.format(toml=path)), err
    assert not any(out_dir.iterdir())


def test_out_may_not_overwrite_the_input(conv, tmp_path, capsys):
    src = tmp_path / "d.png"
    shutil.copy(conv / "laserscan-depth.png", src)
    before = src.read_bytes()
    assert run(["convert", str(src), *LASER_ARGS, "--kind", "range", "--out", str(src)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: --out: {src}: is also an input; refusing to overwrite it"]
    assert src.read_bytes() == before
