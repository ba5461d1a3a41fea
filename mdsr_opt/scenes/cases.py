"""A case turned into a design problem: the target and the muscles (:func:`prepare_case`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any
import numpy as np

from .scene import Case, Scene

__all__ = ['CaseSetup', 'prepare_case']


# ---------------------------------------------------------------------------------------------- design problem
@dataclass
class CaseSetup:
    """A case turned into a design problem: the target shape and the muscles to design contractions for.

    Attributes
    ----------
    scene, case : the scene and the case.
    target : (n, 2) ndarray
        The target shape (external- or internal-driving equilibrium).
    muscles : tuple of Muscle
        Routed on the target (external cases without scene muscles) or the scene's.
    known_contractions : (m,) ndarray or None
        Internal cases: the contractions that made the target (the design's exact answer).
    target_result : EquilibriumResult
        The solve that made the target.
    routing : RoutingResult or None
        The routing on the target (for internal cases a diagnostic: what routing would have chosen).
    times : dict
        Seconds for ``target`` and ``routing``.
    warnings : list of str
        The routing's warnings (why it found no muscle, for instance).
    """

    scene: Scene
    case: Case
    target: np.ndarray
    muscles: tuple
    known_contractions: np.ndarray | None
    target_result: Any
    routing: Any = None
    times: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)

    @property
    def success(self) -> bool:
        """The target solve succeeded and there is at least one muscle."""
        return bool(self.target_result.success) and len(self.muscles) > 0


def prepare_case(scene: Scene, case: Case | str, *, route_internal: bool = True) -> CaseSetup:
    """Solve a case's target and lay its muscles: the input of any design method.

    External cases: :func:`~mdsr_opt.solve_external` with the case's anchors and drags, then
    :func:`~mdsr_opt.routing.route_muscles` with the scene's ``routing_options`` (unless the scene gives
    muscles). Internal cases: :func:`~mdsr_opt.solve_internal` with the scene's muscles at the case's
    contractions, using the scene's ``design_options`` ``muscle_model`` and ``stiffness`` so the design can
    recover them exactly; routing runs as a diagnostic when ``route_internal``.

    A failed target solve is not raised: ``target_result.success`` is False and ``muscles`` is empty.
    """
    import time
    import warnings

    from ..mechanics.equilibrium import solve_external, solve_internal
    from ..synthesis.routing import RoutingWarning, route_muscles

    if isinstance(case, str):
        case = scene.case(case)
    t0 = time.perf_counter()
    known = None
    if case.kind == "external":
        res = solve_external(scene.mesh, scene.material, case.anchors, case.drags)
    else:
        known = case.contractions.copy()
        res = solve_internal(scene.mesh, scene.material, scene.muscles, known,
                             muscle_model=scene.design_options.get("muscle_model", "cable"),
                             stiffness=scene.design_options.get("stiffness", 10.0),
                             anchor_radius=scene.design_options.get("anchor_radius"))
    t1 = time.perf_counter()
    routing = None
    muscles: tuple = ()
    notes: list[str] = []
    if res.success:
        own = case.kind == "external" and case.muscles is not None
        # a case with its own muscles is routed too, as a diagnostic (what routing would have laid)
        if case.kind == "external" and (scene.muscles is None or own) or case.kind == "internal" and route_internal:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", RoutingWarning)
                routing = route_muscles(scene.mesh, res.x, **scene.routing_options)
            notes = [str(w.message) for w in caught if issubclass(w.category, RoutingWarning)]
        if own:
            muscles = tuple(case.muscles)
        elif case.kind == "external" and scene.muscles is None:
            muscles = tuple(routing.muscles)
        else:
            muscles = tuple(scene.muscles)
    t2 = time.perf_counter()
    return CaseSetup(scene=scene, case=case, target=res.x.copy(), muscles=muscles, known_contractions=known,
                     target_result=res, routing=routing, times={"target": t1 - t0, "routing": t2 - t1},
                     warnings=notes)
