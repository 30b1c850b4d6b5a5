"""``markov-grid``: MCL on the occupancy predicted by a Markov chain per cell, synthetic runs."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from synthetic_scans import LASER

from dynmap_sim.agent.localization.localizer import LOCALIZERS, make_localizer
from dynmap_sim.agent.localization.markov_grid_localizer import MarkovGridLocalizer
from dynmap_sim.types import Prior


def test_registered_and_parameters_checked(walls):
    assert LOCALIZERS.get("markov-grid") is MarkovGridLocalizer
    rng = np.random.default_rng(0)
    with pytest.raises(TypeError, match="unknown parameters"):
        make_localizer("markov-grid", laser=LASER, rng=rng, bogus=1)
    with pytest.raises(ValueError, match="prior_rate_per_s"):
        make_localizer("markov-grid", laser=LASER, rng=rng, prior_rate_per_s=0.0)
    loc = make_localizer("markov-grid", laser=LASER, rng=rng)
    with pytest.raises(ValueError, match="walls"):
        loc.begin_run(Prior(initial_pose=np.zeros(3), walls=walls[:0]))


def test_a_box_seen_is_kept_then_forgotten_once_seen_gone(day_runs, box_cells_share):
    """The box is there on days 1-2 and gone on days 3-4: the map predicted after day 2
    holds it (its cells were last seen occupied and change slowly), the one after day 4 no
    longer; every run localizes."""
    loc = make_localizer("markov-grid", laser=LASER, rng=np.random.default_rng(1))
    rng = np.random.default_rng(0)
    for day in range(1, 5):
        err = day_runs(loc, day, rng, with_box=day <= 2, both_runs=True)
        assert err.max() < 0.25, day
        if day == 2:
            assert box_cells_share(loc, 2 * 86400.0) > 0.8
    assert box_cells_share(loc, 4 * 86400.0) < 0.2
    lam_in, lam_out = loc.model.rates()
    assert np.all(lam_in > 0) and np.all(lam_out > 0)
    clone = pickle.loads(pickle.dumps(loc))
    np.testing.assert_array_equal(clone.model.counts, loc.model.counts)
