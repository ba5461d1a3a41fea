"""Quadratic (6-node) triangles: the mesh upgrade and the elastic energy of the virtual prototype.

A linear mesh (:class:`~mdsr_opt.body.mesh.Mesh`) becomes a quadratic one by a node at the middle of every
edge, boundary edges included (the edges stay straight). The displacement is then piecewise quadratic; the
deformation gradient of an element, ``F = sum_a x_a (grad N_a)^T``, is linear over it, and the energy
``sum_e t A_e sum_q w_q Psi(F(xi_q))`` is integrated with the symmetric 6-point rule, exact for polynomials of
degree 4 (``|grad u|^2`` of a quadratic ``u`` has degree 2; the extra points, nearer the vertices, let the
energy see an element squeezed at a corner, where a 3-point rule is blind). ``order=1`` gives the linear (3-node, one point) element of the design model, on the same
code path, so the two can be compared.

The material enters only through its energy density: ``material.psi_expr(F, params)`` with a CasADi 2x2
``F`` and the numeric vector ``material.params``, so any material of :mod:`mdsr_opt.body.material` (or one
with the same two members) works. CasADi differentiates one element's energy twice; the element gradients and
Hessians are evaluated for all elements at once and assembled into sparse arrays.

:func:`split_mesh` refines a linear mesh by splitting every triangle into four through the same edge
midpoints (node numbers ``n + row of mesh.edges``): the split mesh has exactly the nodes of the quadratic
mesh, so it draws and photographs a quadratic state, and refines a mesh that has no outline to re-mesh.

Example
-------
>>> import numpy as np
>>> from mdsr_opt import Mesh, NeoHookean
>>> model = QuadraticModel(Mesh.rectangle(2.0, 1.0, 2, 1), NeoHookean(1.0, 0.3))
>>> model.n_nodes, model.elements.shape
(15, (4, 6))
>>> abs(model.energy(model.points)) < 1e-24
True
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ..body.material import numeric_law
from ..body.mesh import Mesh

__all__ = ["QUAD_POINTS", "QuadraticModel", "extend_prescribed", "midnode_table", "split_mesh", "transfer_state"]

_A, _B = 0.445948490915965, 0.091576213509771
#: Quadrature points (reference coordinates) of the quadratic element: the symmetric 6-point rule, exact for
#: polynomials of degree 4 (weights :data:`QUAD_WEIGHTS`, fractions of the area).
QUAD_POINTS = np.array([[_A, _A], [1 - 2 * _A, _A], [_A, 1 - 2 * _A], [_B, _B], [1 - 2 * _B, _B], [_B, 1 - 2 * _B]])
QUAD_WEIGHTS = np.array([0.223381589678011] * 3 + [0.109951743655322] * 3)


def midnode_table(mesh: Mesh) -> np.ndarray:
    """Per triangle the indices of its three edge-midpoint nodes (edges 0-1, 1-2, 2-0), numbered
    ``mesh.n_nodes + row`` of :attr:`~mdsr_opt.body.mesh.Mesh.edges`; (m, 3)."""
    t = mesh.triangles
    rows = mesh.edge_rows(t[:, [0, 1, 2]].ravel(), t[:, [1, 2, 0]].ravel()).reshape(-1, 3)
    return mesh.n_nodes + rows


def split_mesh(mesh: Mesh) -> Mesh:
    """``mesh`` refined by splitting every triangle into four through its edge midpoints.

    The nodes of ``mesh`` keep their indices; the midpoint of edge ``k`` (a row of ``mesh.edges``) is node
    ``mesh.n_nodes + k``. The result has the nodes of :class:`QuadraticModel`'s mesh of ``mesh``."""
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh must be a Mesh, got {type(mesh).__name__}")
    P, E = mesh.points, mesh.edges
    pts = np.vstack([P, 0.5 * (P[E[:, 0]] + P[E[:, 1]])])
    t, m = mesh.triangles, midnode_table(mesh)
    a, b, c, ab, bc, ca_ = t[:, 0], t[:, 1], t[:, 2], m[:, 0], m[:, 1], m[:, 2]
    tris = np.concatenate([np.column_stack([a, ab, ca_]), np.column_stack([ab, b, bc]),
                           np.column_stack([ca_, bc, c]), np.column_stack([ab, bc, ca_])])
    return Mesh(pts, tris)


def transfer_state(mesh: Mesh, x, points) -> np.ndarray:
    """A state ``x`` (n, 2) of the linear ``mesh`` carried to other rest ``points`` (k, 2) of the same body
    (another mesh of it): the displacement interpolated linearly in the triangle of ``mesh`` that holds each
    point; a point outside every triangle (a boundary meshed differently) takes the displacement of the
    nearest node of ``mesh``. Returns (k, 2) positions."""
    from matplotlib.tri import LinearTriInterpolator, Triangulation
    from scipy.spatial import cKDTree

    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh must be a Mesh, got {type(mesh).__name__}")
    x = np.asarray(x, dtype=float)
    pts = np.asarray(points, dtype=float)
    if x.shape != mesh.points.shape or not np.isfinite(x).all():
        raise ValueError(f"x must be finite positions of the mesh's {mesh.n_nodes} nodes, got shape {x.shape}")
    if pts.ndim != 2 or pts.shape[1] != 2 or not np.isfinite(pts).all():
        raise ValueError(f"points must be finite (k, 2) positions, got shape {pts.shape}")
    P, T = mesh.points, mesh.triangles
    u = x - P
    tri = Triangulation(P[:, 0], P[:, 1], T)
    out = pts.copy()
    inside = np.ones(len(pts), dtype=bool)
    for c in range(2):
        v = LinearTriInterpolator(tri, u[:, c])(pts[:, 0], pts[:, 1])
        inside &= ~np.ma.getmaskarray(v)
        out[:, c] += np.ma.filled(v, 0.0)
    outside = np.flatnonzero(~inside)
    nearest = cKDTree(P).query(pts[outside])[1] if outside.size else []
    for k, node in zip(outside, nearest):  # the affine extension of the best triangle at the nearest node
        cand = T[(T == node).any(1)]
        A = P[cand]                                             # (c, 3, 2)
        M = np.stack([A[:, 1] - A[:, 0], A[:, 2] - A[:, 0]], axis=2)  # columns: the two edge vectors
        l12 = np.linalg.solve(M, (pts[k] - A[:, 0])[:, :, None])[:, :, 0]
        lam = np.column_stack([1.0 - l12.sum(1), l12])
        best = int(np.argmax(lam.min(1)))
        out[k] = pts[k] + lam[best] @ u[cand[best]]
    return out


def extend_prescribed(mesh: Mesh, anchors, drag_nodes, drag_positions):
    """Anchors and drags of ``mesh`` carried to the nodes of :func:`split_mesh` (and of the quadratic mesh):
    the midpoint of an edge joining two anchors is anchored, that of an edge joining two dragged nodes is
    dragged to the middle of their targets (a drag along a straight edge stays straight).

    Returns ``(anchors, drag_nodes, drag_positions)`` on the refined nodes (old indices kept)."""
    n = mesh.n_nodes
    anchors = np.asarray(anchors, dtype=np.int64).ravel()
    dn = np.asarray(drag_nodes, dtype=np.int64).ravel()
    dp = np.asarray(drag_positions, dtype=float).reshape(-1, 2)
    E = mesh.edges
    is_anchor = np.zeros(n, dtype=bool)
    is_anchor[anchors] = True
    target = np.full((n, 2), np.nan)
    target[dn] = dp
    both_a = is_anchor[E[:, 0]] & is_anchor[E[:, 1]]
    both_d = np.isfinite(target[E[:, 0], 0]) & np.isfinite(target[E[:, 1], 0])
    new_a = np.concatenate([anchors, n + np.flatnonzero(both_a)])
    k = np.flatnonzero(both_d)
    new_dn = np.concatenate([dn, n + k])
    new_dp = np.vstack([dp, 0.5 * (target[E[k, 0]] + target[E[k, 1]])])
    return new_a, new_dn, new_dp


def _det2(F: np.ndarray) -> np.ndarray:
    """Determinants of a stack of 2x2 matrices ``F`` (..., 2, 2), in closed form."""
    return F[..., 0, 0] * F[..., 1, 1] - F[..., 0, 1] * F[..., 1, 0]


def _reference_gradients(order: int) -> tuple[np.ndarray, np.ndarray]:
    """Shape-function gradients in reference coordinates at the quadrature points, (nq, nn, 2), and the
    weights (fractions of the element's area), (nq,)."""
    if order == 1:
        return np.array([[[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]]]), np.array([1.0])
    dL = np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]])
    out = []
    for xi, eta in QUAD_POINTS:
        L = np.array([1.0 - xi - eta, xi, eta])
        g = [(4 * L[0] - 1) * dL[0], (4 * L[1] - 1) * dL[1], (4 * L[2] - 1) * dL[2],
             4 * (L[1] * dL[0] + L[0] * dL[1]), 4 * (L[2] * dL[1] + L[1] * dL[2]),
             4 * (L[0] * dL[2] + L[2] * dL[0])]
        out.append(np.array(g))
    return np.array(out), QUAD_WEIGHTS


def _assembly_plan(elements: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The CSR pattern of the (2 n_nodes)-square matrix summing element blocks over the node-interleaved
    coordinates of ``elements`` (m, nn), computed once per mesh: returns ``(slot, indices, indptr)`` with
    ``slot`` the position in the CSR data of each entry of the blocks (m, 2nn, 2nn) raveled, so that the
    matrix is ``np.bincount(slot, blocks.ravel(), len(indices))`` with ``indices`` and ``indptr`` (columns
    sorted and unique in each row). Found on the node pairs (a quarter of the entries): node ``a``'s
    neighbours ``b`` (sorted) give rows ``2a + i`` with columns ``2b + j``."""
    m, nn = elements.shape
    e = elements.astype(np.int64)
    key = (np.repeat(e, nn, axis=1) * n_nodes + np.tile(e, (1, nn))).ravel()          # (m nn nn): a, b
    uniq, pslot = np.unique(key, return_inverse=True)
    a_of, b_of = uniq // n_nodes, uniq % n_nodes
    nptr = np.searchsorted(a_of, np.arange(n_nodes + 1))
    deg = np.diff(nptr)
    # the pair p = (a, b) at offset k = p - nptr[a] in row a: dof (2a + i, 2b + j) at 4 nptr[a] + 2 i deg[a] + 2 k + j
    base = 4 * nptr[a_of] + 2 * (np.arange(len(uniq)) - nptr[a_of])                   # (pairs,)
    i = np.arange(2)
    pos = base[:, None, None] + 2 * i[None, :, None] * deg[a_of][:, None, None] + i[None, None, :]  # (pairs, i, j)
    slot = pos[pslot.ravel().reshape(m, nn, nn)].transpose(0, 1, 3, 2, 4).reshape(-1)   # (e, a, i, b, j)
    indices = np.empty(4 * len(uniq), dtype=np.int32)
    indices[pos.ravel()] = np.broadcast_to(2 * b_of[:, None, None] + i[None, None, :], pos.shape).ravel()
    indptr = np.empty(2 * n_nodes + 1, dtype=np.int64)
    indptr[0:-1:2] = 4 * nptr[:-1]
    indptr[1::2] = 4 * nptr[:-1] + 2 * deg
    indptr[-1] = 4 * nptr[-1]
    return slot, indices, indptr.astype(np.int32)


@dataclass(frozen=True)
class _ElementData:
    G: np.ndarray        # (m, nq, nn, 2): physical shape-function gradients at the quadrature points
    w: np.ndarray        # (m, nq): area x quadrature weight
    dofs: np.ndarray     # (m, 2 nn): global coordinates of each element, node-interleaved
    D: np.ndarray        # (2, 2, m): the inverse rest edge matrix of each element, G[e, q] = dref[q] @ D[:, :, e]
    Tx: np.ndarray       # (nn, 2 nq): dref[q, a, r] at [a, (q, r)]: element nodes -> reference gradients
    Tg: np.ndarray       # (2 nq, nn): its transpose: reference stresses -> nodal forces
    TH: np.ndarray       # (4 nq, nn nn): dref[q, a, r] dref[q, b, s] at [(q, r, s), (a, b)]


def _reference_maps(dref: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The constant matrices that turn the per-element work of :class:`QuadraticModel` into products with
    the reference shape-function gradients ``dref`` (nq, nn, 2), shared by every element: ``F`` from the
    nodes, forces from the stresses and the element Hessian from the tangent are each one matrix product
    over all elements at once (the element's own ``Dm^-1`` enters as 2 x 2 factors per quadrature point)."""
    nq, nn, _ = dref.shape
    Tx = dref.transpose(1, 0, 2).reshape(nn, 2 * nq)
    TH = np.einsum("qar,qbs->qrsab", dref, dref).reshape(4 * nq, nn * nn)
    return Tx, np.ascontiguousarray(Tx.T), TH


class QuadraticModel:
    """The elastic energy of a body on quadratic (``order=2``) or linear (``order=1``) triangles.

    Parameters
    ----------
    mesh : Mesh
        The linear mesh; its nodes keep their indices, the edge midpoints follow (:func:`midnode_table`).
    material : a material of :mod:`mdsr_opt.body.material` (``psi_expr`` and ``params``).
    order : 1 or 2
    numeric : bool
        Evaluate with the material's closed-form stress and tangent when it states them
        (:func:`~mdsr_opt.body.material.numeric_law`, two parameters); otherwise, or with ``False``, with
        CasADi's derivatives of ``psi_expr`` (the reference; tests compare the two).

    Attributes
    ----------
    mesh, material, order
    points : (N, 2) ndarray
        Rest positions of every node (vertices, then edge midpoints for ``order=2``).
    elements : (m, 3 or 6) ndarray
        Per element its vertices then, for ``order=2``, its midpoints on edges 0-1, 1-2, 2-0.
    display_mesh : Mesh
        A linear mesh on exactly these nodes (:func:`split_mesh` for ``order=2``), to draw and photograph.
    """

    def __init__(self, mesh: Mesh, material, order: int = 2, numeric: bool = True):
        if not isinstance(mesh, Mesh):
            raise TypeError(f"mesh must be a Mesh, got {type(mesh).__name__}")
        if isinstance(order, bool) or order not in (1, 2):
            raise ValueError(f"order must be 1 (linear) or 2 (quadratic triangles), got {order!r}")
        if not callable(getattr(material, "psi_expr", None)) or not hasattr(material, "params"):
            raise TypeError(f"material must have psi_expr(F, params) and params, got {type(material).__name__}")
        self.mesh, self.material, self.order = mesh, material, int(order)
        self.params = np.asarray(material.params, dtype=float).ravel()
        if order == 2:
            E = mesh.edges
            P = mesh.points
            self.points = np.vstack([P, 0.5 * (P[E[:, 0]] + P[E[:, 1]])])
            self.elements = np.hstack([mesh.triangles, midnode_table(mesh)]).astype(np.int64)
            self.display_mesh = split_mesh(mesh)
        else:
            self.points = mesh.points.copy()
            self.elements = mesh.triangles.astype(np.int64)
            self.display_mesh = mesh
        self.points.setflags(write=False)
        self.n_nodes = len(self.points)
        dref, wq = _reference_gradients(self.order)
        Dm_inv, areas = mesh.Dm_inv, mesh.areas
        G = np.einsum("qak,mkj->mqaj", dref, Dm_inv)
        nn = self.elements.shape[1]
        dofs = np.stack([2 * self.elements, 2 * self.elements + 1], axis=2).reshape(-1, 2 * nn)
        Tx, Tg, TH = _reference_maps(dref)
        self._data = _ElementData(G=G, w=areas[:, None] * wq[None, :], dofs=dofs,
                                  D=np.ascontiguousarray(np.transpose(Dm_inv, (1, 2, 0))), Tx=Tx, Tg=Tg, TH=TH)
        if self.order == 2:  # shape-function gradients at the three vertices, (m, 3, 6, 2)
            dL = np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]])
            gv = np.array([[(4 * L[0] - 1) * dL[0], (4 * L[1] - 1) * dL[1], (4 * L[2] - 1) * dL[2],
                            4 * (L[1] * dL[0] + L[0] * dL[1]), 4 * (L[2] * dL[1] + L[1] * dL[2]),
                            4 * (L[0] * dL[2] + L[2] * dL[0])] for L in np.eye(3)])
            self._vertex_gradients = np.einsum("vak,mkj->mvaj", gv, Dm_inv)
        self._mapped = None
        #: evaluate with the material's closed-form stress and tangent where it has them (else CasADi)
        self.numeric = bool(numeric) and numeric_law(material)
        self._pattern = _assembly_plan(self.elements, self.n_nodes)

    def _element_function(self, nn: int, nq: int):
        """CasADi function ``(xe, G, w, p) -> (energy, gradient, Hessian)`` of one element."""
        xe = ca.SX.sym("xe", 2 * nn)
        G = ca.SX.sym("G", nn * 2, nq)  # column q: the nn x 2 gradients, row-major
        w = ca.SX.sym("w", nq)
        p = ca.SX.sym("p", len(self.params))
        e = 0
        for q in range(nq):
            F = ca.SX.zeros(2, 2)
            for a in range(nn):
                for i in range(2):
                    for j in range(2):
                        F[i, j] += xe[2 * a + i] * G[2 * a + j, q]
            e += w[q] * self.material.psi_expr(F, p)
        g = ca.gradient(e, xe)
        H = ca.hessian(e, xe)[0]
        return ca.Function("element", [xe, G, w, p], [e, g, H])

    # ------------------------------------------------------------------------------------------- geometry
    def deformation_gradients(self, x) -> np.ndarray:
        """``F`` at every quadrature point, (m, nq, 2, 2), of the state ``x`` ((N, 2) or (2N,))."""
        return self._gradients(x).transpose(2, 3, 0, 1)

    def _gradients(self, x) -> np.ndarray:
        """``F`` at every quadrature point as (2, 2, m, nq) (components first)."""
        x = self._state(x)
        d = self._data
        m, nq = d.w.shape
        xe = x[self.elements].transpose(2, 0, 1).reshape(2 * m, -1)        # (i, e) x a
        Fr = (xe @ d.Tx).reshape(2, m, nq, 2)                            # sum_a x_ai dref_qar: (i, e, q, r)
        D = d.D[:, :, :, None]                                           # (r, j, e, 1)
        return Fr[..., 0][:, None] * D[0][None] + Fr[..., 1][:, None] * D[1][None]  # (i, j, e, q)

    def jacobians(self, x) -> np.ndarray:
        """``det F`` at every quadrature point, (m, nq)."""
        return _det2(self.deformation_gradients(x))

    def vertex_jacobians(self, x) -> np.ndarray:
        """``det F`` at the three vertices of every element, (m, 3) (order 1: the element's constant
        ``det F``, repeated)."""
        x = self._state(x)
        if self.order == 2:  # the linear F of a quadratic element is extreme at its vertices
            return _det2(np.matmul(x[self.elements].transpose(0, 2, 1)[:, None], self._vertex_gradients))
        return np.repeat(self.jacobians(x)[:, :1], 3, axis=1)

    def upright(self, x) -> bool:
        """No element inverted at a quadrature point or at a node (``det F > 0`` at the vertices too, where
        the linear ``F`` of a quadratic element is extreme)."""
        x = self._state(x)
        if not np.all(self.jacobians(x) > 0.0):
            return False
        if self.order == 2 and not np.all(self.vertex_jacobians(x) > 0.0):
            return False
        return True

    def _state(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if x.size != 2 * self.n_nodes:
            raise ValueError(f"a state of this model has {self.n_nodes} nodes (shape ({self.n_nodes}, 2)), "
                             f"got shape {x.shape}")
        return x.reshape(-1, 2)

    # --------------------------------------------------------------------------------------------- energy
    def _evaluate(self, x, params=None, need: int = 2, energy: bool = True):
        """Per element energies (m,), gradients (m, 2nn) and, for ``need=2``, Hessians (m, 2nn, 2nn); with
        ``energy=False`` the closed-form path leaves the energies out (None)."""
        p = self.params if params is None else np.asarray(params, dtype=float).ravel()
        if self.numeric and len(p) == 2:
            return self._evaluate_numeric(x, p, need, energy)
        x = self._state(x)
        d = self._data
        m, nq, nn = d.G.shape[0], d.G.shape[1], d.G.shape[2]
        if self._mapped is None:
            self._mapped = self._element_function(nn, nq).map(m)  # built when first needed
        xe = x.reshape(-1)[d.dofs].T                                                 # (2nn, m)
        Gc = d.G.reshape(m, nq, nn * 2).transpose(2, 0, 1).reshape(nn * 2, m * nq)  # (2nn, m nq)
        e, g, H = self._mapped(xe, Gc, d.w.T, np.repeat(p[:, None], m, axis=1))
        k = 2 * nn
        H = np.asarray(H).reshape(k, m, k).transpose(1, 0, 2) if need == 2 else None
        return np.asarray(e).ravel(), np.asarray(g).T, H

    def _evaluate_numeric(self, x, p, need: int, energy: bool = True):
        """:meth:`_evaluate` from the material's closed-form stress and tangent (``numeric_law``).

        With ``G[e, q] = dref[q] D_e`` (reference gradients times the element's inverse rest edge matrix), the
        element's forces are ``sum_q dref[q] (w P D_e^T)`` and its Hessian ``sum_q dref[q] (w D_e A D_e^T)
        dref[q]^T`` in the pairs of indices of ``A``: the 2 x 2 factors are taken per quadrature point, the
        sums over the shared ``dref`` are one matrix product over all elements (:func:`_reference_maps`)."""
        d = self._data
        m, nq = d.w.shape
        nn = d.Tx.shape[0]
        Fl = self._gradients(x).reshape(2, 2, m * nq)                          # (i, j, n), n = (e, q)
        e = None
        with np.errstate(divide="ignore", invalid="ignore"):
            if energy:
                psi = self.material.density(Fl[0, 0] - 1, Fl[0, 1], Fl[1, 0], Fl[1, 1] - 1, p[0], p[1])
                J = Fl[0, 0] * Fl[1, 1] - Fl[0, 1] * Fl[1, 0]
                e = (d.w * np.where(J > 0, psi, np.nan).reshape(m, nq)).sum(1)
            P, A = self.material.stress_tangent(Fl, p[0], p[1], need == 2)
        w = d.w.reshape(-1)
        Dn = np.broadcast_to(d.D[:, :, :, None], (2, 2, m, nq)).reshape(2, 2, m * nq)  # (r, j, n)
        Pw = P * w
        Pr = np.einsum("ijn,rjn->nir", Pw, Dn)                                # (n, i, r)
        g = (Pr.reshape(m, nq, 2, 2).transpose(0, 2, 1, 3).reshape(2 * m, 2 * nq) @ d.Tg)  # ((e, i), a)
        g = g.reshape(m, 2, nn).transpose(0, 2, 1).reshape(m, 2 * nn)
        H = None
        if need == 2:
            A = np.broadcast_to(A, (2, 2, 2, 2, m * nq)) * w
            B = np.einsum("ijkln,sln->ijksn", A, Dn)                         # (i, j, k, s, n)
            Ar = np.einsum("rjn,ijksn->iknrs", Dn, B)  # (i, k, n, r, s)
            Ar = Ar.reshape(4 * m, nq * 4)                                   # ((i, k, e), (q, r, s))
            Hq = (Ar @ d.TH).reshape(2, 2, m, nn, nn)                        # (i, k, e, a, b)
            H = Hq.transpose(2, 3, 0, 4, 1).reshape(m, 2 * nn, 2 * nn)
        return e, g, H

    def energy(self, x, params=None) -> float:
        """Total elastic energy of the state ``x`` (NaN or inf where an element is inverted)."""
        return float(self._evaluate(x, params, 0)[0].sum())

    def energy_gradient(self, x, params=None) -> tuple[float, np.ndarray]:
        """The energy and its gradient (2N,) (node-interleaved coordinates)."""
        e, g, _ = self._evaluate(x, params, 1)
        out = np.bincount(self._data.dofs.ravel(), g.ravel(), 2 * self.n_nodes)
        return float(e.sum()), out

    def gradient(self, x, params=None) -> np.ndarray:
        """The energy's gradient (2N,) alone (the energy itself is not evaluated)."""
        g = self._evaluate(x, params, 1, energy=False)[1]
        return np.bincount(self._data.dofs.ravel(), g.ravel(), 2 * self.n_nodes)

    def evaluate(self, x, params=None, energy: bool = True) -> tuple[float | None, np.ndarray, sp.csr_matrix]:
        """The energy (None with ``energy=False``: not evaluated), its gradient (2N,) and its Hessian (2N, 2N)
        (sparse) at ``x``."""
        e, g, H = self._evaluate(x, params, 2, energy)
        n2 = 2 * self.n_nodes
        grad = np.bincount(self._data.dofs.ravel(), g.ravel(), n2)
        slot, indices, indptr = self._pattern
        data = np.bincount(slot, H.ravel(), len(indices))
        K = sp.csr_matrix((data, indices, indptr), shape=(n2, n2))
        K.has_sorted_indices = True  # the plan's columns are sorted and unique in every row
        return (float(e.sum()) if energy else None), grad, K
