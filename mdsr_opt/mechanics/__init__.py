"""Mechanics: energy models, solvers, equilibria of external and internal driving, rope constraints,
stability checks."""

from __future__ import annotations

from ..core.lazy import lazy_exports

# public name -> module of this folder that owns it (imported lazily)
_EXPORTS = {
    'EquilibriumResult': 'result',
    'SolverFailure': 'result',
    'external_stability': 'equilibrium',
    'solve_external': 'equilibrium',
    'solve_internal': 'equilibrium',
}

__all__ = sorted(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
