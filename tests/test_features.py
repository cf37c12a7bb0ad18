"""Features, matching and 3D lifting on images with known geometry."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from flexreg.core.camera import SphericalCamera
from flexreg.core.range_image import from_depth
from flexreg.errors import ConfigError
from flexreg.stages.correspondences import lift
from flexreg.stages.keypoints import (
    METHODS,
    create_detector,
    detect_and_describe,
    tiles,
    to_uint8,
)
from flexreg.stages.matching import match


def _texture(rng, h=240, w=320):
    img = cv2.GaussianBlur(rng.random((h, w)).astype(np.float32), (0, 0), 2.0)
    img = (img - img.min()) / (img.max() - img.min())
    return (img * 255).astype(np.uint8)


@pytest.mark.parametrize("method", ["sift", "orb", "akaze", "kaze", "brisk"])
def test_match_recovers_a_known_shift(method, rng):
    img = _texture(rng, 260, 360)
    a, b = img[10:250, 20:340], img[0:240, 0:320]  # b(x, y) = a(x - 20, y - 10)
    fa = detect_and_describe(a, method)
    fb = detect_and_describe(b, method)
    assert len(fa) > 30 and len(fb) > 30
    m = match(fa, fb, ratio=0.8)
    assert len(m) > 15
    d = fb.xy[m[:, 1]] - fa.xy[m[:, 0]]
    good = np.linalg.norm(d - [20.0, 10.0], axis=1) < 1.5
    assert good.mean() > 0.9


def test_unknown_and_missing_methods():
    with pytest.raises(ConfigError, match="unknown feature method"):
        create_detector("harris")
    if not hasattr(cv2, "SURF_create") and not hasattr(
        getattr(cv2, "xfeatures2d", None), "SURF_create"
    ):
        with pytest.raises(ConfigError, match="kaze"):
            create_detector("surf")
    assert set(METHODS) >= {"sift", "orb", "akaze", "kaze", "brisk"}


def test_mask_keeps_features_off_invalid_holes(rng):
    img = _texture(rng)
    mask = np.ones(img.shape, dtype=bool)
    mask[100:140, 100:160] = False
    img[~mask] = 0  # a no-return hole: strong artificial corners
    f = detect_and_describe(img, "sift", mask, border_px=3)
    # distance of each keypoint to the hole: beyond the margin and half the keypoint's size
    dx = np.maximum(np.maximum(100 - f.xy[:, 0], f.xy[:, 0] - 159), 0)
    dy = np.maximum(np.maximum(100 - f.xy[:, 1], f.xy[:, 1] - 139), 0)
    dist = np.hypot(dx, dy)
    assert len(f) > 20 and (dist >= np.maximum(2.5, 0.5 * f.size - 1.0)).all()
    plain = detect_and_describe(img, "sift")  # unmasked: the hole's edges attract keypoints
    pdx = np.maximum(np.maximum(100 - plain.xy[:, 0], plain.xy[:, 0] - 159), 0)
    pdy = np.maximum(np.maximum(100 - plain.xy[:, 1], plain.xy[:, 1] - 139), 0)
    assert (np.hypot(pdx, pdy) < 2).sum() > 5


def test_wrap_finds_seam_features_once(rng):
    img = _texture(rng, 200, 400)
    rolled = np.roll(img, 200, axis=1)  # the seam now runs through the old middle
    f = detect_and_describe(rolled, "sift", wrap=True)
    plain = detect_and_describe(rolled, "sift", wrap=False)
    seam = lambda xy: ((xy[:, 0] < 8) | (xy[:, 0] > 392)).sum()  # noqa: E731
    assert seam(f.xy) > seam(plain.xy)
    assert (f.xy[:, 0] >= 0).all() and (f.xy[:, 0] < 400).all()
    # no keypoint twice (SIFT may repeat a location with another orientation)
    key = np.round(np.column_stack([f.xy, f.angle]), 2)
    assert len(np.unique(key, axis=0)) == len(key)


def test_wrap_keeps_the_hole_support_rule(rng):
    # on a full-turn panorama too, keypoints closer to a no-return hole than ``support`` times
    # their size are dropped (a large support factor makes the rule bite)
    img = _texture(rng, 200, 400)
    mask = np.ones(img.shape, dtype=bool)
    mask[80:120, 180:230] = False
    img[~mask] = 0
    dist = cv2.distanceTransform(mask.astype(np.uint8), cv2.DIST_L2, 5)
    for wrap in (False, True):
        f = detect_and_describe(img, "sift", mask, wrap=wrap, support=4.0)
        d = dist[np.rint(f.xy[:, 1]).astype(int), np.rint(f.xy[:, 0]).astype(int) % 400]
        assert len(f) > 20 and (d >= 4.0 * f.size).all(), wrap


def test_to_uint8():
    assert to_uint8(np.array([[0, 65535]], dtype=np.uint16)).tolist() == [[0, 255]]
    assert to_uint8(np.array([[0.0, 1.0, np.nan]])).tolist() == [[0, 255, 0]]


def test_lift_bilinear_and_discontinuity():
    cam = SphericalCamera.from_reference(40, 20, 0.5, 2.5)
    r = np.full(cam.shape, 5.0)
    r[:, 30:35] = 9.0  # depth jumps between columns 29|30 and 34|35
    r[5, 5] = np.nan
    img = from_depth(r, cam)
    pts, ok = lift(img, np.array([[10.5, 8.25], [29.5, 8.0], [4.5, 4.5], [39.5, 10.0], [-3, 1]]))
    # [-3, 1] wraps to column 37 on a full-turn image
    assert ok.tolist() == [True, False, False, True, True]
    exp = 0.75 * (0.5 * img.xyz[8, 10] + 0.5 * img.xyz[8, 11]) + 0.25 * (
        0.5 * img.xyz[9, 10] + 0.5 * img.xyz[9, 11]
    )
    np.testing.assert_allclose(pts[0], exp, atol=1e-12)
    # at the seam the neighbours of column 39 are 39 and 0 (full turn)
    np.testing.assert_allclose(pts[3], 0.5 * img.xyz[10, 39] + 0.5 * img.xyz[10, 0], atol=1e-12)
    assert np.isnan(pts[1]).all()


def test_sift_in_strips_finds_the_keypoints_of_the_whole_image(rng):
    """SIFT strip by strip (one strip's scale space at a time): the same keypoints and
    descriptors as on the whole image except a few large ones near the strips' edges, and no
    keypoint twice."""
    img = _texture(rng, 600, 400)
    mask = np.ones(img.shape, bool)
    mask[250:300, 100:200] = False
    whole = detect_and_describe(img, "sift", mask)
    strips = detect_and_describe(img, "sift", mask, strip_rows=128)
    assert len(whole) > 200

    def keys(f):
        return list(zip(*np.round(f.xy, 3).T, np.round(f.angle, 2), strict=True))

    kw, ks = set(keys(whole)), set(keys(strips))
    assert len(ks) == len(strips)  # no keypoint found by two strips
    assert len(kw & ks) >= 0.97 * len(kw) and len(ks - kw) <= 0.03 * len(kw)
    # the shared ones carry the same descriptors
    at = {k: i for i, k in enumerate(keys(strips))}
    same = [
        np.abs(whole.descriptors[i] - strips.descriptors[at[k]]).max() <= 1
        for i, k in enumerate(keys(whole))
        if k in at
    ]
    assert np.mean(same) > 0.97
    # other methods normalise over the whole image: strips are ignored
    orb = detect_and_describe(img, "orb", mask, strip_rows=128)
    np.testing.assert_array_equal(orb.xy, detect_and_describe(img, "orb", mask).xy)


def test_sift_in_tiles_finds_the_keypoints_of_the_whole_image(rng):
    """SIFT tile by tile: the tiles cover the image once, and the keypoints and descriptors
    are those of the whole image except a few large ones near the tiles' edges, none twice;
    on a panorama the seam is handled as on the whole image."""
    # a 2048 x 1024 panorama with its seam padding: 2 x 5 tiles of 512 x 436 (the last 432)
    assert tiles((1024, 2176), 262_144) == [
        (r, r + 512, c, min(c + 436, 2176)) for r in (0, 512) for c in range(0, 2176, 436)
    ]
    assert tiles((50, 70), 1_000) == [(0, 50, 0, 35), (0, 50, 35, 70)]  # at least 64 a side
    for shape, px in [((600, 400), 40_000), ((1024, 2176), 262_144), ((333, 777), 5_000)]:
        cover = np.zeros(shape, int)
        for r0, r1, c0, c1 in tiles(shape, px):
            assert (r1 - r0) * (c1 - c0) <= max(px, 64 * 64)
            cover[r0:r1, c0:c1] += 1
        assert (cover == 1).all()
    assert tiles((600, 400), 0) == tiles((600, 400), 240_000) == [(0, 600, 0, 400)]
    img = _texture(rng, 600, 400)
    mask = np.ones(img.shape, bool)
    mask[250:300, 100:200] = False

    def keys(f):
        return list(zip(*np.round(f.xy, 3).T, np.round(f.angle, 2), strict=True))

    for wrap in (False, True):
        whole = detect_and_describe(img, "sift", mask, wrap=wrap)
        tiled = detect_and_describe(img, "sift", mask, wrap=wrap, tile_pixels=150 * 150)
        assert len(whole) > 200
        kw, kt = set(keys(whole)), set(keys(tiled))
        assert len(kt) == len(tiled)  # no keypoint found by two tiles
        assert len(kw & kt) >= 0.96 * len(kw) and len(kt - kw) <= 0.04 * len(kw)
        at = {k: i for i, k in enumerate(keys(tiled))}
        same = [
            np.abs(whole.descriptors[i] - tiled.descriptors[at[k]]).max() <= 1
            for i, k in enumerate(keys(whole))
            if k in at
        ]
        assert np.mean(same) > 0.96
        assert (tiled.xy[:, 0] >= -0.5).all() and (tiled.xy[:, 0] < 400).all()
    orb = detect_and_describe(img, "orb", mask, tile_pixels=150 * 150)
    np.testing.assert_array_equal(orb.xy, detect_and_describe(img, "orb", mask).xy)
