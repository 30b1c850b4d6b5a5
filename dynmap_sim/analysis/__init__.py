"""Analysis: what is read from a results folder after (or while) an experiment runs.

* :mod:`.report` — figures, ``summary.md``, ``per_day.csv``; each paper study that applies
  adds its own (:mod:`dynmap_sim.studies`);
* :mod:`.export` — TUM trajectories for ``evo``;
* :mod:`.headline` — the results table ``run`` and ``replay`` print when done;
* :mod:`.check` — a scenario's ``[expectations]`` evaluated on its results (``dynmap-sim check``).

Analysis reads the results store; the engine (:mod:`dynmap_sim.experiments`) never imports it.
"""
