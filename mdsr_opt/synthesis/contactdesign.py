"""Design with contact: the keywords checked at the door, mapped to the unit body, the check that a design made
without the contacts touches nothing, and the stability of a design's state on the tangent space of its active
contacts.

A design with contact (self-contact ``contact=True`` and/or rigid ``obstacles``) that names no method and whose
target touches nothing (:func:`target_touches`) is made by a gradient method without the contacts first
(``"nested"`` with ``held`` nodes, as a body mounted where its target was anchored is; ``"flattened"`` for the
free body), then checked with them by :func:`untouched`: the
contact forward solve from rest at the designed contractions (the state a servo pulling the ropes reaches, as
the derivative-free method's own evaluation solves it) must succeed, touch nothing (no contact force) and land
on the design's state within the verification's gap tolerance; the design is then verified with the contacts
as any contact design is. When it touches, the design is made again by the derivative-free method, started
from the gradient design's contractions (:func:`~mdsr_opt.synthesis.contractions.design_contractions`). A
target that touches an obstacle or itself is a shape the contact forces make: it is designed by the
derivative-free method with the contacts from the start. The result's ``method`` is the method that designed
it, and its ``contact_route`` (also at the end of its ``status``) says which route was taken and why.

The derivative-free method is the one that takes contact in its search: every objective value is a forward
solve :func:`~mdsr_opt.solve_internal` with the same contact, so the state it scores is the one the body reaches
with its contacts. The flattened NLP and the nested method's adjoint gradient know no contact rows (a state
pressed against itself or an obstacle is no stationary point of their equations), so they are refused when
asked by name with contact rather than verified into a failure; ``method="derivative-free"`` asked by name
searches with the contacts from the start.

Why: an obstacle (or self-contact) that the design never reaches sent every such design down the
derivative-free route, each evaluation a contact solve: a star in mm mounted at its centre over a floor it
never touches stopped at Nelder-Mead's evaluation cap (3,200 contact solves), a failure, where the nested
design without the floor, checked with it, is verified after 26 forward solves.
"""

from __future__ import annotations

import numpy as np

from ..mechanics.align import align
from ..mechanics.anchors import body_size
from ..mechanics.contact import broad_phase
from ..mechanics.contactsteps import DEFAULT_GAP, contact_spec
from ..mechanics.equilibrium import in_held_frame, solve_internal
from ..mechanics.obstacles import check_obstacles
from ..mechanics.units import Units

__all__ = ['CONTACT_METHODS', 'check_design_contact', 'unit_contact', 'contact_minimum', 'gradient_method', 'untouched',
           'contact_words', 'target_touches', 'TOUCH_RTOL']

#: the design methods that take contact (their objective is the contact forward solve's state)
CONTACT_METHODS = ("derivative-free",)

#: a target within this share of the body's size (or twice the contact gap, when that is more) of an obstacle or
#: of itself touches it (:func:`target_touches`): a shape pressed on something, designed with the contacts
TOUCH_RTOL = 1e-3

#: a solve started at a design's state that stays within this distance (relative to the body's size) stays
#: there: the state is the equilibrium the contact solve accepts, and its stability check answers for it
STAY_RTOL = 1e-7


def check_design_contact(mesh, material, contact, obstacles, contact_gap, method: str | None) -> dict:
    """The contact keywords of a design in the caller's units, checked before any work.

    Returns ``{}`` when no contact is asked (``contact=False``, no obstacles), else
    ``{"contact": bool, "obstacles": list, "contact_gap": float or None}`` for
    :func:`~mdsr_opt.solve_internal`. Raises ``TypeError``/``ValueError`` for a non-boolean ``contact``, bad
    obstacles (or one holding a node at rest), a bad ``contact_gap``, or a ``method`` that cannot take contact
    (None: the gradient design checked with the contacts, module docstring).
    """
    spec = contact_spec(Units(mesh, material), obstacles, contact, contact_gap, "ipopt")
    if not spec.active:
        return {}
    if method is not None and method not in CONTACT_METHODS:
        raise ValueError(f"design with contact (contact=True or obstacles) needs method='derivative-free', whose "
                         f"forward solves take the contacts, or no method (a gradient design without them, checked "
                         f"with them); method={method!r} solves equations without contact rows")
    return {"contact": bool(contact), "obstacles": check_obstacles(obstacles, mesh), "contact_gap": contact_gap}


def unit_contact(kw: dict, units: Units) -> dict:
    """The contact keywords ``kw`` (:func:`check_design_contact`) on the body's unit copy."""
    if not kw:
        return {}
    gap = kw.get("contact_gap")
    return {"contact": kw["contact"], "obstacles": [o.scaled(1.0 / units.length, np.zeros(2)) for o in kw["obstacles"]],
            "contact_gap": None if gap is None else units.to_unit(gap)}


def contact_minimum(mesh, material, muscles, contractions, x, kw: dict, *, muscle_model: str = "cable",
                    stiffness: float = 10.0, anchor_radius: float | None = None, tol: float = 1e-8, held=None):
    """Is ``x`` a stable equilibrium at ``contractions`` with the contacts ``kw`` (caller's units)?

    A contact solve (:func:`~mdsr_opt.solve_internal` with ``kw``) starts at ``x`` with no load stepping; its
    stability check is the Hessian of the Lagrangian on the tangent space of the active ropes, anchor patches
    and pushing contacts (:func:`~mdsr_opt.mechanics.contactsolve.contact_stability`). ``x`` passes when that
    solve succeeds (stable, scaled KKT residual at most ``tol``) and stays within :data:`STAY_RTOL` of the body's
    size of ``x`` (after rigid alignment; with obstacles or ``held`` nodes the frame is fixed and no alignment
    is made). ``held``: nodes clamped at rest, as in :func:`~mdsr_opt.solve_internal`.

    Returns ``(stable, residual, result)``: the solve's residual stands for ``x``'s when it stays (NaN when it
    moves away), and ``result`` is that :class:`~mdsr_opt.mechanics.result.EquilibriumResult`.
    """
    x = np.asarray(x, dtype=float).reshape(-1, 2)
    res = solve_internal(mesh, material, muscles, np.clip(contractions, 0.0, 0.999), muscle_model=muscle_model,
                         stiffness=stiffness, anchor_radius=anchor_radius, tol=tol, initial_guess=x, min_step=1.0,
                         align_to_rest=False, held=held, **kw)
    fx = np.asarray(res.x, dtype=float)
    moved = fx - x if kw.get("obstacles") or held is not None else align(x, fx).apply(x) - fx
    stays = bool(np.isfinite(moved).all() and np.linalg.norm(moved, axis=1).max() <= STAY_RTOL * mesh.size)
    ok = bool(res.success and res.stable and stays)
    residual = float(res.residual) if stays and res.residual is not None else float("nan")
    return ok, residual, res


def gradient_method(held) -> str:
    """The gradient method a design takes when none is named: ``"nested"`` for a body with ``held`` nodes
    (the flattened NLP pins the gauge only), else ``"flattened"``; with contact, the method of its first
    design, without the contacts (module docstring)."""
    return "flattened" if held is None else "nested"


def contact_words(kw: dict) -> str:
    """What the contacts ``kw`` (:func:`check_design_contact`) are, for messages: ``"the obstacles"``,
    ``"self-contact"`` or both."""
    parts = (["the obstacles"] if kw.get("obstacles") else []) + (["self-contact"] if kw.get("contact") else [])
    return " and ".join(parts)


def untouched(mesh, material, muscles, design, kw: dict, *, tol: float = 1e-8, gap_rtol: float = 1e-5):
    """Does the design ``design`` (made without contact) touch nothing when its contacts ``kw`` are there?

    The state a robot reaches: a contact solve (:func:`~mdsr_opt.solve_internal` with ``kw``, caller's units)
    from rest at ``design.contractions``, load-stepped, its body held at ``design.held`` (or at its gauge),
    as the derivative-free design's own evaluation and the verification solve it. The design passes when
    that solve succeeds, reports no contact pair (no contact force, no row at its gap: the state keeps the
    contact gap from every obstacle and from itself) and lands within ``gap_rtol * mesh.size`` of
    ``design.x`` (where the states are with ``held`` nodes; after rigid alignment without them).

    Returns ``(passed, why, x, gap)``: ``why`` says what touched or failed, as a predicate of the design
    (``"touches the obstacles: ..."``; empty when passed), ``x`` is
    the contact solve's state (in the obstacles' frame: the one a design with obstacles reports) and ``gap``
    the largest node distance between it and ``design.x`` (a length; NaN when the solve failed).
    """
    held = design.held
    r = solve_internal(mesh, material, muscles, np.clip(design.contractions, 0.0, 0.999),
                       muscle_model=design.muscle_model, stiffness=design.stiffness,
                       anchor_radius=design.anchor_radius, tol=tol, align_to_rest=False, held=held, **kw)
    what = contact_words(kw)
    fx = np.asarray(r.x, dtype=float).reshape(-1, 2)
    if not r.success:
        return False, f"cannot be solved forward with {what} ({r.status})", fx, float("nan")
    x = np.asarray(design.x, dtype=float)
    moved = fx - x if held is not None else align(x, fx).apply(x) - fx
    gap = float(np.linalg.norm(moved, axis=1).max())
    c = r.contact or {}
    pairs = c.get("pairs") or []
    if pairs:
        kinds = sorted({p["kind"] + (f" {p['obstacle']}" if p["obstacle"] >= 0 else "") for p in pairs})
        force = c.get("total_force")
        return False, (f"touches {what}: {len(pairs)} contact pair(s) ({', '.join(kinds)})"
                       + (f", total contact force {force:.3g}" if force is not None else "")
                       + f", the state with them {gap:.3g} from the design's"), fx, gap
    if not gap <= gap_rtol * mesh.size:
        return False, (f"lands {gap:.3g} away with {what} (more than {gap_rtol * mesh.size:.3g}) without a contact "
                       "force: another equilibrium"), fx, gap
    return True, "", fx, gap


def target_touches(mesh, target, kw: dict, held=None) -> str:
    """Does ``target`` touch the contacts ``kw`` (:func:`check_design_contact`, caller's units)? A sentence
    saying where (``""`` when it does not).

    A target pressed on an obstacle (or on itself) is a shape the contact forces make: a gradient design
    without them cannot reach it, and a design that ends short of the obstacle is only a local optimum of the
    design with it (a finger bent onto a disk: 0.085 against 1e-4 for the derivative-free search with the
    disk), so such a target is designed by the derivative-free method with the contacts from the start. The
    target is taken in the obstacles' frame (as given; moved rigidly onto the ``held`` nodes' rest positions
    with them); it touches when a boundary node lies inside an obstacle or a pair of the contact solve's broad
    phase (node and boundary segment, node and obstacle, disk and segment; self-contact pairs with
    ``contact=True``) comes within :data:`TOUCH_RTOL` of the body's size, or twice the contact gap.
    """
    y = np.asarray(target, dtype=float).reshape(-1, 2)
    if held is not None:
        y = in_held_frame(mesh, y, np.asarray(held, dtype=np.int64))
    size = body_size(mesh)
    gap = kw.get("contact_gap")
    thr = max(TOUCH_RTOL * size, 2.0 * (DEFAULT_GAP * size if gap is None else float(gap)))
    obs = kw.get("obstacles") or []
    for k, o in enumerate(obs):
        g = o.gap(y[mesh.boundary_nodes])
        if g.min() < 0:
            return f"its target enters obstacles[{k}] (by {-g.min():.3g})"
    rows = broad_phase(mesh, y, [y], thr, obstacles=obs, self_contact=bool(kw.get("contact")))
    if not rows.n_rows:
        return ""
    g = np.asarray(rows.values(y), dtype=float).reshape(-1)
    if not (g < thr).any():  # the broad phase also keeps farther rows (a concave corner's neighbour pairs)
        return ""
    i = int(np.argmin(g))
    where = f"obstacles[{int(rows.labels[i, 1])}]" if rows.labels[i, 1] >= 0 else "itself"
    return f"its target touches {where} (within {max(g[i], 0.0):.3g}, less than {thr:.3g})"
