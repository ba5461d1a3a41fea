"""One muscle layout from several: the per-pose routings merged under a muscle budget.

:func:`shared_layout` is step 2-4 of :func:`~mdsr_opt.synthesis.poses.design_poses` (its module docstring
says why a union of per-pose layouts and not one routing on a combined graph): candidates taken round-robin
by rank, duplicates (ropes sharing most of their edges, or too close to be moulded apart) merged, at most
``max_muscles`` kept. :func:`check_budget` checks that budget.
"""

from __future__ import annotations

from typing import Mapping, Sequence

from ..body.mesh import Mesh
from ..body.muscles import Muscle
from ..core.checks import check_int
from ..plot.style import muscle_name
from .fabrication import pair_conflicts

__all__ = ["shared_layout", "check_budget"]


def check_budget(max_muscles) -> int | None:
    """The muscle budget: None (no limit) or an integer of at least 1 (TypeError, ValueError otherwise)."""
    if max_muscles is None:
        return None
    return check_int(max_muscles, "max_muscles (the muscle budget, or None)", 1)


def shared_layout(mesh: Mesh, layouts: Mapping[str, Sequence[Muscle]], max_muscles: int | None = None,
                  overlap: float = 0.5, *, fabrication=None, fixture_radius: float | None = None,
                  notes: list | None = None) -> tuple[tuple[Muscle, ...], tuple[tuple[str, ...], ...]]:
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
        could not be moulded beside a kept muscle (channels closer than a channel and a wall, ropes that
        cross, fixtures of radius ``fixture_radius`` that overlap each other or the other's channel:
        :func:`~mdsr_opt.synthesis.fabrication.pair_conflicts`) is merged into it when at least ``overlap`` of
        its nodes lie that close (a duplicate, serving its pose too); else it is kept (its pose may have no
        other rope) and reported in ``notes``. None: no such check.
    fixture_radius : float, optional
        The fixtures' radius for that check; default ``fabrication.min_fixture_radius`` (the smallest the
        ends may get).
    notes : list, optional
        Receives one sentence per candidate merged, or kept though it cannot be moulded beside a kept one.

    Returns
    -------
    muscles : tuple of Muscle: each keeps its name when no two share one; else a muscle's own name (a
        scene's muscle) is kept and a routed one is named by its place ``M1, M2, ...``
        (:func:`mdsr_opt.plot.style.muscle_name`, as in every figure); all by place when two would still
        share a name
    sources : tuple of tuple of str, the poses each muscle serves (the pose it was taken from first).
    """
    budget = check_budget(max_muscles)
    if not (0.0 < float(overlap) <= 1.0):
        raise ValueError(f"overlap must be in (0, 1], got {overlap!r}")
    kept: list[tuple[Muscle, frozenset, list]] = []
    depth = max((len(v) for v in layouts.values()), default=0)
    for r in range(depth):
        for name, mus in layouts.items():
            if r >= len(mus):
                continue
            cand = mus[r] if isinstance(mus[r], Muscle) else Muscle(mus[r])
            ce = cand.edges
            dup = None
            for k, (_, ke, src) in enumerate(kept):
                if len(ce & ke) >= overlap * min(len(ce), len(ke)):
                    dup = k
                    break
            clash = None
            if dup is None and fabrication is not None:
                rad = fabrication.min_fixture_radius if fixture_radius is None else float(fixture_radius)
                for k, (km, _, _) in enumerate(kept):
                    found, near = pair_conflicts(mesh, km, cand, fabrication, rad)
                    if found:
                        clash = (k, found[0], near)
                        break
            if clash is not None:
                k, cf, near = clash
                merged = near >= overlap
                if notes is not None:
                    a, b = mesh.points[cand.nodes[0]], mesh.points[cand.nodes[-1]]
                    what = cf.message.split(": ", 1)[1] if ": " in cf.message else cf.message
                    notes.append(f"pose {name!r}'s rope of rank {r + 1} from ({a[0]:.4g}, {a[1]:.4g}) to "
                                 f"({b[0]:.4g}, {b[1]:.4g}) " + (f"merged into {muscle_name(k)}" if merged else
                                                               f"kept beside {muscle_name(k)}, NOT mouldable in "
                                                               "one layer") + f" ({what})")
                if merged:
                    dup = k
            if dup is not None:
                if name not in kept[dup][2]:
                    kept[dup][2].append(name)
                continue
            if budget is not None and len(kept) >= budget:
                continue
            kept.append((cand, ce, [name]))
    # every name kept when no two muscles share one (a scene's ``inner_left``; the cases of a run, numbered
    # scene-wide: scenes.names.number_in_scene); else a muscle's own name is kept and routed ones (named by
    # place in their pose's layout) are numbered anew, and if two still share one, every one by its place
    names = [m.name or muscle_name(i) for i, (m, _, _) in enumerate(kept)]
    if len(set(names)) < len(names):
        names = [_own_name(m) or muscle_name(i) for i, (m, _, _) in enumerate(kept)]
    if len(set(names)) < len(names):
        names = [muscle_name(i) for i in range(len(kept))]
    muscles = tuple(Muscle(m.nodes, name=n) for n, (m, _, _) in zip(names, kept))
    for m in muscles:
        m.check_on(mesh)
    return muscles, tuple(tuple(s) for _, _, s in kept)


def _own_name(muscle) -> str | None:
    """``muscle``'s name when it was given one, None when it has none or the name of a place in a layout
    (``"M3"``, as routing names its muscles)."""
    name = getattr(muscle, "name", None)
    if not name:
        return None
    digits = name.lstrip(name.rstrip("0123456789"))
    return None if digits and int(digits) > 0 and name == muscle_name(int(digits) - 1) else name
