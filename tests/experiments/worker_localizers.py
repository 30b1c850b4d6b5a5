"""Localizers for the worker-process tests: one that fails, one that kills its process, one
that reports its process id (importable by name from a spawned worker)."""

from __future__ import annotations

import os

import numpy as np
from fake_env import RecordingLocalizer


class FailingLocalizer(RecordingLocalizer):
    """Raises at its 5th update of day 2."""

    def update(self, odom, scan):
        est = super().update(odom, scan)
        self.n = getattr(self, "n", 0) + 1
        if self.calls[-1][1] == 2 and self.n % 51 == 5:
            raise ValueError("the map is on fire")
        return est


class DyingLocalizer(RecordingLocalizer):
    """Kills its own process at the first update (a native crash, say)."""

    def update(self, odom, scan):
        os._exit(3)


class PidLocalizer(RecordingLocalizer):
    """Records the process ids it ran in."""

    def begin_run(self, prior):
        super().begin_run(prior)
        self.pids = [*getattr(self, "pids", []), os.getpid()]
        self.blas_threads = os.environ.get("OPENBLAS_NUM_THREADS")


class NoneLocalizer(RecordingLocalizer):
    """Breaks the contract: update() returns None."""

    def update(self, odom, scan):
        super().update(odom, scan)


class FlatMeanLocalizer(RecordingLocalizer):
    """Breaks the contract: a (2,) mean."""

    def update(self, odom, scan):
        e = super().update(odom, scan)
        return type(e)(mean=e.mean[:2], cov=e.cov)


class InfiniteCovLocalizer(RecordingLocalizer):
    """Breaks the contract: a non-finite covariance at its third scan."""

    def update(self, odom, scan):
        e = super().update(odom, scan)
        self.k = getattr(self, "k", 0) + 1
        if self.k == 3:
            return type(e)(mean=e.mean, cov=np.full((3, 3), np.inf))
        return e
