"""Scene files (TOML or JSON): :func:`load_scene`, every field checked and named on error."""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Mapping
import numpy as np

from ..body.mesh import Mesh
from ..body.muscles import Muscle, muscle_name_clash
from ..core.checks import check_label
from ..synthesis.gait import Gait
from .names import check_name, check_output_names
from .fixtures import fixture_radius_conflict
from .reader import SceneFileError, Reader, read_file, scene_options, tname, fabrication_table
from .scene import Animation, Case, Scene, check_acceptance, mesh_polygon, resolve_resolution
from .noderefs import node_ref, scene_region
from .obstacles import read_obstacles
from .select import boundary_path, edge_path
from .shapes import rigid_motion

__all__ = ['load_scene', 'remeshable', 'scene_from_data', 'material_table', 'parse_units_and_gait']


# ---------------------------------------------------------------------------------------------- scene files
_TOP_KEYS = ("name", "title", "description", "body", "material", "regions", "muscles", "routing", "design",
             "cases", "animations", "expected", "units", "gait", "acceptance", "fabrication", "obstacles")


_BODY_KEYS = ("outline", "holes", "mesh", "resolution", "max_area", "min_angle")


_MATERIAL_KEYS = ("model", "E", "nu", "thickness", "plane", "silicone", "C1", "C2", "C3", "C10", "C01",
                  "stress_unit")


_MUSCLE_KEYS = ("name", "nodes", "path", "boundary")


_CASE_KEYS = ("name", "description", "anchors", "drags", "contractions", "muscles", "anchor_radius", "obstacles")


_DRAG_KEYS = ("nodes", "at", "to", "by", "rotate", "about")


_ANIM_KEYS = ("name", "keyframes", "frames_per_step", "fps")


def load_scene(path: str | os.PathLike, resolution: str | int | None = None) -> Scene:
    """Read a scene file (TOML or JSON) into a :class:`Scene`, checking every field.

    This docstring is the one full description of the format: every key a scene file may hold, each
    section shown with its keys (TOML shown; JSON has the same structure)::

        name = "finger"                       # required: letters, digits, _ - .
        title = "A finger bent by its tip"    # optional, as is description
        units = "mm"                          # optional: the length unit of every coordinate (mm, cm, m,
                                              # um, in; none: "body units"), carried into the gait's schedule
                                              # and the fabrication files (SVG, DXF, CSV)

        [body]                                # required: outline (+ holes) or mesh
        outline = [[0, 0], [4, 0], [4, 1], [0, 1]]
        holes = [[[1, 0.4], [1.4, 0.4], [1.4, 0.6]]]
        resolution = "coarse"                 # or a node count; or max_area = 0.02
        min_angle = 30                        # optional: smallest triangle angle, degrees (default 30)
        # mesh = "finger.vtu"                 # a mesh file (any meshio format), relative to this file

        [material]                            # optional: neo-hookean, E = 1, nu = 0.3, thickness = 1
        model = "neo-hookean"                 # or "linear"; "yeoh" (C1, C2, C3), "mooney-rivlin" (C10, C01)
        E = 1.0
        nu = 0.4
        plane = "strain"                      # or "stress": a thin sheet (nu up to 0.5)
        # stress_unit = "Pa"                  # optional: the unit of E (or C1...): tensions then in N
        # silicone = "dragon-skin-30"         # a preset sheet (mdsr_opt.body.silicone; Pa), with thickness

        [regions]                             # named node sets
        base = { box = [-1, -1, 0, 2] }       # [xmin, ymin, xmax, ymax]
        tip = { near = [4, 0.5], radius = 0.3, boundary = true }
        # also: nodes = [...], polygon = [[x, y], ...], loop = 0 (a boundary loop)

        [[muscles]]                           # optional; internal cases need them; given muscles
                                              # also drive external cases without their own (no routing)
        name = "lower"
        boundary = { from = [0, 0], to = [4, 0] }      # or path = [[x, y], ...], or nodes = [...]
                                              # (boundary may add via = [x, y]: which way round the loop)

        [routing]                             # keyword arguments of route_muscles
        max_muscles = 2
        [fabrication]                         # optional: channel, wall and end fixtures, in `units`
        channel_diameter = 0.04               # each default: a fraction of the body's diameter D (channel
        wall = 0.04                           # 1 %, wall 1 %, fixture 4 %, smallest fixture 1.5 %); ropes
        fixture_radius = 0.16                 # lie >= the larger of channel/2 + wall and min_inset_fraction
        min_fixture_radius = 0.06             # times D inside the body (a fraction in [0, 0.5), default 0.02:
        min_inset_fraction = 0.02             # smaller for a slender body); fixture_radius is the design's
                                              # anchor_radius; mdsr run draws each case's and the gait's
                                              # fabrication files with them
        [design]                              # keyword arguments of design_contractions
        a_max = 0.6
        # contact = true                      # self-contact of the outline in every solve (targets, design,
                                              # animations; the design checked with it), optional
                                              # contact_gap = a length
        [[obstacles]]                         # optional: rigid obstacles in every case, at rest coordinates
        disk = { center = [2, -1.2], radius = 0.5 }   # or halfplane = { point = [0, -1], normal = [0, 1] }
        friction = 0.3                        # or polygon = [[x, y], ...] (convex); friction: Coulomb's, one
                                              # for all (default 0), in the targets (the design: frictionless);
                                              # a case's disks get a grip report (held or not at it);
                                              # disk = { ..., free = true }: the target moves it to where the
                                              # contacts' net force vanishes (its solves then frictionless)
        [acceptance]                          # optional: what a case's design must show to succeed
        max_difference = 0.05                 # difference over the body's diameter (default 0.05)
        idle_contraction = 0.001              # muscles designed below it are dropped (default 0.001)
        bands = true                          # strokes' uncertainty bands (default false)

        [[cases]]                             # required: at least one
        name = "bend"
        description = "tip dragged up"        # optional
        anchors = "base"                      # a region, node indices or [x, y] points
        drags = [{ nodes = "tip", by = [-1.0, 1.5] },
                 { at = [4, 0], to = [3, 1.8] }]       # to / by / rotate (degrees) + about
        muscles = [{ name = "upper", path = [[0.3, 0.7], [3.3, 0.7]] }]  # optional: the case's own muscles
                                              # (tables as [[muscles]]), designed (an internal case: driven)
                                              # instead of the scene's [[muscles]] or a routing
        anchor_radius = 0.12                  # optional, with muscles: their end fixtures' radius
                                              # (default: the design's anchor_radius)
        obstacles = [{ halfplane = { point = [0, -2], normal = [0, 1] } }]   # optional: this case's own
        [[cases]]
        name = "contract"
        contractions = [0.3]                  # an internal case: one per muscle

        [[animations]]                        # optional: forward solves between cases, as a GIF
        name = "wave"
        keyframes = [["rest", 0], ["bend", 1], ["rest", 0]]   # [case or "rest", weight]
        frames_per_step = 6                   # optional (default 6), as is fps = 8

        [gait]                                # optional: the cases as poses of ONE shared muscle layout,
        name = "walk"                         # played in a cycle (default name "gait": out/<name>/)
        poses = ["bend", "rest", "contract"]  # required: case names or "rest", in order
        max_muscles = 4                       # optional: the shared layout's muscle budget
        frames_per_step = 6                   # optional (default 6); step_time = 1.0 (seconds per pose),
        cyclic = true                         # fps = 8 (of the GIF) and cyclic (default true) too

        [expected]                            # optional: key figures the scene is known to reach
        n_muscles = 2                         # (copied into summary.json; documentation and tests)

    Node references (``anchors``, a drag's ``nodes``, a region's ``nodes``) are a region name, a list of
    region names, a list of node indices, or a list of ``[x, y]`` points, each snapped to the nearest node
    (which must lie within one mean edge length). A drag moves its nodes ``to`` a point (one node; for
    several, their centroid goes there), ``by`` a displacement, or ``rotate`` (degrees, anticlockwise)
    ``about`` a point (default: their centroid; one node needs one) and then ``by``. Every error names the
    file and the field, e.g.
    ``scene.toml: cases[1].drags[0].by: expected a point [x, y], got [1]``; unknown fields are errors
    (with a suggestion).

    Parameters
    ----------
    path : a ``.toml`` or ``.json`` file.
    resolution : optional
        Meshes the outline at this resolution instead of the file's ``body.resolution`` or ``body.max_area``
        (a mesh study of the scene). A scene whose body is a mesh file keeps its nodes: a resolution is
        refused for it (:func:`remeshable` tells beforehand).

    Raises
    ------
    FileNotFoundError
        The file (or its mesh file) does not exist.
    SceneFileError (a ValueError), TypeError
        A malformed file.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no such scene file: {path}")
    if path.is_dir():
        raise SceneFileError(f"{path} is a folder, not a scene file (a .toml or .json file)")
    try:
        data = read_file(path)
    except PermissionError:
        raise SceneFileError(f"{path}: cannot read the scene file (permission denied)") from None
    return scene_from_data(path, data, resolution)


def remeshable(path: str | os.PathLike) -> bool:
    """Whether the scene file ``path`` gives its body as an outline, which :func:`load_scene` meshes at any
    resolution (False: a mesh file, whose nodes are given). Raises as :func:`load_scene` for an unreadable
    file."""
    data = read_file(Path(path))
    body = data.get("body") if isinstance(data, Mapping) else None
    return not (isinstance(body, Mapping) and "mesh" in body)


def scene_from_data(path: Path, data: dict, resolution: str | int | None = None) -> Scene:
    """:func:`load_scene` of the scene file ``path`` already parsed by
    :func:`~mdsr_opt.scenes.reader.read_file` into ``data`` (so a caller that looked into the file reads it
    once); ``path`` names the file in messages and locates its mesh file."""
    path = Path(path)
    r = Reader(path)
    top = r.keys(data, _TOP_KEYS, "", required=("name", "body", "cases"))
    name = r.string(top["name"], "name")
    try:
        check_name(name, "name")
    except ValueError as exc:
        r.fail("name", str(exc))
    mesh, res_used = _scene_mesh(r, top["body"], path, resolution)
    material = _scene_material(r, top.get("material", {}))
    regions: dict[str, np.ndarray] = {}
    reg_in = top.get("regions", {})
    r.keys(reg_in, list(reg_in) if isinstance(reg_in, Mapping) else (), "regions")
    for rname, spec in reg_in.items():
        regions[rname] = scene_region(r, mesh, spec, f"regions.{rname}", regions)
    muscles = _muscle_list(r, mesh, top["muscles"], "muscles", regions) if "muscles" in top else None
    routing = scene_options(r, top.get("routing", {}), "routing")
    if "fabrication" in top:  # the [fabrication] table: the routing's (and, through it, the design's)
        if "fabrication" in routing:
            r.fail("fabrication", "is given twice: as [fabrication] and as routing.fabrication; keep one")
        routing["fabrication"] = fabrication_table(r, top["fabrication"], "fabrication")
    design = scene_options(r, top.get("design", {}), "design")
    obstacles, friction = read_obstacles(r, top["obstacles"], "obstacles") if "obstacles" in top else ((), None)
    cases_in = top["cases"]
    if not isinstance(cases_in, list) or not cases_in:
        r.fail("cases", "expected a non-empty list of cases ([[cases]] tables)",
               TypeError if not isinstance(cases_in, list) else SceneFileError)
    cases = []
    seen = set()
    for i, c in enumerate(cases_in):
        case = _scene_case(r, mesh, c, f"cases[{i}]", regions, muscles)
        if case.name in seen:
            r.fail(f"cases[{i}].name", f"{case.name!r} is used by an earlier case")
        seen.add(case.name)
        cases.append(case)
    anims = []
    for i, a in enumerate(top.get("animations", []) if isinstance(top.get("animations", []), list)
                          else r.fail("animations", "expected a list of animations", TypeError)):
        anims.append(_scene_animation(r, a, f"animations[{i}]", seen))
    check_output_names([c.name for c in cases], [a.name for a in anims], path.name,
                       [f"cases[{i}].name" for i in range(len(cases))]
                       + [f"animations[{i}].name" for i in range(len(anims))])
    units, gait = parse_units_and_gait(r, top, seen)  # issue 16
    expected = top.get("expected", {})
    if not isinstance(expected, Mapping):
        r.fail("expected", f"expected a table, got {tname(expected)}", TypeError)
    fab_field = "fabrication" if "fabrication" in top else "routing.fabrication"
    conflict = fixture_radius_conflict(  # one end-fixture size: [design] anchor_radius IS fixture_radius
        design.get("anchor_radius"), routing, {i: c.anchor_radius for i, c in enumerate(cases)},
        {"design": "design.anchor_radius", "fixture": f"{fab_field}.fixture_radius",
         "min": f"{fab_field}.min_fixture_radius", "case": "cases[{}].anchor_radius"})
    if conflict:
        r.fail(*conflict)
    acceptance = top.get("acceptance", {})
    try:
        acceptance = check_acceptance(dict(acceptance) if isinstance(acceptance, Mapping) else acceptance,
                                      f"{path.name}: acceptance", a_max=design.get("a_max"))
    except ValueError as exc:
        raise SceneFileError(str(exc)) from None
    try:
        return Scene(name=name, mesh=mesh, material=material, cases=tuple(cases),
                     title=str(top.get("title", "")), description=str(top.get("description", "")),
                     muscles=muscles, regions=regions, routing_options=routing, design_options=design,
                     animations=tuple(anims), expected=dict(expected), resolution=res_used, source=str(path),
                     units=units, gait=gait, acceptance=acceptance, obstacles=tuple(obstacles), friction=friction)
    except (ValueError, TypeError) as exc:  # cross-field checks of Scene (contraction counts...)
        raise SceneFileError(f"{path.name}: {exc}") from None


def _scene_mesh(r: Reader, body, path: Path, resolution) -> tuple[Mesh, int]:
    b = r.keys(body, _BODY_KEYS, "body")
    if ("outline" in b) == ("mesh" in b):
        r.fail("body", "give exactly one of outline (a polygon) and mesh (a mesh file)")
    if "mesh" in b:
        for k in ("holes", "resolution", "max_area", "min_angle"):
            if k in b:
                r.fail(f"body.{k}", "only applies to an outline, not to a mesh file")
        if resolution is not None:
            r.fail("body.mesh", f"the body is a mesh file with its own nodes: resolution {resolution!r} cannot "
                               "re-mesh it (leave the resolution out, or give body.outline)")
        from ..body.io import read_mesh

        mpath = path.parent / r.string(b["mesh"], "body.mesh")
        if not mpath.exists():
            raise FileNotFoundError(f"{path.name}: body.mesh: no such mesh file: {mpath}")
        try:
            return read_mesh(mpath).mesh, 0
        except ValueError as exc:
            r.fail("body.mesh", str(exc))
    outline = r.points(b["outline"], "body.outline", at_least=3)
    holes_in = b.get("holes", [])
    if not isinstance(holes_in, list):
        r.fail("body.holes", f"expected a list of polygons, got {tname(holes_in)}", TypeError)
    holes = [r.points(h, f"body.holes[{i}]", at_least=3) for i, h in enumerate(holes_in)]
    min_angle = r.number(b.get("min_angle", 30.0), "body.min_angle", positive=True)
    if "max_area" in b and "resolution" in b:
        r.fail("body", "give max_area or resolution, not both")
    try:
        if "max_area" in b and resolution is None:  # a resolution asked for re-meshes (a mesh study)
            return Mesh.from_polygon(outline, max_area=r.number(b["max_area"], "body.max_area", positive=True),
                                     holes=holes, min_angle=min_angle), 0
        res = resolution if resolution is not None else b.get("resolution", "medium")
        try:
            n = resolve_resolution(res)
        except (ValueError, TypeError) as exc:
            r.fail("body.resolution", str(exc), type(exc) if isinstance(exc, TypeError) else SceneFileError)
        return mesh_polygon(outline, holes, resolution=n, min_angle=min_angle), n
    except SceneFileError:
        raise
    except ValueError as exc:  # self-intersecting outline, hole outside, ...
        r.fail("body.outline" if "holes" not in str(exc) else "body.holes", str(exc))


def material_table(material) -> dict:
    """The ``[material]`` table of a scene file that reads back as ``material`` (the inverse of the reader)."""
    from ..body.material import LinearElastic, MooneyRivlin, NeoHookean, Yeoh

    t = float(material.thickness)
    su = {"stress_unit": material.stress_unit} if getattr(material, "stress_unit", None) else {}
    if isinstance(material, Yeoh):
        return {"model": "yeoh", "C1": material.C1, "C2": material.C2, "C3": material.C3, "thickness": t, **su}
    if isinstance(material, MooneyRivlin):
        return {"model": "mooney-rivlin", "C10": material.C10, "C01": material.C01, "thickness": t, **su}
    if isinstance(material, (NeoHookean, LinearElastic)):
        return {"model": "linear" if isinstance(material, LinearElastic) else "neo-hookean",
                "E": float(material.E), "nu": float(material.nu), "thickness": t, "plane": material.plane, **su}
    raise TypeError(f"a scene file cannot hold a {type(material).__name__} material")


def _scene_material(r: Reader, spec):
    from ..body.material import LinearElastic, MooneyRivlin, NeoHookean, Yeoh
    from ..body.silicone import silicone

    m = r.keys(spec, _MATERIAL_KEYS, "material")
    kinds = {"neo-hookean": NeoHookean, "neohookean": NeoHookean, "linear": LinearElastic, "yeoh": Yeoh,
             "mooney-rivlin": MooneyRivlin}
    own = {NeoHookean: ("E", "nu", "thickness", "plane"), LinearElastic: ("E", "nu", "thickness", "plane"),
           Yeoh: ("C1", "C2", "C3", "thickness"), MooneyRivlin: ("C10", "C01", "thickness")}
    if "silicone" in m:
        extra = sorted(set(m) - {"silicone", "thickness", "model"})
        if extra:
            r.fail(f"material.{extra[0]}", "a silicone preset takes only a thickness (and model = 'yeoh' or "
                   "'neo-hookean')")
        law = m.get("model", "yeoh")
        thickness = r.number(m.get("thickness", 1.0), "material.thickness")  # its own error: named once
        try:
            return silicone(m["silicone"], thickness, law=law if law != "neohookean" else "neo-hookean")
        except (TypeError, ValueError) as exc:
            field_ = "model" if str(exc).startswith("law") else "silicone"
            r.fail(f"material.{field_}", str(exc), type(exc) if isinstance(exc, TypeError) else SceneFileError)
    model = m.get("model", "neo-hookean")
    if model not in kinds:
        r.fail("material.model", f"unknown material {model!r} (choose 'neo-hookean', 'linear', 'yeoh' or "
                                 f"'mooney-rivlin')")
    cls = kinds[model]
    extra = sorted(set(m) - set(own[cls]) - {"model", "stress_unit"})
    if extra:
        r.fail(f"material.{extra[0]}", f"not a parameter of a {model} material (it takes "
                                       f"{', '.join(own[cls])})")
    vals = {k: r.number(m[k], f"material.{k}") for k in own[cls] if k in m and k != "plane"}
    su = m.get("stress_unit")
    try:
        if cls in (NeoHookean, LinearElastic):
            return cls(vals.get("E", 1.0), vals.get("nu", 0.3), vals.get("thickness", 1.0),
                       m.get("plane", "strain"), stress_unit=su)
        if cls is Yeoh:
            if "C1" not in vals:
                r.fail("material.C1", "a yeoh material needs C1")
            return Yeoh(vals["C1"], vals.get("C2", 0.0), vals.get("C3", 0.0), vals.get("thickness", 1.0),
                        stress_unit=su)
        if "C10" not in vals:
            r.fail("material.C10", "a mooney-rivlin material needs C10")
        return MooneyRivlin(vals["C10"], vals.get("C01", 0.0), vals.get("thickness", 1.0), stress_unit=su)
    except SceneFileError:  # a field's own error (C1 missing...) names the file and the field once
        raise
    except (TypeError, ValueError) as exc:
        field_ = next((k for k in (*own[cls], "C10 + C01", "unknown stress_unit") if str(exc).startswith(k)), "")
        field_ = "stress_unit" if field_ == "unknown stress_unit" else field_
        field_ = "C10" if field_ == "C10 + C01" else field_
        r.fail(f"material.{field_}" if field_ else "material", str(exc),
               TypeError if isinstance(exc, TypeError) else SceneFileError)


def _muscle_list(r: Reader, mesh: Mesh, v, where: str, regions: dict) -> tuple:
    """The muscles of a ``muscles`` list (the scene's ``[[muscles]]`` or a case's own)."""
    if not isinstance(v, list):
        r.fail(where, f"expected a list of muscles ([[muscles]] tables), got {tname(v)}", TypeError)
    out = tuple(_scene_muscle(r, mesh, m, f"{where}[{i}]", regions) for i, m in enumerate(v))
    clash = muscle_name_clash(out)
    if clash:
        name, i, j = clash
        named = isinstance(v[j], Mapping) and "name" in v[j]
        r.fail(f"{where}[{j}].name" if named else f"{where}[{j}]",
               f"muscle name {name!r} is used twice, by {where}[{i}] and {where}[{j}]"
               + ("" if named and isinstance(v[i], Mapping) and "name" in v[i] else
                  " (an unnamed muscle is called by its place: M1, M2 ...)")
               + ": every table, figure and file names a muscle by it; give each its own name")
    return out


def _scene_muscle(r: Reader, mesh: Mesh, spec, where: str, regions: dict) -> Muscle:
    m = r.keys(spec, _MUSCLE_KEYS, where)
    sel = [k for k in ("nodes", "path", "boundary") if k in m]
    if len(sel) != 1:
        r.fail(where, "give exactly one of nodes (indices), path (waypoints) and boundary ({from, to, via})")
    name = r.string(m["name"], f"{where}.name") if "name" in m else None
    if name is not None:
        try:
            check_label(name, "muscle name")
        except ValueError as exc:
            r.fail(f"{where}.name", str(exc))
    try:
        if "nodes" in m:
            v = m["nodes"]
            if not isinstance(v, list):
                r.fail(f"{where}.nodes", "expected a list of node indices", TypeError)
            for j, i in enumerate(v):
                r.integer(i, f"{where}.nodes[{j}]", None)  # the range: the muscle's own check, which names it
            mus = Muscle(tuple(v), name=name)
            mus.check_on(mesh)
            return mus
        if "path" in m:
            return edge_path(mesh, r.points(m["path"], f"{where}.path", at_least=2), name=name)
        b = r.keys(m["boundary"], ("from", "to", "via"), f"{where}.boundary", required=("from", "to"))
        via = r.point(b["via"], f"{where}.boundary.via") if "via" in b else None
        return boundary_path(mesh, r.point(b["from"], f"{where}.boundary.from"),
                             r.point(b["to"], f"{where}.boundary.to"), via=via, name=name)
    except SceneFileError:
        raise
    except ValueError as exc:
        r.fail(f"{where}.{sel[0]}", str(exc))


def _scene_case(r: Reader, mesh: Mesh, spec, where: str, regions: dict, muscles) -> Case:
    c = r.keys(spec, _CASE_KEYS, where, required=("name",))
    name = r.string(c["name"], f"{where}.name")
    try:
        check_name(name, "case name")
    except ValueError as exc:
        r.fail(f"{where}.name", str(exc))
    desc = str(c.get("description", ""))
    obs, mu = read_obstacles(r, c["obstacles"], f"{where}.obstacles") if "obstacles" in c else ((), None)
    own, radius = _case_muscles(r, mesh, c, where, regions)
    if "contractions" in c:
        for k in ("anchors", "drags"):
            if k in c:
                r.fail(f"{where}.{k}", "an internal case (with contractions) has no anchors or drags: it drives "
                       "the scene's [[muscles]] (or its own muscles), one contraction each")
        v = c["contractions"]
        if not isinstance(v, list):
            r.fail(f"{where}.contractions", f"expected a list of numbers, got {tname(v)}", TypeError)
        a = [r.number(x, f"{where}.contractions[{i}]") for i, x in enumerate(v)]
        driven = own if own is not None else muscles
        if driven is None:
            r.fail(f"{where}.contractions", "an internal case needs muscles ([[muscles]], or its own muscles)")
        if len(a) != len(driven):
            r.fail(f"{where}.contractions", f"needs one value per muscle ({len(driven)}), got {len(a)}")
        for i, x in enumerate(a):
            if not 0.0 <= x < 1.0:
                r.fail(f"{where}.contractions[{i}]", f"must lie in [0, 1), got {x}")
        return Case(name, contractions=a, description=desc, muscles=own, anchor_radius=radius, obstacles=obs,
                    friction=mu)
    # anchors = [] is no anchor, as the key left out (the drags then hold the body)
    anchors = node_ref(r, mesh, c.get("anchors", []), f"{where}.anchors", regions, empty=True)
    drags_in = c.get("drags", [])
    if not isinstance(drags_in, list):
        r.fail(f"{where}.drags", f"expected a list of drags, got {tname(drags_in)}", TypeError)
    nodes, pos = [], []
    for i, d in enumerate(drags_in):
        idx, p = _scene_drag(r, mesh, d, f"{where}.drags[{i}]", regions)
        nodes.append(idx)
        pos.append(p)
    dn = np.concatenate(nodes) if nodes else np.zeros(0, dtype=np.int64)
    dp = np.vstack(pos) if pos else np.zeros((0, 2))
    if len(np.unique(dn)) != len(dn):
        vals, counts = np.unique(dn, return_counts=True)
        r.fail(f"{where}.drags", f"node {int(vals[counts > 1][0])} is dragged twice")
    both = np.intersect1d(anchors, dn)
    if len(both):
        r.fail(where, f"node {int(both[0])} is both anchored and dragged")
    if len(anchors) + len(dn) < 2:
        r.fail(where, "an external case needs at least two fixed nodes (anchors + drags); an internal case "
               "needs contractions")
    return Case(name, anchors=anchors, drag_nodes=dn, drag_positions=dp, description=desc, muscles=own,
                anchor_radius=radius, obstacles=obs, friction=mu)


def _case_muscles(r: Reader, mesh: Mesh, c: dict, where: str, regions: dict):
    """A case's own ``muscles`` (None: not given) and their ``anchor_radius`` (None: not given)."""
    own = None
    if "muscles" in c:  # this case's own layout: the scene's [[muscles]] (or a routing) drive the others
        own = _muscle_list(r, mesh, c["muscles"], f"{where}.muscles", regions)
        if not own:
            r.fail(f"{where}.muscles", "is empty: give at least one muscle, or leave the key out (the scene's "
                   "[[muscles]] then drive this case, or its muscles are routed)")
    radius = None
    if "anchor_radius" in c:
        if own is None:
            r.fail(f"{where}.anchor_radius", "is the end-fixture radius of the case's own muscles: give muscles "
                   "too (or set design.anchor_radius for every case)")
        radius = r.number(c["anchor_radius"], f"{where}.anchor_radius")
        if radius < 0:
            r.fail(f"{where}.anchor_radius", f"must be >= 0, got {radius:g}")
    return own, radius


def _scene_drag(r: Reader, mesh: Mesh, spec, where: str, regions: dict) -> tuple[np.ndarray, np.ndarray]:
    d = r.keys(spec, _DRAG_KEYS, where)
    if ("nodes" in d) == ("at" in d):
        r.fail(where, "give exactly one of nodes (region, indices or points) and at (a point)")
    idx = (node_ref(r, mesh, d["nodes"], f"{where}.nodes", regions) if "nodes" in d
           else node_ref(r, mesh, [d["at"]], f"{where}.at", regions))
    P = mesh.points[idx]
    if "to" in d:
        for k in ("by", "rotate", "about"):
            if k in d:
                r.fail(f"{where}.{k}", "cannot be combined with to")
        return idx, P - P.mean(0) + r.point(d["to"], f"{where}.to")
    if "by" not in d and "rotate" not in d:
        r.fail(where, "say where the nodes go: to (a point), by (a displacement) or rotate (+ about)")
    if "about" in d and "rotate" not in d:
        r.fail(f"{where}.about", "only applies with rotate")
    if "rotate" in d and "about" not in d and len(np.unique(idx)) == 1:
        r.fail(f"{where}.rotate", "turns one node about itself, which moves nothing: give about (the point "
                                  "to turn it around)" + (", or leave rotate out (by alone moves it)" if "by" in d
                                                          else ", or by"))
    ang = math.radians(r.number(d["rotate"], f"{where}.rotate")) if "rotate" in d else 0.0
    about = r.point(d["about"], f"{where}.about") if "about" in d else P.mean(0)
    shift = r.point(d["by"], f"{where}.by") if "by" in d else np.zeros(2)
    return idx, rigid_motion(P, ang, about, shift)


def _scene_animation(r: Reader, spec, where: str, case_names: set) -> Animation:
    a = r.keys(spec, _ANIM_KEYS, where, required=("name", "keyframes"))
    kf = a["keyframes"]
    if not isinstance(kf, list):
        r.fail(f"{where}.keyframes", f"expected a list of [case, fraction] pairs, got {tname(kf)}", TypeError)
    pairs = []
    for i, k in enumerate(kf):
        w = f"{where}.keyframes[{i}]"
        if not isinstance(k, list) or len(k) != 2 or not isinstance(k[0], str):
            r.fail(w, f"expected [case name, fraction], got {k!r}")
        if k[0] != "rest" and k[0] not in case_names:
            r.fail(w, f"unknown case {k[0]!r} (cases: {', '.join(sorted(case_names))}, or 'rest')")
        pairs.append((k[0], r.number(k[1], f"{w}[1]")))
    steps = r.integer(a.get("frames_per_step", 6), f"{where}.frames_per_step", 1)
    name = r.string(a["name"], f"{where}.name")  # each field's own error names the file and field once
    fps = r.number(a.get("fps", 8.0), f"{where}.fps", positive=True)
    try:
        return Animation(name, tuple(pairs), frames_per_step=steps, fps=fps)
    except ValueError as exc:
        r.fail(where, str(exc))


# ---------------------------------------------------------------------------------------------- issue 16: units, gait
_GAIT_KEYS = ("name", "poses", "frames_per_step", "max_muscles", "step_time", "cyclic", "fps")


def parse_units_and_gait(r: Reader, top: Mapping, case_names: set):
    """The scene file's ``units = "mm"`` and ``[gait]`` table (``name``, ``poses`` = case names or "rest",
    ``frames_per_step``, ``max_muscles``, ``step_time``, ``cyclic``, ``fps``)."""
    from ..synthesis.export import UNITS

    units = top.get("units")  # none given: body units (no unit is invented)
    if units is not None and (not isinstance(units, str) or units not in UNITS):
        r.fail("units", f"unknown units {units!r}: expected one of {', '.join(UNITS)}")
    if "gait" not in top:
        return units, None
    g = r.keys(top["gait"], _GAIT_KEYS, "gait", required=("poses",))
    poses = g["poses"]
    if not isinstance(poses, list) or not poses or not all(isinstance(p, str) for p in poses):
        r.fail("gait.poses", f"expected a non-empty list of case names, got {poses!r}")
    for i, p in enumerate(poses):
        if p != "rest" and p not in case_names:
            r.fail(f"gait.poses[{i}]", f"unknown case {p!r} (cases: {', '.join(sorted(case_names))}, or 'rest')")
    for key in ("frames_per_step", "max_muscles"):
        if g.get(key) is not None:
            r.integer(g[key], f"gait.{key}", 1)
    if not isinstance(g.get("cyclic", True), bool):
        r.fail("gait.cyclic", f"expected true or false, got {g['cyclic']!r}")
    name = r.string(g.get("name", "gait"), "gait.name")  # each field's own error names file and field once
    step_time = r.number(g.get("step_time", 1.0), "gait.step_time", positive=True)
    fps = r.number(g.get("fps", 8.0), "gait.fps", positive=True)
    try:
        return units, Gait(name, tuple(poses), frames_per_step=g.get("frames_per_step", 6),
                           max_muscles=g.get("max_muscles"), step_time=step_time, cyclic=g.get("cyclic", True),
                           fps=fps)
    except (ValueError, TypeError) as exc:
        r.fail("gait", str(exc))
