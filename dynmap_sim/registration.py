"""Gymnasium registration of the shipped worlds (entry points are strings: nothing heavy loads).

The entry points are the functions :func:`make_env` and :func:`make_world_env`, not the env
class, for two reasons:

* the render mode reaches :class:`~dynmap_sim.env.DynMapEnv` as given (``"human"``: its own
  matplotlib window; an unknown mode: its error names the modes it has), instead of
  Gymnasium choosing wrappers from the class's metadata.
* ``dynmap_sim/World-v0`` needs ``world=PATH``; without it the env would silently be the lab.

Gymnasium's passive env checker is off (``disable_env_checker=True``): in Gymnasium 1.4 it
marks the first ``reset`` checked before calling it, so after a first ``reset`` that raised
(``options={"day": 99}``) the first ``step`` fails inside the checker with ``TypeError:
cannot unpack non-iterable NoneType``. The env passes the full ``check_env`` in the tests.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium

#: Folder of the worlds that ship with the package's source tree.
WORLDS_DIR = Path(__file__).resolve().parent.parent / "worlds"

ENV_IDS = ("dynmap_sim/Apartment-v0", "dynmap_sim/Lab-v0", "dynmap_sim/World-v0")


def make_env(**kwargs: Any) -> gymnasium.Env:
    """A :class:`~dynmap_sim.env.DynMapEnv` from the keyword arguments ``gymnasium.make``
    passes (the entry point of the envs of the shipped worlds); ``render_mode="rgb_array_list"``
    collects the frames (``RenderCollection``), as ``gymnasium.make`` does for an env class."""
    from dynmap_sim.env import DynMapEnv

    if kwargs.get("render_mode") == "rgb_array_list":
        from gymnasium.wrappers import RenderCollection

        return RenderCollection(DynMapEnv(**{**kwargs, "render_mode": "rgb_array"}))
    return DynMapEnv(**kwargs)


def make_world_env(world: Any = None, **kwargs: Any) -> gymnasium.Env:
    """The entry point of ``dynmap_sim/World-v0``: ``world`` (a world file or a
    ``WorldSpec``) is required."""
    if world is None:
        raise ValueError(
            f"{ENV_IDS[2]} needs world=PATH (a world TOML file) or a WorldSpec; the shipped "
            f"worlds are {ENV_IDS[0]} and {ENV_IDS[1]}"
        )
    return make_env(world=world, **kwargs)


def register_envs() -> None:
    """Register the envs once; calling again is a no-op."""
    if ENV_IDS[0] in gymnasium.registry:
        return
    entry = "dynmap_sim.registration:make_env"
    vec = "dynmap_sim.vector_env:make_vector_env"  # gymnasium.make_vec: DynMapVectorEnv
    common: dict[str, Any] = {
        "entry_point": entry,
        "vector_entry_point": vec,
        "disable_env_checker": True,
    }
    gymnasium.register(id=ENV_IDS[0], kwargs={"world": "apartment"}, **common)
    gymnasium.register(id=ENV_IDS[1], kwargs={"world": "lab"}, **common)
    gymnasium.register(
        id=ENV_IDS[2],
        entry_point="dynmap_sim.registration:make_world_env",
        vector_entry_point=vec,
        disable_env_checker=True,
    )
