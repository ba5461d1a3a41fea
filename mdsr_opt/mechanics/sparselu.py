"""Sparse LU solves of a sequence of matrices that share a pattern: the Newton matrices of one solve.

:class:`ReusedOrdering` finds a fill-reducing order at the first factorisation and reorders later matrices
by a gather of their stored values; :class:`PatternRestriction` takes ``K[rows][:, cols]`` of matrices of one
CSR pattern by a gather as well. Both find the positions once, by factorising or slicing a matrix of the
pattern whose values are the positions themselves.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = ["ReusedOrdering", "PatternRestriction"]


class ReusedOrdering:
    """Sparse LU solves that find a fill-reducing column order (minimum degree on ``A^T + A``) at the first
    factorisation and reuse it for later matrices of the same shape: the Newton matrices of one solve share
    their pattern up to entries that happen to vanish (a rope's friction coupling at a straight node; all its
    terms while its tension is 0). A matrix with more stored entries than the one ordered gets a new order.
    Row pivoting (threshold 0.1, diagonal preferred) is still done per matrix.

    The ordered matrix of a pattern seen before is a gather of the new matrix's stored values (the positions
    found once per pattern), so a Newton matrix given as COO, CSR or CSC triplets with one pattern is
    reordered without sorting."""

    def __init__(self):
        self.inv = None  # the order as an index array: row/column k of the ordered matrix is inv[k]
        self.key = None  # (shape, stored entries) of the matrix the order was found for
        self.plan = None  # (pattern arrays, take, indices, indptr): the ordered CSC of the last pattern

    @staticmethod
    def _pattern(J) -> tuple:
        return (J.format,) + ((J.row, J.col) if J.format == "coo" else (J.indices, J.indptr))

    def _ordered(self, J):
        """``J`` with rows and columns in the order ``inv``, CSC (through the plan of its pattern)."""
        pattern = self._pattern(J)
        plan = self.plan
        if plan is None or len(plan[0]) != len(pattern) or plan[0][0] != pattern[0] or not all(
                a.shape == b.shape and np.array_equal(a, b) for a, b in zip(plan[0][1:], pattern[1:])):
            marker = J.copy()
            marker.data = np.arange(1, J.nnz + 1, dtype=float)  # each stored entry's position, plus one
            inv = self.inv
            Mp = sp.csc_matrix(marker)[:, inv].tocsr()[inv].tocsc()
            if Mp.nnz != J.nnz:  # repeated entries (COO) are summed: no gather
                Jc = sp.csc_matrix(J)
                return Jc[:, inv].tocsr()[inv].tocsc()
            plan = self.plan = (tuple(a.copy() if isinstance(a, np.ndarray) else a for a in pattern),
                                Mp.data.astype(np.int64) - 1, Mp.indices, Mp.indptr)
        return sp.csc_matrix((J.data[plan[1]], plan[2], plan[3]), shape=J.shape)

    def solve(self, J, rhs: np.ndarray) -> np.ndarray:
        """``J^{-1} rhs``; raises RuntimeError for an exactly singular ``J``."""
        return self.factor(J)(rhs)

    def factor(self, J):
        """The LU factorisation of ``J`` as a function ``rhs -> J^{-1} rhs`` (for several right-hand sides, or
        for later steps that keep this matrix); raises RuntimeError for an exactly singular ``J``."""
        opts = {"diag_pivot_thresh": 0.1, "options": {"SymmetricMode": True}}
        if not sp.issparse(J) or J.format not in ("coo", "csr", "csc"):
            J = sp.csc_matrix(J)
        if self.inv is None or self.key[0] != J.shape or J.nnz > self.key[1]:
            J = sp.csc_matrix(J)
            lu = spla.splu(J, permc_spec="MMD_AT_PLUS_A", **opts)
            self.inv, self.key, self.plan = np.argsort(lu.perm_c), (J.shape, J.nnz), None
            return lu.solve
        inv = self.inv
        lu = spla.splu(self._ordered(J), permc_spec="NATURAL", **opts)

        def solve(rhs: np.ndarray) -> np.ndarray:
            out = np.empty_like(rhs)
            out[inv] = lu.solve(rhs[inv])
            return out

        return solve


class PatternRestriction:
    """``K[rows][:, cols]`` of matrices that share one CSR pattern (a model's Hessians,
    :meth:`~mdsr_opt.mechanics.quadratic.QuadraticModel.evaluate`): a gather of their stored values at the
    positions found once from ``K``."""

    def __init__(self, K, rows, cols):
        K = sp.csr_matrix(K)
        marker = sp.csr_matrix((np.arange(1, K.nnz + 1, dtype=float), K.indices, K.indptr), shape=K.shape)
        S = marker[rows][:, cols]
        self.take = S.data.astype(np.int64) - 1
        self.indices, self.indptr, self.shape = S.indices, S.indptr, S.shape
        self.nnz, self.pattern = K.nnz, (K.indices, K.indptr)

    def __call__(self, K) -> sp.csr_matrix:
        if K.format != "csr" or K.nnz != self.nnz or not (K.indices is self.pattern[0] or np.array_equal(
                K.indices, self.pattern[0])):
            raise ValueError("a matrix of another pattern than the one the restriction was found for")
        return sp.csr_matrix((K.data[self.take], self.indices.copy(), self.indptr.copy()), shape=self.shape)
