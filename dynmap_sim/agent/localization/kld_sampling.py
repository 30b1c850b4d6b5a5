"""KLD-sampling: how many particles the posterior needs (Fox 2003; *Probabilistic Robotics*
Table 8.4).

With ``k`` occupied histogram bins, ``n = (k-1)/(2 eps) (1 - 2/(9(k-1)) + sqrt(2/(9(k-1))) z)^3``
particles bound the K-L divergence between the sample-based and the true posterior by
``eps`` with probability ``1-delta`` (``z`` the upper ``1-delta`` normal quantile). AMCL's
bins are 0.5 m x 0.5 m x 10 degrees. Note: nav2 passes ``pf_z`` (0.99 by default) to this
formula as ``z`` itself, not as a probability (ros-navigation/navigation2#4190); we do the
same so that ``nav2-default`` behaves like nav2.

One occupied bin (``k = 1``, the bound's ``k - 1 = 0`` degrees of freedom): nav2's
``pf_resample_limit`` returns ``max_samples`` (``one_bin = "max"``, the default), so a
cloud narrower than a bin that happens to lie inside one is resampled to the maximum and one
that straddles a bin border to the minimum. Fox 2003's algorithm (Table 1) and *Probabilistic
Robotics* Table 8.4 compute the bound only once ``k > 1`` (``M_χ`` stays 0), so the loop
stops at the minimum (``one_bin = "min"``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: Values of ``one_bin``: the count for a single occupied bin (module doc).
ONE_BIN_RULES = ("max", "min")


def kld_sample_count(
    k_bins: ArrayLike,
    pf_err: float,
    pf_z: float,
    min_particles: int,
    max_particles: int,
    one_bin: str = "max",
) -> NDArray[np.int64]:
    """KLD bound for ``k_bins`` occupied bins (vectorized), clamped to ``[min, max]``; one
    bin gives ``max_particles`` (nav2) or ``min_particles`` (Fox 2003), see ``one_bin``."""
    if one_bin not in ONE_BIN_RULES:
        raise ValueError(f"one_bin must be one of {ONE_BIN_RULES}, got {one_bin!r}")
    k = np.asarray(k_bins, dtype=np.float64)
    km1 = np.maximum(k - 1.0, 1.0)
    b = 2.0 / (9.0 * km1)
    x = 1.0 - b + np.sqrt(b) * pf_z
    n = np.ceil(km1 / (2.0 * pf_err) * x**3)
    n = np.where(k <= 1, max_particles if one_bin == "max" else min_particles, n)
    return np.clip(n, min_particles, max_particles).astype(np.int64)


def bin_keys(
    particles: ArrayLike, cell_m: float = 0.5, angle_rad: float = np.deg2rad(10.0)
) -> NDArray[np.int64]:
    """Integer key of each particle's histogram bin ``(x, y, theta)``."""
    p = np.asarray(particles, dtype=np.float64)
    ix = np.floor(p[:, 0] / cell_m).astype(np.int64)
    iy = np.floor(p[:, 1] / cell_m).astype(np.int64)
    it = np.floor(p[:, 2] / angle_rad).astype(np.int64)
    return (ix + 100_000) * 400_000_000 + (iy + 100_000) * 2_000 + (it + 1_000)


def kld_stop(
    keys_in_draw_order: ArrayLike,
    pf_err: float,
    pf_z: float,
    min_particles: int,
    max_particles: int,
    one_bin: str = "max",
) -> int | None:
    """Index of the draw at which AMCL's sequential KLD loop stops (the first whose count
    exceeds the bound for the bins occupied so far), None if none of ``keys_in_draw_order``
    does. A prefix of the draws has the same bins so far at each of its draws, so its stop
    (if any) is the whole sequence's: :func:`kld_prefix_size_lazy` relies on that."""
    keys = np.asarray(keys_in_draw_order)
    if len(keys) == 0:
        return None
    _, first = np.unique(keys, return_index=True)
    new_bin = np.zeros(len(keys), dtype=np.int64)
    new_bin[first] = 1
    k = np.cumsum(new_bin)
    count = np.arange(1, len(keys) + 1)
    # the bound of each bin count 1..k[-1] once (elementwise: the same numbers as per draw)
    bound = kld_sample_count(np.arange(1, k[-1] + 1), pf_err, pf_z, min_particles,
                             max_particles, one_bin)  # fmt: skip
    limit = bound[k - 1]
    stop = np.nonzero(count > limit)[0]
    return int(stop[0]) if len(stop) else None


def _clipped_size(stop: int | None, n_draws: int, min_particles: int, max_particles: int) -> int:
    """The loop's size clamped to ``[min(min_particles, n_draws), max_particles]`` (as
    ``np.clip`` does it, the upper bound last; in integers, without numpy's call)."""
    n = stop + 1 if stop is not None else n_draws
    return min(max(int(n), min(min_particles, n_draws)), int(max_particles))


def kld_prefix_size(
    keys_in_draw_order: ArrayLike,
    pf_err: float,
    pf_z: float,
    min_particles: int,
    max_particles: int,
    one_bin: str = "max",
) -> int:
    """Number of draws AMCL's sequential KLD loop keeps (``pf_update_resample``).

    Samples are drawn one at a time and the loop stops as soon as the count exceeds the
    bound for the bins occupied so far. ``keys_in_draw_order`` are the bin keys of a
    candidate sequence of ``max_particles`` draws in random order; ``one_bin``: the bound
    while they all fall into one bin (:func:`kld_sample_count`).
    """
    keys = np.asarray(keys_in_draw_order)
    if len(keys) == 0:
        return 0
    stop = kld_stop(keys, pf_err, pf_z, min_particles, max_particles, one_bin)
    return _clipped_size(stop, len(keys), min_particles, max_particles)


def kld_prefix_size_lazy(
    keys_of: Callable[[int], NDArray[np.int64]],
    n_draws: int,
    pf_err: float,
    pf_z: float,
    min_particles: int,
    max_particles: int,
    one_bin: str = "max",
    first: int = 1024,
) -> int:
    """:func:`kld_prefix_size` of ``keys_of(n_draws)``, asking ``keys_of(m)`` (the keys of
    the first ``m`` draws) for ``m`` = ``first`` (at least ``min_particles + 1``: the loop
    never stops before), doubled until the loop stops within them: the same size, without
    the keys of the draws after the stop (usually most of them)."""
    if n_draws <= 0:
        return 0
    m = min(n_draws, max(first, min_particles + 1))
    while True:
        stop = kld_stop(keys_of(m), pf_err, pf_z, min_particles, max_particles, one_bin)
        if stop is not None or m == n_draws:
            return _clipped_size(stop, n_draws, min_particles, max_particles)
        m = min(n_draws, 2 * m)
