"""Numeric energy, gradient and Hessian of an :class:`~mdsr_opt.mechanics.model.EnergyModel` in vectorised
numpy, and the CasADi callbacks through which IPOPT evaluates them.

The Hessian of a mesh energy (triangles and edge springs) has the pattern of the node adjacency with
2 x 2 blocks. :class:`HessianPattern` makes that pattern in CSC form from the edges (no sort of all the
element entries) and, for every entry of every element (or edge) block, the position it adds into; the
Hessian is then one ``bincount`` of the blocks :class:`~mdsr_opt.mechanics.newton.NewtonEnergy`
computes. The same numbers fill the upper triangle that IPOPT takes.

:func:`ipopt_functions` wraps the energy, ``(energy, gradient)`` and the upper triangle of the Hessian of
the Lagrangian as CasADi :class:`casadi.Callback` objects that read and write CasADi's buffers in place,
so an IPOPT solve through CasADi needs no symbolic graph of the whole mesh (whose build is linear in the
mesh but costs several times a solve on small meshes).

Example
-------
>>> import numpy as np
>>> from mdsr_opt import Mesh, NeoHookean
>>> from mdsr_opt.mechanics.model import get_model
>>> mesh = Mesh.rectangle(2.0, 1.0, 4, 2)
>>> model = get_model(mesh, NeoHookean(1.0, 0.3))
>>> pat = HessianPattern(mesh.n_nodes, mesh.edges)
>>> pat.shape, int(pat.indptr[-1]) == len(pat.indices)
((30, 30), True)
>>> H = model.hessian(mesh.points, model.params(NeoHookean(1.0, 0.3)))  # one bincount into that pattern
>>> H.nnz == pat.nnz, float(abs(H - H.T).max())
(True, 0.0)
"""

from __future__ import annotations

import weakref

import casadi as ca
import numpy as np
import scipy.sparse as sp


__all__ = ["BufferedFunction", "HessianPattern", "SparseLayout", "ipopt_functions"]


class HessianPattern:
    """The full symmetric CSC pattern of the (2n, 2n) Hessian of an energy of node pairs along ``edges``.

    Parameters
    ----------
    n_nodes : int
    edges : (ne, 2) int array
        Every pair of nodes that share a term (a triangle's sides are edges).

    Attributes
    ----------
    shape : (2n, 2n)
    indptr, indices : CSC arrays (rows sorted within each column).
    upper : int array
        Positions (into ``indices``) of the entries with row <= column, in CSC order of the upper triangle.
    upper_indptr : the upper triangle's column pointers.
    """

    def __init__(self, n_nodes: int, edges):
        n = int(n_nodes)
        E = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
        diag = np.arange(n, dtype=np.int64)
        rows = np.concatenate([E[:, 0], E[:, 1], diag])
        cols = np.concatenate([E[:, 1], E[:, 0], diag])
        self._key = np.unique(cols * n + rows)  # node-level CSC order: by column, then row
        node_row = self._key % n
        self._colptr = np.searchsorted(self._key // n, np.arange(n + 1)).astype(np.int64)
        self.node_colptr, self.node_rows = self._colptr, node_row  #: the node graph (CSC, with diagonal)
        self._deg = np.diff(self._colptr)
        self._n = n
        N = 2 * n
        self.shape = (N, N)
        # dof column 2b + j holds, for each neighbour a of b (sorted), the rows 2a and 2a + 1
        k = np.arange(len(self._key))
        b = self._key // n
        base = 4 * self._colptr[b] + 2 * (k - self._colptr[b])
        indices = np.empty(4 * len(k), dtype=np.int64)
        for j in range(2):
            for i in range(2):
                indices[base + j * 2 * self._deg[b] + i] = 2 * node_row + i
        self.indices = indices.astype(np.int32)
        counts = np.repeat(2 * self._deg, 2)
        self.indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
        col_of = np.repeat(np.arange(N), counts)
        self.upper = np.flatnonzero(indices <= col_of)
        self.upper_indptr = np.concatenate([[0], np.cumsum(np.bincount(col_of[self.upper], minlength=N))])
        self.nnz = len(indices)

    def positions(self, nodes) -> np.ndarray:
        """``(2q, 2q, N)`` positions (into the CSC data) of the entries of the blocks of ``N`` terms on ``q``
        nodes each: entry ``[2u + i, 2v + j]`` is row ``2 nodes[u] + i``, column ``2 nodes[v] + j``."""
        nodes = np.ascontiguousarray(np.asarray(nodes, dtype=np.int64).T)  # (q, N)
        q, N = nodes.shape
        cb = self._colptr[nodes]  # column starts of the block columns, (q, N)
        k = np.searchsorted(self._key, nodes[None, :, :] * self._n + nodes[:, None, :])  # (u, v, N)
        base = 2 * (k + cb[None, :, :])  # 4 colptr[b] + 2 (k - colptr[b])
        two_deg = (2 * self._deg[nodes])[None, None, :, None, :]
        pos = (base[:, None, :, None, :] + np.arange(2)[None, :, None, None, None]
               + np.arange(2)[None, None, None, :, None] * two_deg)
        return pos.reshape(2 * q, 2 * q, N)

    def sparsity_upper(self) -> ca.Sparsity:
        """The upper triangle as a CasADi sparsity."""
        return ca.Sparsity(self.shape[0], self.shape[1], self.upper_indptr.tolist(),
                           self.indices[self.upper].tolist())

    def matrix(self, data) -> sp.csc_matrix:
        return sp.csc_matrix((data, self.indices, self.indptr), shape=self.shape)


class BufferedFunction(ca.Callback):
    """A CasADi callback that evaluates ``fn(inputs, outputs)`` on numpy views of CasADi's buffers.

    ``inputs`` are the nonzeros of each input (zeros for an input not given), ``outputs`` writable views
    of each output's nonzeros, or None for an output the caller does not want; ``fn`` fills them in
    place. Floating-point warnings are silenced: a trial step that inverts a triangle gives non-finite
    values, which IPOPT answers by cutting the step. After Ctrl-C inside
    :func:`~mdsr_opt.core.guards.interruptible`, or a stop requested for the thread (a study's time budget),
    evaluations go on as before: the solver's iteration callback stops it at the end of the step it is
    taking, and the block raises the interrupt or the stop. (Refused evaluations, NaN, would make IPOPT
    search its line down to nothing and start a restoration phase; raising here would make CasADi print
    every evaluation with its inputs.)

    Parameters
    ----------
    name : str
    sp_in, sp_out : lists of casadi.Sparsity
    fn : callable ``(inputs, outputs) -> None``
    """

    def __init__(self, name, sp_in, sp_out, fn):
        ca.Callback.__init__(self)
        self._sp_in, self._sp_out, self._fn = sp_in, sp_out, fn
        self.construct(name, {})

    def get_n_in(self):
        return len(self._sp_in)

    def get_n_out(self):
        return len(self._sp_out)

    def get_sparsity_in(self, i):
        return self._sp_in[i]

    def get_sparsity_out(self, i):
        return self._sp_out[i]

    def has_eval_buffer(self):
        return True

    def eval_buffer(self, arg, res):
        ins = [np.zeros(s.nnz()) if a is None else np.frombuffer(a, dtype=np.float64)
               for a, s in zip(arg, self._sp_in)]
        outs = [None if r is None else np.frombuffer(r, dtype=np.float64) for r in res]  # None: not wanted
        with np.errstate(all="ignore"):  # an inverted triangle in a trial step: non-finite, IPOPT cuts it
            self._fn(ins, outs)
        return 0


class SparseLayout:
    """A fixed sparse pattern summed from parts given as ``(rows, cols)`` index arrays.

    :meth:`add` the parts in order (targets with a negative row or column are dropped, and with
    ``upper`` those below the diagonal), then :meth:`finish`; :meth:`data` sums a list of value arrays,
    one per part in the same order and of the same lengths, into the pattern's nonzeros (CSC order).

    Example
    -------
    >>> lay = SparseLayout(2, 2, upper=True)
    >>> lay.add([0, 1, 1], [0, 0, 1]); lay.add([0], [0])
    >>> lay.finish().nnz(), lay.data([np.array([1.0, 5.0, 2.0]), np.array([3.0])]).tolist()
    (2, [4.0, 2.0])
    """

    def __init__(self, nrow: int, ncol: int, upper: bool = False):
        self.shape = (int(nrow), int(ncol))
        self.upper = upper
        self._parts: list = []
        self._keep = None

    def add(self, rows, cols) -> None:
        rows = np.asarray(rows, dtype=np.int64).ravel()
        cols = np.asarray(cols, dtype=np.int64).ravel()
        if rows.shape != cols.shape:
            raise ValueError(f"rows and cols differ in length: {rows.shape} and {cols.shape}")
        self._parts.append((rows, cols))

    def finish(self) -> ca.Sparsity:
        nrow, ncol = self.shape
        rows = np.concatenate([p[0] for p in self._parts]) if self._parts else np.zeros(0, np.int64)
        cols = np.concatenate([p[1] for p in self._parts]) if self._parts else np.zeros(0, np.int64)
        keep = (rows >= 0) & (cols >= 0)
        if self.upper:
            keep &= rows <= cols
        key = cols[keep] * nrow + rows[keep]
        # np.unique(key, return_inverse=True) by a stable sort: the parts come mostly in CSC order already,
        # which the stable sort exploits
        order = np.argsort(key, kind="stable")
        sorted_key = key[order]
        first = np.ones(len(key), dtype=bool)
        np.not_equal(sorted_key[1:], sorted_key[:-1], out=first[1:])
        ukey = sorted_key[first]
        slot = np.empty(len(key), dtype=np.int64)
        slot[order] = np.cumsum(first) - 1
        self._keep, self._slot = keep, slot
        self.nnz = len(ukey)
        colind = np.concatenate([[0], np.cumsum(np.bincount(ukey // nrow, minlength=ncol))])
        self.sparsity = ca.Sparsity(nrow, ncol, colind.tolist(), (ukey % nrow).tolist())
        self.lengths = [len(p[0]) for p in self._parts]
        return self.sparsity

    def data(self, values) -> np.ndarray:
        vals = np.concatenate([np.broadcast_to(np.asarray(v, dtype=float).ravel(), (n,))
                               for v, n in zip(values, self.lengths)])
        return np.bincount(self._slot, weights=vals[self._keep], minlength=self.nnz)

    def positions(self, part: int) -> np.ndarray:
        """Where each entry of the ``part``-th :meth:`add` (in order) lands among the nonzeros, -1 where it
        was dropped: for callers that write a large part in place and add the others.

        Example
        -------
        >>> lay = SparseLayout(2, 2, upper=True)
        >>> lay.add([0, 1], [1, 0]); lay.add([1, 0], [1, 1]); _ = lay.finish()
        >>> lay.positions(0).tolist(), lay.positions(1).tolist()
        ([0, -1], [1, 0])
        """
        start = sum(self.lengths[:part])
        keep = self._keep[start:start + self.lengths[part]]
        out = np.full(len(keep), -1, dtype=np.int64)
        out[keep] = self._slot[int(self._keep[:start].sum()):][:int(keep.sum())]
        return out


def ipopt_functions(model) -> dict:
    """``{"f": (x, p) -> f, "grad_f": (x, p) -> (f, grad), "hess_lag": (x, p, lam_f, lam_g) -> upper
    triangle}`` of ``model`` (numeric, see :meth:`~mdsr_opt.mechanics.model.EnergyModel.numeric`) as
    CasADi Functions, made once per model."""
    cached = model.__dict__.get("_ipopt_functions")
    if cached is not None:
        return cached
    ref = weakref.ref(model)  # the model keeps these alive; they must not keep the model alive
    n, npar = model.n_dof, model.n_params
    sx, sp_ = ca.Sparsity.dense(n, 1), ca.Sparsity.dense(npar, 1)
    one = ca.Sparsity.dense(1, 1)

    def f(ins, outs):
        if outs[0] is not None:
            outs[0][0] = ref().numeric(ins[1]).energy(ins[0])

    def fg(ins, outs):
        en = ref().numeric(ins[1])
        if outs[0] is not None:
            outs[0][0] = en.energy(ins[0])
        if outs[1] is not None:
            outs[1][:] = en.gradient(ins[0])

    def h(ins, outs):
        if outs[0] is not None:
            m = ref()
            outs[0][:] = m.hessian_data(ins[0], ins[1])[m.hessian_pattern.upper] * ins[2][0]

    fns = {"f": BufferedFunction("energy_num", [sx, sp_], [one], f),
           "grad_f": BufferedFunction("grad_f_num", [sx, sp_], [one, sx], fg),
           "hess_lag": BufferedFunction("hess_lag_num", [sx, sp_, one, ca.Sparsity(0, 1)],
                                 [model.hessian_pattern.sparsity_upper()], h)}
    model.__dict__["_ipopt_functions"] = fns
    return fns
