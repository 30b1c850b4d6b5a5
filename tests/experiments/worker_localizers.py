"""Localizers for the worker-process tests: one that fails, one that kills its process, one
that reports its process id (importable by name from a spawned worker)."""

from __future__ import annotations

import os

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
