"""A localizer's update time in the results is its CPU time, not the wall time it spent
waiting (for a core shared with other processes, or anything else)."""

import sys
import time
from pathlib import Path

import numpy as np

from dynmap_sim.experiments.localizer_pool import RunStream, localize_run
from dynmap_sim.types import Prior

sys.path.insert(0, str(Path(__file__).parent))
from fake_env import RecordingLocalizer  # noqa: E402

SLEEP_S = 0.02


class SleepingLocalizer(RecordingLocalizer):
    """Dead reckoning that sleeps in every update (wall time, almost no CPU)."""

    def update(self, odom, scan):
        time.sleep(SLEEP_S)
        return super().update(odom, scan)


def test_update_time_is_cpu_time():
    n, beams = 5, 8
    stream = RunStream(
        index=0,
        prior=Prior(initial_pose=np.zeros(3), day=1, run=1, first_run=True),
        stamps_s=np.arange(n) * 0.1,
        odom=np.zeros((n, 3)),
        scans=np.ones((n, beams), dtype=np.float32),
        beam_class=np.zeros((n, beams), dtype=np.int8),
        last_of_day=True,
    )
    loc = SleepingLocalizer(None, np.random.default_rng(0))
    out = localize_run("sleeper", loc, stream)
    assert out.busy_s >= n * SLEEP_S  # the wall time of the run holds the sleeps
    assert 0.0 <= out.update_s < 0.5 * n * SLEEP_S  # the update time does not


def test_new_results_say_cpu_and_older_ones_wall(tmp_path):
    """Folders created since update times are CPU times say so in their column header;
    older ones (no ``update_time`` in ``meta``) held wall times and keep that label."""
    from dynmap_sim.experiments.results import ResultsDB

    with ResultsDB.create(tmp_path / "new") as db:
        assert db.update_time_header() == "update CPU [ms/scan]"
        db.con.execute("DELETE FROM meta WHERE key = 'update_time'")
        assert db.update_time_header() == "update wall [ms/scan]"
