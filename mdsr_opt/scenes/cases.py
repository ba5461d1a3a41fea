"""A case turned into a design problem: the target and the muscles (:func:`prepare_case`)."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
import time
from typing import Any
import warnings
import numpy as np

from ..body.muscles import Muscle
from ..core.errors import LayoutError
from ..core.results import compact_repr, load_npz, save_npz, to_jsonable
from .fixtures import scene_fixture_radius
from .obstacles import FreeDisk, case_contact, solve_friction
from .reader import contact_options
from .scene import Case, Scene

__all__ = ['CaseSetup', 'prepare_case', 'case_solve_options', 'solve_target', 'case_anchor_radius',
           'given_muscle_conflicts', 'place_free_disk']


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
    fabrication : list of str
        Muscles the scene gives (not routed) that cannot be moulded as laid out: the
        :class:`~mdsr_opt.synthesis.fabrication.FabricationWarning` :func:`prepare_case` emitted (empty: none).
    anchor_radius : float or None
        The radius of the muscles' end fixtures, which their design takes (:func:`case_anchor_radius`); None:
        the default (:func:`~mdsr_opt.mechanics.anchors.default_anchor_radius`).
    routing_error : str or None
        Why the routing could lay no rope on this body and mesh (the message of its
        :class:`~mdsr_opt.core.errors.LayoutError`: a body too thin for the ropes' inset, a mesh too coarse);
        ``routing`` is then None. A case whose muscles are routed has none (``muscles`` is empty: the case
        fails); one whose routing is a diagnostic (its own muscles, an internal case) goes on without it.
    obstacles : list or None
        The case's obstacles as its target placed them (a :class:`~mdsr_opt.scenes.obstacles.FreeDisk` moved
        to where the grip holds it), which its design takes; None: no obstacles.
    free_disk : dict or None
        With a free disk, where it started and ended and :func:`~mdsr_opt.mechanics.grip.free_disk`'s report
        (``converged``, ``iterations``, ``net_force``).
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
    fabrication: list = field(default_factory=list)
    anchor_radius: float | None = None
    routing_error: str | None = None
    obstacles: list | None = None
    free_disk: dict | None = None

    @property
    def success(self) -> bool:
        """The target solve succeeded and there is at least one muscle."""
        return bool(self.target_result.success) and len(self.muscles) > 0

    def __repr__(self) -> str:
        return compact_repr(self, (), extra={
            "scene": self.scene.name, "case": self.case.name, "kind": self.case.kind, "success": self.success,
            "n_muscles": len(self.muscles), "target": self.target, "known_contractions": self.known_contractions})

    def to_dict(self) -> dict:
        """JSON-ready: scene and case names, the target, muscles, known contractions, the target solve, the
        routing (without its graph), times and warnings."""
        return to_jsonable({
            "scene": self.scene.name, "case": self.case.name, "kind": self.case.kind, "success": self.success,
            "n_nodes": self.scene.mesh.n_nodes, "target": self.target, "muscles": list(self.muscles),
            "known_contractions": self.known_contractions, "target_result": self.target_result.to_dict(),
            "routing": None if self.routing is None else self.routing.to_dict(), "times": self.times,
            "warnings": self.warnings, "fabrication": self.fabrication, "anchor_radius": self.anchor_radius,
            "routing_error": self.routing_error})

    def save(self, path: str | os.PathLike) -> str:
        """Write the setup as one ``.npz`` file: the target, the known contractions and the target solve's
        arrays exactly; muscles, times, warnings and the names of scene and case as metadata. The routing
        (its contraction graph) is not written: :meth:`load` gives ``routing=None``. Returns the path.
        An existing file of that name is replaced, without a warning (``mdsr run`` refuses to without
        ``--overwrite``)."""
        tr = self.target_result
        arrays = {"target": np.asarray(self.target)}
        if self.known_contractions is not None:
            arrays["known_contractions"] = np.asarray(self.known_contractions)
        tr_meta = {}
        for name in tr.__dataclass_fields__:
            value = getattr(tr, name)
            if isinstance(value, np.ndarray):
                arrays[f"target_result.{name}"] = value
            else:
                tr_meta[name] = value
        meta = {"scene": self.scene.name, "case": self.case.name, "n_nodes": self.scene.mesh.n_nodes,
                "muscles": [{"nodes": list(m.nodes), "name": m.name} for m in self.muscles],
                "target_result": tr_meta, "times": self.times, "warnings": list(self.warnings),
                "fabrication": list(self.fabrication), "anchor_radius": self.anchor_radius,
                "routing_error": self.routing_error}
        return save_npz(path, "case_setup", arrays, meta)

    @classmethod
    def load(cls, path: str | os.PathLike, scene: Scene) -> "CaseSetup":
        """Read a setup written by :meth:`save` for ``scene`` (the same scene: name and node count are
        checked; the case is looked up by name). ``routing`` is None.

        Raises
        ------
        FileNotFoundError
            No such file.
        ValueError
            The file (named) is damaged, not a ``.npz``, holds another kind of result or another scene's.
        """
        from ..mechanics.result import EquilibriumResult

        if not isinstance(scene, Scene):
            raise TypeError(f"scene must be the Scene the setup was made for, got {type(scene).__name__}")
        arrays, meta = load_npz(path, "case_setup")
        path = os.fspath(path)
        try:
            if meta["scene"] != scene.name or meta["n_nodes"] != scene.mesh.n_nodes:
                raise ValueError(f"it is a setup of scene {meta['scene']!r} ({meta['n_nodes']} nodes), not of "
                                 f"{scene.name!r} ({scene.mesh.n_nodes} nodes)")
            if meta["case"] not in scene.case_names:
                raise ValueError(f"scene {scene.name!r} has no case {meta['case']!r}")
            case = scene.case(meta["case"])
            trk = {k[len("target_result."):]: v for k, v in arrays.items() if k.startswith("target_result.")}
            target_result = EquilibriumResult(**meta["target_result"], **trk)
            return cls(scene=scene, case=case, target=arrays["target"],
                       muscles=tuple(Muscle(tuple(m["nodes"]), name=m["name"]) for m in meta["muscles"]),
                       known_contractions=arrays.get("known_contractions"), target_result=target_result,
                       routing=None, times=dict(meta["times"]), warnings=list(meta["warnings"]),
                       fabrication=list(meta.get("fabrication", [])), anchor_radius=meta.get("anchor_radius"),
                       routing_error=meta.get("routing_error"))
        except KeyError as exc:
            raise ValueError(f"{path} is damaged: field {exc.args[0]!r} is missing") from None
        except (TypeError, ValueError, AttributeError) as exc:
            raise ValueError(f"{path}: cannot load the setup: {exc}") from None


def prepare_case(scene: Scene, case: Case | str, *, route_internal: bool = True) -> CaseSetup:
    """Solve a case's target and lay its muscles: the input of any design method.

    External cases: :func:`~mdsr_opt.solve_external` with the case's anchors and drags, then
    :func:`~mdsr_opt.synthesis.routing.route_muscles` with the scene's ``routing_options`` (unless the scene gives
    muscles). Internal cases: :func:`~mdsr_opt.solve_internal` with the scene's muscles at the case's
    contractions, using the scene's ``design_options`` ``muscle_model`` and ``stiffness`` and its end-fixture
    radius (:func:`~mdsr_opt.scenes.fixtures.scene_fixture_radius`: ``[design] anchor_radius`` or
    ``[fabrication] fixture_radius``) so the design can recover them exactly; routing runs as a diagnostic
    when ``route_internal``. Both solves take the scene's self-contact and the case's obstacles with their
    friction (:func:`~mdsr_opt.scenes.obstacles.case_contact`).

    A failed target solve is not raised: ``target_result.success`` is False and ``muscles`` is empty. Nor is a
    routing this body or mesh cannot hold (a :class:`~mdsr_opt.core.errors.LayoutError`): its message is
    ``routing_error``, and ``muscles`` is empty when they were to be routed.
    """
    from ..synthesis.fabrication import check_fabrication
    from ..synthesis.routing import RoutingWarning, route_for_design

    if isinstance(case, str):
        case = scene.case(case)
    t0 = time.perf_counter()
    known = None if case.kind == "external" else case.contractions.copy()
    res, placed, freed = solve_target(scene, case)
    t1 = time.perf_counter()
    routing = None
    muscles: tuple = ()
    notes: list[str] = []
    refused = None
    if res.success:
        own = case.kind == "external" and case.muscles is not None
        # a case with its own muscles is routed too, as a diagnostic (what routing would have laid)
        if case.kind == "external" and (scene.muscles is None or own) or case.kind == "internal" and route_internal:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", RoutingWarning)
                ropts = dict(scene.routing_options)  # the fixtures are the design's anchor patches
                ropts["fabrication"] = check_fabrication(ropts.get("fabrication"), scene_fixture_radius(scene))
                try:
                    routing = route_for_design(scene.mesh, res.x, **ropts)
                except LayoutError as exc:  # this body or mesh holds no rope: the case's failure, not the run's
                    refused = str(exc)
            notes = [str(w.message) for w in caught if issubclass(w.category, RoutingWarning)]
        if own:
            muscles = tuple(case.muscles)
        elif case.kind == "external" and scene.muscles is None:
            muscles = () if routing is None else tuple(routing.muscles)
        else:
            muscles = tuple(scene.case_muscles(case))
    given = [] if not muscles or routing is not None and muscles == tuple(routing.muscles) else \
        given_muscle_conflicts(scene, case, muscles)
    t2 = time.perf_counter()
    return CaseSetup(scene=scene, case=case, target=res.x.copy(), muscles=muscles, known_contractions=known,
                     target_result=res, routing=routing, times={"target": t1 - t0, "routing": t2 - t1},
                     warnings=notes, fabrication=given, anchor_radius=case_anchor_radius(scene, case, routing),
                     routing_error=refused, obstacles=placed or None, free_disk=freed)


def case_solve_options(scene: Scene, case: Case) -> dict:
    """The contact keywords of ``case``'s solves: the scene's self-contact
    (:func:`~mdsr_opt.scenes.reader.contact_options`) and the scene's and the case's obstacles with their
    friction (:func:`~mdsr_opt.scenes.obstacles.case_contact`, frictionless with a free disk,
    :func:`~mdsr_opt.scenes.obstacles.solve_friction`); ``{}`` for a case without contact."""
    contact = contact_options(scene.design_options)  # [design] contact = true: the targets touch, too
    contact.update(solve_friction(case_contact(scene, case)))  # the scene's and the case's obstacles
    return contact


def solve_target(scene: Scene, case: Case, **options):
    """The target solve of ``case`` as :func:`prepare_case` makes it: ``(result, obstacles, free_disk)``.

    External cases: :func:`~mdsr_opt.solve_external` of its anchors and drags; internal ones:
    :func:`~mdsr_opt.solve_internal` of its muscles at its contractions; both with :func:`case_solve_options`,
    a free disk first placed where the grip holds it (:func:`place_free_disk`). ``obstacles`` are the case's
    as the target placed them (empty without obstacles), ``free_disk`` the placement's report (None without a
    free disk). ``options``: further keywords of the solver (an ``initial_guess``, say)."""
    from ..mechanics.equilibrium import solve_external, solve_internal

    contact = case_solve_options(scene, case)

    def solve(obstacles=None):
        kw = dict(contact, **options, **({} if obstacles is None else {"obstacles": obstacles}))
        if case.kind == "external":
            return solve_external(scene.mesh, scene.material, case.anchors, case.drags, **kw)
        return solve_internal(scene.mesh, scene.material, scene.case_muscles(case), case.contractions,
                              muscle_model=scene.design_options.get("muscle_model", "cable"),
                              stiffness=scene.design_options.get("stiffness", 10.0),
                              anchor_radius=case_anchor_radius(scene, case), **kw)

    placed, freed = place_free_disk(contact.get("obstacles", []), solve)
    res = solve() if freed is None else freed.pop("result")
    return res, placed, freed


def case_anchor_radius(scene: Scene, case: Case, routing=None) -> float | None:
    """The end-fixture radius the design of ``case``'s muscles takes: the radius its routed ropes were fitted
    to (``routing.fixture_radius``, when routing laid them: an external case of a scene without muscles and
    without its own), the case's own ``anchor_radius`` (with its own muscles), else the scene's one size
    (:func:`~mdsr_opt.scenes.fixtures.scene_fixture_radius`), which also made an internal case's target."""
    routed = case.kind == "external" and scene.muscles is None and case.muscles is None
    if routed and routing is not None and routing.fixture_radius is not None:
        return float(routing.fixture_radius)
    if case.muscles is not None and case.anchor_radius is not None:
        return float(case.anchor_radius)
    return scene_fixture_radius(scene)


def given_muscle_conflicts(scene: Scene, case: Case, muscles) -> list[str]:
    """Warn (:class:`~mdsr_opt.synthesis.fabrication.FabricationWarning`) where muscles the scene gives cannot be
    moulded as laid out -- a channel on the outline, ropes too close -- by the check the Python API's
    :func:`~mdsr_opt.synthesis.pipeline.design_pipeline` makes (:func:`~mdsr_opt.synthesis.fabrication.rope_conflicts`,
    with the scene's ``[fabrication]`` and the case's ``anchor_radius``, else the scene's); returns the
    warning's text (empty: mouldable). The muscles are designed as given."""
    from ..synthesis.fabrication import Fabrication, FabricationWarning, check_fabrication, rope_conflicts, \
        warn_conflicts

    # the given ropes are designed with the scene's fixture radius, so their fixtures are checked at it (a
    # scene saved by the page keeps the routing's nominal fixture_radius beside the radius it fitted)
    r = case.anchor_radius if case.anchor_radius is not None else scene_fixture_radius(scene)
    fab = check_fabrication(scene.routing_options.get("fabrication")) or Fabrication()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", FabricationWarning)
        warn_conflicts(rope_conflicts(scene.mesh, muscles, fab, fixture_radius=r),
                       f"scene {scene.name!r}, case {case.name!r}: the muscles given")
    for w in caught:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return [str(w.message) for w in caught if issubclass(w.category, FabricationWarning)]


def place_free_disk(obstacles, solve) -> tuple[list, dict | None]:
    """Place a case's :class:`~mdsr_opt.scenes.obstacles.FreeDisk` where its grip holds it.

    ``solve(obstacles)`` is the case's target solve with those obstacles. Returns ``(obstacles, None)`` when
    none is free; else the obstacles with the free disk moved (:func:`~mdsr_opt.mechanics.grip.free_disk`,
    the disk first in its solves) and ``{"result", "start", "center", "converged", "iterations",
    "net_force", "why"}``. A search that does not bring the net force down leaves a failed result, its
    ``status`` saying why (a target in which a free disk is pushed away is no grip)."""
    free = [i for i, o in enumerate(obstacles) if isinstance(o, FreeDisk)]
    if not free:
        return list(obstacles), None
    from ..mechanics.grip import free_disk  # scipy.optimize: only for a free disk
    from ..mechanics.obstacles import Disk

    i = free[0]
    start = obstacles[i]
    others = [o for j, o in enumerate(obstacles) if j != i]
    res, disk, info = free_disk(lambda d: solve([d, *others]), Disk(start.center, start.radius))
    if res.success and not info["converged"]:
        res.success = False
        res.status = f"the free disk found no place where the grip holds it: {info.get('why')}"
    placed = list(obstacles)
    placed[i] = FreeDisk(disk.center, disk.radius)
    return placed, {"result": res, "obstacle": i, "start": start.center.tolist(), "center": disk.center.tolist(),
                    "converged": bool(info["converged"]), "iterations": int(info["iterations"]),
                    "net_force": info.get("net_force"), "why": info.get("why", "")}
