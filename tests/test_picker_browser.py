"""`flexreg pick` end to end in a real headless Chromium: the command serves a synthetic
camera-lidar scene with a known extrinsic, the test clicks 8 pairs at their true positions (the
lidar click first; its partner where the snapped return truly projects), watches the live solve
reach the truth within 0.2 deg / 1 cm, drags a mark away and back, saves, and `flexreg calibrate
--pairs` on the saved CSV gives the same result; then asks for suggestions, rejects one, deletes
a pair, and the stopped command warns that the last changes were not saved. With
FLEXREG_WRITE_FIGURES=1 the page's screenshot becomes docs/figures/picker.png."""

from __future__ import annotations

import json
import os
import queue
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from browser import chromium_page
from conftest import REPO, run_cli
from test_picker import picker_scene, true_clicks, write_scene

from flexreg.calibration import project_points, scan_range_image
from flexreg.core.transforms import rotation_error_deg, translation_error_m

pytestmark = pytest.mark.slow


def _start_pick(argv: list[str], timeout_s: float = 120.0) -> tuple[subprocess.Popen, str]:
    """Run ``flexreg pick`` in a subprocess; return it and the URL it printed."""
    cmd = [sys.executable, "-c", "from flexreg.cli import main; main()", "pick", *argv]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    lines: queue.Queue[str] = queue.Queue()
    threading.Thread(target=lambda: [lines.put(line) for line in proc.stdout], daemon=True).start()
    try:
        while True:
            line = lines.get(timeout=timeout_s)
            if "open http://127.0.0.1:" in line:
                return proc, line.split("open ", 1)[1].strip()
    except queue.Empty:
        proc.kill()
        raise AssertionError(f"flexreg pick printed no URL: {proc.stderr.read()}") from None


def _client_xy(page, panel: str, x: float, y: float) -> tuple[float, float]:
    """Page coordinates of pixel centre ``(x, y)`` of a panel's image (the page's own mapping:
    zoom, pan and a mirrored panorama included)."""
    X, Y = page.evaluate(f"window.picker.panels.{panel}.toClient({x}, {y})")
    return float(X), float(Y)


def test_pick_in_chromium_reaches_the_truth_and_saves(tmp_path):
    s = picker_scene()
    files = write_scene(tmp_path / "scene")
    out = tmp_path / "picked" / "pairs.csv"
    argv = ["--image", files["image"], "--camera", files["camera"], "--scan", files["scan"]]
    argv = [str(a) for a in argv] + ["--out", str(out), "--no-browser", "--port", "0"]
    proc, url = _start_pick(argv)
    try:
        with chromium_page() as page:
            page.goto(url)
            page.wait_for_selector("body[data-ready='1']")
            points = s["scan"].points
            candidates = true_clicks(scan_range_image(s["scan"]), 8) + true_clicks(
                scan_range_image(s["scan"]), 8, seed=5
            )
            picked = 0
            for c in candidates:
                page.mouse.click(*_client_xy(page, "lidar", c["x"], c["y"]))
                page.wait_for_selector("#pending[data-side='lidar']")
                P = np.array(json.loads(page.get_attribute("#pending", "data-point")))
                k = int(np.argmin(np.linalg.norm(points - P, axis=1)))
                if not s["visible"][k]:  # snapped onto a return the camera does not see
                    page.keyboard.press("Escape")
                    continue
                uv, _ = project_points(P, s["intrinsics"], s["T"])
                page.mouse.click(*_client_xy(page, "camera", uv[0, 0], uv[0, 1]))
                picked += 1
                page.wait_for_function(
                    f"document.querySelectorAll('#pairs tbody tr').length === {picked}"
                )
                if picked == 8:
                    break
            assert picked == 8
            page.wait_for_function(
                "document.querySelector('#solution').dataset.source === 'solution'"
            )
            T = np.array(json.loads(page.get_attribute("#T", "data-t")))
            rot, trans = rotation_error_deg(T, s["T"]), translation_error_m(T, s["T"])
            assert rot < 0.2 and trans < 0.01, (rot, trans)
            assert page.locator("#pairs tr.outlier").count() == 0
            assert not out.exists()  # nothing written before Save

            _drag_away_and_back(page, T)
            _screenshot(page, tmp_path, c)
            page.click("#save")
            page.wait_for_selector("#message.info:has-text('saved')")
            _suggest_reject_delete(page)
            assert not page.errors, page.errors
    finally:
        proc.terminate()  # the server shuts down gracefully on SIGTERM, as on Ctrl-C
        rc = proc.wait(timeout=30)
    assert rc == 0 and "the last changes were not saved (7 pairs" in proc.stderr.read()
    result = out.with_name("pairs-calib.json")
    assert out.is_file() and result.is_file()
    np.testing.assert_allclose(json.loads(result.read_text())["T_camera_lidar"], T, atol=1e-9)
    calib = tmp_path / "calib.json"
    rc, _, err = run_cli(
        ["calibrate", "--image", files["image"], "--camera", files["camera"], "--scan",
         files["scan"], "--pairs", out, "--out", calib]
    )  # fmt: skip
    assert rc in (0, 3), err
    np.testing.assert_allclose(json.loads(calib.read_text())["T_camera_lidar"], T, atol=1e-9)


def _drag_away_and_back(page, T: np.ndarray) -> None:
    """Drag pair 1's camera mark 12 px away (it becomes an outlier), then back onto its pixel
    (the solution returns)."""
    pair = page.evaluate("window.picker.state().pairs[0]")
    x, y = _client_xy(page, "camera", pair["u"], pair["v"])
    for dx, dy in ((12.0, 0.0), (0.0, 0.0)):
        rev = int(page.evaluate("document.body.dataset.revision"))
        start = page.evaluate("window.picker.state().pairs[0]")
        page.mouse.move(*_client_xy(page, "camera", start["u"], start["v"]))
        page.mouse.down()
        page.mouse.move(x + dx, y + dy, steps=6)
        page.mouse.up()
        page.wait_for_function(f"Number(document.body.dataset.revision) > {rev}")
        outlier = page.locator("#pairs tbody tr:first-child.outlier").count() == 1
        assert outlier == (dx != 0.0)
    back = np.array(json.loads(page.get_attribute("#T", "data-t")))
    np.testing.assert_allclose(back, T, atol=1e-6)


def _suggest_reject_delete(page) -> None:
    """After Save: suggestions around the solution (one rejected), then pair 8 deleted (the
    page then says the state is not saved)."""
    page.click("#suggest")
    page.wait_for_selector("#message.info:has-text('suggestion(s)')")
    n = page.locator("#suggestions tbody tr").count()
    assert n >= 1
    page.click("#suggestions tbody tr:first-child .reject")
    page.wait_for_function(f"document.querySelectorAll('#suggestions tbody tr').length === {n - 1}")
    page.click("#pairs tbody tr:last-child button")
    page.wait_for_function("document.querySelectorAll('#pairs tbody tr').length === 7")
    assert "not saved" in page.inner_text("#status")


def _screenshot(page, tmp_path: Path, hover: dict) -> None:
    """The page with the solution: the lidar view zoomed to the camera's field of view and the
    predicted partner of a hovered lidar return; docs/figures/picker.png on request."""
    page.click("#fit-camera")  # the lidar view zoomed to what the camera sees
    page.wait_for_function("window.picker.panels.lidar.s > 1.5")
    page.mouse.move(*_client_xy(page, "lidar", hover["x"] + 12, hover["y"] + 2))
    page.wait_for_selector("#camera-panel g.ghost", state="attached")
    path = tmp_path / "picker.png"
    if os.environ.get("FLEXREG_WRITE_FIGURES") == "1":
        path = REPO / "docs" / "figures" / "picker.png"
    page.screenshot(path=str(path))
    assert path.stat().st_size > 10_000
