"""The Localizer role (DESIGN.md §5) and its registry.

A localizer is built once per experiment with the laser description and its own random
generator, then driven by the experiment runner::

    loc = make_localizer("static-mcl", laser=spec, rng=rng, config="tuned")
    for day, run in calendar:
        loc.begin_run(prior)
        for odom, scan in stream:
            est = loc.update(odom, scan)
        loc.end_run()
        ...
        loc.end_day()          # after the last run of a day

Localizers must be picklable: the runner checkpoints them after every run.

Users plug in their own class by ``"package.module:ClassName"``; built-in classes register
themselves with :func:`register_localizer`.
"""

from __future__ import annotations

import importlib
from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

from dynmap_sim.types import LaserSpec, Odometry, PoseEstimate, Prior, Scan


class Localizer(ABC):
    """Base class of every localizer. Subclasses take their parameters as keyword arguments."""

    #: Registry name (set by :func:`register_localizer`).
    name: str = "localizer"

    def __init__(self, laser: LaserSpec, rng: np.random.Generator, **params: Any) -> None:
        if params:
            raise TypeError(f"{type(self).__name__}: unknown parameters {sorted(params)}")
        self.laser = laser
        self.rng = rng

    @abstractmethod
    def begin_run(self, prior: Prior) -> None:
        """Start a run (one episode) with the prior knowledge the scenario grants."""

    @abstractmethod
    def update(self, odom: Odometry, scan: Scan) -> PoseEstimate:
        """Fuse one odometry reading and one scan; return the pose estimate in the map frame."""

    def end_run(self) -> None:  # noqa: B027 - optional hook
        """The run is over (B&D §4.4: offline learning of the run's timescale happens here)."""

    def end_day(self) -> None:  # noqa: B027 - optional hook
        """The day is over (B&D §4.4: daily timescales are learned here)."""


L = TypeVar("L", bound=type[Localizer])


class _Registry:
    """Name -> class table; one instance lives in :data:`LOCALIZERS`.

    Built-in localizer modules are imported lazily by :meth:`get` so that importing this
    module stays cheap; their ``register_localizer`` decorators fill the table.
    """

    #: Modules that define built-in localizers, imported on first lookup.
    BUILTIN_MODULES: tuple[str, ...] = (
        "dynmap_sim.agent.dead_reckoning",
        "dynmap_sim.agent.localization.particle_filter",
        "dynmap_sim.agent.localization.dynamic_map_localizer",
    )

    def __init__(self) -> None:
        self._classes: dict[str, type[Localizer]] = {}
        self._loaded = False

    def add(self, name: str, cls: type[Localizer]) -> None:
        self._classes[name] = cls

    def _load_builtins(self) -> None:
        if self._loaded:
            return
        self._loaded = True
        for mod in self.BUILTIN_MODULES:
            try:
                importlib.import_module(mod)
            except ModuleNotFoundError as exc:  # a built-in that is not written yet
                if exc.name != mod:
                    raise

    def names(self) -> list[str]:
        self._load_builtins()
        return sorted(self._classes)

    def get(self, name: str) -> type[Localizer]:
        """Look up ``name`` (a registry name or ``"module:Class"``)."""
        if ":" in name:
            mod_name, _, cls_name = name.partition(":")
            try:
                cls = getattr(importlib.import_module(mod_name), cls_name)
            except (ImportError, AttributeError) as exc:
                raise ValueError(f"cannot load localizer {name!r}: {exc}") from exc
            if not (isinstance(cls, type) and issubclass(cls, Localizer)):
                raise ValueError(f"{name!r} is not a dynmap_sim.agent.localizer.Localizer")
            return cls
        self._load_builtins()
        try:
            return self._classes[name]
        except KeyError:
            raise ValueError(
                f"unknown localizer {name!r}; known: {', '.join(self.names())} "
                "(or give 'package.module:ClassName')"
            ) from None


#: The localizer registry.
LOCALIZERS = _Registry()


def register_localizer(name: str) -> Callable[[L], L]:
    """Class decorator: make a :class:`Localizer` available under ``name``."""

    def deco(cls: L) -> L:
        cls.name = name
        LOCALIZERS.add(name, cls)
        return cls

    return deco


def make_localizer(
    name: str, *, laser: LaserSpec, rng: np.random.Generator, **params: Any
) -> Localizer:
    """Build the localizer registered as ``name`` (or ``"module:Class"``) with ``params``."""
    return LOCALIZERS.get(name)(laser=laser, rng=rng, **params)
