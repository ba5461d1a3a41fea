"""A projected Newton method in numpy/scipy: the ``newton`` backend, written to be fast.

The energy of an :class:`~mdsr_opt.mechanics.model.EnergyModel` without sliding cables is a sum over triangles
(any material with closed forms: Neo-Hookean in plane strain or stress, Yeoh, Mooney-Rivlin, linear elastic)
and edge springs. This module evaluates it, its gradient and a positive
semi-definite approximation of its Hessian with vectorised numpy (no per-element Python or CasADi call):

* elements: ``F = Ds B`` (``B = Dm^-1``), the energy density, first Piola stress ``P`` and the 4 x 4 tangent
  ``dP/dF`` in the material's closed forms (:mod:`mdsr_opt.body.material`, where the law is stated once and
  checked against CasADi's derivatives of it); the tangent is projected to positive semi-definite per
  element (in closed form in the basis of ``F``'s SVD, as every material here is isotropic; batched 4 x 4
  ``eigh`` for a tangent that basis does not split), so the element Hessian ``area D' (dP/dF)+ D`` is
  positive semi-definite too;
* springs ``k/2 (l - r l0)^2``: the 2 x 2 block ``k (u u' + max(1 - r l0 / l, 0) (I - u u'))``;
  only springs with ``k != 0`` are evaluated.

Assembly scatters the element blocks with one ``bincount`` into a fixed CSC pattern of the free-free
Hessian, made once per model and set of fixed coordinates together with a fill-reducing ordering (the
model's :meth:`~mdsr_opt.mechanics.model.EnergyModel.free_ordering`); every factorisation uses that
ordering (``permc_spec="NATURAL"`` on the symmetrically permuted matrix, symmetric mode). A backtracking (Armijo) line search keeps every
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

from ..body.material import numeric_law
from ..core.guards import check_stop
from .blas import one_blas_thread
from .segments import length_third, pair_blocks, spring_energy

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


def _psd4(A: np.ndarray, F: np.ndarray | None = None) -> np.ndarray:
    """Clamp the negative eigenvalues of each symmetric (N, 4, 4) block to zero (only the blocks that are not
    positive definite already). With the deformation gradients ``F`` (N, 2, 2) of blocks that are tangents
    ``dP/dF`` of an isotropic energy, in closed form in the basis their SVD gives (:func:`_psd_isotropic`);
    ``eigh`` for the others and for any block that basis does not split."""
    bad = np.flatnonzero(~_pd4(A))
    if not len(bad):
        return A
    out = A.copy()
    if F is not None:
        proj, split = _psd_isotropic(A[bad], F[bad])
        out[bad[split]] = proj[split]
        bad = bad[~split]
        if not len(bad):
            return out
    w, V = np.linalg.eigh(A[bad])
    out[bad] = (V * np.maximum(w, 0.0)[:, None, :]) @ np.swapaxes(V, 1, 2)
    return out


#: the largest coupling, relative to the block's largest entry, between the scaling and the rotation modes of
#: :func:`_psd_isotropic`'s basis for which a tangent counts as split by it (an isotropic energy's is zero up to
#: round-off, about 1e-15)
SPLIT_RTOL = 1e-10


def _psd_isotropic(A: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The positive semi-definite parts of tangents ``A`` (N, 4, 4; rows and columns ``2 i + j`` for
    ``F_ij``) of an isotropic energy at deformation gradients ``F`` (N, 2, 2), and where that applies.

    With ``F = U diag(s1, s2) V'`` (an SVD in closed form: ``U``, ``V`` rotations, ``s2`` may be negative),
    the four matrices ``U S V'`` with ``S`` = ``e1 e1'``, ``e2 e2'``, ``[[0, -1], [1, 0]] / sqrt 2`` and
    ``[[0, 1], [1, 0]] / sqrt 2`` (two scalings, the twist and the flip) are an orthonormal basis in which an
    isotropic energy's tangent has two 2 x 2 blocks (scalings; twist and flip), the analytic eigensystems
    of isotropic distortion energies (Smith, de Goes and Kim, 2019). Each block's positive part is
    ``(B + |B|) / 2`` with ``|B| = (B^2 + |det B| I) / sqrt(tr B^2 + 2 |det B|)``, the eigenvalues clamped at
    zero as ``eigh`` would. Returns ``(projected (N, 4, 4), split (N,) bool)``: False where the blocks
    couple by more than :data:`SPLIT_RTOL` (not an isotropic tangent: the caller uses ``eigh``)."""
    f00, f01, f10, f11 = F[:, 0, 0], F[:, 0, 1], F[:, 1, 0], F[:, 1, 1]
    phi_p = np.arctan2(f10 - f01, f00 + f11)  # F = R(phi) diag(s1, s2) R(theta): phi + theta, then phi - theta
    phi_m = np.arctan2(f10 + f01, f00 - f11)
    phi, theta = 0.5 * (phi_p + phi_m), 0.5 * (phi_p - phi_m)
    cu, su, cv, sv = np.cos(phi), np.sin(phi), np.cos(theta), np.sin(theta)
    # u1 = (cu, su), u2 = (-su, cu) (columns of U); v1 = (cv, -sv), v2 = (sv, cv) (rows of V'); flattened
    # row-major: a b' = (a0 b0, a0 b1, a1 b0, a1 b1)
    u1v1 = np.stack([cu * cv, -cu * sv, su * cv, -su * sv], 1)
    u2v2 = np.stack([-su * sv, -su * cv, cu * sv, cu * cv], 1)
    u2v1 = np.stack([-su * cv, su * sv, cu * cv, -cu * sv], 1)
    u1v2 = np.stack([cu * sv, cu * cv, su * sv, su * cv], 1)
    r = np.sqrt(0.5)
    Q = np.stack([u1v1, u2v2, r * (u2v1 - u1v2), r * (u2v1 + u1v2)], 2)  # (N, 4, 4): columns, the basis
    Qt = np.swapaxes(Q, 1, 2)
    B = Qt @ A @ Q
    scale = np.abs(B).max(axis=(1, 2))
    split = np.abs(B[:, :2, 2:]).max(axis=(1, 2)) <= SPLIT_RTOL * np.maximum(scale, np.finfo(float).tiny)
    P = np.zeros_like(B)
    for lo in (0, 2):  # each block [[p, q], [q, r]]: B^2 = [[p^2 + q^2, q (p + r)], [q (p + r), r^2 + q^2]]
        p, r, q = B[:, lo, lo], B[:, lo + 1, lo + 1], 0.5 * (B[:, lo, lo + 1] + B[:, lo + 1, lo])
        det = np.abs(p * r - q * q)
        den = np.sqrt(p * p + r * r + 2.0 * (q * q + det))
        inv = 0.5 / np.where(den > 0, den, 1.0)
        P[:, lo, lo] = 0.5 * p + (p * p + q * q + det) * inv
        P[:, lo + 1, lo + 1] = 0.5 * r + (r * r + q * q + det) * inv
        P[:, lo, lo + 1] = P[:, lo + 1, lo] = 0.5 * q + q * (p + r) * inv
    return Q @ P @ Qt, split


class NewtonEnergy:
    """Vectorised energy, gradient and projected Hessian of an :class:`~mdsr_opt.mechanics.model.EnergyModel`.

    Parameters
    ----------
    model : EnergyModel
        A model without sliding cables, of a material with closed forms (:func:`numeric_law`).
    p : (n_params,) array
        The model's parameters (:meth:`EnergyModel.params`): the material's two (``[mu t, lam t]`` for
        Neo-Hookean), spring stiffnesses and rest-length ratios.
    """

    def __init__(self, model, p, geometry: "NewtonEnergy | None" = None):
        if getattr(model, "cables", ()):
            raise ValueError("the element-wise Newton baseline does not support sliding cables")
        if not numeric_law(model.material_law):
            raise ValueError(f"the newton backend needs a material with a closed-form law (density, stress_tangent, "
                             f"tangent_derivative: every material of mdsr_opt.body.material), got "
                             f"{model.material_kind!r}; use backend='ipopt', which evaluates any psi_expr")
        mesh = model.mesh
        p = np.asarray(p, dtype=float).ravel()
        self.n = model.n_dof
        self.kind = model.material_kind
        self.law = model.material_law  #: the material's closed forms (density, stress and tangent)
        self.mu, self.lam = float(p[0]), float(p[1])
        self.tri = mesh.triangles
        self.elem_dofs = model.elem_dofs
        if geometry is not None and geometry.tri is self.tri:  # same mesh: the parameter-free arrays
            self.B, self.area, self._Bh, self._cols, self._dofsT = (geometry.B, geometry.area, geometry._Bh,
                                                                    geometry._cols, geometry._dofsT)
        else:
            self.B = np.asarray(mesh.Dm_inv, dtype=float)  # (m, 2, 2)
            self.area = np.asarray(mesh.areas, dtype=float)
            # dF_kj / dx_(a, k) = Bh[a, j]: F = Ds B with Ds = [x1 - x0, x2 - x0] (elements last: (3, 2, m))
            b0, b1 = self.B[:, 0, :].T, self.B[:, 1, :].T
            self._Bh = np.ascontiguousarray(np.stack([-(b0 + b1), b0, b1]))
            self._cols = [np.ascontiguousarray(self.tri[:, a]) for a in range(3)]
            self._dofsT = np.ascontiguousarray(self.elem_dofs.T).ravel()  # (6, m) order
        ne = model.n_edges
        k, r = p[2:2 + ne], p[2 + ne:2 + 2 * ne]
        on = np.flatnonzero(k != 0.0)
        self.spring_on = on  #: indices of the edges whose spring has a stiffness
        self.k, self.rl0 = k[on], r[on] * np.asarray(mesh.edge_lengths, dtype=float)[on]
        self.edges = np.asarray(mesh.edges)[on]
        self.edge_dofs = model.edge_dofs[on]

    # ----------------------------------------------------------------------------------------- elements
    # Element quantities are stored with the element index last ((2, 2, m), (6, 6, m), ...): every operation
    # below is then on contiguous rows of m numbers, several times faster than batches of small matrices.
    def _F(self, x):
        """Deformation gradients ``F[k, j]`` of all elements, (2, 2, m)."""
        xs, ys = x[0::2], x[1::2]
        c0, c1, c2 = self._cols
        X0, Y0 = xs[c0], ys[c0]
        e1 = np.stack([xs[c1] - X0, ys[c1] - Y0])  # (2, m): first edge, Ds[:, 0]
        e2 = np.stack([xs[c2] - X0, ys[c2] - Y0])
        Bh = self._Bh
        return e1[:, None, :] * Bh[1][None] + e2[:, None, :] * Bh[2][None]

    def energy(self, x) -> float:
        """The energy at ``x`` (flat, 2n); ``inf`` when a triangle is inverted (Neo-Hookean)."""
        F = self._F(x)
        with np.errstate(divide="ignore", invalid="ignore"):  # an inverted triangle: not finite
            psi = self.law.density(F[0, 0] - 1.0, F[0, 1], F[1, 0], F[1, 1] - 1.0, self.mu, self.lam)
        W = float(self.area @ psi)
        if not np.isfinite(W):
            return np.inf
        if len(self.k):
            X = x.reshape(-1, 2)
            l = np.linalg.norm(X[self.edges[:, 1]] - X[self.edges[:, 0]], axis=1)
            W += float(spring_energy(l, self.k, self.rl0).sum())
        return W

    def _stress_tangent(self, F, tangent: bool):
        """``(P (2, 2, m), dP/dF (2, 2, 2, 2, m) or None)``: ``A[i, j, k, l] = dP_ij / dF_kl`` (the material's
        closed forms)."""
        return self.law.stress_tangent(F, self.mu, self.lam, tangent)

    def _element_gradient(self, P) -> np.ndarray:
        """The elements' contribution to the gradient (2n,) from their stresses."""
        Bh = self._Bh
        ge = (Bh[:, None, 0] * P[None, :, 0] + Bh[:, None, 1] * P[None, :, 1]) * self.area  # (3, 2, m)
        return np.bincount(self._dofsT, weights=ge.ravel(), minlength=self.n)

    def _element_hessians(self, A) -> np.ndarray:
        """``area Bh' A Bh`` per element, (6, 6, m) with local dofs ``(x0, y0, x1, y1, x2, y2)``: entry
        ``(2a + k, 2b + l) = area sum_jn Bh[a, j] A[k, j, l, n] Bh[b, n]``, the upper triangle computed
        and mirrored (``A`` has the major symmetry of a second derivative)."""
        Bh = self._Bh
        m = Bh.shape[-1]
        H = np.empty((6, 6, m))
        aB = Bh * self.area
        for k in range(2):
            for l in range(k, 2):
                A00, A01, A10, A11 = A[k, 0, l, 0], A[k, 0, l, 1], A[k, 1, l, 0], A[k, 1, l, 1]
                for a in range(3):
                    q0 = aB[a, 0] * A00 + aB[a, 1] * A10
                    q1 = aB[a, 0] * A01 + aB[a, 1] * A11
                    for b in range(a if k == l else 0, 3):
                        h = q0 * Bh[b, 0] + q1 * Bh[b, 1]
                        H[2 * a + k, 2 * b + l] = h
                        H[2 * b + l, 2 * a + k] = h
        return H

    def gradient(self, x) -> np.ndarray:
        """The energy gradient (2n,)."""
        P, _ = self._stress_tangent(self._F(x), False)
        g = self._element_gradient(P)
        if len(self.k):
            gs = self._spring_terms(x, False)[0]
            g += np.bincount(self.edge_dofs.ravel(), weights=gs.ravel(), minlength=self.n)
        return g

    def _spring_terms(self, x, hessian: bool, project: bool = True):
        """Spring gradients (s, 4) and Hessians (4, 4, s)."""
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
        return g, pair_blocks(K)

    def element_blocks(self, x, project: bool = True):
        """``(gradient (2n,), element Hessians (6, 6, m), spring Hessians (4, 4, s))`` at ``x``; projected
        to positive semi-definite per term unless ``project=False`` (then their sum is the exact Hessian).
        The element tangents are kept for :meth:`projected_blocks`."""
        F = self._F(x)
        P, A = self._stress_tangent(F, True)
        self._A = A
        self._x = x
        g = self._element_gradient(P)
        He = self._element_hessians(_project_tangent(A, F) if project else A)
        Hs = np.zeros((4, 4, 0))
        if len(self.k):
            gs, Hs = self._spring_terms(x, True, project)
            g += np.bincount(self.edge_dofs.ravel(), weights=gs.ravel(), minlength=self.n)
        return g, He, Hs

    def hessian_blocks(self, x):
        """The exact element Hessians (6, 6, m) and spring Hessians (4, 4, s) at ``x`` (their sum is the
        Hessian), without the gradient."""
        _P, A = self._stress_tangent(self._F(x), True)
        Hs = self._spring_terms(x, True, False)[1] if len(self.k) else np.zeros((4, 4, 0))
        return self._element_hessians(A), Hs

    def third_blocks(self, x, v):
        """The exact third derivative of the energy along ``v``, ``D^3 E(x)[v]``, as element blocks (6, 6, m)
        and spring blocks (4, 4, s) (their sum is the derivative of the Hessian along ``v``).

        An element has ``area Bh' dA Bh`` with ``dA`` the derivative of the tangent along ``dF = F(v)`` (``F``
        is linear in the coordinates; the material's ``tangent_derivative``, none for a linear material). A
        spring ``k/2 (l - c)^2`` (``c`` its rest length) has ``-k c D^3 l [dv]``
        (:func:`~mdsr_opt.mechanics.segments.length_third`, ``dv`` the relative move along ``v``).
        """
        x = np.asarray(x, dtype=float).reshape(-1)
        v = np.asarray(v, dtype=float).reshape(-1)
        if self.law.tangent_derivative is None:  # a constant tangent
            He = np.zeros((6, 6, self.tri.shape[0]))
        else:
            He = self._element_hessians(self.law.tangent_derivative(self._F(x), self._F(v), self.mu, self.lam))
        Hs = np.zeros((4, 4, 0))
        if len(self.k):
            X, V = x.reshape(-1, 2), v.reshape(-1, 2)
            i, j = self.edges[:, 0], self.edges[:, 1]
            Hs = pair_blocks(-(self.k * self.rl0)[:, None, None] * length_third(X[j] - X[i], V[j] - V[i]))
        return He, Hs

    def projected_blocks(self):
        """The projected element and spring blocks at the state of the last :meth:`element_blocks` call."""
        He = self._element_hessians(_project_tangent(self._A, self._F(self._x)))
        Hs = self._spring_terms(self._x, True, True)[1] if len(self.k) else np.zeros((4, 4, 0))
        return He, Hs

    def hessian(self, x, project: bool = False) -> sp.csc_matrix:
        """The assembled (2n, 2n) Hessian (exact unless ``project``): for checks."""
        _g, He, Hs = self.element_blocks(x, project)
        rows, cols, vals = [], [], []
        for dofs, H in ((self.elem_dofs, He), (self.edge_dofs, Hs)):
            r, c = _block_rows_cols(dofs)
            rows.append(r)
            cols.append(c)
            vals.append(H.ravel())
        return sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                             shape=(self.n, self.n))


def _project_tangent(A, F=None):
    """The tangents (2, 2, 2, 2, m) with each element's 4 x 4 matrix projected to positive semi-definite;
    ``F`` (2, 2, m), the elements' deformation gradients, for the closed form of an isotropic tangent
    (:func:`_psd4`)."""
    if A.ndim == 5 and A.shape[-1] > 1:
        m = A.shape[-1]
        Am = np.ascontiguousarray(np.moveaxis(A.reshape(4, 4, m), -1, 0))
        Fm = None if F is None else np.ascontiguousarray(np.moveaxis(F, -1, 0))
        return np.moveaxis(_psd4(Am, Fm), 0, -1).reshape(2, 2, 2, 2, m)
    return A  # a constant tangent (linear material) is positive semi-definite


def _block_rows_cols(dofs):
    """Global rows and columns of the entries of blocks (d, d, N) of terms on ``dofs`` (N, d), flattened."""
    N, d = dofs.shape
    D = dofs.T
    return (np.broadcast_to(D[:, None, :], (d, d, N)).ravel(), np.broadcast_to(D[None, :, :], (d, d, N)).ravel())


class _Pattern:
    """The CSC pattern of the free-free Hessian (permuted by a fill-reducing ordering), where each element
    and spring block entry lands in it, and the ordering, made once per model and fixed mask."""

    def __init__(self, energy: NewtonEnergy, free: np.ndarray, order: np.ndarray | None = None):
        n = energy.n
        newidx = np.full(n, -1, dtype=np.int64)
        self.free_idx = np.flatnonzero(free)
        newidx[self.free_idx] = np.arange(len(self.free_idx))
        nf = len(self.free_idx)
        r, c = [], []
        for dofs in (energy.elem_dofs, energy.edge_dofs):
            rr, cc = _block_rows_cols(dofs)
            r.append(rr)
            c.append(cc)
        rows, cols = newidx[np.concatenate(r)], newidx[np.concatenate(c)]
        keep = (rows >= 0) & (cols >= 0)
        self.keep = keep
        rows, cols = rows[keep], cols[keep]
        if order is not None:  # the model's ordering (free coordinates at each new position)
            perm = np.argsort(np.asarray(order))
        else:  # SuperLU's minimum degree on the pattern, once
            S = sp.csc_matrix((np.ones(len(rows)), (rows, cols)), shape=(nf, nf))
            S.sum_duplicates()
            S = S + sp.identity(nf, format="csc") * (4.0 * abs(S).sum(axis=1).max())  # diagonally dominant
            lu = spla.splu(S.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                           options={"SymmetricMode": True})
            perm = np.asarray(lu.perm_c)  # SuperLU: Pc[i, perm_c[i]] = 1: old column i is new column perm_c[i]
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


def _ordering(model, free):
    """The model's fill-reducing ordering of the free coordinates (AMD of the node graph, each node's two
    coordinates together: quicker factorisations of large meshes than SuperLU's minimum degree on the
    coordinates, with the same fill), or None for a model without one."""
    return model.free_ordering(free) if hasattr(model, "free_ordering") else None


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
        cache[key] = _Pattern(en, free, _ordering(model, free))
    pat = cache[key]
    f = en.energy(x)
    status, success, it, scale = "max_iter", False, 0, None
    if not np.isfinite(f):
        return x, False, "the first guess inverts a triangle", 0, time.perf_counter() - t0
    for it in range(1, max_iter + 1):
        check_stop()  # Ctrl-C inside minimize's interruptible block (see mdsr_opt.core.guards)
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
    sparse Newton method; the ordering itself is made once, outside the timing). Only the work a step
    cannot avoid is timed: not the definiteness test of :func:`projected_newton` (extracting SuperLU's
    ``U`` to read its pivots costs about half a factorisation on large meshes)."""
    fixed = np.asarray(fixed, dtype=bool)
    x = np.asarray(x, dtype=float).ravel()
    en = NewtonEnergy(model, p)
    pat = _Pattern(en, ~fixed, _ordering(model, ~fixed))
    ts = []
    for _ in range(max(1, int(repeat))):
        t0 = time.perf_counter()
        with one_blas_thread():  # as the solves run (see mdsr_opt.mechanics.blas)
            g, He, Hs = en.element_blocks(x, project=False)
            H = pat.matrix(He, Hs)
            lu = spla.splu(H, permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
            lu.solve(g[~fixed][pat.order])
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))
