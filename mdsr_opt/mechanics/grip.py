"""Does a grip hold its object? The loads a body's contacts on a rigid disk can resist with Coulomb friction.

From a solve with the disk as an obstacle (its contact forces ``N_i`` at the points ``x_i`` where it touches
the body: a node, or the point of a boundary segment closest to the centre (:func:`contact_points`); normal
``n_i = (x_i - c) / |x_i - c|``), the body pushes on the disk with ``sum_i N_i (-n_i) + tau_i t_i`` where
``t_i`` is the tangent (``n_i`` turned by +90 degrees) and ``|tau_i| <= mu N_i`` (Coulomb: stick while the
tangential force is below ``mu`` times the normal force). The disk, now free, is held against a load ``L`` when
tangential forces within their cones balance it, forces and moment:

``sum_i (-N_i n_i + tau_i t_i) + L = 0``,  ``sum_i tau_i = 0`` (every contact at the radius: the moment)

For each direction ``d`` the largest ``s`` with ``L = s d`` held is a small linear program
(``scipy.optimize.linprog``). The normal forces are those of the solve, kept as the load is applied (a rigid
grip: a body that squeezes harder under load holds more, one that lets go holds less). ``held`` is whether
the load ``load`` (default none: the disk stays put once the support that held it in the solve is gone) is
held.

Example
-------
>>> import numpy as np
>>> from mdsr_opt import Disk
>>> pairs = [{"kind": "obstacle", "obstacle": 0, "nodes": [0, -1, -1], "force": 1.0},
...          {"kind": "obstacle", "obstacle": 0, "nodes": [1, -1, -1], "force": 1.0}]
>>> g = grip_report(np.array([[1.0, 0.0], [-1.0, 0.0]]), {"pairs": pairs}, Disk((0, 0), 1.0), 0.5)
>>> g["held"], round(g["holding_force"], 6)        # squeezed from both sides: nothing sideways
(True, 0.0)
>>> round(g["resisted"][4], 6)                     # straight up (direction 4 of 16): mu N at each contact
1.0
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linprog

from ..core.checks import as_float_array, friction_coefficient
from .obstacles import Disk

__all__ = ["grip_report", "free_disk", "contact_points"]


def grip_report(x, contact: dict, disk, mu: float, obstacle: int = 0, load=None, directions: int = 16,
                rtol: float = 1e-3) -> dict:
    """The loads the contacts on ``disk`` (obstacle number ``obstacle`` of the solve) can resist at friction
    coefficient ``mu`` (module docstring).

    Parameters
    ----------
    x : (n, 2) the solved state (``result.x``).
    contact : the result's ``contact`` report.
    disk : the :class:`~mdsr_opt.Disk` of the solve (user units).
    mu : friction coefficient, >= 0.
    obstacle : its index among the solve's obstacles.
    load : (2,) a load on the disk (e.g. its weight), default none.
    directions : number of load directions tried, evenly spaced from +x counter-clockwise.
    rtol : the force balance is met to ``rtol`` times the largest normal force (a solve's net force on a
        free disk, :func:`free_disk`, is zero to about that).

    Returns
    -------
    dict
        ``mu``; per contact: ``normal_forces``, ``contact_points``, ``contact_nodes`` (the body's node that
        touches, or None where the disk touches a boundary segment between nodes) and ``contact_segments``
        (that segment's two nodes ``[a, b]``, None for a node contact); ``squeeze`` (the net force of the
        contacts' normal forces on the disk); ``directions`` (unit vectors) and ``resisted`` (the largest load
        in each that is held; 0.0 where none is, also where even no load is: a disk pushed harder one way than
        friction can hold, at ``mu = 0`` any net push); ``holding_force`` (the smallest of them: a load of any
        direction up to it is held; None when the disk is not held even without a load, as ``mdsr run``'s grip
        reports say); ``held`` (the load ``load`` is held; False when nothing touches the disk). Every figure
        is finite.
    """
    mu = friction_coefficient(mu, "mu")
    x = as_float_array(x, "x", shape=(None, 2))
    L = np.zeros(2) if load is None else as_float_array(load, "load", shape=(2,)).astype(float)
    pairs = [p for p in contact.get("pairs", []) if p["kind"] in ("obstacle", "obstacle segment") and
             p["obstacle"] == obstacle]
    c = np.asarray(disk.center, dtype=float)
    nodes = np.array([p["nodes"][0] for p in pairs], dtype=np.int64)  # -1: the disk on a segment
    pts = contact_points(x, pairs, c)
    N = np.array([p["force"] for p in pairs], dtype=float)
    n = (pts - c) / np.maximum(np.linalg.norm(pts - c, axis=1), 1e-300)[:, None] if len(nodes) else np.zeros((0, 2))
    t = np.column_stack([-n[:, 1], n[:, 0]]) if len(nodes) else np.zeros((0, 2))
    squeeze = -(N[:, None] * n).sum(0) if len(nodes) else np.zeros(2)
    angles = 2 * np.pi * np.arange(directions) / directions
    D = np.column_stack([np.cos(angles), np.sin(angles)])

    def largest(d, fixed_load=None):
        """max s with tangential forces balancing squeeze + s d (+ fixed_load); NaN when none balances."""
        k = len(nodes)
        # unknowns (tau_1 .. tau_k, s, e_x, e_y): maximise s; e the balance's slack, |e| <= atol
        A_eq = np.zeros((3, k + 3))
        A_eq[:2, :k] = t.T
        A_eq[2, :k] = 1.0
        A_eq[0, k + 1] = A_eq[1, k + 2] = 1.0
        b_eq = np.zeros(3)
        b_eq[:2] = -squeeze - (0.0 if fixed_load is None else fixed_load)
        if fixed_load is None:
            A_eq[:2, k] = d
        atol = rtol * float(N.max(initial=0.0))
        bounds = [(-mu * Ni, mu * Ni) for Ni in N] + [(0, None) if fixed_load is None else (0, 0)] + \
            [(-atol, atol)] * 2
        res = linprog(np.r_[np.zeros(k), -1.0, 0.0, 0.0], A_eq=A_eq, b_eq=b_eq, bounds=bounds, method="highs")
        if res.status == 3:  # unbounded: cannot happen with a load along d needing forces
            return np.inf
        # the slack could stand in for up to atol of the load: not counted as held
        return max(float(res.x[k]) - atol, 0.0) if res.status == 0 else np.nan

    if not len(pairs):  # nothing touches the disk: nothing holds it (as mdsr run's grip reports say)
        resisted, held_load, unloaded = np.full(len(D), np.nan), False, False
    else:
        resisted = np.array([largest(d) for d in D])
        held_load = not np.isnan(largest(None, L))
        unloaded = held_load if not L.any() else not np.isnan(largest(None, np.zeros(2)))  # held without a load
    seg = [p["kind"] == "obstacle segment" for p in pairs]
    return {"mu": float(mu), "contact_nodes": [None if s else int(v) for s, v in zip(seg, nodes)],
            "contact_segments": [[int(p["nodes"][1]), int(p["nodes"][2])] if s else None for s, p in zip(seg, pairs)],
            "contact_points": pts.tolist(), "normal_forces": N.tolist(),
            "squeeze": squeeze.tolist(), "directions": D.tolist(),
            # NaN (no load along d balances, not even none): nothing held there
            "resisted": np.where(np.isnan(resisted), 0.0, resisted).tolist(),
            "holding_force": float(np.nanmin(resisted)) + 0.0 if unloaded else None,
            "held": bool(held_load)}


def contact_points(x, pairs, center) -> np.ndarray:
    """Where each contact pair on a disk (``center``) touches the body in the state ``x`` (n, 2): a node pair's
    node; a segment pair's (``"obstacle segment"``, nodes ``[-1, a, b]``) point of the segment closest to the
    centre. (k, 2)."""
    out = np.zeros((len(pairs), 2))
    for i, p in enumerate(pairs):
        q, a, b = p["nodes"]
        if p["kind"] == "obstacle segment":
            d = x[b] - x[a]
            s = np.clip(float((center - x[a]) @ d) / max(float(d @ d), 1e-300), 0.0, 1.0)
            out[i] = x[a] + s * d
        else:
            out[i] = x[q]
    return out


#: the halvings of a secant step of :func:`free_disk` whose disk ``solve`` refuses (it holds a node of the body)
HALVINGS = 6


def free_disk(solve, disk, *, rtol: float = 1e-3, max_iter: int = 12):
    """Place a free disk where the grip holds it without a support: the centre at which the contacts' net
    force on it vanishes (to ``rtol`` times the largest contact force), by secant (Broyden) steps on the
    centre.

    Parameters
    ----------
    solve : callable
        ``solve(disk) -> EquilibriumResult`` of the body with the disk as its obstacle number 0 (e.g. a
        ``solve_internal`` of the gripper's muscles with ``obstacles=[disk]``). A step to a centre at which it
        raises ValueError (the solves refuse a disk that holds a node of the body at rest) is halved, up to
        :data:`HALVINGS` times; at the first centre the error is raised.
    disk : the :class:`~mdsr_opt.Disk` to start from (its radius is kept).

    Returns
    -------
    (EquilibriumResult, Disk, dict)
        The last solve, its disk and ``{"converged", "iterations", "net_force", "history"}``; ``converged``
        False (the net force named) when a solve fails or the force is not brought down.
    """
    c = np.asarray(disk.center, dtype=float)
    r = float(disk.radius)
    B = None
    history = []
    res, F, c_old, F_old = None, None, None, None
    last = None
    for it in range(max_iter):
        d = Disk(c, r)
        for _ in range(HALVINGS):
            try:
                res = solve(d)
                break
            except ValueError:  # the disk holds a node of the body at rest: the secant step halved
                if last is None:
                    raise
                last = 0.5 * last
                c = c_old + last
                d = Disk(c, r)
        else:
            return res, d, {"converged": False, "iterations": it + 1, "net_force": None, "history": history,
                            "why": f"the disk holds a node of the body at rest after {HALVINGS} halvings of the step"}
        if not res.success:
            return res, d, {"converged": False, "iterations": it + 1, "net_force": None, "history": history,
                            "why": res.status}
        F = np.asarray(res.contact["obstacle_forces"][0], dtype=float)
        scale = max([p["force"] for p in res.contact["pairs"]], default=0.0)
        history.append((c.tolist(), F.tolist()))
        if scale > 0 and np.linalg.norm(F) <= rtol * scale:
            return res, d, {"converged": True, "iterations": it + 1, "net_force": F.tolist(), "history": history}
        if scale == 0:  # nothing touches: the disk is not gripped
            return res, d, {"converged": False, "iterations": it + 1, "net_force": F.tolist(), "history": history,
                            "why": "the body does not touch the disk"}
        if B is None:  # the first step: along the push, a tenth of the radius
            step = 0.1 * r * F / np.linalg.norm(F)
        else:
            dc, dF = c - c_old, F - F_old
            B = B + np.outer(dF - B @ dc, dc) / max(float(dc @ dc), 1e-300)
            step = -np.linalg.lstsq(B, F, rcond=None)[0]
            if np.linalg.norm(step) > 0.25 * r:
                step *= 0.25 * r / np.linalg.norm(step)
        if B is None:
            B = -np.eye(2) * np.linalg.norm(F) / (0.1 * r)
        c_old, F_old, last = c, F, step
        c = c + step
    return res, Disk(c, r), {"converged": False, "iterations": max_iter, "net_force": F.tolist(),
                             "history": history, "why": "the net force did not vanish"}
