"""From target to robot: routing, the design of strokes (flattened NLP and rivals), verification,
the pipeline, several poses on one layout, gait schedules and fabrication files."""

from __future__ import annotations

from ..core.lazy import lazy_exports

# public name -> module of this folder that owns it (imported lazily)
_EXPORTS = {
    'DesignResult': 'results',
    'METHODS': 'results',
    'PipelineResult': 'pipeline',
    'Verification': 'results',
    'check_minimum': 'verify',
    'design_contractions': 'contractions',
    'design_pipeline': 'pipeline',
    'verify_design': 'verify',
}

__all__ = sorted(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
