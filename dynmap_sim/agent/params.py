"""Frozen parameter objects of the agent's modules, built from a scenario's flat ``params``.

A scenario file gives a localizer its parameters as one flat table (``params = {
min_update_dist_m = 0.1 }``); each module keeps them in a frozen dataclass (like
:class:`~dynmap_sim.agent.localization.particle_filter.MCLConfig`). These helpers give every
field the type of its default (a TOML ``3`` for a float field becomes ``3.0``, a list for a
tuple field a tuple), so that the numbers a module computes do not depend on how a value was
spelled, and build a config from such a table, naming the unknown keys.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import fields, replace
from typing import Any, TypeVar

C = TypeVar("C")


def coerce_fields(config: Any) -> None:
    """Convert every field of the frozen dataclass ``config`` to the type of its default.

    ``bool``, ``int``, ``float`` and ``str`` defaults convert the value; a non-empty tuple
    default converts the value to a tuple of its first element's type. Other fields (nested
    configs) are left as they are. Call it from ``__post_init__``.
    """
    for f in fields(config):
        default, value = f.default, getattr(config, f.name)
        if isinstance(default, bool):
            value = bool(value)
        elif isinstance(default, int | float | str):
            value = type(default)(value)
        elif isinstance(default, tuple) and default:
            value = tuple(type(default[0])(v) for v in value)
        else:
            continue
        object.__setattr__(config, f.name, value)


def unknown_keys(cls: type, params: Mapping[str, Any]) -> list[str]:
    """The keys of ``params`` that are not fields of the dataclass ``cls``, sorted."""
    return sorted(set(params) - {f.name for f in fields(cls)})


def config_from_params(
    cls: type[C], owner: str, params: Mapping[str, Any], base: C | None = None
) -> C:
    """``cls(**params)`` (or ``base`` with ``params`` replaced); a key that is not a field of
    ``cls`` is a :class:`TypeError` ``"<owner>: unknown parameters [...]"`` that lists them."""
    unknown = unknown_keys(cls, params)
    if unknown:
        known = ", ".join(sorted(f.name for f in fields(cls)))
        raise TypeError(f"{owner}: unknown parameters {unknown}; known: {known}")
    return replace(base, **params) if base is not None else cls(**params)
