"""mdsr_opt: kinematic modelling and computational design of muscle-driven soft robots.

Data flows one way: mesh -> scene -> equilibrium -> target -> contraction graph -> muscles -> design ->
evaluation. Public names are imported lazily from the module that owns them (see ``_EXPORTS`` and :func:`mdsr_opt.core.lazy.lazy_exports`), so
``import mdsr_opt`` stays cheap and does not touch matplotlib. The command line is :mod:`mdsr_opt.cli`.
"""

from __future__ import annotations

from .core.lazy import lazy_exports

__version__ = "0.1.0"

# public name -> owning module (lazy, so importing the package stays cheap)
_EXPORTS = {
    "Mesh": "body.mesh",
    "check_polygon": "body.mesh",
    "Muscle": "body.muscles",
    "NeoHookean": "body.material",
    "LinearElastic": "body.material",
    "EnergyModel": "mechanics.model",
    "get_model": "mechanics.model",
    "EquilibriumResult": "mechanics.result",
    "SolverFailure": "mechanics.result",
    "solve_external": "mechanics.equilibrium",
    "solve_internal": "mechanics.equilibrium",
    "available_backends": "mechanics.backends",
    "RigidDrag": "mechanics.drags",
    "external_stability": "mechanics.equilibrium",
    "check_stability": "mechanics.stability",
    "StabilityCheck": "mechanics.stability",
    "read_mesh": "body.io",
    "write_mesh": "body.io",
    # routing (issue 3)
    "contraction_graph": "synthesis.routing",
    "route_muscles": "synthesis.routing",
    # design (issue 4)
    "align": "mechanics.align",
    "difference": "mechanics.align",
    "node_weights": "mechanics.align",
    "design_contractions": "synthesis.contractions",
    "design_pipeline": "synthesis.pipeline",
    "verify_design": "synthesis.verify",
    "check_minimum": "synthesis.verify",
    "DesignResult": "synthesis.results",
    "PipelineResult": "synthesis.pipeline",
    "Verification": "synthesis.results",
    # evaluation against photographs (issue 5)
    "contour_from_image": "photos.contours",
    "compare_contours": "photos.compare",
    "RoutingResult": "synthesis.routing",
    "edge_weights": "synthesis.routing",
    "render_photo": "photos.camera",
    "simulated_outline": "photos.compare",
    "evaluate_folder": "photos.folder",
    "ContourComparison": "photos.compare",
    # problem library and scenes (issue 6)
    "Scene": "scenes.scene",
    "Case": "scenes.scene",
    "Animation": "scenes.scene",
    "list_problems": "scenes.library",
    "get_problem": "scenes.library",
    "load_scene": "scenes.scenefile",
    "prepare_case": "scenes.cases",
    "run_scene": "scenes.runscene",
    "run_case": "scenes.runner",
    # the helpers a problem script needs: meshes at a node count, node selection, target maps
    "mesh_polygon": "scenes.scene",
    "resolve_resolution": "scenes.scene",
    "seeds_for": "scenes.scene",
    "nodes_in_box": "scenes.select",
    "nodes_near": "scenes.select",
    "nearest_node": "scenes.select",
    "nodes_in_polygon": "scenes.select",
    "edge_path": "scenes.select",
    "boundary_path": "scenes.select",
    "rigid_motion": "scenes.shapes",
    "arc_map": "scenes.shapes",
    "arc_rigid": "scenes.shapes",
    # solver comparison studies (issue 7)
    "Study": "studies.spec",
    "StudyResult": "studies.study",
    "run_study": "studies.study",
    "list_studies": "studies.spec",
    "choose_fidelity": "studies.fidelity",
    "FidelityChoice": "studies.fidelity",
    # several poses on one layout, gait schedules, fabrication files (issue 16)
    "Pose": "synthesis.poses",
    "PosesResult": "synthesis.poses",
    "design_poses": "synthesis.poses",
    "Gait": "synthesis.gait",
    "GaitSchedule": "synthesis.gait",
    "gait_schedule": "synthesis.gait",
    "export_fabrication": "synthesis.export",
}

__all__ = sorted(_EXPORTS) + ["__version__"]


__getattr__, _ = lazy_exports(__name__, _EXPORTS, globals())


def __dir__():
    return __all__
