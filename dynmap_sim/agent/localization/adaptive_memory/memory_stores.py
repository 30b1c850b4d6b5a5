"""H&W §3 (eq. 1, Figs. 1-2): memory stores as circular buffers of λ time slots of Δt.

Every store (sensory SM, short-term STM, long-term LTM) keeps its data in λ slots; the slot
current at time ``t`` is (eq. 1) ``τ = floor((t - t_s) / Δt) mod λ`` with ``t_s`` the start
of operation, so a store spans ``λ·Δt`` and overwrites its oldest slot. §7.1's values are the
defaults of :class:`~dynmap_sim.agent.localization.adaptive_memory.localizer.AdaptiveMemoryConfig`:
SM Δt = 0.1 s, λ = 10 (1 s); STM Δt = 0.1 s, λ = 100 (10 s); LTM Δt = 8640 s, λ = 10 (one day).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, Generic, TypeVar

import numpy as np

T = TypeVar("T")

#: What a long-term slot that becomes current starts from (``slot_init``), see :class:`LTMStore`.
SLOT_INITS = ("copy_latest", "prior_only", "keep")


def slot_index(t_s: float, start_s: float, dt_s: float, n_slots: int) -> int:
    """H&W eq. 1: the current slot ``floor((t - t_s) / Δt) mod λ`` (Python's mod: in [0, λ))."""
    if dt_s <= 0 or n_slots < 1:
        raise ValueError(f"slot_index: dt_s must be > 0 and n_slots >= 1, got {dt_s}, {n_slots}")
    return int(math.floor((t_s - start_s) / dt_s)) % int(n_slots)


class SlotBuffer(Generic[T]):
    """One store's circular buffer (§3): ``n_slots`` slots of ``dt_s``; :meth:`put` writes the
    slot of time ``t`` (eq. 1), overwriting what it held from ``n_slots·dt_s`` earlier."""

    def __init__(self, dt_s: float, n_slots: int, start_s: float = 0.0) -> None:
        slot_index(start_s, start_s, dt_s, n_slots)  # checks the arguments
        self.dt_s = float(dt_s)
        self.n_slots = int(n_slots)
        self.start_s = float(start_s)
        self.slots: list[T | None] = [None] * self.n_slots
        self.stamps = np.full(self.n_slots, np.nan)

    def slot(self, t_s: float) -> int:
        return slot_index(t_s, self.start_s, self.dt_s, self.n_slots)

    def put(self, t_s: float, value: T) -> int:
        k = self.slot(t_s)
        self.slots[k] = value
        self.stamps[k] = t_s
        return k

    def latest(self) -> T | None:
        """The most recently written slot's content (None: empty)."""
        if np.all(np.isnan(self.stamps)):
            return None
        return self.slots[int(np.nanargmax(self.stamps))]

    def items(self) -> list[T]:
        """The filled slots, oldest first."""
        order = [int(k) for k in np.argsort(self.stamps) if not np.isnan(self.stamps[k])]
        return [self.slots[k] for k in order if self.slots[k] is not None]  # type: ignore[misc]

    def clear(self) -> None:
        self.slots = [None] * self.n_slots
        self.stamps[:] = np.nan


class LTMStore:
    """The long-term memory's obstacle substore (§3, §4.3): λ grids of log-odds, one per slot
    of Δt (§7.1: 10 slots of 2.4 h, one day in all).

    A slot that becomes current (eq. 1) starts, by ``slot_init``:

    * ``"copy_latest"`` (default): a copy of the most recently updated slot. H&W's LTM spans
      exactly one day and their robot ran once a day at the same time, so every run lands in
      the same slot; taken literally (a slot is overwritten when it comes round again) the
      map would be erased every day and nothing would be learned over the weeks, against
      their Figs. 5-7 (semistatic points 23 % on day 1, 3 % on day 7). Starting a slot from
      the latest map keeps what was learned and lets the other slots stay as candidates for
      §6.1's map selection.
    * ``"prior_only"``: the literal reading: the slot restarts from the prior (walls).
    * ``"keep"``: the slot keeps what it held a day earlier (a map per time of day).

    ``new_map()`` makes the prior's map (walls seeded, :mod:`.ltm_map`). The grids are
    allocated lazily: a slot never current holds None and is no candidate for selection.
    """

    def __init__(
        self, dt_s: float, n_slots: int, slot_init: str, new_map: Callable[[], Any]
    ) -> None:
        if slot_init not in SLOT_INITS:
            raise ValueError(f"slot_init must be one of {SLOT_INITS}, got {slot_init!r}")
        self.buffer: SlotBuffer[Any] = SlotBuffer(dt_s, n_slots)
        self.slot_init = slot_init
        self.new_map = new_map
        self.current = -1

    def activate(self, t_s: float) -> int:
        """Make the slot of time ``t_s`` current (eq. 1), initializing it by ``slot_init``
        when it is not current already; returns its index."""
        k = self.buffer.slot(t_s)
        if k == self.current:
            self.buffer.stamps[k] = t_s
            return k
        latest = self.buffer.latest()
        if self.slot_init == "copy_latest" and latest is not None:
            value = latest.copy()
        elif self.slot_init == "keep" and self.buffer.slots[k] is not None:
            value = self.buffer.slots[k]
        else:
            value = self.new_map()
        self.buffer.put(t_s, value)
        self.current = k
        return k

    def map(self, k: int | None = None) -> Any:
        return self.buffer.slots[self.current if k is None else k]

    def filled(self) -> list[int]:
        """Indices of the slots that hold a map."""
        return [k for k, m in enumerate(self.buffer.slots) if m is not None]
