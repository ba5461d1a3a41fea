"""Mechanics: energy models, solvers, equilibria of external and internal driving, rope constraints,
stability checks."""
