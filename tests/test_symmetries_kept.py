"""A plan view's self-overlays are computed once per content: a survey station takes part in
a dozen links and is loaded again for each."""

from __future__ import annotations

import copy
from unittest import mock

import numpy as np
from test_verdict import BOX, _cast, _station

from flexreg.registration import candidates
from flexreg.registration.candidates import self_symmetries
from flexreg.stages.priors import plan_view


def test_symmetries_are_kept_by_content_and_shared_read_only():
    plan = plan_view(_cast(np.array(BOX[0]), np.array(BOX[1]), [], _station(0.6, 0.4)))
    first = self_symmetries(plan)
    assert first and all(not S.flags.writeable for S in first)
    reloaded = copy.deepcopy(plan)  # as a worker loads the station again from its cache
    with mock.patch.object(candidates, "match_top_views", side_effect=AssertionError):
        again = self_symmetries(reloaded)
    assert len(again) == len(first) and all(a is b for a, b in zip(again, first, strict=True))
    again.clear()  # the caller's list is its own
    assert len(self_symmetries(plan)) == len(first)
    fewer = self_symmetries(plan, count=1)  # other parameters: computed, kept apart
    assert len(fewer) <= 2 and len(self_symmetries(plan)) == len(first)


def test_another_plan_is_not_taken_for_a_kept_one():
    a = plan_view(_cast(np.array(BOX[0]), np.array(BOX[1]), [], _station(0.6, 0.4)))
    b = plan_view(_cast(np.array(BOX[0]), np.array(BOX[1]), [], _station(-1.0, 0.5, 30)))
    sa, sb = self_symmetries(a), self_symmetries(b)
    assert not all(np.allclose(x, y) for x, y in zip(sa, sb, strict=False))
