"""One muscle layout from several: the per-pose routings merged under a muscle budget.

:func:`route_poses` is step 1 of :func:`~mdsr_opt.synthesis.poses.design_poses` (every pose routed as the
pipeline routes, with the reason for a pose that gets no rope); :func:`shared_layout` is step 2-4 of :func:`~mdsr_opt.synthesis.poses.design_poses` (its module docstring
says why a union of per-pose layouts and not one routing on a combined graph): candidates taken round-robin
by rank, duplicates (ropes sharing most of their edges, or too close to be moulded apart) merged, a rope
that crosses or crowds the stronger ones fitted beside them as the routing fits its own
(:func:`~mdsr_opt.synthesis.routing_fixtures.fit_fixtures`: shortened or dropped), at most ``max_muscles``
kept. :func:`check_budget` checks that budget.
"""

from __future__ import annotations

import warnings
from dataclasses import replace
from typing import Mapping, Sequence

from ..body.mesh import Mesh
from ..body.muscles import Muscle
from ..core.checks import check_int
from ..plot.style import muscle_label, muscle_name
from .fabrication import pair_conflicts
from .routing_fixtures import fit_fixtures

__all__ = ["route_poses", "shared_layout", "check_budget"]


def check_budget(max_muscles) -> int | None:
    """The muscle budget: None (no limit) or an integer of at least 1 (TypeError, ValueError otherwise)."""
    if max_muscles is None:
        return None
    return check_int(max_muscles, "max_muscles (the muscle budget, or None)", 1)


def route_poses(mesh: Mesh, targets: Mapping, routing_options: Mapping) -> tuple[dict, dict]:
    """Every pose's own layout, routed as :func:`~mdsr_opt.design_pipeline` and ``mdsr run`` route a target
    (:func:`~mdsr_opt.synthesis.routing.route_for_design`, with its fallbacks: deeper inside with smaller
    fixtures, ``K_a = 1``, ropes snapped into the buildable band), so that a pose the pipeline can design gets
    its ropes here too.

    Parameters
    ----------
    mesh : Mesh
    targets : mapping pose name -> (n, 2) target (checked)
    routing_options : mapping, keywords of :func:`~mdsr_opt.synthesis.routing.route_muscles`

    Returns
    -------
    layouts : dict pose name -> tuple of Muscle, ranked strongest first (in the order of ``targets``)
    reasons : dict pose name -> str, for every pose that got no rope: why (the first routing's warnings -- no
        contracted edge, units shorter than ``min_length``, ropes that keep no room for their fixtures or lie
        outside the buildable band, with their figures -- and its notes on ropes dropped for their fixtures).
        The routing's other warnings are passed on; its :class:`~mdsr_opt.synthesis.routing.RoutingWarning`
        are not (a pose with ropes needs none; one without has them here).
    """
    from .routing import RoutingWarning, route_for_design
    from .routing_fixtures import fitting_notes

    layouts, reasons = {}, {}
    for name, target in targets.items():
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            rr = route_for_design(mesh, target, **routing_options)
        said = []
        for w in caught:
            if issubclass(w.category, RoutingWarning):
                said.append(str(w.message))
            else:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        layouts[name] = tuple(rr.muscles)
        if not layouts[name]:
            why = list(dict.fromkeys(said + list(fitting_notes(mesh.points, rr))))
            reasons[name] = ("no rope kept by the routing nor by its fallbacks; the routing with the options "
                             "given: " + ("; ".join(why) or "no reason said"))
    return layouts, reasons


def shared_layout(mesh: Mesh, layouts: Mapping[str, Sequence[Muscle]], max_muscles: int | None = None,
                  overlap: float = 0.5, *, fabrication=None, fixture_radius: float | None = None,
                  notes: list | None = None, by_pose: bool = False,
                  clashes: str = "resolve") -> tuple[tuple[Muscle, ...],
                                                                             tuple[tuple[str, ...], ...]]:
    """Merge per-pose layouts into one: round-robin by rank, duplicates dropped, at most ``max_muscles``.

    Parameters
    ----------
    mesh : Mesh
    layouts : mapping pose name -> muscles ranked strongest first (as :func:`~mdsr_opt.synthesis.routing.route_muscles`
        returns them).
    max_muscles : int, optional
        The budget (at least 1); default: no limit.
    overlap : float in (0, 1]
        A candidate whose edges are covered by a kept muscle to at least this fraction (of the shorter of
        the two) is a duplicate.
    fabrication : Fabrication, optional
        With every field set (:meth:`~mdsr_opt.synthesis.fabrication.Fabrication.for_body`): a candidate that
        could not be moulded beside a kept muscle of another pose (channels closer than a channel and a wall, ropes that
        cross, fixtures of radius ``fixture_radius`` that overlap each other or the other's channel:
        :func:`~mdsr_opt.synthesis.fabrication.pair_conflicts`) is merged into it when at least ``overlap`` of
        its nodes lie that close (a duplicate, serving its pose too); else it is fitted beside the kept ones,
        which are stronger (those of the other poses: a pose's own layout, routed or given, is taken as it is),
        as the routing fits its own ropes
        (:func:`~mdsr_opt.synthesis.routing_fixtures.fit_fixtures` with fixtures of ``fixture_radius``: its
        longest part a channel and a wall clear of their channels and fixtures, with room for its own fixtures
        and no stub), the kept ones left as they are; a rope with no such part, or one that would cost a kept
        rope its fixtures, is dropped (``clashes="keep"``: kept as it is, said NOT mouldable in one layer).
        None: no such check.
    fixture_radius : float, optional
        The fixtures' radius for that check; default ``fabrication.min_fixture_radius`` (the smallest the
        ends may get).
    notes : list, optional
        Receives one sentence per candidate merged, shortened or dropped beside a kept one; none for a candidate
        the budget leaves out (no rope of the layout is the one it would describe).
    by_pose : bool, default False
        Name and order the ropes by the poses' own layouts, which are shown beside the merged one (a
        scene's cases and its gait): see ``muscles``.
    clashes : {"resolve", "keep"}, default "resolve"
        What becomes of a rope that crosses or crowds a kept rope of another pose and is no duplicate of it:
        fitted beside it (shortened or dropped), or kept as routed for a layout whose crossing ropes get
        channels at two depths (the face's expressions), which cannot be moulded in one layer.

    Returns
    -------
    muscles : tuple of Muscle
        Without ``by_pose`` (the merged layout is the only one shown), in the round-robin order, each keeps
        its name when no two share one (a scene's ``inner_left``; the cases of a run, numbered run-wide);
        else a muscle's own name is kept and a routed one is named by its place ``M1, M2, ...``
        (:func:`mdsr_opt.plot.style.muscle_name`, as in every figure); all by place when two would still
        share a name. With ``by_pose``, ordered by the pose each was taken from (in the order of ``layouts``), then
        by its rank there, so the first pose's ropes keep their places (and colours); each keeps the name it
        has in its pose's layout (its own, or ``M<rank>``: :func:`mdsr_opt.plot.style.muscle_label`) when
        that name means this rope (or one merged into it) in every pose's layout; otherwise every rope named
        by its place, and every rope whose name is ambiguous, is prefixed by its pose: ``curl:M2`` (as
        :func:`mdsr_opt.scenes.animate.union_of_layouts` names an animation's muscles).
    sources : tuple of tuple of str, the poses each muscle serves (the pose it was taken from first).
    """
    budget = check_budget(max_muscles)
    if clashes not in ("resolve", "keep"):
        raise ValueError(f"clashes must be 'resolve' or 'keep', got {clashes!r}")
    if not (0.0 < float(overlap) <= 1.0):
        raise ValueError(f"overlap must be in (0, 1], got {overlap!r}")
    # a kept rope: (muscle, edges, poses served, (pose, rank) it was taken from)
    kept: list[tuple[Muscle, frozenset, list, tuple]] = []
    taken: dict[tuple, int] = {}  # (pose, rank) -> the kept rope that stands for it
    labels: dict[tuple, str] = {}  # (pose, rank) -> the name the pose's own layout gives it
    depth = max((len(v) for v in layouts.values()), default=0)
    for r in range(depth):
        for name, mus in layouts.items():
            if r >= len(mus):
                continue
            cand = mus[r] if isinstance(mus[r], Muscle) else Muscle(mus[r])
            labels[(name, r)] = muscle_label(cand, r)
            ce = cand.edges
            dup = None
            for k, (_, ke, src, _) in enumerate(kept):
                if len(ce & ke) >= overlap * min(len(ce), len(ke)):
                    dup = k
                    break
            hits = []
            if dup is None and fabrication is not None:
                rad = fabrication.min_fixture_radius if fixture_radius is None else float(fixture_radius)
                for k, (km, _, _, origin) in enumerate(kept):
                    if origin[0] == name:  # its own pose's layout: fitted by its routing, or given as it is
                        continue
                    found, near = pair_conflicts(mesh, km, cand, fabrication, rad)
                    if found:
                        hits.append((near < overlap, k, found[0]))
            said = None  # what became of the candidate: noted when it is merged, cut or dropped, not when the
            # budget leaves it out (no rope of the layout would then be the one the note describes)
            a, b = mesh.points[cand.nodes[0]], mesh.points[cand.nodes[-1]]
            rope = f"pose {name!r}'s rope of rank {r + 1} from ({a[0]:.4g}, {a[1]:.4g}) to ({b[0]:.4g}, {b[1]:.4g})"
            if hits:  # merged into the first rope it runs along; else fitted beside the kept ones
                unmerged, k, cf = min(hits, key=lambda c: c[:2])
                if not unmerged:
                    what = cf.message.split(": ", 1)[1] if ": " in cf.message else cf.message
                    said = f"{rope} merged into pose {kept[k][3][0]!r}'s rope of rank {kept[k][3][1] + 1} ({what})"
                    dup = k
                elif budget is not None and len(kept) >= budget:
                    continue
                elif clashes == "keep":
                    what = cf.message.split(": ", 1)[1] if ": " in cf.message else cf.message
                    said = (f"{rope} kept beside pose {kept[k][3][0]!r}'s rope of rank {kept[k][3][1] + 1}, NOT "
                            f"mouldable in one layer ({what})")
                else:
                    others = [km for km, _, _, origin in kept if origin[0] != name]
                    part, said = _fitted_beside(mesh, cand, others, fabrication, rad, rope)
                    if not part:
                        if notes is not None:
                            notes.append(said)
                        continue
                    cand = Muscle(part, name=cand.name)
                    ce = cand.edges
            if dup is not None:
                if said is not None and notes is not None:
                    notes.append(said)
                if name not in kept[dup][2]:
                    kept[dup][2].append(name)
                taken[(name, r)] = dup
                continue
            if budget is not None and len(kept) >= budget:
                continue
            if said is not None and notes is not None:
                notes.append(said)
            taken[(name, r)] = len(kept)
            kept.append((cand, ce, [name], (name, r)))
    if by_pose:  # the first pose's ropes first, each pose's in its own order: the first pose's keep their places
        order = list(layouts)
        perm = sorted(range(len(kept)), key=lambda k: (order.index(kept[k][3][0]), kept[k][3][1]))
        new = {old: i for i, old in enumerate(perm)}
        kept = [kept[k] for k in perm]
        names = _names(kept, {key: new[k] for key, k in taken.items()}, labels)
    else:  # every name kept when no two muscles share one (a scene's ``inner_left``; the cases of a run,
        # numbered run-wide: scenes.names); else a muscle's own name is kept and routed ones (named by place in
        # their pose's layout) are numbered anew, and if two still share one, every one by its place
        names = [m.name or muscle_name(i) for i, (m, _, _, _) in enumerate(kept)]
        if len(set(names)) < len(names):
            names = [n if not _is_place_name(n) else muscle_name(i)
                     for i, n in enumerate(labels[origin] for _, _, _, origin in kept)]
        if len(set(names)) < len(names):
            names = [muscle_name(i) for i in range(len(kept))]
    muscles = tuple(Muscle(m.nodes, name=n) for n, (m, _, _, _) in zip(names, kept))
    for m in muscles:
        m.check_on(mesh)
    return muscles, tuple(tuple(s) for _, _, s, _ in kept)


def _fitted_beside(mesh: Mesh, cand: Muscle, kept: Sequence[Muscle], fabrication, radius: float,
                   rope: str) -> tuple[tuple, str | None]:
    """Rope ``cand`` fitted beside the stronger ``kept`` ones (of the other poses) as the routing fits its own ropes
    (:func:`~mdsr_opt.synthesis.routing_fixtures.fit_fixtures`, every fixture of ``radius``: its fixtures
    inside, its longest part a channel and a wall clear of their channels and fixtures, no stub, no fixture
    joining another rope's two), the kept ones left as they are. Returns its node path (empty: dropped) and
    the sentence that says what became of it (None: kept whole), which begins with ``rope``."""
    fab = replace(fabrication, fixture_radius=float(radius), min_fixture_radius=float(radius))
    paths = [list(m.nodes) for m in kept]
    n = len(paths)
    alone = fit_fixtures(mesh, paths, fab)
    fit = fit_fixtures(mesh, paths + [list(cand.nodes)], fab)
    part = dict(fit.kept).get(n, ())
    if [q for i, q in fit.kept if i < n] != list(q for _, q in alone.kept):  # it would cost a stronger rope
        why = [w for i, w in fit.dropped if i < n and i not in dict(alone.dropped)]
        return (), (f"{rope} dropped: keeping it would drop or shorten a stronger rope of the shared layout"
                    + (f" ({why[0]})" if why else ""))
    if len(part) < 2 or any(pair_conflicts(mesh, m, part, fabrication, radius)[0] for m in kept):
        why = dict(fit.dropped).get(n, "its part clear of them conflicts with them still")
        return (), f"{rope} dropped: no part of it that can be moulded beside the stronger ropes is a muscle ({why})"
    if tuple(part) == tuple(cand.nodes):
        return tuple(part), None
    return tuple(part), (f"{rope} shortened to its part that can be moulded beside the stronger ropes of the "
                         f"shared layout (a channel and a wall, {fabrication.channel_diameter:.4g} + "
                         f"{fabrication.wall:.4g}, clear of their channels and of fixtures of radius {radius:.4g}, "
                         f"its own fixtures inside the body): {len(part) - 1} of its {len(cand.nodes) - 1} edges")


def _names(kept, taken: dict, labels: dict) -> list[str]:
    """The names of the kept ropes: the one each has in its pose's layout when, in every pose's layout, that
    name means a rope standing for this one; else prefixed by its pose (every rope named by its place too,
    so that no bare ``M2`` reads as another pose's ``M2``)."""
    own = [labels[origin] for _, _, _, origin in kept]
    clean = [all(taken.get(key) == k for key, lab in labels.items() if lab == own[k]) for k in range(len(kept))]
    if all(clean):
        return own
    names = [n if ok and not _is_place_name(n) else f"{origin[0]}:{n}"
             for n, ok, (_, _, _, origin) in zip(own, clean, kept)]
    return [n if names.count(n) == 1 else f"{n}#{k + 1}" for k, n in enumerate(names)]


def _is_place_name(name: str) -> bool:
    """Is ``name`` the name of a place in a layout (``"M3"``, as routing names its muscles)?"""
    digits = name[len(name.rstrip("0123456789")):]
    return bool(digits) and int(digits) > 0 and name == muscle_name(int(digits) - 1)
