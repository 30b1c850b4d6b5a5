"""The exhibition's memory (B&D Fig. 9) on a synthetic local map with known medians."""

from __future__ import annotations

import numpy as np
import pytest

from dynmap_sim.agent.maps.dynamic_map import MapSnapshot
from dynmap_sim.studies.biber_duckett.exhibition import exhibit_memory, fig9_days, first_hits
from dynmap_sim.studies.biber_duckett.findings import exhibition_finding
from dynmap_sim.types import BeamClass

ROOM = np.array([[-5, -5, 5, -5], [5, -5, 5, 5], [5, 5, -5, 5], [-5, 5, -5, -5]], float)
STAND = np.array([[2.0, -1.0, 2.0, 1.0]])  # an exhibit 2 m east of the local map
SEGS = np.concatenate([ROOM, STAND])
CLS = np.array([int(BeamClass.WALL)] * 4 + [int(BeamClass.EXHIBIT)], dtype=np.int8)
LEVELS = (1, 2, 3, 4)
N_RAYS = {1: 360, 2: 720, 3: 1440, 4: 1440}


def test_first_hits_of_rays():
    r, k = first_hits(np.zeros(2), 4, SEGS, 8.0)  # east, north, west, south
    assert np.allclose(r, [2.0, 5.0, 5.0, 5.0]) and k.tolist() == [4, 2, 3, 0]
    r, k = first_hits(np.zeros(2), 4, SEGS, 1.0)
    assert np.all(np.isinf(r)) and np.all(k == -1)


def snapshot(remembers: dict[int, bool]) -> MapSnapshot:
    """Medians with (True) or without (False) the stand, per level."""
    meds = []
    for level in LEVELS:
        segs = SEGS if remembers[level] else ROOM
        r, _ = first_hits(np.zeros(2), N_RAYS[level], segs, 8.0)
        meds.append(np.rint(r * 1000).astype(np.uint16)[None, :])
    return MapSnapshot(np.zeros((1, 2)), LEVELS, tuple(meds), 0.1)


def test_the_exhibition_enters_the_short_timescales_and_fades():
    none = {lv: False for lv in LEVELS}
    short = {1: True, 2: True, 3: False, 4: False}
    snaps = [(3, snapshot(none)), (6, snapshot(short)), (9, snapshot(short))]
    snaps += [(12, snapshot(none)), (15, snapshot(none))]
    mem = exhibit_memory(snaps, SEGS, CLS, 8.0)
    assert mem is not None and mem.days == (3, 6, 9, 12, 15)
    n_ex = mem.n_exhibit_rays[4]
    assert 0.1 * 1440 < n_ex < 0.2 * 1440  # a 2 m stand at 2 m: about 53 degrees
    lv = list(mem.levels)
    assert mem.share[1, lv.index(1)] == pytest.approx(1.0)
    assert mem.share[1, lv.index(4)] == 0.0 and mem.share[3, lv.index(1)] == 0.0
    assert fig9_days(mem.days, [4, 5, 6, 7, 8, 9]) == [3, 6, 9, 12]
    f = exhibition_finding(mem, [4, 5, 6, 7, 8, 9])
    assert f.holds, f.measured
    assert f.measured.startswith("day 9: λ2 100 %, λ3 100 %; day 12: λ2 0 %, λ3 0 %")
    # λ5 that takes in the exhibition (it should not: u = 0.05) fails the finding
    every = {lv: True for lv in LEVELS}
    bad = exhibit_memory(snaps[:2] + [(9, snapshot(every))] + snaps[3:], SEGS, CLS, 8.0)
    assert not exhibition_finding(bad, [4, 5, 6, 7, 8, 9]).holds
    # no exhibit in the geometry: nothing to measure
    assert exhibit_memory(snaps, ROOM, CLS[:4], 8.0) is None
