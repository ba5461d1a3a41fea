"""The obstacles, friction and self-contact of the case the ``mdsr author`` page edits, taken as ``mdsr run`` takes
them.

The page edits one external case of the scene it opened (:class:`~mdsr_opt.author.roundtrip.Origin`).
:func:`edited_case` is that case with the page's anchors and drags and the case's own obstacles and friction, so
every solve of the session goes through the helpers ``mdsr run`` uses for the saved scene:
:func:`~mdsr_opt.scenes.cases.solve_target` for the target (a free disk placed where the grip holds it),
:func:`~mdsr_opt.scenes.obstacles.check_case_obstacles` for what a saved scene would refuse,
:func:`~mdsr_opt.scenes.grips.obstacle_design` for the design. A drawn outline has no scene: no obstacles, no
self-contact. :func:`obstacle_entries` gives the obstacles as the page draws them and :func:`contact_lines`
what the page does with them.
"""

from __future__ import annotations

from ..mechanics.equilibrium import solve_external
from ..mechanics.obstacles import Disk, HalfPlane
from ..scenes.cases import case_solve_options, solve_target
from ..scenes.grips import design_route, obstacle_design
from ..scenes.obstacles import FreeDisk, check_case_obstacles
from ..scenes.reader import contact_options
from ..scenes.scene import Case
from .roundtrip import AUTO, edited_case_name

__all__ = ["edited_case", "solve_options", "target_solve", "live_options", "design_options_with_obstacles",
           "route_notes", "obstacle_entries", "contact_lines"]


def edited_case(session) -> Case | None:
    """The case the page edits, as the saved scene will hold it: the session's anchors and drags with the
    opened case's own obstacles and friction (None for a session without a scene, a drawn outline)."""
    o = session.origin
    if o is None:
        return None
    was = o.scene.case(o.case) if o.case is not None else None
    return Case(edited_case_name(session), anchors=session.anchors, drag_nodes=session.drag_nodes,
                drag_positions=session.drag_positions, obstacles=was.obstacles if was is not None else (),
                friction=was.friction if was is not None else None)


def solve_options(session) -> dict:
    """The contact keywords of the edited case's solves (:func:`~mdsr_opt.scenes.cases.case_solve_options`):
    the scene's self-contact and the obstacles with their friction; ``{}`` without contact."""
    case = edited_case(session)
    if case is None:
        return contact_options(session.design_options)
    return case_solve_options(session.origin.scene, case)


def target_solve(session):
    """The target solve of the edited case, exactly as ``mdsr run`` solves the saved scene's
    (:func:`~mdsr_opt.scenes.cases.solve_target`): ``(result, obstacles placed, free-disk report or None)``.

    Raises ValueError (naming the scene and the case) for what the saved scene would refuse: a drag whose
    straight path from rest enters an obstacle, a case with obstacles anchored at fewer than two nodes."""
    case = edited_case(session)
    if case is None:
        res = solve_external(session.mesh, session.material, session.anchors,
                             (session.drag_nodes, session.drag_positions), **contact_options(session.design_options))
        return res, [], None
    check_case_obstacles(session.origin.scene, case)
    return solve_target(session.origin.scene, case)


def live_options(session) -> dict:
    """The contact keywords of a live drag's warm solve: :func:`solve_options` with the obstacles where the last
    settled solve placed them (a free disk is held there while the drag moves, :func:`contact_lines`)."""
    kw = solve_options(session)
    placed = session.placed
    if kw.get("obstacles") and placed:
        kw["obstacles"] = list(placed)
    return kw


def design_options_with_obstacles(session, opts: dict) -> tuple[dict, list[str]]:
    """The design keywords ``opts`` with the edited case's obstacles as its target placed them, by
    :func:`~mdsr_opt.scenes.grips.obstacle_design` (``mdsr run``'s: designed without them and checked with them,
    derivative-free with them when touched or named; the body clamped at the anchors, frictionless), and the
    notes saying so: ``(opts, notes)``. The page's method ``"auto"``
    (:data:`~mdsr_opt.author.roundtrip.AUTO`) names none."""
    if opts.get("method") == AUTO:
        opts = {k: v for k, v in opts.items() if k != "method"}
    case = edited_case(session)
    if case is None:
        return opts, []
    return obstacle_design(session.origin.scene, case, opts, session.placed or None)


def route_notes(session) -> list[str]:
    """How the session's design met the edited case's obstacles, as ``mdsr run`` says it
    (:func:`~mdsr_opt.scenes.grips.design_route`); empty without obstacles or a design."""
    case = edited_case(session)
    if case is None or session.design is None:
        return []
    return design_route(session.origin.scene, case, session.design)


def obstacle_entries(obstacles) -> list[dict]:
    """The obstacles as the page draws them: ``{"kind": "disk", "center", "radius", "free"}``,
    ``{"kind": "halfplane", "point", "normal"}`` (the body's side is where the normal points) or
    ``{"kind": "polygon", "points"}``."""
    out = []
    for o in obstacles:
        if isinstance(o, Disk):
            out.append({"kind": "disk", "center": o.center.tolist(), "radius": float(o.radius),
                        "free": isinstance(o, FreeDisk)})
        elif isinstance(o, HalfPlane):
            out.append({"kind": "halfplane", "point": o.point.tolist(), "normal": o.normal.tolist()})
        else:
            out.append({"kind": "polygon", "points": o.polygon.tolist()})
    return out


def contact_lines(session) -> list[str]:
    """What the page does with the edited case's obstacles, friction and self-contact, one line each (empty
    without contact)."""
    kw = solve_options(session)
    if not kw:
        return []
    out = []
    obs = kw.get("obstacles", [])
    if obs:
        kinds = ", ".join(e["kind"] + (" (free)" if e.get("free") else "") for e in obstacle_entries(obs))
        out.append(f"obstacles ({kinds}), friction {kw['friction']:g}: the target, the design and its "
                   "verification take them, as mdsr run does")
    if kw.get("contact"):
        out.append("self-contact: the target, the design and its verification take it, as mdsr run does")
    out.append("live drag: no fast preview (it models no contact): each move is a full solve with the contact")
    if any(isinstance(o, FreeDisk) for o in obs):
        out.append("live drag: the free disk stays where the last settled solve placed it; a release places it "
                   "again")
    if obs:
        out.append("design: method auto: by the nested method without the obstacles, checked with them, and by the "
                   "derivative-free search with them when they are touched (the design says which); the body "
                   "clamped at the anchors, frictionless")
    return out
