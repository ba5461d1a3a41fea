"""A projected Newton method in numpy/scipy: the ``newton`` backend, written to be fast.

The energy of an :class:`~mdsr_opt.model.EnergyModel` without sliding cables is a sum over triangles
(Neo-Hookean or linear elastic) and edge springs. This module evaluates it, its gradient and a positive
semi-definite approximation of its Hessian with vectorised numpy (no per-element Python or CasADi call):

* elements: ``F = Ds B`` (``B = Dm^-1``), first Piola stress ``P`` and the 4 x 4 tangent ``dP/dF`` in closed
  form; the tangent is projected to positive semi-definite per element (batched 4 x 4 ``eigh``), so the
  element Hessian ``area D' (dP/dF)+ D`` is positive semi-definite too;
* springs ``k/2 (l - r l0)^2``: the 2 x 2 block ``k (u u' + max(1 - r l0 / l, 0) (I - u u'))``;
  only springs with ``k != 0`` are evaluated.

Assembly scatters the element blocks with one ``bincount`` into a fixed CSC pattern of the free-free
Hessian, made once per model and set of fixed coordinates together with a fill-reducing ordering (from
SuperLU's first factorisation); every later factorisation reuses that ordering (``permc_spec="NATURAL"`` on
the symmetrically permuted matrix, symmetric mode). A backtracking (Armijo) line search keeps every
triangle un-inverted.

Example
-------
>>> import numpy as np
>>> from mdsr_opt import Mesh, NeoHookean, solve_external
>>> mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
>>> left = np.flatnonzero(mesh.points[:, 0] < 1e-9); right = np.flatnonzero(mesh.points[:, 0] > 4 - 1e-9)
>>> a = solve_external(mesh, NeoHookean(1.0, 0.3), left, (right, mesh.points[right] + [1.0, 0.0]), backend="newton")
>>> b = solve_external(mesh, NeoHookean(1.0, 0.3), left, (right, mesh.points[right] + [1.0, 0.0]))
>>> a.success, abs(a.energy - b.energy) < 1e-10
(True, True)
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = ["NewtonEnergy", "projected_newton", "step_seconds"]


def _pd4(A: np.ndarray) -> np.ndarray:
    """Mask of the (N, 4, 4) symmetric blocks that are positive definite: every pivot of an LDL' without
    pivoting (leading principal minors) positive, in a few vectorised operations."""
    A = A.copy()
    ok = np.ones(len(A), dtype=bool)
    for k in range(4):
        d = A[:, k, k]
        ok &= d > 0
        if k < 3:
            r = A[:, k + 1:, k] / np.where(d > 0, d, 1.0)[:, None]
            A[:, k + 1:, k + 1:] -= r[:, :, None] * A[:, None, k, k + 1:]
    return ok


def _psd4(A: np.ndarray) -> np.ndarray:
    """Clamp the negative eigenvalues of each symmetric (N, 4, 4) block to zero (``eigh`` only on the blocks
    that are not positive definite already)."""
    bad = np.flatnonzero(~_pd4(A))
    if not len(bad):
        return A
    w, V = np.linalg.eigh(A[bad])
    out = A.copy()
    out[bad] = (V * np.maximum(w, 0.0)[:, None, :]) @ np.swapaxes(V, 1, 2)
    return out


class NewtonEnergy:
    """Vectorised energy, gradient and projected Hessian of an :class:`~mdsr_opt.model.EnergyModel`.

    Parameters
    ----------
    model : EnergyModel
        A model without sliding cables, of a Neo-Hookean or linear elastic material.
    p : (n_params,) array
        The model's parameters (:meth:`EnergyModel.params`): ``[mu t, lam t]``, spring stiffnesses and
        rest-length ratios.
    """

    def __init__(self, model, p, geometry: "NewtonEnergy | None" = None):
        if getattr(model, "cables", ()):
            raise ValueError("the element-wise Newton baseline does not support sliding cables")
        if model.material_kind not in ("neo-hookean", "linear"):
            raise ValueError(f"the newton backend supports neo-hookean and linear materials, got "
                             f"{model.material_kind!r}")
        mesh = model.mesh
        p = np.asarray(p, dtype=float).ravel()
        self.n = model.n_dof
        self.kind = model.material_kind
        self.mu, self.lam = float(p[0]), float(p[1])
        self.tri = mesh.triangles
        self.elem_dofs = model.elem_dofs
        if geometry is not None and geometry.tri is self.tri:  # same mesh: the parameter-free arrays
            self.B, self.area, self.D, self.DT = geometry.B, geometry.area, geometry.D, geometry.DT
        else:
            self.B = np.asarray(mesh.Dm_inv, dtype=float)  # (m, 2, 2)
            self.area = np.asarray(mesh.areas, dtype=float)
            # D: vec(F) (row-major F00, F01, F10, F11) from the 6 element dofs (x0, y0, x1, y1, x2, y2)
            m = len(self.tri)
            B = self.B
            D = np.zeros((m, 4, 6))
            for i in range(2):  # F_ij = sum_k Ds_ik B_kj, Ds_i0 = x1_i - x0_i, Ds_i1 = x2_i - x0_i
                for j in range(2):
                    D[:, 2 * i + j, 2 + i] = B[:, 0, j]
                    D[:, 2 * i + j, 4 + i] = B[:, 1, j]
                    D[:, 2 * i + j, i] = -(B[:, 0, j] + B[:, 1, j])
            self.D = D
            self.DT = np.ascontiguousarray(np.swapaxes(D, 1, 2))
        ne = model.n_edges
        k, r = p[2:2 + ne], p[2 + ne:2 + 2 * ne]
        on = np.flatnonzero(k != 0.0)
        self.spring_on = on  #: indices of the edges whose spring has a stiffness
        self.k, self.rl0 = k[on], r[on] * np.asarray(mesh.edge_lengths, dtype=float)[on]
        self.edges = np.asarray(mesh.edges)[on]
        self.edge_dofs = model.edge_dofs[on]

    # ----------------------------------------------------------------------------------------- elements
    def _F(self, x):
        X = x.reshape(-1, 2)[self.tri]  # (m, 3, 2)
        Ds = np.stack([X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]], axis=2)  # columns: edges
        return Ds @ self.B

    def energy(self, x) -> float:
        """The energy at ``x`` (flat, 2n); ``inf`` when a triangle is inverted (Neo-Hookean)."""
        F = self._F(x)
        if self.kind == "neo-hookean":
            # in terms of F - I (tr F'F - 2 = |F - I|^2 + 2 tr(F - I), ln J = log1p(J - 1)): no cancellation
            # of O(1) terms, so a state at rest has an energy of round-off squared, not of round-off
            a, d = F[:, 0, 0] - 1.0, F[:, 1, 1] - 1.0
            b, c = F[:, 0, 1], F[:, 1, 0]
            Jm1 = a + d + (a * d - b * c)
            if not (Jm1 > -1.0).all():
                return np.inf
            lnJ = np.log1p(Jm1)
            psi = (self.mu / 2 * (a * a + b * b + c * c + d * d) + self.mu * ((a + d) - lnJ)
                   + self.lam / 2 * lnJ ** 2)
        else:
            e = 0.5 * (F + np.swapaxes(F, 1, 2)) - np.eye(2)
            tr = e[:, 0, 0] + e[:, 1, 1]
            psi = self.mu * (e * e).sum(axis=(1, 2)) + self.lam / 2 * tr ** 2
        W = float(self.area @ psi)
        if len(self.k):
            X = x.reshape(-1, 2)
            l = np.linalg.norm(X[self.edges[:, 1]] - X[self.edges[:, 0]], axis=1)
            W += float(0.5 * (self.k * (l - self.rl0) ** 2).sum())
        return W

    def _stress_tangent(self, F, tangent: bool):
        """``(P (m, 2, 2), dP/dF (m, 4, 4) or None)``, row-major vec of ``F``."""
        m = len(F)
        if self.kind == "neo-hookean":
            J = F[:, 0, 0] * F[:, 1, 1] - F[:, 0, 1] * F[:, 1, 0]
            lnJ = np.log(J)
            G = np.stack([np.stack([F[:, 1, 1], -F[:, 1, 0]], 1), np.stack([-F[:, 0, 1], F[:, 0, 0]], 1)], 1)
            G = G / J[:, None, None]  # F^-T
            P = self.mu * F + (self.lam * lnJ - self.mu)[:, None, None] * G
            if not tangent:
                return P, None
            g = G.reshape(m, 4)
            # dP_ij/dF_kl = mu d_ik d_jl + (mu - lam lnJ) G_il G_kj + lam G_ij G_kl
            A = self.mu * np.broadcast_to(np.eye(4), (m, 4, 4)).copy()
            A += self.lam * g[:, :, None] * g[:, None, :]
            cross = (G[:, :, None, None, :] * np.swapaxes(G, 1, 2)[:, None, :, :, None]).reshape(m, 4, 4)  # G_il G_kj
            A += (self.mu - self.lam * lnJ)[:, None, None] * cross
            return P, A
        e = 0.5 * (F + np.swapaxes(F, 1, 2)) - np.eye(2)
        tr = e[:, 0, 0] + e[:, 1, 1]
        P = 2 * self.mu * e + (self.lam * tr)[:, None, None] * np.eye(2)
        if not tangent:
            return P, None
        I2 = np.eye(2)
        C = (self.mu * (np.einsum("ik,jl->ijkl", I2, I2) + np.einsum("il,jk->ijkl", I2, I2))
             + self.lam * np.einsum("ij,kl->ijkl", I2, I2)).reshape(4, 4)
        return P, np.broadcast_to(C, (m, 4, 4))

    def gradient(self, x) -> np.ndarray:
        """The energy gradient (2n,)."""
        P, _ = self._stress_tangent(self._F(x), False)
        ge = (P.reshape(-1, 1, 4) * self.area[:, None, None]) @ self.D
        g = np.bincount(self.elem_dofs.ravel(), weights=ge.ravel(), minlength=self.n)
        if len(self.k):
            gs = self._spring_terms(x, False)[0]
            g += np.bincount(self.edge_dofs.ravel(), weights=gs.ravel(), minlength=self.n)
        return g

    def _spring_terms(self, x, hessian: bool, project: bool = True):
        X = x.reshape(-1, 2)
        d = X[self.edges[:, 1]] - X[self.edges[:, 0]]
        l = np.maximum(np.linalg.norm(d, axis=1), 1e-300)
        u = d / l[:, None]
        f = (self.k * (l - self.rl0))[:, None] * u  # dW/d(x_j) = f, dW/d(x_i) = -f
        g = np.concatenate([-f, f], axis=1)
        if not hessian:
            return g, None
        s = 1.0 - self.rl0 / l
        if project:
            s = np.maximum(s, 0.0)
        uu = u[:, :, None] * u[:, None, :]
        K = self.k[:, None, None] * (uu + s[:, None, None] * (np.eye(2) - uu))
        H = np.empty((len(K), 4, 4))
        H[:, :2, :2] = K
        H[:, 2:, 2:] = K
        H[:, :2, 2:] = -K
        H[:, 2:, :2] = -K
        return g, H

    def element_blocks(self, x, project: bool = True):
        """``(gradient (2n,), element Hessians (m, 6, 6), spring Hessians (s, 4, 4))`` at ``x``; projected
        to positive semi-definite per term unless ``project=False`` (then their sum is the exact Hessian).
        The element tangents are kept for :meth:`projected_blocks`."""
        P, A = self._stress_tangent(self._F(x), True)
        self._A = A = np.ascontiguousarray(A)
        self._x = x
        ge = (P.reshape(-1, 1, 4) * self.area[:, None, None]) @ self.D
        g = np.bincount(self.elem_dofs.ravel(), weights=ge.ravel(), minlength=self.n)
        if project:
            A = _psd4(A)
        He = (self.DT @ (A @ self.D)) * self.area[:, None, None]
        Hs = np.zeros((0, 4, 4))
        if len(self.k):
            gs, Hs = self._spring_terms(x, True, project)
            g += np.bincount(self.edge_dofs.ravel(), weights=gs.ravel(), minlength=self.n)
        return g, He, Hs

    def hessian_blocks(self, x):
        """The exact element Hessians (m, 6, 6) and spring Hessians (s, 4, 4) at ``x`` (their sum is the
        Hessian), without the gradient."""
        _P, A = self._stress_tangent(self._F(x), True)
        He = (self.DT @ (A @ self.D)) * self.area[:, None, None]
        Hs = self._spring_terms(x, True, False)[1] if len(self.k) else np.zeros((0, 4, 4))
        return He, Hs

    def projected_blocks(self):
        """The projected element and spring blocks at the state of the last :meth:`element_blocks` call."""
        He = (self.DT @ (_psd4(self._A) @ self.D)) * self.area[:, None, None]
        Hs = self._spring_terms(self._x, True, True)[1] if len(self.k) else np.zeros((0, 4, 4))
        return He, Hs

    def hessian(self, x, project: bool = False) -> sp.csc_matrix:
        """The assembled (2n, 2n) Hessian (exact unless ``project``): for checks."""
        _g, He, Hs = self.element_blocks(x, project)
        rows, cols, vals = [], [], []
        for dofs, H in ((self.elem_dofs, He), (self.edge_dofs, Hs)):
            d = dofs.shape[1]
            rows.append(np.repeat(dofs, d, axis=1).ravel())
            cols.append(np.tile(dofs, (1, d)).ravel())
            vals.append(H.ravel())
        return sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                             shape=(self.n, self.n))


class _Pattern:
    """The CSC pattern of the free-free Hessian (permuted by a fill-reducing ordering), where each element
    and spring block entry lands in it, and the ordering, made once per model and fixed mask."""

    def __init__(self, energy: NewtonEnergy, free: np.ndarray):
        n = energy.n
        newidx = np.full(n, -1, dtype=np.int64)
        self.free_idx = np.flatnonzero(free)
        newidx[self.free_idx] = np.arange(len(self.free_idx))
        nf = len(self.free_idx)
        r, c = [], []
        for dofs in (energy.elem_dofs, energy.edge_dofs):
            d = dofs.shape[1]
            r.append(np.repeat(dofs, d, axis=1).ravel())
            c.append(np.tile(dofs, (1, d)).ravel())
        rows, cols = newidx[np.concatenate(r)], newidx[np.concatenate(c)]
        keep = (rows >= 0) & (cols >= 0)
        self.keep = keep
        rows, cols = rows[keep], cols[keep]
        # ordering: SuperLU's minimum degree on the pattern, once
        S = sp.csc_matrix((np.ones(len(rows)), (rows, cols)), shape=(nf, nf))
        S.sum_duplicates()
        S = S + sp.identity(nf, format="csc") * (4.0 * abs(S).sum(axis=1).max())  # diagonally dominant: no pivoting
        lu = spla.splu(S.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                       options={"SymmetricMode": True})
        perm = np.asarray(lu.perm_c)  # SuperLU: Pc[i, perm_c[i]] = 1, i.e. old column i is new column perm_c[i]
        self.order = np.argsort(perm)  # old index at each new position
        rp, cp = perm[rows], perm[cols]
        key = cp.astype(np.int64) * nf + rp
        uniq, self.pos = np.unique(key, return_inverse=True)
        self.indptr = np.searchsorted(uniq // nf, np.arange(nf + 1)).astype(np.int32)
        self.indices = (uniq % nf).astype(np.int32)
        self.nnz = len(uniq)
        self.nf = nf
        self.perm = perm
        self.diag = np.flatnonzero(self.indices == np.repeat(np.arange(nf), np.diff(self.indptr)))

    def matrix(self, He, Hs) -> sp.csc_matrix:
        vals = np.concatenate([He.ravel(), Hs.ravel()])[self.keep]
        data = np.bincount(self.pos, weights=vals, minlength=self.nnz)
        return sp.csc_matrix((data, self.indices, self.indptr), shape=(self.nf, self.nf))


def _newton_step(pat: _Pattern, He, Hs, g):
    """``-H^-1 g`` when the assembled ``H`` (slightly regularised) is positive definite (the pivots of its
    symmetric factorisation, in the ordering made once), else None."""
    H = pat.matrix(He, Hs)
    H.data[pat.diag] += 1e-10 * float(np.abs(H.data[pat.diag]).max())
    try:
        lu = spla.splu(H, permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    except RuntimeError:  # singular
        return None
    if not (np.array_equal(lu.perm_r, lu.perm_c) and (lu.U.diagonal() > 0).all()):
        return None
    dz = np.empty(pat.nf)
    dz[pat.order] = -lu.solve(g[pat.order])
    return dz


def projected_newton(model, p, x0, fixed, values, tol: float = 1e-8, max_iter: int = 200):
    """Minimise the model's energy over the free coordinates by projected Newton.

    Returns ``(x, success, status, iterations, seconds)``. Converged when the max-norm of the free gradient
    is at most ``tol * max(1, its initial value)``, as the previous baseline did."""
    t0 = time.perf_counter()
    fixed = np.asarray(fixed, dtype=bool)
    free = ~fixed
    x = np.array(x0, dtype=float)
    x[fixed] = values
    en = NewtonEnergy(model, p)
    cache = model.__dict__.setdefault("_newton_patterns", {})
    key = fixed.tobytes()
    if key not in cache:
        cache.clear()  # one mask at a time: patterns are large
        cache[key] = _Pattern(en, free)
    pat = cache[key]
    f = en.energy(x)
    status, success, it, scale = "max_iter", False, 0, None
    if not np.isfinite(f):
        return x, False, "the first guess inverts a triangle", 0, time.perf_counter() - t0
    for it in range(1, max_iter + 1):
        g_all, He, Hs = en.element_blocks(x, project=False)
        g = g_all[free]
        gn = float(np.abs(g).max()) if g.size else 0.0
        if scale is None:
            scale = max(gn, 1e-300)
        if gn <= tol * max(1.0, scale) or not g.size:
            status, success = "converged", True
            it -= 1
            break
        # the exact Hessian when it is positive definite (quadratic convergence near the minimum, where the
        # per-term projection would discard the curvature of compressed elements), else the projected one
        dz = _newton_step(pat, He, Hs, g)
        if dz is None:
            dz = _newton_step(pat, *en.projected_blocks(), g)
        if dz is None:
            status = "linear solve failed: the projected Hessian is singular"
            break
        slope = float(g @ dz)
        t = 1.0
        while t > 1e-8:
            y = x.copy()
            y[free] += t * dz
            fy = en.energy(y)
            if np.isfinite(fy) and fy <= f + 1e-4 * t * slope:
                break
            if t == 1.0 and np.isfinite(fy) and fy - f <= 1e-13 * abs(f) \
                    and np.abs(en.gradient(y)[free]).max() < gn:
                break  # near the minimum the decrease is below round-off: accept a step that lowers |g|
            t *= 0.5
        else:
            status = "line search failed"
            break
        x, f = y, fy
    return x, success, status, it, time.perf_counter() - t0


def step_seconds(model, p, x, fixed, repeat: int = 5) -> float:
    """Median seconds of one Newton step's work at ``x``: the vectorised assembly of the gradient and the
    exact Hessian, and one sparse factorisation and solve with the reused ordering (the "floor" unit of a
    sparse Newton method; the ordering itself is made once, outside the timing)."""
    fixed = np.asarray(fixed, dtype=bool)
    x = np.asarray(x, dtype=float).ravel()
    en = NewtonEnergy(model, p)
    pat = _Pattern(en, ~fixed)
    ts = []
    for _ in range(max(1, int(repeat))):
        t0 = time.perf_counter()
        g, He, Hs = en.element_blocks(x, project=False)
        _newton_step(pat, He, Hs, g[~fixed])
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))
