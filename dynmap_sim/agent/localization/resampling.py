"""Low-variance (systematic) resampling, *Probabilistic Robotics* Table 4.4."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray


class LowVarianceDraws:
    """The ``n`` draws of :func:`low_variance_resample` (one random offset taken from ``rng``
    when made), each computed only when asked for by position (:meth:`at`): draw ``j`` is the
    first particle whose cumulative weight exceeds ``(r + j) / n``."""

    def __init__(self, weights: ArrayLike, n: int, rng: np.random.Generator) -> None:
        w = np.asarray(weights, dtype=np.float64)
        self.n = int(n)
        self.n_weights = len(w)
        if n <= 0:
            self.cumulative = np.zeros(0)
            self.offset = 0.0
            return
        total = w.sum()
        if not np.isfinite(total) or total <= 0:
            raise ValueError("weights must have a positive finite sum")
        c = np.cumsum(w / total)
        c[-1] = 1.0
        self.cumulative = c
        self.offset = rng.random()

    def at(self, positions: NDArray[np.integer]) -> NDArray[np.intp]:
        """The particle indices of the draws at ``positions`` (each in ``[0, n)``)."""
        u = (self.offset + positions) / self.n
        idx = np.searchsorted(self.cumulative, u, side="right")
        return np.minimum(idx, self.n_weights - 1).astype(np.intp)

    def all(self) -> NDArray[np.intp]:
        """Every draw, in order."""
        if self.n <= 0:
            return np.zeros(0, dtype=np.intp)
        return self.at(np.arange(self.n))


def low_variance_resample(weights: ArrayLike, n: int, rng: np.random.Generator) -> NDArray[np.intp]:
    """Indices of ``n`` draws from normalized ``weights`` with one random offset ``r ~ U[0, 1/n)``.

    Each particle ``i`` is drawn ``floor(n w_i)`` or ``ceil(n w_i)`` times (Table 4.4).
    """
    return LowVarianceDraws(weights, n, rng).all()
