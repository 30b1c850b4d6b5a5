"""dynmap_sim: a Gymnasium testbed for long-term SLAM in changing indoor environments.

Importing the package registers the environments ``dynmap_sim/Apartment-v0``,
``dynmap_sim/Lab-v0`` and ``dynmap_sim/World-v0`` (keyword ``world=PATH``).
"""

from __future__ import annotations

from dynmap_sim.types import BEAM_CLASSES, BeamClass

__version__ = "0.1.0"
__all__ = ["BEAM_CLASSES", "BeamClass", "__version__"]


def _register_envs() -> None:
    from dynmap_sim.registration import register_envs

    register_envs()


_register_envs()
