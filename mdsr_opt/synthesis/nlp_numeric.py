"""The flattened design NLP evaluated in numpy: IPOPT through CasADi callbacks, no symbolic graph.

The NLP is the one :mod:`~mdsr_opt.synthesis.nlp` states (same variables, parameters, scaling,
constraints and exact derivatives; iterates agree with its MX and SX forms to rounding), but every
function IPOPT calls is a :class:`~mdsr_opt.mechanics.assembly.BufferedFunction` that fills CasADi's
buffers from vectorised numpy:

- the energy's gradient, Hessian and third derivative along the multipliers
  (:meth:`~mdsr_opt.mechanics.model.EnergyModel.third_data`) in the CSC order of the mesh's
  :class:`~mdsr_opt.mechanics.assembly.HessianPattern`;
- the muscle constraints' values, Jacobian, Hessian, third derivative and Hessian-vector products from
  their closed forms (:class:`~mdsr_opt.mechanics.constraints.MuscleConstraints`);
- the objective ``so sum_i w_i |x_i - y_i|^2`` when the state's rigid pose is free (see
  :mod:`~mdsr_opt.synthesis.nlp`): a diagonal Hessian; else ``so sum_i w_i |R(theta) x_i + t - y_i|^2``
  and its derivatives per node.

Each sparse output is summed from its parts by one ``bincount`` into a pattern made once
(:class:`SparseLayout`), so building the NLP costs index arithmetic only, no MX graph of a term-by-term
assembly.

It applies when the energy is numeric (Neo-Hookean or linear elastic, see
:attr:`~mdsr_opt.mechanics.model.EnergyModel.is_numeric`) and the contractions move at most the
springs' rest lengths (:func:`supports`): the exact cable and the per-segment springs. A spring
``k/2 (l - r l0)^2`` whose ratio ``r`` moves with ``a`` adds ``-k l0 grad l dr/da`` to the Jacobian's
``a`` columns and ``-k l0 Hessian(l) lam dr/da`` to the Lagrangian Hessian's ``x``-``a`` block.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ..mechanics.assembly import BufferedFunction, SparseLayout
from ..mechanics.segments import length_direction, length_hessian_product
from . import objective as pinned
from .problem import DesignProblem

__all__ = ["numeric_nlp", "supports"]


def _rest_ratio_rows(prob: DesignProblem) -> slice:
    """Where the springs' rest-length ratios sit in the model's parameters."""
    ne = prob.model.n_edges
    return slice(2 + ne, 2 + 2 * ne)


def supports(prob: DesignProblem) -> bool:
    """Whether :func:`numeric_nlp` applies: a numeric energy (Neo-Hookean or linear elastic, no sliding
    cable) in which the contractions move at most the springs' rest lengths (the cable moves nothing, the
    per-segment springs their rest lengths)."""
    if not getattr(prob.model, "is_numeric", False):
        return False
    B = np.array(prob.B, dtype=float, copy=True)
    B[_rest_ratio_rows(prob)] = 0.0
    return not np.any(B)


def _aligned_objective(x, y, w, v, so, exact: bool):
    """The objective of the pinned pose (a body whose energy changes under rotation):
    ``(f, dfdx (2n,), dfdv (3,), Hessian parts)`` of ``so sum_i w_i |R(theta) x_i + t - y_i|^2`` with
    ``v = (theta, t0, t1)`` (:mod:`~mdsr_opt.synthesis.objective`). The Hessian parts are per-node arrays in
    the order of :data:`~mdsr_opt.synthesis.objective.HESSIAN_PARTS` (the ``v``-``v`` ones summed over the
    nodes by the layout); without ``exact``, the Gauss-Newton Hessian."""
    X0, X1 = x[0::2], x[1::2]
    c, s = np.cos(v[0]), np.sin(v[0])
    rx, ry = pinned.residual(X0, X1, y[0::2], y[1::2], c, s, v[1], v[2])
    W2 = 2.0 * so * w
    f = so * float(w @ (rx * rx + ry * ry))
    (g0, g1), gv, parts = pinned.derivatives(X0, X1, rx, ry, W2, c, s, exact)
    gx = np.empty_like(x)
    gx[0::2], gx[1::2] = g0, g1
    return f, gx, np.array([q.sum() for q in gv]), parts


class _NumericNLP:
    """Index bookkeeping and the evaluation functions of the numeric NLP (see :func:`numeric_nlp`)."""

    def __init__(self, prob: DesignProblem, exact: bool):
        model, mesh = prob.model, prob.mesh
        self.prob, self.model, self.exact = prob, model, exact
        n, m = mesh.n_nodes, prob.m
        blk = prob.block
        self.blk, self.mc = blk, prob.constraints
        nc = blk.nc
        self.n, self.m, self.nc = n, m, nc
        self.nx = nx = 2 * n
        self.it = it = nx + m  # the pinned pose's rotation and translation (none for a free pose)
        self.ik = ik = it + prob.nv
        self.nz = nz = ik + nc
        self.npar = model.n_params
        self.free = np.nonzero(prob.free)[0]
        nfree = self.nfree = len(self.free)
        cidx = np.full(nx, -1, dtype=np.int64)  # dof -> stationarity row (-1: gauge)
        cidx[self.free] = np.arange(nfree)
        dl = self.dofs = np.asarray(blk.dofs, dtype=np.int64)  # the constraints' local dofs (global indices)
        self.rows = np.asarray(blk.rows, dtype=np.int64)  # the constraints' rows the block uses
        rowmap = np.full(self.mc.n_constraints, -1, dtype=np.int64)  # constraint row -> block row
        rowmap[self.rows] = np.arange(nc)
        self.row_scale = np.asarray(blk.row_scale, dtype=float)
        pat = model.hessian_pattern
        pcols = np.repeat(np.arange(pat.shape[1]), np.diff(pat.indptr))
        prow = pat.indices.astype(np.int64)
        z0 = np.zeros(self.mc.n_local)
        lam0 = np.zeros(self.mc.n_constraints)
        hr, hc, _ = self.mc.local_hessian_entries(prob.X[dl], lam0)
        Jl = self.mc.local_jacobian(prob.X[dl])
        jrow = np.repeat(np.arange(Jl.shape[0]), np.diff(Jl.indptr))
        self._jkeep = rowmap[jrow] >= 0
        jr, jc = rowmap[jrow[self._jkeep]], dl[Jl.indices[self._jkeep]]
        self._jscale = self.row_scale[jr]

        jac = self.jac = SparseLayout(nfree + nc, nz)
        jac.add(cidx[prow], pcols)  # sc x energy Hessian
        jac.add(cidx[dl[hr]], dl[hc])  # d(J' kappa)/dx
        jac.add(cidx[jc], ik + jr)  # d(J' kappa)/dkappa = J'
        jac.add(nfree + jr, jc)  # dC/dx
        if blk.rope:  # d(C + a)/da on the rope rows
            jac.add(nfree + np.arange(m), nx + np.arange(m))
        # springs: the rest-length ratio r_e of edge e moves with a_c by B[r_e, c] (every nonzero of B)
        Br = sp.coo_matrix(np.asarray(prob.B)[_rest_ratio_rows(prob)])
        self._se, self._scol, self._sb = Br.row.astype(np.int64), Br.col.astype(np.int64), Br.data
        E = np.asarray(mesh.edges, dtype=np.int64)[self._se]
        self._sdofs = np.column_stack([2 * E[:, 1], 2 * E[:, 1] + 1, 2 * E[:, 0], 2 * E[:, 0] + 1])  # j, then i
        self._sl0 = np.asarray(mesh.edge_lengths, dtype=float)[self._se]
        acol = np.repeat(nx + self._scol, 4)
        jac.add(cidx[self._sdofs.ravel()], acol)  # sc d(grad E)/da
        jac.finish()

        hess = self.hess = SparseLayout(nz, nz, upper=True)
        if prob.free_pose:
            hess.add(np.arange(nx), np.arange(nx))  # the objective's diagonal
        else:
            loc = {"x0": 2 * np.arange(n), "x1": 2 * np.arange(n) + 1, "th": np.full(n, it),
                   "t0": np.full(n, it + 1), "t1": np.full(n, it + 2)}
            for a, b in pinned.HESSIAN_PARTS:
                hess.add(loc[a], loc[b])
        if exact:
            hess.add(prow, pcols)  # sc D^3 E [lam_u]
            tr, tc, _ = self.mc.local_third_entries(prob.X[dl], lam0, z0)
            hess.add(dl[tr], dl[tc])  # D^3 (kappa . C)[lam_u]
            hess.add(dl[hr], dl[hc])  # omega . Hessian(C)
            pr, pc, _ = self.mc.local_hessian_product_entries(prob.X[dl], z0)
            hess.add(dl[pr], np.where(rowmap[pc] >= 0, ik + rowmap[pc], -1))  # d^2 (lam_u . J' kappa)/dx dkappa
            hess.add(self._sdofs.ravel(), acol)  # sc d^2 (lam_u . grad E)/dx da
        hess.finish()

    # ------------------------------------------------------------------ evaluation
    def _split(self, z, par):
        nx, ik, n = self.nx, self.ik, self.n
        return (z[:nx], z[nx:self.it], z[ik:], par[:nx], par[nx:nx + n], par[nx + n:nx + n + self.npar],
                float(par[nx + n + self.npar]), float(par[nx + n + self.npar + 1]))

    def _params(self, p0, a) -> np.ndarray:
        return p0 + self.prob.B @ a if len(self._se) else p0

    def _spring_parts(self, x, p0, v=None) -> np.ndarray:
        """Per moving spring (edge e, muscle c, weight b = dr_e/da_c), with ``d l / dr = 0`` and
        ``d grad W / dr = -k l0 grad l``: the values ``-b k l0 grad l`` (``v`` None: the gradient's
        derivative in ``a``, the Jacobian's ``a`` columns) or ``-b k l0 Hessian(l) v`` (the Lagrangian
        Hessian's ``x``-``a`` block), at the edge's dofs ``(x_j, y_j, x_i, y_i)``, (4 per spring)."""
        if not len(self._se):
            return np.zeros(0)
        X = x.reshape(-1, 2)
        k = p0[2:2 + self.model.n_edges][self._se]  # the stiffness does not move with a
        j, i = self._sdofs[:, 0] // 2, self._sdofs[:, 2] // 2
        if v is None:
            q = length_direction(X[j] - X[i])[1]
        else:
            V = v.reshape(-1, 2)
            q = length_hessian_product(X[j] - X[i], V[j] - V[i])
        c = -(self._sb * k * self._sl0)[:, None]
        return np.column_stack([c * q, -c * q]).ravel()

    def _lam_rows(self, kappa) -> np.ndarray:
        """Block multipliers as multipliers of all the constraints' rows (scaled as the block scales them)."""
        lam = np.zeros(self.mc.n_constraints)
        lam[self.rows] = np.asarray(kappa, dtype=float) * self.row_scale
        return lam

    def _jacobian_local(self, xl) -> np.ndarray:
        """The nonzeros of the block's rows of the constraints' Jacobian, scaled (the layout's entries)."""
        return self.mc.local_jacobian(xl).data[self._jkeep] * self._jscale

    def constraints(self, z, par) -> np.ndarray:
        x, a, kap, _y, _w, p0, _so, sc = self._split(z, par)
        g = self.model.gradient(x, self._params(p0, a)) * sc
        if self.nc:
            xl = x[self.dofs]
            lam = self._lam_rows(kap)
            Jl = self.mc.local_jacobian(xl)
            g[self.dofs] += Jl.T @ lam
        out = np.empty(self.nfree + self.nc)
        out[:self.nfree] = g[self.free]
        if self.nc:
            C = self.blk.values(x)
            if self.blk.rope:
                C[:self.m] += a
            out[self.nfree:] = C
        return out

    def jacobian(self, z, par) -> np.ndarray:
        """The constraints' Jacobian values at ``(z, par)``; the last one is kept (IPOPT asks twice at its
        starting point, and each such call assembles the energy's Hessian)."""
        key = (np.asarray(z, dtype=float).tobytes(), np.asarray(par, dtype=float).tobytes())
        last = self.__dict__.get("_last_jacobian")
        if last is not None and last[0] == key:
            return last[1]
        data = self._jacobian(z, par)
        self.__dict__["_last_jacobian"] = (key, data)
        return data

    def _jacobian(self, z, par) -> np.ndarray:
        x, a, kap, _y, _w, p0, _so, sc = self._split(z, par)
        parts = [self.model.hessian_data(x, self._params(p0, a)) * sc]
        xl = x[self.dofs]
        parts.append(self.mc.local_hessian_entries(xl, self._lam_rows(kap))[2])  # zeros without rows
        jd = self._jacobian_local(xl)
        parts += [jd, jd]
        if self.blk.rope:
            parts.append(np.ones(self.m))
        parts.append(sc * self._spring_parts(x, p0))
        return self.jac.data(parts)

    def objective(self, z, par, grad: bool):
        x, _a, _kap, y, w, _p, so, _sc = self._split(z, par)
        g = np.zeros(self.nz) if grad else None
        if self.prob.free_pose:
            r = (x - y).reshape(-1, 2)
            f = so * float(w @ (r * r).sum(1))
            if grad:
                g[:self.nx] = (2.0 * so * w[:, None] * r).ravel()
            return f, g
        f, gx, gv, _parts = _aligned_objective(x, y, w, z[self.it:self.ik], so, self.exact)
        if grad:
            g[:self.nx] = gx
            g[self.it:self.ik] = gv
        return f, g

    def _objective_hessian(self, z, par, lam_f) -> list:
        x, _a, _kap, y, w, _p, so, _sc = self._split(z, par)
        if self.prob.free_pose:
            return [np.repeat(2.0 * so * lam_f * w, 2)]
        return [lam_f * q for q in _aligned_objective(x, y, w, z[self.it:self.ik], so, self.exact)[3]]

    def hessian(self, z, par, lam_f, lam_g) -> np.ndarray:
        x, a, kap, _y, _w, p0, _so, sc = self._split(z, par)
        parts = self._objective_hessian(z, par, lam_f)
        if self.exact:
            lam_u = np.zeros(self.nx)
            lam_u[self.free] = lam_g[:self.nfree]
            parts.append(self.model.third_data(x, self._params(p0, a), lam_u * sc))
            xl, ul = x[self.dofs], lam_u[self.dofs]
            parts.append(self.mc.local_third_entries(xl, self._lam_rows(kap), ul)[2])
            parts.append(self.mc.local_hessian_entries(xl, self._lam_rows(lam_g[self.nfree:]))[2])
            _r, pc, pv = self.mc.local_hessian_product_entries(xl, ul)
            full = np.zeros(self.mc.n_constraints)
            full[self.rows] = self.row_scale
            parts.append(pv * full[pc])
            parts.append(sc * self._spring_parts(x, p0, lam_u))
        return self.hess.data(parts)


def numeric_nlp(prob: DesignProblem, hessian: str):
    """The flattened NLP with numpy callbacks (requires :func:`supports`).

    Parameters
    ----------
    prob : DesignProblem
    hessian : {"exact", "gauss-newton"}
        The Lagrangian's exact Hessian, or the objective's only (no third derivatives).

    Returns
    -------
    nlp : dict
        ``{"x", "p", "f", "g"}`` for ``casadi.nlpsol``, over MX symbols (``f`` and ``g`` are callbacks).
    options : dict
        The ``grad_f``, ``jac_g`` and ``hess_lag`` options of ``nlpsol``.
    keep : dict
        Every callback: keep it referenced as long as the solver lives (CasADi does not own them).
    """
    if not supports(prob):
        raise ValueError("the numeric design NLP needs a numeric energy (a Neo-Hookean or linear elastic "
                         "material, no sliding cable) whose parameters the contractions move at most in the "
                         "springs' rest lengths")
    nlp = _NumericNLP(prob, hessian == "exact")
    nz, npar, ng = nlp.nz, 3 * prob.mesh.n_nodes + nlp.npar + 2, nlp.nfree + nlp.nc
    sz, sp_ = ca.Sparsity.dense(nz, 1), ca.Sparsity.dense(npar, 1)
    one = ca.Sparsity.dense(1, 1)

    def f(ins, outs):
        outs[0][0] = nlp.objective(ins[0], ins[1], False)[0]

    def g(ins, outs):
        outs[0][:] = nlp.constraints(ins[0], ins[1])

    def grad_f(ins, outs):
        fv, gv = nlp.objective(ins[0], ins[1], outs[1] is not None)
        if outs[0] is not None:
            outs[0][0] = fv
        if outs[1] is not None:
            outs[1][:] = gv

    def jac_g(ins, outs):
        if outs[0] is not None:
            outs[0][:] = nlp.constraints(ins[0], ins[1])
        if outs[1] is not None:
            outs[1][:] = nlp.jacobian(ins[0], ins[1])

    def hess_lag(ins, outs):
        if outs[0] is not None:
            outs[0][:] = nlp.hessian(ins[0], ins[1], float(ins[2][0]), ins[3])

    fns = {"f": BufferedFunction("design_f_num", [sz, sp_], [one], f),
           "g": BufferedFunction("design_g_num", [sz, sp_], [ca.Sparsity.dense(ng, 1)], g),
           "grad_f": BufferedFunction("design_grad_f_num", [sz, sp_], [one, sz], grad_f),
           "jac_g": BufferedFunction("design_jac_g_num", [sz, sp_], [ca.Sparsity.dense(ng, 1), nlp.jac.sparsity],
                                     jac_g),
           "hess_lag": BufferedFunction("design_hess_lag_num", [sz, sp_, one, ca.Sparsity.dense(ng, 1)],
                                        [nlp.hess.sparsity], hess_lag)}
    zs, ps = ca.MX.sym("z", nz), ca.MX.sym("par", npar)
    problem = {"x": zs, "p": ps, "f": fns["f"](zs, ps), "g": fns["g"](zs, ps)}
    return problem, {k: fns[k] for k in ("grad_f", "jac_g", "hess_lag")}, fns
