"""Means over seeds with 95 % confidence intervals, and paired differences (sweep reports).

A sweep repeats an experiment over a handful of seeds (typically 3-10). Each seed gives one
number per localizer and day (its mean position error that day); these numbers are the
samples. The interval of their mean uses **Student's t** with ``n - 1`` degrees of freedom:

    mean ± t(0.975, n-1) · s / sqrt(n)

because the spread ``s`` is itself estimated from the same few seeds. With the normal
quantile (1.96) instead, an interval over 4 seeds would be far too narrow: t(0.975, 3) =
3.18, so it would hold the true mean in about 86 % of sweeps, not 95 %. The t interval is
exact when the per-seed values are normally distributed and robust enough otherwise (each
value is itself a mean over hundreds of scans).

Two localizers that ran on the same seed saw the very same world, people and sensor noise,
so their comparison is **paired**: the interval is that of the per-seed differences
``a - b`` (:func:`paired_difference`), much narrower than comparing two independent
intervals, since the seed-to-seed variation common to both cancels.

One seed gives a mean but no interval (NaN bounds); no seed gives NaN throughout.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from dynmap_sim.metrics.result import Result

#: The confidence level of the sweep reports' intervals.
CI_LEVEL = 0.95


@dataclass(frozen=True, eq=False)
class MeanInterval(Result):
    """The mean of ``n`` samples with its two-sided confidence interval (Student t).

    ``sd``: sample standard deviation (``ddof=1``); ``half_width``: ``t · sd / sqrt(n)``.
    NaN where undefined (``n < 2``: no interval; ``n == 0``: no mean either).
    """

    n: int
    mean: float
    sd: float
    half_width: float
    low: float
    high: float
    level: float = CI_LEVEL

    def contains(self, value: float) -> bool:
        """Whether ``value`` lies in the interval (False when there is none)."""
        return bool(self.low <= value <= self.high)


def t_quantile(n: int, level: float = CI_LEVEL) -> float:
    """The two-sided Student t quantile for ``n`` samples (``n - 1`` degrees of freedom);
    NaN for ``n < 2``."""
    if n < 2:
        return math.nan
    from scipy import stats  # here: scipy.stats takes a while to import, few callers need it

    return float(stats.t.ppf(0.5 + level / 2.0, n - 1))


def mean_interval(values: ArrayLike, level: float = CI_LEVEL) -> MeanInterval:
    """Mean and ``level`` confidence interval of ``values`` (NaN entries skipped)."""
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), not {level!r}")
    x = np.asarray(values, dtype=np.float64).ravel()
    x = x[np.isfinite(x)]
    n = int(x.size)
    nan = math.nan
    if n == 0:
        return MeanInterval(0, nan, nan, nan, nan, nan, level)
    mean = float(x.mean())
    if n == 1:
        return MeanInterval(1, mean, nan, nan, nan, nan, level)
    sd = float(x.std(ddof=1))
    half = t_quantile(n, level) * sd / math.sqrt(n)
    return MeanInterval(n, mean, sd, half, mean - half, mean + half, level)


def paired_difference(a: ArrayLike, b: ArrayLike, level: float = CI_LEVEL) -> MeanInterval:
    """Mean and interval of the paired differences ``a[i] - b[i]`` (same seed ``i``); pairs
    with a NaN on either side are dropped."""
    x = np.asarray(a, dtype=np.float64).ravel()
    y = np.asarray(b, dtype=np.float64).ravel()
    if x.shape != y.shape:
        raise ValueError(f"paired samples need the same length, not {x.size} and {y.size}")
    return mean_interval(x - y, level)


@dataclass(frozen=True, eq=False)
class BootstrapInterval(Result):
    """A statistic of ``n`` samples with its percentile bootstrap interval (Efron &
    Tibshirani 1993, ch. 13): ``low`` and ``high`` are the ``(1 - level) / 2`` and
    ``(1 + level) / 2`` quantiles of the statistic over ``n_boot`` resamples with
    replacement. NaN bounds with fewer than two samples, NaN throughout with none."""

    n: int
    value: float
    low: float
    high: float
    level: float = CI_LEVEL
    n_boot: int = 0

    def excludes(self, value: float) -> bool:
        """Whether ``value`` lies outside the interval (False when there is none)."""
        return bool(value < self.low or value > self.high)


#: Resamples of :func:`bootstrap_interval`: the percentile interval's bounds move by well
#: under 1 % of its width between draws at this size.
N_BOOT = 4000


def bootstrap_interval(
    values: ArrayLike,
    statistic: str = "median",
    level: float = CI_LEVEL,
    n_boot: int = N_BOOT,
    seed: int = 0,
) -> BootstrapInterval:
    """``statistic`` (``median``, ``mean``, ``p90`` or ``share``: the mean of 0/1 values) of
    the finite ``values`` with its percentile bootstrap interval. Used over *worlds*: each
    world is one sample, so the interval says how much the verdict would move on another
    draw of worlds. ``seed`` fixes the resamples: the same values give the same interval."""
    stats = {
        "median": lambda x: np.median(x, axis=-1),
        "mean": lambda x: np.mean(x, axis=-1),
        "share": lambda x: np.mean(x, axis=-1),
        "p90": lambda x: np.quantile(x, 0.9, axis=-1),
    }
    if statistic not in stats:
        raise ValueError(f"statistic must be one of {sorted(stats)}, not {statistic!r}")
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), not {level!r}")
    x = np.asarray(values, dtype=np.float64).ravel()
    x = x[np.isfinite(x)]
    n = int(x.size)
    if n == 0:
        return BootstrapInterval(0, math.nan, math.nan, math.nan, level, 0)
    f = stats[statistic]
    value = float(f(x))
    if n == 1:
        return BootstrapInterval(1, value, math.nan, math.nan, level, 0)
    rng = np.random.default_rng(seed)
    draws = f(x[rng.integers(0, n, size=(n_boot, n))])
    low, high = np.quantile(draws, [(1 - level) / 2, (1 + level) / 2])
    return BootstrapInterval(n, value, float(low), float(high), level, n_boot)
