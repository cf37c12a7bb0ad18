"""The README's picker walkthrough, end to end in headless Chromium on `flexreg synth --rig`
output: the commands are read from the README (a smaller station and a seed added to `synth`,
`--no-browser --port 0` to `pick`). Before any pair the page says it does not know where the
camera looks, from the second pair on it outlines a rough view holding the camera's true view,
then ten pairs are clicked as a user would (a lidar return, then its partner zoomed in on the
camera image), the projected lidar shows, Save writes the pairs, and `calibrate --truth` lands
within 0.1 deg / 1 cm of the rig's truth.

Why 0.1 deg / 1 cm holds whatever the machine: each lidar click snaps to a real return and its
partner is that return's true projection, clicked at a zoom of at least 10 screen pixels per
camera pixel, so every camera pixel is off by at most half a screen pixel, 0.05 camera px
(checked below on the page's own record). With f = 512 px that is 1e-4 rad (0.006 deg) per
pair; ten pairs spread over the image cannot turn it into 0.1 deg (16 times as much), and at
the scene's few metres it moves the camera's centre by well under a centimetre."""

from __future__ import annotations

import json
import re
import shlex

import numpy as np
import pytest
from browser import chromium_page
from conftest import REPO, run_cli
from test_picker_browser import _client_xy, _start_pick

from flexreg.calibration import project_points, scan_range_image
from flexreg.io import read_scan
from flexreg.io.intrinsics import read_extrinsic, read_intrinsics

pytestmark = pytest.mark.slow

#: least zoom of the camera panel when its partner is clicked, screen pixels per camera pixel
CLICK_ZOOM = 10.0


def readme_walkthrough() -> list[list[str]]:
    """The `flexreg` commands of the README's camera-lidar walkthrough, in order."""
    text = (REPO / "README.md").read_text()
    section = text.split("## Calibrate a camera against a lidar", 1)[1].split("\n## ", 1)[0]
    commands = []
    for block in re.findall(r"```sh\n(.*?)```", section, flags=re.S):
        joined = re.sub(r"\\\n\s*", " ", block)
        for line in joined.splitlines():
            if line.strip().startswith(".venv/bin/flexreg "):
                commands.append(shlex.split(line)[1:])
    return commands


def _in(folder, argv: list[str]) -> list[str]:
    """``argv`` with the README's ``rig/...`` paths inside ``folder``."""
    return [str(folder / a) if a.startswith("rig") else a for a in argv]


def _targets(folder, n_cols: int = 5, n_rows: int = 3) -> list[dict]:
    """Panorama pixels of returns the camera sees, one per cell of a grid over the image."""
    scan = read_scan(folder / "rig" / "station_00.ptx")
    intr = read_intrinsics(folder / "rig" / "camera.json")
    T = read_extrinsic(folder / "rig" / "gt.json")
    ri = scan_range_image(scan)
    rows, cols = np.nonzero(ri.valid & (ri.index >= 0))
    uv, z = project_points(scan.points[ri.index[rows, cols]], intr, T)
    W, H = intr.size
    ok = (z > 0) & (uv[:, 0] > 10) & (uv[:, 0] < W - 11) & (uv[:, 1] > 10) & (uv[:, 1] < H - 11)
    cells = np.floor(uv[ok] / [W / n_cols, H / n_rows]).astype(int)
    rng = np.random.default_rng(0)
    out = []
    for cell in np.unique(cells, axis=0):
        k = rng.choice(np.flatnonzero((cells == cell).all(axis=1)))
        out.append({"x": float(cols[ok][k]), "y": float(rows[ok][k])})
    return out


def _click_partner(page, u: float, v: float) -> None:
    """Zoom the camera panel in at ``(u, v)`` (the wheel, as a user does), click it, zoom out."""
    page.mouse.move(*_client_xy(page, "camera", u, v))
    while page.evaluate("window.picker.panels.camera.s") < CLICK_ZOOM:
        page.mouse.wheel(0, -1000)
        page.wait_for_timeout(50)
    page.mouse.click(*_client_xy(page, "camera", u, v))
    page.evaluate("window.picker.panels.camera.fit()")


def test_readme_walkthrough_on_a_synthetic_rig(tmp_path):
    synth, pick, calibrate = readme_walkthrough()
    assert synth[:2] == ["synth", "--rig"] and pick[0] == "pick" and calibrate[0] == "calibrate"
    assert "--truth" in calibrate
    rc, _, err = run_cli([*_in(tmp_path, synth), "--resolution", "512x256", "--seed", "2"])
    assert rc == 0, err
    truth = read_extrinsic(tmp_path / "rig" / "gt.json")
    intr = read_intrinsics(tmp_path / "rig" / "camera.json")
    out = tmp_path / "rig" / "pairs.csv"
    proc, url = _start_pick([*_in(tmp_path, pick[1:]), "--no-browser", "--port", "0"])
    try:
        with chromium_page() as page:
            page.goto(url)
            page.wait_for_selector("body[data-ready='1']")
            assert "not known yet" in page.inner_text("#view-note")
            picked = 0
            for t in _targets(tmp_path):
                page.mouse.click(*_client_xy(page, "lidar", t["x"], t["y"]))
                page.wait_for_selector("#pending[data-side='lidar']")
                P = np.array(json.loads(page.get_attribute("#pending", "data-point")))
                uv, z = project_points(P, intr, truth)
                u, v = float(uv[0, 0]), float(uv[0, 1])
                if not (z[0] > 0 and 0 <= u <= intr.width - 1 and 0 <= v <= intr.height - 1):
                    page.keyboard.press("Escape")  # snapped onto a return outside the picture
                    continue
                _click_partner(page, u, v)
                picked += 1
                page.wait_for_function(
                    f"document.querySelectorAll('#pairs tbody tr').length === {picked}"
                )
                if picked == 2:
                    _rough_view_holds_the_truth(page, tmp_path, intr, truth)
                if picked == 10:
                    break
            assert picked == 10
            page.wait_for_function(
                "document.querySelector('#solution').dataset.source === 'solution'"
            )
            _clicks_within_half_a_screen_pixel(page, intr, truth)
            page.wait_for_function(
                "(() => { const o = document.querySelector('#camera-panel img.overlay');"
                " return !o.hidden && o.complete && o.naturalWidth > 0"
                " && o.src.includes('zoom='); })()"
            )
            assert page.locator("#lidar-panel g.camera-view:not(.rough)").count() == 1
            page.click("#save")
            page.wait_for_selector("#message.info:has-text('saved')")
            assert not page.errors, page.errors
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    assert out.is_file()
    rc, text, err = run_cli(_in(tmp_path, calibrate))
    assert rc in (0, 3), err
    assert "error vs truth" in text
    result = json.loads((tmp_path / "rig" / "calib.json").read_text())
    errors = result["error_vs_truth"]
    assert errors["rotation_deg"] < 0.1 and errors["translation_m"] < 0.01, errors
    assert (tmp_path / "rig" / "overlay.png").is_file()


def _rough_view_holds_the_truth(page, folder, intr, truth) -> None:
    """After two pairs: the rough view is outlined and holds the middle of the camera's true
    view on the panorama (the centre pixel's return)."""
    page.wait_for_selector("#lidar-panel g.camera-view.rough", state="attached")
    assert page.get_attribute("#view-note", "data-source") == "pairs"
    x0, y0, x1, y1 = page.evaluate("window.picker.state().lidar.camera_view.box")
    scan = read_scan(folder / "rig" / "station_00.ptx")
    ri = scan_range_image(scan)
    rows, cols = np.nonzero(ri.valid & (ri.index >= 0))
    uv, z = project_points(scan.points[ri.index[rows, cols]], intr, truth)
    centre = np.array([intr.width / 2, intr.height / 2])
    k = int(np.argmin(np.where(z > 0, np.linalg.norm(uv - centre, axis=1), np.inf)))
    assert x0 <= cols[k] <= x1 and y0 <= rows[k] <= y1


def _clicks_within_half_a_screen_pixel(page, intr, truth) -> None:
    """The page recorded every camera pixel within half a screen pixel at CLICK_ZOOM of the
    true projection of its pair's return."""
    pairs = page.evaluate("window.picker.state().pairs")
    P = np.array([p["point"] for p in pairs])
    uv, _ = project_points(P, intr, truth)
    got = np.array([[p["u"], p["v"]] for p in pairs])
    assert np.abs(got - uv).max() <= 0.5 / CLICK_ZOOM + 1e-9
