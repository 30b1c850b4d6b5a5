"""``fremen``: MCL on the map FreMEn predicts for the time of each run.

Krajník et al., "FreMEn", IEEE T-RO 2017 §III (the temporal model,
:mod:`dynmap_sim.agent.maps.fremen`) and Krajník et al., ECMR 2015 (localization on the
predicted map of the time); the MCL core, the map's frame and the learning at the end of
each run are :mod:`.temporal_map_mcl`'s.

Only cells ever seen occupied get a spectral model (about 1 kB each with the default 28
periods); a cell never seen occupied is free wherever it was seen. A cell's model starts at
its first occupied observation, so its free observations before that are not in its mean:
the cost of not keeping a spectrum for every cell of the frame (115 MB for a 20 m x 15 m
floor at 5 cm).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.agent.localization.localizer import register_localizer
from dynmap_sim.agent.localization.temporal_map_mcl import TemporalMapMCL
from dynmap_sim.agent.maps.fremen import WEEK_S, Fremen, default_periods
from dynmap_sim.types import LaserSpec


@register_localizer("fremen")
class FremenLocalizer(TemporalMapMCL):
    """FreMEn-predicted maps for MCL. ``n_periods``: candidate periods a week / 1..N (28:
    down to 6 h, as runs a few times a day cannot resolve shorter ones; the week for
    weekday/weekend schedules, the day at N = 7); ``max_order``: most spectral components
    per cell (3: a day, a week and one harmonic; the order itself is chosen per cell by
    prediction error); ``default_order``: the order before any cell's prediction was scored
    (0: the static mean until the data show periodicity). The other parameters are
    :class:`~.temporal_map_mcl.TemporalMapMCL`'s."""

    def __init__(
        self,
        laser: LaserSpec,
        rng: np.random.Generator,
        n_periods: int = 28,
        max_order: int = 3,
        default_order: int = 0,
        **params: Any,
    ) -> None:
        super().__init__(laser, rng, **params)
        self.periods_s = default_periods(WEEK_S, int(n_periods))
        Fremen(0, self.periods_s, int(max_order), int(default_order))  # checks the values
        self.max_order = int(max_order)
        self.default_order = int(default_order)
        self.model: Fremen | None = None
        #: per frame cell, its index in :attr:`model` (-1: never seen occupied)
        self.index: NDArray[np.int64] | None = None

    def _make_model(self, n_cells: int) -> None:
        self.model = Fremen(0, self.periods_s, self.max_order, self.default_order)
        self.index = np.full(n_cells, -1, np.int64)

    def _observe(self, t_s: float, cells: NDArray[np.int64], states: NDArray[np.float64]) -> None:
        assert self.model is not None and self.index is not None
        new = cells[(states > 0.5) & (self.index[cells] < 0)]
        if new.size:
            self.index[new] = self.model.add_cells(new.size) + np.arange(new.size)
        idx = self.index[cells]
        tracked = idx >= 0
        self.model.update(np.full(int(tracked.sum()), t_s), idx[tracked], states[tracked])

    def _predict(self, t_s: float) -> NDArray[np.float64]:
        assert self.model is not None and self.index is not None
        p = np.zeros(self.index.size)
        tracked = np.flatnonzero(self.index >= 0)
        if tracked.size:
            p[tracked] = self.model.predict(t_s, self.index[tracked])
        return p
