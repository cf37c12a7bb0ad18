"""Whole-shift twins (:mod:`flexreg.registration.twins`): in a hall of identical bays an
answer a bay off fits as well as the truth, and only its twins give it away (hand-made hall
ray-cast exactly, as in ``test_verdict``)."""

from __future__ import annotations

import numpy as np
import pytest
from test_verdict import BOX, CUPBOARD, _full_pair, _station, _views

from flexreg.core.transforms import invert, make_transform
from flexreg.registration.candidates import polisher
from flexreg.registration.config import JudgeConfig
from flexreg.registration.fullres import pose_masks
from flexreg.registration.settle import open_share
from flexreg.registration.twins import find_twins, horizontal_axes, shares, slide_refuted
from flexreg.registration.verdict import decide
from flexreg.stages.normals import grid_normals
from flexreg.stages.sampling import area_sample

#: a hall 60 m long, 8 m wide, 3 m high
HALL = ([-30.0, -4.0, -1.5], [30.0, 4.0, 1.5])
BAY = 5.0
#: room-high pillars every bay on both sides of the aisle
PILLARS = [
    (np.array([x - 0.2, y - 0.2, -1.5]), np.array([x + 0.2, y + 0.2, 1.5]))
    for x in np.arange(-27.5, 28.0, BAY)
    for y in (-2.0, 2.0)
]
UP = np.array([0.0, 0.0, 1.0])
THR = 0.02


def _hall(blocks):
    T_wt, T_ws = _station(0.0, 0.0), _station(2 * BAY, 0.5, 20)
    pair, T = _full_pair(*HALL, blocks, T_wt, T_ws)
    one_bay_nearer = invert(T_wt) @ make_transform(np.eye(3), [-BAY, 0.0, 0.0]) @ T_ws
    return pair, T, one_bay_nearer


def _twins(pair, T):
    """The twins, each polished by the quick ICP as in the pipeline."""
    src = pair.source.image
    sample = area_sample(src.xyz[src.valid].astype(np.float64), 5000)
    polish = polisher(pair.target.image, grid_normals(pair.target.image), sample, THR)
    return find_twins(pair, T, UP, polish, THR, JudgeConfig(), range_m=12.0)


def test_the_axes_of_a_hall_are_its_walls():
    pair, _, _ = _hall(PILLARS)
    a, b = horizontal_axes(pair.target, UP)
    assert sorted([round(abs(a[0]), 3), round(abs(b[0]), 3)]) == [0.0, 1.0]
    assert abs(a @ UP) < 1e-9 and abs(b @ UP) < 1e-9


def test_an_answer_a_bay_off_has_the_truth_among_its_twins_and_is_ambiguous():
    """Placed one bay nearer, the source fits the pillars and walls as well as at the truth
    (nothing in open space); the twin one bay back is the truth (within a step of the sweep:
    along the hall only the thin pillars hold the polish) and explains much of it."""
    pair, T, wrong = _hall(PILLARS)
    assert shares(pair, wrong, THR)[1] <= 1e-3  # no single-pose test refuses it
    ev = _twins(pair, wrong)
    back = [
        t for t in ev["twins"] if np.allclose(t["offset_m"], T[:3, 3] - wrong[:3, 3], atol=0.25)
    ]
    assert back and back[0]["open_share"] <= 1e-3
    assert back[0]["explained_share"] >= 0.2 * ev["answer"]["explained_share"]
    v = decide({"twins": ev})
    assert [r.code for r in v.reasons] == ["ambiguous"]
    assert "moved 5.0 m along x fits too" in v.reasons[0].message


def test_in_a_room_no_twin_fits_and_explains_much():
    """A room with a cupboard does not repeat: the right answer slid along either wall puts
    the walls where the other scanner saw through, or, slid out of the room, explains no
    more than the shared wall's plane; it stays confident."""
    T_wt, T_ws = _station(0.6, 0.4), _station(-1.0, 0.5, 30)
    pair, T = _full_pair(*BOX, CUPBOARD, T_wt, T_ws)
    ev = _twins(pair, T)
    assert ev["answer"]["open_share"] == 0.0
    assert ev["twins"]
    assert all(t["open_share"] > 0.01 or t["explained_share"] < 0.1 for t in ev["twins"])
    assert decide({"twins": ev}).confident


@pytest.mark.parametrize(
    ("explained", "open_share", "ambiguous"),
    [
        (0.20, 0.001, True),  # explains a fifth of the answer's 100 %, at the open limit
        (0.19, 0.0, False),  # explains less than a fifth
        (0.90, 0.0011, False),  # contradicts more than the limit (and twice the answer's)
    ],
)
def test_a_twin_counts_when_it_fits_and_explains_a_fifth(explained, open_share, ambiguous):
    ev = {
        "twins": {
            "answer": {"explained_share": 1.0, "open_share": 0.0004},
            "twins": [
                {
                    "offset_m": [5.6, 0.1, 0.0],
                    "shift_m": 5.6,
                    "explained_share": explained,
                    "open_share": open_share,
                }
            ],
        }
    }
    v = decide(ev)
    assert (not v.confident) is ambiguous
    off = decide(ev, judge=JudgeConfig(open_share=0.0))
    assert off.confident


def test_twins_need_a_twin():
    ev = {"twins": {"answer": {"explained_share": 0.8, "open_share": 0.0}, "twins": []}}
    assert decide(ev).confident


#: the hall ending 6 m behind the target station: the end wall is the one thing that tells
#: one bay from the next
END_HALL = ([-6.0, -4.0, -1.5], [52.0, 4.0, 1.5])
END_PILLARS = [p for p in PILLARS if p[0][0] > END_HALL[0][0]]


def _slid(hall, blocks, shift_bays):
    """:func:`slide_refuted` of the truth moved ``shift_bays`` bays along the hall (the
    stations a bay apart), with the truth and the moved pose."""
    T_wt, T_ws = _station(0.0, 0.0), _station(BAY, 0.5, 20)
    pair, T = _full_pair(*hall, blocks, T_wt, T_ws)
    wrong = invert(T_wt) @ make_transform(np.eye(3), [shift_bays * BAY, 0.0, 0.0]) @ T_ws
    (_, _), two = _views(*hall, blocks, T_wt, T_ws)
    src = pair.source.image
    sample = area_sample(src.xyz[src.valid].astype(np.float64), 5000)
    polish = polisher(pair.target.image, grid_normals(pair.target.image), sample, THR)
    won = slide_refuted(pair, wrong, UP, polish, two.forward, THR, JudgeConfig())
    return pair, T, wrong, won


@pytest.mark.parametrize("shift_bays", [-2, -1, 1])
def test_an_answer_bays_off_that_the_end_wall_refutes_slides_back_onto_the_truth(shift_bays):
    """Bays off, the answer puts the end wall (or what the source saw in front of it) where
    the other scanner saw through; slid along the hall, it fits again at the truth only,
    which beats it."""
    pair, T, wrong, won = _slid(END_HALL, END_PILLARS, shift_bays)
    assert open_share(pose_masks(pair, wrong, THR)) > 1e-3
    assert won is not None and won.origin == "slide"
    assert np.linalg.norm(won.T_target_source[:3, 3] - T[:3, 3]) < 0.05
    assert open_share(pose_masks(pair, won.T_target_source, THR)) <= 1e-3


def test_without_a_cue_no_slide_is_preferred():
    """Far from both ends every bay fits alike: no slid pose beats the answer a bay off,
    none is returned (the verdict's twins say the answer is ambiguous)."""
    *_, won = _slid(HALL, PILLARS, -1)
    assert won is None
