"""From target to robot: routing, the design of strokes (flattened NLP and rivals), verification,
the pipeline, several poses on one layout, gait schedules and fabrication files."""

from __future__ import annotations

import importlib

# public name -> module of this folder that owns it (imported lazily)
_EXPORTS = {
    'DesignResult': 'results',
    'METHODS': 'results',
    'PipelineResult': 'pipeline',
    'Verification': 'results',
    'check_minimum': 'verify',
    'design': 'pipeline',
    'design_contractions': 'contractions',
    'design_pipeline': 'pipeline',
    'verify_design': 'verify',
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
