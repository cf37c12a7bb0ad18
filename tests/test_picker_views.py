"""What the picker draws to be seen: the projected lidar's dots keep their size on screen and
stay apart at any zoom, and the panorama says where the camera looks before the first solve
(not known yet; roughly, from two pairs; the initial guess's view)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from test_picker import picker_scene, true_clicks

from flexreg.calibration import scan_range_image
from flexreg.picker import PickSession
from flexreg.picker.views import OVERLAY_DOT_PX, OVERLAY_SPACING_PX, overlay_rgba


@pytest.mark.parametrize("zoom", [0.25, 1.0, 4.0])
def test_overlay_dots_keep_their_screen_size_and_spacing(zoom):
    s = picker_scene()
    layer = overlay_rgba(s["scan"].points, s["intrinsics"], s["T"], (640, 480), zoom=zoom)
    alpha = layer[..., 3] > 0
    n, _, stats, _ = cv2.connectedComponentsWithStats(alpha.astype(np.uint8), 8)
    assert n > 50
    # a dot with its rim is at least OVERLAY_DOT_PX screen pixels across (a pixel at least)
    widths = stats[1:, cv2.CC_STAT_WIDTH]
    assert np.median(widths) * zoom >= OVERLAY_DOT_PX
    if zoom < 1:  # thinned: at most one dot per square of OVERLAY_SPACING_PX screen pixels
        cell = OVERLAY_SPACING_PX / zoom
        assert n - 1 <= (640 / cell + 1) * (480 / cell + 1)
    # the rim is dark and the dots bright: seen on light and dark pictures alike
    grey = layer[..., :3].astype(float).mean(axis=2)
    assert grey[alpha].min() < 40 and grey[alpha].max() > 150


def test_panorama_says_where_the_camera_looks_before_the_first_solve(tmp_path):
    s = picker_scene()
    kw = {"out": tmp_path / "p.csv", "result_out": tmp_path / "p.json"}
    session = PickSession(s["image"], s["scan"], s["intrinsics"], **kw)
    view = session.state()["lidar"]["camera_view"]
    assert view["box"] is None and view["source"] is None and "not known yet" in view["note"]
    clicks = true_clicks(scan_range_image(s["scan"]), 2)
    for c in clicks:
        session.add_pair(c["u"], c["v"], c["mode"], c["x"], c["y"])
    rough = session.state()["lidar"]["camera_view"]
    assert rough["source"] == "pairs" and "2 pairs" in rough["note"]
    guessed = PickSession(s["image"], s["scan"], s["intrinsics"], T_init=s["T"], **kw)
    known = guessed.state()["lidar"]["camera_view"]
    assert known["source"] == "initial guess"
    # the rough view (camera taken at the lidar's centre, 33 cm from the truth, 7 degrees
    # turned) overlaps the true one by most of it
    (a0, b0, a1, b1), (c0, d0, c1, d1) = rough["box"], known["box"]
    inter = max(0, min(a1, c1) - max(a0, c0)) * max(0, min(b1, d1) - max(b0, d0))
    assert inter > 0.5 * (c1 - c0) * (d1 - d0)
