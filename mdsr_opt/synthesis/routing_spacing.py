"""The seed spacing as a length through the body: a small region nearer than it to one holding far more is a
fragment of that one (:func:`apart_from_stronger`), and a weaker rope that runs beside a stronger one within it is its
twin (:func:`parallel_twins`).

The search (:class:`~mdsr_opt.synthesis.routing_search.Router`) starts a unit only from a seed edge farther
than its seed spacing (a length, :data:`~mdsr_opt.synthesis.routing.SEED_SPACING` of the body's diameter)
from the units made before it. Two things escaped that check on fine meshes, and each gave more, shorter
muscles for the same target as the mesh was refined:

* **Islands.** Each contracted region is seeded on its own. On a jittered mesh the edge weights are noisy, and
  beside a strongly contracted side the set of strong edges breaks into islands of one to four edges; on a
  finer mesh there are more of them (a 4 x 1 strip's band search: 3, 6, 10 regions at 2k, 8k, 16.7k nodes),
  and each seeded island grows into a muscle. Regions are ranked by the contraction they hold, and one nearer
  than the spacing to a region that holds :data:`FRAGMENT_SHARE` of it or less is not seeded: it is a
  fragment of that region. Regions of a like size stay apart (a coarse tentacle's strong edges lie in
  islands of one to three edges, each its own muscle's seed). (Joining the
  two instead would seed the joined region at its strongest edges, which may be the island's: islands of a
  few strongly contracted edges round a squeezed eye, inside the ropes' inset, would then be seeded
  before the ring just outside them.)
* **Twins.** The spacing is checked against the units as seeds, a few edges long; they then grow, and a seed
  a little more than the spacing from a short first unit grows into a rope beside the grown one along its
  length. The band routing (:mod:`~mdsr_opt.synthesis.routing_band`) adds more: it pools the ropes of
  several searches, which lay the same contraction twice. So, strongest first, a rope that lies within the
  spacing of the ropes kept before it over :data:`TWIN_SHARE` of its rest length or more is their twin and
  is dropped (said in the routing's ``dropped``), rather than fitted beside them or cut to the leftover
  beside them. A rope and its own mirror image are never twins (a symmetric layout keeps its pairs whole); a
  rope that crosses a stronger one, or meets it at an end, lies beside it over a short part only.

Distances are shortest paths along mesh edges at rest, not straight lines: two arcs on either side of a
small hole (an eye squeezed shut) are close across the hole but not through the body, and each is a muscle.
"""

from __future__ import annotations

import numpy as np

from .routing_memo import rest_graph

__all__ = ["TWIN_SHARE", "FRAGMENT_SHARE", "apart_from_stronger", "parallel_twins"]

#: A rope lying within the seed spacing of stronger ropes over at least this share of its rest length is a
#: twin of them (as :func:`~mdsr_opt.synthesis.layouts.shared_layout`'s ``overlap`` for duplicates).
TWIN_SHARE = 0.5

#: A region nearer than the seed spacing to one holding at least ``1 / FRAGMENT_SHARE`` times its contraction
#: is a fragment of that one (an island of a few edges beside a strongly contracted side), not seeded.
FRAGMENT_SHARE = 0.1


def _near(mesh, sources, spacing: float) -> np.ndarray:
    """Per node, its distance through the body (along mesh edges at rest) from the nearest of ``sources``;
    ``inf`` beyond ``spacing``."""
    from scipy.sparse.csgraph import dijkstra

    graph, _ = rest_graph(mesh)
    return dijkstra(graph, directed=True, indices=np.asarray(sources, dtype=np.int64), min_only=True,
                    limit=spacing)


def apart_from_stronger(mesh, groups, spacing: float, holds) -> list[bool]:
    """Per group of nodes (ranked by ``holds``, the contraction each holds, largest first), whether it is no
    fragment of a group kept before it: one holding at least ``1 / FRAGMENT_SHARE`` times as much and nearer
    than ``spacing`` through the body (along mesh edges at rest).

    Example
    -------
    >>> from mdsr_opt import Mesh
    >>> mesh = Mesh.rectangle(4.0, 1.0, 4, 1)          # nodes 0..4 along y = 0
    >>> apart_from_stronger(mesh, [[0, 1], [2], [3], [4]], 1.5, [50.0, 1.0, 10.0, 1.0])
    [True, False, True, False]
    """
    keep, kept = [], []  # kept: (distance field, hold) of the groups kept
    for g, hold in zip(groups, holds):
        g = np.asarray(g, dtype=np.int64)
        ok = not any(h * FRAGMENT_SHARE >= hold and np.any(d[g] < spacing) for d, h in kept)
        keep.append(ok)
        if ok:
            kept.append((_near(mesh, g, spacing), hold))
    return keep


def parallel_twins(mesh, paths, spacing: float, ids=None, mirror=None) -> dict:
    """The twins among ropes ranked strongest first (module docstring).

    Parameters
    ----------
    mesh : Mesh
    paths : sequence of node sequences
        The ropes, strongest first.
    spacing : float
        How near a stronger rope, through the body, a rope's segment lies (both its nodes) to count as beside
        it (a length, > 0).
    ids : sequence of int, optional
        Per rope, its unit id in the search (negative: none).
    mirror : sequence of int, optional
        Per unit id, the id of its mirror image (symmetric routing): a rope is never its mirror image's twin.

    Returns
    -------
    dict of int to str
        Per twin, its index and why it is dropped ("dropped: ...", with the share of its rest length that lies
        beside the ropes kept before it).

    Example
    -------
    >>> from mdsr_opt import Mesh
    >>> mesh = Mesh.rectangle(4.0, 1.0, 4, 4)          # rows of 5 nodes, 0.25 apart
    >>> list(parallel_twins(mesh, [[0, 1, 2, 3, 4], [5, 6, 7, 8, 9], [20, 21, 22, 23, 24]], 0.3))
    [1]
    """
    P = mesh.points
    out, kept, near = {}, [], {}
    for i, p in enumerate(paths):
        p = np.asarray(p, dtype=np.int64)
        twin = mirror[ids[i]] if mirror is not None and ids is not None and ids[i] >= 0 else None
        others = [j for j in kept if twin is None or ids[j] != twin]
        seg = np.linalg.norm(P[p[1:]] - P[p[:-1]], axis=1)
        if others and len(p) >= 2 and seg.sum() > 0:
            d = np.min([near[j] for j in others], axis=0)
            share = float(seg[(d[p[1:]] < spacing) & (d[p[:-1]] < spacing)].sum() / seg.sum())
            if share >= TWIN_SHARE:
                out[i] = (f"dropped: {share:.0%} of it lies within {spacing:.4g} of stronger ropes (the seed "
                          "spacing, or a channel and a wall when more): their parallel twin")
                continue
        kept.append(i)
        near[i] = _near(mesh, p, spacing)
    return out
