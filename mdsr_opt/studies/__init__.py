"""Solver comparison studies: problems, runs, the study runner, fidelity choice and routing quality."""
