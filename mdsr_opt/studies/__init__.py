"""Solver comparison studies: problems, runs, the study runner, fidelity choice and routing quality."""

from __future__ import annotations

from ..core.lazy import lazy_exports

# public name -> module of this folder that owns it (imported lazily)
_EXPORTS = {
    'COLUMNS': 'spec',
    'DESIGN_METHODS': 'spec',
    'FAILURES': 'spec',
    'FIDELITY_STUDY': 'spec',
    'GUESSES': 'spec',
    'MATERIALS': 'problems',
    'PROBLEMS': 'problems',
    'RunOutcome': 'runs',
    'RunSpec': 'spec',
    'RunTimeout': 'runs',
    'STRIP': 'problems',
    'STUDIES': 'spec',
    'Setup': 'problems',
    'Study': 'spec',
    'StudyProblem': 'problems',
    'StudyResult': 'study',
    'TIMING_COLUMNS': 'spec',
    'boundary_overlaps': 'runs',
    'build_setup': 'problems',
    'execute_run': 'runs',
    'get_study_problem': 'problems',
    'get_study': 'spec',
    'interpolate': 'runs',
    'list_studies': 'spec',
    'list_study_problems': 'problems',
    'run_study': 'study',
    'state_error': 'runs',
}

__all__ = sorted(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
