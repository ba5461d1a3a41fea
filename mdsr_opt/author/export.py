"""Saving an authoring session: a scene file ``mdsr run`` reproduces, figures, meshes and results.

The scene file is JSON in the format :func:`~mdsr_opt.load_scene` reads. Its body is the session's mesh,
written next to it as ``<name>.mesh.vtu`` (binary float64, so the nodes and their numbering come back
exactly and node ids stay valid); the edited case keeps its name, its anchors are node ids and each drag
is one node moved ``to`` its exact position; every part of the scene opened that the page does not edit
is kept (:mod:`.roundtrip`: the other cases, regions, gait, animations, material...); routed muscles are
the edited case's own ``muscles``, node lists without the ones the user deleted (so ``mdsr run`` designs
that case with them instead of routing again, and the other cases as before);
routing and design options are the ones the page used, the muscle model written out so a changed default
cannot change the result; the channel, wall and fixture sizes are the ``[fabrication]`` table, and the
design's ``anchor_radius`` is the fixture radius the ropes were fitted to.
"""

from __future__ import annotations

import io
import os
import tempfile
import zipfile
from pathlib import Path

from ..body.io import write_json, write_mesh
from .roundtrip import check_read_back, scene_file

__all__ = ["save_scene", "download", "DOWNLOADS", "WouldReplace"]

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


class WouldReplace(FileExistsError):
    """:func:`save_scene` would replace files it was not allowed to (``paths``); nothing was written."""

    def __init__(self, paths):
        self.paths = [os.fspath(p) for p in paths]
        super().__init__(f"{', '.join(self.paths)} already exist{'s' if len(self.paths) == 1 else ''}")


def save_scene(session, out, name: str | None = None, *, overwrite=True, notes: list | None = None) -> list[str]:
    """Write ``<name>.json`` and ``<name>.mesh.vtu`` into the folder ``out`` (created); returns the two
    paths.

    The file keeps every part of the scene the session opened that the page does not edit
    (:mod:`.roundtrip`); the muscles routed on the page are the edited case's own. ``notes``: a list that
    receives what the save changes for the cases the page did not edit (design settings or channel sizes
    set on the page, which are the scene's).

    ``overwrite``: ``True`` replaces existing files; ``False``, or a function of a path returning whether
    that existing file may be replaced, raises :class:`WouldReplace` (before anything is written) for the
    existing files it may not replace.

    Both files are written in a scratch folder, read back there with :func:`~mdsr_opt.load_scene` and
    compared with the session and the scene it opened (mesh, cases, muscles, fabrication, regions, gait,
    animations), and only then moved into ``out``: a scene ``load_scene`` refuses (an edit it does not accept)
    raises ``ValueError``, a mismatch ``RuntimeError``, and neither leaves a file.
    """
    from ..scenes.names import check_name
    from ..scenes.scenefile import load_scene

    if len(session.anchors) + len(session.drag_nodes) < 2:
        raise ValueError("nothing to save yet: a scene's case needs at least two fixed nodes (anchors and drags)")
    name = name or session.name
    check_name(name, "scene name")  # letters, digits, _ - . (it names the files)
    folder = Path(out)
    mesh_path = folder / f"{name}.mesh.vtu"
    scene_path = folder / f"{name}.json"
    d, said = scene_file(session, name, mesh_path.name)
    if overwrite is not True:
        keep = [p for p in (scene_path, mesh_path) if p.exists() and not (overwrite and overwrite(p))]
        if keep:
            raise WouldReplace(keep)
    folder.mkdir(parents=True, exist_ok=True)
    # written and read back in a scratch folder beside the targets, moved into place only when it reads back:
    # a scene mdsr run would refuse leaves no file behind
    with tempfile.TemporaryDirectory(prefix=".mdsr-save-", dir=folder) as scratch:
        tmp_scene, tmp_mesh = Path(scratch) / scene_path.name, Path(scratch) / mesh_path.name
        write_mesh(tmp_mesh, session.mesh)
        write_json(tmp_scene, d)
        try:
            back = load_scene(tmp_scene)
        except (ValueError, TypeError) as exc:  # e.g. drags a contact scene refuses: the edit, not a bug
            raise ValueError(f"not saved: as edited, {name} would not load: "
                             f"{str(exc).replace(str(tmp_scene), scene_path.name)}") from None
        wrong = check_read_back(back, session, d)
        if wrong:
            raise RuntimeError(f"{scene_path} does not read back as the session: {wrong} (please report this)")
        os.replace(tmp_mesh, mesh_path)
        os.replace(tmp_scene, scene_path)
    if notes is not None:
        notes.extend(said)
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
        save_figure(fig, path, close=True)  # the server runs for hours: no figure kept open
    return path.read_bytes(), "image/png" if what.endswith(".png") else "application/octet-stream"
