"""A contact solve's first try: the equilibrium without contact rows, kept when nothing touches along its path.

A solve with contact (``contact=True`` and/or ``obstacles``, the IPOPT contact method) first solves the same
problem without the contact rows (:func:`~mdsr_opt.mechanics.loadsteps.load_continuation`: the same load path,
model, tolerances, iteration caps and stability check as a solve without contact) and keeps that state as the
contact solve's answer when it is admissible for the contact problem with every contact inactive:

- **the path**: the start and every accepted load step's state, and the final state (after a saddle escape,
  if any), each has no boundary crossing, no node inside an obstacle, no boundary segment cutting into a disk
  and no obstacle inside the body (:meth:`~mdsr_opt.mechanics.contactsolve.ContactProblem.penetrates`), no
  corner of a polygon obstacle inside the body, and every candidate contact row of the broad phase at that
  state (self-contact node-segment pairs, creases, interior nodes at folds, obstacles; incl. the
  ``contact_gap``) more than a margin beyond its gap: ``tol`` times the body's size at the final state (the
  margin within which the contact residual counts a row active), ``max(tol, intermediate tolerance)`` times
  the size at the load steps before it, which are solved only to that tolerance. Between consecutive states,
  the nodes moved on straight lines, no boundary node passes through a boundary segment
  (:func:`~mdsr_opt.mechanics.ccd.earliest_impact`), a disk or a polygon obstacle. The load stepping stops at
  the first state that fails (its cost is then only the steps before it);
- **the final state**: the solve without contact succeeded (scaled KKT residual at most ``tol``, every element
  upright, stable unless the caller skips that check), its residual with the contact rows
  (:func:`~mdsr_opt.mechanics.contactsolve.contact_residual`, no row active) is at most ``tol``, and it is a
  stable equilibrium on the tangent space of its taut ropes and anchor patches
  (:func:`~mdsr_opt.mechanics.contactsolve.contact_stability`, with no pushing contact).

Such a state satisfies the contact problem's KKT conditions with zero multipliers: it is stationary without
the contact rows, every gap ``g(x) >= gap`` holds strictly, so complementarity holds with zero contact forces,
and touching nothing it has no friction force either (the friction of
:mod:`~mdsr_opt.mechanics.friction` acts only at touching rows); its Hessian, positive definite on the tangent
space of the active muscle rows, makes it a strict local minimum of the contact problem, whose feasible set
contains a neighbourhood of it. Its contact report has the layout of any contact report
(:func:`~mdsr_opt.mechanics.contactsteps.contact_report`), with no pair, zero forces and the candidate rows
near the state counted in ``n_candidates``; its status says the contact-free solve was checked and kept.

Otherwise the contact solve runs as it would without this first try, from the same start (a warm start from
the contact-free state would not be the same solve: its first load step would start elsewhere); the first
try's iterations and time are added to its own (with ``verbose`` it prints why the first try was not kept).
A start that already touches, or that the contact solve refuses, skips the first try.

Measured on trial 12's C-ring (203 nodes) with nothing touching: its tip turned 70 degrees, 411 IPOPT
iterations with the contact rows against 7 for the kept contact-free solve; one rope contracted 10 and 20 %,
168 and 647 against 8 and 17; the states agree to the contact solve's tolerance (1e-7 of the size).
"""

from __future__ import annotations

import numpy as np

from .ccd import earliest_impact
from .contact import boundary_segments
from .contactsolve import ContactProblem, contact_residual, contact_stability
from .loadsteps import INTERMEDIATE_TOL, load_continuation

__all__ = ["contact_free_solve", "PathCheck", "KEPT"]

#: the status note of a contact solve answered by its contact-free solve
KEPT = "contact-free solve checked and kept: no contact pair within its gap along its path (zero contact forces)"


class PathCheck:
    """The admissibility of a solve's path for the contact problem ``prob`` (module docstring): call
    :meth:`step` with each state in turn after ``x_start`` (None: the first state starts the path); it returns
    why the state (or the straight move to it from the one before) is not admissible, or None. ``margin``: how
    far beyond its gap a row must stay at the final state (load fraction 1), ``loose``: at the states before it
    (relative to the size)."""

    def __init__(self, prob: ContactProblem, x_start, margin: float, loose: float):
        self.prob, self.margin, self.loose = prob, float(margin), float(loose)
        seg, pos = boundary_segments(prob.mesh)
        self.segs, self.nodes = seg, np.flatnonzero(pos[:, 0] >= 0)
        self.last = None if x_start is None else np.asarray(x_start, dtype=float).reshape(-1)

    def step(self, x, s: float = 1.0) -> str | None:
        """Why the state ``x`` ((2n,)) at load fraction ``s`` (1: the final state, held to the final margin), or
        the straight move to it from the last state, is not admissible; None when both are (``x`` then
        becomes the last state)."""
        prob, S = self.prob, self.prob.mesh.size
        x = np.asarray(x, dtype=float).reshape(-1)
        margin = self.margin if s >= 1.0 else max(self.margin, self.loose * S)
        why = prob.penetrates(x) or self._corner_inside(x)
        if why is not None:
            return why
        rows = prob.rows_for(x, [x])
        if rows.n_rows:
            clear = rows.values(x) - prob.spec.gap
            k = int(np.argmin(clear))
            if clear[k] <= margin:
                p, a, b = (int(q) if q < prob.mesh.n_nodes else -1 for q in rows.pts[k])
                return (f"a contact row (nodes {p}, {a}, {b}) within {clear[k] / S:.3g} of the size beyond its "
                        f"gap at load {s:.4g}")
        if self.last is not None and not np.array_equal(x, self.last):
            why = self._path(self.last.reshape(-1, 2), x.reshape(-1, 2))
            if why is not None:
                return why
        self.last = x
        return None

    def _corner_inside(self, x) -> str | None:
        X = x.reshape(-1, 2)
        polys = [(k, ob) for k, ob in enumerate(self.prob.spec.obstacles) if ob.kind == "polygon"]
        if not polys:
            return None
        from shapely.geometry import Point, Polygon

        loops = self.prob.mesh.boundary_loops
        body = Polygon(X[loops[0]], [X[lp] for lp in loops[1:]])
        for k, ob in polys:
            if any(body.contains(Point(*c)) for c in ob.corners()):
                return f"a corner of obstacle {k} inside the body"
        return None

    def _path(self, X0, X1) -> str | None:
        """Why the straight move from ``X0`` to ``X1`` crosses the boundary or enters an obstacle, or None."""
        prob = self.prob
        if prob.spec.self_contact and np.isfinite(earliest_impact(X0, X1, self.nodes, self.segs)):
            return "the boundary passes through itself between two load steps"
        P0, P1 = X0[self.nodes], X1[self.nodes]
        for k, ob in enumerate(prob.spec.obstacles):
            if ob.kind == "disk":
                d = P1 - P0
                t = np.clip(((ob.center - P0) * d).sum(1) / np.maximum((d * d).sum(1), 1e-300), 0.0, 1.0)
                if (np.linalg.norm(P0 + t[:, None] * d - ob.center, axis=1) - ob.radius < prob.spec.gap).any():
                    return f"a boundary node passes through obstacle {k} between two load steps"
            elif ob.kind == "polygon" and _enters(ob.edge_gaps(P0), ob.edge_gaps(P1), prob.spec.gap).any():
                return f"a boundary node passes through obstacle {k} between two load steps"
        return None  # a half-plane: a straight move between two states outside it stays outside


def _enters(g0, g1, gap) -> np.ndarray:
    """Whether each point's straight move enters a convex polygon grown by ``gap``, from its edge gaps at the
    move's ends ((k, m) each): some ``t`` in [0, 1] with every edge gap below ``gap`` (Cyrus-Beck clipping)."""
    lo, hi = np.zeros(len(g0)), np.ones(len(g0))
    dg = g1 - g0
    with np.errstate(divide="ignore", invalid="ignore"):
        tc = np.where(dg != 0, (gap - g0) / dg, np.nan)
    out0, out1 = g0 >= gap, g1 >= gap
    never = (out0 & out1).any(axis=1)
    hi = np.minimum(hi, np.where(~out0 & out1, tc, np.inf).min(axis=1))  # inside at first, out past tc
    lo = np.maximum(lo, np.where(out0 & ~out1, tc, -np.inf).max(axis=1))  # outside at first, in past tc
    return ~never & (lo < hi)


def contact_free_solve(prob: ContactProblem, p_of, fixed, values_of, x_start, tol, max_iter, options, min_step,
                       verbose, predict, settle, loose, force):
    """The contact-free first try of a contact solve (module docstring): ``(out, spent, why)``.

    ``out``: the result dict of :func:`~mdsr_opt.mechanics.contactsteps.contact_continuation` when the
    contact-free state is kept (rows: the candidates near it, forces zero), else None; ``spent``: the first
    try's ``iterations``, ``solve_time`` and ``build_time``; ``why``: why it was not kept ("" when kept)."""
    loose = INTERMEDIATE_TOL if loose is None else float(loose)
    path = PathCheck(prob, None, tol * prob.mesh.size, loose)
    why = path.step(x_start, 0.0)  # a start that touches (or is refused by the contact solve): no first try
    if why is not None:
        return None, {"iterations": 0, "solve_time": 0.0, "build_time": 0.0}, f"its start: {why}"
    x, status, ok, iters, steps, t_solve, t_build = load_continuation(
        prob.mesh, prob.solver_model, p_of, fixed, values_of, np.array(x_start, dtype=float), "ipopt", tol,
        max_iter, options, min_step, verbose, predict, settle=settle, intermediate_tol=loose, on_step=path.step)
    spent = {"iterations": iters, "solve_time": t_solve, "build_time": t_build}
    if not ok:
        return None, spent, status
    # the final state: checked at the last load step, unless a saddle escape moved it (then with the move to it)
    why = None if np.array_equal(x, path.last) else path.step(x)
    if why is not None:
        return None, spent, why
    p1 = p_of(1.0)
    rows = prob.rows_for(x, [x])
    res, fc = contact_residual(prob, rows, x, p1, fixed, tol, force)
    if not res.value <= tol:
        return None, spent, f"its residual with the contact rows {res.value:.3g} > tol {tol:.3g}"
    chk = contact_stability(prob, rows, x, p1, fixed, res, fc)
    if not chk.stable:
        return None, spent, "it is not a stable equilibrium"
    out = {"x": x, "status": f"{status}; {KEPT}", "success": True, "iterations": iters, "steps": steps,
           "solve_time": t_solve, "build_time": t_build, "rows": rows, "residual": res,
           "forces": np.zeros(rows.n_rows), "stability": chk, "fraction": 1.0}
    return out, spent, ""
