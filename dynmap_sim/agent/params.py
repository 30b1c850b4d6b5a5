"""Frozen parameter objects of the agent's modules: pydantic dataclasses with one-line errors.

A scenario file gives a module its parameters as one flat table (``params = {
min_update_dist_m = 0.1 }``); each module keeps them in a frozen dataclass made by
:func:`params_dataclass` (like
:class:`~dynmap_sim.agent.localization.particle_filter.MCLConfig`), validated by pydantic
as the world and scenario files are. The fields are strict, so that the numbers a module
computes do not depend on how a value was spelled: a TOML ``3`` for a float field becomes
``3.0``; an :data:`Int` takes an integral float (``8000.0``); a tuple field marked
:data:`AsTuple` takes a list; anything else of the wrong kind (a string for a number, 1.5
for an integer) is an error. The range types below (:data:`Positive` ...) check the
values, so that a scenario's bad parameter is an error naming it when the scenario is
loaded rather than a crash in the middle of a run. ``pydantic.TypeAdapter(cls)
.json_schema()`` describes a class's fields.
"""

from __future__ import annotations

import functools
import math
import numbers
from collections.abc import Callable, Mapping
from dataclasses import fields
from typing import Annotated, Any, TypeVar, dataclass_transform

import pydantic
from pydantic import AfterValidator, BeforeValidator, ConfigDict, Field, ValidationError
from pydantic.fields import FieldInfo

C = TypeVar("C")


class ParamError(ValueError):
    """A bad parameter value, worded ``"<owner>: <field> must be ..., got ..."``."""


class Says:
    """The rule of a range type in words ("a finite number > 0"), for its error message;
    ``bounded``: the words give its upper bound (else a value above one gets it added)."""

    def __init__(self, text: str, bounded: bool = False) -> None:
        self.text, self.bounded = text, bounded


def _integral(value: Any) -> Any:
    """An integral number (``8000.0``, ``np.int64(3)``) as an ``int``; anything else as it
    is, for the strict ``int`` check to reject (a bool too)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return value
    if isinstance(value, numbers.Integral):
        return int(value)
    return int(value) if math.isfinite(value) and value == int(value) else value


def _not_nan(value: float) -> float:
    if math.isnan(value):
        raise ValueError("NaN")
    return value


#: An integer field; an integral float (TOML ``1e3``, ``8000.0``) becomes an ``int``.
Int = Annotated[int, BeforeValidator(_integral)]
#: A tuple field; a list (TOML's arrays) becomes a tuple.
AsTuple = BeforeValidator(lambda v: tuple(v) if isinstance(v, list) else v)
#: Finite and > 0.
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False), Says("a finite number > 0")]
#: Finite and >= 0.
NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False), Says("a finite number >= 0")]
#: In [0, 1].
Fraction = Annotated[float, Field(ge=0, le=1), Says("a number in [0, 1]", bounded=True)]
#: Any finite number.
Finite = Annotated[float, Field(allow_inf_nan=False), Says("a finite number")]
#: Any number but NaN (infinities allowed, e.g. "no floor").
NotNaN = Annotated[float, AfterValidator(_not_nan), Says("a number (not NaN)")]
#: An integer >= 1.
PositiveInt = Annotated[int, Field(ge=1), BeforeValidator(_integral), Says("an integer >= 1")]
#: An integer >= 0.
NonNegativeInt = Annotated[int, Field(ge=0), BeforeValidator(_integral), Says("an integer >= 0")]


def int_range(low: int, high: int) -> Any:
    """An integer in ``[low, high]``, as an annotation (``n: int_range(1, 20) = 3``): the
    bounds come before the conversion of :data:`Int`, so that the JSON schema shows them."""
    return Annotated[
        int, Field(ge=low, le=high), BeforeValidator(_integral), Says(f"an integer >= {low}")
    ]


#: Wrong kinds of value by pydantic's error type: a :class:`TypeError` "must be ...".
_KINDS = {
    "float_type": "a number",
    "int_type": "an integer",
    "bool_type": "true or false",
    "string_type": "a string",
    "tuple_type": "a list",
}


def _rule(info: FieldInfo, error: Any) -> str | None:
    """A range type's rule in words (None: the field has none), with the upper bound that
    ``error`` (pydantic's) found exceeded."""
    says = next((m for m in reversed(info.metadata) if isinstance(m, Says)), None)
    if says is None or says.bounded or error["type"] != "less_than_equal":
        return None if says is None else says.text
    return f"{says.text} and <= {error['ctx']['le']:,}"


def _shown(info: FieldInfo, value: Any) -> str:
    """``value`` as the field holds it (an ``int`` 0 of a float field is ``0.0``)."""
    if isinstance(value, numbers.Real) and not isinstance(value, bool):
        if info.annotation is float:
            value = float(value)
        elif info.annotation is int and math.isfinite(value):
            value = int(value)
    return repr(value)


def _one_line(cls: type, owner: str, error: ValidationError) -> Exception:
    """The first problem of ``error`` as a one-line :class:`TypeError` (an unknown key, a
    value of the wrong kind) or :class:`ValueError` (out of range) naming ``owner`` and the
    field; an error that a validator already worded is passed on as it is."""
    errors = error.errors(include_url=False)
    unknown = sorted(str(e["loc"][0]) for e in errors if e["type"] == "unexpected_keyword_argument")
    if unknown:
        known = ", ".join(sorted(f.name for f in fields(cls)))
        return TypeError(f"{owner}: unknown parameters {unknown}; known: {known}")
    e = errors[0]
    raised = e.get("ctx", {}).get("error")
    if isinstance(raised, ParamError):
        return raised  # a part's own (a nested config built by a validator)
    if isinstance(raised, Exception) and not e["loc"]:  # a cross-field rule (__post_init__)
        text = str(raised)
        return ParamError(text if text.startswith(f"{owner}: ") else f"{owner}: {text}")
    name = str(e["loc"][0]) if e["loc"] else ""
    if e["type"] in _KINDS:
        return TypeError(f"{owner}: {name} must be {_KINDS[e['type']]}, got {e['input']!r}")
    info = cls.__pydantic_fields__.get(name)  # type: ignore[attr-defined]
    rule = None if info is None else _rule(info, e)
    if rule is None:  # pydantic's own words (a tuple of the wrong length ...)
        return ParamError(f"{owner}: {name}: {e['msg']}, got {e['input']!r}")
    return ParamError(f"{owner}: {name} must be {rule}, got {_shown(info, e['input'])}")


@dataclass_transform(frozen_default=True)
def params_dataclass(owner: str | None = None) -> Callable[[type[C]], type[C]]:
    """Make a class a frozen pydantic dataclass whose fields are strict and whose unknown
    keyword is an error; its errors are one line naming ``owner`` (default: the class name)
    and the field (:func:`_one_line`). ``dataclasses.replace`` validates again."""

    def make(cls: type[C]) -> type[C]:
        config = ConfigDict(extra="forbid", strict=True)
        dc: Any = pydantic.dataclasses.dataclass(frozen=True, config=config)(cls)
        init = dc.__init__

        @functools.wraps(init)
        def __init__(self: Any, *args: Any, **kwargs: Any) -> None:
            try:
                init(self, *args, **kwargs)
            except ValidationError as error:
                raise _one_line(dc, owner or cls.__name__, error) from None

        dc.__init__, dc._params_init = __init__, init
        return dc  # type: ignore[no-any-return]

    return make


def build(cls: type[C], params: Mapping[str, Any], owner: str) -> C:
    """``cls(**params)`` for a :func:`params_dataclass` ``cls``, its errors naming ``owner``
    (e.g. the scenario table it came from) instead of the class's own."""
    config = cls.__new__(cls)
    try:
        cls._params_init(config, **params)  # type: ignore[attr-defined]
    except ValidationError as error:
        raise _one_line(cls, owner, error) from None
    return config
