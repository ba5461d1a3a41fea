"""Equilibria with contact: the energy minimised with the contact gaps of :mod:`mdsr_opt.mechanics.contact` as
inequality constraints (``g >= gap``) beside any muscle constraints, solved by IPOPT through CasADi.

Each load step starts from a state without penetration. Its candidate pairs come from the broad phase
(:func:`~mdsr_opt.mechanics.contact.broad_phase`, within a radius that grows with the step's motion); after a
solve the pairs are looked for again in the new state, and the step is solved again with the union, until no
new pair appears, no pair holds a point beyond its segment's end, and the boundary does not cross itself
(:meth:`~mdsr_opt.Mesh.boundary_crosses`) nor enters an obstacle. A step with no candidate pair is solved as
without contact.

The tolerance contract (:mod:`mdsr_opt.mechanics.residual`) takes the contact rows in: the multipliers of the
muscle rows and of the contact rows within ``tol`` of their gap are fitted together by least squares (ropes
only pulling, contacts only pushing), and the residual is ``max(stationarity, violation)`` with the contact
rows' violation ``(gap - g)_+ / size``. The contact forces are those multipliers. Only a stable state is a
success: the Hessian of the Lagrangian positive definite on the tangent space of the active rows (rigid
patches, taut ropes, contacts that push).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp
from scipy.linalg import qr
from shapely.geometry import Point, Polygon

from ..core.guards import interruptible
from .assembly import ipopt_functions
from .contact import ContactRows, broad_phase
from .friction import EPS as FRICTION_EPS, FrictionTerm, friction_expr, friction_params, n_friction_params
from .kkt import kkt_factor
from .loadsteps import upright
from .residual import Residual, ipopt_tolerances
from .result import MinimizeOutcome, solver_status
from .ropesolve import pinned_bounds
from .stability import check_stability
from .stopping import with_stop_callback

__all__ = ["ContactSpec", "ContactProblem", "contact_residual", "polish", "contact_stability", "merge_rows",
           "row_key"]


@dataclass
class ContactSpec:
    """What contact a solve models (on the unit body): ``obstacles`` (list), ``self_contact``, ``gap`` and
    ``friction``."""

    obstacles: list
    self_contact: bool
    gap: float
    friction: float = 0.0  #: Coulomb coefficient between body and obstacles (:mod:`~mdsr_opt.mechanics.friction`)

    @property
    def active(self) -> bool:
        return bool(self.obstacles) or self.self_contact


class ContactProblem:
    """The equilibrium problem of ``model`` (an energy model, or a
    :class:`~mdsr_opt.mechanics.constrained.ConstrainedModel` ``cm`` with muscle rows) with contact ``spec``."""

    def __init__(self, mesh, model, spec: ContactSpec, cm=None):
        self.mesh, self.model, self.cm, self.spec = mesh, model, cm, spec
        self.solver_model = cm if cm is not None else model
        seg = mesh.boundary_edges
        self.h = float(np.mean(np.hypot(*(mesh.points[seg[:, 1]] - mesh.points[seg[:, 0]]).T)))
        self._solvers: dict = {}
        self.friction_term = None  # the step's FrictionTerm (contact_step sets it), None without friction
        self.normal_lag: dict = {}  # row key -> the normal force the friction of the next solve takes
        self.lag_error = 0.0  # the last step's relative change of the lagged normal forces
        self.release = 0.0  # the release weight of new self-contact rows (contact.RELEASE in careful load steps)

    def friction_rows(self, rows: ContactRows) -> np.ndarray:
        """The rows that carry friction: a body node against an obstacle, a disk against a body segment (none
        without friction)."""
        if self.spec.friction <= 0 or not rows.n_rows:
            return np.zeros(0, dtype=np.int64)
        return np.flatnonzero((rows.labels[:, 0] == 1) | (rows.labels[:, 0] == 5))

    @staticmethod
    def friction_points(rows: ContactRows, sel) -> np.ndarray:
        """The body node pairs (k, 2) of the friction rows ``sel``: a node twice, a disk-segment row's segment."""
        P = rows.pts[sel]
        return np.where((rows.w[sel, 0] == 4.0)[:, None], P[:, 1:], P[:, [0, 0]])

    def friction_for(self, rows: ContactRows, x0, N) -> FrictionTerm | None:
        """The :class:`~mdsr_opt.mechanics.friction.FrictionTerm` of ``rows`` from the step's start ``x0`` with
        lagged normal forces ``N`` (one per friction row); None without friction rows."""
        sel = self.friction_rows(rows)
        if not len(sel):
            return None
        z = np.concatenate([np.asarray(x0, dtype=float).reshape(-1), rows.consts.reshape(-1)]).reshape(-1, 2)
        pts = rows.pts[sel]
        disk = rows.w[sel, 0] == 1.0
        onseg = rows.w[sel, 0] == 4.0  # the disk's centre p against the segment (a, b): the point it touches
        a, b = z[pts[:, 1]], z[pts[:, 2]]
        ts = np.clip(((z[pts[:, 0]] - a) * (b - a)).sum(1) / np.maximum(((b - a) ** 2).sum(1), 1e-300), 0.0, 1.0)
        t = np.where(disk[:, None], z[pts[:, 0]] - a, b - a)
        t[onseg] = a[onseg] + ts[onseg, None] * (b - a)[onseg] - z[pts[onseg, 0]]
        t[disk | onseg] = np.column_stack([-t[disk | onseg, 1], t[disk | onseg, 0]])
        t /= np.maximum(np.linalg.norm(t, axis=1), 1e-300)[:, None]
        wts = np.column_stack([np.where(onseg, 1.0 - ts, 1.0), np.where(onseg, ts, 0.0)])
        return FrictionTerm(self.friction_points(rows, sel), t, x0, N, self.spec.friction,
                            FRICTION_EPS * self.mesh.size, wts)

    # ------------------------------------------------------------------ pieces
    def split(self, p):
        """``(energy parameters, rope targets or None)`` of the solver model's parameters ``p``."""
        if self.cm is None:
            return np.asarray(p, dtype=float), None
        pe, targets, _ = self.cm.split(p)
        return pe, (targets if self.cm.n_targets else None)

    def rows_for(self, x_ref, states, extra: float = 0.0) -> ContactRows:
        move = max(float(np.abs(np.asarray(s).reshape(-1) - np.asarray(x_ref).reshape(-1)).max()) for s in states)
        radius = 0.5 * self.h + 2.0 * move + self.spec.gap + extra
        return broad_phase(self.mesh, x_ref, states, radius, self.spec.obstacles, self.spec.self_contact,
                           tol=1e-9 * self.mesh.size, release=self.release)

    def penetrates(self, x) -> str | None:
        """Why ``x`` (2n,) is not admissible (a crossing, a node inside an obstacle), or None."""
        X = np.asarray(x, dtype=float).reshape(-1, 2)
        if self.spec.self_contact and self.mesh.boundary_crosses(X):
            return "the boundary crosses itself"
        bn = self.mesh.boundary_nodes
        body = None
        for k, ob in enumerate(self.spec.obstacles):
            g = ob.gap(X[bn])
            if g.min() < 0:
                return f"node {int(bn[int(np.argmin(g))])} inside obstacle {k}"
            if ob.kind == "disk":  # a boundary segment cutting into a disk between two nodes outside it
                seg = self.mesh.boundary_edges
                gs = ob.segment_gap(X[seg[:, 0]], X[seg[:, 1]])
                if gs.min() < 0:
                    return f"boundary segment {seg[int(np.argmin(gs))].tolist()} cuts into obstacle {k}"
            inner = getattr(ob, "inner_point", None)
            if inner is not None:  # an obstacle between the nodes, inside the body (passed through it)
                if body is None:
                    loops = self.mesh.boundary_loops
                    body = Polygon(X[loops[0]], [X[lp] for lp in loops[1:]])
                if body.is_valid and body.contains(Point(*inner)):
                    return f"obstacle {k} inside the body"
        return None

    # ------------------------------------------------------------------ the NLP
    def _solver(self, rows: ContactRows, tol: float, max_iter: int, options: dict | None):
        key = (rows.key(), float(tol), int(max_iter), repr(sorted((options or {}).items())))
        if key in self._solvers:
            return self._solvers[key], 0.0
        t0 = time.perf_counter()
        model, cm = self.model, self.cm
        n = model.n_dof
        x, p = ca.MX.sym("x", n), ca.MX.sym("p", model.n_params)
        xr, rho = ca.MX.sym("xr", n), ca.MX.sym("rho")  # the proximal term rho/2 |x - xr|^2
        lam_f = ca.MX.sym("lam_f")
        nm = cm.n_rows if cm is not None else 0
        lam_g = ca.MX.sym("lam_g", nm + rows.n_rows)
        numeric = getattr(model, "is_numeric", False)
        o = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes", **ipopt_tolerances(tol),
             "ipopt.max_iter": int(max_iter), "ipopt.linear_solver": "mumps", "error_on_fail": False,
             "calc_lam_p": False, "calc_lam_x": False, "ipopt.fixed_variable_treatment": "make_parameter_nodual",
             "ipopt.bound_relax_factor": 0.0, "show_eval_warnings": False}
        o.update(options or {})
        o = with_stop_callback(o)
        if numeric:
            fns = ipopt_functions(model)
            fe, ge = fns["grad_f"](x, p)
            o["no_nlp_grad"] = True
        else:
            fe, ge = model.grad_fn(x, p)
        prox = rho / 2 * ca.sumsqr(x - xr)
        fsel = self.friction_rows(rows)
        if len(fsel) and "ipopt.max_soc" not in (options or {}):
            # no second-order corrections with friction: where a contact slips the friction potential is all but
            # linear (its curvature mu N eps^2 / |u|^3), and steps made with a correction jumped across its kink
            # and back, accepted as lowering the infeasibility, until the iteration cap (a C's jaws closed on a
            # disk at mu 0.3: 57,454 iterations in all, the load stepping stalled)
            o["ipopt.max_soc"] = 0
        FP = ca.MX.sym("fp", n_friction_params(len(fsel)))
        fr = friction_expr(x, self.friction_points(rows, fsel), FP)
        f = fe + prox + fr
        P = ca.vertcat(p, xr, rho, FP)
        gf = ge + rho * (x - xr) + (ca.gradient(fr, x) if len(fsel) else 0)
        o["grad_f"] = ca.Function("contact_grad_f", [x, P], [f, gf], ["x", "p"], ["f", "grad"])
        gc = rows.expr(x)
        Jc = ca.jacobian(gc, x)
        lam_c = lam_g[nm:]
        Hc = ca.triu(ca.hessian(ca.dot(lam_c, gc), x)[0]) if rows.n_rows else ca.MX(n, n)
        if cm is not None:
            if numeric:
                cf = cm.numeric_functions()
                gm = cf["g"](x, p)
                Jm = cf["jac_g"](x, p)[1]
                He = cf["hess_lag"](x, p, lam_f, lam_g[:nm])
            else:
                gm = cm.nlp_constraints_expr(x)
                Jm = cm.nlp_jacobian_expr(x)
                He = cm.hess_lag_upper(x, p, lam_f, lam_g[:nm])
            g = ca.vertcat(gm, gc)
            J = ca.vertcat(Jm, Jc)
        else:
            He = fns["hess_lag"](x, p, lam_f, ca.MX(0, 1)) if numeric else model.hess_lag_fn(x, p, lam_f, ca.MX(0, 1))
            g, J = gc, Jc
        if g.size1():
            o["jac_g"] = ca.Function("contact_jac_g", [x, P], [g, J])
        Hp = lam_f * rho * ca.DM(ca.Sparsity.diag(n), 1.0)
        if len(fsel):
            Hp = Hp + lam_f * ca.triu(ca.hessian(fr, x)[0])
        o["hess_lag"] = ca.Function("contact_hess_lag", [x, P, lam_f, lam_g], [He + Hc + Hp],
                                    ["x", "p", "lam_f", "lam_g"], ["hess"])
        solver = ca.nlpsol("contact_equilibrium", "ipopt", {"x": x, "p": P, "f": f, "g": g}, o)
        if len(self._solvers) >= 8:
            self._solvers.pop(next(iter(self._solvers)))
        self._solvers[key] = solver
        return solver, time.perf_counter() - t0

    def minimize(self, rows: ContactRows, p, x0, fixed, values, tol, max_iter, options=None, prox=None) \
            -> MinimizeOutcome:
        """One IPOPT solve with the rows ``rows`` (``lam_g``: the muscle rows' physical multipliers, then the
        contact forces, ``>= 0``); ``prox = (rho, xr)`` adds ``rho/2 |x - xr|^2`` to the energy (a proximal
        step: it bounds how far the state moves from ``xr``)."""
        solver, bt = self._solver(rows, tol, max_iter, options)
        pe, _ = self.split(p)
        lbx, ubx, x0 = pinned_bounds(self.model.n_dof, x0, fixed, values)
        if self.cm is not None:
            lbm, ubm = self.cm.nlp_bounds(p)
        else:
            lbm, ubm = np.zeros(0), np.zeros(0)
        lbg = np.concatenate([lbm, np.full(rows.n_rows, self.spec.gap)])
        ubg = np.concatenate([ubm, np.full(rows.n_rows, np.inf)])
        t0 = time.perf_counter()
        with interruptible():
            rho, xr = (0.0, x0) if prox is None else prox
            fterm = self.friction_term
            fp = friction_params(fterm) if fterm is not None and len(self.friction_rows(rows)) else np.zeros(2)
            sol = solver(x0=x0, p=np.concatenate([pe, np.asarray(xr, dtype=float).reshape(-1), [rho], fp]), lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
        st = solver.stats()
        status, its = solver_status(st)
        lam = np.asarray(sol["lam_g"]).ravel()
        nm = self.cm.n_rows if self.cm is not None else 0
        lam_phys = np.concatenate([lam[:nm] * (self.cm.row_scale if nm else 1.0), -lam[nm:]])
        return MinimizeOutcome(np.asarray(sol["x"]).ravel(), bool(st.get("success", False)), status, its,
                               time.perf_counter() - t0, bt, lam_phys)


#: the active sets a polishing Newton step tries (a held row released, a free one held, the step made again)
#: before it gives up: at the 1,701-node turn's full load (54 rows, IPOPT's 41 near their gap held at first)
#: the eighth still released one row, the ninth was consistent (residual 8e-3 -> 5e-8 in that step)
ACTIVE_SET_TRIES = 20


def _stack(*mats, n):
    mats = [m for m in mats if m is not None and m.shape[0]]
    return sp.vstack(mats, format="csr") if mats else sp.csr_matrix((0, n))


def contact_residual(prob: ContactProblem, rows: ContactRows, x, p, fixed, tol: float, force: float):
    """The scaled KKT residual with contact (module docstring): ``(Residual, contact forces (N,))``; the
    Residual's ``lam`` holds the muscle rows' multipliers (None without them)."""
    x = np.asarray(x, dtype=float).reshape(-1)
    free = ~np.asarray(fixed, dtype=bool)
    cm, S = prob.cm, prob.mesh.size
    pe, targets = prob.split(p)
    g = prob.model.gradient(x, pe)
    if prob.friction_term is not None:
        g = g + prob.friction_term.gradient(x)
    gf = np.where(free, g, 0.0)
    nm = cm.n_rows if cm is not None else 0
    nt = cm.n_targets if cm is not None else 0
    Jm = cm.jacobian(x).tocsr() if nm else None
    Jc = rows.jacobian(x) if rows.n_rows else None
    gc = rows.values(x) if rows.n_rows else np.zeros(0)
    active = np.zeros(nm + rows.n_rows, dtype=bool)
    if nm:
        active[:nm] = True
        if nt:
            active[:nt] = ~cm.short_ropes(x, p, float(tol))
    active[nm:] = gc - prob.spec.gap <= tol * S
    J = _stack(Jm, Jc, n=len(x))
    Jz = J.tocsr(copy=True)
    if Jz.nnz:
        Jz.data[~free[Jz.indices]] = 0.0
    lam = np.zeros(nm + rows.n_rows)
    sign = np.concatenate([np.ones(nt), np.zeros(nm - nt), -np.ones(rows.n_rows)])  # ropes pull, contacts push
    first = active.copy()
    for _ in range(nt + rows.n_rows + 1):
        lam[:] = 0.0
        Ja = Jz[active]
        if Ja.shape[0] == 0:
            break
        sol = np.linalg.lstsq(Ja.T.toarray(), -gf, rcond=None)[0] if Ja.shape[0] < 400 else \
            sp.linalg.lsqr(Ja.T, -gf, atol=1e-14, btol=1e-14)[0]
        lam[active] = sol
        wrong = active & (sign * lam < 0)
        if not wrong.any():
            break
        worst = np.argmin(np.where(wrong, sign * lam, np.inf))
        active[worst] = False
    gl = g + (J.T @ lam if J.shape[0] else 0.0)
    s = float(np.abs(gl[free]).max()) / force if free.any() else 0.0
    if s > tol and (first != active).any():  # rows released for their sign: where the rows are dependent (both
        # faces of a flat fold pushing) a least-squares solution has forces of either sign where ones of the right
        # sign fit as well, and releasing the worst one at a time leaves too few; the fit again with the signs as
        # bounds (bounded-variable least squares). Imported here: scipy.optimize imports scipy.spatial and more,
        # which a run's main process otherwise leaves to its jobs (only such a contact fit needs it)
        from scipy.optimize import lsq_linear

        lam2 = np.zeros_like(lam)
        lo = np.where(sign[first] > 0, 0.0, -np.inf)
        hi = np.where(sign[first] < 0, 0.0, np.inf)
        lam2[first] = lsq_linear(Jz[first].T.toarray()[free], -gf[free], bounds=(lo, hi), method="bvls",
                                 tol=1e-14).x
        gl2 = g + J.T @ lam2
        s2 = float(np.abs(gl2[free]).max()) / force
        if s2 < s:
            lam, gl, s = lam2, gl2, s2
    viol = 0.0
    if nm:
        v = cm.values(x)
        over = float(np.max((v[:nt] - targets) / cm.constraints.rest_lengths[:nt], initial=0.0)) if nt else 0.0
        viol = max(over, float(np.abs(v[nt:]).max(initial=0.0)) / S)
    if rows.n_rows:
        viol = max(viol, float(np.max(prob.spec.gap - gc, initial=0.0)) / S)
    taut = (lam[:nt] > 0) if nt else None
    return Residual(max(s, viol), s, viol, lam[:nm] if nm else None, taut), -lam[nm:]


def polish(prob: ContactProblem, rows, x, p, fixed, tol, force, lam=None, steps: int = 3):
    """Newton steps on the KKT system, kept while they lower the residual and keep the state upright and
    admissible: ``(x, Residual, forces)``.

    The rows held as equalities are the solver's estimate of its active set, as
    :func:`~mdsr_opt.mechanics.residual.meet_tolerance` takes it for ropes: every rigid row; a rope or a
    contact within ``sqrt(tol)`` (of ``L0``, of the size) of its bound, or whose multiplier relative to
    ``E t S`` is at least its distance from it (``lam``: the muscle rows' physical multipliers, then the
    contact forces; by default the fitted ones). An interior point method leaves an active contact
    1e-8 to 1e-7 of the size off its gap; held, it meets it. A held row whose multiplier comes out of sign
    (a contact pulling, a rope pushing) is released and the step made again."""
    res, fc = contact_residual(prob, rows, x, p, fixed, tol, force)
    if res.value <= tol:
        return x, res, fc
    cm, S = prob.cm, prob.mesh.size
    nm = cm.n_rows if cm is not None else 0
    nt = cm.n_targets if cm is not None else 0
    if lam is None:
        lam = np.concatenate([res.lam if res.lam is not None else np.zeros(0), fc])
    lam = np.asarray(lam, dtype=float).copy()
    pe, targets = prob.split(p)
    act = np.ones(nm + rows.n_rows, dtype=bool)
    if nt:
        short = (targets - cm.values(x)[:nt]) / cm.constraints.rest_lengths[:nt]
        act[:nt] = (short <= np.sqrt(tol)) | (lam[:nt] / force >= short)
    if rows.n_rows:
        d = (rows.values(x) - prob.spec.gap) / S
        act[nm:] = (d <= np.sqrt(tol)) | (lam[nm:] / force >= d)
    free = ~fixed
    scale = np.concatenate([cm.constraints.rest_lengths[:nt] if nt else np.zeros(0), np.full(nm - nt, S),
                            np.full(rows.n_rows, S)])
    for _ in range(steps):
        H = _hessian(prob, rows, x, p, lam)
        Hf = H.tocsr()[free][:, free]
        J, c = _rows(prob, rows, x, p)
        g = prob.model.gradient(x, pe)
        if prob.friction_term is not None:
            g = g + prob.friction_term.gradient(x)
        Jfree = J[:, free]
        done = None
        for reduce in (False, True):  # every held row in the step; if that fails, only independent ones
            dx, mult, act2 = _kkt_step(Hf, Jfree, g[free], c, act, (nt, nm), 0.1 * tol * scale, reduce)
            if dx is None:
                continue
            y = x.copy()
            y[free] += dx
            if not upright(prob.mesh, y) or prob.penetrates(y):
                continue
            r2, f2 = contact_residual(prob, rows, y, p, fixed, tol, force)
            if r2.value < res.value:
                done = y, r2, f2, mult, act2
                break
        if done is None:
            break
        x, res, fc, mult, act = done
        lam = np.concatenate([mult[:nm], -mult[nm:]])
        if res.value <= 1e-2 * tol:
            break
    return x, res, fc


def _kkt_step(Hf, J, g, c, act, counts, over_tol, reduce):
    """One Newton step of :func:`polish` on the KKT system with the rows ``act`` held: ``(step, multipliers,
    rows held)``, the step None when no consistent active set was found within :data:`ACTIVE_SET_TRIES`. A held
    row whose multiplier comes out of sign (a rope pushing, a contact pulling) is released, a free row that the
    step would violate by more than ``over_tol`` (a rope longer than its target, a contact inside its gap) is
    held, and the step made again. ``reduce``: of the held rows only independent ones enter the system
    (:func:`_independent`); the others are left to them, neither released nor checked."""
    nt, nm = counts
    nf = Hf.shape[0]
    for _ in range(ACTIVE_SET_TRIES):
        held = _independent(J, act) if reduce else act
        fac = kkt_factor(Hf, J[held])
        if fac is None:
            return None, None, act
        sol = fac.solve(np.concatenate([-g, -c[held]]))
        if not np.all(np.isfinite(sol)):
            return None, None, act
        mult = np.zeros(len(act))
        mult[held] = sol[nf:]
        wrong = held & (np.concatenate([-mult[:nt], np.zeros(nm - nt), mult[nm:]]) > 0)
        lin = c + J @ sol[:nf]
        over = ~act & (np.concatenate([lin[:nt], np.zeros(nm - nt), -lin[nm:]]) > over_tol)
        if not wrong.any() and not over.any():
            return sol[:nf], mult, act
        act = (act & ~wrong) | over
    return None, None, act


#: a held row whose Jacobian row is within this (relative to the largest pivot of a pivoted QR) of the span of
#: the rows before it is left to them (:func:`_independent`)
DEPENDENT_RTOL = 1e-6


def _independent(J, act) -> np.ndarray:
    """The rows of ``act`` (mask) whose rows of ``J`` are linearly independent: a column-pivoted QR of their
    transpose, the rows of pivots above :data:`DEPENDENT_RTOL` of the first. Where both faces of a flat fold
    push, a point sliding past a segment's end onto the next held by both segments' rows, the held rows are
    dependent to 1e-7 and the KKT step of all of them solves an inconsistency of their values (1e-7 of the
    size) through that near-singular direction: a step of a third of an element."""
    idx = np.flatnonzero(act)
    if len(idx) < 2:
        return act
    R, piv = qr(J[idx].toarray().T, mode="r", pivoting=True)
    d = np.abs(np.diag(R))
    out = np.zeros_like(act)
    out[idx[piv[d > DEPENDENT_RTOL * d[0]]]] = True
    return out


def _hessian(prob, rows, x, p, lam):
    """The Hessian of the Lagrangian with the muscle multipliers and contact forces ``lam``."""
    cm = prob.cm
    pe, targets = prob.split(p)
    nm = cm.n_rows if cm is not None else 0
    H = cm.hessian(x, cm.params(pe, targets, lam[:nm])) if cm is not None else prob.model.hessian(x, pe)
    if prob.friction_term is not None:
        H = (H + prob.friction_term.hessian(x)).tocsc()
    if rows.n_rows:
        H = (H + rows.hessian(x, -lam[nm:])).tocsc()
    return H


def _rows(prob, rows, x, p):
    """``(Jacobian, value - bound)`` of every muscle and contact row."""
    cm = prob.cm
    Jm = cm.jacobian(x).tocsr() if cm is not None else None
    cmv = (cm.values(x) - cm.bounds(p)[1]) if cm is not None else np.zeros(0)
    Jc = rows.jacobian(x) if rows.n_rows else None
    ccv = rows.values(x) - prob.spec.gap if rows.n_rows else np.zeros(0)
    return _stack(Jm, Jc, n=len(x)), np.concatenate([cmv, ccv])


def _lagrangian(prob, rows, x, p, fixed, res, fc):
    """``(Hessian of the Lagrangian, Jacobian of the active rows, their values minus targets)``."""
    cm = prob.cm
    pe, targets = prob.split(p)
    if cm is not None:
        lam_m = res.lam
        H = cm.hessian(x, cm.params(pe, targets, lam_m))
        nt = cm.n_targets
        act = np.ones(cm.n_rows, dtype=bool)
        if nt:
            act[:nt] = lam_m[:nt] > 0
        Jm = cm.jacobian(x).tocsr()[act]
        cmv = (cm.values(x) - cm.bounds(p)[1])[act]
    else:
        H = prob.model.hessian(x, pe)
        Jm, cmv = None, np.zeros(0)
    if prob.friction_term is not None:
        H = (H + prob.friction_term.hessian(x)).tocsc()
    if rows.n_rows:
        H = (H + rows.hessian(x, -fc)).tocsc()
        pushing = fc > 0
        Jc = rows.jacobian(x)[pushing]
        ccv = rows.values(x)[pushing] - prob.spec.gap
    else:
        Jc, ccv = None, np.zeros(0)
    return H, _stack(Jm, Jc, n=len(x)), np.concatenate([cmv, ccv])


def contact_stability(prob, rows, x, p, fixed, res, fc):
    """:func:`~mdsr_opt.mechanics.stability.check_stability` of the Lagrangian on the tangent space of the
    active rows (rigid patches, taut ropes, contacts that push)."""
    H, A, _ = _lagrangian(prob, rows, x, p, fixed, res, fc)
    # the mesh's fill-reducing ordering: the free block's factorisation, or with active rows the KKT matrix's
    order = prob.model.free_ordering(~fixed) if getattr(prob.model, "is_numeric", False) else None
    return check_stability(H, ~fixed, A if A.shape[0] else None, order=order)


def merge_rows(a: ContactRows, b: ContactRows, drop=frozenset()) -> ContactRows:
    """The union of two row sets (by their points), without the keys in ``drop``."""
    pts, w, lab, consts = [], [], [], []
    seen = set()
    for rows in (a, b):
        for i in range(rows.n_rows):
            key = row_key(rows, i)
            if key in seen or key in drop:
                continue
            seen.add(key)
            q = []
            for j in rows.pts[i]:
                if j >= rows.n_nodes:
                    consts.append(rows.consts[j - rows.n_nodes])
                    q.append(rows.n_nodes + len(consts) - 1)
                else:
                    q.append(int(j))
            pts.append(q)
            w.append(rows.w[i])
            lab.append(rows.labels[i])
    return ContactRows(np.array(pts, dtype=np.int64).reshape(-1, 3), a.n_nodes, np.array(consts).reshape(-1, 2),
                       np.array(w, dtype=float).reshape(-1, 2), np.array(lab, dtype=np.int64).reshape(-1, 2))


def row_key(rows, i) -> tuple:
    """What identifies row ``i`` of ``rows`` across row sets: its kind, obstacle, points (fixed ones by value)."""
    p = rows.pts[i]
    c = tuple(tuple(np.round(rows.consts[j - rows.n_nodes], 12).tolist()) if j >= rows.n_nodes else int(j)
              for j in p)
    return (tuple(rows.labels[i].tolist()), c, float(rows.w[i, 1]))
