"""Low-variance (systematic) resampling, *Probabilistic Robotics* Table 4.4."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray


def low_variance_resample(weights: ArrayLike, n: int, rng: np.random.Generator) -> NDArray[np.intp]:
    """Indices of ``n`` draws from normalized ``weights`` with one random offset ``r ~ U[0, 1/n)``.

    Each particle ``i`` is drawn ``floor(n w_i)`` or ``ceil(n w_i)`` times (Table 4.4).
    """
    w = np.asarray(weights, dtype=np.float64)
    if n <= 0:
        return np.zeros(0, dtype=np.intp)
    total = w.sum()
    if not np.isfinite(total) or total <= 0:
        raise ValueError("weights must have a positive finite sum")
    c = np.cumsum(w / total)
    c[-1] = 1.0
    u = (rng.random() + np.arange(n)) / n
    return np.minimum(np.searchsorted(c, u, side="right"), len(w) - 1).astype(np.intp)
