"""Frozen parameter objects of the agent's modules, built from a scenario's flat ``params``.

A scenario file gives a localizer its parameters as one flat table (``params = {
min_update_dist_m = 0.1 }``); each module keeps them in a frozen dataclass (like
:class:`~dynmap_sim.agent.localization.particle_filter.MCLConfig`). These helpers give every
field the type of its default (a TOML ``3`` for a float field becomes ``3.0``, a list for a
tuple field a tuple), so that the numbers a module computes do not depend on how a value was
spelled, and build a config from such a table, naming the unknown keys. :func:`check_fields`
checks the values (finite, positive, integer ...), so that a scenario's bad parameter is an
error naming it when the scenario is loaded rather than a crash in the middle of a run.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Collection, Mapping
from dataclasses import fields, replace
from typing import Any, TypeVar

C = TypeVar("C")


def _convert(owner: str, name: str, kind: type, value: Any) -> Any:
    """``value`` as a ``kind`` (bool, int, float or str); a :class:`TypeError` naming
    ``owner`` and ``name`` when it is not one (a string for a number, 1.5 for an integer)."""
    if kind is bool:
        if isinstance(value, bool | numbers.Integral) and value in (0, 1):
            return bool(value)
        what = "true or false"
    elif kind is int:
        if isinstance(value, bool):
            pass
        elif isinstance(value, numbers.Integral):
            return int(value)
        elif isinstance(value, numbers.Real) and math.isfinite(value) and value == int(value):
            return int(value)  # TOML 1e3 or 8000.0
        what = "an integer"
    elif kind is float:
        if isinstance(value, numbers.Real) and not isinstance(value, bool):
            return float(value)
        what = "a number"
    else:
        if isinstance(value, str):
            return value
        what = "a string"
    raise TypeError(f"{owner}: {name} must be {what}, got {value!r}")


def coerce_fields(config: Any, owner: str | None = None) -> None:
    """Convert every field of the frozen dataclass ``config`` to the type of its default.

    ``bool``, ``int``, ``float`` and ``str`` defaults convert the value; a non-empty tuple
    default converts the value to a tuple of its first element's type. Other fields (nested
    configs) are left as they are. A value of another kind (a string for a number, 1.5 for
    an integer) is a :class:`TypeError` ``"<owner>: <field> must be ..., got ..."`` (owner:
    the class name unless given). Call it from ``__post_init__``.
    """
    who = owner or type(config).__name__
    for f in fields(config):
        default, value = f.default, getattr(config, f.name)
        if isinstance(default, bool | int | float | str):
            kind = bool if isinstance(default, bool) else type(default)
            value = _convert(who, f.name, kind, value)
        elif isinstance(default, tuple) and default:
            if isinstance(value, str | bytes) or not isinstance(value, Collection):
                raise TypeError(f"{who}: {f.name} must be a list, got {value!r}")
            kind = type(default[0])
            value = tuple(_convert(who, f.name, kind, v) for v in value)
        else:
            continue
        object.__setattr__(config, f.name, value)


def check_fields(
    config: Any,
    owner: str,
    *,
    positive: Collection[str] = (),
    non_negative: Collection[str] = (),
    fraction: Collection[str] = (),
    finite: Collection[str] = (),
    not_nan: Collection[str] = (),
    at_most: Mapping[str, float] | None = None,
) -> None:
    """Check the values of the (coerced, :func:`coerce_fields`) fields of ``config``; the
    first one out of its range is a :class:`ValueError` naming the owner, the field and the
    value, e.g. ``"static-mcl: max_particles must be an integer >= 1, got -5"``.

    ``positive``: finite and > 0 (an integer field: >= 1); ``non_negative``: finite and >= 0;
    ``fraction``: in [0, 1]; ``finite``: any finite number; ``not_nan``: any number but NaN
    (infinities allowed, e.g. "no floor"); ``at_most``: an upper bound of a field (also
    listed in one of the others). Call it from ``__post_init__`` after :func:`coerce_fields`.
    """
    limits = at_most or {}
    for name in (*positive, *non_negative, *fraction, *finite, *not_nan):
        value = getattr(config, name)
        integer = isinstance(value, int) and not isinstance(value, bool)
        number = "an integer" if integer else "a finite number"
        if name in positive:
            ok, what = math.isfinite(value) and value > 0, number + (" >= 1" if integer else " > 0")
        elif name in non_negative:
            ok, what = math.isfinite(value) and value >= 0, f"{number} >= 0"
        elif name in fraction:
            ok, what = 0 <= value <= 1, "a number in [0, 1]"
        elif name in finite:
            ok, what = math.isfinite(value), number
        else:
            ok, what = not math.isnan(value), "a number (not NaN)"
        if ok and name in limits and not value <= limits[name]:
            ok, what = False, f"{what} and <= {limits[name]:,}"
        if not ok:
            raise ValueError(f"{owner}: {name} must be {what}, got {value!r}")


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
