"""The flattened design NLP: state, contractions and muscle multipliers in one IPOPT problem.

Variables ``z = [x (2n), a (m), kappa (nc)]``, parameters ``[y (2n), e (n), p0, so, sc]``::

    min   so sum_i e_i |x_i - y_i|^2
    s.t.  sc grad_x E(x, p0 + B a) + J(x)' kappa = 0   on the free coordinates
          C(x) + [a; 0] = 0                            (rope strains, rigid end patches)
          0 <= a <= a_upper,  tension >= 0 (cable)   (a_upper: a_max or the free-length cap)

**The state's rigid pose is free** when the energy does not change under rigid motion (Neo-Hookean; the
springs and the muscle constraints never do): the objective alone then places ``x`` in its best
alignment with the target, and equals the aligned difference at every feasible point. The stationarity
rows of the three gauge coordinates (node ``i``'s two, one of node ``j``'s) are left out, being implied
by the others: the gradient is orthogonal to the rigid motions, which these three coordinates pin while
node ``j``'s gauge coordinate is not perpendicular to ``i``-``j``. At a pose where it is, the rows left
out are no longer implied: the constraints' Jacobian loses rank and a state held by opposite forces on
``i`` and ``j`` becomes feasible. :func:`run_flattened` therefore moves the target into the warm start's
frame (near the gauge frame, far from that pose) rather than the state to the target, and rejects a
solution whose left-out rows do not vanish (:data:`GAUGE_RTOL`). Posed with an explicit rotation and
translation instead, the alignment's three variables coupled to every node and made three dense rows in
the KKT matrix: at 3k nodes and 4 muscles an IPOPT iteration took about 60 % longer.

**A pinned pose** for a body whose energy changes under rotation (the linear elastic material): the
gauge coordinates are fixed and ``z = [x, a, theta, t, kappa]`` with the objective
``so sum_i e_i |R(theta) x_i + t - y_i|^2``.

Three ways to give IPOPT the derivatives (``derivatives=`` of the design), all exact, iterates agreeing to
rounding, and all from the same statements: the material's density and the spring energy (see
:mod:`~mdsr_opt.mechanics.model`), the muscle constraints (:mod:`~mdsr_opt.mechanics.constraints`) and the
pinned pose's residual (:mod:`~mdsr_opt.synthesis.objective`):

* ``"casadi"`` (:func:`_symbolic_nlp`): the NLP in SX, differentiated by CasADi -- the reference;
* ``"assembled"`` (:func:`_assembled_nlp`): an MX graph summed term by term from CasADi's derivatives of each
  term's SX function, with the objective's closed-form derivatives; the fallback of ``"numeric"``;
* ``"numeric"`` (:mod:`~mdsr_opt.synthesis.nlp_numeric`): numpy callbacks evaluating the closed forms.

Tests compare the last two with the first at random points (values, Jacobian, Hessian of the Lagrangian).
"""

from __future__ import annotations

import math
import time
from types import SimpleNamespace
import casadi as ca
import numpy as np
import scipy.sparse as sp

from ..mechanics.model import to_dm
from ..mechanics.stopping import with_stop_callback
from . import objective as pinned
from .nlp_numeric import numeric_nlp, supports as numeric_supports
from .problem import ForwardSolver, DesignProblem


# ---------------------------------------------------------------------------------------------- assembled derivatives
class _Assembly:
    """A sparse matrix summed from vectors of term values by constant scatter matrices.

    Each part is a column of values and, per scattered value, a target ``(row, col)``, the index of its
    source in the column and an optional weight. The pattern is the union of all targets (CSC order is
    ascending ``col * nrow + row``), and the matrix is ``sum_k S_k v_k`` on that pattern.
    """

    def __init__(self, nrow: int, ncol: int):
        self.shape = (nrow, ncol)
        self.parts: list = []
        self._scatter = None

    def add(self, values, rows, cols, src, weights=None):
        """Scatter ``values[src[k]] * weights[k]`` to ``(rows[k], cols[k])``; targets with a negative row
        or column are dropped."""
        rows, cols, src = (np.asarray(v, dtype=np.int64) for v in (rows, cols, src))
        weights = np.ones(len(rows)) if weights is None else np.asarray(weights, dtype=float)
        keep = (rows >= 0) & (cols >= 0)
        if keep.any():
            self.parts.append((values, rows[keep], cols[keep], src[keep], weights[keep]))

    def build(self, values: list | None = None) -> ca.MX:
        """The assembled matrix; ``values`` (one column per part, the same sizes) replaces the parts' values,
        reusing the scatter (for a second matrix with the same structure)."""
        nrow, ncol = self.shape
        if not self.parts:
            return ca.MX(nrow, ncol)
        if self._scatter is None:  # one scatter matrix from all parts' values, stacked
            offsets = np.cumsum([0] + [p[0].numel() for p in self.parts])
            keys = np.concatenate([p[2] * nrow + p[1] for p in self.parts])
            src = np.concatenate([p[3] + o for p, o in zip(self.parts, offsets)])
            wts = np.concatenate([p[4] for p in self.parts])
            ukeys, nzpos = np.unique(keys, return_inverse=True)
            colind = np.concatenate([[0], np.cumsum(np.bincount(ukeys // nrow, minlength=ncol))])
            spars = ca.Sparsity(nrow, ncol, colind.tolist(), (ukeys % nrow).tolist())
            self._scatter = (spars, _scatter_dm(nzpos.ravel(), src, wts, len(ukeys), int(offsets[-1])))
        spars, S = self._scatter
        vals = ca.vertcat(*([p[0] for p in self.parts] if values is None else values))
        return ca.MX(spars, ca.mtimes(S, vals))


def _scatter_dm(rows: np.ndarray, cols: np.ndarray, wts: np.ndarray, nrow: int, ncol: int) -> ca.DM:
    """The sparse DM ``S[rows[k], cols[k]] += wts[k]`` built in CSC order directly (one sort of the
    entries; duplicates summed), without scipy's format conversions."""
    key = cols * nrow + rows
    order = np.argsort(key, kind="stable")
    key, w = key[order], wts[order]
    first = np.concatenate([[True], key[1:] != key[:-1]])
    if not first.all():  # the same source to the same target twice: one entry, weights summed
        w = np.add.reduceat(w, np.nonzero(first)[0])
        key = key[first]
    colind = np.concatenate([[0], np.cumsum(np.bincount(key // nrow, minlength=ncol))])
    return ca.DM(ca.Sparsity(nrow, ncol, colind.tolist(), (key % nrow).tolist()), w)


def _block_targets(rmap: np.ndarray, cmap: np.ndarray, upper: bool):
    """Targets of per-instance ``d x d`` blocks (``vec`` order, instance after instance): local entry
    ``(i, j)`` of instance ``e`` goes to ``(rmap[e, i], cmap[e, j])``; entries mapped to -1 are dropped,
    and with ``upper`` those below the diagonal too. Returns ``(rows, cols, src)``."""
    N, d = rmap.shape
    rr = np.broadcast_to(rmap[:, None, :], (N, d, d)).reshape(-1)
    cc = np.broadcast_to(cmap[:, :, None], (N, d, d)).reshape(-1)
    keep = (rr >= 0) & (cc >= 0)
    if upper:
        keep &= rr <= cc
    src = np.nonzero(keep)[0]
    return rr[keep], cc[keep], src


def _param_targets(rmap: np.ndarray, idx: np.ndarray, B: sp.csr_matrix, col0: int):
    """Targets of per-instance ``d x nd`` derivatives with respect to a parameter datum (``vec`` order,
    instance after instance), chained with ``dp/da = B``: local entry ``(i, j)`` of instance ``e`` goes to
    ``(rmap[e, i], col0 + c)`` with weight ``B[idx[j, e], c]`` for every nonzero of that row of ``B``.
    Returns ``(rows, cols, src, weights)``."""
    N, d = rmap.shape
    nd = idx.shape[0]
    e, j, i = (g.ravel() for g in np.meshgrid(np.arange(N), np.arange(nd), np.arange(d), indexing="ij"))
    src = e * nd * d + j * d + i
    q = idx[j, e]
    row = rmap[e, i]
    cnt = np.diff(B.indptr)[q]
    rep = np.repeat(np.arange(len(q)), cnt)
    k = B.indptr[q][rep] + (np.arange(len(rep)) - np.repeat(np.cumsum(cnt) - cnt, cnt))
    rows, cols, srcs, wts = row[rep], col0 + B.indices[k], src[rep], B.data[k]
    keep = rows >= 0
    return rows[keep], cols[keep], srcs[keep], wts[keep]


def _term_functions(fam, sens: list[int], exact: bool = True) -> dict:
    """SX functions of one term family ``W(xl, *data, glob)`` for the flattened NLP.

    ``g``: ``-> grad W``; ``gh``: ``-> (grad W, vec(Hessian W))``; ``lxx``: ``(xl, lam, *data, glob) ->
    vec(d^2 (lam . grad W) / dxl^2)`` (third derivatives of ``W`` contracted with the local multipliers);
    and, for the parameter data inputs ``sens`` (those moved by the contractions), ``dg``: ``->
    [vec(d grad W / d datum)]`` and ``lxp``: ``(xl, lam, ...) -> [vec(d^2 (lam . grad W) / dxl d datum)]``.
    Without ``exact`` (Gauss-Newton Hessian) the third-derivative functions ``lxx`` and ``lxp`` are omitted.
    """
    W = fam.W
    d = W.size1_in(0)
    xl = ca.SX.sym("xl", d)
    lam = ca.SX.sym("lam", d)
    dl = [ca.SX.sym(f"d{i}", W.size1_in(1 + i)) for i in range(W.n_in() - 2)]
    gl = ca.SX.sym("gl", W.size1_in(W.n_in() - 1))
    args, largs = [xl, *dl, gl], [xl, lam, *dl, gl]
    w = W(*args)
    gx = ca.gradient(w, xl)
    lg = ca.gradient(ca.dot(lam, gx), xl)  # = Hessian(W) lam

    def vec(e):
        return ca.vec(ca.densify(e))

    out = {"g": ca.Function(f"{fam.name}_g", args, [gx]),
           "gh": ca.Function(f"{fam.name}_gh", args, [gx, vec(ca.jacobian(gx, xl))])}
    if exact:
        out["lxx"] = ca.Function(f"{fam.name}_lxx", largs, [vec(ca.jacobian(lg, xl))])
    if sens:
        out["dg"] = ca.Function(f"{fam.name}_dg", args, [vec(ca.jacobian(gx, dl[k])) for k in sens])
        if exact:
            out["lxp"] = ca.Function(f"{fam.name}_lxp", largs, [vec(ca.jacobian(lg, dl[k])) for k in sens])
    return out


def _mapped(fn: ca.Function, X, *args) -> list:
    """Outputs (a list) of ``fn`` mapped serially over the columns of ``X`` (and of the per-instance args)."""
    return fn.map(X.shape[1], "serial").call([X, *args])


def _objective_terms(x, y, w, v, so, gauss_newton: bool):
    """The objective of the pinned pose ``so sum_i w_i |R(theta) x_i + t - y_i|^2`` and its derivatives per
    node (:mod:`~mdsr_opt.synthesis.objective`) as vectorised MX rows (``x``, ``y``: 2n; ``w``: n;
    ``v = [theta, t]``).

    Returns ``f``, the gradient parts ``(g_x0, g_x1)`` (per node, 1 x n) and ``(g_theta, g_t0, g_t1)``, and
    the Hessian parts as a dict ``{(a, b): 1 x n values}`` over the local variables ``a, b`` in ``x0, x1,
    th, t0, t1`` (entries of the ``(theta, t)`` block are per-node summands)."""
    X0, X1 = x[0::2].T, x[1::2].T
    c, s = ca.cos(v[0]), ca.sin(v[0])
    rx, ry = pinned.residual(X0, X1, y[0::2].T, y[1::2].T, c, s, v[1], v[2])
    f = so * ca.sum2(w.T * (rx ** 2 + ry ** 2))
    gx, gv, parts = pinned.derivatives(X0, X1, rx, ry, 2 * so * w.T, c, s, not gauss_newton)
    return f, gx, tuple(ca.sum2(q) for q in gv), dict(zip(pinned.HESSIAN_PARTS, parts))


def _assembled_nlp(prob: DesignProblem, hessian: str):
    """The flattened NLP with its derivatives assembled term by term.

    Returns ``(nlp, functions)``: the NLP dict (MX) and the ``grad_f``, ``jac_g`` and ``hess_lag``
    Functions for IPOPT, all exact:

    - constraints ``sc grad_x E(x, p0 + B a)`` on the free coordinates: per-term gradients scattered;
    - their Jacobian: in ``x``, the per-term Hessians scattered onto the free rows (both triangles); in
      ``a``, the per-term derivatives of the gradient with respect to the parameter data, chained with
      ``B``, over the terms whose parameters move with ``a`` (the muscles' springs or cables);
    - the objective's gradient and Hessian: closed-form per-node expressions, vectorised;
    - the Hessian of the Lagrangian (upper triangle): the objective's, plus the per-term third derivatives
      of the energy contracted with the multipliers (``x-x``) and their parameter derivatives (``x-a``);
      the ``a-a`` block is zero since the constraints are affine in ``a``.

    Edge springs without a muscle have zero stiffness for every design of these muscles and are left out.
    """
    model, n, m = prob.model, prob.mesh.n_nodes, prob.m
    blk = prob.block
    nc = blk.nc
    nx = 2 * n
    it = nx + m  # the pinned pose's rotation and translation (none for a free pose)
    ik = it + prob.nv  # index of the muscle constraints' multipliers kappa
    nz = ik + nc
    npar = model.n_params
    z = ca.MX.sym("z", nz)
    par = ca.MX.sym("par", 3 * n + npar + 2)
    x, a, v, kap = z[:nx], z[nx:nx + m], z[it:ik], z[ik:]
    y, w, p0 = par[:nx], par[nx:nx + n], par[nx + n:nx + n + npar]
    so, sc = par[3 * n + npar], par[3 * n + npar + 1]
    B = sp.csr_matrix(prob.B)
    B.eliminate_zeros()
    p = p0 + ca.mtimes(to_dm(B), a)
    free = np.nonzero(prob.free)[0]
    nfree = len(free)
    cidx = np.full(nx, -1, dtype=np.int64)  # dof -> constraint row (-1: gauge)
    cidx[free] = np.arange(nfree)
    lam_f = ca.MX.sym("lam_f")
    lam_g = ca.MX.sym("lam_g", nfree + nc)
    P = sp.csr_matrix((np.ones(nfree), (free, np.arange(nfree))), shape=(nx, nfree))
    lam_u = ca.mtimes(to_dm(P), lam_g[:nfree])  # the stationarity rows' multipliers per dof (0 on the gauge)
    lam_x = sc * lam_u

    # objective
    exact = hessian == "exact"  # else Gauss-Newton: the objective's part only, no third derivatives
    hess = _Assembly(nz, nz)
    if prob.free_pose:
        W2 = 2 * so * ca.repmat(w.T, 2, 1)  # (2, n): the objective's Hessian diagonal per coordinate
        r = ca.reshape(x - y, 2, n)
        f = so * ca.sum2(w.T * ca.sum1(r ** 2))
        # dense: with structural zeros (the a-entries) IPOPT through CasADi took wrong steps and failed
        grad_f = ca.densify(ca.vertcat(ca.vec(W2 * r), ca.MX(m + nc, 1)))
        hess.add(lam_f * ca.vec(W2), np.arange(nx), np.arange(nx), np.arange(nx))
    else:
        f, gx, gv, ho = _objective_terms(x, y, w, v, so, not exact)
        grad_f = ca.densify(ca.vertcat(ca.vec(ca.vertcat(*gx)), ca.MX(m, 1), *gv, ca.MX(nc, 1)))
        loc = {"x0": 2 * np.arange(n), "x1": 2 * np.arange(n) + 1, "th": np.full(n, it),
               "t0": np.full(n, it + 1), "t1": np.full(n, it + 2)}
        for (ka, kb), val in ho.items():
            hess.add(lam_f * val.T, loc[ka], loc[kb], np.arange(n))

    # constraints, their Jacobian, and their part of the Lagrangian's Hessian, term by term
    gval, gjac = _Assembly(nfree, 1), []  # the constraints, and their values from jac_g's term functions
    jac = _Assembly(nfree + nc, nz)  # stationarity rows, then the muscle constraints' rows
    ind = np.diff(B.indptr) > 0  # parameters moved by the contractions
    for fam in model.term_families():
        rows = np.arange(fam.dofs.shape[0])
        if fam.name == "spring":  # data (l0, k, r): only springs with stiffness
            rows = np.nonzero(prob.p0[fam.data_index[1][0]] != 0)[0]
        if len(rows) == 0:
            continue
        if len(fam.glob_index) and ind[fam.glob_index].any():  # pragma: no cover - p(a) never moves material
            raise NotImplementedError(f"{fam.name}: the shared parameters depend on the contractions")
        sens = [k for k, idx in enumerate(fam.data_index) if idx is not None and ind[np.asarray(idx)[:, rows]].any()]
        fn = _term_functions(fam, sens, exact)
        dofs = fam.dofs[rows]
        N, d = dofs.shape
        X = ca.reshape(x[dofs.reshape(-1).tolist()], d, N)
        L = ca.reshape(lam_x[dofs.reshape(-1).tolist()], d, N)
        ins = fam.inputs(p, rows)
        gtargets = (cidx[dofs].reshape(-1), np.zeros(N * d), np.arange(N * d))
        gval.add(ca.vec(_mapped(fn["g"], X, *ins)[0]), *gtargets)
        gl, Hl = _mapped(fn["gh"], X, *ins)
        gjac.append(ca.vec(gl))
        jac.add(sc * ca.vec(Hl), *_block_targets(cidx[dofs], dofs, upper=False))
        if exact:
            hess.add(ca.vec(_mapped(fn["lxx"], X, L, *ins)[0]), *_block_targets(dofs, dofs, upper=True))
        if not sens:
            continue
        moving = np.zeros(N, dtype=bool)  # instances whose parameters move with a
        for k in sens:
            moving |= ind[np.asarray(fam.data_index[k])[:, rows]].any(axis=0)
        sub = np.nonzero(moving)[0]
        ds = dofs[sub]
        Xs, Ls = (ca.reshape(u[ds.reshape(-1).tolist()], d, len(sub)) for u in (x, lam_x))
        ins = fam.inputs(p, rows[sub])
        dgv = _mapped(fn["dg"], Xs, *ins)
        lxpv = _mapped(fn["lxp"], Xs, Ls, *ins) if exact else [None] * len(sens)
        for k, dv, lv in zip(sens, dgv, lxpv):
            idx = np.asarray(fam.data_index[k])[:, rows[sub]]
            jac.add(sc * ca.vec(dv), *_param_targets(cidx[ds], idx, B, nx))
            if exact:
                hess.add(ca.vec(lv), *_param_targets(ds, idx, B, nx))
    g_stat = sc * ca.densify(gval.build())
    g_stat_j = sc * ca.densify(gval.build(gjac))
    g, g_j = g_stat, g_stat_j
    if nc:  # the muscle constraints: their rows, and J^T kappa in the stationarity rows
        dl = blk.dofs
        xl = x[dl.tolist()]
        C, JTk = blk.val(xl, kap)
        JTk_j, Jnz, Hknz = blk.jac(xl, kap)
        extra, extra_j = _Assembly(nfree, 1), _Assembly(nfree, 1)
        for asm, val in ((extra, JTk), (extra_j, JTk_j)):
            asm.add(val, cidx[dl], np.zeros(blk.d), np.arange(blk.d))
        arow = ca.vertcat(a, ca.MX(blk.n_rigid, 1)) if blk.rope else ca.MX(nc, 1)
        g = ca.vertcat(g_stat + ca.densify(extra.build()), C + arow)
        g_j = ca.vertcat(g_stat_j + ca.densify(extra_j.build()), C + arow)
        jr, jc = np.asarray(blk.J_sp.row()), np.asarray(blk.J_sp.get_col())
        hr, hc = np.asarray(blk.Hk_sp.row()), np.asarray(blk.Hk_sp.get_col())
        jac.add(Hknz, cidx[dl[hr]], dl[hc], np.arange(len(hr)))  # d(J^T kappa)/dx
        jac.add(Jnz, cidx[dl[jc]], ik + jr, np.arange(len(jr)))  # d(J^T kappa)/dkappa = J^T
        jac.add(Jnz, nfree + jr, dl[jc], np.arange(len(jr)))  # dC/dx
        if blk.rope:  # d(C + a)/da on the rope rows
            jac.add(ca.MX(ca.DM.ones(m)), nfree + np.arange(m), nx + np.arange(m), np.arange(m))
        gmap = np.concatenate([dl, ik + np.arange(nc)])
        Hs = blk.H_sp
        lam_l = lam_u[dl.tolist()]
        if exact:
            hess.add(blk.hess(xl, lam_l, kap, lam_g[nfree:]), gmap[np.asarray(Hs.row())],
                     gmap[np.asarray(Hs.get_col())], np.arange(Hs.nnz()))

    fns = {"grad_f": ca.Function("design_grad_f", [z, par], [f, grad_f], ["x", "p"], ["f", "grad"]),
           "jac_g": ca.Function("design_jac_g", [z, par], [g_j, jac.build()],
                                ["x", "p"], ["g", "jac"]),
           "hess_lag": ca.Function("design_hess_lag", [z, par, lam_f, lam_g], [hess.build()],
                                   ["x", "p", "lam_f", "lam_g"], ["hess"])}
    return {"x": z, "p": par, "f": f, "g": g}, fns


# ---------------------------------------------------------------------------------------------- flattened NLP
#: IPOPT options of a warm-started design (the start is an equilibrium with its least-squares multipliers):
#: a small first barrier parameter and bound push keep IPOPT near that start instead of recentring the
#: contractions and tensions, and the least-squares estimate of the constraints' multipliers (a
#: factorisation) is skipped. The barrier starts at 1e-11 (IPOPT's smallest), so no iteration only lowers it
#: to the tolerance, and the bounds' multipliers at 1e-8 instead of 1 (the start's bounds are inactive but
#: for slack ropes and contractions at 0).
WARM_START_OPTIONS = {"mu_init": 1e-11, "bound_push": 1e-10, "bound_frac": 1e-10, "constr_mult_init_max": 0.0,
                      "bound_mult_init_val": 1e-8}


#: the warm start's forward solve stops at this scaled KKT residual (the NLP meets its equilibrium rows itself)
WARM_START_TOL = 1e-4

#: MUMPS's fill-reducing ordering for the design's KKT matrices: approximate minimum degree (0) instead of
#: MUMPS's automatic choice, which on bench_design's strips with 4 muscles (300 to 10k nodes) made the
#: design's IPOPT call slower at every size, with the same iterations except at 10k nodes (noisy target: 33
#: iterations against 18 with AMD). QAMD (6) was close to AMD; METIS, PORD, AMF and SCOTCH were slower.
MUMPS_ORDERING = 0


#: IPOPT's relaxation of the variable bounds (its default 1e-8 lets a contraction end 1e-8 beyond its bound):
#: none, so a contraction at ``a_max``, at its cap or at 0 is the one the ropes' lengths were solved for.
#: With the default, clipping it back left the rope 1e-8 L0 off its target, which the forward solver's
#: measure reads as a slack rope (scaled KKT residual 1e-3), and the design's state took a Newton polish
#: (the strip of bench_fine_design with two ropes at their caps; commit 8be3578 has the figures)
BOUND_RELAX = 0.0


#: flattened-design solvers kept per mesh (one per muscles, model, Hessian, derivatives and IPOPT options)
DESIGN_SOLVERS_KEPT = 8


def _flattened_solver(prob: DesignProblem, hessian: str, derivatives: str, opts_key: tuple, ipopt_opts: dict):
    """The flattened NLP's solver, cached on the mesh per muscles, muscle model, Hessian mode, derivatives
    and options.

    Parameters of the NLP: target ``y`` (2n), weights (n), ``p0``, objective scale, constraint scale, so one
    built solver serves any target, weights, material numbers and stiffness.

    ``derivatives="numeric"`` gives IPOPT numpy callbacks (:func:`~mdsr_opt.synthesis.nlp_numeric.numeric_nlp`)
    where they apply (a Neo-Hookean or linear elastic body), else what ``"assembled"`` gives: the
    derivatives assembled term by term in MX (:func:`_assembled_nlp`); ``"casadi"`` builds the NLP in SX
    and lets CasADi differentiate it.
    """
    mesh = prob.mesh
    if derivatives == "numeric" and not numeric_supports(prob):
        derivatives = "assembled"
    key = ("design-flattened", tuple(mu.nodes for mu in prob.muscles), prob.muscle_model, prob.material.kind,
           prob.anchor_radius, hessian, derivatives, opts_key)
    cache = mesh.__dict__.setdefault("_design_cache", {})
    if key in cache:
        return cache[key][0], 0.0
    if len(cache) >= DESIGN_SOLVERS_KEPT:  # the oldest solver goes, with the callbacks it evaluates
        cache.pop(next(iter(cache)))
    t0 = time.perf_counter()
    opts = {"print_time": False, "error_on_fail": False, "show_eval_warnings": False}
    opts.update({f"ipopt.{k}": v for k, v in ipopt_opts.items()})
    if derivatives == "numeric":
        nlp, fns, keep = numeric_nlp(prob, hessian)  # the callbacks stay alive as long as the solver
        opts.update(fns)
        opts["calc_lam_p"] = False
        opts["no_nlp_grad"] = True  # nlp_grad only serves the multipliers of bounds and parameters
    elif derivatives == "assembled":
        keep = None
        nlp, fns = _assembled_nlp(prob, hessian)
        opts.update(fns)
        opts["calc_lam_p"] = False  # parameter multipliers are not used: skip their derivatives
    else:
        keep = None
        nlp, extra = _symbolic_nlp(prob, hessian)
        opts.update(extra)
    solver = ca.nlpsol("design_flattened", "ipopt", nlp, with_stop_callback(opts))  # Ctrl-C: next iteration
    bt = time.perf_counter() - t0
    cache[key] = (solver, keep)
    return solver, bt


def _symbolic_nlp(prob: DesignProblem, hessian: str):
    """The flattened NLP in SX; CasADi differentiates it (the energy's gradient expanded symbolically)."""
    mesh, model = prob.mesh, prob.model
    n, m = mesh.n_nodes, prob.m
    x = ca.SX.sym("x", 2 * n)
    a = ca.SX.sym("a", m)
    y = ca.SX.sym("y", 2 * n)
    w = ca.SX.sym("w", n)
    p0 = ca.SX.sym("p0", model.n_params)
    so = ca.SX.sym("obj_scale")
    sc = ca.SX.sym("con_scale")
    B = sp.csc_matrix(prob.B)
    Bdm = ca.DM(ca.Sparsity(B.shape[0], B.shape[1], B.indptr.tolist(), B.indices.tolist()), B.data.tolist())
    g = model.grad_fn(x, p0 + ca.mtimes(Bdm, a))[1]
    free = np.nonzero(prob.free)[0].tolist()
    blk = prob.block
    kap = ca.SX.sym("kappa", blk.nc)
    G = sc * g[free]
    if blk.nc:  # the muscle constraints, written from MuscleConstraints directly (not from the block)
        mc = prob.constraints
        parts = []
        if blk.rope:
            parts.append(mc.lengths_expr(x) / ca.DM(prob.L0) - 1.0 + a)
        if blk.n_rigid:
            parts.append(mc.rigid_expr(x) * ca.DM(blk.rigid_scale))
        C = ca.vertcat(*parts)
        Ca = C - (ca.vertcat(a, ca.SX(blk.n_rigid, 1)) if blk.rope else 0)  # the part that depends on x
        G = ca.vertcat(G + ca.gradient(ca.dot(kap, Ca), x)[free], C)
    if prob.free_pose:
        res = ca.reshape(x - y, 2, n)
        z = ca.vertcat(x, a, kap)
    else:  # the pinned pose: a rotation theta and translation t align the state
        th, tt = ca.SX.sym("theta"), ca.SX.sym("t", 2)
        Xm, Ym = ca.reshape(x, 2, n), ca.reshape(y, 2, n)
        res = ca.vertcat(*pinned.residual(Xm[0, :], Xm[1, :], Ym[0, :], Ym[1, :], ca.cos(th), ca.sin(th),
                                          tt[0], tt[1]))
        z = ca.vertcat(x, a, th, tt, kap)
    f = so * ca.dot(w, ca.sum1(res ** 2).T)
    par = ca.vertcat(y, w, p0, so, sc)
    extra = {}
    if hessian == "gauss-newton":
        # Hessian of the objective only (constrained Gauss-Newton): no third derivatives of the energy, and
        # the residuals' Jacobian alone (2 so J' W J)
        lam_f = ca.SX.sym("lam_f")
        lam_g = ca.SX.sym("lam_g", G.numel())
        r = ca.vec(res * ca.repmat(ca.sqrt(w).T, 2, 1))
        Jr = ca.jacobian(r, z)
        Hgn = ca.triu(2 * so * lam_f * ca.mtimes(Jr.T, Jr))
        extra["hess_lag"] = ca.Function("design_hess_gn", [z, par, lam_f, lam_g], [Hgn],
                                        ["x", "p", "lam_f", "lam_g"], ["hess"])
    return {"x": z, "p": par, "f": f, "g": G}, extra


#: IPOPT's exit at its acceptable tolerances: the design is kept, and counts as a success only when its
#: verification passes (a design with ``verify=False`` and this exit is not a success)
ACCEPTABLE = "Solved_To_Acceptable_Level"


#: largest residual (in units of ``E t h``) of the stationarity rows the free-pose NLP leaves out; a solution
#: has them at round-off (1e-14 to 1e-12), a state held by forces on the gauge nodes (possible only at a
#: degenerate pose) at 1e-3
GAUGE_RTOL = 1e-7


def _gauge_residual(prob: DesignProblem, x, a, kappa, sc) -> float:
    """Max-norm of the left-out stationarity rows (the gauge coordinates) at a solution of the NLP."""
    g = prob.model.gradient(x, prob.params(a)) * sc
    blk = prob.block
    if blk.nc:
        g = g + blk.jacobian(x).T @ kappa
    return float(np.abs(g[prob.gauge]).max())


def _discarded(defer, a: np.ndarray, slack: np.ndarray) -> bool:
    """``defer`` (a caller's ``skip_verification``) discards a design with contractions ``a`` whose ropes
    ``slack`` carry no tension: asked with a preview holding ``contractions``, ``slack`` and ``success``
    (a predicate needing more of the design is not asked: False)."""
    if defer is None:
        return False
    try:
        return bool(defer(SimpleNamespace(contractions=a, slack=slack.copy(), success=True)))
    except (AttributeError, TypeError, KeyError):
        return False


def run_flattened(prob, a0, fwd: ForwardSolver, tol, max_iter, hessian, scaling, warm_start, ipopt_options, clock,
                   derivatives="numeric", defer=None):
    mesh, n, m = prob.mesh, prob.mesh.n_nodes, prob.m
    start = None  # the warm start's forward solve starts from this shape (else from rest)
    if isinstance(warm_start, np.ndarray):  # a given shape: handled as the target is
        start, warm_start = warm_start, "target"
    elif warm_start == "target":
        start = prob.y
    ipopt_opts = {"print_level": 0, "sb": "yes", "tol": tol, "max_iter": max_iter, "mu_strategy": "monotone",
                  "mumps_pivot_order": MUMPS_ORDERING, "bound_relax_factor": BOUND_RELAX}
    if warm_start:
        ipopt_opts.update(WARM_START_OPTIONS)
    ipopt_opts.update(ipopt_options or {})
    solver, bt = _flattened_solver(prob, hessian, derivatives,
                                   tuple(sorted((k, repr(v)) for k, v in ipopt_opts.items())), ipopt_opts)
    t_start = time.perf_counter()
    if warm_start:
        # from the target any equilibrium will do (no stability check), since the design is verified
        # (a stable equilibrium, from its state or from rest) and repeated from rest if that fails; the warm
        # start's equilibrium need only meet WARM_START_TOL, and it becomes the forward solver's last state
        x0, ok, status = fwd.solve(a0, start=start, tol=max(fwd.tol, WARM_START_TOL))
        if not ok:
            return None, f"warm start failed: {status}", 0, bt
    else:
        x0 = prob.X.copy()
    J0, al0, _ = prob.objective(x0.reshape(-1, 2))
    history = [(clock(), math.sqrt(J0) * prob.h)]
    if scaling == "auto":
        # a target far from reachable has J0 >> 1 (J grows as 1/h^2 under refinement): dividing by it keeps
        # IPOPT's absolute tolerance a relative one (without it a 4k-node design stopped at "acceptable")
        so, sc = 1.0 / (prob.W * prob.h ** 2) / max(1.0, J0), 1.0 / (prob.Et * prob.h)
    else:  # "size": objective normalised by the body's size (the badly scaled variant, for comparisons)
        so, sc = 1.0 / (prob.W * mesh.size ** 2), 1.0 / (prob.Et * prob.h)
    blk = prob.block
    a_start = np.asarray(a0, dtype=float).copy()
    if warm_start and blk.nc:
        # multipliers of the forward equilibrium (least squares); a rope the forward solve left slack
        # starts at the contraction it reached, at zero tension
        gs = prob.model.gradient(x0, prob.params(a_start)) * sc
        kap0 = blk.multipliers(x0, gs, prob.free)
        if blk.rope:
            ach = prob.achieved(x0.reshape(-1, 2))
            slack = ach < a_start - 1e-9
            a_start[slack] = np.clip(ach[slack], 0.0, prob.a_upper[slack])
            kap0[:m] = np.maximum(kap0[:m], 0.0)
    else:
        kap0 = np.zeros(blk.nc)
    ik = 2 * n + m + prob.nv  # the multipliers kappa
    if prob.free_pose:
        # the target moved into the start's frame (the aligned difference does not change): the state then
        # stays near the solver's gauge frame, where the left-out gauge rows follow from the others (at a
        # pose turning node j's gauge coordinate perpendicular to i-j they would not: see the module)
        y = (prob.y - al0.t) @ al0.R
        z0 = np.concatenate([x0, a_start, kap0])
    else:
        y = prob.y
        z0 = np.concatenate([x0, a_start, [al0.angle], al0.t, kap0])
    lbz = np.full(len(z0), -np.inf)
    ubz = np.full(len(z0), np.inf)
    if not prob.free_pose:
        lbz[prob.gauge] = prob.X[prob.gauge]
        ubz[prob.gauge] = prob.X[prob.gauge]
    lbz[2 * n:2 * n + m] = 0.0
    ubz[2 * n:2 * n + m] = prob.a_upper
    if blk.rope:  # a rope only pulls: tension >= 0
        lbz[ik:ik + m] = 0.0
    par = np.concatenate([y.reshape(-1), prob.w, prob.p0, [so, sc]])
    sol = solver(x0=z0, p=par, lbx=lbz, ubx=ubz, lbg=0.0, ubg=0.0)
    st = solver.stats()
    z = np.asarray(sol["x"]).ravel()
    # "Solved_To_Acceptable_Level": IPOPT stopped at its acceptable tolerances, not at tol (a rounding floor of
    # the objective's decrease on a fine mesh is one way there); kept as found, with the status, and
    # a success only when the verification passes (the design's caller, ACCEPTABLE)
    ok = bool(st.get("success")) and st.get("return_status") in ("Solve_Succeeded", ACCEPTABLE)
    iters = int(st.get("iter_count", 0))
    unpolished = None  # the near-zero tensions of a design left unpolished
    if ok and blk.rope:
        # A slack rope sits on its bound tau = 0 where the interior point method converges slowly (a
        # degenerate bound: its multiplier is about zero too, e.g. when the target is reachable), leaving
        # tensions of ~1e-7 and contractions off by ~1e-6. Polish: fix the near-zero tensions at 0 (their
        # ropes then only measure a = achieved contraction) and solve again from the solution; kept when
        # it converges and the objective is no worse.
        kr = z[ik:ik + m]
        small = kr < 1e-4 * max(1.0, float(kr.max()))
        if small.any() and _discarded(defer, np.clip(z[2 * n:2 * n + m], 0.0, prob.a_upper), small):
            # the caller discards this design (it makes the layout again without its idle muscles): the
            # polish would only turn the near-zero tensions into zeros, so they are reported as zeros
            unpolished = small.copy()
            small[:] = False
        if small.any():
            lb2, ub2 = lbz.copy(), ubz.copy()
            lb2[ik + np.nonzero(small)[0]] = 0.0
            ub2[ik + np.nonzero(small)[0]] = 0.0
            z2 = z.copy()
            z2[ik + np.nonzero(small)[0]] = 0.0
            sol2 = solver(x0=z2, p=par, lbx=lb2, ubx=ub2, lbg=0.0, ubg=0.0)
            st2 = solver.stats()
            iters += int(st2.get("iter_count", 0))
            if st2.get("return_status") == "Solve_Succeeded" and \
                    float(sol2["f"]) <= float(sol["f"]) * (1 + 1e-6) + 1e-14:
                z = np.asarray(sol2["x"]).ravel()
    status = str(st.get("return_status", "unknown"))
    if ok and status == ACCEPTABLE:
        status += " (IPOPT's acceptable tolerances met, not tol)"
    if ok and prob.free_pose:  # the left-out gauge rows must vanish with the others
        gres = _gauge_residual(prob, z[:2 * n], z[2 * n:2 * n + m], z[ik:], sc)
        if gres > GAUGE_RTOL:
            ok = False
            status += f"; rejected: the gauge coordinates are not in equilibrium (residual {gres:.3g})"
    kappa = z[ik:].copy()
    if unpolished is not None:
        kappa[np.flatnonzero(unpolished)] = 0.0
    out = {"x": z[:2 * n], "a": np.clip(z[2 * n:2 * n + m], 0.0, prob.a_upper), "success": ok,
           "kappa": kappa, "status": status, "iterations": iters,
           "history": history, "initial_difference": math.sqrt(J0) * prob.h, "t_start": t_start}
    return out, out["status"], out["iterations"], bt
