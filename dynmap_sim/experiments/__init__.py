"""The experiment engine: scenarios, the episode loop, drivers, the localizer bench, results.

* :mod:`.scenario` — scenario files (TOML, validated; ``load_scenario``);
* :mod:`.runner` — ``run_experiment``: days x runs, localizers side by side, checkpoints;
* :mod:`.drivers` — who steers a run (the ``tour`` operator sees the truth);
* :mod:`.localizer_pool` — the localizer bench: a run's stream through every localizer, in-process
  or in worker processes;
* :mod:`.results` — the SQLite results store (one per experiment);
* :mod:`.replay` — mapping and localizers on a recorded CARMEN log.

Reports, exports and expectation checks are in :mod:`dynmap_sim.analysis`, the papers'
findings in :mod:`dynmap_sim.studies`; the engine imports neither.
"""
