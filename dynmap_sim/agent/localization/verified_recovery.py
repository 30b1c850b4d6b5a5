"""Global recovery by a verified challenger (``MCLConfig.recovery_global = "verify"``).

Augmented MCL (*Probabilistic Robotics* Table 8.3) puts random poses into the one particle set
when the fit drops; the heaviest cluster is then the estimate, so a random pose that fits
*less badly* than a tracked cloud fitting badly wins, wherever it is. Here the random poses
go into a second particle set, the **challenger**: a global localization filter of its own
(uniform start over the free space; Table 8.3 inside it, against the tracked set's
``w_slow`` and gated at the acceptance level, so it keeps drawing random poses until it
fits well enough to be adopted). It runs only while the tracked set's recovery gate is
open (``AMCLFilter.gate_open``) and replaces the tracked set only once it is *verified*:
for ``recovery_accept_updates`` consecutive filter updates its scan fits at its estimate

* at least ``recovery_accept_ratio * w_ref`` per beam (``w_ref`` the tracked set's reference,
  the fit a correctly localized filter has had: a kidnapped robot's true pose reaches it, a
  stranger on a stale map does not), and
* better than the tracked set's fit at the tracked estimate.

When the gate closes (the tracked set fits again) the challenger is dropped. Verifying a
new hypothesis before believing it is the rule of multi-hypothesis localization (Jensfelt
& Kristensen 2001, IEEE T-RA 17(5)); Lenser & Veloso's sensor resetting (2000) and Table
8.3 both adopt new poses without it.
"""

from __future__ import annotations

import copy
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:
    from dynmap_sim.agent.localization.particle_filter import AMCLFilter


class VerifiedRecovery:
    """The challenger set of one tracked :class:`AMCLFilter` and its verification count."""

    def __init__(self) -> None:
        self.challenger: AMCLFilter | None = None
        #: Consecutive updates the challenger passed the test.
        self.n_accepted = 0
        #: Challengers started / adopted so far (diagnostics).
        self.n_started = 0
        self.n_adopted = 0

    def reset(self) -> None:
        """Drop the challenger (gate closed, adopted, or a new run)."""
        self.challenger = None
        self.n_accepted = 0

    def step(
        self,
        tracked: AMCLFilter,
        tracked_pose: ArrayLike,
        ranges_m: ArrayLike,
        odom_old: ArrayLike | None,
        odom_new: ArrayLike,
        rng: np.random.Generator,
    ) -> bool:
        """One filter update, after ``tracked.correct``: start, move and weigh the
        challenger, and adopt it into ``tracked`` when verified (returns True then; the
        caller re-takes the estimate). ``odom_old``: the odometry at the previous update
        (None at the first update of a run)."""
        if not tracked.gate_open():
            self.reset()  # the tracked set fits again (or never stopped)
            return False
        ch = self.challenger
        if ch is None:
            ch = copy.copy(tracked)  # shares the map, likelihood table and free cells
            # Table 8.3 inside the challenger, gated at the acceptance level: it keeps
            # drawing random poses, from its first update on, while its fit is below what
            # it must reach to be adopted.
            ch.config = replace(
                tracked.config,
                recovery_global="inject",
                recovery_ratio_threshold=tracked.config.recovery_accept_ratio,
                recovery_min_updates=1,
            )
            ch.init_uniform(rng)
            # Its own Table 8.3 recovery measures against the fit of the tracking so far:
            # a challenger that settles on a place fitting worse keeps drawing random poses
            # (from its own start, w_slow would learn the wrong place's level and stop).
            ch.w_slow = tracked.w_slow
            ch.n_random_injected = ch.n_local_injected = 0
            self.challenger = ch
            self.n_started += 1
        elif odom_old is not None:
            ch.predict(odom_old, odom_new, rng)
        ch.correct(ranges_m)
        pose, _ = ch.estimate()
        fit = ch.mean_beam_loglik(pose, ranges_m)
        fit_tracked = tracked.mean_beam_loglik(tracked_pose, ranges_m)
        w_ref = tracked.reference_weight()
        bar = np.log(tracked.config.recovery_accept_ratio * w_ref) if w_ref > 0 else np.inf
        ok = bool(np.isfinite(fit) and fit >= bar and fit > fit_tracked)
        self.n_accepted = self.n_accepted + 1 if ok else 0
        if self.n_accepted >= tracked.config.recovery_accept_updates:
            tracked.adopt(ch)
            self.n_adopted += 1
            self.reset()
            return True
        ch.resample(rng)
        return False
