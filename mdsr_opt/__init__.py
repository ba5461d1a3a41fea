"""mdsr_opt: kinematic modelling and computational design of muscle-driven soft robots.

Data flows one way: mesh -> scene -> equilibrium -> target -> contraction graph -> muscles -> design ->
evaluation. Public names are imported lazily from the module that owns them (see ``_EXPORTS``), so
``import mdsr_opt`` stays cheap and does not touch matplotlib. The command line is :mod:`mdsr_opt.cli`.
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

# public name -> owning module (lazy, so importing the package stays cheap)
_EXPORTS = {
    "Mesh": "mesh",
    "check_polygon": "mesh",
    "Muscle": "muscles",
    "NeoHookean": "material",
    "LinearElastic": "material",
    "EnergyModel": "model",
    "get_model": "model",
    "EquilibriumResult": "equilibrium",
    "SolverFailure": "equilibrium",
    "solve_external": "equilibrium",
    "solve_internal": "equilibrium",
    "available_backends": "equilibrium",
    "RigidDrag": "drags",
    "external_stability": "equilibrium",
    "check_stability": "stability",
    "StabilityCheck": "stability",
    "read_mesh": "io",
    "write_mesh": "io",
    # routing (issue 3)
    "contraction_graph": "routing",
    "route_muscles": "routing",
    # design (issue 4)
    "align": "align",
    "difference": "align",
    "node_weights": "align",
    "design_contractions": "design",
    "design_pipeline": "design",
    "verify_design": "design",
    "check_minimum": "design",
    "DesignResult": "design",
    "PipelineResult": "design",
    "Verification": "design",
    # evaluation against photographs (issue 5)
    "contour_from_image": "evaluate",
    "compare_contours": "evaluate",
    "RoutingResult": "routing",
    "edge_weights": "routing",
    "render_photo": "evaluate",
    "simulated_outline": "evaluate",
    "evaluate_folder": "evaluate",
    "ContourComparison": "evaluate",
    # problem library and scenes (issue 6)
    "Scene": "scenes",
    "Case": "scenes",
    "Animation": "scenes",
    "list_problems": "scenes",
    "get_problem": "scenes",
    "load_scene": "scenes",
    "prepare_case": "scenes",
    "run_scene": "scenes",
    "run_case": "scenes",
    # the helpers a problem script needs: meshes at a node count, node selection, target maps
    "mesh_polygon": "scenes",
    "resolve_resolution": "scenes",
    "seeds_for": "scenes",
    "nodes_in_box": "scenes",
    "nodes_near": "scenes",
    "nearest_node": "scenes",
    "nodes_in_polygon": "scenes",
    "edge_path": "scenes",
    "boundary_path": "scenes",
    "rigid_motion": "scenes",
    "arc_map": "scenes",
    "arc_rigid": "scenes",
    # solver comparison studies (issue 7)
    "Study": "study",
    "StudyResult": "study",
    "run_study": "study",
    "list_studies": "study",
    "choose_fidelity": "fidelity",
    "FidelityChoice": "fidelity",
    # several poses on one layout, gait schedules, fabrication files (issue 16)
    "Pose": "poses",
    "PosesResult": "poses",
    "design_poses": "poses",
    "Gait": "gait",
    "GaitSchedule": "gait",
    "gait_schedule": "gait",
    "export_fabrication": "export",
}

__all__ = sorted(_EXPORTS) + ["__version__"]


def __getattr__(name: str):
    mod = _EXPORTS.get(name)
    if mod is None:
        raise AttributeError(f"module 'mdsr_opt' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{mod}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return __all__
