"""End fixtures that fit: the routed ropes made buildable with the fixture at each end (:func:`fit_fixtures`).

The routing (:func:`~mdsr_opt.synthesis.routing.route_muscles`) lays ropes on nodes at least the channel's
clearance inside the body (:meth:`~mdsr_opt.synthesis.fabrication.Fabrication.clearance`). Each rope then
needs a fixture of radius ``r_f`` (its ``fixture_radius``, the design's ``anchor_radius``) at both ends, and
the routing, not the user, chose the ropes, so it resolves every conflict itself instead of refusing the
design. The resolutions, in order, each recorded as a sentence in the routing's ``notes``:

1. **Fixtures inside.** An end whose fixture disk (radius ``r_f + wall``) would reach outside the outline or
   into a hole is moved inward along its rope, node by node, to the first node with room; a rope with no
   such node keeps no muscle.
2. **Stubs.** A rope shorter than two fixture diameters (``4 r_f``), or whose free part (the rope outside its
   two rigid end patches) is less than :data:`MIN_FREE_FRACTION` of it, is no muscle: its fixtures would
   hold most of it, and a contraction of 0.6 (the design's ``a_max``) would have to shorten the free part
   by more than itself.
3. **Clearance.** Each rope, strongest first, keeps a wall between its channel and the stronger ropes':
   it is shortened to its longest part whose segments lie at least ``channel_diameter + wall`` from their
   centre lines and ``r_f + channel_diameter / 2 + wall`` from their fixtures, with ends (its fixtures) at
   least that far from their lines and ``2 r_f + wall`` from their fixtures; a rope with no such part is
   dropped. Two ropes that cross are thus never both kept whole, and fixtures of different ropes never
   overlap -- but for ends closer than ``r_f``, which share one plate (two ropes knotted to it; the design
   holds it as one rigid part): there the ropes meet, and their clearance holds outside the plate's wall.
   The rope whose two fixtures are joined through others' plates could not contract: the weakest rope of
   such a part is dropped and the check runs again.
4. **Shrinking.** When the steps above lose a rope at ``r_f`` but would keep more with the smallest
   fixture ``min_fixture_radius``, the fixtures of all ropes shrink to the largest size (on a geometric
   ladder of :data:`N_SHRINK_STEPS` sizes from ``r_f`` down to that minimum) that keeps as many. One size
   holds for every end, since the design takes one ``anchor_radius``.

5. **Shared plates.** Ropes whose ends lie closer than ``r_f`` (the same node, where ropes snapped into the
   band meet, or neighbours) keep one fixture plate between them, as step 3 allows; the routing says each
   plate among the ropes it keeps (:func:`shared_plates`) in its ``notes`` with the ropes it holds (the SVG
   and DXF drawings draw it once, in black). Ropes are merged through their fixtures, never spliced.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..body.muscles import Muscle
from ..core.quantities import percent_beside
from ..mechanics.anchors import patch_groups
from .fabrication import Fabrication, boundary_distance, rope_conflicts

__all__ = ["MIN_FREE_FRACTION", "N_SHRINK_STEPS", "FixtureFit", "fit_fixtures", "common_fixture_radius",
           "shared_plates", "fitting_notes"]

#: The free rope (outside its two end patches) must be at least this fraction of a muscle's rest length.
MIN_FREE_FRACTION = 2.0 / 3.0
#: Fixture sizes tried between ``fixture_radius`` and ``min_fixture_radius`` when ropes would be lost.
N_SHRINK_STEPS = 8


@dataclass(frozen=True)
class FixtureFit:
    """The outcome of :func:`fit_fixtures`.

    Attributes
    ----------
    kept : tuple of (int, tuple of int)
        Per kept rope: its index among the input paths and its (possibly shortened) node path.
    radius : float
        The fixture radius the ropes fit with (``fixture_radius``, or smaller down to ``min_fixture_radius``).
    notes : tuple of str
        One sentence per resolution (an end moved inward, a rope dropped and why, the fixtures shrunk, a
        fixture plate that ropes ending closer than its radius share), each once.
    dropped : tuple of (int, str)
        Per dropped rope: its input index and the reason.
    """

    kept: tuple
    radius: float
    notes: tuple
    dropped: tuple


def _where(P, path) -> str:
    a, b = P[path[0]], P[path[-1]]
    return f"the rope from ({a[0]:.4g}, {a[1]:.4g}) to ({b[0]:.4g}, {b[1]:.4g})"


def _clear_of(P, path, stronger, r: float, wall: float, channel: float, need: float, dist, tol: float) -> tuple:
    """The longest part of ``path`` that can be moulded beside the ``stronger`` ropes: every segment at least
    ``channel + wall`` from their centre lines and ``r + channel / 2 + wall`` from their fixtures; its ends (its
    fixtures) also ``r + channel / 2 + wall`` from their lines, ``2 r + wall`` from their fixtures and
    ``need`` inside the body (each up to ``tol``). Empty when no such part of two nodes or more exists."""
    import shapely
    from shapely.geometry import MultiLineString, MultiPoint

    if not stronger:
        return tuple(path)
    path = np.asarray(path)
    lines = MultiLineString([P[list(q)] for q in stronger])
    all_ends = [q[e] for q in stronger for e in (0, -1)]
    # an end of this rope within a fixture's radius of a stronger rope's end shares its plate (one rigid
    # part, as the design holds it): the ropes meet there and need their clearance only outside its wall
    mine = [e for e in (path[0], path[-1]) if r > 0]
    shared = [f for f in all_ends if any(np.linalg.norm(P[f] - P[e]) < r for e in mine)]
    ends = MultiPoint([P[f] for f in all_ends if f not in shared]) if len(shared) < len(all_ends) else None
    at_plate = np.zeros(len(path), bool)
    if shared:
        zone = shapely.union_all([shapely.Point(P[f]).buffer(r + wall, 32) for f in shared])
        lines = lines.difference(zone)
        at_plate = np.min([np.linalg.norm(P[path] - P[f], axis=1) for f in shared], axis=0) < r
    seg = shapely.linestrings(np.stack([P[path[:-1]], P[path[1:]]], axis=1))
    if shared:
        seg = shapely.difference(seg, zone)

    def far(geoms, items, d):  # NaN (an empty part, inside a shared plate) counts as far enough
        if geoms is None or geoms.is_empty:
            return np.ones(len(items), bool)
        return ~(shapely.distance(items, geoms) < d - tol)

    ok = far(lines, seg, channel + wall) & far(ends, seg, r + 0.5 * channel + wall)
    if ok.all():
        k, j = 0, len(path) - 1
    else:
        best, k, j, start = 0, 0, -1, None
        for i, good in enumerate(list(ok) + [False]):
            if good and start is None:
                start = i
            elif not good and start is not None:
                if i - start > best:
                    best, k, j = i - start, start, i
                start = None
    pts = shapely.points(P[path])
    end_ok = (((far(lines, pts, r + 0.5 * channel + wall) & far(ends, pts, 2 * r + wall)) | at_plate)
              & (dist[path] >= need - tol))
    while k < j and not end_ok[k]:
        k += 1
    while j > k and not end_ok[j]:
        j -= 1
    return tuple(path[k:j + 1]) if j > k else ()


def _fit_at(mesh, paths, r: float, wall: float, dist: np.ndarray, channel: float | None = None) -> FixtureFit:
    P = mesh.points
    need = r + wall
    notes, dropped, work = [], [], []
    for i, p in enumerate(paths):
        k, j = 0, len(p) - 1
        while k < len(p) and dist[p[k]] < need:
            k += 1
        while j > k and dist[p[j]] < need:
            j -= 1
        if j - k < 1:
            why = (f"no node of it lies {need:.4g} inside the body (fixture radius {r:.4g} + wall {wall:.4g}), "
                   "so no end fixture fits")
            dropped.append((i, why))
            notes.append(f"{_where(P, p)} dropped: {why}")
            continue
        if k or j < len(p) - 1:
            notes.append(f"{_where(P, p)}: ends moved inward by {k} and {len(p) - 1 - j} node(s) so that its "
                         f"fixtures (radius {r:.4g} + wall {wall:.4g}) lie inside the body")
        work.append((i, tuple(p[k:j + 1])))
    if channel is not None:  # 3. Clearance: each rope kept a wall clear of the stronger ones, trimmed or dropped
        clear = []
        tol = 1e-9 * float(np.ptp(P, axis=0).max())
        for i, p in work:
            q = _clear_of(P, p, [c for _, c in clear], r, wall, channel, need, dist, tol)
            if len(q) < 2:
                why = (f"it cannot be moulded beside stronger ropes: no part of it lies a channel and a wall "
                       f"({channel:.4g} + {wall:.4g}) from their channels with room for its fixtures (radius "
                       f"{r:.4g})")
                dropped.append((i, why))
                notes.append(f"{_where(P, p)} dropped: {why}")
                continue
            if len(q) < len(p):
                notes.append(f"{_where(P, p)}: shortened to the part that lies a channel and a wall ({channel:.4g}"
                             f" + {wall:.4g}) clear of stronger ropes' channels and fixtures (radius {r:.4g}): "
                             f"{len(q) - 1} of its {len(p) - 1} edges")
            clear.append((i, q))
        work = clear
    # each rope's muscle, rest length, segments and their lengths, made once (a dropped rope leaves the lists)
    mus = [Muscle(p) for _, p in work]
    L = [m.rest_length(mesh) for m in mus]
    segs = [(m.segments, m.segment_lengths(P)) for m in mus]
    while work:
        groups, joined = patch_groups(mesh, mus, r)
        group_of = np.full(mesh.n_nodes, -1)
        for gi, g in enumerate(groups):
            group_of[g] = gi
        free = np.empty(len(mus))
        for c, (seg, seg_len) in enumerate(segs):
            inside = (group_of[seg[:, 0]] >= 0) & (group_of[seg[:, 0]] == group_of[seg[:, 1]])
            free[c] = seg_len[~inside].sum() / L[c]
        stub = [c for c in range(len(mus)) if L[c] < 4.0 * r or free[c] < MIN_FREE_FRACTION]
        if stub:
            c = stub[-1]  # the weakest first: dropping it may free another's fixtures
            why = (f"too short for two fixtures of radius {r:.4g}: " + (
                f"rest length {L[c]:.4g}, less than the {4 * r:.4g} (4 radii) two fixtures and the rope between "
                f"them need" if L[c] < 4.0 * r else
                f"of its rest length {L[c]:.4g} only {percent_beside(free[c], MIN_FREE_FRACTION)}% lies outside its "
                f"end fixtures (at least {MIN_FREE_FRACTION:.0%} needed)"))
        elif joined:
            c0 = joined[0]
            g = group_of[work[c0][1][0]]
            members = [c for c, (_, p) in enumerate(work) if group_of[p[0]] == g or group_of[p[-1]] == g]
            c = max(members)
            why = ("its two fixtures are joined through the fixtures of other ropes (one rigid part), so it "
                   "could not contract" if c == c0 else
                   f"its fixture joins the two fixtures of {_where(P, work[c0][1])} through other fixtures "
                   "(one rigid part), which could then not contract; the weaker rope is dropped")
        else:
            break
        i, p = work.pop(c)
        del mus[c], L[c], segs[c]
        dropped.append((i, why))
        notes.append(f"{_where(P, p)} dropped: {why}")
    return FixtureFit(tuple(work), float(r), tuple(notes), tuple(dropped))


def fit_fixtures(mesh, paths, fabrication: Fabrication) -> FixtureFit:
    """Make routed ropes buildable with their end fixtures (see the module docstring).

    Parameters
    ----------
    mesh : Mesh
    paths : sequence of node sequences
        The routed ropes, strongest first.
    fabrication : Fabrication
        With every field set (:meth:`~mdsr_opt.synthesis.fabrication.Fabrication.for_body`).

    Returns
    -------
    FixtureFit
    """
    fit = _fitted(mesh, [list(p) for p in paths], fabrication)
    return FixtureFit(fit.kept, fit.radius, tuple(dict.fromkeys(fit.notes)), fit.dropped)


def shared_plates(P, paths, r: float) -> tuple:
    """One sentence per fixture plate of radius ``r`` that ropes (node ``paths`` on the points ``P``) ending
    closer than ``r`` share (as :func:`~mdsr_opt.synthesis.export_dxf.fixture_plates` draws them): step 5."""
    ends = [(i, e) for i, p in enumerate(paths) for e in (p[0], p[-1])]
    seen, out = set(), []
    for a, (i, e) in enumerate(ends):
        if a in seen:
            continue
        group, todo = {a}, [a]
        while todo:  # ends chained closer than r form one plate
            b = todo.pop()
            for c, (_, f) in enumerate(ends):
                if c not in group and np.linalg.norm(P[ends[b][1]] - P[f]) < r:
                    group.add(c)
                    todo.append(c)
        seen |= group
        ropes = sorted({ends[b][0] for b in group})
        if len(ropes) > 1:
            q = np.mean([P[ends[b][1]] for b in group], axis=0)
            gap = max(np.linalg.norm(P[ends[b][1]] - P[ends[c][1]]) for b in group for c in group)
            out.append(" and ".join(_where(P, paths[k]) for k in ropes)
                       + f" share one end fixture at ({q[0]:.4g}, {q[1]:.4g}): their ends lie {gap:.4g} apart, "
                       f"closer than the fixture radius {r:.4g}, so one plate holds them (one rigid part)")
    return tuple(out)


def _fitted(mesh, paths, fabrication: Fabrication) -> FixtureFit:
    dist = boundary_distance(mesh)
    r0, r_min, wall = fabrication.fixture_radius, fabrication.min_fixture_radius, fabrication.wall
    c = fabrication.channel_diameter
    fit = _fit_at(mesh, paths, r0, wall, dist, c)
    if len(fit.kept) == len(paths) or r_min >= r0:
        return fit
    low = _fit_at(mesh, paths, r_min, wall, dist, c)
    if len(low.kept) <= len(fit.kept):
        return fit
    for k in range(1, N_SHRINK_STEPS + 1):
        r = r0 * (r_min / r0) ** (k / N_SHRINK_STEPS) if r_min > 0 else r0 * (1.0 - k / N_SHRINK_STEPS)
        trial = low if k == N_SHRINK_STEPS else _fit_at(mesh, paths, r, wall, dist, c)
        if len(trial.kept) >= len(low.kept):
            note = (f"fixtures shrunk from radius {r0:.4g} to {trial.radius:.4g} (the smallest allowed is "
                    f"{r_min:.4g}) so that {len(trial.kept) - len(fit.kept)} more rope(s) keep room for them")
            return FixtureFit(trial.kept, trial.radius, (note,) + trial.notes, trial.dropped)
    return low  # not reached: the ladder ends at r_min


def common_fixture_radius(mesh, muscles, fabrication: Fabrication) -> float:
    """One fixture radius for ropes fitted apart (the layouts of several cases driven together, as in an
    animation): the largest size on the ladder from ``fixture_radius`` down to ``min_fixture_radius`` at which
    every rope keeps both fixtures as it is (no end moved, none dropped) and no fixture overlaps another's or
    another rope's channel with its wall (:func:`~mdsr_opt.synthesis.fabrication.rope_conflicts`);
    ``min_fixture_radius`` if none.

    Parameters
    ----------
    mesh : Mesh
    muscles : sequence of Muscle or node sequences
    fabrication : Fabrication
        With every field set (:meth:`~mdsr_opt.synthesis.fabrication.Fabrication.for_body`).
    """
    dist = boundary_distance(mesh)
    paths = [list(getattr(m, "nodes", m)) for m in muscles]
    r0, r_min = fabrication.fixture_radius, fabrication.min_fixture_radius
    for k in range(N_SHRINK_STEPS + 1):
        r = r0 * (r_min / r0) ** (k / N_SHRINK_STEPS) if r_min > 0 else r0 * (1.0 - k / N_SHRINK_STEPS)
        fit = _fit_at(mesh, paths, r, fabrication.wall, dist)
        if not fit.dropped and not fit.notes and not any(
                cf.kind in ("fixtures", "fixture-channel")
                for cf in rope_conflicts(mesh, paths, fabrication, fixture_radius=r)):
            return float(r)
    return float(r_min)


def fitting_notes(P, routing) -> list:
    """The notes of a routing (:class:`~mdsr_opt.synthesis.routing_result.RoutingResult` on the points ``P``)
    that say a rope was moved, cut or dropped for its fixtures: all but the sentences of the end plates its
    ropes share (:func:`shared_plates`), which lose nothing."""
    if routing.fixture_radius is None:
        return list(routing.notes)
    plates = set(shared_plates(P, [list(m.nodes) for m in routing.muscles], routing.fixture_radius))
    return [n for n in routing.notes if n not in plates]
