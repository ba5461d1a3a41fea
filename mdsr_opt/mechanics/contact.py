"""Contact gap rows: a body's boundary against itself and against rigid obstacles, with a broad phase.

Every row is a gap ``g(x) >= gap`` (``gap`` small, stated by the solve) of one of two forms:

- **node-segment**: a point ``p`` and a segment ``(a, b)`` with the body on its left,
  ``g = n . (p - a)`` with the outward normal ``n = (d_y, -d_x) / |d|``, ``d = b - a``: the signed distance of
  ``p`` from the segment's line, positive outside. Self-contact (``p`` a boundary node, ``(a, b)`` a boundary
  segment not near it along the boundary), a body node against a half-plane or a polygon's edge (``a``,
  ``b`` fixed, the obstacle on the left), and a polygon's corner against a body segment (``p`` fixed).
- **disk**: ``g = |p - c| - r`` for a body node ``p``; and **disk-segment**, the disk against a body segment
  ``(a, b)`` near it: ``g = n . (c - a) - r`` while the centre ``c`` projects inside the segment (the same line
  distance, the centre as the point), beyond an end the distance from that end plus a release that makes the
  row looser than the end node's disk row (:func:`_disk_segment_gap`). A disk has no corners to keep out of
  the body's segments, as a polygon's are: without this row a segment between two nodes outside the disk can
  cut through it (a disk smaller than an edge passes into the body between two nodes). The row is exact (the
  distance from the centre to the segment) where the centre projects inside it, the node rows where it does
  not; a pair is made only with the centre on the segment's outer side in the state the step starts from
  (``n . (c - a) >= 0``), and its point of contact is the centre's projection.

Points are body nodes (variables) or fixed points (obstacles). The line distance equals the distance to the
segment while ``p`` projects inside it; a pair is made only for a point that projects within
``[-DELTA, 1 + DELTA]`` of the segment and lies on its outer side in the state the step starts from
(:func:`broad_phase`), and the pairs are refreshed between solves, so a point that slides past a segment's end
is held by the next segment (a pair whose point a solve leaves beyond ``[-DELTA, 1 + DELTA]`` is dropped and
the segment the point slid to takes it over: :func:`handoff_rows`). A point may rest against the extended
line up to ``DELTA`` times a segment's length beyond its end. A solve that crosses the
boundary with no new pair found (a fold within one step bringing together nodes that projected far beyond
each other's segments at its start) adds the pairs of the state of first touch along the path
(:func:`first_touch_rows`).

The multiplier of a row is its contact force (normal, along ``n``; a force ``f n`` on ``p`` and
``-f n (1 - t)``, ``-f n t`` on ``a`` and ``b`` at the projection ``t``).

Example
-------
>>> import numpy as np
>>> x = np.array([[0.5, 0.2], [0.0, 0.0], [1.0, 0.0]])    # node 0 above the segment (1, 2)
>>> rows = ContactRows([[0, 2, 1]], 3)                      # (2 -> 1: the body below, on its left)
>>> rows.values(x).round(6).tolist(), rows.projections(x).round(6).tolist()
([0.2], [0.5])
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.sparse as sp

__all__ = ["ContactRows", "broad_phase", "DELTA", "boundary_segments", "disk_segments", "first_touch_rows",
           "handoff_rows"]

#: a pair is made while its point projects within [-DELTA, 1 + DELTA] of the segment
DELTA = 0.25

#: the weight of a self-contact row's release (careful load steps, :mod:`~mdsr_opt.mechanics.contactsteps`): beyond ``[-DELTA, 1 + DELTA]`` its gap grows by
#: ``RELEASE |b - a| e^2`` (``e`` how far beyond, in segment lengths), so a point that slides past the
#: segment's end within a solve is not held against the extended line (the segment next to it, or the
#: crossing check, takes over); within the range the gap is the line distance
RELEASE = 4.0


def _functions():
    """CasADi SX functions of one row, mapped later: ``g(z, w)``, ``dg/dz`` and ``d2g/dz2`` with
    ``z = (p, a, b)`` and ``w = (kind, r)`` (kind 0 node-segment, ``r`` its release weight (:data:`RELEASE`, 0 for
    none), 1 disk centred at ``a``, 2 node-line: the
    node-segment formula on the whole line through ``a`` and ``b``, a half-plane; 3 angle: ``r`` times the
    angle outside the body at ``a`` between its boundary neighbours ``p`` and ``b``, in ``(0, 2 pi]``; 4 a disk
    centred at ``p`` of radius ``r`` against the body segment ``(a, b)``, :func:`_disk_segment_gap`)."""
    cached = globals().get("_FNS")
    if cached is not None:
        return cached
    z = ca.SX.sym("z", 6)
    w = ca.SX.sym("w", 2)
    p, a, b = z[0:2], z[2:4], z[4:6]
    d = b - a
    ns = (d[1] * (p[0] - a[0]) - d[0] * (p[1] - a[1])) / ca.sqrt(ca.dot(d, d))
    tp = ca.dot(p - a, d) / ca.dot(d, d)  # a self-contact row let go beyond its projection range (RELEASE)
    ns = ns + w[1] * ca.sqrt(ca.dot(d, d)) * (ca.fmax(-DELTA - tp, 0) ** 2 + ca.fmax(tp - 1 - DELTA, 0) ** 2)
    dk = ca.sqrt(ca.dot(p - a, p - a)) - w[1]
    u, v = p - a, b - a  # the angle row: outside angle at a from p (previous node) to b (next node)
    ang = w[1] * (np.pi + ca.atan2(-(u[0] * v[1] - u[1] * v[0]), -ca.dot(u, v)))
    g = ca.if_else(ca.fabs(w[0] - 1.0) < 0.5, dk, ca.if_else(ca.fabs(w[0] - 3.0) < 0.5, ang, ns))
    g = ca.if_else(ca.fabs(w[0] - 4.0) < 0.5, _disk_segment_gap(p, a, b, w[1]), g)
    fns = (ca.Function("contact_gap", [z, w], [g]), ca.Function("contact_gap_jac", [z, w], [ca.jacobian(g, z)]),
           ca.Function("contact_gap_hess", [z, w], [ca.hessian(g, z)[0]]))
    globals()["_FNS"] = fns
    return fns


#: the release of a disk-segment row beyond its segment's ends (:func:`_disk_segment_gap`): small, for its
#: curvature ``2 DISK_RELEASE / |b - a|`` enters the Lagrangian's Hessian times the row's multiplier (with 1 the
#: library gripper's first load step took 276 IPOPT iterations, 67 with 0.03, 80 with 0.01; with 0 the row
#: equals the end node's row there and the solve failed)
DISK_RELEASE = 0.03


def _disk_segment_gap(c, a, b, r):
    """The gap of a disk (centre ``c``, radius ``r``) and a body segment ``(a, b)`` (body on its left), CasADi
    SX: while ``c`` projects onto the segment, its signed distance from the segment's line (positive outside)
    minus ``r``; beyond an end (``s`` how far along the line) the distance from that end plus
    ``DISK_RELEASE s^2 / |b - a|`` minus ``r``. The two pieces meet with equal value and gradient where ``c``
    projects onto an end (from the outer side); beyond the ends the row is strictly looser than the end node's
    own disk row ``|x - c| - r``, which takes over there (so the two are never both active with the same
    gradient)."""
    d = b - a
    dd = ca.dot(d, d)
    L = ca.sqrt(dd)
    h = (d[1] * (c[0] - a[0]) - d[0] * (c[1] - a[1])) / L
    t = ca.dot(c - a, d) / dd
    s = L * (ca.fmax(-t, 0) + ca.fmax(t - 1, 0))
    q = a + ca.fmin(ca.fmax(t, 0), 1) * d
    return ca.if_else(s > 0, ca.sqrt(ca.dot(c - q, c - q)) + DISK_RELEASE * s * s / L, h) - r


class ContactRows:
    """A set of contact gap rows on a body of ``n_nodes`` nodes.

    Parameters
    ----------
    pts : (N, 3) int array
        Per row the points ``p, a, b``: a body node ``< n_nodes``, else ``n_nodes + j`` for the fixed point
        ``consts[j]``.
    n_nodes : int
    consts : (k, 2) fixed points (obstacles).
    w : (N, 2) per row ``(kind, radius)``: kind 0 node-segment (``radius``: its release weight,
        :data:`RELEASE` for a self-contact pair, else 0), 1 disk (centre ``a``), 2 node-line, 3 angle
        (``radius``: the length the angle is scaled by), 4 disk-segment (centre ``p``, segment ``(a, b)``).
    labels : (N, 2) int per row ``(kind code, obstacle index or -1)``; kind codes: 0 self, 1 node-obstacle,
        2 obstacle corner-body segment, 3 an interior node kept inside a boundary segment next to it, 4 the
        outside angle at a boundary node (a crease), 5 a disk against a body segment.
    """

    def __init__(self, pts, n_nodes, consts=None, w=None, labels=None):
        self.pts = np.asarray(pts, dtype=np.int64).reshape(-1, 3)
        self.n_nodes = int(n_nodes)
        self.consts = np.zeros((0, 2)) if consts is None else np.asarray(consts, dtype=float).reshape(-1, 2)
        N = len(self.pts)
        self.w = np.zeros((N, 2)) if w is None else np.asarray(w, dtype=float).reshape(N, 2)
        self.labels = np.zeros((N, 2), dtype=np.int64) if labels is None else np.asarray(labels).reshape(N, 2)
        self.n_rows = N
        self.n_dof = 2 * self.n_nodes
        P = self.pts
        # coordinate indices into z = [x (2n), consts (2k)], (6, N)
        self.index = np.vstack([2 * P[:, 0], 2 * P[:, 0] + 1, 2 * P[:, 1], 2 * P[:, 1] + 1,
                                2 * P[:, 2], 2 * P[:, 2] + 1]).astype(np.int64)

    def key(self) -> tuple:
        """What identifies the set (for caching its NLP)."""
        return (self.pts.tobytes(), self.consts.tobytes(), self.w.tobytes())

    def _z(self, x) -> np.ndarray:
        return np.concatenate([np.asarray(x, dtype=float).reshape(-1), self.consts.reshape(-1)])

    def _eval(self, which, x):
        Z = self._z(x)[self.index]
        return np.asarray(_functions()[which].map(self.n_rows)(Z, self.w.T))

    def values(self, x) -> np.ndarray:
        """The gaps ``g`` (N,) at ``x``."""
        if not self.n_rows:
            return np.zeros(0)
        return self._eval(0, x).reshape(-1)

    def jacobian(self, x) -> sp.csr_matrix:
        """``dg/dx`` (N, 2n), scipy CSR."""
        if not self.n_rows:
            return sp.csr_matrix((0, self.n_dof))
        J = self._eval(1, x).reshape(self.n_rows, 6)  # mapped jacobians side by side: (1, 6N)
        rows = np.repeat(np.arange(self.n_rows), 6)
        cols = self.index.T.reshape(-1)
        keep = cols < self.n_dof
        return sp.csr_matrix((J.reshape(-1)[keep], (rows[keep], cols[keep])), shape=(self.n_rows, self.n_dof))

    def hessian(self, x, lam) -> sp.csc_matrix:
        """``sum_r lam_r Hessian(g_r)`` (2n, 2n), scipy CSC."""
        if not self.n_rows:
            return sp.csc_matrix((self.n_dof, self.n_dof))
        H = self._eval(2, x).reshape(6, self.n_rows, 6)  # (6, 6N) -> [i, row, j]
        H = np.transpose(H, (1, 0, 2)) * np.asarray(lam, dtype=float)[:, None, None]
        I = self.index.T  # (N, 6)
        r = np.repeat(I, 6, axis=1).reshape(-1)
        c = np.tile(I, (1, 6)).reshape(-1)
        keep = (r < self.n_dof) & (c < self.n_dof)
        return sp.csc_matrix((H.reshape(-1)[keep], (r[keep], c[keep])), shape=(self.n_dof, self.n_dof))

    def expr(self, x):
        """The gaps as a CasADi column of the MX ``x`` (2n)."""
        if not self.n_rows:
            return ca.MX(0, 1)
        z = ca.vertcat(x, ca.DM(self.consts.reshape(-1)))
        Z = ca.reshape(z[self.index.T.reshape(-1).tolist()], 6, self.n_rows)
        return ca.reshape(_functions()[0].map(self.n_rows)(Z, ca.DM(self.w.T)), self.n_rows, 1)

    def projections(self, x) -> np.ndarray:
        """The projection parameter ``t`` of each node-segment row's point on its segment (NaN for disks and
        lines)."""
        z = self._z(x).reshape(-1, 2)
        p, a, b = z[self.pts[:, 0]], z[self.pts[:, 1]], z[self.pts[:, 2]]
        d = b - a
        with np.errstate(all="ignore"):
            t = ((p - a) * d).sum(1) / (d * d).sum(1)
        return np.where(self.w[:, 0] > 0.5, np.nan, t)  # disks and lines: no end

    def node_forces(self, x, force) -> np.ndarray:
        """The contact forces on the body's nodes (n, 2) for row forces ``force`` (N,) ``>= 0``: each row's
        force times its gap's gradient."""
        f = self.jacobian(x).T @ np.asarray(force, dtype=float)
        return f.reshape(-1, 2)


def boundary_segments(mesh) -> tuple[np.ndarray, np.ndarray]:
    """``(segments (b, 2), pos (n, 3))``: the boundary segments with the body on their left and, per node,
    ``(loop id, position in the loop, loop length)``, -1 off the boundary (cached on the mesh)."""
    cached = mesh.__dict__.get("_contact_boundary")
    if cached is not None:
        return cached
    pos = np.full((mesh.n_nodes, 3), -1, dtype=np.int64)
    for k, loop in enumerate(mesh.boundary_loops):
        pos[loop, 0] = k
        pos[loop, 1] = np.arange(len(loop))
        pos[loop, 2] = len(loop)
    out = (np.asarray(mesh.boundary_edges, dtype=np.int64), pos)
    mesh.__dict__["_contact_boundary"] = out
    return out


def _near_along_boundary(pos, p, a, b, hops: int = 1) -> np.ndarray:
    """Whether node ``p`` is within ``hops`` boundary edges of ``a`` or ``b`` (same loop)."""
    out = np.zeros(len(p), dtype=bool)
    for q in (a, b):
        same = pos[p, 0] == pos[q, 0]
        L = pos[p, 2]
        dd = np.abs(pos[p, 1] - pos[q, 1])
        dd = np.minimum(dd, L - dd)
        out |= same & (dd <= hops)
    return out


def _inner_pairs(mesh, seg, pos) -> np.ndarray:
    """``(interior node, segment index)`` pairs: each interior node with the boundary segments whose end nodes
    are its neighbours (cached on the mesh)."""
    cached = mesh.__dict__.get("_contact_inner_pairs")
    if cached is not None:
        return cached
    nb = mesh.neighbors
    out = []
    for si, (a, b) in enumerate(seg.tolist()):
        for q in set(nb[a].tolist()) | set(nb[b].tolist()):
            if pos[q, 0] < 0:
                out.append((q, si))
    arr = np.array(sorted(set(out)), dtype=np.int64).reshape(-1, 2)
    mesh.__dict__["_contact_inner_pairs"] = arr
    return arr


#: the outside angle (degrees) at a boundary node below which it is a crease: its angle is kept positive
#: (and its interior neighbours inside the segments next to it)
FOLD_ANGLE = 150.0


def _loop_neighbours(seg, n) -> tuple[np.ndarray, np.ndarray]:
    """``(next, previous)`` boundary node of each node (-1 off the boundary)."""
    nxt = np.full(n, -1, dtype=np.int64)
    prv = np.full(n, -1, dtype=np.int64)
    nxt[seg[:, 0]] = seg[:, 1]
    prv[seg[:, 1]] = seg[:, 0]
    return nxt, prv


def _edge_scale(mesh, seg, pos) -> np.ndarray:
    """Per boundary node the mean rest length of its two boundary edges (the length an angle row is scaled
    by, so that its gap is a length like the others')."""
    P = mesh.points
    ln = np.hypot(*(P[seg[:, 1]] - P[seg[:, 0]]).T)
    out = np.zeros(len(pos))
    np.add.at(out, seg[:, 0], 0.5 * ln)
    np.add.at(out, seg[:, 1], 0.5 * ln)
    return out


def _outside_angle(x, seg, pos) -> np.ndarray:
    """Per node, the angle (radians, in ``[0, 2 pi)``) outside the body between its two boundary edges in the
    state ``x`` (``2 pi`` off the boundary)."""
    out = np.full(len(pos), 2 * np.pi)
    nxt = np.full(len(pos), -1, dtype=np.int64)
    prv = np.full(len(pos), -1, dtype=np.int64)
    nxt[seg[:, 0]] = seg[:, 1]
    prv[seg[:, 1]] = seg[:, 0]
    c = np.flatnonzero((nxt >= 0) & (prv >= 0))
    u, v = x[nxt[c]] - x[c], x[prv[c]] - x[c]
    inside = np.mod(np.arctan2(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0], (u * v).sum(1)), 2 * np.pi)
    out[c] = 2 * np.pi - inside
    return out


def _point_segment(p, a, b):
    """``(distance, t, signed line distance)`` of points ``p`` to segments ``(a, b)`` (body on the left)."""
    d = b - a
    dd = np.maximum((d * d).sum(1), 1e-300)
    t = ((p - a) * d).sum(1) / dd
    q = a + np.clip(t, 0, 1)[:, None] * d
    dist = np.hypot(*(p - q).T)
    g = (d[:, 1] * (p[:, 0] - a[:, 0]) - d[:, 0] * (p[:, 1] - a[:, 1])) / np.sqrt(dd)
    return dist, t, g


def disk_segments(disk, seg, x_ref, states, radius: float, tol: float = 0.0) -> np.ndarray:
    """The boundary segments ``seg`` ((b, 2) node pairs) that a disk's rows (kind 4) are made for: those
    within ``radius`` of the disk (the distance from its centre to the segment, less its radius) in any of
    ``states`` ((n, 2) each), with the centre on the segment's outer side (``n . (c - a) >= -tol``) in
    ``x_ref``."""
    c = np.asarray(disk.center, dtype=float)
    if not len(seg):
        return np.zeros(0, dtype=np.int64)
    close = np.zeros(len(seg), dtype=bool)
    for s in states:
        dist, _, _ = _point_segment(np.tile(c, (len(seg), 1)), s[seg[:, 0]], s[seg[:, 1]])
        close |= dist - disk.radius < radius
    _, _, g = _point_segment(np.tile(c, (len(seg), 1)), x_ref[seg[:, 0]], x_ref[seg[:, 1]])
    return np.flatnonzero(close & (g >= -tol))


def broad_phase(mesh, x_ref, states, radius: float, obstacles=(), self_contact: bool = True,
                tol: float = 0.0, release: float = 0.0) -> ContactRows:
    """Candidate rows: pairs that come within ``radius`` in any of ``states`` ((n, 2) each) and whose point
    lies on the outer side of the segment (``g >= -tol``) projecting within ``[-DELTA, 1 + DELTA]`` in ``x_ref``
    (a state without penetration: the start of the step).

    ``release``: the self-contact rows' release weight (:data:`RELEASE`; 0: held against the extended line).
    Self-contact pairs a boundary node with every boundary segment not its own (at a straight or convex
    boundary its neighbours project beyond the segment's ends and are left out; at a fold they are not);
    obstacles add their rows for boundary nodes (and a polygon's corners, a disk itself, against body segments:
    :func:`disk_segments`)."""
    from scipy.spatial import cKDTree  # on first use: a solve without contact never loads it

    xr = np.asarray(x_ref, dtype=float).reshape(-1, 2)
    states = [np.asarray(s, dtype=float).reshape(-1, 2) for s in states] or [xr]
    n = mesh.n_nodes
    seg, pos = boundary_segments(mesh)
    bnodes = np.flatnonzero(pos[:, 0] >= 0)
    pts, w, labels, consts = [], [], [], []
    seglen = max(float(max(np.hypot(*(s[seg[:, 1]] - s[seg[:, 0]]).T).max() for s in states)), 1e-300)

    def near_pairs(P):  # (point index, segment index) pairs within radius in some state
        found = []
        for s, Pt in zip(states, P):
            mid = cKDTree(0.5 * (s[seg[:, 0]] + s[seg[:, 1]]))
            M = cKDTree(Pt).sparse_distance_matrix(mid, radius + 0.5 * seglen, output_type="ndarray")
            if len(M):
                found.append(np.column_stack([M["i"], M["j"]]).astype(np.int64))
        if not found:
            return np.zeros((0, 2), dtype=np.int64)
        both = np.vstack(found)
        key = np.unique(both[:, 0] * len(seg) + both[:, 1])
        arr = np.column_stack([key // len(seg), key % len(seg)])
        keep = np.zeros(len(arr), dtype=bool)
        for s, Pt in zip(states, P):
            dist, _, _ = _point_segment(Pt[arr[:, 0]], s[seg[arr[:, 1], 0]], s[seg[arr[:, 1], 1]])
            keep |= dist < radius
        return arr[keep]

    if self_contact and len(bnodes):
        arr = near_pairs([s[bnodes] for s in states])
        if len(arr):
            p, a, b = bnodes[arr[:, 0]], seg[arr[:, 1], 0], seg[arr[:, 1], 1]
            ok = ~_near_along_boundary(pos, p, a, b, hops=0)
            _, t, g = _point_segment(xr[p], xr[a], xr[b])
            ok &= (g >= -tol) & (t >= -DELTA) & (t <= 1 + DELTA)
            for q, aa, bb in zip(p[ok], a[ok], b[ok]):
                pts.append((q, aa, bb))
                w.append((0.0, release))
                labels.append((0, -1))
        # creases: the outside angle at a boundary node kept positive where it folds (below FOLD_ANGLE) in some
        # state, or where it went through zero in one (from below 5 pi / 4 in the reference state to above
        # 3 pi / 2): a boundary folding at one node, its two edges closing onto each other
        nxt, prv = _loop_neighbours(seg, len(pos))
        ref = _outside_angle(xr, seg, pos)
        crease = np.zeros(len(pos), dtype=bool)
        for s_ in states:
            o = _outside_angle(s_, seg, pos)
            crease |= (o < np.radians(FOLD_ANGLE)) | ((o > 1.5 * np.pi) & (ref < 1.25 * np.pi))
        crease &= ref < 2 * np.pi
        h = _edge_scale(mesh, seg, pos)
        for c in np.flatnonzero(crease):
            pts.append((prv[c], c, nxt[c]))
            w.append((3.0, h[c]))
            labels.append((4, -1))
    if self_contact and len(seg):
        # the interior neighbours of a segment's end nodes stay inside it where the boundary folds (its outside
        # angle below FOLD_ANGLE): with every element upright, the triangles around a boundary node can still
        # fold over each other (a kink of a wrinkling side), an interior node passing out through a boundary
        # segment next to it
        inner = _inner_pairs(mesh, seg, pos)
        if len(inner):
            q, si = inner[:, 0], inner[:, 1]
            a, b = seg[si, 0], seg[si, 1]
            close = np.zeros(len(q), dtype=bool)
            for s in states:
                close |= _point_segment(s[q], s[a], s[b])[0] < radius
            _, t, g = _point_segment(xr[q], xr[a], xr[b])
            folded = _outside_angle(xr, seg, pos) < np.radians(FOLD_ANGLE)
            ok = close & (g <= tol) & (t >= -DELTA) & (t <= 1 + DELTA) & (folded[a] | folded[b])
            for qq, aa, bb in zip(q[ok], a[ok], b[ok]):
                pts.append((qq, bb, aa))  # the segment reversed: its inner side is the gap's positive side
                w.append((0.0, 0.0))
                labels.append((3, -1))
    for k, ob in enumerate(obstacles):
        gaps = [ob.gap(s[bnodes]) for s in states]
        close = np.zeros(len(bnodes), dtype=bool)
        for g in gaps:
            close |= g < radius
        for q in bnodes[close]:
            if ob.kind == "disk":
                consts.append(ob.center)
                consts.append(ob.center + np.array([1.0, 0.0]))
                c = n + len(consts) - 2
                pts.append((q, c, c + 1))
                w.append((1.0, ob.radius))
            else:
                E = ob.edges()
                if len(E) > 1:  # the edge of the largest gap in the reference state
                    E = E[[int(np.argmax(ob.edge_gaps(xr[[q]])[0]))]]
                consts.append(E[0, 0])
                consts.append(E[0, 1])
                c = n + len(consts) - 2
                pts.append((q, c, c + 1))
                w.append((2.0 if ob.kind == "half-plane" else 0.0, 0.0))
            labels.append((1, k))
        for si in disk_segments(ob, seg, xr, states, radius, tol) if ob.kind == "disk" else ():
            consts.append(ob.center)
            pts.append((n + len(consts) - 1, seg[si, 0], seg[si, 1]))
            w.append((4.0, ob.radius))
            labels.append((5, k))
        C = ob.corners()
        if len(C):
            arr = near_pairs([C for _ in states])
            if len(arr):
                _, t, g = _point_segment(C[arr[:, 0]], xr[seg[arr[:, 1], 0]], xr[seg[arr[:, 1], 1]])
                ok = (g >= -tol) & (t >= -DELTA) & (t <= 1 + DELTA)
                for ci, si in arr[ok]:
                    consts.append(C[ci])
                    pts.append((n + len(consts) - 1, seg[si, 0], seg[si, 1]))
                    w.append((0.0, 0.0))
                    labels.append((2, k))
    return ContactRows(np.array(pts, dtype=np.int64).reshape(-1, 3), n, np.array(consts).reshape(-1, 2),
                       np.array(w, dtype=float).reshape(-1, 2), np.array(labels, dtype=np.int64).reshape(-1, 2))


def _segments_meet(p, q, r, s) -> np.ndarray:
    """Whether segments ``(p, q)`` and ``(r, s)`` ((k, 2) each) have a point in common (closed segments)."""
    def orient(a, b, c):
        return np.sign((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    o1, o2, o3, o4 = orient(p, q, r), orient(p, q, s), orient(r, s, p), orient(r, s, q)
    return (o1 * o2 <= 0) & (o3 * o4 <= 0)


def first_touch_rows(mesh, x0, x1, tol: float = 0.0, bisections: int = 40, release: float = 0.0) -> ContactRows:
    """Self-contact rows for the crossings a solve made: for each pair of boundary segments that share no node
    and meet in ``x1`` ((n, 2)) but not in the admissible state ``x0``, the state of first touch along the
    straight path from ``x0`` to ``x1`` (bisection), and there the node-segment pair of the four (an end of
    one segment against the other) that is closest, on the segment's outer side (``g >= -tol``) and
    projecting within ``[-DELTA, 1 + DELTA]``.

    The broad phase admits a pair by its projection in the state a step starts from; a boundary that folds
    within one step (a crease forming on a straight side) brings together nodes that projected far beyond
    each other's segments there. The state of first touch is where such a pair is admissible."""
    from ..body.polygons import segment_contacts

    X0 = np.asarray(x0, dtype=float).reshape(-1, 2)
    X1 = np.asarray(x1, dtype=float).reshape(-1, 2)
    seg, _pos = boundary_segments(mesh)
    hit = segment_contacts(X1, seg)
    if len(hit):
        hit = hit[[not (set(seg[i].tolist()) & set(seg[j].tolist())) for i, j in hit]]
    empty = ContactRows(np.zeros((0, 3), dtype=np.int64), mesh.n_nodes)
    if not len(hit):
        return empty
    A, B = seg[hit[:, 0]], seg[hit[:, 1]]
    D = X1 - X0

    def meet(al):
        X = lambda k: X0[k] + al[:, None] * D[k]
        return _segments_meet(X(A[:, 0]), X(A[:, 1]), X(B[:, 0]), X(B[:, 1]))

    lo, hi = np.zeros(len(hit)), np.ones(len(hit))
    keep = ~meet(lo)
    lo, hi, A, B = lo[keep], hi[keep], A[keep], B[keep]
    for _ in range(bisections):
        mid = 0.5 * (lo + hi)
        m = meet(mid)
        hi = np.where(m, mid, hi)
        lo = np.where(m, lo, mid)
    pts = set()
    for k in range(len(A)):
        Xa = X0 + lo[k] * D
        best = None
        for p, (a, b) in ((A[k, 0], B[k]), (A[k, 1], B[k]), (B[k, 0], A[k]), (B[k, 1], A[k])):
            dist, t, g = _point_segment(Xa[[p]], Xa[[a]], Xa[[b]])
            if g[0] >= -tol and -DELTA <= t[0] <= 1 + DELTA and (best is None or dist[0] < best[0]):
                best = (dist[0], (int(p), int(a), int(b)))
        if best is not None:
            pts.add(best[1])
    if not pts:
        return empty
    P = np.array(sorted(pts), dtype=np.int64)
    return ContactRows(P, mesh.n_nodes, None, np.tile([0.0, release], (len(P), 1)), np.tile([0, -1], (len(P), 1)))


def handoff_rows(mesh, rows: ContactRows, which, t, x=None, release: float = 0.0) -> ContactRows:
    """Self-contact rows that take over from the rows ``which`` of ``rows`` whose point ``t`` (their
    projections) slid beyond an end of their segment: the point against the boundary segment next to that end
    (the one before ``a`` for ``t < 0``, after ``b`` for ``t > 1``), unless the point is one of its ends.
    Given the state ``x`` ((n, 2)), the walk along the boundary goes on past that segment, up to
    ``ceil(|t|) + 1`` segments (the point slid that many segment lengths), to the segment nearest the point
    there: the one its closest boundary point moved to."""
    seg, pos = boundary_segments(mesh)
    nxt, prv = _loop_neighbours(seg, len(pos))
    X = None if x is None else np.asarray(x, dtype=float).reshape(-1, 2)
    out = set()
    for i, ti in zip(np.asarray(which, dtype=np.int64).tolist(), np.asarray(t, dtype=float).tolist()):
        p, a, b = (int(v) for v in rows.pts[i])
        best = None
        hops = 1 if X is None else int(np.ceil(abs(ti if ti < 0 else ti - 1.0))) + 1
        for _ in range(hops):
            a, b = (int(prv[a]), a) if ti < 0 else (b, int(nxt[b]))
            if min(a, b) < 0 or p in (a, b):
                break
            d = 0.0 if X is None else float(_point_segment(X[[p]], X[[a]], X[[b]])[0][0])
            if best is None or d < best[0]:
                best = (d, (p, a, b))
        if best is not None:
            out.add(best[1])
    P = np.array(sorted(out), dtype=np.int64).reshape(-1, 3)
    return ContactRows(P, mesh.n_nodes, None, np.tile([0.0, release], (len(P), 1)), np.tile([0, -1], (len(P), 1)))
