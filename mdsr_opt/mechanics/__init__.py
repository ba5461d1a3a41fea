"""Mechanics: energy models, solvers, equilibria of external and internal driving, rope constraints,
stability checks."""

from __future__ import annotations

import importlib

# public name -> module of this folder that owns it (imported lazily)
_EXPORTS = {
    'EquilibriumResult': 'result',
    'SolverFailure': 'result',
    'external_stability': 'equilibrium',
    'solve_external': 'equilibrium',
    'solve_internal': 'equilibrium',
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    mod = _EXPORTS.get(name)
    if mod is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{mod}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return __all__
