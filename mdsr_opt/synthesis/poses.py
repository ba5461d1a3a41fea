"""One muscle layout for several poses, and the gait schedule that moves a body between them.

A real muscle-driven robot carries one set of muscles and changes pose by changing their strokes.
:func:`design_poses` lays ONE set of muscles for all the target poses of a body and designs each pose's
strokes on it; :func:`~mdsr_opt.synthesis.gait.gait_schedule` turns a cyclic sequence of those poses into an
actuation schedule (the stroke of every muscle over time), solved forward frame by frame.

Shared layout
-------------
The layout is the union of the poses' own routings, deduplicated, under a muscle budget:

1. every pose is routed on its own target as the pipeline routes (:func:`~mdsr_opt.synthesis.layouts.route_poses`:
   :func:`~mdsr_opt.synthesis.routing.route_for_design` with the same options and its fallbacks), giving each
   pose a ranked list of muscles (strongest first);
2. the candidates are taken round-robin by rank (every pose's strongest muscle, then every pose's second
   ...), so under a budget each pose keeps its most important muscles rather than one pose taking all;
3. a candidate whose edges are at least ``overlap`` (default half) covered by a muscle already in the layout
   is the same channel and is not added again (the pose is recorded as a source of the kept muscle), as is
   one that runs along it too close to be moulded beside it; a candidate that otherwise crosses or crowds
   the ropes already kept is fitted beside them as the routing fits its own ropes
   (:func:`~mdsr_opt.synthesis.routing_fixtures.fit_fixtures`, the stronger ropes first: shortened to its
   longest part a channel and a wall clear of their channels and fixtures, or dropped), at the smallest
   fixture; the fixtures then get the largest size every kept rope has room for
   (:func:`~mdsr_opt.synthesis.routing_fixtures.common_fixture_radius`). Each of these is said in the
   result's ``notes``; a clash left (ropes given, not routed) is in its ``problems``, and no success;
4. at most ``max_muscles`` are kept; given separate layouts (a scene's cases), named as in them (prefixed
   by the pose where two poses give one name to different ropes: ``curl:M2``);
5. after the poses are designed on it (below), a muscle that pulls in no pose (released in every pose, or
   idle -- below ``idle_contraction``, or slack -- wherever engaged) is dropped and those poses designed
   again, as :func:`~mdsr_opt.synthesis.acceptance.design_active` drops an idle muscle of one design
   (:mod:`~mdsr_opt.synthesis.poses_rounds`).

Why not route once on a combined contraction graph (e.g. the largest contraction of each edge over the
poses)? A muscle pulls in one direction: a combined graph mixes edges that contract in different poses, and
the router, which follows uniformly contracted chains, can join a left-bend edge to a right-bend edge into
one muscle that serves neither. The union keeps every muscle a chain that one pose contracts uniformly,
and it can never need more muscles than the separate layouts together (it is their deduplicated union).

Strokes per pose
----------------
With the layout fixed, the poses share no unknowns: every pose has its own state, contractions and rigid
alignment, so a single flattened NLP over all poses is block diagonal. Measured side by side with the same
stand-in machinery (``tests/benchmarks/bench_poses.py``: gecko, 555 nodes, 4 shared muscles, 2 poses, 4
repeats), the joint NLP reaches the same optima (to 1e-11), takes 24 IPOPT iterations against 22 + 17 for
the two NLPs apart, solves in about the same time and builds in about half the time (one solver instead
of two). Solving is not faster, and the build saving is small next to the design module's own assembled
NLPs, so the poses are designed one NLP per pose with
:func:`~mdsr_opt.synthesis.contractions.design_contractions` on the shared layout: the exact cable model,
every pose verified on its own, and a pose that fails does not spoil the others.

A muscle is *engaged* in a pose when its path shortens in that pose's target; the pose is designed with its
engaged muscles only. The others are *released*: an inextensible rope held at its rest length would stop
the body from stretching along it (a bent strip's convex side), so its servo pays the rope out to the path
length of the designed state, a negative stroke at zero tension (reported in ``strokes``).

Example
-------
>>> import numpy as np
>>> from mdsr_opt import Mesh, NeoHookean
>>> from mdsr_opt.synthesis.poses import design_poses
>>> mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
>>> X = mesh.points
>>> def bend(s):                                   # s = +1: bend up (left), -1: down (right)
...     R = 3.0; phi = (X[:, 0] - 2.0) / R; r = R - s * (X[:, 1] - 0.5)
...     return np.column_stack([r * np.sin(phi), s * (R - r * np.cos(phi))])
>>> res = design_poses(mesh, NeoHookean(1.0, 0.3), {"left": bend(1), "right": bend(-1)})
>>> res.n_muscles, int(res.separate_n_muscles.sum()), res.success
(2, 2, True)
>>> bool(np.all(res.differences <= 1.1 * res.separate_differences))
True
"""

from __future__ import annotations

import numbers
import time
import warnings
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from ..core.guards import interruptible
from ..body.checks import check_target_shape, solved_state
from ..body.fingerprint import check_same_mesh, mesh_fingerprint
from ..core.checks import as_float_array, check_label, check_options, keyword_names
from ..core.quantities import check_length_unit
from .acceptance import A_MAX, IDLE_CONTRACTION, check_idle_contraction, rest_difference
from ..body.mesh import Mesh
from ..body.muscles import check_muscles
from .fabrication import Fabrication, check_channel_fits, check_fabrication, rope_conflicts, warn_conflicts
from .routing_fixtures import common_fixture_radius
from .layouts import check_budget, route_poses, shared_layout
from .poses_result import PosesResult
from .poses_rounds import design_round, drop_idle

__all__ = ["Pose", "design_poses"]


# ---------------------------------------------------------------------------------------------- inputs
@dataclass(frozen=True, eq=False)
class Pose:
    """A named target shape of a body.

    Parameters
    ----------
    name : str
    target : (n, 2) array
        Target node positions (any rigid placement).
    mesh : Mesh, optional
        The body the target belongs to; when given, :func:`design_poses` checks that it is the same body.
    """

    name: str
    target: np.ndarray
    mesh: Mesh | None = None


def _same_mesh(a: Mesh, b: Mesh) -> bool:
    return a is b or (a.points.shape == b.points.shape and a.triangles.shape == b.triangles.shape
                      and np.array_equal(a.triangles, b.triangles) and np.allclose(a.points, b.points, rtol=0,
                                                                                   atol=1e-12 * a.size))


def _check_poses(mesh: Mesh, poses) -> list[Pose]:
    """Normalise ``poses`` (mapping name -> target, or a sequence of Pose / (name, target) / target)."""
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh must be a Mesh, got {type(mesh).__name__}")
    if isinstance(poses, Mapping):
        items = [Pose(str(k), v) for k, v in poses.items()]
    elif isinstance(poses, (list, tuple)):
        items = []
        for i, p in enumerate(poses):
            if isinstance(p, Pose):
                items.append(p)
            elif isinstance(p, tuple) and len(p) == 2 and isinstance(p[0], str):
                items.append(Pose(p[0], p[1]))
            else:
                items.append(Pose(f"pose{i}", p))
    else:
        raise TypeError(f"poses must be a mapping of name to target or a list of poses, got {type(poses).__name__}")
    if not items:
        raise ValueError("poses is empty: give at least one target pose")
    out, names = [], set()
    for p in items:
        check_label(p.name, "pose name")  # it heads columns of the muscle table and the schedule
        if not p.name or p.name == "rest":
            raise ValueError(f"pose name {p.name!r} is not allowed ('rest' means zero strokes in a gait)")
        if p.name in names:
            raise ValueError(f"pose name {p.name!r} is used twice")
        names.add(p.name)
        if p.mesh is not None and not _same_mesh(mesh, p.mesh):
            raise ValueError(f"pose {p.name!r} belongs to a different mesh ({p.mesh.n_nodes} nodes) than the one "
                             f"given ({mesh.n_nodes} nodes): all poses must be of the same mesh")
        t = solved_state(p.target, f"pose {p.name!r}: target")  # a failed solve's result is refused here
        t = as_float_array(t, f"pose {p.name!r}: target")  # strings, bools, None: TypeError, not coerced
        if np.ndim(t) != 2 or np.shape(t)[1] != 2 or np.shape(t)[0] != mesh.n_nodes:
            raise ValueError(f"pose {p.name!r}: target has shape {np.shape(t)}, expected ({mesh.n_nodes}, 2); all "
                             "poses must be of the same mesh")
        # the check of every design's target (finite, no inverted triangle), before any pose is routed
        out.append(Pose(p.name, check_target_shape(mesh, t, f"pose {p.name!r}: target"), mesh))
    return out


# ---------------------------------------------------------------------------------------------- design
def _idle_threshold(idle_contraction, dopt: dict) -> tuple[float, bool]:
    """The idle threshold and whether slack ropes count as idle: ``idle_contraction`` checked (below ``a_max``;
    a slack rope idle when it is above 0); None: :data:`~mdsr_opt.synthesis.acceptance.IDLE_CONTRACTION`, or 0
    when ``a_max`` is not above it (a design asked for tiny contractions), and a slack rope idle."""
    cable = dopt.get("muscle_model", "cable") == "cable"  # a spring under compression pushes: never slack
    if idle_contraction is not None:
        thr = check_idle_contraction(idle_contraction, a_max=dopt.get("a_max", A_MAX))
        return thr, thr > 0 and cable
    a_max = dopt.get("a_max", A_MAX)
    low = isinstance(a_max, numbers.Real) and not isinstance(a_max, bool) and a_max <= IDLE_CONTRACTION
    return (0.0 if low else IDLE_CONTRACTION), cable


def _check_option_dicts(routing_options, design_options) -> tuple[dict, dict]:
    """``routing_options`` and ``design_options`` as dicts, each key checked against the keywords of the
    function it is passed to (an unknown key named with the nearest one)."""
    from .contractions import design_contractions
    from .routing import route_muscles

    return (check_options(routing_options, keyword_names(route_muscles), "routing_options"),
            check_options(design_options, keyword_names(design_contractions), "design_options"))


@interruptible()
def design_poses(mesh: Mesh, material, poses, *, max_muscles: int | None = None,
                 routing_options: Mapping | None = None, design_options: Mapping | None = None,
                 overlap: float = 0.5, compare: bool = True, separate: Mapping[str, tuple] | None = None,
                 units: str | None = None, fabrication=None, clashes: str = "resolve",
                 idle_contraction: float | None = None) -> PosesResult:
    """Route ONE muscle layout for all poses and design each pose's strokes on it.

    See the module docstring for how the layout is made (union of the poses' routings, round-robin by rank,
    deduplicated, under a budget) and why each pose is one NLP on the shared layout.

    Parameters
    ----------
    mesh, material : the body.
    poses : mapping name -> (n, 2) target, or a list of :class:`Pose` / ``(name, target)`` / targets.
        A bare target in a list is named by its place: ``pose0``, ``pose1``...
        At least one; all of ``mesh`` (a :class:`Pose` carrying another mesh is refused). A target may be a
        solve's result (an :class:`~mdsr_opt.mechanics.result.EquilibriumResult`): its ``x``, refused when the
        solve failed.
    max_muscles : int, optional
        The muscle budget of the shared layout (at least 1); default: every non-duplicate muscle the poses'
        routings give.
    routing_options : dict, optional
        Keywords of :func:`~mdsr_opt.synthesis.routing.route_muscles`, used for every pose's own routing, made
        as the pipeline's (:func:`~mdsr_opt.synthesis.routing.route_for_design`: a ``K_a`` or ``band`` given
        is used as given; a ``max_muscles`` there limits each pose's own layout).
    design_options : dict, optional
        Keywords of :func:`~mdsr_opt.synthesis.contractions.design_contractions` (``method``, ``a_max``,
        ``muscle_model``...); ``fixture_wall`` defaults to the fabrication's ``wall``.
    overlap : float, default 0.5
        Duplicate threshold of :func:`~mdsr_opt.synthesis.layouts.shared_layout`.
    compare : bool, default True
        Also design every pose on its own layout (the separate differences); without it those are NaN.
    separate : mapping name -> (muscles, DesignResult), optional
        Separate layouts and designs already made (e.g. by the scene runner) with the same options: they
        are used instead of routing and designing again. A pose whose engaged muscles on the shared layout
        are exactly its separate muscles (the same node chains in the same order) takes that design as its
        shared-layout design too, when its recorded method, ``a_max``, muscle model, stiffness, anchor
        radius and fixture wall are those of ``design_options``.
    units : str, optional
        The mesh's length unit (see :data:`mdsr_opt.synthesis.export.UNITS`), recorded in the result with
        the material's ``stress_unit``: tables and fabrication files then give lengths in it and tensions in
        N. None: body units.
    fabrication : Fabrication or dict of its fields, optional
        As ``routing_options["fabrication"]`` (give it once): the ropes' channel, wall and fixtures, recorded.
    clashes : {"resolve", "keep"}, default "resolve"
        Ropes of different poses that cross or crowd each other: resolved (see Returns), or kept as routed
        (a layout whose crossing ropes get channels at two depths): then listed in ``problems``, and the
        result is no success (:func:`~mdsr_opt.synthesis.layouts.shared_layout`).
    idle_contraction : float in [0, 1), optional
        A muscle that pulls in no pose -- released in every pose, or designed below this contraction or
        slack (no tension) in every pose that engages it -- is idle, as in
        :func:`~mdsr_opt.synthesis.pipeline.design_pipeline`: dropped from the shared layout and the poses
        that engaged it designed again without it (:func:`~mdsr_opt.synthesis.poses_rounds.drop_idle`), said in
        ``notes`` and ``dropped``; when a pose fails without it, it is kept, with a
        :class:`~mdsr_opt.synthesis.results.MuscleWarning` and a note. Default
        :data:`~mdsr_opt.synthesis.acceptance.IDLE_CONTRACTION` (0 when ``a_max`` is not above it; slack ropes
        are still dropped); 0: keep every muscle. Must lie below ``a_max``.

    Returns
    -------
    PosesResult
        A pose is a success (``pose_success``) when its design converged, was verified and removes at least
        :data:`~mdsr_opt.synthesis.acceptance.MIN_PROGRESS` of the rest shape's difference to its target.
        The result's ``success`` is every pose's and the layout's. Ropes of different poses that cross or
        crowd each other are resolved as the routing resolves its own (merged, shortened or dropped, the
        fixtures as large as every rope has room for), each said in ``notes``; a clash left (ropes given,
        not routed: :func:`~mdsr_opt.synthesis.fabrication.rope_conflicts`) is listed in ``problems`` and
        makes the result no success. With ``separate``, the muscles keep the names those
        layouts give them (see :func:`~mdsr_opt.synthesis.layouts.shared_layout`, ``by_pose``); a muscle
        dropped as idle leaves its name unused. Each pose's design warnings (a saturated muscle's
        :class:`~mdsr_opt.synthesis.results.MuscleWarning`) start ``design_poses: pose '<name>' on the
        shared layout:``.

    Raises
    ------
    TypeError, ValueError
        Before any work: an empty pose list, a target from a failed solve, poses of a different mesh or
        shape, a target that is no shape of the body (:func:`~mdsr_opt.body.checks.check_target_shape`), a pose name with a control
        character, a separate design made on another mesh, a budget below one, a duplicated pose name, a
        bad overlap. ValueError after routing when no pose gets a rope, with each pose's reason.
    """
    from .contractions import design_contractions
    from ..body.material import Material

    t0 = time.perf_counter()
    items = _check_poses(mesh, poses)
    if not isinstance(material, Material):
        raise TypeError(f"material must be a NeoHookean, LinearElastic, Yeoh or MooneyRivlin, got "
                        f"{type(material).__name__}")
    budget = check_budget(max_muscles)
    if clashes not in ("resolve", "keep"):
        raise ValueError(f"clashes must be 'resolve' or 'keep', got {clashes!r}")
    if not (0.0 < float(overlap) <= 1.0):
        raise ValueError(f"overlap must be in (0, 1], got {overlap!r}")
    units = check_length_unit(units)
    ropt, dopt = _check_option_dicts(routing_options, design_options)  # misspelt keys: before any work
    thr, drop_slack = _idle_threshold(idle_contraction, dopt)
    # the ropes are fitted to their end fixtures, which are the design's anchor patches
    if fabrication is not None and "fabrication" in ropt:
        raise ValueError("give the fabrication once: as design_poses(fabrication=...) or in routing_options")
    ropt["fabrication"] = check_fabrication(ropt.get("fabrication", fabrication), dopt.get("anchor_radius"))
    separate = dict(separate or {})
    # a channel the body cannot hold: before any solve (only sizes given, when no pose is routed)
    check_channel_fits(mesh, ropt["fabrication"], routed=any(p.name not in separate for p in items))
    for k in separate:
        if k not in {p.name for p in items}:
            raise ValueError(f"separate names an unknown pose {k!r}")
        check_muscles(mesh, separate[k][0], f"separate[{k!r}] muscles")  # of this mesh, one label each
        sep_design = separate[k][1] if isinstance(separate[k], (tuple, list)) and len(separate[k]) == 2 else None
        check_same_mesh(mesh, getattr(sep_design, "rest_mesh", None), f"the separate design of pose {k!r}")

    routed, why_none = route_poses(mesh, {p.name: p.target for p in items if p.name not in separate}, ropt)
    own = {p.name: tuple(separate[p.name][0]) if p.name in separate else routed[p.name] for p in items}
    why_none.update({k: "its given layout has no muscle" for k in separate if not own[k]})
    t_route = time.perf_counter() - t0
    fab = None if ropt["fabrication"] is False else ropt["fabrication"].for_body(mesh)
    notes: list = []
    muscles, sources = shared_layout(mesh, own, budget, overlap, fabrication=fab,
                                     fixture_radius=dopt.get("anchor_radius"), notes=notes, by_pose=bool(separate),
                                     clashes=clashes)
    if not muscles:  # every pose's routing (as the pipeline routes) kept no rope: each one's reason
        raise ValueError("no rope for any pose, nothing to design: " + "; ".join(f"pose {k!r}: {v}"
                                                                               for k, v in why_none.items()))
    if dopt.get("anchor_radius") is None and fab is not None:
        # the poses' layouts were fitted apart: one fixture size every shared rope keeps its fixtures with
        dopt["anchor_radius"] = common_fixture_radius(mesh, muscles, fab)
        if dopt["anchor_radius"] < fab.fixture_radius:
            notes.append(f"fixtures shrunk from radius {fab.fixture_radius:.4g} to {dopt['anchor_radius']:.4g} (the "
                         f"smallest allowed is {fab.min_fixture_radius:.4g}): the largest size at which every rope of "
                         "the shared layout keeps both fixtures inside the body and clear of the other ropes")
    # the wall a rope's two end fixtures keep between them in every design: the fabrication's (as the pipeline's)
    dopt.setdefault("fixture_wall", (fab or Fabrication().for_body(mesh)).wall)
    t1 = time.perf_counter()
    Drest = np.array([rest_difference(mesh, p.target, dopt) for p in items])  # the "do nothing" design
    rnd = design_round(mesh, material, items, muscles, dopt, separate, Drest, units)
    # a muscle that pulls in no pose (released, or idle in every design that engages it): dropped, as
    # design_pipeline drops an idle muscle, and the poses that engaged it designed again
    rnd, dropped, _ = drop_idle(mesh, material, items, rnd, dopt, separate, Drest, units, thr=thr,
                                drop_slack=drop_slack, notes=notes)
    if len(rnd.muscles) < len(muscles):
        sources = tuple(src for mu, src in zip(muscles, sources) if any(mu is k for k in rnd.muscles))
        muscles = rnd.muscles
    status = list(rnd.status)
    for k, p in enumerate(items):
        if own[p.name] and not any(p.name in src for src in sources):
            status[k] += ("; none of the ropes of its own layout is in the shared layout (over the budget, "
                          "dropped beside stronger ropes or idle in every pose: see the notes)")
        elif not own[p.name]:
            status[k] += f"; its own routing kept no rope ({why_none[p.name]})"
        for w in rnd.caught.get(p.name, ()):  # the muscles named are the shared layout's: the pose is said
            warnings.warn(f"design_poses: pose {p.name!r} on the shared layout: {w.message}", w.category,
                          stacklevel=3)
    t_shared = time.perf_counter() - t1
    problems: list[str] = []
    if fab is not None:  # a rope given (a scene's own) whose channel or fixture leaves the body is said
        found = rope_conflicts(mesh, muscles, fab, fixture_radius=dopt.get("anchor_radius"))
        # ropes of one pose's own layout (given: a routed one is fitted) that clash are said, as design_pipeline
        # says them; ropes kept for different poses that still clash make a layout that cannot be moulded
        across = [c for c in found if len(c.muscles) == 2 and sources[c.muscles[0]][0] != sources[c.muscles[1]][0]]
        warn_conflicts(found, "design_poses: the shared layout", stacklevel=4)
        if across:
            problems.append(f"the shared layout cannot be moulded in one layer: {len(across)} place(s) where ropes "
                            "of different poses clash: " + "; ".join(c.message for c in across))

    t2 = time.perf_counter()
    Dsep = np.full(len(items), np.nan)
    nsep = np.array([len(own[p.name]) for p in items], dtype=int)
    if compare:
        for k, p in enumerate(items):
            if p.name in separate and separate[p.name][1] is not None:
                Dsep[k] = float(separate[p.name][1].difference)
            elif own[p.name]:
                with warnings.catch_warnings(record=True) as caught:
                    Dsep[k] = design_contractions(mesh, material, own[p.name], p.target, **dopt).difference
                for w in caught:  # its muscles are named in the pose's own layout, not in the shared one
                    warnings.warn(f"design_poses: pose {p.name!r} on its own layout (compared): {w.message}",
                                  w.category, stacklevel=3)
    t_sep = time.perf_counter() - t2
    designs = rnd.designs
    radius = next((getattr(d, "anchor_radius", None) for d in designs.values()), None)
    return PosesResult(names=tuple(p.name for p in items), muscles=muscles,
                       rest_lengths=np.array([mu.rest_length(mesh) for mu in muscles]), sources=sources,
                       contractions=rnd.contractions, strokes=rnd.strokes, tensions=rnd.tensions,
                       differences=rnd.differences, pose_success=rnd.ok, status=tuple(status),
                       states=np.array(rnd.states), separate_differences=Dsep, separate_n_muscles=nsep,
                       engaged=rnd.engaged, anchor_radius=None if radius is None else float(radius),
                       muscle_model=str(dopt.get("muscle_model", getattr(next(iter(designs.values()), None),
                                                                          "muscle_model", "cable"))),
                       max_muscles=budget, times={"routing": t_route, "shared": t_shared, "separate": t_sep,
                                                  "total": time.perf_counter() - t0}, designs=designs,
                       rest_mesh=mesh_fingerprint(mesh), rest_differences=Drest, units=units,
                       stress_unit=getattr(material, "stress_unit", None), problems=tuple(problems), fabrication=fab,
                       notes=tuple(dict.fromkeys(notes)), dropped=dropped)
