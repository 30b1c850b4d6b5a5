"""Gymnasium registration of the shipped worlds (entry points are strings: nothing heavy loads)."""

from __future__ import annotations

from pathlib import Path

import gymnasium

#: Folder of the worlds that ship with the package's source tree.
WORLDS_DIR = Path(__file__).resolve().parent.parent / "worlds"

ENV_IDS = ("dynmap_sim/Apartment-v0", "dynmap_sim/Lab-v0", "dynmap_sim/World-v0")


def register_envs() -> None:
    """Register the envs once; calling again is a no-op."""
    if ENV_IDS[0] in gymnasium.registry:
        return
    entry = "dynmap_sim.env:DynMapEnv"
    gymnasium.register(id=ENV_IDS[0], entry_point=entry, kwargs={"world": "apartment"})
    gymnasium.register(id=ENV_IDS[1], entry_point=entry, kwargs={"world": "lab"})
    gymnasium.register(id=ENV_IDS[2], entry_point=entry)
