"""The base of the metrics' results: frozen dataclasses that save to JSON and load back equal
(like evo's ``Result``).

A result's fields are numbers, strings or tuples of them. NaN marks an undefined value (no
scans, nothing reported) and compares equal to NaN, so that a result read back from its JSON
equals the one written. JSON has no NaN or infinity: they are written as ``null`` and
``"inf"``/``"-inf"``.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, fields
from typing import Any, TypeVar

R = TypeVar("R", bound="Result")


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    if isinstance(a, tuple | list) and isinstance(b, tuple | list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(v, b[k]) for k, v in a.items())
    return bool(a == b)


def _to_json_value(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None if math.isnan(v) else ("inf" if v > 0 else "-inf")
    if isinstance(v, tuple | list):
        return [_to_json_value(x) for x in v]
    if isinstance(v, dict):
        return {k: _to_json_value(x) for k, x in v.items()}
    return v


class Result:
    """Mixin of a flat frozen dataclass result (declare it ``@dataclass(frozen=True,
    eq=False)`` so that this NaN-aware ``==`` is kept): ``to_dict``/``from_dict``,
    ``to_json``/``from_json``."""

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)  # type: ignore[call-overload]

    @classmethod
    def from_dict(cls: type[R], d: dict[str, Any]) -> R:
        """The result of :meth:`to_dict` (or of parsed :meth:`to_json`)."""
        types = {f.name: str(f.type) for f in fields(cls)}  # type: ignore[arg-type]
        unknown = set(d) - set(types)
        if unknown:
            raise ValueError(f"{cls.__name__}: unknown fields {sorted(unknown)}")
        out: dict[str, Any] = {}
        for k, v in d.items():
            kind = types[k]
            if kind == "float":
                v = math.nan if v is None else float(v)
            elif kind == "int":
                v = int(v)
            elif kind.startswith("tuple"):
                elem = kind[kind.index("[") + 1 :].split(",")[0].strip()
                conv = {"float": lambda x: math.nan if x is None else float(x), "int": int}
                v = tuple(conv.get(elem, lambda x: x)(x) for x in v)
            out[k] = v
        return cls(**out)

    def to_json(self) -> str:
        return json.dumps(_to_json_value(self.to_dict()))

    @classmethod
    def from_json(cls: type[R], text: str) -> R:
        return cls.from_dict(json.loads(text))

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return _same(self.to_dict(), other.to_dict())  # type: ignore[attr-defined]

    def __hash__(self) -> int:
        return hash(self.to_json())
