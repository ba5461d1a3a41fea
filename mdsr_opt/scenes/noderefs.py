"""How a scene file names nodes: by a region name, node indices or [x, y] points (:func:`node_ref`, for a
case's ``anchors``, a drag's ``nodes`` or ``at``, a region's ``nodes``), and its ``[regions]`` entries
(:func:`scene_region`). Every mistake is a :class:`~mdsr_opt.scenes.reader.SceneFileError` (or TypeError)
naming the file and the field."""

from __future__ import annotations

import numpy as np

from ..body.mesh import Mesh
from .reader import Reader, tname
from .select import nearest_node, nodes_in_box, nodes_in_polygon, nodes_near

__all__ = ["REGION_KEYS", "node_ref", "scene_region"]

#: the keys of a ``[regions]`` entry
REGION_KEYS = ("nodes", "box", "near", "radius", "polygon", "boundary", "loop")


def node_ref(r: Reader, mesh: Mesh, v, where: str, regions: dict, empty: bool = False) -> np.ndarray:
    """A region name, region names, node indices or [x, y] points -> node indices (sorted, each once).

    ``empty``: an empty list names no node (a case's ``anchors = []``, as the key left out); else it is
    refused, saying so (a drag or a region of no node does nothing)."""
    tol = float(mesh.edge_lengths.mean())
    if isinstance(v, str):
        v = [v]
    if not isinstance(v, list):
        r.fail(where, f"expected a region name, node indices or [x, y] points, got {v!r}", TypeError)
    if not v and not empty:
        r.fail(where, "is an empty list, which names no node: give a region name, node indices or [x, y] points")
    out = []
    for i, item in enumerate(v):
        w = f"{where}[{i}]"
        if isinstance(item, str):
            if item not in regions:
                r.fail(w, f"unknown region {item!r} (regions: {', '.join(regions) or 'none defined'})")
            out.extend(regions[item].tolist())
        elif isinstance(item, bool):
            r.fail(w, "expected a node index, a region name or a point, got a boolean", TypeError)
        elif isinstance(item, int):
            if not 0 <= item < mesh.n_nodes:
                r.fail(w, f"node index {item} out of range [0, {mesh.n_nodes})")
            out.append(item)
        elif isinstance(item, list):
            p = r.point(item, w)
            try:
                out.append(nearest_node(mesh, p, tol=tol))
            except ValueError as exc:
                r.fail(w, str(exc))
        else:
            r.fail(w, f"expected a node index, a region name or a point [x, y], got {tname(item)}", TypeError)
    return np.unique(np.asarray(out, dtype=np.int64))


def scene_region(r: Reader, mesh: Mesh, spec, where: str, regions: dict) -> np.ndarray:
    """A ``[regions]`` entry (one of ``nodes``, ``box``, ``near`` + ``radius``, ``polygon``, ``loop``; with
    ``boundary = true`` its boundary nodes alone) -> its node indices; a region of no node is refused."""
    s = r.keys(spec, REGION_KEYS, where)
    sel = [k for k in ("nodes", "box", "near", "polygon", "loop") if k in s]
    if len(sel) != 1:
        r.fail(where, "give exactly one of nodes, box, near, polygon, loop (boundary = true may restrict it)")
    kind = sel[0]
    bnd = s.get("boundary", False)
    if not isinstance(bnd, bool):
        r.fail(f"{where}.boundary", f"expected true or false, got {bnd!r}", TypeError)
    if "radius" in s and kind != "near":
        r.fail(f"{where}.radius", "only applies to near")
    if kind == "nodes":
        idx = node_ref(r, mesh, s["nodes"], f"{where}.nodes", regions)
        if bnd:
            idx = np.intersect1d(idx, mesh.boundary_nodes)
    elif kind == "box":
        v = s["box"]
        if not isinstance(v, list) or len(v) != 4:
            r.fail(f"{where}.box", f"expected [xmin, ymin, xmax, ymax], got {v!r}")
        x0, y0, x1, y1 = (r.number(c, f"{where}.box[{i}]") for i, c in enumerate(v))
        if x0 > x1 or y0 > y1:
            r.fail(f"{where}.box", "needs xmin <= xmax and ymin <= ymax")
        idx = nodes_in_box(mesh, x0, y0, x1, y1, boundary=bnd)
    elif kind == "near":
        p = r.point(s["near"], f"{where}.near")
        if "radius" not in s:
            r.fail(f"{where}.radius", "missing (required with near)")
        idx = nodes_near(mesh, p, r.number(s["radius"], f"{where}.radius", positive=True), boundary=bnd)
    elif kind == "polygon":
        poly = r.points(s["polygon"], f"{where}.polygon", at_least=3)
        try:
            idx = nodes_in_polygon(mesh, poly, boundary=bnd)
        except ValueError as exc:  # a polygon that encloses nothing (its vertices on one line): named by its field
            r.fail(f"{where}.polygon", str(exc).removeprefix("nodes_in_polygon: "))
    else:
        k = r.integer(s["loop"], f"{where}.loop (a boundary loop index)", 0, len(mesh.boundary_loops) - 1)
        idx = np.sort(np.asarray(mesh.boundary_loops[k], dtype=np.int64))
    if len(idx) == 0:
        r.fail(where, "selects no node of the mesh")
    return np.asarray(idx, dtype=np.int64)
