"""Self-contact by a smooth barrier (incremental potential contact): the energy and its derivatives.

The body's boundary keeps off itself by a barrier on the distance ``d`` of every boundary node ``p`` from
every boundary segment ``(a, b)`` that does not end at it (the distance from the point to the segment, not to
its line: it is exact across the segment's ends, where it becomes the distance to the end node). Pairs
closer than ``dhat`` add ``kappa b(d)`` with

    ``b(d) = -(d - dhat)^2 log(d / dhat)``  for ``0 < d < dhat``, 0 beyond,

twice continuously differentiable at ``dhat`` (``b``, ``b'`` and ``b''`` vanish there) and infinite at
``d = 0``. The default ``dhat`` is a tenth of the mean boundary edge at rest (:data:`DHAT`), and at most half
the smallest rest distance of such a pair (:data:`REST_FRACTION`), so that no pair is within ``dhat`` at rest:
an unloaded body stays at rest with no contact force. The total energy is the strain energy
(:class:`~mdsr_opt.mechanics.newton.NewtonEnergy`) plus the barrier's. A state of finite total energy reached along steps that no boundary node crosses a boundary
segment in (continuous collision detection, :mod:`~mdsr_opt.mechanics.ccd`) has no crossing: the barrier
pushes touching parts apart with the force ``-kappa b'(d) grad d`` on each pair (:func:`pair_forces`),
which is how contact forces are reported. ``d`` stays positive: the barrier's contacts keep a gap between
0 and ``dhat`` whose size depends on ``kappa`` and the contact pressure.

The Hessian of a pair (6 x 6 in ``(p, a, b)``) is ``kappa (b'' grad d grad d' + b' H_d)``; Newton's method
(:mod:`~mdsr_opt.mechanics.barriersolve`) projects it to positive semi-definite per pair (clamping its
negative eigenvalues), as it does the elements' blocks.

Example
-------
>>> import numpy as np
>>> x = np.array([[0.5, 0.002], [0.0, 0.0], [1.0, 0.0]])    # node 0 just above the segment (1, 2)
>>> d, gd, _ = point_segment_distance(x, np.array([[0, 1, 2]]))
>>> round(float(d[0]), 6), (np.round(gd[0], 6) + 0.0).tolist()
(0.002, [0.0, 1.0, 0.0, -0.5, 0.0, -0.5])
>>> b, db, _ = barrier(np.array([0.002]), 0.01)
>>> bool(b[0] > 0 and db[0] < 0)
True
"""

from __future__ import annotations

import numpy as np

from .ccd import swept_pairs

__all__ = ["barrier", "point_segment_distance", "BarrierEnergy", "pair_forces", "project_psd", "rest_reach", "DHAT",
           "KAPPA", "REST_FRACTION"]

#: the barrier's reach ``dhat`` as a fraction of the mean boundary edge length at rest (at most
#: :data:`REST_FRACTION` of the smallest rest distance of the pairs)
DHAT = 0.1

#: the default ``dhat`` is at most this fraction of the smallest distance at rest among the pairs the barrier
#: considers (each boundary node and each boundary segment not ending at it), so that no pair is within
#: ``dhat`` at rest and an unloaded body stays at rest with no contact force (a short boundary edge, at a
#: corner for instance, brings a node within a tenth of the mean edge of the segment after its neighbour)
REST_FRACTION = 0.5

#: the barrier's stiffness ``kappa`` in units of the body's ``E t`` (the unit body's is 1): a pair under a
#: contact force ``f`` rests at ``d`` with ``kappa |b'(d)| = f``, about ``kappa dhat^2 / d`` for ``d`` well
#: below ``dhat``. With ``dhat`` a fixed fraction of the edge length and a contact pressure ``q`` (a force
#: ``q h`` per pair on edges of length ``h``) the gap ``d / dhat`` is about ``kappa DHAT / (q / E t)``: the
#: same on every mesh of a body. With 1 and pressures of a few percent of ``E t`` the gaps are a fraction of
#: ``dhat``
KAPPA = 1.0


def barrier(d, dhat: float):
    """``(b, b', b'')`` of ``b(d) = -(d - dhat)^2 log(d / dhat)`` for ``d < dhat`` (0 beyond) elementwise.

    Parameters
    ----------
    d : array of positive distances.
    dhat : the barrier's reach.

    Returns
    -------
    tuple of three arrays shaped as ``d``; ``b`` is ``inf`` at ``d <= 0``.
    """
    d = np.asarray(d, dtype=float)
    on = d < dhat
    with np.errstate(divide="ignore", invalid="ignore"):
        r = d - dhat
        lg = np.log(d / dhat)
        b = np.where(on, -r * r * lg, 0.0)
        db = np.where(on, -2.0 * r * lg - r * r / d, 0.0)
        ddb = np.where(on, -2.0 * lg - 4.0 * r / d + r * r / (d * d), 0.0)
    b = np.where(d <= 0.0, np.inf, b)
    return b, db, ddb


_SEL = {"p": np.array([0, 1]), "a": np.array([2, 3]), "b": np.array([4, 5])}


def point_segment_distance(X, pairs, hessian: bool = True):
    """The distance ``d`` of each pair's node from its segment, its gradient and Hessian in ``(p, a, b)``.

    Parameters
    ----------
    X : (n, 2) array of node positions.
    pairs : (N, 3) int array of rows ``(p, a, b)``.
    hessian : compute the (N, 6, 6) Hessians (else None).

    Returns
    -------
    d : (N,) distances.
    grad : (N, 6) gradients in ``(p_x, p_y, a_x, a_y, b_x, b_y)``.
    hess : (N, 6, 6) Hessians or None.

    Notes
    -----
    With ``t`` the projection parameter of ``p`` on the segment's line: for ``t <= 0`` the distance from
    ``a``, for ``t >= 1`` from ``b``, between them ``|(b - a) x (p - a)| / |b - a|``. Each piece is written
    as ``d = sqrt(D)`` with ``D`` a squared distance whose derivatives are closed forms; the pieces meet with
    equal value and gradient (the Hessian jumps at the ends, where the barrier's Newton steps do not need
    more).
    """
    X = np.asarray(X, dtype=float)
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 3)
    N = len(pairs)
    P, A, B = X[pairs[:, 0]], X[pairs[:, 1]], X[pairs[:, 2]]
    e, w = B - A, P - A
    ee = np.einsum("ij,ij->i", e, e)
    t = np.einsum("ij,ij->i", w, e) / np.maximum(ee, 1e-300)
    D = np.empty(N)
    gD = np.zeros((N, 6))
    HD = np.zeros((N, 6, 6)) if hessian else None
    I2 = np.eye(2)
    for end, mask in (("a", t <= 0.0), ("b", t >= 1.0)):  # point-point: D = |p - q|^2
        k = np.flatnonzero(mask)
        if not len(k):
            continue
        u = P[k] - (A[k] if end == "a" else B[k])
        D[k] = np.einsum("ij,ij->i", u, u)
        q = _SEL[end]
        gD[k[:, None], _SEL["p"]] = 2.0 * u
        gD[k[:, None], q] = -2.0 * u
        if hessian:
            for r, sr in (("p", 1.0), (end, -1.0)):
                for c, sc in (("p", 1.0), (end, -1.0)):
                    HD[np.ix_(k, _SEL[r], _SEL[c])] = 2.0 * sr * sc * I2
    k = np.flatnonzero((t > 0.0) & (t < 1.0))  # point-line: D = c^2 / q, c = e x w, q = e . e
    if len(k):
        ek, wk, q = e[k], w[k], ee[k]
        c = ek[:, 0] * wk[:, 1] - ek[:, 1] * wk[:, 0]
        D[k] = c * c / q
        gc = np.zeros((len(k), 6))  # dc/dw = (-e_y, e_x), dc/de = (w_y, -w_x); w = p - a, e = b - a
        dw = np.stack([-ek[:, 1], ek[:, 0]], 1)
        de = np.stack([wk[:, 1], -wk[:, 0]], 1)
        gc[:, 0:2] = dw
        gc[:, 4:6] = de
        gc[:, 2:4] = -dw - de
        gq = np.zeros((len(k), 6))
        gq[:, 4:6] = 2.0 * ek
        gq[:, 2:4] = -2.0 * ek
        qi = 1.0 / q
        gD[k] = (2.0 * c * qi)[:, None] * gc - (c * c * qi * qi)[:, None] * gq
        if hessian:
            Sw = np.zeros((2, 6))
            Sw[:, 0:2], Sw[:, 2:4] = I2, -I2
            Se = np.zeros((2, 6))
            Se[:, 4:6], Se[:, 2:4] = I2, -I2
            R = np.array([[0.0, 1.0], [-1.0, 0.0]])  # c = e' R w
            Hc = Se.T @ R @ Sw
            Hc = Hc + Hc.T
            Hq = 2.0 * Se.T @ Se
            o = lambda u, v: u[:, :, None] * v[:, None, :]  # noqa: E731 (outer products per row)
            cq, cq2 = c * qi, c * qi * qi
            HD[k] = (2.0 * qi[:, None, None] * o(gc, gc) + 2.0 * cq[:, None, None] * Hc[None]
                     - 2.0 * cq2[:, None, None] * (o(gc, gq) + o(gq, gc))
                     - (c * cq2)[:, None, None] * Hq[None] + (2.0 * c * cq2 * qi)[:, None, None] * o(gq, gq))
    d = np.sqrt(np.maximum(D, 0.0))
    ds = np.maximum(d, 1e-300)
    grad = gD / (2.0 * ds)[:, None]
    hess = None
    if hessian:
        hess = HD / (2.0 * ds)[:, None, None] - gD[:, :, None] * gD[:, None, :] / (4.0 * ds ** 3)[:, None, None]
    return d, grad, hess


def project_psd(H):
    """Each symmetric block of ``H`` (N, k, k) with its negative eigenvalues clamped to zero."""
    if not len(H):
        return H
    w, V = np.linalg.eigh(0.5 * (H + np.swapaxes(H, 1, 2)))
    return (V * np.maximum(w, 0.0)[:, None, :]) @ np.swapaxes(V, 1, 2)


def pair_dofs(pairs) -> np.ndarray:
    """The six coordinates ``(2p, 2p + 1, 2a, 2a + 1, 2b, 2b + 1)`` of each pair, (N, 6)."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 3)
    return np.stack([2 * pairs, 2 * pairs + 1], axis=2).reshape(-1, 6)


def pair_forces(X, pairs, kappa: float, dhat: float):
    """The barrier's contact forces of ``pairs`` at ``X``: ``(magnitudes (N,), distances (N,), node forces
    (n, 2))``. A pair pushes its node away from its segment with ``f = -kappa b'(d)`` along ``grad_p d`` and
    its segment's ends back (``-kappa b'(d) grad d``, summing to zero); ``node forces`` sums them per node
    (minus the barrier energy's gradient)."""
    X = np.asarray(X, dtype=float)
    d, gd, _ = point_segment_distance(X, pairs, hessian=False)
    _b, db, _ = barrier(d, dhat)
    f = -kappa * db
    node = np.bincount(pair_dofs(pairs).ravel(), weights=(f[:, None] * gd).ravel(), minlength=X.size)
    return f, d, node.reshape(-1, 2)


def rest_reach(X, nodes, segs, reach: float) -> float:
    """``reach`` or, when smaller, :data:`REST_FRACTION` of the smallest distance at ``X`` (rest) of a node
    from a segment not ending at it (those within ``reach``; a zero distance, a mesh touching itself at rest,
    is left to the solve's check of its first state)."""
    X = np.asarray(X, dtype=float)
    pairs = swept_pairs(X, X, nodes, segs, reach)
    d = point_segment_distance(X, pairs, hessian=False)[0] if len(pairs) else np.zeros(0)
    d = d[d > 0.0]
    return float(min(reach, REST_FRACTION * d.min())) if len(d) else float(reach)


class BarrierEnergy:
    """The strain energy of a model plus the self-contact barrier of its boundary.

    Parameters
    ----------
    model : EnergyModel
        A model with closed-form material laws (``model.is_numeric``).
    p : parameter vector of the model.
    dhat : float, optional
        The barrier's reach (default :data:`DHAT` times the mean boundary edge length at rest, at most
        :data:`REST_FRACTION` of the smallest distance at rest of a node from a segment not ending at it:
        :func:`rest_reach`; with ``self_contact`` False, the former).
    kappa : float, optional
        The barrier's stiffness (default :data:`KAPPA` times the model's unit stiffness ``E t``; pass it in
        the body's energy units).
    planes : (k, 2, 2) array, optional
        Rigid half-planes, each ``(point q, unit normal n)`` (``n`` into the free side): every boundary node
        ``p`` is kept on the free side by the same barrier on ``d = n . (p - q)`` (a segment cannot enter a
        half-plane without an end node in it).
    self_contact : bool
        Keep the boundary off itself (default); False: only off the planes.
    fixed_nodes : int array, optional
        Nodes left out of the planes' terms (the fixed ones: their terms are constants, infinite for a node
        on a plane, so a body anchored on the ground keeps its feet there).
    """

    def __init__(self, model, p, dhat: float | None = None, kappa: float | None = None, planes=None,
                 self_contact: bool = True, fixed_nodes=None):
        mesh = model.mesh
        self.model, self.p = model, np.asarray(p, dtype=float)
        self.elastic = model.numeric(self.p)
        self.segs = np.asarray(mesh.boundary_edges, dtype=np.int64)
        self.nodes = np.unique(self.segs)
        pts = mesh.points
        h = float(np.linalg.norm(pts[self.segs[:, 1]] - pts[self.segs[:, 0]], axis=1).mean())
        self.h = h  #: the mean boundary edge length at rest
        self.self_contact = bool(self_contact)
        reach = rest_reach(pts, self.nodes, self.segs, DHAT * h) if self.self_contact else DHAT * h
        self.dhat = float(reach if dhat is None else dhat)
        self.kappa = float(KAPPA if kappa is None else kappa)
        self.n = 2 * mesh.n_nodes
        self.planes = np.zeros((0, 2, 2)) if planes is None else np.asarray(planes, dtype=float).reshape(-1, 2, 2)
        skip = np.zeros(0, dtype=np.int64) if fixed_nodes is None else np.asarray(fixed_nodes, dtype=np.int64)
        self.plane_nodes = np.setdiff1d(self.nodes, skip)  #: the boundary nodes the planes' barrier acts on

    def plane_distances(self, x) -> np.ndarray:
        """``d`` (k, b) of every boundary node the planes act on (:attr:`plane_nodes`) from every plane, signed
        (negative inside)."""
        X = np.asarray(x, dtype=float).reshape(-1, 2)[self.plane_nodes]
        return np.einsum("kj,kbj->kb", self.planes[:, 1], X[None] - self.planes[:, 0][:, None])

    def plane_impact(self, x0, x1) -> float:
        """The earliest ``t`` in ``[0, 1]`` at which a boundary node reaches a plane along the straight step
        from ``x0`` to ``x1`` (``inf`` when none does)."""
        if not len(self.planes):
            return np.inf
        d0, d1 = self.plane_distances(x0), self.plane_distances(x1)
        hit = d1 <= 0.0
        if not hit.any():
            return np.inf
        return float((d0[hit] / np.maximum(d0[hit] - d1[hit], 1e-300)).min())

    def plane_terms(self, x):
        """The node-plane terms within ``dhat`` at ``x``: ``(nodes (N,), planes (N,), d (N,))``."""
        if not len(self.planes):
            z = np.zeros(0, dtype=np.int64)
            return z, z, np.zeros(0)
        d = self.plane_distances(x)
        k, j = np.nonzero(d < self.dhat)
        return self.plane_nodes[j], k, d[k, j]

    def pairs(self, X0, X1=None) -> np.ndarray:
        """The candidate pairs within ``dhat`` anywhere along the step from ``X0`` to ``X1`` (default: at
        ``X0``), (N, 3) rows ``(p, a, b)``."""
        X0 = np.asarray(X0, dtype=float).reshape(-1, 2)
        X1 = X0 if X1 is None else np.asarray(X1, dtype=float).reshape(-1, 2)
        if not self.self_contact:
            return np.zeros((0, 3), dtype=np.int64)
        return swept_pairs(X0, X1, self.nodes, self.segs, self.dhat)

    def active(self, x, cand) -> np.ndarray:
        """The rows of ``cand`` closer than ``dhat`` at ``x``."""
        if not len(cand):
            return cand
        d = point_segment_distance(np.asarray(x).reshape(-1, 2), cand, hessian=False)[0]
        return cand[d < self.dhat]

    def contact_energy(self, x, cand) -> float:
        """The barrier energy at ``x`` over the candidate pairs ``cand`` and the planes (``inf`` at a zero
        distance or a node in a plane)."""
        W = 0.0
        if len(self.planes):
            d = self.plane_distances(x)
            if (d <= 0.0).any():
                return np.inf
            W += self.kappa * float(barrier(d[d < self.dhat], self.dhat)[0].sum())
        if not len(cand):
            return W
        d = point_segment_distance(np.asarray(x).reshape(-1, 2), cand, hessian=False)[0]
        return W + self.kappa * float(barrier(d, self.dhat)[0].sum())

    def energy(self, x, cand) -> float:
        """Strain plus barrier energy at ``x`` (flat), ``inf`` at an inverted element or a zero distance."""
        W = self.elastic.energy(x)
        if not np.isfinite(W):
            return np.inf
        return W + self.contact_energy(x, cand)

    def gradient(self, x, cand) -> np.ndarray:
        """The total energy's gradient (2n,)."""
        g = self.elastic.gradient(x)
        act = self.active(x, cand)
        if len(act):
            g = g - pair_forces(np.asarray(x).reshape(-1, 2), act, self.kappa, self.dhat)[2].ravel()
        return g - self.plane_forces(x)[2].ravel()

    def plane_forces(self, x):
        """The planes' forces on the nodes within ``dhat`` of them: ``(magnitudes (N,), the terms
        (nodes, planes, d), node forces (n, 2))``, each ``-kappa b'(d)`` along the plane's normal."""
        p, k, d = self.plane_terms(x)
        f = -self.kappa * barrier(d, self.dhat)[1]
        node = np.zeros((self.n // 2, 2))
        if len(p):
            np.add.at(node, p, f[:, None] * self.planes[k, 1])
        return f, (p, k, d), node

    def blocks(self, x, cand, project: bool = True):
        """``(gradient (2n,), element blocks, spring blocks, pairs (N, 3), pair blocks (N, 6, 6))`` at ``x``
        (flat): each block projected to positive semi-definite unless ``project=False`` (then their sum is
        the exact Hessian). The node-plane terms come last among the pairs, as rows ``(p, p, p)`` whose
        blocks are nonzero on ``p``'s first two coordinates only."""
        g, He, Hs = self.elastic.element_blocks(x, project=False)
        if project:
            He, Hs = self.elastic.projected_blocks()
        act = self.active(x, cand)
        Hp = np.zeros((0, 6, 6))
        if len(act):
            d, gd, Hd = point_segment_distance(np.asarray(x).reshape(-1, 2), act)
            _b, db, ddb = barrier(d, self.dhat)
            g = g + np.bincount(pair_dofs(act).ravel(), weights=(self.kappa * db[:, None] * gd).ravel(),
                                minlength=self.n)
            Hp = self.kappa * (ddb[:, None, None] * gd[:, :, None] * gd[:, None, :] + db[:, None, None] * Hd)
            if project:
                Hp = project_psd(Hp)
        p, k, d = self.plane_terms(x)
        if len(p):  # as pairs (p, p, p) whose block is kappa b'' n n' on p's coordinates (positive semi-definite)
            _b, db, ddb = barrier(d, self.dhat)
            nrm = self.planes[k, 1]
            g = g + np.bincount(np.stack([2 * p, 2 * p + 1], 1).ravel(), weights=(self.kappa * db[:, None] * nrm).ravel(),
                                minlength=self.n)
            Hq = np.zeros((len(p), 6, 6))
            Hq[:, :2, :2] = self.kappa * ddb[:, None, None] * nrm[:, :, None] * nrm[:, None, :]
            act = np.concatenate([act, np.stack([p, p, p], 1)])
            Hp = np.concatenate([Hp, Hq])
        return g, He, Hs, act, Hp
