"""One registry for every role chosen by name from a scenario file (Nav2-style plugins).

Localizers, drivers, planners, controllers and paper studies are each looked up in a
:class:`Registry`: a built-in implementation by its registered name (``"static-mcl"``,
``"tour"``), a user's own class by ``"package.module:ClassName"``. Built-in modules are
imported on the first lookup, so importing a role's module stays cheap. Registering a name
twice is an error: a plugin cannot silently replace another.

The module imports nothing of the package, so every layer may use it.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Generic, TypeVar

T = TypeVar("T")
C = TypeVar("C", bound=type)


class DuplicateNameError(ValueError):
    """A second class was registered under a name that is taken."""


class Registry(Generic[T]):
    """Name -> class table of one role.

    ``role`` names the role in messages (``"localizer"``); ``base`` is the class every
    implementation must derive from; ``builtin_modules`` are imported on first lookup (their
    :meth:`register` decorators fill the table).
    """

    def __init__(self, role: str, base: type[T], builtin_modules: tuple[str, ...] = ()) -> None:
        self.role = role
        self.base = base
        self.builtin_modules = tuple(builtin_modules)
        self._classes: dict[str, type[T]] = {}
        self._loaded = False

    def add(self, name: str, cls: type[T]) -> None:
        """Register ``cls`` as ``name``; :class:`DuplicateNameError` when the name is taken
        by another class (registering the same class again, as a module reload does, is
        allowed)."""
        if not name or ":" in name:
            raise ValueError(f"{self.role} name {name!r}: must be non-empty without ':'")
        if not (isinstance(cls, type) and issubclass(cls, self.base)):
            raise TypeError(f"{cls!r} is not a {_qualified(self.base)}")
        old = self._classes.get(name)
        if old is not None and _qualified(old) != _qualified(cls):
            raise DuplicateNameError(
                f"{self.role} name {name!r} is already taken by {_qualified(old)}; "
                f"register {_qualified(cls)} under another name"
            )
        self._classes[name] = cls

    def register(self, name: str) -> Callable[[C], C]:
        """Class decorator: make the class available as ``name`` (sets ``cls.name``)."""

        def deco(cls: C) -> C:
            self.add(name, cls)
            cls.name = name  # type: ignore[attr-defined]
            return cls

        return deco

    def _load_builtins(self) -> None:
        if self._loaded:
            return
        self._loaded = True
        for mod in self.builtin_modules:
            importlib.import_module(mod)

    def names(self) -> list[str]:
        """The registered names, sorted."""
        self._load_builtins()
        return sorted(self._classes)

    def get(self, name: str) -> type[T]:
        """The class registered as ``name``, or loaded from ``"package.module:ClassName"``.

        Raises ValueError naming the known names, or why a ``module:Class`` cannot be used.
        """
        if ":" in name:
            return self._load(name)
        self._load_builtins()
        try:
            return self._classes[name]
        except KeyError:
            raise ValueError(
                f"unknown {self.role} {name!r}; known: {', '.join(self.names())} "
                "(or give 'package.module:ClassName')"
            ) from None

    def _load(self, ref: str) -> type[T]:
        mod_name, _, cls_name = ref.partition(":")
        if not (
            all(part.isidentifier() for part in mod_name.split(".")) and cls_name.isidentifier()
        ):
            raise ValueError(
                f"cannot load {self.role} {ref!r}: give 'package.module:ClassName' (an absolute "
                "dotted module path, one ':' and a class name)"
            )
        try:
            mod = importlib.import_module(mod_name)
        except ImportError as exc:
            raise ValueError(
                f"cannot load {self.role} {ref!r}: {exc}. The module must be importable: "
                "next to the scenario file, installed, or in a folder on PYTHONPATH"
            ) from exc
        except Exception as exc:  # the module's own code failed (a SyntaxError, ...)
            raise ValueError(
                f"cannot load {self.role} {ref!r}: importing {mod_name} failed: "
                f"{type(exc).__name__}: {exc}"
            ) from exc
        cls = getattr(mod, cls_name, None)
        if cls is None:
            raise ValueError(f"cannot load {self.role} {ref!r}: {mod_name} has no {cls_name!r}")
        if not (isinstance(cls, type) and issubclass(cls, self.base)):
            raise ValueError(
                f"{ref!r} is not a {_qualified(self.base)}: a {self.role} must derive from it"
            )
        return cls


def _qualified(cls: type) -> str:
    return f"{cls.__module__}.{cls.__qualname__}"
