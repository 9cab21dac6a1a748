"""Packages whose public names load their submodule on first use (PEP 562).

Importing ``trialformat``, ``estimation``, ``diagnosis`` or ``orchestrator`` then loads no
numpy, scipy, matplotlib or FMU code, so the CLI's --help and option errors print at once;
the heavy modules load where a name is first used.
"""

from __future__ import annotations

from importlib import import_module


def first_use(package: str, namespace: dict, exports: dict, submodules=()):
    """``(__getattr__, __dir__)`` for the module ``package`` with globals ``namespace``.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    namespace : dict
        Its ``globals()``: a loaded name is stored there, so it loads once.
    exports : dict
        Public name -> relative submodule that defines it (``{"Trial": ".logs"}``).
    submodules : iterable of str
        Submodules reachable as attributes (``trialformat.logs``).
    """
    submodules = tuple(submodules)

    def __getattr__(name):
        if name in exports:
            value = getattr(import_module(exports[name], package), name)
        elif name in submodules:
            value = import_module("." + name, package)
        else:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        namespace[name] = value
        return value

    def __dir__():
        return sorted(set(namespace) | set(exports) | set(submodules))

    return __getattr__, __dir__
