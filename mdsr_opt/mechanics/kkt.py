"""Sparse factorisations of KKT matrices ``[[H, J'], [J, 0]]`` in a fill-reducing order.

A KKT matrix is symmetric indefinite with a zero block, so SuperLU's symmetric mode (diagonal pivots, no
ordering of its own) breaks down on it in most orders. It does not when every constraint row is eliminated
right after the last unknown it involves: by then its diagonal entry has filled in (a Schur complement
entry). :func:`kkt_order` makes that order from a fill-reducing ordering of ``H`` (the mesh's, made once);
:func:`kkt_factor` factors in it, checking the result. With diagonal pivots only, the factorisation is
``P K P' = L D L'`` and the signs of ``D`` are the inertia of ``K`` (Sylvester), which for a ``J`` of full
row rank is that of ``H`` on the null space of ``J`` plus ``(m, m, 0)``: :func:`kkt_inertia`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = ["kkt_order", "kkt_factor", "kkt_inertia", "least_squares_multipliers"]


def kkt_order(J, order) -> np.ndarray:
    """The elimination order of ``[[H, J'], [J, 0]]``: the unknowns in ``order`` (a permutation of H's
    rows), each row of ``J`` right after the last unknown it involves (rows involving none first)."""
    J = sp.csr_matrix(J)
    order = np.asarray(order, dtype=np.int64)
    n, m = len(order), J.shape[0]
    pos = np.empty(n, dtype=np.int64)
    pos[order] = np.arange(n)
    last = np.full(m, -1, dtype=np.int64)
    rows = np.repeat(np.arange(m), np.diff(J.indptr))
    np.maximum.at(last, rows, pos[J.indices])
    return np.argsort(np.concatenate([2 * pos, 2 * last + 1]), kind="stable")


class OrderedFactor:
    """SuperLU factor of ``K[perm][:, perm]`` that solves with ``K``; ``d`` the pivots (diagonal of ``U``),
    ``symmetric`` whether only diagonal pivots were taken (then ``d`` gives the inertia). Both are worked
    out when asked (``U`` is a copy of the factor): a solve needs neither."""

    def __init__(self, lu, perm):
        self.lu, self.perm = lu, perm

    @property
    def symmetric(self) -> bool:
        return bool(np.array_equal(self.lu.perm_r, self.lu.perm_c))

    @property
    def d(self) -> np.ndarray:
        return self.lu.U.diagonal()

    def solve(self, rhs):
        out = np.empty(np.shape(rhs), dtype=float)
        out[self.perm] = self.lu.solve(np.asarray(rhs, dtype=float)[self.perm])
        return out


def _kkt(H, J):
    H = sp.csc_matrix(H)
    J = sp.csr_matrix(J)
    return sp.bmat([[H, J.T], [J, None]], format="csc") if J.shape[0] else H


def kkt_factor(H, J, order=None, rtol: float = 1e-8):
    """A factorisation of the KKT matrix ``[[H, J'], [J, 0]]`` with a ``solve(rhs)`` method, or None when
    it is singular.

    With ``order`` (a fill-reducing ordering of ``H``'s rows, e.g.
    :meth:`~mdsr_opt.mechanics.model.EnergyModel.free_ordering`) the factorisation is SuperLU's without an
    ordering of its own in :func:`kkt_order` (symmetric mode, diagonal pivots preferred). On the
    load-stepping predictor of a 3k-node design with 4 cable muscles (6,101 unknowns, 326 constraint rows)
    it has 0.40 M factor entries against 0.88 M with SuperLU's COLAMD, solutions equal to 1e-12. A
    factorisation whose solution of a test right-hand side has a relative residual above ``rtol``
    (a pivot that should not have been taken) is replaced by the COLAMD one, as is a failed one.
    """
    K = _kkt(H, J)
    if order is not None:
        perm = kkt_order(J, order) if J.shape[0] else np.asarray(order, dtype=np.int64)
        try:
            fac = OrderedFactor(spla.splu(K[perm][:, perm].tocsc(), permc_spec="NATURAL", diag_pivot_thresh=0.01,
                                          options={"SymmetricMode": True}), perm)
            b = np.random.default_rng(0).standard_normal(K.shape[0])
            with np.errstate(all="ignore"):
                r = K @ fac.solve(b) - b
            if np.all(np.isfinite(r)) and np.linalg.norm(r) <= rtol * np.linalg.norm(b):
                return fac
        except RuntimeError:
            pass
    try:
        return spla.splu(K)  # COLAMD, not MMD, on this indefinite matrix
    except RuntimeError:
        return None


def kkt_inertia(H, J, order, rtol: float = 1e-10):
    """``(n_negative, n_zero)`` of ``H`` on the null space of ``J`` (``J`` of full row rank) from one
    factorisation of the KKT matrix in :func:`kkt_order`, or None when that factorisation took an
    off-diagonal pivot or failed (the caller then uses another method).

    A pivot with ``|d| <= rtol * max|diag H|`` makes the answer None rather than a guess (the signs of the
    pivots decide only when none is near zero)."""
    K = _kkt(H, J)
    m = J.shape[0]
    perm = kkt_order(J, order)
    try:
        fac = OrderedFactor(spla.splu(K[perm][:, perm].tocsc(), permc_spec="NATURAL", diag_pivot_thresh=0.0,
                                      options={"SymmetricMode": True}), perm)
    except RuntimeError:
        return None
    d = fac.d
    if not fac.symmetric or not np.all(np.isfinite(d)):
        return None
    h = float(abs(sp.csc_matrix(H).diagonal()).max()) or 1.0
    if (np.abs(d) <= rtol * h).any():  # a pivot near zero: not a question for the signs alone
        return None
    n_neg = int((d < 0).sum()) - m  # each row of a full-rank J adds one negative pivot
    return None if n_neg < 0 else (n_neg, 0)


def least_squares_multipliers(J, g, rtol: float = 1e-10):
    """``lam`` minimising ``|g + J' lam|`` (``J`` of full row rank), or None when the factorisation below
    breaks down or its solution has a relative residual above ``rtol`` (the caller then solves the normal
    equations ``J J' lam = -J g``).

    Solved as the augmented system ``[[I, J'], [J, 0]] [r; lam] = [-g; 0]`` on the columns ``J`` involves,
    factorised with diagonal pivots in an order that eliminates first every column only one row involves
    (a node of an anchor patch, a rope node outside the patches: pivot 1, no fill but that row's diagonal,
    which becomes ``-sum J_kc^2``), then the rows that had such a column, the other columns next and the
    rows without such a column last. The normal equations couple every row of a patch through its two
    reference nodes (a dense block per patch); this order keeps that coupling to the reference nodes' few
    columns. (Eliminating a rope's row right after one of its own columns, before the others, coupled all
    of its nodes' columns: a dense block of the rope's length squared.)
    """
    J = sp.csr_matrix(J, copy=True)
    J.eliminate_zeros()
    g = np.asarray(g, dtype=float)
    m = J.shape[0]
    cols = np.unique(J.indices)
    if m == 0 or len(cols) == 0:
        return None
    Jc = J[:, cols].tocsr()
    nc = len(cols)
    rows = np.repeat(np.arange(m), np.diff(Jc.indptr))
    big = np.abs(Jc.data) >= 1e-3 * np.maximum.reduceat(np.abs(Jc.data), Jc.indptr[:-1])[rows]
    solo = (np.bincount(Jc.indices, minlength=nc)[Jc.indices] == 1) & big  # alone in their column, no tiny pivot
    first = np.zeros(nc, dtype=bool)  # the columns eliminated first: one row each
    first[Jc.indices[solo]] = True
    paired = np.zeros(m, dtype=bool)  # the rows with such a column: a nonzero pivot once those are eliminated
    paired[rows[solo]] = True
    order = np.concatenate([np.flatnonzero(first), nc + np.flatnonzero(paired), np.flatnonzero(~first),
                            nc + np.flatnonzero(~paired)])
    K = sp.bmat([[sp.identity(nc, format="csr"), Jc.T], [Jc, None]], format="csc")
    rhs = np.concatenate([-g[cols], np.zeros(m)])
    try:
        lu = spla.splu(K[order][:, order].tocsc(), permc_spec="NATURAL", diag_pivot_thresh=0.0,
                       options={"SymmetricMode": True})
    except RuntimeError:
        return None
    sol = np.empty(nc + m)
    with np.errstate(all="ignore"):
        sol[order] = lu.solve(rhs[order])
        r = K @ sol - rhs
    if not (np.all(np.isfinite(r)) and np.linalg.norm(r) <= rtol * max(np.linalg.norm(rhs), 1e-300)):
        return None
    return sol[nc:]
