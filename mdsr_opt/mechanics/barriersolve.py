"""Self-contact solved with the barrier (:mod:`~mdsr_opt.mechanics.barrier`) by the project's own Newton
method: ``solve_external(..., contact=True, contact_method="barrier")``.

Each Newton step on the total energy (strain plus barrier) over the free coordinates:

1. the gradient and Hessian blocks (elements, springs, and the 6 x 6 blocks of the node-segment pairs closer
   than ``dhat``); the exact Hessian's step when it is positive definite, else the step of the blocks each
   projected to positive semi-definite (:meth:`~mdsr_opt.mechanics.barrier.BarrierEnergy.blocks`);
2. the pairs that come within ``dhat`` anywhere along the full step (the broad phase over the step's swept
   circles, :func:`~mdsr_opt.mechanics.ccd.swept_pairs`), and among them the earliest time of impact
   ``t*`` (:func:`~mdsr_opt.mechanics.ccd.time_of_impact`);
3. a backtracking (Armijo) line search from ``min(1, 0.8 t*)`` on the total energy, which is infinite at an
   inverted element.

No step reaches a node on a segment (the first trial stops short of the earliest impact and the barrier's
energy only grows closer in), so no accepted state crosses; each accepted load step's state is also checked
exactly (:meth:`~mdsr_opt.body.mesh.Mesh.boundary_crossing`).

Load steps move the fixed coordinates along their path (the drags') as in
:func:`~mdsr_opt.mechanics.loadsteps.load_continuation`: each starts from the Newton predictor of the total
energy (its projected Hessian) for the fixed nodes' move, or, when the straight move to it meets the boundary
or inverts an element, from the state with only the fixed nodes moved; when that fails too, or the step's
Newton iterations do not converge, the step is halved. A success has the scaled gradient of the total energy
(``residual``) at most ``tol``, no crossing, and is checked stable with the exact Hessian of the total energy
(inertia of its factorisation: a minimum, not a saddle).

Example
-------
A strip clamped at both ends and pushed together by 30 % buckles and folds onto itself:

>>> import numpy as np
>>> from mdsr_opt import Mesh, NeoHookean, solve_external
>>> mesh = Mesh.rectangle(4.0, 1.0, 40, 10)
>>> P = mesh.points
>>> left, right = np.flatnonzero(P[:, 0] == 0.0), np.flatnonzero(P[:, 0] == 4.0)
>>> push = {int(i): (P[i, 0] - 1.2, P[i, 1]) for i in right}
>>> res = solve_external(mesh, NeoHookean(1.0, 0.3), left, push, contact=True, contact_method="barrier")
>>> res.success, res.stable, mesh.boundary_crosses(res.x), round(res.energy, 4)
(True, True, False, 0.1823)
>>> len(res.contact["pairs"]) > 0 and res.contact["total_force"] > 0
True
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..core.guards import check_stop, interruptible
from .barrier import KAPPA, BarrierEnergy, pair_dofs, pair_forces, project_psd
from .blas import one_blas_thread
from .ccd import time_of_impact
from .loadsteps import INTERMEDIATE_TOL, STEP_ITER_CAP, equilibrium_result, min_jacobian
from .stability import check_stability

__all__ = ["assemble", "barrier_newton", "barrier_continuation", "barrier_report", "block_matvec", "settle", "stability",
           "solve_with_barrier", "check_planes_at_rest", "TOI_SAFETY", "RESTARTS", "KICK"]

#: the first trial of a line search goes this fraction of the way to the earliest time of impact
TOI_SAFETY = 0.8


def _rows_cols(dofs):
    """Rows and columns of the entries of blocks (k, k, N) on ``dofs`` (N, k), flattened like the blocks."""
    D = np.asarray(dofs).T
    k, N = D.shape
    return np.broadcast_to(D[:, None, :], (k, k, N)).ravel(), np.broadcast_to(D[None, :, :], (k, k, N)).ravel()


def block_matvec(dofs, H, v) -> np.ndarray:
    """``sum_e H_e v[dofs_e]`` scattered back: the product of the assembled matrix of blocks ``H`` (k, k, N)
    on ``dofs`` (N, k) with ``v`` (without assembling it)."""
    if not H.shape[-1]:
        return np.zeros_like(v)
    loc = v[np.asarray(dofs)]  # (N, k)
    out = np.einsum("ijn,nj->ni", H, loc)
    return np.bincount(np.asarray(dofs).ravel(), weights=out.ravel(), minlength=len(v))


class _System:
    """The free-free Hessian of a barrier energy in a fill-reducing order: the elements' and springs' pattern
    made once, the pairs' entries added per step; factorised with a test of definiteness."""

    def __init__(self, bar: BarrierEnergy, free):
        self.free = np.asarray(free, dtype=bool)
        model = bar.model
        order = model.free_ordering(self.free) if hasattr(model, "free_ordering") else np.arange(self.free.sum())
        nf = int(self.free.sum())
        pos = np.empty(nf, dtype=np.int64)
        pos[np.asarray(order)] = np.arange(nf)  # new position of each free coordinate
        self.newidx = np.full(bar.n, -1, dtype=np.int64)
        self.newidx[np.flatnonzero(self.free)] = pos
        self.order, self.nf = np.asarray(order), nf
        en = bar.elastic
        r, c = [], []
        for dofs in (en.elem_dofs, en.edge_dofs):
            rr, cc = _rows_cols(dofs)
            r.append(rr)
            c.append(cc)
        rows, cols = self.newidx[np.concatenate(r)], self.newidx[np.concatenate(c)]
        self.keep = (rows >= 0) & (cols >= 0)
        key = cols[self.keep] * nf + rows[self.keep]
        uniq, self.pos = np.unique(key, return_inverse=True)
        self.indptr = np.searchsorted(uniq // nf, np.arange(nf + 1))
        self.indices = uniq % nf
        self.nnz = len(uniq)

    def matrix(self, He, Hs, pairs, Hp) -> sp.csc_matrix:
        """The assembled free-free matrix (permuted)."""
        vals = np.concatenate([He.ravel(), Hs.ravel()])[self.keep]
        A = sp.csc_matrix((np.bincount(self.pos, weights=vals, minlength=self.nnz), self.indices, self.indptr),
                          shape=(self.nf, self.nf))
        if len(pairs):
            r, c = _rows_cols(pair_dofs(pairs))
            Hpt = np.ascontiguousarray(np.moveaxis(Hp, 0, -1)).ravel()
            r, c = self.newidx[r], self.newidx[c]
            ok = (r >= 0) & (c >= 0)
            A = A + sp.csc_matrix((Hpt[ok], (r[ok], c[ok])), shape=(self.nf, self.nf))
        return A

    def solve(self, He, Hs, pairs, Hp, rhs):
        """``H^-1 rhs`` (free coordinates, natural order) when ``H`` is positive definite, else None."""
        H = self.matrix(He, Hs, pairs, Hp).tocsc()
        dg = H.diagonal()
        H = H + sp.diags(1e-10 * float(np.abs(dg).max(initial=1.0)) * np.ones(self.nf), format="csc")
        try:
            lu = spla.splu(H, permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        except RuntimeError:
            return None
        if not (np.array_equal(lu.perm_r, lu.perm_c) and (lu.U.diagonal() > 0).all()):
            return None
        return _unpermute(lu.solve(rhs[self.order]), self.order)


def _unpermute(v, order):
    out = np.empty_like(v)
    out[order] = v
    return out


def _step(bar, system, x, cand, free, rhs_extra=None, exact=True):
    """Newton's step on the free coordinates at ``x`` (``rhs_extra``: added to the gradient, the predictor's
    load term): ``(step, gradient, exact used)``; step None when even the projected Hessian is singular."""
    g, He, Hs, act, Hp = bar.blocks(x, cand, project=False)
    gf = g[free] if rhs_extra is None else g[free] + rhs_extra
    dz = system.solve(He, Hs, act, Hp, -gf) if exact else None
    if dz is not None:
        return dz, g, True
    He, Hs = bar.elastic.projected_blocks()
    return system.solve(He, Hs, act, project_psd(Hp), -gf), g, False


def _ccd_limit(bar, x, y, cand) -> float:
    """The first trial fraction of the step from ``x`` to ``y``: :data:`TOI_SAFETY` times the earliest time
    of impact of the pairs ``cand`` (swept within ``dhat``), at most 1; 1 with no impact."""
    toi = time_of_impact(x.reshape(-1, 2), y.reshape(-1, 2), cand)
    t = min(float(toi.min()) if len(toi) else np.inf, bar.plane_impact(x, y))
    return 1.0 if not np.isfinite(t) else min(1.0, TOI_SAFETY * t)


def barrier_newton(bar: BarrierEnergy, system: _System, x, free, gtol: float, max_iter: int):
    """Minimise the total energy over the free coordinates from ``x`` (admissible: finite energy, no
    crossing). Returns ``(x, converged, status, iterations, gradient max-norm)``."""
    x = np.array(x, dtype=float)
    cand = bar.pairs(x)
    f = bar.energy(x, cand)
    if not np.isfinite(f):
        return x, False, "the start has an infinite energy", 0, np.inf
    gn = np.inf
    for it in range(1, max_iter + 1):
        check_stop()
        dz, g, _exact = _step(bar, system, x, cand, free)
        gf = g[free]
        gn = float(np.abs(gf).max()) if gf.size else 0.0
        if gn <= gtol:
            return x, True, "converged", it - 1, gn
        if dz is None:
            return x, False, "the projected Hessian is singular", it, gn
        y = x.copy()
        y[free] += dz
        cand = bar.pairs(x, y)
        t = _ccd_limit(bar, x, y, cand)
        slope = float(gf @ dz)
        while t > 1e-12:
            y = x.copy()
            y[free] += t * dz
            fy = bar.energy(y, cand)
            if np.isfinite(fy) and fy <= f + 1e-4 * t * slope:
                break
            if np.isfinite(fy) and fy - f <= 1e-13 * abs(f) and \
                    np.abs(bar.gradient(y, cand)[free]).max() < gn:
                break  # at the minimum the decrease is below round-off: a step that lowers |g|
            t *= 0.5
        else:
            return x, False, f"line search failed (gradient {gn:.3g})", it, gn
        x, f = y, fy
        cand = bar.pairs(x)
    return x, False, f"iteration cap {max_iter} (gradient {gn:.3g})", max_iter, gn


def _admissible_move(bar, x, y, cand=None) -> bool:
    """The straight move from ``x`` to ``y`` meets no boundary segment and ends at a finite energy."""
    if min_jacobian(bar.model.mesh, y) <= 0.0:
        return False
    cand = bar.pairs(x, y) if cand is None else cand
    toi = time_of_impact(x.reshape(-1, 2), y.reshape(-1, 2), cand)
    if len(toi) and np.isfinite(toi).any() or np.isfinite(bar.plane_impact(x, y)):
        return False
    return bool(np.isfinite(bar.energy(y, cand)))


def _predict(bar, system, x, free, fixed, vals):
    """The Newton predictor of the total energy for the fixed coordinates moved to ``vals`` (projected
    Hessian), or None."""
    delta = np.zeros_like(x)
    delta[fixed] = vals - x[fixed]
    cand = bar.pairs(x)
    g, He, Hs, act, Hp = bar.blocks(x, cand, project=True)
    en = bar.elastic
    load = block_matvec(en.elem_dofs, He, delta)
    if Hs.shape[-1]:
        load += block_matvec(en.edge_dofs, Hs, delta)
    if len(act):
        load += block_matvec(pair_dofs(act), np.moveaxis(Hp, 0, -1), delta)
    dz = system.solve(He, Hs, act, Hp, -(g[free] + load[free]))
    if dz is None:
        return None
    y = x.copy()
    y[fixed] = vals
    y[free] += dz
    return y


def barrier_continuation(bar: BarrierEnergy, fixed, values_of, x_start, gtol: float, max_iter: int, min_step: float,
                         verbose: bool = False, loose: float | None = None) -> dict:
    """Apply the fixed coordinates' path ``values_of(s)``, ``s`` from 0 to 1, in adaptive load steps, each
    solved by :func:`barrier_newton` (module docstring). ``gtol``: the last step's bound on the max-norm of
    the free gradient (earlier ones: ``loose``, default ``gtol`` times ``INTERMEDIATE_TOL / 1e-8``, at least
    ``gtol``). Returns a dict: ``x``, ``success``, ``status``, ``iterations``, ``steps``,
    ``gradient``, ``fraction``."""
    mesh = bar.model.mesh
    fixed = np.asarray(fixed, dtype=bool)
    free = ~fixed
    system = _System(bar, free)
    loose = max(gtol, INTERMEDIATE_TOL * gtol / 1e-8) if loose is None else max(gtol, loose)
    x = np.array(x_start, dtype=float)
    s, ds = 0.0, 1.0
    steps, iters, status, gn, escaped, chk = [], 0, "not started", np.inf, 0, None
    x[fixed] = values_of(0.0)
    if not np.isfinite(bar.energy(x, bar.pairs(x))) or mesh.boundary_crossing(x.reshape(-1, 2)) is not None:
        return {"x": x, "success": False, "status": "the first state inverts an element, crosses or touches itself",
                "iterations": 0, "steps": steps, "gradient": np.inf, "fraction": 0.0}
    while s < 1.0 - 1e-12:
        check_stop()
        if ds < min_step:
            return {"x": x, "success": False, "status": f"load stepping stalled at fraction {s:.4g} ({status})",
                    "iterations": iters, "steps": steps, "gradient": gn, "fraction": s}
        s_new = min(1.0, s + ds)
        vals = values_of(s_new)
        guess = _predict(bar, system, x, free, fixed, vals)
        if guess is None or not _admissible_move(bar, x, guess):
            guess = x.copy()
            guess[fixed] = vals
            if not _admissible_move(bar, x, guess):
                status = "the fixed nodes' move meets the boundary or inverts an element"
                ds /= 2
                continue
        cap = max_iter if ds < 4 * min_step else min(max_iter, STEP_ITER_CAP)
        y, ok, st, it, gn_y = barrier_newton(bar, system, guess, free, gtol if s_new >= 1.0 else loose, cap)
        iters += it
        status = st
        if ok and mesh.boundary_crossing(y.reshape(-1, 2)) is not None:
            ok, status = False, ("a crossing the collision detection missed" if bar.self_contact else
                                 "the boundary crosses itself (contact is off: contact=True models it)")
        if ok:  # a buckling body leaves the unstable branch as soon as it buckles
            y, chk, tries, it, gn_s = settle(bar, system, y, fixed, gtol if s_new >= 1.0 else loose, max_iter)
            iters += it
            gn_y = gn_y if gn_s is None else gn_s
            escaped += tries
        if ok:
            x, s, gn = y, s_new, gn_y
            steps.append(s)
            if verbose:
                print(f"  load {s:.4f}: {st}, {it} Newton iterations, {len(bar.active(x, bar.pairs(x)))} pairs")
            ds = min(2 * ds, 1.0 - s) if s < 1.0 else ds
        else:
            ds /= 2
    if escaped:
        status += f"; left a saddle along its negative curvature ({escaped} re-solve(s) over the load steps)"
    return {"x": x, "success": True, "status": status, "iterations": iters, "steps": steps, "gradient": gn,
            "fraction": 1.0, "stability": chk}


#: saddle escape: re-solves from kicked states per load step
RESTARTS = 4

#: saddle escape: the kick's largest node move / body size
KICK = 0.02


def stability(bar: BarrierEnergy, x, fixed):
    """The :class:`~mdsr_opt.mechanics.stability.StabilityCheck` of the exact Hessian of the total energy
    (elements, springs and pairs, none projected) on the free coordinates at ``x``."""
    _g, He, Hs, act, Hp = bar.blocks(x, bar.pairs(x), project=False)
    return check_stability(assemble(bar, He, Hs, act, Hp), ~fixed, order=bar.model.free_ordering(~fixed))


def settle(bar: BarrierEnergy, system, x, fixed, gtol: float, max_iter: int):
    """Leave a saddle: while the exact Hessian at ``x`` is not positive definite, move along its direction of
    negative curvature (:data:`KICK` of the body's size at the largest node move, less if the move meets the
    boundary or inverts an element; the side of lower energy) and minimise again, up to :data:`RESTARTS`
    times. Returns ``(x, last check, re-solves, Newton iterations, gradient max-norm or None)``."""
    chk = stability(bar, x, fixed)
    tries, iters, gn, scale = 0, 0, None, 1.0
    free = ~np.asarray(fixed, dtype=bool)
    while not chk.stable and tries < RESTARTS and chk.direction is not None:
        tries += 1
        v = np.asarray(chk.direction, dtype=float)
        amp = scale * KICK * bar.model.mesh.size / max(float(np.linalg.norm(v.reshape(-1, 2), axis=1).max()), 1e-300)
        best = None
        for sign in (1.0, -1.0):
            a = amp
            for _ in range(10):
                y = x + sign * a * v
                if _admissible_move(bar, x, y):
                    e = bar.energy(y, bar.pairs(y))
                    if best is None or e < best[0]:
                        best = (e, y)
                    break
                a /= 2
        if best is None:
            break
        y, ok, _st, it, gn_y = barrier_newton(bar, system, best[1], free, gtol, max_iter)
        iters += it
        if not ok or bar.model.mesh.boundary_crossing(y.reshape(-1, 2)) is not None:
            scale /= 2
            continue
        x, gn = y, gn_y
        chk = stability(bar, x, fixed)
    return x, chk, tries, iters, gn


def barrier_report(bar: BarrierEnergy, x, fraction: float = 1.0, length: float = 1.0, force: float = 1.0) -> dict:
    """The contact part of a result, as :func:`~mdsr_opt.mechanics.contactsteps.contact_report` gives it for
    the constraint method (lengths times ``length``, forces times ``force``): per pair within ``dhat`` its
    nodes ``(p, a, b)``, distance (``gap``) and the barrier's force ``-kappa b'(d)``; the contact force on
    each node; the total; and the barrier's ``dhat`` and ``kappa``."""
    X = np.asarray(x, dtype=float).reshape(-1, 2)
    act = bar.active(X, bar.pairs(X))
    f, d, node = pair_forces(X, act, bar.kappa, bar.dhat)
    fo, (po, ko, do), node_o = bar.plane_forces(X)
    per_ob = np.zeros((len(bar.planes), 2))
    if len(po):
        np.add.at(per_ob, ko, -fo[:, None] * bar.planes[ko, 1])  # the force the body exerts on each plane
    gaps = np.concatenate([d, do])
    pairs = [{"kind": "self", "nodes": [int(v) for v in act[i]], "obstacle": -1, "gap": float(d[i]) * length,
              "force": float(f[i]) * force} for i in range(len(act))]
    pairs += [{"kind": "obstacle", "nodes": [int(po[i]), -1, -1], "obstacle": int(ko[i]), "gap": float(do[i]) * length,
               "force": float(fo[i]) * force} for i in range(len(po))]
    return {"method": "barrier", "dhat": bar.dhat * length, "kappa": bar.kappa * force / length,
            "gap": float(gaps.min()) * length if len(gaps) else None, "friction": None,
            "load_fraction": float(fraction), "forces_known": True, "pairs": pairs, "n_candidates": len(pairs),
            "node_forces": ((node + node_o) * force).tolist(), "obstacle_forces": (per_ob * force).tolist(),
            "total_force": float(f.sum() + fo.sum()) * force}


def solve_with_barrier(mesh, model, material, p, fixed, values_of, x_start, tol, max_iter, min_step, verbose, mode,
                       units, t_model=0.0, dhat=None, kappa=None, planes=None, self_contact=True):
    """The checked :class:`~mdsr_opt.mechanics.result.EquilibriumResult` (unit body) of a self-contact solve
    by the barrier, with its ``contact`` report in the user's units (:func:`barrier_report`; its
    ``barrier_energy`` the barrier's part of the total energy, which ``energy``, the strain energy, leaves
    out). ``dhat`` in unit lengths, ``kappa`` in units of ``E t`` (None: the defaults of
    :mod:`~mdsr_opt.mechanics.barrier`); ``planes`` (k, 2, 2) rigid half-planes (point, unit normal) on the
    unit body; ``self_contact`` False: the planes alone."""
    if not getattr(model, "is_numeric", False):
        raise ValueError("contact_method='barrier' needs a material with closed forms (every material of "
                         "mdsr_opt.body.material) and no sliding cables")
    F = material.E * material.thickness * mesh.size
    kap = KAPPA if kappa is None else kappa  # in units of E t: the shape of a displacement-driven solve is E's
    fixed_nodes = np.flatnonzero(np.asarray(fixed, dtype=bool).reshape(-1, 2).all(axis=1))
    bar = BarrierEnergy(model, p, dhat, kap * material.E * material.thickness, planes, self_contact, fixed_nodes)
    first = np.array(x_start, dtype=float)
    first[fixed] = values_of(0.0)
    check_planes_at_rest(bar, mesh.points, first, units.length)
    why = "inverts an element" if min_jacobian(mesh, first) <= 0.0 else mesh.boundary_crossing(first.reshape(-1, 2))
    if why is None and not np.isfinite(bar.energy(first, bar.pairs(first))):
        why = "touches itself (a boundary node on a boundary segment)"
    if why is not None:  # refused here: the barrier is infinite there, no state to start from or report on
        raise ValueError(f"contact_method='barrier': the first state (the initial guess with the fixed nodes at "
                         f"the start of their path) {why}")
    t0 = time.perf_counter()
    with interruptible(), one_blas_thread():
        out = barrier_continuation(bar, fixed, values_of, x_start, tol * F, max_iter, min_step, verbose)
        x = out["x"]
        ok, status = out["success"], out["status"]
        chk = out["stability"] if ok else None
        if ok:
            if not chk.stable:
                ok = False
                status += (f"; rejected: not a stable equilibrium ({chk.n_negative} negative, {chk.n_zero} zero "
                           f"curvature directions of the total energy's Hessian)")
    t_solve = time.perf_counter() - t0
    res = equilibrium_result(mesh, model, material, p, p, x, fixed, status, ok, out["iterations"], out["steps"],
                             t_model, t_solve, "newton", mode, tol, check_stability=False,
                             residual=out["gradient"] / F)
    if chk is not None:
        res.stable, res.stability = bool(chk.stable), units.stability_out(chk).summary()
    res.contact = barrier_report(bar, x, out["fraction"], units.length, units.force)
    res.contact["barrier_energy"] = float(bar.contact_energy(x, bar.pairs(x))) * units.energy
    return res


def check_planes_at_rest(bar: BarrierEnergy, rest, x_start, length: float = 1.0) -> None:
    """Refuse (ValueError) a scene whose free boundary nodes lie within ``dhat`` of a half-plane at rest (the
    barrier, infinite at a zero distance, would push them off with no load) or on or inside one in the first
    state ``x_start`` (flat); the message names the nodes (lengths times ``length``)."""
    if not len(bar.planes):
        return
    for X, reach, where in ((rest, bar.dhat, "at rest"), (x_start, 0.0, "in the initial guess")):
        d = bar.plane_distances(np.asarray(X, dtype=float).reshape(-1))
        k, j = np.nonzero(d <= reach if reach == 0.0 else d < reach)
        if len(j):
            nodes = sorted({int(v) for v in bar.plane_nodes[j]})
            few = ", ".join(str(v) for v in nodes[:8]) + (f" ... ({len(nodes)} nodes)" if len(nodes) > 8 else "")
            raise ValueError(
                f"contact_method='barrier': free boundary node(s) {few} lie {where} within the barrier's reach "
                f"dhat = {bar.dhat * length:.4g} of HalfPlane obstacle {int(k[0])} (nearest distance "
                f"{float(d[k, j].min()) * length:.4g}); the barrier is infinite at distance 0 and pushes nodes "
                f"nearer than dhat: lift the body off the plane by at least dhat, anchor those nodes, or use "
                f"contact_method='ipopt'")


def assemble(bar, He, Hs, act, Hp) -> sp.csc_matrix:
    """The (2n, 2n) matrix of the blocks."""
    en = bar.elastic
    parts = [(en.elem_dofs, He), (en.edge_dofs, Hs)]
    if len(act):
        parts.append((pair_dofs(act), np.moveaxis(Hp, 0, -1)))
    rows, cols, vals = [], [], []
    for dofs, H in parts:
        if not H.shape[-1]:
            continue
        r, c = _rows_cols(dofs)
        rows.append(r)
        cols.append(c)
        vals.append(np.ascontiguousarray(H).ravel())
    return sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(bar.n, bar.n))
