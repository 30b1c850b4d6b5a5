"""Progress of the robot along its route (a waypoint polyline), for rewards and episode ends.

The robot's position is projected onto the route polyline, searching only from the segment
it is on to a few segments ahead, and accepting at most ``max_gain_m`` of new progress per
update, so a route that returns to its start (a tour) or passes a place twice is followed in
order and cutting across a loop earns nothing. Progress is the largest arc length [m] reached
so far.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike


class RouteProgress:
    """Monotone arc-length progress along ``route`` ``(K, 2)`` [m]."""

    def __init__(
        self,
        route: ArrayLike,
        lookahead: int = 3,
        goal_tolerance_m: float = 0.3,
        max_gain_m: float = 2.0,
    ):
        pts = np.asarray(route, dtype=np.float64).reshape(-1, 2)
        if pts.shape[0] < 1:
            raise ValueError("a route needs at least one waypoint")
        self._pts = [(float(x), float(y)) for x, y in pts]
        lens = np.hypot(*np.diff(pts, axis=0).T) if pts.shape[0] > 1 else np.zeros(0)
        self._len = [float(v) for v in lens]
        self._cum = [0.0, *np.cumsum(lens).tolist()]
        self.length_m = self._cum[-1]
        self.lookahead = int(lookahead)
        self.goal_tolerance_m = float(goal_tolerance_m)
        self.max_gain_m = float(max_gain_m)
        self.reset()

    def reset(self) -> None:
        """Back to the start of the route."""
        self._k = 0
        self.progress_m = 0.0

    @property
    def fraction(self) -> float:
        """Fraction of the route done, in ``[0, 1]``."""
        return self.progress_m / self.length_m if self.length_m > 0.0 else 1.0

    def update(self, x_m: float, y_m: float) -> float:
        """Project the position; return the progress made by this update [m] (>= 0)."""
        n_seg = len(self._len)
        if n_seg == 0:
            return 0.0
        best_d2 = math.inf
        k0, done_m, gain_m = self._k, self.progress_m, self.max_gain_m
        best_k, best_s = k0, done_m
        pts, lens, cum = self._pts, self._len, self._cum
        for k in range(k0, min(k0 + self.lookahead + 1, n_seg)):
            if k > k0 and cum[k] - done_m > gain_m:
                # too far ahead along the route for one update, and so is every later
                # segment (its start is farther still, and s >= cum[k] below)
                break
            (x0, y0), (x1, y1) = pts[k], pts[k + 1]
            dx, dy = x1 - x0, y1 - y0
            L = lens[k]
            t = ((x_m - x0) * dx + (y_m - y0) * dy) / (L * L) if L > 0.0 else 0.0
            t = min(max(t, 0.0), 1.0)
            ex, ey = x0 + t * dx - x_m, y0 + t * dy - y_m
            d2 = ex * ex + ey * ey
            s = cum[k] + t * L
            if k > k0 and s - done_m > gain_m:
                continue  # too far ahead along the route for one update
            if d2 < best_d2 - 1e-12:
                best_d2, best_k, best_s = d2, k, s
        self._k = best_k
        gained = max(best_s - done_m, 0.0)
        self.progress_m += gained
        return gained

    def done(self, x_m: float, y_m: float) -> bool:
        """True once the last waypoint is reached after having followed the whole route."""
        gx, gy = self._pts[-1]
        near_goal = math.hypot(x_m - gx, y_m - gy) <= self.goal_tolerance_m
        return near_goal and self.progress_m >= self.length_m - 2.0 * self.goal_tolerance_m
