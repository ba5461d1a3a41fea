"""Load stepping with contact (:mod:`mdsr_opt.mechanics.contactsolve`): each step's candidate pairs refreshed
until none is new and the state is admissible, the last state held to the tolerance contract and checked
stable on the tangent space of its active rows, a saddle left along its negative curvature."""

from __future__ import annotations

import time

import numpy as np

from ..core.guards import check_stop, interruptible
from .backends import minimize
from .anchors import body_size
from .blas import one_blas_thread
from .contact import DELTA, RELEASE, ContactRows, first_touch_rows, handoff_rows
from ..core.checks import friction_coefficient, positive_float
from .contactsolve import (ContactProblem, ContactSpec, contact_residual, row_key, merge_rows, contact_stability,
                           polish)
from .contactfree import KEPT, contact_free_solve
from .friction import EPS as FRICTION_EPS, LAG_ITER, LAG_RTOL
from .loadsteps import INTERMEDIATE_TOL, equilibrium_result, min_jacobian, predict_state, solve_step, upright
from .obstacles import check_obstacles

__all__ = ["check_gap", "contact_continuation", "contact_report", "contact_spec", "solve_with_contact", "MAX_REFRESH",
           "DEFAULT_GAP"]

#: solves of one load step with refreshed pairs before it is given up (and halved)
MAX_REFRESH = 8

#: IPOPT's first barrier parameter in careful load steps (:func:`careful_options`; its default is 0.1)
MU_INIT = 1e-5


def careful_options(options: dict | None) -> dict:
    """The IPOPT options of a careful load step: ``options`` (which win) with the first barrier parameter
    :data:`MU_INIT`. A load step starts from an admissible state in which touching pairs sit at their gap, a
    slack of about ``gap``; IPOPT's default barrier of 0.1 pushes them apart with a force ``mu / slack``
    hundreds of times the elastic forces. Where a crease has formed its first iterates tear the crease open,
    and it may not come back within its iteration cap, or comes back to a state far from the step's start
    that crosses pairs the broad phase did not see."""
    return {"ipopt.mu_init": MU_INIT, **(options or {})}


def _empty(prob) -> ContactRows:
    return ContactRows(np.zeros((0, 3), dtype=np.int64), prob.mesh.n_nodes)


def contact_step(prob: ContactProblem, p, x_ref, guess, fixed, vals, tol, max_iter, options, final, loose,
                 rho: float = 0.0):
    """Solve one load step from ``guess`` (``x_ref``: the admissible state it started from) with pairs
    refreshed (module docstring of :mod:`~mdsr_opt.mechanics.contactsolve`): ``(outcome, rows)``. With
    ``rho > 0`` a proximal step (``rho/2 |x - x_ref|^2`` added to the energy). A pair whose point is beyond
    its segment's end is dropped and the segment the point slid to takes it over
    (:func:`~mdsr_opt.mechanics.contact.handoff_rows`); where the point already touches that segment, before
    the last load step, without a new solve (:func:`_hand_over`)."""
    rows = prob.rows_for(x_ref, [x_ref, guess])
    drop: set = set()
    its, t_solve, t_build = 0, 0.0, 0.0
    nm = prob.cm.n_rows if prob.cm is not None else 0
    start = guess
    out = None
    lags = 0
    handed = _empty(prob)
    warm = False  # the solve starts from the last one's state: admissible, its touching pairs at their gap
    for _ in range(MAX_REFRESH + LAG_ITER):
        check_stop()
        step_tol = tol if final else max(tol, loose)
        opts = careful_options(options) if warm else options
        fsel = prob.friction_rows(rows)
        lagged = np.array([prob.normal_lag.get(row_key(rows, i), 0.0) for i in fsel])
        prob.friction_term = prob.friction_for(rows, x_ref, lagged)
        if rho > 0:
            out = prob.minimize(rows, p, start, fixed, vals, step_tol, max_iter, opts, (rho, x_ref))
            lam_c = out.lam_g[nm:]
        elif rows.n_rows == 0:
            if final:
                out = solve_step(prob.mesh, prob.solver_model, p, start, fixed, vals, "ipopt", tol, max_iter, options)
            else:
                out = minimize(prob.solver_model, p, start, fixed, vals, backend="ipopt", tol=step_tol,
                               max_iter=max_iter, options=options)
            lam_c = np.zeros(0)
        else:
            out = prob.minimize(rows, p, start, fixed, vals, step_tol, max_iter, opts)
            lam_c = out.lam_g[nm:]
        its += out.iterations
        t_solve += out.solve_time
        t_build += out.build_time
        if not (out.success and upright(prob.mesh, out.x)):
            break
        x1 = out.x
        why = prob.penetrates(x1)
        new = merge_rows(rows, prob.rows_for(x_ref, [x_ref, guess, x1]), drop)
        if why is None:  # and the pairs of the solve's own state (admissible: the next solve starts from it), e.g.
            # a point come to a segment's end that projected beyond it where the step started, or a fold closed
            # within the solve whose point projected beyond the segment it now rests on
            new = merge_rows(new, prob.rows_for(x1, [x1]), drop)
        swapped, swap_in = set(), set()
        if rows.n_rows:  # a pair whose point is beyond its segment's end: its point handed to the segment it
            # slid to, the pair dropped unless its gap lets it go there (a released row, RELEASE: kept, for the
            # point may slide back within the step)
            t = rows.projections(x1)
            outside = ((t < -DELTA) | (t > 1 + DELTA)) & (rows.labels[:, 0] == 0)
            for i in np.flatnonzero(outside & (rows.w[:, 1] <= 0)):
                drop.add(row_key(rows, i))
            if outside.any():
                hand, swapped, swap_in = _hand_over(prob, rows, np.flatnonzero(outside), t, x1, step_tol, final)
                new = merge_rows(new, hand, drop)
                handed = merge_rows(handed, hand)  # kept for a crossing no pair prevents
        keys_old = {row_key(rows, i) for i in range(rows.n_rows)}
        nxt = x1 if why is None else start  # the state the next solve starts from
        new = _admissible(prob, new, nxt, keys_old)
        keys_new = {row_key(new, i) for i in range(new.n_rows)}
        grew = bool(keys_new - keys_old - swap_in) or bool(keys_old - keys_new - swapped)
        if why is not None and not grew and prob.spec.self_contact:  # the pairs a fold within the step brought
            new = merge_rows(merge_rows(new, handed, drop), first_touch_rows(prob.mesh, x_ref, x1,
                                                                              1e-9 * prob.mesh.size,
                                                                              release=prob.release), drop)
            new = _admissible(prob, new, nxt, keys_old)
            grew = {row_key(new, i) for i in range(new.n_rows)} != keys_old
        if why is None and not grew:
            if len(fsel):  # the lagged normal forces: solved again until they stop changing
                N = lam_c[fsel]
                change = float(np.abs(N - lagged).max()) / max(float(N.max()), 1e-300)
                for i, Ni in zip(fsel, N):
                    prob.normal_lag[row_key(rows, i)] = float(Ni)
                prob.lag_error = change
                if change > LAG_RTOL and lags < LAG_ITER:
                    lags += 1
                    start = x1
                    continue
                if change > LAG_RTOL:
                    out.success = False
                    out.status += f"; the lagged normal forces still change by {change:.3g} after {lags} solves"
                    break
            out.iterations, out.solve_time, out.build_time = its, t_solve, t_build
            return out, rows
        if why is not None and not grew:
            out.success = False
            out.status += f"; rejected: {why} and no new contact pair to prevent it"
            break
        rows = new
        if why is None:  # the next solve from this one's state, IPOPT's barrier started at MU_INIT: its default
            # (0.1) pushes the touching pairs apart with forces hundreds of times the elastic ones, and where a
            # fold has closed within the solve it tears the fold open again
            start, warm = x1, True
    if out is not None and out.success:
        out.success = False
        out.status += f"; contact pairs still changing after {MAX_REFRESH} solves"
    out.iterations, out.solve_time, out.build_time = its, t_solve, t_build
    return out, rows


def _admissible(prob, rows: ContactRows, start, keep) -> ContactRows:
    """In careful load steps (``prob.release > 0``), ``rows`` without the rows new to the step's set (keys not
    in ``keep``) that the state ``start`` the next solve starts from violates (gap below the stated one): a
    pair taken from a crossing state (a handed-over point, a first touch along the path) whose point lies
    inside its segment's line at the start. IPOPT started from such a row's violation (at the turn's crease
    mouth and clamped corner, 0.03-0.16) spent its iteration cap in the restoration phase, every step halving
    cutting back at inverted elements; without the row the crossing it was for is found again or the step is
    rejected and halved. Outside careful steps ``rows`` as given."""
    if prob.release <= 0 or not rows.n_rows:
        return rows
    g = rows.values(start) - prob.spec.gap
    bad = {row_key(rows, i) for i in np.flatnonzero(g < -1e-9 * prob.mesh.size)} - set(keep)
    return merge_rows(rows, _empty(prob), bad) if bad else rows


def _hand_over(prob, rows, which, t, x1, tol, final):
    """The rows that take over from the rows ``which`` whose points (projections ``t``) are beyond their
    segments' ends in the solve's state ``x1``: ``(rows, keys swapped out, keys swapped in)``. A point's new
    segment is the one its closest boundary point moved to (:func:`~mdsr_opt.mechanics.contact.handoff_rows`).
    Before the last load step (``final`` False), where the point already touches that segment in ``x1``
    (projecting onto it, its gap within the stated gap, or ``100 tol`` of the size, of the bound) the state
    needs no new solve for it: the pair is swapped (a point sliding along a face past several of its
    segments within one load step, as on a fine mesh)."""
    gtol = max(prob.spec.gap, 100.0 * tol * prob.mesh.size)
    hand, out, inn = _empty(prob), set(), set()
    for i in which:
        h = handoff_rows(prob.mesh, rows, [i], [t[i]], x1, release=prob.release)
        if not h.n_rows:
            continue
        hand = merge_rows(hand, h)
        th = float(h.projections(x1)[0])
        if not final and abs(float(h.values(x1)[0]) - prob.spec.gap) <= gtol and -DELTA <= th <= 1 + DELTA:
            out.add(row_key(rows, i))
            inn.add(row_key(h, 0))
    return hand, out, inn


def _kick(prob, p, x, direction, fixed, amp):
    d = direction.reshape(-1, 2)
    a0 = amp * prob.mesh.size / max(float(np.linalg.norm(d, axis=1).max()), 1e-300)
    best = None
    for sign in (1.0, -1.0):
        a = a0
        for _ in range(8):
            y = x + sign * a * direction
            if min_jacobian(prob.mesh, y) > 0.0 and prob.penetrates(y) is None:
                e = prob.solver_model.energy(y, p)
                if np.isfinite(e) and (best is None or e < best[0]):
                    best = (e, y)
                break
            a /= 2
    return None if best is None else best[1]


#: the proximal steps of a saddle escape (:func:`_descend`): the first weight (relative to ``E t``), its
#: decrease per accepted step and the weight below which the plain solve takes over
PROX_START, PROX_FACTOR, PROX_END = 1e-1, 0.25, 1e-4


def _descend(prob, p, x, y, fixed, vals, tol, max_iter, options, loose):
    """From the kicked state ``y`` near the saddle ``x``, proximal steps (:func:`contact_step` with
    ``rho > 0``), each from the last admissible state, with the weight lowered after each accepted step and
    raised after a rejected one: the body moves away from the saddle in steps short enough for the broad
    phase to see every pair it closes. ``(state, iterations)``; state None when no step is accepted."""
    rho, xr, its, ok = PROX_START, np.array(y, dtype=float), 0, False
    guess = y
    for _ in range(60):
        check_stop()
        if rho < PROX_END:
            break
        out, _r = contact_step(prob, p, xr, guess, fixed, vals, tol, max_iter, options, False, loose, rho)
        its += out.iterations
        if out.success:
            step = float(np.abs(out.x - xr).max())
            xr, guess, ok = out.x, out.x, True
            rho *= PROX_FACTOR
            if step < 1e-6 * prob.mesh.size and rho < 1e-2:
                break
        else:
            rho *= 10.0
            if rho > 1e4:
                break
    return (xr if ok else None), its


def _escape(prob, p, x, rows, res, fc, fixed, vals, tol, max_iter, options, loose, force, final):
    """Check the state's stability (:func:`~mdsr_opt.mechanics.contactsolve.contact_stability`) and leave a
    saddle along its negative curvature (a kick, proximal steps, a solve), up to 4 times:
    ``(x, rows, res, forces, check, tries, iterations)``. ``final``: the re-solves are held to ``tol``
    (else to ``loose``, for a state that only starts the next load step)."""
    chk = contact_stability(prob, rows, x, p, fixed, res, fc)
    tries, amp, its = 0, 0.02, 0
    while not chk.stable and tries < 4 and chk.direction is not None:
        check_stop()
        tries += 1
        y = _kick(prob, p, x, chk.direction, fixed, amp)
        if y is None:
            break
        y, it = _descend(prob, p, x, y, fixed, vals, tol, max_iter, options, loose)
        its += it
        if y is None:
            amp /= 2
            continue
        out, r = contact_step(prob, p, y, y, fixed, vals, tol, max_iter, options, final, loose)
        its += out.iterations
        if not out.success:
            amp /= 2
            continue
        step_tol = tol if final else max(tol, loose)
        y2, res2, fc2 = polish(prob, r, out.x, p, fixed, step_tol, force, out.lam_g if r.n_rows else None)
        if not res2.value <= step_tol:
            amp /= 2
            continue
        x, rows, res, fc = y2, r, res2, fc2
        chk = contact_stability(prob, rows, x, p, fixed, res, fc)
    return x, rows, res, fc, chk, tries, its


def contact_continuation(prob: ContactProblem, p_of, fixed, values_of, x_start, tol, max_iter, options, min_step,
                         verbose, predict=True, settle=True, loose=None, force=1.0, max_step=1.0, escape=True):
    """Load stepping with contact: ``dict(x, status, success, iterations, steps, solve_time, build_time, rows,
    residual (Residual), forces, stability)``."""
    loose = INTERMEDIATE_TOL if loose is None else float(loose)
    mesh = prob.mesh
    with interruptible(), one_blas_thread():
        x = np.array(x_start, dtype=float)
        why = prob.penetrates(x)
        if why is not None:
            raise ValueError(f"the state the solve starts from is not admissible: {why}")
        s, ds = 0.0, max_step
        steps, iters, t_solve, t_build, status = [], 0, 0.0, 0.0, "not started"
        rows = _empty(prob)
        lam_last = None
        careful = False  # switched on by a load step about to stall (careful_options, released rows)
        prob.release = 0.0
        while s < 1.0 - 1e-12:
            check_stop()
            if ds < min_step:  # the state returned is the last one solved: its contact forces fitted there
                fc_s = contact_residual(prob, rows, x, p_of(s), fixed, max(float(np.sqrt(tol)), loose), force)[1] \
                    if rows.n_rows else None
                return _out(x, f"load stepping stalled at fraction {s:.4g} ({status})", False, iters, steps,
                            t_solve, t_build, rows, forces=fc_s, fraction=s)
            s_new = min(1.0, s + ds)
            p, vals = p_of(s_new), values_of(s_new)
            t0 = time.perf_counter()
            guess = predict_state(prob.solver_model, p, x, fixed, vals) if predict and not (careful and rows.n_rows) \
                else None
            t_solve += time.perf_counter() - t0
            plain = x.copy()  # the state the step starts from with only the fixed nodes moved
            plain[fixed] = vals
            predicted = True
            if guess is None or min_jacobian(mesh, guess) <= 0.0 or prob.penetrates(guess) is not None:
                guess, predicted = plain, False
                if min_jacobian(mesh, guess) <= 0.0:
                    status = "first guess inverts an element"
                    ds /= 2
                    continue
            cap = max_iter if ds < 4 * min_step else min(max_iter, 100)
            opts = careful_options(options) if careful else options
            out, r = contact_step(prob, p, x, guess, fixed, vals, tol, cap, opts, s_new >= 1.0, loose)
            if not out.success and (careful and predicted or not careful and ds / 2 < min_step) and \
                    min_jacobian(mesh, plain) > 0.0:
                # about to stall (or already careful): from here on careful steps (careful_options), each from
                # the state it starts from where the body touches itself. The Newton predictor models no
                # contact: at a crease it can move nodes many elements for a short load step, and the pairs
                # the broad phase then admits hold a state far from this one
                first, careful = out, True
                opts, prob.release = careful_options(options), RELEASE
                out, r = contact_step(prob, p, x, plain, fixed, vals, tol, cap, opts, s_new >= 1.0, loose)
                out.iterations += first.iterations
                out.solve_time += first.solve_time
                out.build_time += first.build_time
                if out.success:
                    guess = plain
            lam_last = out.lam_g if r.n_rows else None
            iters += out.iterations
            t_solve += out.solve_time
            t_build += out.build_time
            if not out.success and (escape and ds <= 4 * min_step or careful and ds / 2 < min_step) and \
                    guess is not None:
                # a step this short still fails: the state jumps (a crease snapping in) at any load past this one.
                # The jump followed by proximal steps, short enough for the broad phase to see each pair it closes
                # (in careful load steps of the first attempt too, when the next halving would stall)
                y, it = _descend(prob, p, x, guess, fixed, vals, tol, max_iter, opts, loose)
                iters += it
                if y is not None:
                    out2, r2 = contact_step(prob, p, y, y, fixed, vals, tol, max_iter, opts, s_new >= 1.0, loose)
                    iters += out2.iterations
                    if out2.success:
                        out, r = out2, r2
                        lam_last = out.lam_g if r.n_rows else None
            status = out.status
            if out.success and s_new < 1.0 and settle and escape:  # a buckling body leaves the unstable branch early
                lam0 = out.lam_g if r.n_rows else None
                xs, res_s, fc_s = polish(prob, r, out.x, p, fixed, max(tol, loose), force, lam0)
                xs, r, _res, _fc, chk_s, tries_s, it = _escape(prob, p, xs, r, res_s, fc_s, fixed, vals, tol, max_iter,
                                                              opts, loose, force, False)
                iters += it
                if tries_s:
                    out.x = xs
                    lam_last = None
            if out.success:
                x, s, rows = out.x, s_new, r
                steps.append(s)
                if verbose:
                    print(f"  load {s:.4f}: {out.status}, {out.iterations} iterations, {r.n_rows} contact pairs")
                ds = min(2 * ds, 1.0 - s, max_step) if s < 1.0 else ds
            else:
                ds /= 2
        p1 = p_of(1.0)
        x, res, fc = polish(prob, rows, x, p1, fixed, tol, force, lam_last)
        if not res.value <= tol:  # the forces reported: fitted on the rows within sqrt(tol) of their gap (an
            # interior point leaves touching rows 1e-8 to 1e-7 of the size off it: within tol none may be held)
            fc_r = contact_residual(prob, rows, x, p1, fixed, max(float(np.sqrt(tol)), tol), force)[1] \
                if rows.n_rows else fc
            return _out(x, status + f"; rejected: residual {res.value:.3g} > tol {tol:.3g}", False, iters, steps,
                        t_solve, t_build, rows, res, fc_r)
        if not settle:
            return _out(x, status, True, iters, steps, t_solve, t_build, rows, res, fc)
        if escape:
            x, rows, res, fc, chk, tries, it = _escape(prob, p1, x, rows, res, fc, fixed, values_of(1.0), tol,
                                                       max_iter, careful_options(options) if careful else options,
                                                       loose, force, True)
        else:
            chk, tries, it = contact_stability(prob, rows, x, p1, fixed, res, fc), 0, 0
        iters += it
        ok = bool(chk.stable)
        if ok and tries:
            status += f"; left a saddle along its negative curvature ({tries} re-solve(s))"
        if not ok:
            status += (f"; rejected: not a stable equilibrium ({chk.n_negative} negative, {chk.n_zero} zero "
                       f"curvature directions on the tangent space of the active contacts and ropes)")
        return _out(x, status, ok, iters, steps, t_solve, t_build, rows, res, fc, chk)


def _out(x, status, ok, iters, steps, t_solve, t_build, rows, res=None, forces=None, chk=None,
         fraction=1.0) -> dict:
    return {"x": x, "status": status, "success": ok, "iterations": iters, "steps": steps, "solve_time": t_solve,
            "build_time": t_build, "rows": rows, "residual": res, "forces": forces, "stability": chk,
            "fraction": fraction}


_KINDS = {0: "self", 1: "obstacle", 2: "obstacle corner", 3: "inner", 4: "crease", 5: "obstacle segment"}


def contact_report(prob: ContactProblem, out: dict, length: float = 1.0, force: float = 1.0) -> dict:
    """The contact part of a result (JSON-ready, in the user's units: lengths times ``length``, forces times
    ``force``): per active pair its kind, nodes (``p, a, b``; -1 for an obstacle's fixed point), obstacle,
    gap and normal force; the contact force on each node and the total on each obstacle (the force the body
    exerts on it). ``load_fraction``: the load at which the state was solved (below 1 when the load stepping
    stalled: the forces are those of the state returned, at that load); ``forces_known`` False when the
    forces of the state's touching rows (listed with force None) could not be fitted."""
    rows, fc, x = out["rows"], out["forces"], out["x"]
    n = prob.mesh.n_nodes
    known = fc is not None or rows.n_rows == 0
    if fc is None or rows.n_rows == 0:
        fc = np.zeros(rows.n_rows)
    g = rows.values(x) if rows.n_rows else np.zeros(0)
    nodes = np.where(rows.pts < n, rows.pts, -1)
    node_f = rows.node_forces(x, fc) if rows.n_rows else np.zeros((n, 2))
    per_ob = np.zeros((len(prob.spec.obstacles), 2))
    for k in range(len(prob.spec.obstacles)):
        sel = rows.labels[:, 1] == k
        if sel.any():
            per_ob[k] = -(rows.jacobian(x)[sel].T @ fc[sel]).reshape(-1, 2).sum(0)
    act = fc > 0
    if not known:  # the rows at their gap (within 1e-6 of the size), forces unknown
        act = g - prob.spec.gap <= 1e-6 * prob.mesh.size
    fr = None
    if prob.friction_term is not None and prob.spec.friction > 0:  # the friction force on the body: -grad D
        tf = prob.friction_term  # with the lagged normal forces the equilibrium holds with
        if len(tf.nodes) == len(prob.friction_rows(rows)):
            gfr = tf.gradient(x).reshape(-1, 2)
            node_f = node_f - gfr
            sel = prob.friction_rows(rows)
            for k in range(len(prob.spec.obstacles)):
                mine = rows.labels[sel, 1] == k
                per_ob[k] += np.array([np.sum(tf.forces(x)[mine] * tf.t[mine, 0]),
                                       np.sum(tf.forces(x)[mine] * tf.t[mine, 1])])
    term = prob.friction_term
    if prob.spec.friction > 0:
        sel = prob.friction_rows(rows)
        if term is not None and len(term.nodes) != len(sel):
            term = None
        fr = {"mu": prob.spec.friction, "eps": FRICTION_EPS * prob.mesh.size * length, "lag_error": prob.lag_error,
              "nodes": [] if term is None else term.nodes.tolist(),  # -1: a point on a segment (a disk's)
              "segments": [] if term is None else [None if q >= 0 else [int(a), int(b), float(wb)] for q, (a, b), wb
                                                   in zip(term.nodes, term.pairs, term.weights[:, 1])],
              "tangential": [] if term is None else (term.forces(x) * force).tolist(),
              "normal": [] if term is None else (term.N * force).tolist(),
              "slipping": [] if term is None else term.slipping(x).tolist(),
              "step_slide": [] if term is None else (term.tangential_move(x) * length).tolist()}
    return {"gap": prob.spec.gap * length, "friction": fr, "load_fraction": float(out.get("fraction", 1.0)),
            "forces_known": bool(known),
            "pairs": [{"kind": _KINDS[int(rows.labels[i, 0])], "nodes": nodes[i].tolist(),
                       "obstacle": int(rows.labels[i, 1]), "gap": float(g[i]) * length,
                       "force": float(fc[i]) * force if known else None} for i in np.flatnonzero(act)],
            "n_candidates": int(rows.n_rows),
            "node_forces": (node_f * force).tolist(),
            "obstacle_forces": (per_ob * force).tolist(),
            "total_force": float(fc[act].sum()) * force}


def contact_spec(units, obstacles, contact, contact_gap, backend, friction=0.0):
    """The :class:`~mdsr_opt.mechanics.contactsolve.ContactSpec` of a solve's keywords on its unit body
    (``obstacles`` checked by :func:`~mdsr_opt.mechanics.obstacles.check_obstacles` against the body at rest),
    refused at the door when contact is asked of a backend other than ``"ipopt"``."""
    if not isinstance(contact, (bool, np.bool_)):
        raise TypeError(f"contact must be True or False, got {contact!r}")
    obs = check_obstacles(obstacles, units.mesh)
    if contact_gap is None:
        gap = DEFAULT_GAP * body_size(units.unit_mesh)
    else:
        gap = units.to_unit(check_gap(positive_float(contact_gap, "contact_gap"), body_size(units.mesh)))
    friction = friction_coefficient(friction)
    if friction > 0 and not obs:
        raise ValueError("friction acts between the body and obstacles: give obstacles")
    spec = ContactSpec([o.scaled(1.0 / units.length, np.zeros(2)) for o in obs], bool(contact), float(gap),
                       float(friction))
    if spec.active and backend != "ipopt":
        raise ValueError(f"contact (obstacles or contact=True) is solved with backend 'ipopt' only, got {backend!r}")
    return spec


#: the longest load step of a contact solve's second attempt (the first takes load steps as long as they
#: converge and leaves no saddle): a strip clamped at both ends and pushed by 50 % buckles and folds onto
#: itself; from the straight state at full load no saddle escape found a stable state, in steps of 1/8 it
#: leaves the unstable branch as soon as it buckles
RETRY_STEP = 0.125

#: the default gap a contact keeps, relative to the body's size (its diameter,
#: :func:`~mdsr_opt.mechanics.anchors.body_size`, the same however the body is turned)
DEFAULT_GAP = 1e-4

#: the largest contact gap, as a fraction of the body's size: a gap is a small clearance between touching parts
MAX_GAP = 0.1


def check_gap(gap: float, size: float) -> float:
    """``gap`` (the self-contact gap, in the body's units) if it is below :data:`MAX_GAP` of the body's
    ``size``; else a ``ValueError`` naming both."""
    if gap >= MAX_GAP * size:
        raise ValueError(f"contact_gap {gap:g} is {gap / size:.0%} of the body's size {size:.4g}: it is the small "
                         f"clearance kept between touching parts (default {DEFAULT_GAP:g} of the size); give less "
                         f"than {MAX_GAP:g} of the size")
    return gap


def _with_contact(prob, p_of, fixed, values_of, x_start, tol, max_iter, options, min_step, verbose, predict, settle,
                  loose, F) -> dict:
    """The contact solve (:func:`contact_continuation`): in long load steps, and if that fails again in short ones
    with a saddle left at any of them."""
    out = contact_continuation(prob, p_of, fixed, values_of, x_start, tol, max_iter, options, min_step, verbose,
                               predict, settle, loose, F, escape=False)
    if not out["success"]:  # again in short load steps, a saddle left at any of them
        first = out
        out = contact_continuation(prob, p_of, fixed, values_of, x_start, tol, max_iter, options, min_step, verbose,
                                   predict, settle, loose, F, max_step=RETRY_STEP, escape=True)
        for k in ("iterations", "solve_time", "build_time"):
            out[k] += first[k]
        if not out["success"]:
            out["status"] += f" (after a first attempt in long load steps: {first['status']})"
    return out


def solve_with_contact(mesh, model, material, p_of, fixed, values_of, x_start, spec, tol, max_iter, options,
                       min_step, verbose, predict, mode, units, cm=None, settle=True, loose=None,
                       p_elastic=None, t_model=0.0):
    """The checked :class:`~mdsr_opt.mechanics.result.EquilibriumResult` (unit body) of a solve with contact,
    with its ``contact`` report in the user's units (:func:`contact_report`), and the fitted muscle rows'
    multipliers (None without them)."""
    prob = ContactProblem(mesh, model, spec, cm)
    F = material.E * material.thickness * mesh.size
    # the contact-free solve first, kept when nothing touches along its path (zero multipliers: a KKT point of
    # the contact problem); else the contact solve from the same start, as without that first try
    out, spent, why = contact_free_solve(prob, p_of, fixed, values_of, x_start, tol, max_iter, options, min_step,
                                         verbose, predict, settle, loose, F)
    if out is not None:
        if verbose:
            print(f"  {KEPT}")
    else:
        if verbose and why:
            print(f"  contact-free solve not kept ({why}): solving with contact")
        out = _with_contact(prob, p_of, fixed, values_of, x_start, tol, max_iter, options, min_step, verbose,
                            predict, settle, loose, F)
        for k in ("iterations", "solve_time", "build_time"):
            out[k] += spent[k]
    p1 = p_of(1.0)
    resid = out["residual"]
    value = resid.value if resid is not None else np.inf
    res = equilibrium_result(mesh, prob.solver_model, material, p1, p1 if p_elastic is None else p_elastic,
                             out["x"], fixed, out["status"], out["success"], out["iterations"], out["steps"],
                             t_model + out["build_time"], out["solve_time"], "ipopt", mode, tol,
                             check_stability=False, residual=value)
    chk = out["stability"]
    if chk is not None:
        res.stable, res.stability = bool(chk.stable), units.stability_out(chk).summary()
    res.contact = contact_report(prob, out, units.length, units.force)
    return res, (None if resid is None else resid.lam)
