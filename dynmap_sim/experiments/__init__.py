"""Experiments: scenarios, the calendar loop, results, reports and regression checks.

* :mod:`.scenario` — scenario files (TOML, validated; ``load_scenario``);
* :mod:`.runner` — ``run_experiment``: days x runs, localizers side by side, checkpoints;
* :mod:`.drivers` — the ``tour`` operator that steers along the route (sees the truth);
* :mod:`.results` — the SQLite results store (one per experiment);
* :mod:`.report`, :mod:`.export` — figures, ``summary.md``, ``per_day.csv``, TUM files;
* :mod:`.check` — regression checks against a scenario's ``[expectations]``.
"""
