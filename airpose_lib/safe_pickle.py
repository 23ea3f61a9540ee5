"""Reading pickles that come from outside the kit without running their code.

A pickle is a program: unpickling may call any function that is importable (``os.system`` among
them). The release's files (detector output, per-sample labels, marker poses) and a third
party's recordings are pickles, so every one the kit reads goes through :func:`load`, whose
unpickler resolves only the types those files hold and refuses every other global before it is
called:

* containers and scalars: ``dict``, ``list``, ``tuple``, ``set``, ``frozenset``, ``int``,
  ``float``, ``complex``, ``bool``, ``str``, ``bytes``, ``bytearray``, ``OrderedDict`` (and
  ``_codecs.encode``, which protocols 0-2 use to write bytes);
* numpy arrays, dtypes and scalars (``numpy.core.multiarray._reconstruct`` / ``scalar``,
  ``numpy.core.numeric._frombuffer``, ``numpy.ndarray``, ``numpy.dtype``, in numpy 1's and
  numpy 2's spellings).

``dict``, ``list`` and the numbers need no global at all in a pickle; the rest are plain data
constructors. Object arrays unpickle their items through the same unpickler.

Checkpoints are different: they hold torch tensors and, in the authors' Lightning files, objects
of classes the kit does not have. :func:`torch_pickle_module` gives ``torch.load`` an unpickler
that builds tensors and plain containers and turns every other global into an inert
placeholder (a ``dict`` subclass that records its arguments), so no foreign code runs either.

Imports nothing of the kit; numpy and torch are imported when a file needs them.
"""
from __future__ import annotations

import builtins
import collections
import io
import os
import pickle
import types
from pathlib import Path
from typing import Any

__all__ = ["ForbiddenGlobalError", "load", "loads", "torch_pickle_module"]

_DATA_BUILTINS = frozenset({"dict", "list", "tuple", "set", "frozenset", "int", "float", "complex",
                            "bool", "str", "bytes", "bytearray"})
# numpy's names of the array / scalar rebuilders under numpy 1 (``numpy.core``) and 2 (``numpy._core``).
_NUMPY_MULTIARRAY = ("numpy.core.multiarray", "numpy._core.multiarray")
_NUMPY_GLOBALS = frozenset({"_reconstruct", "scalar"})
_NUMPY_NUMERIC = ("numpy.core.numeric", "numpy._core.numeric")


class ForbiddenGlobalError(pickle.UnpicklingError):
    """The pickle names a global outside the admitted types (it may be trying to run code)."""


def _numpy_global(module: str, name: str) -> Any | None:
    """The numpy function or class ``module.name`` if it is one of the admitted ones, else None."""
    if module in _NUMPY_MULTIARRAY and name in _NUMPY_GLOBALS:
        import numpy as np

        core = getattr(np, "_core", None) or np.core
        return getattr(core.multiarray, name)
    if module == "numpy" and name in ("ndarray", "dtype"):
        import numpy as np

        return getattr(np, name)
    if module in _NUMPY_NUMERIC and name == "_frombuffer":  # protocol-5 arrays
        import numpy as np

        core = getattr(np, "_core", None) or np.core
        return core.numeric._frombuffer
    return None


class _DataUnpickler(pickle.Unpickler):
    """Resolves only containers, scalars and numpy arrays / dtypes (module docstring)."""

    def find_class(self, module: str, name: str):
        if module in ("builtins", "__builtin__") and name in _DATA_BUILTINS:
            return getattr(builtins, name)
        if module == "collections" and name == "OrderedDict":
            return collections.OrderedDict
        if module == "_codecs" and name == "encode":  # how protocols 0-2 write bytes
            import _codecs

            return _codecs.encode
        found = _numpy_global(module, name)
        if found is not None:
            return found
        raise ForbiddenGlobalError(f"it names {module}.{name}, which a data file never holds (only dicts, "
                                   "lists, tuples, numbers, strings and numpy arrays are read)")


def loads(data: bytes, *, encoding: str = "latin1") -> Any:
    """Unpickle ``data`` admitting only plain data (module docstring).

    Args:
        data: the pickle's bytes.
        encoding: for Python-2 ``str`` objects (the release's files are Python-2 era: latin1).
    Raises:
        ForbiddenGlobalError: the pickle names another global; nothing of it was called.
        pickle.UnpicklingError, EOFError, ValueError ...: a truncated or garbled pickle.
    """
    return _DataUnpickler(io.BytesIO(data), encoding=encoding).load()


def load(path: str | os.PathLike, *, encoding: str = "latin1") -> Any:
    """:func:`loads` of the file ``path`` (opened read-only)."""
    with open(Path(path), "rb") as fh:
        return _DataUnpickler(fh, encoding=encoding).load()


# -- checkpoints ------------------------------------------------------------------------------------
class _Placeholder(dict):
    """Stands in for an object of a class that is not imported (e.g. Lightning's AttributeDict)."""

    _source = "?"

    def __init__(self, *args, **kwargs):
        super().__init__()
        if args:
            self["__args__"] = args
        self.update(kwargs)

    def __setstate__(self, state):
        self["__state__"] = state

    def __repr__(self) -> str:
        return f"<placeholder for {self._source}: {dict.__repr__(self)}>"


_PLACEHOLDERS: dict[tuple[str, str], type] = {}
_CHECKPOINT_BUILTINS = _DATA_BUILTINS | {"slice", "object"}


class _CheckpointUnpickler(pickle.Unpickler):
    """Resolves torch's tensor/storage rebuilders, dtypes and plain containers; every other global
    becomes a :class:`_Placeholder` subclass, so unpickling runs no foreign code."""

    def find_class(self, module: str, name: str):
        import torch

        if module == "torch._utils" and name.startswith("_rebuild_"):
            return getattr(torch._utils, name)
        if module == "torch" and (name.endswith("Storage") or name in ("Size", "device")
                                  or isinstance(getattr(torch, name, None), torch.dtype)):
            return getattr(torch, name)
        if module == "torch.storage" and name in ("TypedStorage", "UntypedStorage"):
            return getattr(torch.storage, name)
        if module == "collections" and name in ("OrderedDict", "defaultdict"):
            return getattr(collections, name)
        if module in ("builtins", "__builtin__") and name in _CHECKPOINT_BUILTINS:
            return getattr(builtins, name)
        if module in ("copyreg", "copy_reg") and name == "_reconstructor":
            import copyreg

            return copyreg._reconstructor
        found = _numpy_global(module, name)
        if found is not None:
            return found
        key = (module, name)
        if key not in _PLACEHOLDERS:
            _PLACEHOLDERS[key] = type(name, (_Placeholder,), {"_source": f"{module}.{name}"})
        return _PLACEHOLDERS[key]


def torch_pickle_module() -> types.SimpleNamespace:
    """A ``pickle_module`` for ``torch.load(..., weights_only=False)`` that runs no foreign code:
    tensors and containers are built, every other object becomes an inert placeholder."""
    return types.SimpleNamespace(Unpickler=_CheckpointUnpickler,
                                 load=lambda f, **kw: _CheckpointUnpickler(f, **kw).load(),
                                 __name__="airpose_safe_pickle")
