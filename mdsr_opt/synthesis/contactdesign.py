"""Design with contact: the keywords checked at the door, mapped to the unit body, and the stability of a
design's state on the tangent space of its active contacts.

A design with contact (self-contact ``contact=True`` and/or rigid ``obstacles``) runs by the derivative-free
method: every objective value is a forward solve :func:`~mdsr_opt.solve_internal` with the same contact, so the
state it scores is the one the body reaches with its contacts. The flattened NLP and the nested method's
adjoint gradient know no contact rows (a state pressed against itself or an obstacle is no stationary point of
their equations), so they are refused with contact rather than verified into a failure.

An obstacle (or self-contact) that the design never reaches still sends the design down the derivative-free
route. Measured (trial 11's bodies; process CPU time, one run each): a T in mm with a floor 20 mm below it,
derivative-free 32.2 s for a difference of 2.47 % of its size, flattened without the floor 0.1 s for
2.18 % (Nelder-Mead stopped at a worse point); a star mounted at its centre with a floor 20 mm below,
derivative-free 2.3 s, nested with the same held nodes and no floor 0.3 s, the same contractions and
difference. The gradient route is not taken automatically yet: the flattened design is a free body
aligned to its target while obstacles stand in the gauge (or held) frame, so its state must first be moved
into that frame and verified with the contacts (a state within the contact gap of an obstacle or of itself
is no longer the contact solve's answer), and design_pipeline, design_poses and the scene runner each choose
the method themselves. Until then a caller who knows the obstacles are never touched and mounts the body
(``held``) may design without them by ``method="nested"`` with the same ``held`` nodes (the frame the
obstacles stand in) and check that design with :func:`~mdsr_opt.synthesis.verify.verify_design` given them.
"""

from __future__ import annotations

import numpy as np

from ..mechanics.align import align
from ..mechanics.contactsteps import contact_spec
from ..mechanics.equilibrium import solve_internal
from ..mechanics.obstacles import check_obstacles
from ..mechanics.units import Units

__all__ = ['CONTACT_METHODS', 'check_design_contact', 'unit_contact', 'contact_minimum']

#: the design methods that take contact (their objective is the contact forward solve's state)
CONTACT_METHODS = ("derivative-free",)

#: a solve started at a design's state that stays within this distance (relative to the body's size) stays
#: there: the state is the equilibrium the contact solve accepts, and its stability check answers for it
STAY_RTOL = 1e-7


def check_design_contact(mesh, material, contact, obstacles, contact_gap, method: str) -> dict:
    """The contact keywords of a design in the caller's units, checked before any work.

    Returns ``{}`` when no contact is asked (``contact=False``, no obstacles), else
    ``{"contact": bool, "obstacles": list, "contact_gap": float or None}`` for
    :func:`~mdsr_opt.solve_internal`. Raises ``TypeError``/``ValueError`` for a non-boolean ``contact``, bad
    obstacles (or one holding a node at rest), a bad ``contact_gap``, or a ``method`` that cannot take contact.
    """
    spec = contact_spec(Units(mesh, material), obstacles, contact, contact_gap, "ipopt")
    if not spec.active:
        return {}
    if method not in CONTACT_METHODS:
        raise ValueError(f"design with contact (contact=True or obstacles) needs method='derivative-free', whose "
                         f"forward solves take the contacts; method={method!r} solves equations without contact "
                         "rows")
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
