"""Scenes: the problem library's data model, node selection, the registry, scene files and the runner."""

from __future__ import annotations

from ..core.lazy import lazy_exports

# public name -> module of this folder that owns it (imported lazily)
_EXPORTS = {
    'Animation': 'scene',
    'AnimationResult': 'animate',
    'Case': 'scene',
    'CaseReport': 'runner',
    'CaseRun': 'runner',
    'CaseSetup': 'cases',
    'RESERVED_NAMES': 'names',
    'RESOLUTIONS': 'scene',
    'RUN_FILES': 'names',
    'SHAPES_ARE_OURS': 'scene',
    'Scene': 'scene',
    'SceneFileError': 'reader',
    'SceneReport': 'runner',
    'UnknownName': 'scene',
    'animate': 'animate',
    'arc_map': 'shapes',
    'arc_rigid': 'shapes',
    'boundary_path': 'select',
    'check_output_names': 'names',
    'check_scene_options': 'reader',
    'check_units_and_gait': 'scene',
    'edge_path': 'select',
    'figure_scripts': 'library',
    'get_problem': 'library',
    'list_problems': 'library',
    'load_problem_module': 'library',
    'load_scene': 'scenefile',
    'mesh_polygon': 'scene',
    'nearest_node': 'select',
    'nodes_in_box': 'select',
    'nodes_in_polygon': 'select',
    'nodes_near': 'select',
    'parse_units_and_gait': 'scenefile',
    'prepare_case': 'cases',
    'problems_dir': 'library',
    'resolve_resolution': 'scene',
    'rigid_motion': 'shapes',
    'run_case': 'runner',
    'run_entries': 'runscene',
    'run_main': 'runscene',
    'run_scene': 'runscene',
    'seeds_for': 'scene',
    'write_case': 'runner',
    'case_parts': 'runner',
    'measure_case': 'runner',
    'case_files': 'runner',
    'write_scene': 'runscene',
}

__all__ = sorted(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
