"""Shared helper of the CARMEN reader's tests."""

from __future__ import annotations

import warnings
from typing import Any

from dynmap_sim.io.carmen import CarmenLog, CarmenOdometryWarning, read_carmen


def read_warned(path: Any, **kw: Any) -> tuple[CarmenLog, list[str]]:
    """``read_carmen(path, **kw)`` and the texts of the odometry warnings it gave."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        log = read_carmen(path, **kw)
    return log, [str(w.message) for w in caught if issubclass(w.category, CarmenOdometryWarning)]
