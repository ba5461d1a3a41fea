"""The scene file a session saves: the page's edits laid over the scene it opened, every other part kept.

The page edits one external case (its anchors and drags), the muscles (routing, deletions), the routing,
fabrication and design settings. Everything else of the scene it opened -- the other cases and every
case's name, regions, gait, animations, given muscles (until the page routes), material, units,
acceptance, expected figures, title -- goes into the saved file as it was loaded: for a scene file, its
own tables (a region stays ``{ box = [...] }``, a case that was not edited keeps its ``by`` drags); for a
problem script's scene, the same parts written out as node ids and exact positions. :func:`scene_file`
builds the file's content and names what the saved file cannot hold or what an edit made inconsistent
(e.g. an internal case whose contractions no longer match the routed layout): the page shows those notes,
and ``mdsr run`` names the same field when it reads the file. :func:`check_read_back` compares the saved
file, read with :func:`~mdsr_opt.load_scene`, with the session and the scene it came from.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

__all__ = ["Origin", "scene_dict", "scene_file", "check_read_back", "refused_cases", "kept_lines",
           "edited_case_name"]

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


def _case_table(case) -> dict:
    """A problem script's case as a scene file's ``[[cases]]`` table."""
    d = {"name": case.name}
    if case.description:
        d["description"] = case.description
    if case.kind == "internal":
        d["contractions"] = [float(a) for a in case.contractions]
        return d
    d.update(_fixed_table(case.anchors, case.drag_nodes, case.drag_positions))
    return d


def _gait_table(g) -> dict:
    d = {"name": g.name, "poses": list(g.sequence), "frames_per_step": int(g.frames_per_step),
         "step_time": float(g.step_time), "cyclic": bool(g.cyclic), "fps": float(g.fps)}
    if g.max_muscles is not None:
        d["max_muscles"] = int(g.max_muscles)
    return d


def _cases(session, notes: list) -> list:
    """The saved scene's cases, in the opened scene's order, the edited one with the page's anchors and drags
    (its own table when they did not change), a new ``authored`` case last when the scene had no external
    case."""
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
            out.append(own)
            continue
        d = {"name": c.name, "description": c.description or "anchors and drags set on the page"}
        d.update(_fixed_table(*fixed))
        out.append(d)
    if not seen:
        d = {"name": edited, "description": "anchors and drags set on the page"}
        d.update(_fixed_table(*fixed))
        out.append(d)
    # a problem script's case may lay its own muscles; the edited one lays the page's once routed
    own = [c.name for c in (o.scene.cases if o is not None else ()) if c.muscles is not None
           and (c.name != edited or session.routing is None)]
    if own:
        many = len(own) > 1
        notes.append(f"case{'s' * many} {', '.join(own)}: {'their' if many else 'its'} own muscles (set by the "
                     "problem script) cannot be written in a scene file: mdsr run of the saved file routes "
                     "them, or lays the muscles routed on the page")
    return out


def refused_cases(d: dict, session) -> list[str]:
    """The internal cases kept as loaded whose contractions no longer match the saved layout ``d["muscles"]``
    (the page routed or deleted muscles): ``mdsr run`` refuses the saved file until they are fixed."""
    o = session.origin
    n = len(d.get("muscles", ()))
    return [c.name for c in (o.scene.cases if o is not None else ()) if c.kind == "internal"
            and len(c.contractions) != n]


def _muscle_notes(d: dict, session, notes: list) -> None:
    refused = refused_cases(d, session)
    if refused:  # a scene's internal cases give one contraction per muscle of that scene
        k = len(session.origin.scene.case(refused[0]).contractions)
        many = len(refused) > 1
        notes.append(f"case{'s' * many} {', '.join(refused)} (kept as loaded) give{'' if many else 's'} "
                     f"{k} contraction(s), one per muscle of the scene opened, but the saved scene has "
                     f"{len(d.get('muscles', ()))} muscle(s) (the layout routed on the page): mdsr run refuses "
                     "the file until each gives one per muscle")


def scene_file(session, name: str, mesh_file: str) -> tuple[dict, list[str]]:
    """The scene file's content for ``session`` (body = ``mesh_file``) and the notes the page shows with it.

    The page's parts: the edited case's anchors and drags (:func:`edited_case_name`), the muscles once
    routed (without the deleted ones), the routing, fabrication and design settings used. Every other part
    of the scene opened is kept (see the module's description). Notes name what the file cannot hold or what
    ``mdsr run`` will refuse in it because of an edit on the page.
    """
    from ..scenes.scenefile import material_table

    o = session.origin
    scene = o.scene if o is not None else None
    notes: list[str] = []
    src = _file_name(session.source) or session.name
    said = (scene.description.rstrip() + " ") if scene is not None and scene.description else ""
    d = {
        "name": name,
        "title": scene.title if scene is not None and scene.title else f"{name}: authored with mdsr author",
        # the file's name alone: a scene file holds no path of the machine it was saved on
        "description": f"{said}Authored on the mdsr author page from {src}.",
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
    if session.routing is not None or session.muscles:  # the layout routed on the page (after its deletions)
        if session.muscles:
            d["muscles"] = [{"name": m.name or f"m{i}", "nodes": [int(v) for v in m.nodes]}
                            for i, m in enumerate(session.muscles)]
    elif scene is not None and scene.muscles:  # the scene's given muscles, until the page routes
        d["muscles"] = o.raw("muscles") or [{"name": m.name or f"m{i}", "nodes": [int(v) for v in m.nodes]}
                                            for i, m in enumerate(scene.muscles)]
    routing = dict(session.routing_params or session.routing_options)
    fab = session.fabrication if session.routing is not None else routing.get("fabrication")
    routing.pop("fabrication", None)  # written as the [fabrication] table
    if routing:
        d["routing"] = {k: _plain(v) for k, v in routing.items() if v is not None}
    if fab is False or fab:
        d["fabrication"] = fab if fab is False else {k: float(v) for k, v in fab.items() if v is not None}
    design = dict(session.design_params or session.design_options)
    if session.fixture_radius is not None:  # the routed ropes' fixtures (shrunk when they had to be)
        design["anchor_radius"] = float(session.fixture_radius)
    if session.design is not None:
        design["muscle_model"] = session.design.muscle_model
        design["stiffness"] = float(session.design.stiffness)
        design["a_max"] = float(session.design.a_max)
        design["method"] = session.design.method
    if design:
        d["design"] = {k: _plain(v) for k, v in design.items() if v is not None}
    d["cases"] = _cases(session, notes)
    _muscle_notes(d, session, notes)
    others = [c.name for c in (scene.cases if scene is not None else ()) if c.kind == "external"
              and c.name != edited_case_name(session)]
    if session.routing is not None and session.muscles and scene is not None and (others or scene.muscles):
        was = (f"replace the scene's muscles {', '.join(str(m.name) for m in scene.muscles)}" if scene.muscles
               else "are the scene's [[muscles]]")
        notes.append(f"the muscles routed here {was}: mdsr run designs every external case with them"
                     + (f" (also {', '.join(others)}, kept as loaded)" if others else ""))
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


def scene_dict(session, name: str, mesh_file: str) -> dict:
    """The scene file's content for ``session`` (:func:`scene_file` without its notes)."""
    return scene_file(session, name, mesh_file)[0]


def _same_case(a, b) -> bool:
    if a.kind != b.kind:
        return False
    if a.kind == "internal":
        return np.array_equal(a.contractions, b.contractions)
    return _same_fixed(a, b.anchors, b.drag_nodes, b.drag_positions)


def check_read_back(back, session, d: dict, refused=()) -> str:
    """What differs between the saved scene ``back`` (read with :func:`~mdsr_opt.load_scene`) and the
    session it was saved from, its content ``d`` and the scene the session opened ("" when nothing does).

    ``refused``: the cases (:func:`refused_cases`) left out of ``back`` with the gait and animations, which
    are then not compared."""
    o = session.origin
    edited = edited_case_name(session)
    names = [c["name"] for c in d["cases"] if c["name"] not in refused]
    if [c.name for c in back.cases] != names:
        return f"cases {[c.name for c in back.cases]} for {names}"
    case = back.case(edited)
    if not _same_fixed(case, session.anchors, session.drag_nodes, session.drag_positions):
        return f"case {edited!r}: anchors or drags"
    if not (np.array_equal(back.mesh.points, session.mesh.points)
            and np.array_equal(back.mesh.triangles, session.mesh.triangles)):
        return "the mesh"
    if session.routing is not None or session.muscles:  # the page's layout
        want = [tuple(m.nodes) for m in session.muscles]
    else:  # the scene's given muscles (or none)
        want = [tuple(m.nodes) for m in (o.scene.muscles or ())] if o is not None else []
    if [tuple(m.nodes) for m in (back.muscles or ())] != want:
        return "the muscles"
    if back.routing_options.get("fabrication") != d.get("fabrication"):
        return "the fabrication table"
    if o is None:
        return ""
    scene = o.scene
    for c in scene.cases:
        if c.name != edited and c.name not in refused and not _same_case(back.case(c.name), c):
            return f"case {c.name!r} kept as loaded"
    if not refused and (back.gait != scene.gait or back.animations != scene.animations):
        return "the gait or the animations"
    if set(back.regions) != set(scene.regions) or any(
            not np.array_equal(np.unique(back.regions[k]), np.unique(scene.regions[k])) for k in scene.regions):
        return "the regions"
    if (back.units or None) != (scene.units or None):
        return "the units"
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
        out.append(f"muscles {', '.join(str(m.name) for m in scene.muscles)}: kept as loaded until you route")
    if scene.gait is not None:
        out.append(f"gait {scene.gait.name!r} (poses {', '.join(scene.gait.sequence)}): kept as loaded")
    if scene.animations:
        out.append(f"animations {', '.join(a.name for a in scene.animations)}: kept as loaded")
    rest = [k for k, v in (("material", True), ("units", scene.units), ("acceptance", scene.acceptance),
                           ("expected figures", scene.expected), ("title", scene.title)) if v]
    out.append(f"{', '.join(rest)}: kept as loaded")
    return out
