"""One frame of a walk on the table (:mod:`~mdsr_opt.synthesis.walk`): its NLP, built once per body and muscle
layout, solved with the friction potential itself and, when that fails, in its epigraph form."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..core.guards import interruptible
from ..mechanics.assembly import ipopt_functions
from ..mechanics.constrained import ConstrainedModel
from ..mechanics.constraints import muscle_constraints
from ..mechanics.model import get_model
from ..mechanics.residual import ipopt_tolerances
from ..mechanics.result import solver_status
from ..mechanics.stopping import with_stop_callback

__all__ = ["MAX_MOVE", "PLAIN_ITER", "FrameSolver"]

#: a solve that moves a node by more than this many body sizes has failed (a quasi-static frame moves it by
#: about a stroke)
MAX_MOVE = 2.0
#: the iterations a frame's solve with the friction potential itself gets before its epigraph form takes over
PLAIN_ITER = 60


class FrameSolver:
    """The frame's NLP on the unit body: elastic energy + ground friction (+ a drag with mu = 0, :mod:`~mdsr_opt.synthesis.walk`) subject to the
    ropes and anchor patches; built once.

    A solve that fails with ``D`` is made again with the friction in epigraph form: one variable ``t_k`` per
    node with ``t_k^2 - |x_k - x0_k|^2 >= eps^2``, ``t_k >= 0`` and ``sum_k mu N_k t_k`` in the objective, the
    same minimiser as ``D`` with rows of bounded curvature (``D``'s Hessian jumps from ``mu N / eps`` where a
    node sticks to about nothing where it slips, which sends Newton's steps far once ``eps`` is small against
    a frame's slide, and most where few nodes carry the weight: feet lifted in turn)."""

    def __init__(self, mesh, material, mus, radius, tol, max_iter, options):
        emodel = get_model(mesh, material)
        mc = muscle_constraints(mesh, mus, radius)
        self.cm = cm = ConstrainedModel(emodel, mc, True)
        self.emodel, self.L0 = emodel, mc.rest_lengths
        n = emodel.n_dof
        nn = n // 2
        x, p = ca.MX.sym("x", n), ca.MX.sym("p", emodel.n_params)
        x0, muN = ca.MX.sym("x0", n), ca.MX.sym("muN", nn)
        eps, rho = ca.MX.sym("eps"), ca.MX.sym("rho")
        w = ca.MX.sym("w", n)  # the drag's weight per coordinate
        lam_f = ca.MX.sym("lam_f")
        o = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes", **ipopt_tolerances(tol),
             "ipopt.max_iter": int(max_iter), "ipopt.linear_solver": "mumps", "error_on_fail": False,
             "calc_lam_p": False, "calc_lam_x": False, "show_eval_warnings": False}
        o.update(options or {})
        o = with_stop_callback(o)
        lam_m = ca.MX.sym("lam_m", cm.n_rows)
        if getattr(emodel, "is_numeric", False):
            fns = ipopt_functions(emodel)
            fe, ge = fns["grad_f"](x, p)
            o["no_nlp_grad"] = True
            cf = cm.numeric_functions()
            g, J = cf["g"](x, p), cf["jac_g"](x, p)[1]
            He_of = lambda lm: cf["hess_lag"](x, p, lam_f, lm)
        else:
            fe, ge = emodel.grad_fn(x, p)
            g, J = cm.nlp_constraints_expr(x), cm.nlp_jacobian_expr(x)
            He_of = lambda lm: cm.hess_lag_upper(x, p, lam_f, lm)
        P = ca.vertcat(p, x0, muN, eps, rho, w)
        d = x - x0
        drag = rho / 2 * ca.dot(w, d ** 2)
        # D itself
        fr = ca.dot(muN, ca.sqrt(d[0::2] ** 2 + d[1::2] ** 2 + eps ** 2) - eps) + drag  # D
        po = dict(o)
        po["ipopt.max_iter"] = min(int(max_iter), PLAIN_ITER)  # then the epigraph form takes over
        po["grad_f"] = ca.Function("walk_grad_f", [x, P], [fe + fr, ge + ca.gradient(fr, x)], ["x", "p"],
                                   ["f", "grad"])
        po["jac_g"] = ca.Function("walk_jac_g", [x, P], [g, J])
        po["hess_lag"] = ca.Function("walk_hess_lag", [x, P, lam_f, lam_m],
                                     [He_of(lam_m) + lam_f * ca.triu(ca.hessian(fr, x)[0])],
                                     ["x", "p", "lam_f", "lam_g"], ["hess"])
        nlp = {"x": x, "p": P, "f": fe + fr, "g": g}
        self.solver = ca.nlpsol("walk_frame", "ipopt", nlp, po)
        self.warm = ca.nlpsol("walk_frame_warm", "ipopt", nlp, {
            **po, "ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-9,
            "ipopt.warm_start_bound_push": 1e-12, "ipopt.warm_start_mult_bound_push": 1e-12})
        # the epigraph form
        t = ca.MX.sym("t", nn)
        z = ca.vertcat(x, t)
        lam_g = ca.MX.sym("lam_g", cm.n_rows + nn)
        gt = t ** 2 - d[0::2] ** 2 - d[1::2] ** 2  # >= eps^2 with t >= 0
        fz = ca.dot(muN, t) + drag
        lo = dict(o)
        lo["ipopt.bound_relax_factor"] = 0.0  # the rows' bound eps^2 held exactly (not relaxed by 1e-8)
        lo["grad_f"] = ca.Function("walk_epi_grad_f", [z, P], [fe + fz, ca.vertcat(ge + ca.gradient(drag, x), muN)],
                                   ["x", "p"], ["f", "grad"])
        Jz = ca.vertcat(ca.horzcat(J, ca.MX(J.size1(), nn)), ca.jacobian(gt, z))
        lo["jac_g"] = ca.Function("walk_epi_jac_g", [z, P], [ca.vertcat(g, gt), Jz])
        Hz = ca.diagcat(He_of(lam_g[:cm.n_rows]), ca.MX(nn, nn)) + \
            ca.triu(ca.hessian(lam_f * drag + ca.dot(lam_g[cm.n_rows:], gt), z)[0])
        lo["hess_lag"] = ca.Function("walk_epi_hess_lag", [z, P, lam_f, lam_g], [Hz], ["x", "p", "lam_f", "lam_g"],
                                     ["hess"])
        self.epigraph = ca.nlpsol("walk_frame_epigraph", "ipopt", {"x": z, "p": P, "f": fe + fz,
                                                                   "g": ca.vertcat(g, gt)}, lo)
        self.lam, self.x_last = None, None
        share = np.zeros(mesh.n_nodes)  # each node's share of the area (a third of each triangle's)
        np.add.at(share, mesh.triangles.reshape(-1), np.repeat(mesh.areas / 3.0, 3))
        self.area = share / share.sum()
        self.size = float(mesh.size)
        self.material = material
        self.nn = nn

    def solve(self, x_start, x0, strokes, muN, eps, rho, w):
        """``(x, success, status, iterations)`` of one solve from ``x_start`` with ``D`` (from the last
        solution: IPOPT warm-started with its multipliers; a cold start when that fails), and when that fails
        with the epigraph form."""
        p = self.cm.params(self.emodel.params(self.material), self.L0 - strokes)
        lbg, ubg = self.cm.nlp_bounds(p)
        P = np.concatenate([self.cm.split(p)[0], x0, muN, [eps, rho], w])
        its = 0
        with interruptible():
            if self.lam is not None and np.array_equal(x_start, self.x_last):
                x, ok, st, it = self._plain(self.warm, x_start, P, lbg, ubg, self.lam)
                its += it
                if ok:
                    return x, ok, st, its
            x, ok, st, it = self._plain(self.solver, x_start, P, lbg, ubg, None)
            its += it
            if ok:
                return x, ok, st, its
            zs, ok, st, it = self._epigraph(x_start, P, lbg, ubg, x0, eps)
            return zs[:len(x_start)], ok, st, its + it

    def moved_to(self, x) -> None:
        """The last solution moved rigidly to ``x`` (the ropes' multipliers do not change): the next solve from
        ``x`` is still warm-started."""
        if self.x_last is not None:
            self.x_last = np.asarray(x, dtype=float).copy()

    def _plain(self, solver, x_start, P, lbg, ubg, lam):
        sol = solver(x0=x_start, p=P, lbg=lbg, ubg=ubg, **({"lam_g0": lam} if lam is not None else {}))
        st = solver.stats()
        status, its = solver_status(st)
        x = np.asarray(sol["x"]).ravel()
        ok = bool(st.get("success", False))
        if ok:
            self.lam, self.x_last = np.asarray(sol["lam_g"]).ravel(), x.copy()
        return x, ok, status, its

    def _epigraph(self, x_start, P, lbg, ubg, x0, eps):
        u = (np.asarray(x_start, dtype=float) - x0).reshape(-1, 2)
        z0 = np.concatenate([x_start, np.sqrt((u * u).sum(1) + eps ** 2) + eps])
        n = len(x_start)
        # t >= 0, and at most 10 x MAX_MOVE sizes: a node without load (no cost on its t) keeps a bounded t
        sol = self.epigraph(x0=z0, p=P, lbx=np.concatenate([np.full(n, -np.inf), np.zeros(self.nn)]),
                            ubx=np.concatenate([np.full(n, np.inf), np.full(self.nn, 10 * MAX_MOVE * self.size)]),
                            lbg=np.concatenate([lbg, np.full(self.nn, eps ** 2)]),
                            ubg=np.concatenate([ubg, np.full(self.nn, np.inf)]))
        st = self.epigraph.stats()
        status, its = solver_status(st)
        ok = bool(st.get("success", False))
        zs = np.asarray(sol["x"]).ravel()
        if ok:
            self.lam, self.x_last = np.asarray(sol["lam_g"]).ravel()[:self.cm.n_rows], zs[:n].copy()
        return zs, ok, status, its
