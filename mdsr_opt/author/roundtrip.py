"""The scene file a session saves: the page's edits laid over the scene it opened, every other part kept.

The page edits one external case: its anchors and drags and, once routed, its muscles (less the deleted
ones), saved as that case's own ``muscles`` with the radius of the end fixtures they were fitted to (so
they drive that case alone); and the fabrication and design settings. Everything else of the scene it
opened -- the ``[routing]`` knobs (the page's made the saved layout), the other cases with their own
muscles (or their routing) and every case's name, the scene's given ``[[muscles]]``, regions, gait, animations,
material, units, acceptance, expected figures, title -- goes into the saved file as it was loaded: for a
scene file, its own tables (a region stays ``{ box = [...] }``, a case that was not edited keeps its ``by``
drags); for a problem script's scene, the same parts written out as node ids and exact positions.
:func:`scene_file` builds the file's content and the notes the page shows with it (the design settings and
channel sizes set on the page are the scene's: the other cases are designed with them too).
:func:`check_read_back` compares the saved file, read with :func:`~mdsr_opt.load_scene`, with the session
and the scene it came from.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ..scenes.obstacles import obstacle_tables

__all__ = ["AUTO", "Origin", "scene_dict", "scene_file", "check_read_back", "kept_lines", "edited_case_name",
           "saved_layout"]

#: the page's method choice that names none: the design chooses as ``mdsr run`` does for a scene without one
#: (flattened; nested for a clamped body; with obstacles a gradient design checked with them, derivative-free
#: when they are touched), and a save writes no method
AUTO = "auto"

#: the sentence a save adds to the scene's description (followed by the file it was opened from)
AUTHORED_FROM = "Authored on the mdsr author page from "

#: what the page calls the case it edits when the scene it opened has no external case
AUTHORED = "authored"


@dataclass(frozen=True)
class Origin:
    """The scene a session opened: ``scene`` (a :class:`~mdsr_opt.scenes.scene.Scene`), the name of the case
    whose anchors and drags the page edits (``case``; None: the scene has no external case), and the scene
    file's parsed content (``data``; None for a problem script's scene)."""

    scene: object
    case: str | None = None
    data: dict | None = None

    def raw(self, key: str):
        """The scene file's own ``key`` section (None when there is no file or no such section)."""
        return self.data.get(key) if isinstance(self.data, dict) else None


def edited_case_name(session) -> str:
    """The name the saved scene gives the case edited on the page: the opened case's, else ``authored``
    (numbered when a case of the scene has that name)."""
    o = session.origin
    if o is not None and o.case is not None:
        return o.case
    taken = {c.name for c in o.scene.cases} if o is not None else set()
    name, k = AUTHORED, 1
    while name in taken:
        k += 1
        name = f"{AUTHORED}_{k}"
    return name


def _plain(v):
    if isinstance(v, (np.floating, np.integer, np.bool_)):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, dict):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    return v


def _file_name(source) -> str:
    """The last part of a path (``/``- or ``\\``-separated, whichever platform wrote it): no folder."""
    return re.split(r"[\\/]", str(source or "").rstrip("\\/"))[-1]


def _fixed_table(anchors, drag_nodes, drag_positions) -> dict:
    """Anchors as node ids, each drag one node moved ``to`` its exact position."""
    d = {}
    if len(anchors):
        d["anchors"] = [int(v) for v in anchors]
    if len(drag_nodes):
        d["drags"] = [{"nodes": [int(i)], "to": [float(p[0]), float(p[1])]} for i, p in zip(drag_nodes, drag_positions)]
    return d


def _by_node(nodes, positions):
    order = np.argsort(nodes, kind="stable")
    return np.asarray(nodes)[order], np.asarray(positions).reshape(-1, 2)[order]


def _same_fixed(case, anchors, drag_nodes, drag_positions) -> bool:
    """``case`` holds these anchors and drags (in any order, positions bit for bit)."""
    a, b = _by_node(case.drag_nodes, case.drag_positions), _by_node(drag_nodes, drag_positions)
    return (np.array_equal(np.sort(case.anchors), np.sort(anchors)) and np.array_equal(a[0], b[0])
            and np.array_equal(a[1], b[1]))


def _muscle_tables(muscles) -> list:
    """Muscles as ``[[muscles]]`` tables (node ids), unnamed ones called ``m<i>``."""
    return [{"name": m.name or f"m{i}", "nodes": [int(v) for v in m.nodes]} for i, m in enumerate(muscles)]


def _case_table(case) -> dict:
    """A problem script's case as a scene file's ``[[cases]]`` table (with its own muscles, if any)."""
    d = {"name": case.name}
    if case.description:
        d["description"] = case.description
    if case.obstacles:  # its own obstacles (and their friction)
        d["obstacles"] = obstacle_tables(case.obstacles, case.friction)
    if case.kind == "internal":
        d["contractions"] = [float(a) for a in case.contractions]
    else:
        d.update(_fixed_table(case.anchors, case.drag_nodes, case.drag_positions))
    if case.muscles is not None:
        d["muscles"] = _muscle_tables(case.muscles)
    if case.anchor_radius is not None:
        d["anchor_radius"] = float(case.anchor_radius)
    return d


def _gait_table(g) -> dict:
    d = {"name": g.name, "poses": list(g.sequence), "frames_per_step": int(g.frames_per_step),
         "step_time": float(g.step_time), "cyclic": bool(g.cyclic), "fps": float(g.fps)}
    if g.max_muscles is not None:
        d["max_muscles"] = int(g.max_muscles)
    return d


def _cases(session) -> list:
    """The saved scene's cases, in the opened scene's order, the edited one with the page's anchors and drags
    (its own table when they did not change) and the page's muscles once routed as its own ``muscles`` (its
    own muscles kept otherwise), a new ``authored`` case last when the scene had no external case."""
    o = session.origin
    fixed = (session.anchors, session.drag_nodes, session.drag_positions)
    edited = edited_case_name(session)
    raw = o.raw("cases") if o is not None else None
    out, seen = [], False
    for i, c in enumerate(o.scene.cases if o is not None else ()):
        own = raw[i] if isinstance(raw, list) and i < len(raw) else None
        if c.name != edited:
            out.append(own if own is not None else _case_table(c))
            continue
        seen = True
        if own is not None and _same_fixed(c, *fixed):
            d = dict(own)
        else:
            d = {"name": c.name, "description": c.description or "anchors and drags set on the page"}
            d.update(_fixed_table(*fixed))
            if c.muscles is not None:  # its own muscles (and their fixtures' radius), as written
                d["muscles"] = own["muscles"] if own is not None else _muscle_tables(c.muscles)
            if c.anchor_radius is not None:
                d["anchor_radius"] = float(c.anchor_radius)
            if c.obstacles:  # its own obstacles, as written
                d["obstacles"] = own["obstacles"] if own is not None and "obstacles" in own else \
                    obstacle_tables(c.obstacles, c.friction)
        out.append(_with_page_muscles(d, session))
    if not seen:
        d = {"name": edited, "description": "anchors and drags set on the page"}
        d.update(_fixed_table(*fixed))
        out.append(_with_page_muscles(d, session))
    return out


def saved_layout(session) -> tuple:
    """The muscles a save lays in the edited case: the layout the last design was made for when it dropped idle
    muscles (``mdsr run`` drops them again from the same design, so its result is the page's: a design made
    afresh on the muscles kept may stop elsewhere), else the page's layout (after its deletions)."""
    if session.design is not None and session.dropped and session.designed_layout:
        return tuple(session.designed_layout)
    return tuple(session.muscles)


def _with_page_muscles(d: dict, session) -> dict:
    """The edited case's table ``d`` with the layout routed on the page (after its deletions) as its own
    muscles, designed with the end fixtures they were fitted to: they drive this case alone."""
    if session.muscles:
        d["muscles"] = _muscle_tables(saved_layout(session))
        d.pop("anchor_radius", None)
        if session.fixture_radius is not None:  # the routed ropes' fixtures (shrunk when they had to be)
            d["anchor_radius"] = float(session.fixture_radius)
    return d


def scene_file(session, name: str, mesh_file: str) -> tuple[dict, list[str]]:
    """The scene file's content for ``session`` (body = ``mesh_file``) and the notes the page shows with it.

    The page's parts: the edited case's anchors and drags (:func:`edited_case_name`) and, once routed, its
    own muscles (without the deleted ones); the fabrication and design settings used (the ``[routing]``
    knobs stay the scene's: the other cases and the gait route with them). Every other
    part of the scene opened is kept (see the module's description). Notes name the settings set on the page
    that are the scene's and so change how the other cases are designed (``[design]``, ``[fabrication]``).
    """
    from ..scenes.scenefile import material_table

    o = session.origin
    scene = o.scene if o is not None else None
    notes: list[str] = []
    src = _file_name(session.source) or session.name
    said = (scene.description.rstrip() + " ") if scene is not None and scene.description else ""
    said = said.split(AUTHORED_FROM)[0]  # saved again: one sentence saying where from, the last source
    d = {
        "name": name,
        "title": scene.title if scene is not None and scene.title else f"{name}: authored with mdsr author",
        # the file's name alone: a scene file holds no path of the machine it was saved on
        "description": f"{said}{AUTHORED_FROM}{src}.",
        "body": {"mesh": mesh_file},
        "material": o.raw("material") if o is not None and o.raw("material") is not None
        else material_table(session.material),
    }
    if session.units:
        d["units"] = session.units
    if session.acceptance:
        d["acceptance"] = {k: _plain(v) for k, v in session.acceptance.items()}
    if scene is not None and scene.regions:
        d["regions"] = o.raw("regions") or {k: {"nodes": [int(v) for v in idx]} for k, idx in scene.regions.items()}
    if scene is not None and scene.obstacles:  # the rigid obstacles of every case
        d["obstacles"] = o.raw("obstacles") or obstacle_tables(scene.obstacles, scene.friction)
    if scene is not None and scene.muscles:  # the scene's given muscles (the page's are its case's own)
        d["muscles"] = o.raw("muscles") or _muscle_tables(scene.muscles)
    # the scene's routing knobs: the page's made the edited case's layout, which its table holds; they are
    # not the other cases' (nor the gait's)
    routing = dict(session.routing_options)
    fab = session.fabrication if session.routing is not None else routing.get("fabrication")
    routing.pop("fabrication", None)  # written as the [fabrication] table
    if routing:
        d["routing"] = {k: _plain(v) for k, v in routing.items() if v is not None}
    if fab is False or fab:
        d["fabrication"] = fab if fab is False else {k: float(v) for k, v in fab.items() if v is not None}
    design = dict(session.design_params or session.design_options)
    design.pop("anchor_radius", None)  # the scene's: the routed ropes' fixtures are the edited case's own
    design.pop("fixture_wall", None)  # the [fabrication] table's wall, not a [design] key
    if session.design_options.get("anchor_radius") is not None:
        design["anchor_radius"] = session.design_options["anchor_radius"]
    if session.design is not None:
        design["muscle_model"] = session.design.muscle_model
        design["stiffness"] = float(session.design.stiffness)
        design["a_max"] = float(session.design.a_max)
        # the page's "auto" names no method (mdsr run chooses as the page did); the method asked where the
        # obstacles made the choice (mdsr run makes it again, a case without them keeps the one asked); else the
        # one the design ran
        asked = session.design_params.get("method")
        design["method"] = None if asked == AUTO else (asked if session.design_notes else None) or \
            session.design.method
    if design:
        d["design"] = {k: _plain(v) for k, v in design.items() if v is not None}
        _design_note(session, d["design"], notes)
    if saved_layout(session) != tuple(session.muscles):
        names = ", ".join(str(x.name) for x in session.dropped)
        notes.append(f"muscles: saved with {names}, which the design dropped as idle: mdsr run drops "
                     f"{'it' if len(session.dropped) == 1 else 'them'} again from the same design (the page's result)")
    _fabrication_note(session, notes)
    d["cases"] = _cases(session)
    if scene is not None and scene.animations:
        d["animations"] = o.raw("animations") or [
            {"name": a.name, "keyframes": [[k, float(w)] for k, w in a.keyframes],
             "frames_per_step": int(a.frames_per_step), "fps": float(a.fps)} for a in scene.animations]
    if scene is not None and scene.gait is not None:
        d["gait"] = o.raw("gait") or _gait_table(scene.gait)
    if scene is not None and scene.expected:
        d["expected"] = o.raw("expected") or _plain(dict(scene.expected))
    if notes:  # the file says it too, for whoever runs it
        d["description"] += " Saved with notes: " + " ".join(n.rstrip(".") + "." for n in notes)
    return d, notes


def _design_note(session, design: dict, notes: list) -> None:
    """Say so when the design settings set on the page, which are the scene's ``[design]``, change how the
    other cases of the scene opened are designed."""
    import inspect

    from ..synthesis.contractions import design_contractions

    o = session.origin
    others = [c.name for c in (o.scene.cases if o is not None else ()) if c.name != edited_case_name(session)]
    if not others:
        return
    default = {k: p.default for k, p in inspect.signature(design_contractions).parameters.items()}
    changed = [f"{k} {design[k]!r}, was {session.design_options.get(k, default.get(k))!r}"
               for k in ("method", "a_max", "muscle_model", "stiffness")
               if k in design and design[k] != session.design_options.get(k, default.get(k))]
    if changed:
        notes.append(f"the design settings set here ({'; '.join(changed)}) are the scene's [design]: mdsr run "
                     f"designs every case with them, also {', '.join(others)}")


def _fabrication_note(session, notes: list) -> None:
    """Say so when the channel, wall and fixture sizes the page routed with, which are the scene's
    ``[fabrication]``, differ from the ones the other cases of the scene opened were routed with."""
    o = session.origin
    others = [c.name for c in (o.scene.cases if o is not None else ()) if c.name != edited_case_name(session)]
    if session.routing is None or not others:
        return
    now, was = session.fabrication_sizes(session.fabrication), \
        session.fabrication_sizes(session.routing_options.get("fabrication"))
    if now == was:
        return
    changed = ("off, was on" if now is False else "on, was off" if was is False else
               "; ".join(f"{k} {now[k]:.4g}, was {was[k]:.4g}" for k in now if now[k] != was.get(k)))
    notes.append(f"the channel, wall and fixture sizes set here ({changed}) are the scene's [fabrication]: "
                 f"mdsr run routes and checks every case's ropes with them, also {', '.join(others)}")


def scene_dict(session, name: str, mesh_file: str) -> dict:
    """The scene file's content for ``session`` (:func:`scene_file` without its notes)."""
    return scene_file(session, name, mesh_file)[0]


def _layout(muscles) -> list:
    return [tuple(m.nodes) for m in (muscles or ())]


def _same_case(a, b) -> bool:
    if a.kind != b.kind:
        return False
    if a.kind == "internal":
        return np.array_equal(a.contractions, b.contractions)
    return (_same_fixed(a, b.anchors, b.drag_nodes, b.drag_positions) and _layout(a.muscles) == _layout(b.muscles)
            and a.anchor_radius == b.anchor_radius)


def _obstacles(obstacles) -> list:
    return obstacle_tables(obstacles)


def check_read_back(back, session, d: dict) -> str:
    """What differs between the saved scene ``back`` (read with :func:`~mdsr_opt.load_scene`) and the
    session it was saved from, its content ``d`` and the scene the session opened ("" when nothing does)."""
    o = session.origin
    edited = edited_case_name(session)
    names = [c["name"] for c in d["cases"]]
    if [c.name for c in back.cases] != names:
        return f"cases {[c.name for c in back.cases]} for {names}"
    case = back.case(edited)
    if not _same_fixed(case, session.anchors, session.drag_nodes, session.drag_positions):
        return f"case {edited!r}: anchors or drags"
    if not (np.array_equal(back.mesh.points, session.mesh.points)
            and np.array_equal(back.mesh.triangles, session.mesh.triangles)):
        return "the mesh"
    was = o.scene.case(edited) if o is not None and edited in o.scene.case_names else None
    # the edited case lays the page's layout once routed, else its own muscles as loaded (or none)
    if _layout(case.muscles) != _layout(saved_layout(session) or (was.muscles if was is not None else None)):
        return f"case {edited!r}: muscles"
    radius = session.fixture_radius if session.muscles else (was.anchor_radius if was is not None else None)
    if case.anchor_radius != (None if radius is None else float(radius)):
        return f"case {edited!r}: anchor_radius"
    if _layout(back.muscles) != _layout(o.scene.muscles if o is not None else None):
        return "the scene's muscles"
    if back.design_options.get("anchor_radius") != session.design_options.get("anchor_radius"):
        return "the design's anchor_radius"
    if back.routing_options.get("fabrication") != d.get("fabrication"):
        return "the fabrication table"
    if o is None:
        return ""
    scene = o.scene
    for c in scene.cases:
        if c.name != edited and not _same_case(back.case(c.name), c):
            return f"case {c.name!r} kept as loaded"
    if back.gait != scene.gait or back.animations != scene.animations:
        return "the gait or the animations"
    if set(back.regions) != set(scene.regions) or any(
            not np.array_equal(np.unique(back.regions[k]), np.unique(scene.regions[k])) for k in scene.regions):
        return "the regions"
    if (back.units or None) != (scene.units or None):
        return "the units"
    if _obstacles(back.obstacles) != _obstacles(scene.obstacles) or back.friction != scene.friction:
        return "the obstacles"
    if o.case is not None and (_obstacles(back.case(edited).obstacles) != _obstacles(scene.case(edited).obstacles)
                               or back.case(edited).friction != scene.case(edited).friction):
        return f"case {edited!r}: obstacles"
    return ""


def kept_lines(session) -> list[str]:
    """What a saved scene keeps of the scene the page opened, one line each, as the page lists them."""
    o = session.origin
    if o is None:
        return []
    scene, edited = o.scene, edited_case_name(session)
    out = []
    others = [c.name for c in scene.cases if c.name != edited]
    new = "" if o.case is not None else " (a new case)"
    out.append(f"case {edited!r}{new}: anchors and drags as set here"
               + (f"; cases {', '.join(others)}: kept as loaded" if others else ""))
    if scene.regions:
        out.append(f"regions {', '.join(scene.regions)}: kept as loaded")
    if scene.muscles:
        out.append(f"muscles {', '.join(str(m.name) for m in scene.muscles)}: kept as loaded")
    if others:  # the layout routed here is the edited case's own: the other cases keep theirs (or route)
        out.append(f"muscles routed here: case {edited!r}'s alone; cases {', '.join(others)}: their muscles (or "
                   "routing) as loaded")
    owned = [c.name for c in scene.cases if c.obstacles]
    if scene.obstacles or owned:  # every solve of the page takes them, as mdsr run does
        what = [f"{len(scene.obstacles)} of the scene"] if scene.obstacles else []
        what += [f"case {n!r}'s own" for n in owned]
        fr = "" if scene.friction is None else f", friction {scene.friction:g}"
        out.append(f"obstacles ({'; '.join(what)}){fr}: kept as loaded")
    if scene.gait is not None:
        out.append(f"gait {scene.gait.name!r} (poses {', '.join(scene.gait.sequence)}): kept as loaded")
    if scene.animations:
        out.append(f"animations {', '.join(a.name for a in scene.animations)}: kept as loaded")
    knobs = [k for k in scene.routing_options if k != "fabrication"]  # the layout routed here is saved as such
    rest = [k for k, v in (("material", True), ("routing knobs", knobs), ("units", scene.units),
                           ("acceptance", scene.acceptance),
                           ("expected figures", scene.expected), ("title", scene.title)) if v]
    out.append(f"{', '.join(rest)}: kept as loaded")
    return out
