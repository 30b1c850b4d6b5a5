"""Synthetic corridors and a unicycle robot for the control tests (no simulator); the tests
import it by putting this folder on ``sys.path`` (like ``tests/experiments/fake_env.py``)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from dynmap_sim.agent.control.controller import Controller
from dynmap_sim.agent.planning.clearance_grid import ClearanceGrid, build_clearance_grid

#: The hard clearance (robot radius 0.2 m + 0.05 m margin) and the cruise speed.
HARD_M = 0.25
SPEED_MPS = 0.35


def corridor(extra: np.ndarray | None = None, half_m: float = 1.0) -> np.ndarray:
    """Walls of a straight corridor along x (``y = +-half_m``, x from -1 to 9) plus ``extra``."""
    walls = np.array([[-1.0, -half_m, 9.0, -half_m], [-1.0, half_m, 9.0, half_m]])
    return walls if extra is None else np.concatenate([walls, extra])


def grid_of(segments: np.ndarray) -> ClearanceGrid:
    return build_clearance_grid(segments, np.zeros((0, 3)), resolution_m=0.05)


def seg_distance(xy: np.ndarray, segs: np.ndarray) -> float:
    """Exact distance from a point to the nearest of the segments ``(N, 4)``."""
    a, b = segs[:, :2], segs[:, 2:]
    ab = b - a
    u = np.clip(np.einsum("ij,ij->i", xy - a, ab) / np.einsum("ij,ij->i", ab, ab), 0.0, 1.0)
    return float(np.min(np.hypot(*(a + u[:, None] * ab - xy).T)))


def drive(
    ctrl: Controller,
    grid: ClearanceGrid,
    pose: np.ndarray,
    dt_s: float = 0.1,
    steps: int = 1500,
    stop: Callable[[Controller], bool] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Unicycle ``(x, y, theta)`` driven by ``ctrl`` until done (or ``stop``); poses ``(T+1,
    3)`` and commands ``(T, 2)``."""
    poses, cmds = [np.asarray(pose, float)], []
    for _ in range(steps):
        if ctrl.done or (stop is not None and stop(ctrl)):
            break
        x, y, th = poses[-1]
        v, w = (float(c) for c in ctrl.command(poses[-1], grid))
        cmds.append((v, w))
        poses.append(
            np.array([x + v * math.cos(th) * dt_s, y + v * math.sin(th) * dt_s, th + w * dt_s])
        )
    return np.array(poses), np.array(cmds).reshape(-1, 2)
