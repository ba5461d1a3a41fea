"""Exact muscle constraints: rope path lengths and rigid anchor patches at the muscles' ends.

A muscle is a rope along a chain of mesh nodes ``v0 ... vk``. Its path length in a state ``x`` is

``L_c(x) = sum_i |x_{v_{i+1}} - x_{v_i}|``                       (convex in ``x``)

and the exact cable model of :func:`~mdsr_opt.solve_internal` asks ``L_c(x) <= (1 - a_c) L0_c`` (a rope can
only pull), with the constraint's multiplier as the rope's tension ``tau_c >= 0``.

**Anchor patches.** A rope that ends on one node pulls the body with a point force, under which a planar
elastic body has no finite displacement: the end segments collapse further with every refinement. Each end
is therefore anchored over a patch of physical size, the way a knot, bead or plate spreads the force: the
body nodes within ``radius`` of the end node at rest (and connected to it through such nodes) move rigidly
with it. The radius defaults to :data:`ANCHOR_FRACTION` of the body's size (its diameter at rest,
:func:`body_size`), :func:`default_anchor_radius`; it is never a number of nodes. A node equally far from both
ends of one muscle, or nearer the other end, is left out of an end's patch, so the two patches of a muscle
never overlap. Patches of *different* muscles that share a node are merged into one rigid group.

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
``x0, y0, x1, y1, ...`` as in :mod:`mdsr_opt.model`.

Example
-------
>>> import numpy as np
>>> from mdsr_opt import Mesh, Muscle
>>> from mdsr_opt.muscle_constraints import MuscleConstraints
>>> mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
>>> bottom = [i for i in np.argsort(mesh.points[:, 0]) if mesh.points[i, 1] == 0.0]
>>> mc = MuscleConstraints(mesh, [Muscle(bottom)], radius=0.3)
>>> mc.rest_lengths, mc.n_rigid > 0
(array([4.]), True)
>>> float(np.abs(mc.rigid(mesh.points)).max())
0.0
"""

from __future__ import annotations

import time

import casadi as ca
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ._checks import positive_float
from .muscles import check_muscles

__all__ = ["ANCHOR_FRACTION", "body_size", "default_anchor_radius", "check_anchor_radius", "anchor_patches",
           "rigid_groups",
           "MuscleConstraints", "ConstrainedModel", "spring_stiffness", "segment_spring_parameters",
           "spring_segments"]

#: Default anchor radius as a fraction of the body's size (its diameter at rest, :func:`body_size`).
ANCHOR_FRACTION = 0.04


def body_size(mesh) -> float:
    """The body's diameter at rest: the largest distance between two of its nodes.

    Unlike the bounding-box diagonal (``mesh.size``) it does not change when the body is rotated; for an
    axis-aligned rectangle the two agree.
    """
    cache = mesh.__dict__
    if "_diameter" not in cache:
        P = mesh.points
        try:
            from scipy.spatial import ConvexHull

            V = P[ConvexHull(P).vertices]
        except Exception:  # degenerate hull (collinear points): every node
            V = P
        d = 0.0
        for i0 in range(0, len(V), 1024):
            d = max(d, float(np.sqrt(((V[i0:i0 + 1024, None, :] - V[None, :, :]) ** 2).sum(-1)).max()))
        cache["_diameter"] = d
    return cache["_diameter"]


def default_anchor_radius(mesh) -> float:
    """The default anchor radius: :data:`ANCHOR_FRACTION` (0.04) times :func:`body_size`, in length units."""
    return ANCHOR_FRACTION * body_size(mesh)


def _check_radius(mesh, radius) -> float:
    if radius is None:
        return default_anchor_radius(mesh)
    return positive_float(radius, "anchor_radius", allow_zero=True)


def _ball(mesh, centre: int, radius: float, keep: np.ndarray) -> list[int]:
    """Nodes within ``radius`` of ``centre`` at rest (among ``keep``), connected to it through such nodes."""
    P = mesh.points
    inside = (np.linalg.norm(P - P[centre], axis=1) <= radius) & keep
    inside[centre] = True
    nbrs = mesh.neighbors
    seen, stack, out = {centre}, [centre], []
    while stack:
        v = stack.pop()
        out.append(v)
        for w in nbrs[v].tolist():
            if inside[w] and w not in seen:
                seen.add(w)
                stack.append(w)
    rest = sorted(set(out) - {centre}, key=lambda i: (float(np.linalg.norm(P[i] - P[centre])), i))
    return [centre] + rest


def anchor_patches(mesh, muscles, radius: float | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per muscle the node sets of its two end anchors, ``(start_patch, end_patch)``.

    Parameters
    ----------
    mesh : Mesh
    muscles : sequence of Muscle or node lists
    radius : float, optional
        Anchor radius in length units (default :func:`default_anchor_radius`); 0 anchors each end on its node.

    Returns
    -------
    list of (ndarray, ndarray)
        Each patch lists the end node first, then the body nodes within ``radius`` of it at rest, connected
        to it through such nodes and strictly nearer to it than to the muscle's other end (so a muscle's two
        patches never overlap), by increasing distance.
    """
    mus = check_muscles(mesh, muscles)
    r = _check_radius(mesh, radius)
    P = mesh.points
    out = []
    for m in mus:
        s, e = m.nodes[0], m.nodes[-1]
        ds = np.linalg.norm(P - P[s], axis=1)
        de = np.linalg.norm(P - P[e], axis=1)
        out.append((np.array(_ball(mesh, s, r, ds < de), dtype=np.int64),
                    np.array(_ball(mesh, e, r, de < ds), dtype=np.int64)))
    return out


def rigid_groups(mesh, muscles, radius: float | None = None) -> list[np.ndarray]:
    """Anchor patches merged where patches of different muscles share a node: each group moves rigidly.

    Groups of one node are dropped (they constrain nothing). Raises ``ValueError`` when merging would join
    the two ends of one muscle (it could then not contract); a smaller ``radius`` avoids that.
    """
    mus = check_muscles(mesh, muscles)
    patches = anchor_patches(mesh, mus, radius)
    flat = [p for pair in patches for p in pair]
    parent = list(range(len(flat)))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    owner: dict[int, int] = {}
    for k, p in enumerate(flat):
        for v in p.tolist():
            if v in owner:
                a, b = find(owner[v]), find(k)
                if a != b:
                    parent[max(a, b)] = min(a, b)
            else:
                owner[v] = k
    for c in range(len(mus)):
        if find(2 * c) == find(2 * c + 1):
            raise ValueError(f"the anchor patches of muscle {c} are joined through other muscles' anchors, so "
                             "it could not contract; give a smaller anchor_radius")
    groups: dict[int, list[int]] = {}
    for k, p in enumerate(flat):
        g = groups.setdefault(find(k), [])
        g.extend(v for v in p.tolist() if v not in g)
    return [np.array(g, dtype=np.int64) for _, g in sorted(groups.items()) if len(g) >= 2]


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
    :meth:`~mdsr_opt.model.EnergyModel.params` as ``springs=``.

    Raises
    ------
    ValueError
        When ``a' >= 1`` (the anchors cover too much of a muscle for the contraction asked).
    """
    from .model import spring_parameters

    mus = check_muscles(mesh, muscles)
    a = np.asarray(contractions, dtype=float).reshape(-1)
    ks, a_eff = spring_segments(mesh, material, mus, stiffness, anchor_radius)
    return spring_parameters(mesh, mus, a * a_eff, ks)


def spring_segments(mesh, material, muscles, stiffness: float, anchor_radius: float | None = None):
    """``(per-muscle segment stiffness arrays, per-muscle factor L0 / L0_free)`` of the dummy springs (see
    :func:`segment_spring_parameters`); stiffness is 0 on segments inside an anchor patch."""
    mus = check_muscles(mesh, muscles)
    K = spring_stiffness(mesh, material, stiffness)
    group_of = np.full(mesh.n_nodes, -1)
    for gi, g in enumerate(rigid_groups(mesh, mus, anchor_radius)):
        group_of[g] = gi
    ks, fac = [], []
    for m in mus:
        seg = m.segments
        l0 = m.segment_lengths(mesh.points)
        inside = (group_of[seg[:, 0]] >= 0) & (group_of[seg[:, 0]] == group_of[seg[:, 1]])
        if inside.all():
            raise ValueError(f"muscle {m._label()} lies inside its anchor patches: give a smaller anchor_radius")
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
        Anchor radius (default :func:`default_anchor_radius`; 0 for single-node ends).

    Attributes
    ----------
    n_muscles, n_rigid, n_constraints : int
        Rope rows, rigid rows and their sum (rows are ropes first, then rigid).
    rest_lengths : (n_muscles,) ndarray
        ``L0`` per muscle along its node chain.
    groups : list of ndarray
        The rigid groups (see :func:`rigid_groups`).
    dofs : ndarray
        Sorted global coordinates (of the 2n) that any constraint involves.
    radius : float
    """

    def __init__(self, mesh, muscles, radius: float | None = None):
        self.mesh = mesh
        self.muscles = check_muscles(mesh, muscles)
        if not self.muscles:
            raise ValueError("MuscleConstraints needs at least one muscle")
        self.radius = _check_radius(mesh, radius)
        self.groups = rigid_groups(mesh, self.muscles, self.radius)
        n = mesh.n_nodes
        self.n_dof = 2 * n
        P = mesh.points
        self.rest_lengths = np.array([m.rest_length(mesh) for m in self.muscles])
        nodes = sorted(set(v for m in self.muscles for v in m.nodes) | set(v for g in self.groups for v in g.tolist()))
        self.dofs = np.array([d for v in nodes for d in (2 * v, 2 * v + 1)], dtype=np.int64)
        loc = {v: k for k, v in enumerate(nodes)}
        nd = len(self.dofs)
        xl = ca.SX.sym("xl", nd)

        def pt(v):
            return xl[2 * loc[v]:2 * loc[v] + 2]

        rows = []
        for m in self.muscles:
            L = 0
            for a, b in m.segments.tolist():
                L += ca.sqrt(ca.sumsqr(pt(b) - pt(a)))
            rows.append(L)
        rigid = []
        for g in self.groups:
            e = int(g[0])
            dist = np.linalg.norm(P[g] - P[e], axis=1)
            r = int(g[int(np.argmax(dist))])
            U = P[r] - P[e]
            UU = float(U @ U)
            u = pt(r) - pt(e)
            c = (u[0] * U[0] + u[1] * U[1]) / UU
            s = (U[0] * u[1] - U[1] * u[0]) / UU
            for j in g.tolist():
                if j in (e, r):
                    continue
                D = P[j] - P[e]
                rigid.append(pt(j)[0] - pt(e)[0] - (c * D[0] - s * D[1]))
                rigid.append(pt(j)[1] - pt(e)[1] - (s * D[0] + c * D[1]))
            rigid.append((ca.sumsqr(u) - UU) / (2 * np.sqrt(UU)))
        self.n_muscles = len(rows)
        self.n_rigid = len(rigid)
        self.n_constraints = self.n_muscles + self.n_rigid
        g_all = ca.vertcat(*rows, *rigid)
        lam = ca.SX.sym("lam", self.n_constraints)
        self._g = ca.Function("muscle_g", [xl], [g_all])
        self._J = ca.Function("muscle_jac", [xl], [ca.jacobian(g_all, xl)])
        H = ca.hessian(ca.dot(lam, g_all), xl)[0]
        self._H = ca.Function("muscle_hess", [xl, lam], [ca.triu(H)])
        # (nd, 2n) selection: x_local = S x
        self._S = sp.csr_matrix((np.ones(nd), (np.arange(nd), self.dofs)), shape=(nd, self.n_dof))
        self._S_dm = _to_dm(self._S)

    # ------------------------------------------------------------------ symbolic (SX or MX, length 2n)
    def _local(self, x):
        return x[self.dofs.tolist()]

    def constraints_expr(self, x):
        """All constraint rows, ropes first then rigid, as a CasADi column."""
        return self._g(self._local(x))

    def lengths_expr(self, x):
        """Rope path lengths ``L_c(x)`` (n_muscles,)."""
        return self.constraints_expr(x)[:self.n_muscles]

    def rigid_expr(self, x):
        """Rigid-patch residuals (n_rigid,): all zero iff every group moved rigidly, keeping orientation."""
        return self.constraints_expr(x)[self.n_muscles:]

    def jacobian_expr(self, x):
        """Sparse Jacobian (n_constraints, 2n) of :meth:`constraints_expr`."""
        return ca.mtimes(self._J(self._local(x)), self._S_dm)

    def hessian_expr(self, x, lam):
        """Upper triangle (2n, 2n) of ``sum_i lam_i * Hessian(g_i)`` (sparse; only anchors and ropes)."""
        Hl = self._H(self._local(x), lam)
        return ca.mtimes(ca.mtimes(self._S_dm.T, Hl), self._S_dm)

    # ------------------------------------------------------------------ numeric (x as (n, 2) or (2n,))
    def _xl(self, x) -> np.ndarray:
        return np.asarray(x, dtype=float).reshape(-1)[self.dofs]

    def values(self, x) -> np.ndarray:
        """All constraint rows at ``x``."""
        return np.asarray(self._g(self._xl(x))).ravel()

    def lengths(self, x) -> np.ndarray:
        """Rope path lengths at ``x`` (n_muscles,)."""
        return self.values(x)[:self.n_muscles]

    def rigid(self, x) -> np.ndarray:
        """Rigid-patch residuals at ``x`` (n_rigid,)."""
        return self.values(x)[self.n_muscles:]

    def jacobian(self, x) -> sp.csr_matrix:
        """Jacobian (n_constraints, 2n) at ``x`` as a scipy CSR matrix (rows: ropes, then rigid)."""
        Jl = _to_scipy(self._J(self._xl(x)))
        return (Jl @ self._S).tocsr()

    def hessian(self, x, lam) -> sp.csc_matrix:
        """``sum_i lam_i * Hessian(g_i)`` at ``x``, full symmetric (2n, 2n) scipy CSC matrix."""
        lam = np.asarray(lam, dtype=float).reshape(-1)
        if len(lam) != self.n_constraints:
            raise ValueError(f"lam must have {self.n_constraints} entries, got {len(lam)}")
        U = _to_scipy(self._H(self._xl(x), lam))
        Hl = U + sp.triu(U, 1).T
        return (self._S.T @ Hl @ self._S).tocsc()


def _to_dm(S) -> ca.DM:
    S = sp.csc_matrix(S)
    S.sort_indices()
    spars = ca.Sparsity(S.shape[0], S.shape[1], S.indptr.astype(np.int64).tolist(),
                        S.indices.astype(np.int64).tolist())
    return ca.DM(spars, S.data.tolist())


def _to_scipy(M) -> sp.csc_matrix:
    M = ca.DM(M)
    s = M.sparsity()
    return sp.csc_matrix((np.asarray(M.nonzeros(), dtype=float), np.asarray(s.row()), np.asarray(s.colind())),
                         shape=(M.size1(), M.size2()))


def check_anchor_radius(mesh, radius) -> float:
    """``radius`` as a float in length units (None gives :func:`default_anchor_radius`); clear errors."""
    return _check_radius(mesh, radius)


class ConstrainedModel:
    """An :class:`~mdsr_opt.model.EnergyModel` whose minimisation carries muscle constraints.

    The objective is the model's energy; the constraints are the rigid anchor rows of ``constraints`` and,
    with ``ropes=True`` (the exact cable), one rope row per muscle, ``L_c(x) <= target_c``. The parameter
    vector is ``p = [energy params, rope targets (n_targets), multipliers (n_rows)]``: the multipliers enter
    :meth:`gradient` and :meth:`hessian`, which are those of the Lagrangian
    ``E(x) + sum_i lam_i g_i(x)`` (with zero multipliers, those of the energy), so a KKT point has zero
    :meth:`gradient` on the free coordinates. :func:`mdsr_opt.backends.minimize` recognises this class and
    passes the constraints to the NLP.

    Parameters
    ----------
    model : EnergyModel
    constraints : MuscleConstraints
    ropes : bool
        Whether the rope rows are constraints (the exact cable) or left out (dummy springs: only anchors).
    """

    def __init__(self, model, constraints: MuscleConstraints, ropes: bool):
        self.model = model
        self.constraints = constraints
        self.ropes = bool(ropes)
        self.mesh = model.mesh
        self.n_dof = model.n_dof
        mc = constraints
        self.rows = np.arange(mc.n_constraints) if self.ropes else np.arange(mc.n_muscles, mc.n_constraints)
        self.n_rows = len(self.rows)
        self.n_targets = mc.n_muscles if self.ropes else 0
        self.n_energy_params = model.n_params
        self.n_params = model.n_params + self.n_targets + self.n_rows
        self._solvers: dict = {}

    # ------------------------------------------------------------------ parameters
    def params(self, p_energy, targets=None, lam=None) -> np.ndarray:
        """``p`` from the energy parameters, the rope targets (cable only) and optional multipliers."""
        p = np.zeros(self.n_params)
        p[:self.n_energy_params] = p_energy
        if self.n_targets:
            if targets is None:
                raise ValueError("the exact cable needs its rope target lengths")
            p[self.n_energy_params:self.n_energy_params + self.n_targets] = targets
        if lam is not None:
            p[self.n_energy_params + self.n_targets:] = lam
        return p

    def split(self, p):
        """``(p_energy, targets, lam)`` of a parameter vector."""
        p = np.asarray(p, dtype=float)
        a, b = self.n_energy_params, self.n_energy_params + self.n_targets
        return p[:a], p[a:b], p[b:]

    def force_scale(self, p) -> float:
        """A force that sizes the multipliers: ``mu * thickness * body_size`` (``mu`` the shear modulus)."""
        return abs(float(self.split(p)[0][0])) * body_size(self.mesh)

    def _lam_full(self, lam) -> np.ndarray:
        out = np.zeros(self.constraints.n_constraints)
        out[self.rows] = lam
        return out

    def bounds(self, p, equality_ropes: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """``(lbg, ubg)`` of the NLP's constraint rows: ropes ``<= target`` (``== target`` when
        ``equality_ropes``), rigid rows ``== 0``."""
        _, targets, _ = self.split(p)
        lb = np.zeros(self.n_rows)
        ub = np.zeros(self.n_rows)
        if self.n_targets:
            ub[:self.n_targets] = targets
            lb[:self.n_targets] = targets if equality_ropes else -np.inf
        return lb, ub

    # ------------------------------------------------------------------ numeric evaluation
    def values(self, x) -> np.ndarray:
        """The NLP's constraint rows at ``x``."""
        return self.constraints.values(x)[self.rows]

    def jacobian(self, x) -> sp.csr_matrix:
        return self.constraints.jacobian(x)[self.rows]

    def energy(self, x, p) -> float:
        return self.model.energy(x, self.split(p)[0])

    def gradient(self, x, p) -> np.ndarray:
        """Gradient of the Lagrangian (of the energy when the multipliers in ``p`` are zero)."""
        pe, _, lam = self.split(p)
        g = self.model.gradient(x, pe)
        if np.any(lam):
            g = g + self.jacobian(x).T @ lam
        return g

    def hessian(self, x, p) -> sp.csc_matrix:
        """Hessian of the Lagrangian, full symmetric scipy CSC."""
        pe, _, lam = self.split(p)
        H = self.model.hessian(x, pe)
        if np.any(lam):
            H = (H + self.constraints.hessian(x, self._lam_full(lam))).tocsc()
        return H

    # ------------------------------------------------------------------ symbolic pieces for the NLP
    def constraints_expr(self, x):
        g = self.constraints.constraints_expr(x)
        return g if self.ropes else g[self.constraints.n_muscles:]

    def hess_lag_upper(self, x, p, lam_f, lam_g):
        """Upper triangle of the Lagrangian's Hessian as a CasADi expression (for IPOPT's ``hess_lag``)."""
        lam = lam_g if self.ropes else ca.vertcat(ca.MX(self.constraints.n_muscles, 1), lam_g)
        return self.model.hess_lag_fn(x, p, lam_f, ca.MX(0, 1)) + self.constraints.hessian_expr(x, lam)

    def solver(self, backend: str, options: dict, factory):
        """``(solver, build seconds)``, cached per backend and options like the energy model's."""
        key = (backend, repr(sorted(options.items())))
        if key in self._solvers:
            return self._solvers[key], 0.0
        t0 = time.perf_counter()
        s = factory(self)
        self._solvers[key] = s
        return s, time.perf_counter() - t0

    # ------------------------------------------------------------------ predictor and multipliers
    def predict(self, p, x, fixed, values):
        """A Newton (KKT) step from ``x`` on the Lagrangian (multipliers fitted at ``x``, see
        :meth:`multipliers`): fixed coordinates moved to ``values``, the constraints linearised
        and met, ropes whose predicted tension is negative dropped (slack), the step halved while it would
        leave an element with less than half the smallest ``det F`` of ``x``. None if the system is
        singular."""
        free = ~fixed
        pe, targets, _ = self.split(p)
        # the Hessian of the Lagrangian at x, with x's own multipliers (every rope taken as at its length):
        # under load the energy's Hessian alone can be indefinite where the ropes hold the body
        lam_x, _ = self.multipliers(x, self.params(pe, self.values(x)[:self.n_targets] if self.n_targets else None),
                                    fixed)
        H = self.hessian(x, self.params(pe, targets if self.n_targets else None, lam_x))
        Hff = H[free][:, free]
        dfix = values - x[fixed]
        g = self.model.gradient(x, pe)
        rhs_x = -(g[free] + H[free][:, fixed] @ dfix)
        J = self.jacobian(x)
        c = self.values(x)
        lb, ub = self.bounds(p)
        c = c - ub  # ropes: L - target; rigid: residual
        keep = np.ones(self.n_rows, dtype=bool)
        if self.n_targets:  # a rope shorter than its target at the start is taken as slack
            keep[:self.n_targets] = c[:self.n_targets] > -1e-12 * self.constraints.rest_lengths
        for _ in range(3):
            Jk = J[keep]
            Jf, Jc = Jk[:, free], Jk[:, fixed]
            K = sp.bmat([[Hff, Jf.T], [Jf, None]], format="csc")
            rhs = np.concatenate([rhs_x, -(c[keep] + Jc @ dfix)])
            try:
                sol = spla.splu(K, permc_spec="MMD_AT_PLUS_A").solve(rhs)
            except RuntimeError:
                return None
            if not np.all(np.isfinite(sol)):
                return None
            nk = int(keep[:self.n_targets].sum())
            tau = sol[free.sum():free.sum() + nk]
            if not self.n_targets or np.all(tau >= 0):
                break
            idx = np.nonzero(keep[:self.n_targets])[0]
            keep[idx[tau < 0]] = False
        # a linearised step can nearly invert elements (a large contraction bends the body far): shorten it
        # until no element has lost more than half its area ratio, which halves the NLP's iterations on
        # hard scenes (measured on two opposing ropes: 13-23 iterations down to 6-9)
        j0 = float(self.mesh.jacobians(np.asarray(x, dtype=float).reshape(-1, 2)).min())
        t = 1.0
        while True:
            y = np.array(x, dtype=float)
            y[free] += t * sol[:free.sum()]
            y[fixed] = values
            if t <= 1.0 / 64 or self.mesh.jacobians(y.reshape(-1, 2)).min() >= 0.5 * j0:
                return y
            t /= 2

    def multipliers(self, x, p, fixed, rtol: float = 1e-7) -> tuple[np.ndarray, np.ndarray]:
        """Least-squares multipliers at a solution ``x``: ``(lam (n_rows,), taut (n_targets,) bool)``.

        Ropes shorter than their target by more than ``rtol * L0`` are slack (multiplier 0); a taut rope
        whose fitted multiplier is negative is released and the fit repeated, so tensions are never
        compressive. The Lagrangian gradient with these multipliers (:meth:`gradient`) is the KKT residual.
        """
        free = ~fixed
        pe, targets, _ = self.split(p)
        g = self.model.gradient(x, pe)[free]
        J = self.jacobian(x)[:, free].tocsr()
        active = np.ones(self.n_rows, dtype=bool)
        nt = self.n_targets
        if nt:
            L = self.values(x)[:nt]
            active[:nt] = L >= targets - rtol * self.constraints.rest_lengths
        lam = np.zeros(self.n_rows)
        for _ in range(nt + 1):
            Ja = J[active]
            if Ja.shape[0] == 0:
                break
            A = (Ja @ Ja.T).tocsc()
            try:
                la = spla.splu(A).solve(-(Ja @ g))
            except RuntimeError:
                la = np.linalg.lstsq(Ja.T.toarray(), -g, rcond=None)[0]
            lam[:] = 0.0
            lam[active] = la
            neg = np.nonzero(active[:nt] & (lam[:nt] < 0))[0]
            if len(neg) == 0:
                break
            active[neg] = False
        return lam, active[:nt]
