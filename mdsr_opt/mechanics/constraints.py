"""Exact muscle constraints: rope path lengths and rigid anchor patches at the muscles' ends.

A muscle is a rope along a chain of mesh nodes ``v0 ... vk``. Its path length in a state ``x`` is

``L_c(x) = sum_i |x_{v_{i+1}} - x_{v_i}|``                       (convex in ``x``)

and the exact cable model of :func:`~mdsr_opt.solve_internal` asks ``L_c(x) <= (1 - a_c) L0_c`` (a rope can
only pull), with the constraint's multiplier as the rope's tension ``tau_c >= 0``.

**Anchor patches** (:mod:`mdsr_opt.mechanics.anchors`): each end of a rope is held by a rigid patch of
physical size, the body nodes within ``radius`` of the end node; patches of different muscles that share a
node are one rigid group. Their names are re-exported here.

**Rigidity without extra variables.** For a group with nodes ``e`` (its first end node), ``r`` (the group
node farthest from ``e``) and the others ``j``, with rest offsets ``U = X_r - X_e``, ``D_j = X_j - X_e`` and
current ``u = x_r - x_e``:

``x_j - x_e - A(u) D_j = 0``  with  ``A(u) = [[c, -s], [s, c]]``, ``c = u.U/|U|^2``, ``s = (U x u)/|U|^2``
``(|u|^2 - |U|^2) / (2 |U|) = 0``

``A(u)`` is the rotation-and-scale taking ``U`` to ``u``; the last row fixes the scale. These are ``2k - 3``
independent equations for a group of ``k`` nodes (a rigid motion in the plane has 3 degrees of freedom),
all linear in ``x`` except the scale row, and they keep the orientation (no reflection). A group of one
node has no equation, of two nodes one (their distance).

Constraint rows are ordered ropes first (one per muscle), then the rigid rows. Coordinates are interleaved
``x0, y0, x1, y1, ...`` as in :mod:`mdsr_opt.mechanics.model`.
:class:`mdsr_opt.mechanics.constrained.ConstrainedModel` puts these constraints into an equilibrium NLP.

Example
-------
>>> import numpy as np
>>> from mdsr_opt import Mesh, Muscle
>>> from mdsr_opt.mechanics.constraints import MuscleConstraints
>>> mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
>>> bottom = [i for i in np.argsort(mesh.points[:, 0]) if mesh.points[i, 1] == 0.0]
>>> mc = MuscleConstraints(mesh, [Muscle(bottom)], radius=0.3)
>>> mc.rest_lengths, mc.n_rigid > 0
(array([4.]), True)
>>> float(np.abs(mc.rigid(mesh.points)).max())
0.0
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ..core.errors import LayoutError
from ..core.checks import positive_float
from .anchors import (anchor_radius_or_default, body_size,
                      rigid_groups, valid_muscles)
from .model import to_dm, spring_parameters
from .segments import length_hessian_product, length_third

__all__ = ["MuscleConstraints", "muscle_constraints", "spring_stiffness", "segment_spring_parameters",
           "spring_segments"]

def spring_stiffness(mesh, material, stiffness: float) -> float:
    """Axial stiffness ``K = stiffness * E * thickness * body_size(mesh)`` (a force) of the dummy-spring muscles.

    A muscle segment of rest length ``l0`` is a spring of stiffness ``K / l0``, so the springs of a muscle
    together are an elastic rod of axial stiffness ``K`` whatever the mesh (see
    :func:`segment_spring_parameters`).
    """
    return positive_float(stiffness, "stiffness") * material.E * material.thickness * body_size(mesh)


def segment_spring_parameters(mesh, material, muscles, contractions, stiffness: float,
                              anchor_radius: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per-edge ``(k, r)`` of the dummy-spring model with stiffness stated per unit rest length.

    Each segment of rest length ``l0`` adds ``k/2 (l - (1 - a') l0)^2`` with ``k = K / l0`` and
    ``K = stiffness * E * thickness * body_size(mesh)`` (:func:`spring_stiffness`): the energy of a muscle is then
    ``K/2 * sum_i l0_i (l_i/l0_i - (1 - a'))^2``, a quadrature of ``K/2 * integral (stretch - (1 - a'))^2 ds``
    that converges under refinement instead of softening as segments multiply.

    Segments inside a rigid anchor patch (both nodes in one group of :func:`rigid_groups` for
    ``anchor_radius``) carry no spring: they cannot shorten. The other segments are all shortened alike by
    ``a' = a L0 / L0_free`` (``L0_free``: their total rest length), so that a muscle whose springs all reach
    their rest lengths has contracted by exactly ``a`` along its whole chain, as the exact cable does.
    Pass ``anchor_radius=0`` for the paper's plain model (every segment, ``a' = a``). Feed the result to
    :meth:`~mdsr_opt.mechanics.model.EnergyModel.params` as ``springs=``.

    Raises
    ------
    ValueError
        When ``a' >= 1`` (the anchors cover too much of a muscle for the contraction asked).
    """
    mus = valid_muscles(mesh, muscles)
    a = np.asarray(contractions, dtype=float).reshape(-1)
    ks, a_eff = spring_segments(mesh, material, mus, stiffness, anchor_radius)
    return spring_parameters(mesh, mus, a * a_eff, ks)


def spring_segments(mesh, material, muscles, stiffness: float, anchor_radius: float | None = None):
    """``(per-muscle segment stiffness arrays, per-muscle factor L0 / L0_free)`` of the dummy springs (see
    :func:`segment_spring_parameters`); stiffness is 0 on segments inside an anchor patch. Cached on the mesh
    per node chains, radius and stiffness (the arrays are read-only)."""
    mus = valid_muscles(mesh, muscles)
    K = spring_stiffness(mesh, material, stiffness)
    key = (tuple(m.nodes for m in mus), anchor_radius_or_default(mesh, anchor_radius), K)
    cache = mesh.__dict__.setdefault("_spring_segment_cache", {})
    if key not in cache:
        if len(cache) >= 32:
            cache.pop(next(iter(cache)))
        ks, fac = _spring_segments(mesh, mus, K, key[1])
        for k in ks:
            k.flags.writeable = False
        cache[key] = (ks, fac)
    ks, fac = cache[key]
    return list(ks), fac.copy()


def _spring_segments(mesh, mus, K, anchor_radius):
    group_of = np.full(mesh.n_nodes, -1)
    for gi, g in enumerate(rigid_groups(mesh, mus, anchor_radius)):
        group_of[g] = gi
    ks, fac = [], []
    for m in mus:
        seg = m.segments
        l0 = m.segment_lengths(mesh.points)
        inside = (group_of[seg[:, 0]] >= 0) & (group_of[seg[:, 0]] == group_of[seg[:, 1]])
        if inside.all():
            raise LayoutError(f"muscle {m._label()} lies inside its anchor patches: give a smaller anchor_radius")
        ks.append(np.where(inside, 0.0, K / l0))
        fac.append(l0.sum() / l0[~inside].sum())
    return ks, np.array(fac)


class MuscleConstraints:
    """Rope lengths and rigid anchor patches of a set of muscles on one mesh, as CasADi and numpy functions.

    Parameters
    ----------
    mesh : Mesh
    muscles : sequence of Muscle or node lists
    radius : float, optional
        Anchor radius (default :func:`~mdsr_opt.mechanics.anchors.default_anchor_radius`; 0 for single-node ends).
    held : node indices, optional
        Nodes clamped at rest (:func:`~mdsr_opt.solve_internal`'s ``held``): a rigid group holding two or more
        of them is clamped whole (its nodes are fixed coordinates of the solve), so it has no rows here (they
        would constrain fixed coordinates only: rows with no free column, a singular KKT matrix).

    Attributes
    ----------
    n_muscles, n_rigid, n_constraints : int
        Rope rows, rigid rows and their sum (rows are ropes first, then rigid).
    rest_lengths : (n_muscles,) ndarray
        ``L0`` per muscle along its node chain.
    groups : list of ndarray
        The rigid groups (see :func:`rigid_groups`) with rows: all but those clamped by ``held``.
    dofs : ndarray
        Sorted global coordinates (of the 2n) that any constraint involves; ``n_local`` their number (the
        ``local_*`` methods take the state at these coordinates).
    linear_rows : (n_constraints,) bool ndarray
        Rows linear in the state (rigid rows other than each group's scale row).
    radius : float
    """

    def __init__(self, mesh, muscles, radius: float | None = None, held=None):
        self.mesh = mesh
        self.muscles = valid_muscles(mesh, muscles)
        if not self.muscles:
            raise ValueError("MuscleConstraints needs at least one muscle")
        self.radius = anchor_radius_or_default(mesh, radius)
        self.groups = [g for g in rigid_groups(mesh, self.muscles, self.radius)
                       if held is None or np.isin(g, held).sum() < 2]
        n = mesh.n_nodes
        self.n_dof = 2 * n
        P = mesh.points
        self.rest_lengths = np.array([m.rest_length(mesh) for m in self.muscles])
        node_set = set(v for m in self.muscles for v in m.nodes) | set(v for g in self.groups for v in g.tolist())
        nodes = np.array(sorted(node_set), dtype=np.int64)
        self.dofs = np.column_stack([2 * nodes, 2 * nodes + 1]).reshape(-1)
        loc = np.full(n, -1, dtype=np.int64)
        loc[nodes] = np.arange(len(nodes))
        nd = len(self.dofs)
        self.n_local = nd
        self.n_muscles = len(self.muscles)
        # ropes: segment (a, b) of muscle c adds |x_b - x_a| to row c (local node indices)
        seg = np.concatenate([m.segments for m in self.muscles]).astype(np.int64)
        self._seg_row = np.repeat(np.arange(self.n_muscles), [len(m.segments) for m in self.muscles])
        self._seg_a, self._seg_b = loc[seg[:, 0]], loc[seg[:, 1]]
        # rigid rows, per group: two linear rows per node j other than e and r, then the scale row. With
        # u = x_r - x_e, alpha = U.D_j / |U|^2 and beta = (U_1 D_0 - U_0 D_1) / |U|^2 the rows
        # x_j - x_e - A(u) D_j are  x_j0 - x_e0 - alpha u_0 - beta u_1  and  x_j1 - x_e1 + beta u_0 - alpha u_1
        lr, lc, lv = [], [], []  # the linear rows' constant Jacobian (local columns)
        sc_row, sc_e, sc_r, sc_UU = [], [], [], []
        k = 0
        for g in self.groups:
            e = int(g[0])
            dist = np.linalg.norm(P[g] - P[e], axis=1)
            r = int(g[int(np.argmax(dist))])
            U = P[r] - P[e]
            UU = float(U @ U)
            le, lrr = 2 * int(loc[e]), 2 * int(loc[r])
            for j in g.tolist():
                if j in (e, r):
                    continue
                D = P[j] - P[e]
                al = float(U @ D) / UU
                be = float(U[1] * D[0] - U[0] * D[1]) / UU
                lj = 2 * int(loc[j])
                lr += [k] * 5 + [k + 1] * 5
                lc += [lj, le, le + 1, lrr, lrr + 1, lj + 1, le + 1, le, lrr, lrr + 1]
                lv += [1.0, -1.0 + al, be, -al, -be, 1.0, -1.0 + al, -be, be, -al]
                k += 2
            sc_row.append(k)
            sc_e.append(le)
            sc_r.append(lrr)
            sc_UU.append(UU)
            k += 1
        self.n_rigid = k
        self.n_constraints = self.n_muscles + self.n_rigid
        self._lin = sp.csr_matrix((lv, (lr, lc)), shape=(k, nd))
        self._sc_row = np.asarray(sc_row, dtype=np.int64)
        self._sc_e, self._sc_r = np.asarray(sc_e, dtype=np.int64), np.asarray(sc_r, dtype=np.int64)
        self._sc_UU = np.asarray(sc_UU, dtype=float)
        # (nd, 2n) selection: x_local = S x
        self._S = sp.csr_matrix((np.ones(nd), (np.arange(nd), self.dofs)), shape=(nd, self.n_dof))
        self._sym = None
        self._jpat = None
        #: rows linear in the state (the rigid rows other than the scale rows): constant Jacobian, no curvature
        self.linear_rows = np.zeros(self.n_constraints, dtype=bool)
        self.linear_rows[self.n_muscles:] = True
        self.linear_rows[self.n_muscles + self._sc_row] = False

    # ------------------------------------------------------------------ symbolic (SX or MX, length 2n)
    def _functions(self):
        """CasADi pieces, built on first use from the same closed forms as the numeric methods (both agree
        to rounding): ``nl(xl)``, the nonlinear rows (ropes, then each group's scale row); ``P``, their
        placement among all rows; ``Lin``, the constant Jacobian of the linear rows; ``H(xl, lam)``, the upper
        triangle of ``sum_i lam_i Hessian(g_i)``; ``S``, the selection of the local coordinates. Keeping the
        linear rows out of the SX function makes its Jacobian (CasADi's, for an NLP) 50x cheaper to build."""
        if self._sym is None:
            xl = ca.SX.sym("xl", self.n_local)
            nl = self._nonlinear_expr(xl)
            nm, ng = self.n_muscles, len(self._sc_row)
            rows = np.concatenate([np.arange(nm), nm + self._sc_row])
            P = to_dm(sp.csr_matrix((np.ones(nm + ng), (rows, np.arange(nm + ng))),
                                     shape=(self.n_constraints, nm + ng)))
            lin = sp.vstack([sp.csr_matrix((nm, self.n_local)), self._lin], format="csr")
            lam = ca.SX.sym("lam", self.n_constraints)
            H = ca.hessian(ca.dot(ca.mtimes(P.T, lam), nl), xl)[0]
            self._sym = {"nl": ca.Function("muscle_g_nonlinear", [xl], [nl]), "P": P, "Lin": to_dm(lin),
                         "P_sp": _to_scipy(P).tocsr(), "Lin_sp": lin,
                         "H": ca.Function("muscle_hess", [xl, lam], [ca.triu(H)]), "S": to_dm(self._S)}
        return self._sym

    def symbolic_parts(self) -> tuple:
        """``(nl, P, Lin)`` with all rows ``= P nl(xl) + Lin xl``: ``nl`` the SX Function of the nonlinear rows
        (ropes, then each rigid group's scale row) of the local coordinates, ``P`` (n_constraints, n_nl) their
        placement and ``Lin`` (n_constraints, n_local) the linear rows' constant Jacobian, both scipy CSR."""
        f = self._functions()
        return f["nl"], f["P_sp"], f["Lin_sp"]

    def _nonlinear_expr(self, xl):
        """The rope lengths, then each rigid group's scale row (vectorised with sparse constant matrices)."""
        nd, ns = self.n_local, len(self._seg_a)

        def pick(idx, comp):  # (len(idx), nd) selection of local coordinate 2 idx + comp
            return to_dm(sp.csr_matrix((np.ones(len(idx)), (np.arange(len(idx)), 2 * idx + comp)),
                                        shape=(len(idx), nd)))

        dx = ca.mtimes(pick(self._seg_b, 0) - pick(self._seg_a, 0), xl)
        dy = ca.mtimes(pick(self._seg_b, 1) - pick(self._seg_a, 1), xl)
        agg = to_dm(sp.csr_matrix((np.ones(ns), (self._seg_row, np.arange(ns))), shape=(self.n_muscles, ns)))
        L = ca.mtimes(agg, ca.sqrt(dx ** 2 + dy ** 2))
        if not len(self._sc_row):
            return L
        u0 = ca.mtimes(pick(self._sc_r // 2, 0) - pick(self._sc_e // 2, 0), xl)
        u1 = ca.mtimes(pick(self._sc_r // 2, 1) - pick(self._sc_e // 2, 1), xl)
        scale = (u0 ** 2 + u1 ** 2 - ca.DM(self._sc_UU)) / ca.DM(2 * np.sqrt(self._sc_UU))
        return ca.vertcat(L, scale)

    def local_expr(self, xl):
        """All rows as a CasADi expression of the local coordinates ``xl`` (SX or MX of length
        :attr:`n_local`: the state at :attr:`dofs`): the nonlinear rows through one SX function, the linear
        rows as a constant sparse matrix times ``xl``."""
        f = self._functions()
        return ca.mtimes(f["P"], f["nl"](xl)) + ca.mtimes(f["Lin"], xl)

    def _local(self, x):
        return x[self.dofs.tolist()]

    def constraints_expr(self, x):
        """All constraint rows, ropes first then rigid, as a CasADi column."""
        return self.local_expr(self._local(x))

    def lengths_expr(self, x):
        """Rope path lengths ``L_c(x)`` (n_muscles,)."""
        return self.constraints_expr(x)[:self.n_muscles]

    def rigid_expr(self, x):
        """Rigid-patch residuals (n_rigid,): all zero iff every group moved rigidly, keeping orientation."""
        return self.constraints_expr(x)[self.n_muscles:]

    def jacobian_expr(self, x):
        """Sparse Jacobian (n_constraints, 2n) of :meth:`constraints_expr`."""
        fns = self._functions()
        if "J" not in fns:
            xl = ca.SX.sym("xl", self.n_local)
            J = ca.mtimes(fns["P"], ca.jacobian(self._nonlinear_expr(xl), xl)) + fns["Lin"]
            fns["J"] = ca.Function("muscle_jac", [xl], [J])
        return ca.mtimes(fns["J"](self._local(x)), fns["S"])

    def hessian_expr(self, x, lam):
        """Upper triangle (2n, 2n) of ``sum_i lam_i * Hessian(g_i)`` (sparse; only anchors and ropes)."""
        fns = self._functions()
        Hl = fns["H"](self._local(x), lam)
        return ca.mtimes(ca.mtimes(fns["S"].T, Hl), fns["S"])

    # ------------------------------------------------------------------ numeric (x as (n, 2) or (2n,))
    def _xl(self, x) -> np.ndarray:
        return np.asarray(x, dtype=float).reshape(-1)[self.dofs]

    def _segments(self, xl):
        """Per rope segment ``(d, |d|)`` with ``d = x_b - x_a`` (local state ``xl``)."""
        X = xl.reshape(-1, 2)
        d = X[self._seg_b] - X[self._seg_a]
        return d, np.sqrt((d * d).sum(1))

    def local_values(self, xl) -> np.ndarray:
        """All constraint rows from the local coordinates ``xl`` (the state at :attr:`dofs`)."""
        xl = np.asarray(xl, dtype=float)
        _d, ln = self._segments(xl)
        out = np.empty(self.n_constraints)
        out[:self.n_muscles] = np.bincount(self._seg_row, ln, minlength=self.n_muscles)
        if self.n_rigid:
            rig = self._lin @ xl
            X = xl.reshape(-1, 2)
            u = X[self._sc_r // 2] - X[self._sc_e // 2]
            rig[self._sc_row] = ((u * u).sum(1) - self._sc_UU) / (2 * np.sqrt(self._sc_UU))
            out[self.n_muscles:] = rig
        return out

    def _jacobian_pattern(self):
        """CSR pattern of :meth:`local_jacobian` and, per entry of its value list (ropes' ``b0, b1, a0, a1``
        per segment, the linear rows, the scale rows' ``r0, r1, e0, e1``), the slot it adds to."""
        if getattr(self, "_jpat", None) is None:
            a2, b2 = 2 * self._seg_a, 2 * self._seg_b
            lin = self._lin.tocoo()
            e, r = self._sc_e, self._sc_r
            rows = np.concatenate([np.tile(self._seg_row, 4), self.n_muscles + lin.row,
                                   self.n_muscles + np.tile(self._sc_row, 4)])
            cols = np.concatenate([b2, b2 + 1, a2, a2 + 1, lin.col, r, r + 1, e, e + 1])
            key = rows * self.n_local + cols
            ukey, slot = np.unique(key, return_inverse=True)
            indptr = np.concatenate([[0], np.cumsum(np.bincount(ukey // self.n_local,
                                                                minlength=self.n_constraints))])
            self._jpat = (indptr, ukey % self.n_local, slot.ravel(), lin.data)
        return self._jpat

    def local_jacobian(self, xl) -> sp.csr_matrix:
        """Jacobian ``(n_constraints, n_local)`` with respect to the local coordinates (closed form)."""
        xl = np.asarray(xl, dtype=float)
        indptr, indices, slot, lin = self._jacobian_pattern()
        d, ln = self._segments(xl)
        t = d / ln[:, None]
        X = xl.reshape(-1, 2)
        u = X[self._sc_r // 2] - X[self._sc_e // 2]
        v = u / np.sqrt(self._sc_UU)[:, None]
        vals = np.concatenate([t[:, 0], t[:, 1], -t[:, 0], -t[:, 1], lin, v[:, 0], v[:, 1], -v[:, 0], -v[:, 1]])
        data = np.bincount(slot, vals, minlength=len(indices))
        return sp.csr_matrix((data, indices, indptr), shape=(self.n_constraints, self.n_local))

    def local_hessian(self, xl, lam) -> sp.csr_matrix:
        """``sum_i lam_i * Hessian(g_i)`` with respect to the local coordinates, full symmetric (closed form:
        ``(I - t t^T) / |d|`` per rope segment, ``I / |U|`` per scale row; the other rigid rows are linear)."""
        rows, cols, vals = self.local_hessian_entries(xl, lam)
        return sp.csr_matrix((vals, (rows, cols)), shape=(self.n_local, self.n_local))

    @staticmethod
    def _pair_entries(blocks):
        """``(rows, cols, vals)`` of 2 x 2 blocks ``(row0, col0, B (N, 2, 2))`` placed at ``(row0 + i, col0 + j)``."""
        rows, cols, vals = [], [], []
        for r0, c0, B in blocks:
            for i in range(2):
                for j in range(2):
                    rows.append(r0 + i)
                    cols.append(c0 + j)
                    vals.append(B[:, i, j])
        return tuple(np.concatenate(v) for v in (rows, cols, vals))

    def _pairs(self, K, S=None):
        """The four blocks ``[[K, -K], [-K, K]]`` of each rope segment (``K`` (ns, 2, 2)) and, with ``S``, of
        each scale row's pair ``(e, r)``."""
        a, b = 2 * self._seg_a, 2 * self._seg_b
        blocks = [(a, a, K), (b, b, K), (a, b, -K), (b, a, -K)]
        if S is not None:
            e, r = self._sc_e, self._sc_r
            blocks += [(e, e, S), (r, r, S), (e, r, -S), (r, e, -S)]
        return blocks

    def local_hessian_entries(self, xl, lam) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`local_hessian` as ``(rows, cols, vals)`` (duplicates to be summed), with rows and columns
        that depend only on the constraints (not on ``xl`` or ``lam``): for assembling into a fixed pattern."""
        xl = np.asarray(xl, dtype=float)
        lam = np.asarray(lam, dtype=float).reshape(-1)
        d, ln = self._segments(xl)
        t = d / ln[:, None]
        w = lam[self._seg_row] / ln
        K = w[:, None, None] * (np.eye(2)[None] - t[:, :, None] * t[:, None, :])  # (ns, 2, 2)
        S = None
        if self.n_rigid:
            ws = lam[self.n_muscles + self._sc_row] / np.sqrt(self._sc_UU)
            S = ws[:, None, None] * np.eye(2)[None]
        return self._pair_entries(self._pairs(K, S))

    def local_third_entries(self, xl, lam, v) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``sum_i lam_i D^3 g_i(xl)[v]`` (the derivative of :meth:`local_hessian` along the local direction
        ``v``) as ``(rows, cols, vals)`` with fixed rows and columns. Only the ropes have one, their segments'
        :func:`~mdsr_opt.mechanics.segments.length_third`; the scale rows are quadratic and the other rigid
        rows linear."""
        lam = np.asarray(lam, dtype=float).reshape(-1)
        d, _ln = self._segments(np.asarray(xl, dtype=float))
        V = np.asarray(v, dtype=float).reshape(-1, 2)
        K = lam[self._seg_row][:, None, None] * length_third(d, V[self._seg_b] - V[self._seg_a])
        return self._pair_entries(self._pairs(K))

    def local_hessian_product_entries(self, xl, v) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The products ``Hessian(g_i)(xl) v`` of every row's Hessian with the local direction ``v``, as the
        columns of an ``(n_local, n_constraints)`` matrix given by ``(rows, cols, vals)`` (fixed rows and
        columns; the linear rows have none)."""
        d, _ln = self._segments(np.asarray(xl, dtype=float))
        V = np.asarray(v, dtype=float).reshape(-1, 2)
        kb = length_hessian_product(d, V[self._seg_b] - V[self._seg_a])  # the product at b; -kb at a
        rows = [2 * self._seg_b, 2 * self._seg_b + 1, 2 * self._seg_a, 2 * self._seg_a + 1]
        cols = [self._seg_row] * 4
        vals = [kb[:, 0], kb[:, 1], -kb[:, 0], -kb[:, 1]]
        if self.n_rigid:
            e, r = self._sc_e, self._sc_r
            du = np.asarray(v, dtype=float).reshape(-1)
            ks = np.column_stack([du[r] - du[e], du[r + 1] - du[e + 1]]) / np.sqrt(self._sc_UU)[:, None]
            row = self.n_muscles + self._sc_row
            rows += [r, r + 1, e, e + 1]
            cols += [row] * 4
            vals += [ks[:, 0], ks[:, 1], -ks[:, 0], -ks[:, 1]]
        return tuple(np.concatenate(u) for u in (rows, cols, vals))

    def values(self, x) -> np.ndarray:
        """All constraint rows at ``x``."""
        return self.local_values(self._xl(x))

    def lengths(self, x) -> np.ndarray:
        """Rope path lengths at ``x`` (n_muscles,)."""
        return self.values(x)[:self.n_muscles]

    def rigid(self, x) -> np.ndarray:
        """Rigid-patch residuals at ``x`` (n_rigid,)."""
        return self.values(x)[self.n_muscles:]

    def jacobian(self, x) -> sp.csr_matrix:
        """Jacobian (n_constraints, 2n) at ``x`` as a scipy CSR matrix (rows: ropes, then rigid)."""
        Jl = self.local_jacobian(self._xl(x))
        return sp.csr_matrix((Jl.data, self.dofs[Jl.indices], Jl.indptr), shape=(self.n_constraints, self.n_dof))

    def hessian(self, x, lam) -> sp.csc_matrix:
        """``sum_i lam_i * Hessian(g_i)`` at ``x``, full symmetric (2n, 2n) scipy CSC matrix."""
        lam = np.asarray(lam, dtype=float).reshape(-1)
        if len(lam) != self.n_constraints:
            raise ValueError(f"lam must have {self.n_constraints} entries, got {len(lam)}")
        Hl = self.local_hessian(self._xl(x), lam).tocoo()
        return sp.csc_matrix((Hl.data, (self.dofs[Hl.row], self.dofs[Hl.col])), shape=(self.n_dof, self.n_dof))


def muscle_constraints(mesh, muscles, radius: float | None = None, held=None) -> MuscleConstraints:
    """The :class:`MuscleConstraints` of ``muscles`` on ``mesh`` (``held``: clamped nodes, as there), cached on
    the mesh per node chains, radius and held nodes.

    :func:`~mdsr_opt.solve_internal` keeps its constraints in the same cache (same key), so a design, its
    forward solves and its verification share one set (and one built CasADi function of it).
    """
    mus = valid_muscles(mesh, muscles)
    r = anchor_radius_or_default(mesh, radius)
    cache = mesh.__dict__.setdefault("_muscle_constraint_cache", {})
    key = (tuple(m.nodes for m in mus), float(r)) + (() if held is None else (tuple(sorted(map(int, held))),))
    if key not in cache:
        if len(cache) >= 16:
            cache.pop(next(iter(cache)))
        cache[key] = MuscleConstraints(mesh, mus, r, held)
    return cache[key]


def _to_scipy(M) -> sp.csc_matrix:
    M = ca.DM(M)
    s = M.sparsity()
    return sp.csc_matrix((np.asarray(M.nonzeros(), dtype=float), np.asarray(s.row()), np.asarray(s.colind())),
                         shape=(M.size1(), M.size2()))
