"""Walking on a table: a gait's frames solved in sequence on the ground with quasi-static Coulomb friction.

The robot lies flat on a table and is seen from above. The table is under the whole body (out of plane), so
the normal forces are known without a contact solve: every node carries a share ``N_k`` of the body's weight
``W`` -- by its lumped area (a third of each triangle's area at each of its corners: a uniform sheet pressing
evenly on the table, the default), or, when ``feet`` are given, the feet alone carry it: a uniform pressure on
the area they cover, the triangles whose corners are all feet nodes (a body resting on its feet; the same area,
so the same loads, on a refinement that keeps the feet nodes and adds the midpoints between them). The table resists in-plane sliding by isotropic Coulomb friction:
a node sticks while its tangential force is below ``mu N_k`` and slips at it.

Each frame is one minimisation (a lagged, smoothed dissipation potential, the standard way to keep a quasi-static
friction step a minimisation): with ``x0`` the previous frame's state,

``min_x  E(x) + D(x)``,  ``D(x) = sum_k mu N_k (sqrt(|x_k - x0_k|^2 + eps^2) - eps)``,  ropes ``L_c(x) <= L0_c - s_c``

with ``E`` the body's elastic energy and ``s_c`` the frame's stroke of muscle ``c`` (the exact cable of
:func:`~mdsr_opt.solve_internal`). The body is free in the plane: no gauge, friction holds it. Since the normal
forces come from the weight, nothing is lagged but the reference ``x0``; a frame's slip path is taken as the
straight line from ``x0`` (``substeps`` splits each frame into that many solves for a curved path).

Errors of the model (``eps`` = :data:`EPS` times the body's size, 1e-6 by default): the friction force on a node
is ``mu N u / sqrt(u^2 + eps^2)`` with ``u = |x_k - x0_k|``, so a sticking node under a tangential force ``F``
creeps by ``eps (F/mu N) / sqrt(1 - (F/mu N)^2)`` per frame (below 2 eps for ``F < 0.9 mu N``) and a slipping
node feels ``mu N (1 - eps^2/(2 u^2))`` instead of ``mu N``. With ``mu = 0`` nothing holds the body: a frame
then moves it as little as it can, ``min sum_k N_k |x_k - x0_k|^2`` over rigid motions (``N_k`` the loads of
``feet``; a vanishing viscous drag; its mass centre stays put), and the displacement is that of a body on ice.
That rigid motion is placed exactly (weighted Procrustes, :func:`place_rigidly`), not left to the solve: the
small drag that keeps the NLP regular fixes it only to about the solve's tolerance divided by the drag, an error
the same in every cycle. The drag's own pull on the shape is then taken out by a second solve centred on the
placed state, so a reciprocal cycle with ``mu = 0`` returns the body to where it was to within the solve's
tolerance (and to round-off as ``tol`` goes to zero).

What walks: while friction is weak against the body's stiffness (``mu W << E t size``, as for a silicone robot on
a table) it only decides which way the body's rigid motion goes, the least dissipating one. With every node (or
the same feet) loaded in every frame, a reciprocal gait (out to a pose and back, as ``rest -> bend_left -> rest``)
goes nowhere: the way back undoes the way out. A gait walks when it lifts feet (``touching``: the inchworm, the
gecko's diagonal pairs) or when its strokes go round a loop of poses (a small drift).

:func:`walk` solves a stroke schedule (one cycle, repeated ``cycles`` times) and returns a :class:`WalkResult`:
the centroid's displacement and the rotation per cycle, and the nodes (and named feet) that slip in each frame.
:func:`walk_gait` takes the strokes of a :class:`~mdsr_opt.synthesis.gait.GaitSchedule`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ..body.mesh import Mesh
from ..body.muscles import check_distinct_ropes, check_muscles
from ..core.checks import as_float_array, friction_coefficient, positive_int
from ..core.guards import check_stop
from ..core.results import to_jsonable
from ..mechanics.align import align
from ..mechanics.anchors import check_anchor_radius
from ..mechanics.units import Units
from .walkframe import MAX_MOVE, FrameSolver

__all__ = ["GroundFriction", "WalkResult", "walk", "walk_gait", "walk_scene", "scene_schedule", "foot_groups",
           "node_loads", "rigid_motion", "place_rigidly", "schedule_cycle", "EPS", "SLIP"]

#: the smoothing length of the ground's friction potential, relative to the body's size
EPS = 1e-6
#: a node slips in a frame when its friction force reaches this fraction of ``mu N`` (``|u| >= 7.0 eps``)
SLIP = 0.99
#: the smoothing length a frame's solve starts from (relative to the size), continued down to :data:`EPS`
EPS_START = 1e-2
#: a failed solve is done again with a drag ``r/2 sum_k a_k |x_k - x0_k|^2`` on every node (``a_k`` its share of the
#: area; unit body), ``r`` relaxed along this path, then without it from there
DRAG_PATH = (1e-2, 1e-4, 1e-6)
#: a frame whose solve fails is split in halves at most this many times
MAX_SPLITS = 4
#: default weight of the body, a fraction of ``E t size`` (its stiffness times its size)
WEIGHT = 1e-3


def node_loads(mesh: Mesh, weight: float = 1.0, feet=None) -> np.ndarray:
    """The normal force on every node (n,): ``weight`` spread as a uniform pressure over the whole body or, with
    ``feet`` (node indices), over the area the feet cover: the triangles whose three corners are all feet nodes
    (0 elsewhere). Each triangle of the area gives a third of its share to each of its corners (the consistent
    load of a uniform pressure on linear triangles), so the loads do not depend on the mesh beyond the area: a
    refinement that keeps the feet nodes and adds the midpoints between them covers the same area. Every foot
    (connected piece of ``feet``, :func:`foot_groups`) must cover a triangle: a ``ValueError`` names one that
    does not, as it would carry no weight."""
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh must be a Mesh, got {type(mesh).__name__}")
    w = float(weight)
    if not (np.isfinite(w) and w >= 0):
        raise ValueError(f"weight must be a number >= 0, got {weight!r}")
    covered = np.ones(mesh.n_triangles, dtype=bool)
    if feet is not None:
        f = np.unique(np.asarray(feet, dtype=np.int64).reshape(-1))
        if not len(f) or f.min() < 0 or f.max() >= mesh.n_nodes:
            raise ValueError(f"feet must be node indices in [0, {mesh.n_nodes}), at least one, got {feet!r}")
        keep = np.zeros(mesh.n_nodes, dtype=bool)
        keep[f] = True
        covered = keep[mesh.triangles].all(1)
        if not covered.any():
            raise ValueError("feet cover no triangle of the mesh: a foot is an area of the body, give the nodes of "
                             "a triangle or more")
        for name, nodes in foot_groups(mesh, f).items():  # a foot covering no triangle would carry no weight
            one = np.zeros(mesh.n_nodes, dtype=bool)
            one[nodes] = True
            if not one[mesh.triangles].all(1).any():
                near = np.round(mesh.points[nodes].mean(0), 4).tolist()
                raise ValueError(f"feet: {name} ({len(nodes)} node(s) near {near}) covers no triangle of the mesh, "
                                 "so it would carry no weight: a foot is an area of the body, give the nodes of a "
                                 "triangle or more")
    share = np.zeros(mesh.n_nodes)
    np.add.at(share, mesh.triangles[covered].reshape(-1), np.repeat(mesh.areas[covered] / 3.0, 3))
    return w * share / share.sum()


def rigid_motion(X, Y, weights=None) -> tuple[np.ndarray, float]:
    """The weighted centroid's displacement (2,) and the best-fit rotation (radians, counter-clockwise) from
    the node positions ``X`` (n, 2) to ``Y`` (n, 2) (least squares, weights default equal)."""
    X, Y = np.asarray(X, float).reshape(-1, 2), np.asarray(Y, float).reshape(-1, 2)
    w = np.ones(len(X)) if weights is None else np.asarray(weights, float)
    w = w / w.sum()
    cx, cy = w @ X, w @ Y
    A, B = X - cx, Y - cy
    s = float((w * (A[:, 0] * B[:, 1] - A[:, 1] * B[:, 0])).sum())
    c = float((w * (A * B).sum(1)).sum())
    return cy - cx, float(np.arctan2(s, c))


class GroundFriction:
    """``D(x) = sum_k mu_k N_k (sqrt(|x_k - x0_k|^2 + eps^2) - eps)`` of the module docstring, isotropic in the
    plane, for all nodes (``x0`` (2n,), ``mu N`` (n,) per node, ``eps`` a length), with its gradient and Hessian.

    Example
    -------
    >>> import numpy as np
    >>> gf = GroundFriction(np.zeros(2), np.array([2.0]), 1e-3)
    >>> round(gf.energy(np.array([0.6, 0.8])), 4)      # slipping 1: about mu N |u|
    1.998
    >>> np.round(gf.gradient(np.array([0.6, 0.8])), 4).tolist()   # the force, mu N along the slip
    [1.2, 1.6]
    """

    def __init__(self, x0, muN, eps: float):
        self.x0 = np.asarray(x0, dtype=float).reshape(-1)
        self.muN = np.asarray(muN, dtype=float).reshape(-1)
        self.eps = float(eps)
        if len(self.x0) != 2 * len(self.muN):
            raise ValueError(f"x0 has {len(self.x0)} coordinates, mu N {len(self.muN)} nodes")

    def moves(self, x) -> np.ndarray:
        """Each node's displacement since ``x0`` (n, 2)."""
        return np.asarray(x, dtype=float).reshape(-1, 2) - self.x0.reshape(-1, 2)

    def energy(self, x) -> float:
        d = self.moves(x)
        return float((self.muN * (np.sqrt((d * d).sum(1) + self.eps ** 2) - self.eps)).sum())

    def forces(self, x) -> np.ndarray:
        """The friction force the table takes from each node (n, 2): ``mu N u / sqrt(|u|^2 + eps^2)``, the
        gradient of ``D`` (the node feels its opposite)."""
        d = self.moves(x)
        return (self.muN / np.sqrt((d * d).sum(1) + self.eps ** 2))[:, None] * d

    def gradient(self, x) -> np.ndarray:
        return self.forces(x).reshape(-1)

    def slipping(self, x, rtol: float = SLIP) -> np.ndarray:
        """Nodes whose friction force reaches ``rtol`` of ``mu N`` (n,) bool (never a node without load)."""
        f = np.hypot(*self.forces(x).T)
        return (self.muN > 0) & (f >= rtol * self.muN)

    def hessian(self, x) -> sp.csc_matrix:
        d = self.moves(x)
        r2 = (d * d).sum(1) + self.eps ** 2
        a = self.muN / np.sqrt(r2)
        b = self.muN / r2 ** 1.5
        n = len(self.muN)
        rows, cols, vals = [], [], []
        for i in range(2):
            for j in range(2):
                rows.append(2 * np.arange(n) + i)
                cols.append(2 * np.arange(n) + j)
                vals.append((a if i == j else 0.0) - b * d[:, i] * d[:, j])
        return sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                             shape=(2 * n, 2 * n))

    @staticmethod
    def expr(x, x0, muN, eps):
        """``D`` as a CasADi expression of ``x`` (2n) with the parameters ``x0`` (2n), ``muN`` (n), ``eps``."""
        d = x - x0
        return ca.dot(muN, ca.sqrt(d[0::2] ** 2 + d[1::2] ** 2 + eps ** 2) - eps)


@dataclass(eq=False)
class WalkResult:
    """The frames of a gait walked on the table.

    Attributes
    ----------
    states : (F, n, 2) ndarray
        Every frame's state in the table's frame; frame 0 is the rest shape where it starts.
    strokes : (F, m) ndarray
        The strokes solved.
    cycle_frames : int
        Frames per cycle (``states[c * cycle_frames]`` ends cycle ``c``).
    displacement : (cycles, 2) ndarray
        The displacement of the body's centre of area (nodes weighted by lumped area) in each cycle.
    rotation : (cycles,) ndarray
        The body's best-fit rotation in each cycle (radians, counter-clockwise).
    slipping : (F, n) bool ndarray
        The nodes that slip from the previous frame to this one (row 0: none).
    feet_slipping : dict
        Per named foot, (F,) bool: it touches the table and slides as a whole in that frame (the net friction
        force on it reaches :data:`SLIP` of its ``mu N``); a planted foot may still slip locally where it
        deforms (``slipping``).
    frame_success : (F,) bool ndarray
        Per frame, its solve succeeded.
    status : tuple of str
    mu, weight, eps : float
        The friction coefficient, the body's weight and the smoothing length (the mesh's units).
    loads : (F, n) ndarray
        The normal force on each node in each frame (zero where a foot is lifted).
    units : str
    centroids : (F, 2) ndarray
        The centre of area in each frame relative to the cycle's first frame (``states[1]``).
    turns : (F,) ndarray
        The best-fit rotation in each frame relative to ``states[1]`` (radians, unwrapped).
    unreached : tuple of str
        The poses of the walked schedule its layout never reached (:attr:`GaitSchedule.unreached
        <mdsr_opt.synthesis.gait.GaitSchedule.unreached>`; :func:`walk_gait`): the body walks, but not the gait
        that was asked for.
    success : bool (property)
        Every frame solved and every pose of the schedule reached.
    """

    states: np.ndarray
    strokes: np.ndarray
    cycle_frames: int
    displacement: np.ndarray
    rotation: np.ndarray
    slipping: np.ndarray
    feet_slipping: dict
    frame_success: np.ndarray
    status: tuple
    mu: float
    weight: float
    eps: float
    loads: np.ndarray
    units: str = "body units"
    centroids: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    turns: np.ndarray = field(default_factory=lambda: np.zeros(0))
    iterations: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    time: float = 0.0
    unreached: tuple = ()

    @property
    def cycles(self) -> int:
        return len(self.rotation)

    @property
    def success(self) -> bool:
        """Every frame solved and every pose of the schedule reached (``frame_success``, ``unreached``)."""
        return bool(np.all(self.frame_success)) and not self.unreached

    @property
    def distance(self) -> np.ndarray:
        """The distance the centroid covers in each cycle (cycles,)."""
        return np.hypot(*self.displacement.T)

    def __repr__(self) -> str:
        d = self.displacement.mean(0) if self.cycles else np.zeros(2)
        return (f"WalkResult({self.cycles} cycle(s) of {self.cycle_frames} frames, mu {self.mu:g}: per cycle "
                f"({d[0]:.4g}, {d[1]:.4g}) {self.units}, rotation {np.degrees(self.rotation.mean()):.3g} deg; "
                f"{int(self.frame_success.sum())}/{len(self.frame_success)} frames solved"
                + (f"; pose(s) {', '.join(self.unreached)} NOT reached by the layout" if self.unreached else "") + ")")

    def to_dict(self) -> dict:
        """Every field as JSON-ready values (arrays as nested lists, NaN as None); :meth:`summary` is the
        short form."""
        return {f: to_jsonable(getattr(self, f)) for f in self.__dataclass_fields__}

    def summary(self) -> dict:
        """JSON-ready figures: displacement and rotation per cycle, slipping per frame."""
        return {"mu": self.mu, "weight": self.weight, "eps": self.eps, "units": self.units,
                "cycles": self.cycles, "cycle_frames": self.cycle_frames,
                "displacement": self.displacement.tolist(), "distance": self.distance.tolist(),
                "rotation_deg": np.degrees(self.rotation).tolist(), "success": self.success,
                "unreached": list(self.unreached),
                "slipping_fraction": (self.slipping.sum(1) / self.slipping.shape[1]).tolist(),
                "feet_slipping": {k: v.astype(int).tolist() for k, v in self.feet_slipping.items()},
                "failed_frames": [int(k) for k in np.flatnonzero(~np.asarray(self.frame_success, bool))]}


def _eps_path(eps: float) -> list:
    """Smoothing lengths from :data:`EPS_START` of the size (the unit body's size is about 1) down to ``eps``,
    a factor 100 at a time."""
    out = [eps]
    while out[-1] * 100 < EPS_START:
        out.append(out[-1] * 100)
    return out[::-1] if len(out) > 1 else out


def place_rigidly(y, x0, weights) -> np.ndarray:
    """``y`` (2n,) moved rigidly to where ``sum_k w_k |y_k - x0_k|^2`` is least (weighted Procrustes, weights
    (n,): :func:`~mdsr_opt.mechanics.align.align`)."""
    Y, X0 = np.asarray(y, float).reshape(-1, 2), np.asarray(x0, float).reshape(-1, 2)
    return align(Y, X0, weights).apply(Y).reshape(-1)


def _frame(fs, x, s_from, s_to, substeps, un, muN, eps, rho, w, depth: int = 0, place=None):
    """One frame from state ``x`` at strokes ``s_from`` to ``s_to`` in ``substeps`` solves, each from the last
    (the friction's reference too); a failed solve is split in two halves, at most :data:`MAX_SPLITS` times.
    ``place`` (n,) weights, with ``mu = 0``: each solve's state is placed rigidly where it moves least from the
    last (:func:`place_rigidly`), then solved again with the drag centred there and placed again (the module
    docstring). Returns ``(x, success, status, iterations)``."""
    its = 0
    for j in range(1, substeps + 1):
        a = s_from + (s_to - s_from) * (j - 1) / substeps
        b = s_from + (s_to - s_from) * j / substeps
        x_new, ok, it = x, True, 0
        for e in _eps_path(eps):  # the smoothing length continued down to eps: Newton's path stays short
            x_new, ok, st, i = fs.solve(x_new, x, un.to_unit(b), muN, e, rho, w)
            it += i
        its += it
        if not ok:  # a drag on every node, relaxed to nothing: each solve starts from the last one's minimum
            x_new = x
            for r in DRAG_PATH:
                x_new, ok_r, st, i = fs.solve(x_new, x, un.to_unit(b), muN, eps, rho + r, w + np.repeat(fs.area, 2))
                its += i
                if not ok_r:
                    break
            if ok_r:
                x_new, ok, st, i = fs.solve(x_new, x, un.to_unit(b), muN, eps, rho, w)
                its += i
        if not ok and depth < MAX_SPLITS:
            x_new, ok, st, it = _frame(fs, x, a, b, 2, un, muN, eps, rho, w, depth + 1, place)
            its += it
        elif ok and place is not None:
            x_new = place_rigidly(x_new, x, place)
            fs.moved_to(x_new)
            x_c, ok_c, _, i = fs.solve(x_new, x_new, un.to_unit(b), muN, eps, rho, w)  # no pull left at its start
            its += i
            if ok_c:
                x_new = place_rigidly(x_c, x, place)
                fs.moved_to(x_new)
        if ok and np.abs(x_new - x).max() > MAX_MOVE * fs.size:
            ok, st = False, (f"the body flew off (a node moved more than {MAX_MOVE:g} times the body's size in one "
                             "solve)")
        if not ok:
            return x, False, st, its
        x = x_new
    return x, True, "Solve_Succeeded", its


def _strokes(strokes, m: int) -> np.ndarray:
    S = as_float_array(strokes, "strokes")  # strings, bools, None: TypeError, never coerced
    if S.ndim != 2 or S.shape[1] != m or S.shape[0] < 1:
        raise ValueError(f"strokes must be an (F, {m}) array: one row per frame of the cycle, one column per "
                         f"muscle, got shape {S.shape}")
    if not np.isfinite(S).all():
        raise ValueError("strokes must be finite")
    return S


def walk(mesh: Mesh, material, muscles: Sequence, strokes, *, mu: float = 0.5, cycles: int = 2,
         weight: float | None = None, feet=None, feet_groups: Mapping | None = None, touching=None,
         substeps: int = 1,
         anchor_radius: float | None = None, tol: float = 1e-8, max_iter: int = 300, options: dict | None = None,
         units: str = "body units", start=None) -> WalkResult:
    """Walk a cyclic stroke schedule on the table with Coulomb friction (the module docstring's model).

    Parameters
    ----------
    mesh, material : the body.
    muscles : list of :class:`~mdsr_opt.Muscle` (ropes, the exact cable of :func:`~mdsr_opt.solve_internal`).
    strokes : (F, m) array
        One cycle: the length each muscle's rope is pulled in, per frame (negative: paid out). The cycle is
        closed by its first frame and repeated ``cycles`` times; the walk starts at rest, and at the first frame.
    mu : float >= 0
        Coulomb's coefficient between body and table.
    cycles : int >= 1
    weight : float, optional
        The body's weight on the table (force units of ``material``); default :data:`WEIGHT` x ``E t size``.
        With ``mu`` it sets the friction forces (their ratio to the elastic forces); without slip of the whole
        body nothing else depends on it.
    feet : node indices, optional
        The nodes that touch the table: the weight spread evenly over the triangles they cover (all three
        corners feet nodes; :func:`node_loads`); default all nodes.
    feet_groups : mapping name -> node indices, optional
        Named feet whose slipping is reported per frame (``WalkResult.feet_slipping``).
    touching : (F, G) bool array, optional
        Per frame of the cycle (the ``F`` rows of ``strokes``), which of the ``G`` ``feet_groups`` (in their
        order) touch the table: in that
        frame the weight rests on those feet alone (evenly over the area they cover) and the others are
        lifted (no friction). This is how a gait anchors one end and then the other (an inchworm). Default: the
        contact given by ``feet`` in every frame.
    substeps : int >= 1
        Solves per frame (strokes interpolated linearly), the friction's reference moved each time.
    anchor_radius : as in :func:`~mdsr_opt.solve_internal`.
    tol, max_iter, options : IPOPT's tolerance contract, iterations and options per solve.
    units : the mesh's length unit (reported; default "body units": none is invented).
    start : (n, 2) array, optional
        The state the walk starts from: the body in the cycle's first frame (e.g. solved by
        :func:`~mdsr_opt.solve_internal`), first settled into this model off the table (ropes and anchor
        patches as here, a vanishing drag holding it in place); default the rest shape (strokes zero).

    Returns
    -------
    WalkResult
        ``F * cycles + 2`` states (the start, then every frame). A frame whose solve fails (after splitting it
        in halves, :data:`MAX_SPLITS` times at most) is reported in ``success`` and ``status``; it keeps its
        start state and the walk goes on from there (its displacement then counts nothing for that frame).
    """
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh must be a Mesh, got {type(mesh).__name__}")
    mus = check_muscles(mesh, muscles)
    if not mus:
        raise ValueError("walking needs at least one muscle")
    check_distinct_ropes(mus)
    S = _strokes(strokes, len(mus))
    mu = friction_coefficient(mu, "mu")
    cycles, substeps = positive_int(cycles, "cycles"), positive_int(substeps, "substeps")
    radius = check_anchor_radius(mesh, anchor_radius)
    L0 = np.array([m.length(mesh.points) for m in mus])
    if (S >= L0).any():
        raise ValueError("a stroke must be shorter than its muscle's rest length")
    un = Units(mesh, material)
    W = WEIGHT * un.force if weight is None else float(weight)
    loads = node_loads(mesh, W, feet)
    groups = {str(k): np.asarray(v, dtype=np.int64).reshape(-1) for k, v in dict(feet_groups or {}).items()}
    for k, v in groups.items():
        if not len(v) or v.min() < 0 or v.max() >= mesh.n_nodes:
            raise ValueError(f"foot {k!r}: node indices must be in [0, {mesh.n_nodes}), at least one")
        inside = np.zeros(mesh.n_nodes, dtype=bool)
        inside[v] = True
        if touching is not None and not inside[mesh.triangles].all(1).any():
            raise ValueError(f"foot {k!r} covers no triangle of the mesh: a foot that carries weight is an area of "
                             "the body, give the nodes of a triangle or more")
    F = len(S)
    if touching is None:
        frame_loads = np.tile(loads, (F, 1))
    else:
        T = np.asarray(touching)
        if T.shape != (F, len(groups)) or T.dtype != bool:
            raise ValueError(f"touching must be an ({F}, {len(groups)}) bool array: a row per frame of the cycle "
                             f"(the {F} rows of strokes, WalkResult.cycle_frames; a gait schedule's closing frame, "
                             f"which repeats its first, is not one), a column per foot of feet_groups, got shape "
                             f"{T.shape} of {T.dtype}")
        if not T.any(1).all():
            raise ValueError(f"touching: frame(s) {np.flatnonzero(~T.any(1)).tolist()} touch the table with no foot")
        names = list(groups)
        frame_loads = np.array([node_loads(mesh, W, np.concatenate([groups[names[g]] for g in np.flatnonzero(row)]))
                                for row in T])
    X = mesh.points if start is None else np.asarray(start, dtype=float).reshape(mesh.n_nodes, 2)
    t0 = time.perf_counter()
    fs = FrameSolver(un.unit_mesh, un.unit_material, mus, un.to_unit(radius), tol, max_iter, options)
    muN_of = float(mu) * np.vstack([np.tile(frame_loads, (cycles, 1)), frame_loads[:1]]) / un.force
    eps = EPS * un.unit_mesh.size
    rho = 0.0 if mu > 0 else 1.0  # with mu = 0 the vanishing drag of the docstring (weights: the loads)
    place = node_loads(mesh, 1.0, feet) if mu == 0 else None  # the drag's weights; its limit placed exactly
    wdrag = np.repeat(place, 2) * 1e-6 if mu == 0 else np.zeros(2 * mesh.n_nodes)
    full = np.vstack([np.tile(S, (cycles, 1)), S[:1]])
    states, ok, status, its = [X.copy()], [True], ["start"], [0]
    slip = [np.zeros(mesh.n_nodes, dtype=bool)]
    x = un.to_unit(X).reshape(-1)
    if start is not None:  # settle the given state into this model (its ropes and patches) off the table
        area = node_loads(mesh, 1.0)
        x_s, ok_s, st_s, _ = fs.solve(x, x, un.to_unit(S[0]), np.zeros(mesh.n_nodes), eps, 1.0,
                                      np.repeat(area, 2) * 1e-6)
        if not ok_s:
            raise ValueError(f"start: the body in the cycle's first frame does not solve ({st_s})")
        x = place_rigidly(x_s, x, area)  # the drag's limit: where the given state is, not where tol left it
        fs.moved_to(x)
        states[0] = x.reshape(-1, 2) * un.length
    prev_s = np.zeros(len(mus)) if start is None else S[0].copy()
    for k in range(len(full)):
        check_stop()
        frame_start = x.copy()
        x, good, msg, itk = _frame(fs, x, prev_s, full[k], substeps, un, muN_of[k], eps, rho, wdrag, place=place)
        prev_s = full[k]
        gf = GroundFriction(frame_start, muN_of[k], eps)
        slip.append(gf.slipping(x) if mu > 0 else np.ones(mesh.n_nodes, dtype=bool))
        states.append(x.reshape(-1, 2) * un.length)
        ok.append(good)
        status.append(msg)
        its.append(itk)
    states = np.array(states)
    strokes_all = np.vstack([np.zeros(len(mus)), full])
    area = node_loads(mesh, 1.0)  # the body's centre of area and best-fit rotation, whatever touches
    track = [rigid_motion(states[1], y, area) for y in states]
    centroids = np.array([d for d, _ in track])
    turns = np.unwrap(np.array([r for _, r in track]))
    ends = 1 + F * np.arange(cycles + 1)
    disp, rot = np.diff(centroids[ends], axis=0), np.diff(turns[ends])
    slip = np.array(slip)
    loads_all = np.vstack([frame_loads[:1], np.tile(frame_loads, (cycles, 1)), frame_loads[:1]])
    feet_slip = {k: np.zeros(len(states), dtype=bool) for k in groups}
    for i in range(1, len(states)):  # a foot slips as a whole when its net friction force reaches SLIP mu N
        f = GroundFriction(states[i - 1].reshape(-1), float(mu) * loads_all[i], EPS * mesh.size).forces(states[i])
        for k, v in groups.items():
            cap = float(mu) * loads_all[i, v].sum()
            feet_slip[k][i] = cap > 0 and np.hypot(*f[v].sum(0)) >= SLIP * cap
    return WalkResult(states=states, strokes=strokes_all, cycle_frames=F, displacement=disp,
                      rotation=rot, centroids=centroids, turns=turns, slipping=slip, feet_slipping=feet_slip, frame_success=np.array(ok),
                      status=tuple(status), mu=float(mu), weight=W, eps=EPS * mesh.size, loads=loads_all, units=units,
                      iterations=np.array(its), time=time.perf_counter() - t0)


def schedule_cycle(schedule, touching=None) -> tuple:
    """One cycle of a :class:`~mdsr_opt.synthesis.gait.GaitSchedule`: its strokes (F, m) without the closing
    frame, which repeats the first in a cyclic gait, and ``touching`` fitted to them: ``(strokes, touching)``.
    ``touching`` may have a row per frame of the cycle, or a row per frame of the schedule, closing frame
    too: then its last row must repeat its first (a ``ValueError`` says so) and is dropped with it."""
    S = np.asarray(schedule.strokes, dtype=float)
    if len(S) > 1 and np.allclose(S[0], S[-1]):
        S = S[:-1]
        if touching is not None and np.ndim(touching) == 2 and len(touching) == len(S) + 1:
            T = np.asarray(touching)
            if not np.array_equal(T[0], T[-1]):
                raise ValueError(f"touching has {len(T)} rows, the schedule's frames with the closing one, which "
                                 f"repeats the first: its last row must repeat its first row too (it differs), "
                                 f"or give the {len(S)} rows of one cycle without the closing frame "
                                 "(WalkResult.cycle_frames)")
            touching = T[:-1]
    return S, touching


def walk_gait(mesh: Mesh, material, schedule, muscles: Sequence, **kwargs) -> WalkResult:
    """:func:`walk` with the strokes of a :class:`~mdsr_opt.synthesis.gait.GaitSchedule` (its last frame, which
    repeats the first in a cyclic gait, dropped: :func:`schedule_cycle`, which fits ``touching`` to them too)
    on the muscles of its layout, starting from its first frame's state (placed on the table as it is);
    ``kwargs`` as in :func:`walk`."""
    S, touching = schedule_cycle(schedule, kwargs.get("touching"))
    if touching is not None:
        kwargs["touching"] = touching
    kwargs.setdefault("units", schedule.units)
    if kwargs.get("start") is None and bool(schedule.frame_success[0]):
        kwargs["start"] = schedule.states[0]  # the first pose, solved without the table: its first frame stays
    res = walk(mesh, material, muscles, S, **kwargs)
    res.unreached = tuple(schedule.unreached)  # the gait asked for, not walked: no success
    return res


def foot_groups(mesh: Mesh, nodes) -> dict:
    """The connected pieces (along mesh edges) of a node set, as named feet ``{"foot 1": nodes, ...}``, numbered
    by their centres from left to right (then bottom to top)."""
    from scipy.sparse.csgraph import connected_components

    v = np.unique(np.asarray(nodes, dtype=np.int64).reshape(-1))
    if not len(v) or v.min() < 0 or v.max() >= mesh.n_nodes:
        raise ValueError(f"feet must be node indices in [0, {mesh.n_nodes}), at least one")
    E = np.asarray(mesh.edges, dtype=np.int64)
    inside = np.zeros(mesh.n_nodes, dtype=bool)
    inside[v] = True
    E = E[inside[E].all(1)]
    pos = np.full(mesh.n_nodes, -1)
    pos[v] = np.arange(len(v))
    A = sp.coo_matrix((np.ones(len(E)), (pos[E[:, 0]], pos[E[:, 1]])), shape=(len(v), len(v)))
    k, lab = connected_components(A, directed=False)
    parts = [v[lab == i] for i in range(k)]
    parts.sort(key=lambda g: tuple(np.round(mesh.points[g].mean(0), 9)))
    return {f"foot {i + 1}": g for i, g in enumerate(parts)}


def scene_schedule(scene, layout, *, sequence=None, frames_per_step: int | None = None,
                   feet: str | None = "all") -> tuple:
    """The schedule of ``layout`` for ``scene``'s gait (:func:`~mdsr_opt.synthesis.gait.gait_schedule`;
    ``sequence`` and ``frames_per_step`` default to the scene's ``[gait]``) and the scene's ``"feet"`` region
    (None when it names none): ``(schedule, region)``. ``feet`` (``"all"`` or ``"region"``, which needs that
    region) is checked here, before the schedule is solved."""
    from .gait import gait_schedule

    gait = getattr(scene, "gait", None)
    if gait is None and (sequence is None or frames_per_step is None):
        raise ValueError(f"scene {getattr(scene, 'name', '?')!r} has no [gait]: give sequence and frames_per_step")
    if feet not in ("all", "region"):
        raise ValueError(f"feet must be 'all' or 'region', got {feet!r}")
    region = dict(getattr(scene, "regions", {}) or {}).get("feet")
    if feet == "region" and region is None:
        raise ValueError(f"scene {scene.name!r} names no 'feet' region")
    seq = list(gait.sequence if sequence is None else sequence)
    fps = gait.frames_per_step if frames_per_step is None else frames_per_step
    return gait_schedule(scene.mesh, scene.material, layout, seq, frames_per_step=fps, units=scene.units), region


def walk_scene(scene, layout, *, sequence=None, frames_per_step: int | None = None, feet: str | None = "all",
               **kwargs) -> tuple:
    """A scene's gait walked on the table: the schedule of ``layout`` (a
    :class:`~mdsr_opt.synthesis.poses_result.PosesResult` laid for the scene's gait, e.g. ``layout.json`` of
    ``mdsr run``) solved by :func:`~mdsr_opt.synthesis.gait.gait_schedule`, then :func:`walk_gait`.

    ``feet="all"`` (default): the weight on every node by lumped area (a sheet lying flat); ``feet="region"``:
    on the scene's ``"feet"`` region alone; either way the pieces of that region are the named feet whose
    slipping is reported (:func:`foot_groups`). ``sequence`` and ``frames_per_step`` default to the scene's
    ``[gait]``; ``kwargs`` go to :func:`walk` (``mu``, ``cycles``, ``touching``...). Returns
    ``(schedule, WalkResult)``."""
    sch, region = scene_schedule(scene, layout, sequence=sequence, frames_per_step=frames_per_step, feet=feet)
    if region is not None:
        kwargs.setdefault("feet_groups", foot_groups(scene.mesh, region))
    if feet == "region":
        kwargs.setdefault("feet", region)
    kwargs.setdefault("anchor_radius", layout.anchor_radius)
    return sch, walk_gait(scene.mesh, scene.material, sch, layout.muscles, **kwargs)
