"""Public names a package re-exports from its modules, imported when first used (PEP 562): a
package's ``__init__`` that imported them eagerly would make every module of the package depend on
all of them (importing ``cloth_sim.physics.mesh`` would load ``physics.stability``, which needs the
model, which needs ``physics.mesh``), and the layers below the model could not be imported from it.
"""

from __future__ import annotations

import importlib


def exports(package: str, names: dict[str, str]):
    """``(__getattr__, __dir__)`` for ``package``: ``names`` maps each public name to the module
    (relative to the package) that defines it."""

    def __getattr__(name):
        if name in names:
            value = getattr(importlib.import_module(names[name], package), name)
            vars(importlib.import_module(package))[name] = value
            return value
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__():
        return sorted(set(vars(importlib.import_module(package))) | set(names))

    return __getattr__, __dir__
