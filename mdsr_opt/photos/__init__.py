"""Photographs: extracting contours (with holes), contour metrics, the synthetic camera, folder tables."""

from __future__ import annotations

from ..core.lazy import lazy_exports

# public name -> module of this folder that owns it (imported lazily)
_EXPORTS = {
    'CaseResult': 'folder',
    'ContourComparison': 'compare',
    'IMAGE_SUFFIXES': 'images',
    'LoopComparison': 'loops',
    'MAX_KERNEL': 'contours',
    'MAX_PIXELS': 'images',
    'STATE_SUFFIXES': 'folder',
    'SyntheticPhoto': 'camera',
    'body_mask': 'contours',
    'compare_contours': 'compare',
    'compare_loops': 'loops',
    'contour_from_image': 'contours',
    'contour_loops_from_image': 'contours',
    'evaluate_folder': 'folder',
    'evaluate_image': 'compare',
    'load_image': 'images',
    'render_photo': 'camera',
    'simulated_loops': 'loops',
    'simulated_outline': 'compare',
    'write_table': 'folder',
}

__all__ = sorted(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
