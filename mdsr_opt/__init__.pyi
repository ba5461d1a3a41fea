"""The public names of :mod:`mdsr_opt`, for type checkers; at run time ``__init__.py`` reads this file
and imports each name from its module on first use (``lazy_loader.attach_stub``)."""

# the body: meshes, materials, muscles, mesh files
from .body.io import read_mesh as read_mesh, write_mesh as write_mesh
from .body.material import (
    LinearElastic as LinearElastic,
    MooneyRivlin as MooneyRivlin,
    NeoHookean as NeoHookean,
    Yeoh as Yeoh,
)
from .body.silicone import silicone as silicone
from .body.mesh import Mesh as Mesh
from .body.polygons import check_polygon as check_polygon
from .body.muscles import Muscle as Muscle

# mechanics: equilibria of external and internal driving, stability, alignment
from .mechanics.align import align as align, difference as difference, node_weights as node_weights
from .mechanics.anchors import body_size as body_size
from .mechanics.backends import available_backends as available_backends
from .mechanics.drags import RigidDrag as RigidDrag
from .mechanics.equilibrium import (
    external_stability as external_stability,
    solve_external as solve_external,
    solve_internal as solve_internal,
)
from .mechanics.grip import free_disk as free_disk, grip_report as grip_report
from .mechanics.model import EnergyModel as EnergyModel, get_model as get_model
from .mechanics.obstacles import Disk as Disk, HalfPlane as HalfPlane, Obstacle as Obstacle
from .mechanics.result import EquilibriumResult as EquilibriumResult, SolverFailure as SolverFailure
from .mechanics.stability import check_stability as check_stability, StabilityCheck as StabilityCheck

# from target to robot: routing, design, verification, poses, gaits, fabrication files
from .synthesis.acceptance import AcceptanceWarning as AcceptanceWarning
from .synthesis.contractions import design_contractions as design_contractions
from .synthesis.export import export_fabrication as export_fabrication
from .synthesis.fabrication import Fabrication as Fabrication, FabricationWarning as FabricationWarning
from .synthesis.gait import Gait as Gait, gait_schedule as gait_schedule, GaitSchedule as GaitSchedule, GaitWarning as GaitWarning
from .synthesis.walk import walk as walk, walk_scene as walk_scene, WalkResult as WalkResult
from .synthesis.pipeline import design_pipeline as design_pipeline, PipelineResult as PipelineResult
from .synthesis.poses import design_poses as design_poses, Pose as Pose
from .synthesis.poses_result import PosesResult as PosesResult
from .synthesis.results import DesignResult as DesignResult, MuscleWarning as MuscleWarning, Verification as Verification
from .synthesis.routing import (
    contraction_graph as contraction_graph,
    edge_weights as edge_weights,
    route_for_design as route_for_design,
    route_muscles as route_muscles,
    RoutingWarning as RoutingWarning,
)
from .synthesis.routing_result import RoutingResult as RoutingResult
from .synthesis.verify import check_minimum as check_minimum, verify_design as verify_design

# photographs: contours, the synthetic camera, comparisons
from .photos.camera import render_photo as render_photo
from .photos.compare import (
    compare_contours as compare_contours,
    ContourComparison as ContourComparison,
    simulated_outline as simulated_outline,
)
from .photos.contours import (
    contour_from_image as contour_from_image,
    contour_loops_from_image as contour_loops_from_image,
)
from .photos.loops import (
    compare_loops as compare_loops,
    LoopComparison as LoopComparison,
    simulated_loops as simulated_loops,
)
from .photos.folder import evaluate_folder as evaluate_folder

# scenes and the problem library: the data model, node selection, target maps, the runner
from .scenes.cases import prepare_case as prepare_case
from .scenes.library import get_problem as get_problem, list_problems as list_problems
from .scenes.runner import run_case as run_case
from .scenes.runscene import run_scene as run_scene
from .scenes.scene import (
    Animation as Animation,
    Case as Case,
    mesh_polygon as mesh_polygon,
    resolve_resolution as resolve_resolution,
    Scene as Scene,
    seeds_for as seeds_for,
)
from .scenes.scenefile import load_scene as load_scene
from .scenes.select import (
    boundary_path as boundary_path,
    edge_path as edge_path,
    nearest_node as nearest_node,
    nodes_in_box as nodes_in_box,
    nodes_in_polygon as nodes_in_polygon,
    nodes_near as nodes_near,
)
from .scenes.shapes import arc_map as arc_map, arc_rigid as arc_rigid, rigid_motion as rigid_motion

# solver comparison studies
from .studies.fidelity import choose_fidelity as choose_fidelity, FidelityChoice as FidelityChoice
from .studies.spec import list_studies as list_studies, Study as Study
from .studies.study import run_study as run_study, StudyResult as StudyResult

__version__: str
