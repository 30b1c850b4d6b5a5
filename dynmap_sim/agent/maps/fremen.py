"""Frequency Map Enhancement (FreMEn) of many binary cells at once.

Krajník, Fentanes, Santos, Duckett, "FreMEn: Frequency Map Enhancement for Long-Term Mobile
Robot Autonomy in Changing Environments", IEEE T-RO 33(4), 2017, §III (the spectral model,
its incremental update and the choice of its order): the state ``s(t)`` of
a cell (a door open, a grid cell occupied) is modelled by its mean ``α0`` and the ``m``
strongest spectral components of ``s(t) − α0`` among a set of candidate periods ``T_k``
(``ω_k = 2π / T_k``), and its probability predicted as

    p(t) = α0 + Σ_{j ≤ m} 2 |α_j| cos(ω_j t + arg α_j),

with ``α_k = (1/n) Σ_i (s(t_i) − α0) e^{−i ω_k t_i}``. The sums are kept incrementally
(the paper's online update): per cell and period ``S_k = Σ s(t_i) e^{−i ω_k t_i}`` and
``G_k = Σ e^{−i ω_k t_i}``, so that ``α_k = (S_k − α0 G_k) / n`` holds exactly after any
number of updates, whatever the sampling times (irregular, with gaps), without storing the
observations.

The model order ``m`` is chosen per cell by prediction error (the paper selects it on data
the model has not seen): every batch given to :meth:`Fremen.update` is first
predicted by the current model for each order ``0 … max_order`` and the squared errors are
summed per cell and order; :attr:`Fremen.order` is the order of least summed error. Order 0
is the static mean, so a cell whose changes are not periodic falls back to it.

The time-specific map on which Krajník et al. (ECMR 2015) localize is :meth:`Fremen.predict`
of all cells at the time of a run, thresholded.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.agent.maps.cell_observations import cell_indices, observation_arrays
from dynmap_sim.jit import compiled

#: Seconds in a day and a week.
DAY_S = 86400.0
WEEK_S = 7.0 * DAY_S


def default_periods(longest_s: float = WEEK_S, n_periods: int = 56) -> NDArray[np.float64]:
    """Candidate periods [s] ``longest_s / k`` for ``k = 1 … n_periods``, longest first.

    A week is the longest period because the schedules of people (working days, weekends)
    repeat weekly; its harmonics include the day (``k = 7``) and its own harmonics (half a
    day, 8 h, …), which a square profile such as "open in working hours" needs. 56 harmonics
    stop at 3 h: shorter periods need several observations an hour to be told apart from
    noise (a sampling argument: the candidate periods are the ones the observations can resolve)."""
    if longest_s <= 0 or n_periods < 1:
        raise ValueError("longest_s must be > 0 and n_periods >= 1")
    return longest_s / np.arange(1, n_periods + 1, dtype=np.float64)


class Fremen:
    """FreMEn models of ``n_cells`` binary cells (T-RO 2017 §III), vectorised over cells.

    ``periods_s`` are the candidate periods [s] (default :func:`default_periods`: a week
    and its harmonics down to 3 h); ``max_order`` the most spectral components a cell may
    use (the order itself is chosen per cell by prediction error, see the module);
    ``default_order`` the order of a cell none of whose observations was scored yet (2: a
    day and one harmonic, enough for "open by day, shut at night" before any evidence);
    ``prior_p`` the probability of a cell never observed (0.5: no knowledge).
    Memory: ``32 · len(periods_s) + 8 · (max_order + 4)`` bytes per cell.
    """

    def __init__(
        self,
        n_cells: int,
        periods_s: ArrayLike | None = None,
        max_order: int = 5,
        default_order: int = 2,
        prior_p: float = 0.5,
    ) -> None:
        periods = default_periods() if periods_s is None else np.asarray(periods_s, np.float64)
        if periods.ndim != 1 or periods.size == 0 or not np.all(periods > 0):
            raise ValueError("periods_s must be a non-empty 1-D array of positive periods [s]")
        if not 0 <= default_order <= max_order <= periods.size:
            raise ValueError("need 0 <= default_order <= max_order <= len(periods_s)")
        if not 0.0 <= prior_p <= 1.0:
            raise ValueError("prior_p must be in [0, 1]")
        self.n_cells = int(n_cells)
        self.periods_s = periods
        self.omegas = 2.0 * np.pi / periods  # [rad/s]
        self.max_order = int(max_order)
        self.default_order = int(default_order)
        self.prior_p = float(prior_p)
        self.n_obs = np.zeros(self.n_cells, np.int64)
        self.sum_state = np.zeros(self.n_cells, np.float64)
        # per cell and period: Re S, Im S, Re G, Im G (module docstring)
        self.acc = np.zeros((self.n_cells, periods.size, 4), np.float64)
        self.sse = np.zeros((self.n_cells, self.max_order + 1), np.float64)
        self.n_scored = np.zeros(self.n_cells, np.int64)

    def add_cells(self, n: int) -> int:
        """Append ``n`` never-observed cells (a map that tracks only the cells it has seen
        occupied grows as it sees new ones); the index of the first new cell."""
        first = self.n_cells
        self.n_cells += int(n)
        self.n_obs = np.concatenate([self.n_obs, np.zeros(n, np.int64)])
        self.sum_state = np.concatenate([self.sum_state, np.zeros(n)])
        self.acc = np.concatenate([self.acc, np.zeros((n, *self.acc.shape[1:]))])
        self.sse = np.concatenate([self.sse, np.zeros((n, self.sse.shape[1]))])
        self.n_scored = np.concatenate([self.n_scored, np.zeros(n, np.int64)])
        return first

    # ------------------------------------------------------------------ learning
    def update(
        self, times_s: ArrayLike, cells: ArrayLike, states: ArrayLike, score: bool = True
    ) -> None:
        """Add observations: cell ``cells[i]`` seen in state ``states[i]`` (0 free/closed, 1
        occupied/open, or a probability) at time ``times_s[i]`` [s]. With ``score`` the batch
        is first predicted by the current model at every order and the squared errors added
        to :attr:`sse` (the order selection). Observations at one time should be
        consecutive: the kernel evaluates the trigonometric terms once per distinct time."""
        t, c, s = observation_arrays(times_s, cells, states, self.n_cells)
        if t.size == 0:
            return
        if score:
            self._score(t, c, s)
        _accumulate(t, c, s, self.omegas, self.acc, self.n_obs, self.sum_state)

    def _score(self, t: NDArray, c: NDArray, s: NDArray) -> None:
        """Sum the squared prediction errors of every order on observations not yet learned
        (the components once per distinct cell here, the predictions in a kernel)."""
        uc, inv = np.unique(c, return_inverse=True)
        mean, amp, phase, omega = self.components(uc, order=self.max_order)
        model = (mean, amp, phase, omega)
        _score_orders(t, c, s, inv.astype(np.int64), model, self.n_obs, self.sse, self.n_scored)

    # ------------------------------------------------------------------ the model
    @property
    def order(self) -> NDArray[np.int64]:
        """Per cell, the number of spectral components of least summed prediction error
        (ties: the lower order); :attr:`default_order` where nothing was scored yet."""
        best = np.argmin(self.sse, axis=1).astype(np.int64)
        return np.where(self.n_scored > 0, best, self.default_order)

    def mean(self, cells: ArrayLike | None = None) -> NDArray[np.float64]:
        """``α0`` of ``cells`` (all by default): the share of time observed occupied."""
        idx = self._cells(cells)
        n = self.n_obs[idx]
        return np.where(n > 0, self.sum_state[idx] / np.maximum(n, 1), self.prior_p)

    def spectrum(self, cells: ArrayLike | None = None) -> NDArray[np.complex128]:
        """``α_k`` of ``cells`` for every candidate period, shape ``(k, n_periods)``:
        ``2 |α_k|`` is the amplitude of the period's cosine in ``s(t)``, ``arg α_k`` its phase
        [rad] at ``t = 0``."""
        idx = self._cells(cells)
        a = self.acc[idx]
        n = np.maximum(self.n_obs[idx], 1)[:, None]
        mu = self.mean(idx)[:, None]
        return ((a[..., 0] - mu * a[..., 2]) + 1j * (a[..., 1] - mu * a[..., 3])) / n

    def components(
        self, cells: ArrayLike | None = None, order: ArrayLike | int | None = None
    ) -> tuple[NDArray, NDArray, NDArray, NDArray]:
        """The model of ``cells``: ``(α0 (k,), amplitude (k, M), phase [rad] (k, M),
        ω [rad/s] (k, M))`` with the ``M = max_order`` strongest components by ``|α|``,
        strongest first; components beyond a cell's ``order`` (default :attr:`order`) have
        amplitude 0."""
        idx = self._cells(cells)
        alpha = self.spectrum(idx)
        m = self.max_order
        top = np.argsort(-np.abs(alpha), axis=1, kind="stable")[:, :m]
        sel = np.take_along_axis(alpha, top, axis=1)
        ords = self.order[idx] if order is None else np.broadcast_to(order, idx.shape)
        keep = np.arange(m)[None, :] < np.asarray(ords)[:, None]
        amp = np.where(keep, 2.0 * np.abs(sel), 0.0)
        return self.mean(idx), amp, np.angle(sel), self.omegas[top]

    def predict(
        self,
        times_s: ArrayLike,
        cells: ArrayLike | None = None,
        order: ArrayLike | int | None = None,
    ) -> NDArray[np.float64]:
        """``p(t)`` (the module's model) clipped to [0, 1] for ``cells`` (all by default) at
        ``times_s`` [s]: shape ``(k,)`` for a scalar time, ``(n_times, k)`` for an array."""
        t = np.asarray(times_s, np.float64)
        mean, amp, phase, omega = self.components(cells, order)
        tt = t.reshape(-1, 1, 1)
        p = mean[None, :] + np.sum(amp[None] * np.cos(omega[None] * tt + phase[None]), axis=2)
        p = np.clip(p, 0.0, 1.0)
        return p[0] if t.ndim == 0 else p

    def _cells(self, cells: ArrayLike | None) -> NDArray[np.int64]:
        return cell_indices(cells, self.n_cells)


# ---------------------------------------------------------------------- compiled kernels
@compiled
def _accumulate(times, cells, states, omegas, acc, n_obs, sum_state):  # pragma: no cover
    """Add ``s e^{−iωt}`` and ``e^{−iωt}`` of every observation to its cell's sums;
    the cosines and sines are evaluated once per run of equal times."""
    n_p = omegas.size
    cs = np.empty(n_p)
    sn = np.empty(n_p)
    last = np.nan
    for i in range(times.size):
        t = times[i]
        if t != last:
            for p in range(n_p):
                a = omegas[p] * t
                cs[p] = np.cos(a)
                sn[p] = np.sin(a)
            last = t
        k = cells[i]
        x = states[i]
        n_obs[k] += 1
        sum_state[k] += x
        for p in range(n_p):
            acc[k, p, 0] += x * cs[p]
            acc[k, p, 1] -= x * sn[p]
            acc[k, p, 2] += cs[p]
            acc[k, p, 3] -= sn[p]


@compiled
def _score_orders(times, cells, states, inv, model, n_obs, sse, n_scored):  # pragma: no cover
    """Add each observation's squared error of the prediction clipped to [0, 1] at every
    order ``0 … M`` to ``sse[cell]``; ``model`` = (mean, amplitude, phase, ω) of the distinct
    cells, strongest component first, row ``inv[i]`` for observation ``i``. A cell never
    observed before is not scored (its prior says nothing about the order)."""
    mean, amp, phase, omega = model
    n_m = amp.shape[1]
    for i in range(times.size):
        k = cells[i]
        if n_obs[k] == 0:
            continue
        u = inv[i]
        p = mean[u]
        e = min(max(p, 0.0), 1.0) - states[i]
        sse[k, 0] += e * e
        for m in range(n_m):
            p += amp[u, m] * np.cos(omega[u, m] * times[i] + phase[u, m])
            e = min(max(p, 0.0), 1.0) - states[i]
            sse[k, m + 1] += e * e
        n_scored[k] += 1
