"""Saving an authoring session: a scene file ``mdsr run`` reproduces, figures, meshes and results.

The scene file is JSON in the format :func:`~mdsr_opt.load_scene` reads. Its body is the session's mesh,
written next to it as ``<name>.mesh.vtu`` (binary float64, so the nodes and their numbering come back
exactly and node ids stay valid); anchors are node ids; each drag is one node moved ``to`` its exact
position; routed muscles are node lists, without the ones the user deleted (so ``mdsr run`` uses them
instead of routing again); routing and design options are the ones the page used, the muscle model written
out so a changed default cannot change the result; the channel, wall and fixture sizes are the
``[fabrication]`` table, and the design's ``anchor_radius`` is the fixture radius the ropes were fitted to.
"""

from __future__ import annotations

import io
import os
import re
import zipfile
from pathlib import Path

import numpy as np

from ..body.io import write_json, write_mesh

__all__ = ["scene_dict", "save_scene", "download", "DOWNLOADS", "WouldReplace"]

#: What the page can download: file name -> description.
DOWNLOADS = {
    "scene.zip": "the scene file and its mesh (run with mdsr run)",
    "target.png": "the target with anchors and drags",
    "graph.png": "the contraction graph of the target",
    "muscles.png": "the routed muscles",
    "design.png": "the driven state over the target",
    "target.vtu": "the target as a mesh (displacements)",
    "driven.vtu": "the designed, driven state as a mesh",
    "results.json": "anchors, drags, target, muscles and design as numbers",
}


def scene_dict(session, name: str, mesh_file: str) -> dict:
    """The scene file's content for ``session`` (body = ``mesh_file``, one external case ``authored``)."""
    from ..scenes.scenefile import material_table

    mat = session.material
    d = {
        "name": name,
        "title": f"{name}: authored with mdsr author",
        # the file's name alone: a scene file holds no path of the machine it was saved on
        "description": f"Authored on the mdsr author page from {_file_name(session.source) or session.name}.",
        "body": {"mesh": mesh_file},
        "material": material_table(mat),
    }
    if session.units:
        d["units"] = session.units
    if session.acceptance:
        d["acceptance"] = {k: _plain(v) for k, v in session.acceptance.items()}
    if session.muscles:
        d["muscles"] = [{"name": m.name or f"m{i}", "nodes": [int(v) for v in m.nodes]}
                        for i, m in enumerate(session.muscles)]
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
    case = {"name": "authored", "description": "anchors and drags set on the page"}
    if len(session.anchors):
        case["anchors"] = [int(v) for v in session.anchors]
    if len(session.drag_nodes):
        case["drags"] = [{"nodes": [int(i)], "to": [float(p[0]), float(p[1])]}
                         for i, p in zip(session.drag_nodes, session.drag_positions)]
    d["cases"] = [case]
    return d


class WouldReplace(FileExistsError):
    """:func:`save_scene` would replace files it was not allowed to (``paths``); nothing was written."""

    def __init__(self, paths):
        self.paths = [os.fspath(p) for p in paths]
        super().__init__(f"{', '.join(self.paths)} already exist{'s' if len(self.paths) == 1 else ''}")


def _file_name(source) -> str:
    """The last part of a path (``/``- or ``\\``-separated, whichever platform wrote it): no folder."""
    return re.split(r"[\\/]", str(source or "").rstrip("\\/"))[-1]


def _plain(v):
    if isinstance(v, (np.floating, np.integer, np.bool_)):
        return v.item()
    return v


def save_scene(session, out, name: str | None = None, *, overwrite=True) -> list[str]:
    """Write ``<name>.json`` and ``<name>.mesh.vtu`` into the folder ``out`` (created); returns the two
    paths.

    ``overwrite``: ``True`` replaces existing files; ``False``, or a function of a path returning whether
    that existing file may be replaced, raises :class:`WouldReplace` (before anything is written) for the
    existing files it may not replace.

    The file is read back with :func:`~mdsr_opt.load_scene` and compared with the session (mesh, anchors,
    drags, muscles); a mismatch raises ``RuntimeError`` rather than leaving a scene that would not
    reproduce the page.
    """
    from ..scenes.scenefile import load_scene

    if len(session.anchors) + len(session.drag_nodes) < 2:
        raise ValueError("nothing to save yet: a scene's case needs at least two fixed nodes (anchors and drags)")
    name = name or session.name
    from ..scenes.scene import Case  # name check: letters, digits, _ - .

    Case(name, anchors=[0, 1])
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    mesh_path = folder / f"{name}.mesh.vtu"
    scene_path = folder / f"{name}.json"
    if overwrite is not True:
        keep = [p for p in (scene_path, mesh_path) if p.exists() and not (overwrite and overwrite(p))]
        if keep:
            raise WouldReplace(keep)
    write_mesh(mesh_path, session.mesh)
    write_json(scene_path, scene_dict(session, name, mesh_path.name))
    back = load_scene(scene_path)
    case = back.cases[0]
    same = (np.array_equal(back.mesh.points, session.mesh.points)
            and np.array_equal(back.mesh.triangles, session.mesh.triangles)
            and np.array_equal(np.sort(case.anchors), np.sort(session.anchors))
            and np.array_equal(case.drag_nodes, session.drag_nodes)
            and np.array_equal(case.drag_positions, session.drag_positions)
            and [tuple(m.nodes) for m in (back.muscles or ())] == [tuple(m.nodes) for m in session.muscles]
            and back.routing_options.get("fabrication") == scene_dict(session, name, "")
            .get("fabrication"))
    if not same:
        raise RuntimeError(f"{scene_path} does not read back as the session (please report this)")
    return [os.fspath(scene_path), os.fspath(mesh_path)]


def results_dict(session) -> dict:
    """Anchors, drags, the shown state, the target, muscles and the design as JSON-ready numbers."""
    d = {"format": "mdsr_opt.author_results/1", "name": session.name, "n_nodes": session.n_nodes,
         "anchors": session.anchors.tolist(), "drag_nodes": session.drag_nodes.tolist(),
         "drag_positions": session.drag_positions.tolist(),
         "state": None if session.state is None else {k: v for k, v in session.state.to_dict().items()},
         "target": None if session.target is None else session.target.tolist(),
         "muscles": [[int(v) for v in m.nodes] for m in session.muscles]}
    if session.design is not None:
        d["design"] = session.design_summary()
    return d


def download(session, what: str, tmpdir) -> tuple[bytes, str]:
    """The bytes and media type of one download (see :data:`DOWNLOADS`); ValueError when not available yet."""
    from ..plot.common import save_figure
    from ..plot.design import plot_contraction_graph, plot_design, plot_routing
    from ..plot.scenes import plot_target

    if what not in DOWNLOADS:
        raise ValueError(f"unknown download {what!r} (choose from {', '.join(DOWNLOADS)})")
    tmp = Path(tmpdir)
    mesh, x = session.mesh, session.target
    if what == "scene.zip":
        files = save_scene(session, tmp / "scene")
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
            for f in files:
                z.write(f, Path(f).name)
        return buf.getvalue(), "application/zip"
    if what == "results.json":
        path = write_json(tmp / "results.json", results_dict(session))
        return Path(path).read_bytes(), "application/json"
    if what == "driven.vtu" or what == "design.png":
        if session.design is None:
            raise ValueError(f"{what}: no design yet")
    elif x is None:
        raise ValueError(f"{what}: no settled target yet")
    path = tmp / what
    units = session.units or None  # the figures' axes: the scene's unit, else "body units"
    if what == "target.vtu":
        write_mesh(path, mesh, x=x, material=session.material)
    elif what == "driven.vtu":
        write_mesh(path, mesh, x=session.design.x_aligned, material=session.material)
    else:
        if what == "target.png":
            fig = plot_target(mesh, x, anchors=session.anchors, drag_nodes=session.drag_nodes,
                              drag_positions=session.drag_positions if len(session.drag_nodes) else None,
                              title=f"{session.name}: target", units=units)
        elif what == "graph.png":
            fig = plot_contraction_graph(mesh, x, units=units)
        elif what == "muscles.png":
            if not session.muscles:
                raise ValueError("muscles.png: no muscles yet")
            fig = plot_routing(mesh, x, session.muscles, units=units)
        else:
            fig = plot_design(mesh, session.design, x, session.muscles, units=units)
        save_figure(fig, path)
    return path.read_bytes(), "image/png" if what.endswith(".png") else "application/octet-stream"
