"""Lazy package namespaces: a package's public names are imported from its modules on first use,
so importing the package stays cheap (no torch, VTK or ZeroMQ until needed)."""
from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping, Sequence

__all__ = ["lazy_namespace"]


def lazy_namespace(package: str, namespace: dict, modules: Sequence[str],
                   exports: Mapping[str, str] | None = None) -> tuple[Callable, Callable]:
    """Module-level ``__getattr__`` and ``__dir__`` for ``package`` (PEP 562).

    Args:
        package: the package's ``__name__``.
        namespace: its ``globals()`` (a resolved name is cached there).
        modules: submodules searched in order for a name in their ``__all__`` (``()``: no
            search, only ``exports``).
        exports: name -> submodule (dotted below ``package``) for names looked up directly,
            before the search.
    """
    exports = dict(exports or {})

    def __getattr__(name: str):
        if name in modules:  # `from pkg import submodule` asks here first: import just that one
            value = importlib.import_module(f"{package}.{name}")
            namespace[name] = value
            return value
        module = exports.get(name)
        if module is None and not name.startswith("_"):
            for candidate in modules:
                mod = importlib.import_module(f"{package}.{candidate}")
                if name in getattr(mod, "__all__", ()):
                    module = candidate
                    break
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f"{package}.{module}"), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(modules) | set(exports))

    return __getattr__, __dir__
