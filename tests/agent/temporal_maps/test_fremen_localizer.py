"""``fremen``: MCL on the FreMEn-predicted map of the run's time, on synthetic runs."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from synthetic_scans import LASER

from dynmap_sim.agent.localization.fremen_localizer import FremenLocalizer
from dynmap_sim.agent.localization.localizer import LOCALIZERS, make_localizer
from dynmap_sim.types import Prior


def test_registered_and_parameters_checked():
    assert LOCALIZERS.get("fremen") is FremenLocalizer
    rng = np.random.default_rng(0)
    with pytest.raises(TypeError, match="unknown parameters"):
        make_localizer("fremen", laser=LASER, rng=rng, bogus=1)
    with pytest.raises(ValueError, match="occupied_threshold"):
        make_localizer("fremen", laser=LASER, rng=rng, occupied_threshold=1.0)
    with pytest.raises(ValueError):
        make_localizer("fremen", laser=LASER, rng=rng, max_order=40)
    with pytest.raises(ValueError, match="first_map"):
        make_localizer("fremen", laser=LASER, rng=rng, first_map="lidar")
    with pytest.raises(ValueError, match="mapper_params"):
        make_localizer("fremen", laser=LASER, rng=rng, first_map="walls", mapper_params={"a": 1})
    assert make_localizer("fremen", laser=LASER, rng=rng).config_name == "tuned"
    assert make_localizer("fremen", laser=LASER, rng=rng, first_map="walls").config_name == (
        "walls-only"
    )
    loc = make_localizer("fremen", laser=LASER, rng=rng)
    with pytest.raises(ValueError, match="walls"):
        loc.begin_run(Prior(initial_pose=np.zeros(3)))


@pytest.mark.parametrize("first_map", ["slam", "walls"])
def test_learns_a_daily_box_and_predicts_it_by_time_of_day(day_runs, box_cells_share, first_map):
    """Morning runs see the box, evening runs its empty place: after four days the map
    predicted for a morning holds the box and the one for an evening does not, and both
    runs localize, whether the first run was mapped by SLAM or localized on the walls."""
    loc = make_localizer("fremen", laser=LASER, rng=np.random.default_rng(1), first_map=first_map,
                         run_clock_s=8 * 3600.0, run_spacing_s=12 * 3600.0)  # fmt: skip
    rng = np.random.default_rng(0)
    for day in range(1, 5):
        err = day_runs(loc, day, rng, with_box=True)
        assert err.max() < 0.25, day
    day5 = 4 * 86400.0
    assert box_cells_share(loc, day5 + 8 * 3600.0) > 0.8
    assert box_cells_share(loc, day5 + 20 * 3600.0) < 0.2
    assert np.all(loc.model.order[loc.index[loc.index >= 0]] <= loc.max_order)
    art = loc.day_artifacts()["temporal_map"]  # day 4's two runs, as each localized on
    assert art["p_occupied"].shape == (2, *loc.frame.shape)
    assert art["run"].tolist() == [1, 2]
    np.testing.assert_allclose(art["t_s"], [day5 - 16 * 3600.0, day5 - 4 * 3600.0], atol=1.0)
    seen = np.isfinite(art["p_occupied"])
    assert seen.any() and np.all((art["p_occupied"][seen] >= 0) & (art["p_occupied"][seen] <= 1))
    # the morning map holds the box, the evening map does not (as predicted before each run)
    morning, evening = (np.nan_to_num(m.astype(float)) for m in art["p_occupied"])
    assert (morning > 0.5).sum() > (evening > 0.5).sum()
    clone = pickle.loads(pickle.dumps(loc))
    np.testing.assert_array_equal(clone.model.acc, loc.model.acc)
