"""``markov-grid``: MCL on the occupancy an independent Markov chain per cell predicts.

Saarinen, Andreasson, Lilienthal, IROS 2012 §III (the chains,
:mod:`dynmap_sim.agent.maps.markov_grid`): at the start of each run every cell's occupancy
is predicted from its last observation over the gap since, with its learned entry and exit
rates; the MCL core, the map's frame and the learning at the end of each run are
:mod:`.temporal_map_mcl`'s. 48 bytes a cell: every cell of the frame has its chain.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.agent.localization.localizer import register_localizer
from dynmap_sim.agent.localization.temporal_map_mcl import TemporalMapMCL
from dynmap_sim.agent.maps.markov_grid import WEEK_S, MarkovGrid
from dynmap_sim.types import LaserSpec


@register_localizer("markov-grid")
class MarkovGridLocalizer(TemporalMapMCL):
    """Markov-chain-predicted maps for MCL. ``prior_rate_per_s``, ``prior_weight_s`` and
    ``max_gap_s``: :class:`~dynmap_sim.agent.maps.markov_grid.MarkovGrid`'s (a cell not yet
    seen to change is taken to change once a week, a prior worth an hour of observation;
    every gap between runs counts). The other parameters are
    :class:`~.temporal_map_mcl.TemporalMapMCL`'s."""

    def __init__(
        self,
        laser: LaserSpec,
        rng: np.random.Generator,
        prior_rate_per_s: float = 1.0 / WEEK_S,
        prior_weight_s: float = 3600.0,
        max_gap_s: float = math.inf,
        **params: Any,
    ) -> None:
        super().__init__(laser, rng, **params)
        self.chain_params = {
            "prior_rate_per_s": float(prior_rate_per_s),
            "prior_weight_s": float(prior_weight_s),
            "max_gap_s": float(max_gap_s),
        }
        MarkovGrid(0, **self.chain_params)  # checks the values
        self.model: MarkovGrid | None = None

    def _make_model(self, n_cells: int) -> None:
        self.model = MarkovGrid(n_cells, **self.chain_params)

    def _observe(self, t_s: float, cells: NDArray[np.int64], states: NDArray[np.float64]) -> None:
        assert self.model is not None
        self.model.update(np.full(cells.size, t_s), cells, states)

    def _predict(self, t_s: float) -> NDArray[np.float64]:
        assert self.model is not None
        return self.model.predict(t_s)
