"""Figures by stage (matplotlib). Every ``plot_*`` function takes ``ax=`` and returns the figure; importing
this package leaves the matplotlib backend alone and imports no study or scene code."""

from __future__ import annotations

from ..core.lazy import lazy_exports

# public name -> module of this folder that owns it (imported lazily)
_EXPORTS = {
    'close_figure': 'common',
    'plot_contraction_graph': 'design',
    'plot_design': 'design',
    'plot_design_benchmark': 'design',
    'plot_edges': 'common',
    'plot_fidelity': 'studies',
    'plot_mesh': 'common',
    'plot_muscles': 'common',
    'plot_overlay': 'photos',
    'plot_routing': 'design',
    'plot_routing_timings': 'design',
    'plot_scene': 'scenes',
    'plot_study_pareto': 'studies',
    'plot_study_scaling': 'studies',
    'plot_study_success': 'studies',
    'plot_target': 'scenes',
    'save_animation': 'scenes',
    'save_figure': 'common',
}

__all__ = sorted(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
