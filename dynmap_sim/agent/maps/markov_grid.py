"""Independent Markov chain occupancy grid: each cell a two-state chain with learned rates.

Saarinen, Andreasson, Lilienthal, "Independent Markov chain occupancy grid maps for
representation of dynamic environments", IROS 2012, §III: a cell's occupancy is a two-state
Markov chain, free -> occupied ("entry") and occupied -> free ("exit"), each a Poisson process
whose rate is learned online from the transitions the robot observes; between observations the
occupancy probability relaxes to the chain's stationary value. In continuous time, with entry
rate ``λ_in`` and exit rate ``λ_out`` [1/s], the probability ``dt`` seconds after the cell was
seen with probability ``p(t)`` is

    p(t + dt) = p_inf + (p(t) − p_inf) · exp(−(λ_in + λ_out) · dt),
    p_inf = λ_in / (λ_in + λ_out),

the closed-form solution of the chain's forward equation ``dp/dt = λ_in (1 − p) − λ_out p``.

The rates are estimated as events per exposure: ``λ_in`` is the number of observed 0 -> 1
changes between consecutive observations of a cell divided by the time the cell was seen free
(the intervals that began in state 0), ``λ_out`` likewise for 1 -> 0. This is the maximum-
likelihood rate of a Poisson process; it undercounts when a cell can change more than once
between two observations, which ``max_gap_s`` bounds by ignoring longer intervals.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.agent.maps.cell_observations import cell_indices, observation_arrays
from dynmap_sim.jit import compiled

#: Seconds in a week: the default prior rate is one change a week (see :class:`MarkovGrid`).
WEEK_S = 7.0 * 86400.0


class MarkovGrid:
    """Independent two-state Markov chains of ``n_cells`` cells (Saarinen et al. 2012 §III).

    ``prior_rate_per_s`` [1/s] and ``prior_weight_s`` [s] are a prior on both rates, added as
    ``prior_rate_per_s · prior_weight_s`` pseudo-events over ``prior_weight_s`` of exposure
    (defaults: one change a week, worth an hour of observation: a cell not yet seen to change
    is assumed to change slowly, a few runs outweigh the prior, and the rates are never 0 so
    every prediction relaxes to ``p_inf``); ``max_gap_s`` [s] is the longest interval between
    two observations of a cell that counts (default unbounded: every interval counts, see
    the module docstring);
    ``prior_p`` the probability of a cell never observed (0.5: no knowledge).
    Memory: 48 bytes per cell.
    """

    def __init__(
        self,
        n_cells: int,
        prior_rate_per_s: float = 1.0 / WEEK_S,
        prior_weight_s: float = 3600.0,
        max_gap_s: float = math.inf,
        prior_p: float = 0.5,
    ) -> None:
        if not (prior_rate_per_s > 0 and prior_weight_s > 0):
            raise ValueError("prior_rate_per_s and prior_weight_s must be > 0")
        if not max_gap_s > 0:
            raise ValueError("max_gap_s must be > 0")
        if not 0.0 <= prior_p <= 1.0:
            raise ValueError("prior_p must be in [0, 1]")
        self.n_cells = int(n_cells)
        self.prior_rate_per_s = float(prior_rate_per_s)
        self.prior_weight_s = float(prior_weight_s)
        self.max_gap_s = float(max_gap_s)
        self.prior_p = float(prior_p)
        #: per cell: observed 0 -> 1 and 1 -> 0 changes, time [s] seen free and seen occupied
        #: (intervals by their starting state); rows of :attr:`counts`
        self.counts = np.zeros((4, self.n_cells), np.float64)
        #: per cell: time [s] and state of the last observation (NaN: never observed)
        self.last_t_s = np.full(self.n_cells, np.nan)
        self.last_state = np.full(self.n_cells, np.nan)

    def update(self, times_s: ArrayLike, cells: ArrayLike, states: ArrayLike) -> None:
        """Add observations: cell ``cells[i]`` seen in state ``states[i]`` (>= 0.5 occupied)
        at ``times_s[i]`` [s], in time order per cell (an observation older than the cell's
        last one is an error, raised before anything is learned)."""
        t, c, s = observation_arrays(times_s, cells, states, self.n_cells)
        if t.size == 0:
            return
        by_cell = np.argsort(c, kind="stable")
        cs, ts = c[by_cell], t[by_cell]
        same = cs[1:] == cs[:-1]
        first = np.concatenate([[True], ~same])
        if np.any(ts[1:][same] < ts[:-1][same]) or np.any(ts[first] < self.last_t_s[cs[first]]):
            raise ValueError("observations of a cell must come in time order, after its last one")
        _count_transitions(t, c, s, self.max_gap_s, self.counts, self.last_t_s, self.last_state)

    @property
    def n_in(self) -> NDArray[np.float64]:
        """Observed 0 -> 1 changes per cell."""
        return self.counts[0]

    @property
    def n_out(self) -> NDArray[np.float64]:
        """Observed 1 -> 0 changes per cell."""
        return self.counts[1]

    @property
    def exposure_free_s(self) -> NDArray[np.float64]:
        """Time [s] per cell between observations that began free."""
        return self.counts[2]

    @property
    def exposure_occ_s(self) -> NDArray[np.float64]:
        """Time [s] per cell between observations that began occupied."""
        return self.counts[3]

    def rates(self, cells: ArrayLike | None = None) -> tuple[NDArray, NDArray]:
        """``(λ_in, λ_out)`` [1/s] of ``cells`` (all by default): events per exposure with
        the prior pseudo-counts."""
        idx = self._cells(cells)
        ev, w = self.prior_rate_per_s * self.prior_weight_s, self.prior_weight_s
        lam_in = (self.n_in[idx] + ev) / (self.exposure_free_s[idx] + w)
        lam_out = (self.n_out[idx] + ev) / (self.exposure_occ_s[idx] + w)
        return lam_in, lam_out

    def stationary(self, cells: ArrayLike | None = None) -> NDArray[np.float64]:
        """``p_inf = λ_in / (λ_in + λ_out)``: the long-run share of time occupied."""
        lam_in, lam_out = self.rates(cells)
        return lam_in / (lam_in + lam_out)

    def predict(self, times_s: ArrayLike, cells: ArrayLike | None = None) -> NDArray[np.float64]:
        """Occupancy probability of ``cells`` (all by default) at ``times_s`` [s] from each
        cell's last observation (the module's closed form; shape ``(k,)`` for a scalar time,
        ``(n_times, k)`` for an array). A time before the last observation uses ``|dt|``
        (a two-state chain is reversible); a cell never observed has ``prior_p``."""
        t = np.asarray(times_s, np.float64)
        idx = self._cells(cells)
        lam_in, lam_out = self.rates(idx)
        p_inf = lam_in / (lam_in + lam_out)
        seen = np.isfinite(self.last_t_s[idx])
        p0 = np.where(seen, self.last_state[idx], self.prior_p)
        dt = np.abs(t.reshape(-1, 1) - np.where(seen, self.last_t_s[idx], 0.0)[None, :])
        p = p_inf + (p0 - p_inf) * np.exp(-(lam_in + lam_out) * dt)
        p = np.where(seen[None, :], p, self.prior_p)
        return p[0] if t.ndim == 0 else p

    def _cells(self, cells: ArrayLike | None) -> NDArray[np.int64]:
        return cell_indices(cells, self.n_cells)


# ---------------------------------------------------------------------- compiled kernels
@compiled
def _count_transitions(times, cells, states, max_gap_s, counts, last_t, last_s):  # pragma: no cover
    """Count each cell's changes between consecutive observations and the exposure of the
    intervals by their starting state into ``counts`` (rows: n_in, n_out, exposure free,
    exposure occupied); the observations are in time order per cell."""
    for i in range(times.size):
        k = cells[i]
        t = times[i]
        x = 1.0 if states[i] >= 0.5 else 0.0
        if not np.isnan(last_t[k]):
            dt = t - last_t[k]
            if dt <= max_gap_s:
                if last_s[k] < 0.5:
                    counts[2, k] += dt
                    if x > 0.5:
                        counts[0, k] += 1.0
                else:
                    counts[3, k] += dt
                    if x < 0.5:
                        counts[1, k] += 1.0
        last_t[k] = t
        last_s[k] = x
