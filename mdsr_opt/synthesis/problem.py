"""The data a design shares between its methods: the design problem and its forward solver."""

from __future__ import annotations

import numbers
import time
import casadi as ca
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..body.checks import check_target_shape
from ..body.muscles import Muscle, check_distinct_ropes, check_muscles
from ..core.checks import as_float_array, positive_float
from ..mechanics.align import align, node_weights
from ..mechanics.anchors import anchor_radius_or_default
from ..mechanics.constraints import muscle_constraints, segment_spring_parameters, spring_segments, spring_stiffness
from ..mechanics.align import Alignment
from ..mechanics.equilibrium import gauge_coordinates, held_coordinates, in_gauge_frame, in_held_frame, solve_internal
from ..mechanics.loadsteps import STEP_ITER_CAP, check_mesh_material, upright
from ..mechanics.constrained import ConstrainedModel
from ..mechanics.kkt import least_squares_multipliers
from ..mechanics.model import get_model, to_dm
from ..mechanics.ropesolve import projected_energy_hessian
from ..mechanics.residual import kkt_residual, meet_tolerance


# ---------------------------------------------------------------------------------------------- the problem
class DesignProblem:
    """Everything the three methods share: model, affine parameters ``p(a) = p0 + B a``, the muscle
    constraints (rope lengths for the cable, rigid end patches for both models), gauge, weights, scales.

    ``held`` (checked node indices, :func:`~mdsr_opt.mechanics.equilibrium.check_held`, or None): the body is
    clamped at these nodes, at rest, as a robot mounted on its base; its pose is then no longer free, so the
    target is moved rigidly onto the held nodes' rest positions once (:func:`in_held_frame`; the identity for a
    target solved with those nodes anchored) and states are compared with it where they are, without a rigid
    alignment (:meth:`objective`): a design whose tip is off by a turn about the mount is off."""

    def __init__(self, mesh, material, muscles, target, weights, muscle_model, stiffness, a_max,
                 anchor_radius=None, fixture_wall=None, held=None):
        self.mesh, self.material, self.muscles = mesh, material, muscles
        self.held = None if held is None else np.asarray(held, dtype=np.int64)
        self.y = target if held is None else in_held_frame(mesh, target, self.held)
        self.w = weights
        self.muscle_model = muscle_model
        self.stiffness = stiffness
        self.a_max = a_max
        self.m = len(muscles)
        t0 = time.perf_counter()
        # the exact cable is a constraint, not an energy: the energy model is the body's (plus the
        # per-segment springs of the "springs" model, zero for the cable)
        self.model = get_model(mesh, material)
        self.anchor_radius = anchor_radius_or_default(mesh, anchor_radius)  # checked by the callers, at their doors
        self.constraints = muscle_constraints(mesh, muscles, self.anchor_radius, self.held)
        self.build_time = time.perf_counter() - t0
        self.L0 = np.asarray(self.constraints.rest_lengths, dtype=float)

        def params(a):  # the same parameters solve_internal builds (springs: stiffness per unit rest length)
            if muscle_model == "springs":
                return self.model.params(material, springs=segment_spring_parameters(
                    mesh, material, muscles, a, stiffness, self.anchor_radius))
            return self.model.params(material)

        self.p0 = params(np.zeros(self.m))
        # p is affine in a (springs: r_e = 1 - stiffness-weighted mean contraction; the cable: constant)
        self.B = np.column_stack([params(np.eye(self.m)[c]) - self.p0 for c in range(self.m)])
        self.fixed = held_coordinates(mesh, self.held, muscles, self.anchor_radius)
        # the fixed coordinates: the three gauge coordinates (in their order), or the held nodes'
        self.gauge = list(gauge_coordinates(mesh)) if held is None else list(np.flatnonzero(self.fixed))
        self.free = ~self.fixed
        #: the wall between a rope's two end fixtures the design keeps (None: not kept), see
        #: :func:`fixture_caps`
        self.fixture_wall = fixture_wall
        #: per muscle the largest contraction the design may give: ``a_max``, or less where the end patches
        #: hold most of the rope (:func:`contraction_caps`) or its end fixtures would meet (:func:`fixture_caps`)
        self.a_upper = contraction_caps(mesh, material, muscles, stiffness, self.anchor_radius, a_max,
                                        target)
        if fixture_wall is not None:
            self.a_upper = np.minimum(self.a_upper, fixture_caps(mesh.points, muscles, self.anchor_radius,
                                                                 fixture_wall))
        self.X = mesh.points.reshape(-1).copy()
        self.h = float(mesh.edge_lengths.mean())
        self.Et = material.E * material.thickness
        self.W = float(weights.sum())
        #: the flattened NLP leaves the state's rigid pose free when the energy does not change under rigid
        #: motion (see :mod:`~mdsr_opt.synthesis.nlp`); else it pins the gauge and aligns the state with an
        #: explicit rotation and translation (``nv = 3`` variables)
        self.free_pose = bool(getattr(material, "rotation_invariant", False))
        self.nv = 0 if self.free_pose else 3
        self._block = None

    @property
    def block(self) -> "_ConstraintBlock":
        """The muscle constraints as one sparse SX block (built on first use)."""
        if self._block is None:
            t0 = time.perf_counter()
            self._block = _ConstraintBlock(self)
            self.build_time += time.perf_counter() - t0
        return self._block

    def params(self, a) -> np.ndarray:
        return self.p0 + self.B @ np.asarray(a, dtype=float)

    def objective(self, x2):
        """Scaled objective ``D / (sum e h^2)`` of a state (n, 2), its alignment, and ``dJ/dx`` (2n,)."""
        al = self.alignment(x2)
        r = x2 @ al.R.T + al.t - self.y
        J = float((self.w * (r ** 2).sum(1)).sum()) / (self.W * self.h ** 2)
        dJ = (2.0 / (self.W * self.h ** 2)) * (self.w[:, None] * (r @ al.R))  # envelope theorem: R, t optimal
        return J, al, dJ.reshape(-1)

    def alignment(self, x2) -> Alignment:
        """The best rigid alignment of a state (n, 2) onto the target (weighted), or with ``held`` nodes the
        identity with the weighted RMS distance where the state is (the held nodes fix the pose)."""
        if self.held is None:
            return align(x2, self.y, self.w)
        r = np.asarray(x2, dtype=float) - self.y
        return Alignment(np.eye(2), np.zeros(2), float(np.sqrt((self.w * (r ** 2).sum(1)).sum() / self.W)))

    def in_frame(self, x2) -> np.ndarray | None:
        """A state (n, 2) in any pose moved rigidly into the forward solver's frame: the gauge frame of a
        free body (:func:`in_gauge_frame`; None when no rotation does it), or onto the held nodes' rest
        positions (:func:`in_held_frame`)."""
        if self.held is None:
            return in_gauge_frame(self.mesh, x2)
        return in_held_frame(self.mesh, x2, self.held)

    def dg_da(self, xflat) -> np.ndarray:
        """``dg/da`` (2n, m): exact columns since the gradient is affine in ``p`` and ``p`` is affine in ``a``."""
        g0 = self.model.gradient(xflat, self.p0)
        return np.column_stack([self.model.gradient(xflat, self.p0 + self.B[:, c]) - g0 for c in range(self.m)])

    def kkt_data(self, a, xflat):
        """What a stability check of the driven state ``xflat`` at contractions ``a`` needs, all in units of
        ``E t h`` (the NLP's scaling): ``(H, free, A, kappa, residual)`` with ``H`` the Hessian of the
        Lagrangian ``E + kappa . C`` (scipy, (2n, 2n)), ``free`` the non-gauge dofs, ``A`` the Jacobian of
        the active muscle constraints (anchor patches, taut ropes; None without constraints), ``kappa``
        the least-squares multipliers and ``residual`` the max-norm of the Lagrangian's free gradient."""
        xflat = np.asarray(xflat, dtype=float).reshape(-1)
        kap, J, res = self.stationarity(a, xflat)
        H = self.model.hessian(xflat, self.params(a)) / (self.Et * self.h)
        blk = self.block
        if not blk.nc:
            return H.tocsc(), self.free.copy(), None, kap, res
        act = np.ones(blk.nc, dtype=bool)
        if blk.rope:  # a slack rope (no tension) constrains nothing
            act[:self.m] = kap[:self.m] > 1e-9 * max(1.0, float(np.abs(kap).max()))
        return (H + blk.hessian(xflat, kap)).tocsc(), self.free.copy(), J[np.nonzero(act)[0]], kap, res

    def stationarity(self, a, xflat) -> tuple[np.ndarray, sp.csr_matrix | None, float]:
        """``(kappa, J, residual)`` of the driven state ``xflat`` at contractions ``a`` in units of ``E t h``:
        the least-squares multipliers of the muscle constraints, their Jacobian (None without constraints)
        and the max-norm of the Lagrangian's free gradient (:meth:`kkt_data` without the Hessian)."""
        xflat = np.asarray(xflat, dtype=float).reshape(-1)
        g = self.model.gradient(xflat, self.params(a)) / (self.Et * self.h)
        blk = self.block
        if not blk.nc:
            return np.zeros(0), None, float(np.abs(g[self.free]).max())
        kap = blk.multipliers(xflat, g, self.free)
        J = blk.jacobian(xflat)
        return kap, J, float(np.abs((g + J.T @ kap)[self.free]).max())

    def _contract(self, a):
        """``(model, p)`` of the tolerance contract at contractions ``a``: the energy model or, with muscle
        constraints, a :class:`~mdsr_opt.mechanics.constrained.ConstrainedModel` with the rope targets."""
        cable = self.muscle_model == "cable"
        if not cable and not self.constraints.n_rigid:
            return self.model, self.params(a)
        cm = self.__dict__.get("_constrained")
        if cm is None:
            cm = self.__dict__["_constrained"] = ConstrainedModel(self.model, self.constraints, cable)
        return cm, cm.params(self.params(a), (1.0 - np.asarray(a, dtype=float)) * self.L0 if cable else None)

    def polished(self, a, xflat, tol: float) -> np.ndarray:
        """The driven state ``xflat`` at contractions ``a`` in the solver's gauge frame, polished by Newton
        steps on the KKT system when its scaled KKT residual is above ``tol``
        (:func:`~mdsr_opt.mechanics.residual.meet_tolerance`): the design NLP meets its equilibrium rows to
        its own tolerance and scaling, the verification asks the forward solver's measure."""
        xflat = np.asarray(xflat, dtype=float).reshape(-1)
        moved = self.in_frame(xflat.reshape(-1, 2))
        if moved is None:
            return xflat
        model, p = self._contract(a)
        return meet_tolerance(model, moved.reshape(-1), p, self.fixed, tol, self.Et * self.mesh.size,
                              upright=lambda y: upright(self.mesh, y))[0]

    def kkt_residual(self, a, xflat, tol: float) -> float:
        """The scaled KKT residual of the driven state ``xflat`` at contractions ``a``, as
        :func:`~mdsr_opt.solve_internal` accepts its states at ``tol``
        (:func:`~mdsr_opt.mechanics.residual.kkt_residual`: the Lagrangian's free gradient over ``E t size``,
        ropes pulling only within ``tol L0`` of their targets, and the constraints' violation), evaluated
        in the solver's gauge frame (:func:`~mdsr_opt.mechanics.equilibrium.in_gauge_frame`: a state aligned
        to rest is checked where the solver had it)."""
        xflat = np.asarray(xflat, dtype=float).reshape(-1)
        moved = self.in_frame(xflat.reshape(-1, 2))
        if moved is not None:
            xflat = moved.reshape(-1)
        model, p = self._contract(a)
        return kkt_residual(model, xflat, p, self.fixed, tol, self.Et * self.mesh.size).value

    def achieved(self, x2) -> np.ndarray:
        """Achieved contraction ``1 - L / L0`` of every muscle along its node chain in state ``x2``."""
        return 1.0 - np.array([mu.length(x2) for mu in self.muscles]) / self.L0

    def tensions(self, a, xflat) -> np.ndarray:
        """Per muscle pulling force in state ``xflat`` (force units, ``E t`` times a length).

        The cable: the rope's tension, the multiplier of its length constraint, recovered from the
        equilibrium by least squares (:meth:`_ConstraintBlock.multipliers`). Springs: the mean force of
        the muscle's free segment springs, ``K a' (a - achieved)`` as :func:`~mdsr_opt.solve_internal`
        reports it (positive when they pull)."""
        if self.muscle_model == "cable":
            g = self.model.gradient(xflat, self.params(a)) / (self.Et * self.h)
            kap = self.block.multipliers(xflat, g, self.free)
            return self.block.tension(kap)
        x2 = np.asarray(xflat, dtype=float).reshape(-1, 2)
        K = spring_stiffness(self.mesh, self.material, self.stiffness)
        _ks, a_fac = spring_segments(self.mesh, self.material, self.muscles, self.stiffness, self.anchor_radius)
        return K * a_fac * (np.asarray(a, dtype=float) - self.achieved(x2))


#: the largest share of its free length (the part outside its two end patches) by which a design may shorten
#: a rope when ``a_max`` is smaller: a contraction ``a`` of a rope whose patches hold the share ``1 - 1/f``
#: of its rest length shortens the free part by ``a f``, and at ``a f -> 1`` the free part and the silicone
#: around it are crushed to nothing. Without a cap a short rope between two patches (0.41 long, patches of
#: radius 0.165: ``f = 4.3``) drove the flattened design of a 4 x 1 strip at 4.3k nodes through iterates
#: that inverted elements (500 IPOPT iterations, no convergence), and at 8k nodes to ``a f = 0.94``.
FREE_SHORTENING_MAX = 0.6
#: where the target shortens a rope's free part further, the share of what the target leaves of it that the
#: design must keep (:func:`contraction_caps`), and the share of its rest length it keeps in any case
TARGET_FREE_SHARE = 0.9
FREE_REMAINDER_MIN = 0.1


def contraction_caps(mesh, material, muscles, stiffness, anchor_radius, a_max, target=None) -> np.ndarray:
    """Per muscle the upper bound of its contraction in a design, ``min(a_max, (1 - r) / f)``: no rope's free
    part keeps less than the share ``r`` of its rest length, ``f = L0 / L0_free`` the rope's rest length over
    its length outside its end patches (:func:`~mdsr_opt.mechanics.constraints.spring_segments`).
    ``r = 1 - max(a_max, FREE_SHORTENING_MAX)``, so a rope without patch segments (``f = 1``) keeps
    ``a_max``. Where the ``target`` shape itself shortens a rope's path further (it contracts by
    ``a_t = 1 - L(target) / L0``, its free part keeps ``1 - a_t f`` of its length as far as the patches keep
    theirs, and the target inverts no element), the design may go a little beyond the target:
    ``r = TARGET_FREE_SHARE (1 - a_t f)`` (0.9 of it), never below ``FREE_REMAINDER_MIN``. A contraction the body was shown at is thus
    never cut off by the cap (a target made by the forward solve at known contractions is recovered).

    Example
    -------
    >>> from mdsr_opt import Mesh, Muscle, NeoHookean
    >>> mesh = Mesh.rectangle(4.0, 1.0, 32, 8)
    >>> long, short = Muscle(range(0, 33)), Muscle(range(265, 270))  # 4 and 0.5 long, bottom and top edge
    >>> contraction_caps(mesh, NeoHookean(1.0, 0.3), [long, short], 10.0, 0.125, 0.6).round(4).tolist()
    [0.5625, 0.3]
    >>> squeezed = mesh.points * [0.6, 1.0]  # the target shortens both paths by 40 %
    >>> contraction_caps(mesh, NeoHookean(1.0, 0.3), [long, short], 10.0, 0.125, 0.6, squeezed).round(4).tolist()
    [0.5625, 0.41]
    """
    _ks, fac = spring_segments(mesh, material, muscles, stiffness, anchor_radius)
    fac = np.asarray(fac, dtype=float)
    keep = np.full(len(fac), 1.0 - max(float(a_max), FREE_SHORTENING_MAX))
    if target is not None:
        y = np.asarray(target, dtype=float).reshape(-1, 2)
        a_t = np.array([1.0 - m.length(y) / m.length(mesh.points) for m in muscles])
        keep = np.minimum(keep, np.maximum(TARGET_FREE_SHARE * (1.0 - a_t * fac), FREE_REMAINDER_MIN))
    return np.minimum(float(a_max), (1.0 - keep) / fac)


def fixture_caps(points, muscles, radius: float, wall: float) -> np.ndarray:
    """Per muscle the largest contraction at which its two end fixtures (disks of ``radius``, centred on its end
    nodes) keep a ``wall`` between them along the rope, ``1 - (2 radius + wall) / L0`` (at least 0), ``L0`` the
    rope's length along its path at rest (``points``): a taut rope drawn in by ``a`` leaves ``(1 - a) L0`` of
    rope between the fixtures' centres, along which the two fixtures slide in its channel, and they need
    ``2 radius + wall`` between their centres, as fixtures of different ropes do
    (:func:`~mdsr_opt.synthesis.fabrication.rope_conflicts`). (Ends that come near each other across the
    body, a strip curled until its ends touch, are kept apart by the body itself: its contact.) Without end
    fixtures (``radius`` 0) every cap is 1, and so is a rope already shorter than that at rest: no contraction
    makes it buildable, its layout does not fit its fixtures (routing drops such stubs; :func:`short_ropes`
    names them). :func:`fixture_overlaps` checks the designed state itself.

    Example
    -------
    >>> import numpy as np
    >>> from mdsr_opt import Muscle
    >>> P = np.array([[0.0, 0.0], [0.3, 0.4], [0.6, 0.0]])
    >>> fixture_caps(P, [Muscle([0, 1, 2])], 0.2, 0.1).round(4).tolist()   # 1 - 0.5 / 1
    [0.5]
    """
    need = 2.0 * float(radius) + float(wall)
    if float(radius) <= 0.0:
        return np.ones(len(muscles))
    X = np.asarray(points, dtype=float).reshape(-1, 2)
    l0 = np.array([m.length(X) for m in muscles])
    with np.errstate(divide="ignore"):
        return np.where(l0 < need, 1.0, np.clip(1.0 - need / l0, 0.0, 1.0))


def short_ropes(points, muscles, radius: float, wall: float) -> list:
    """The muscles shorter at rest (``points``) than their two end fixtures need, ``2 radius + wall``: per
    such muscle ``(index, rest length, need)`` (:func:`fixture_caps` leaves them uncapped)."""
    need = 2.0 * float(radius) + float(wall)
    if float(radius) <= 0.0:
        return []
    X = np.asarray(points, dtype=float).reshape(-1, 2)
    return [(c, l0, need) for c, l0 in enumerate(m.length(X) for m in muscles) if l0 < need]


def fixture_overlaps(x, muscles, radius: float, wall: float, tol: float = 1e-9, rest=None) -> list:
    """The muscles whose two end fixtures (disks of ``radius``) keep less than ``wall`` between them along the
    rope in the state ``x`` (less than ``2 radius + wall - tol`` of rope between its end nodes,
    :func:`fixture_caps`): per such muscle ``(index, length, 2 radius + wall)``; empty without end fixtures
    (``radius`` 0). With the ``rest`` state, ropes already too short there (:func:`short_ropes`) are left out.

    Example
    -------
    >>> import numpy as np
    >>> from mdsr_opt import Muscle
    >>> x = np.array([[0.0, 0.0], [0.2, 0.0], [0.45, 0.0]])
    >>> [(c, round(d, 3), round(n, 3)) for c, d, n in fixture_overlaps(x, [Muscle([0, 1, 2])], 0.2, 0.1)]
    [(0, 0.45, 0.5)]
    """
    if float(radius) <= 0.0:
        return []
    need = 2.0 * float(radius) + float(wall)
    X = np.asarray(x, dtype=float).reshape(-1, 2)
    R = None if rest is None else np.asarray(rest, dtype=float).reshape(-1, 2)
    out = []
    for c, m in enumerate(muscles):
        d = m.length(X)
        if d < need - tol and (R is None or m.length(R) >= need):
            out.append((c, d, need))
    return out


def _nonzeros(M: ca.SX) -> ca.SX:
    """The structural nonzeros of ``M`` as a column (column-major order, as its sparsity lists them)."""
    return ca.vec(M.nz[:]) if M.nnz() else ca.SX(0, 1)


class _ConstraintBlock:
    """The muscle constraints of the flattened NLP as one sparse block over the dofs they touch.

    Rows: for the cable, one per rope, ``L_c(x) / L0_c - 1`` (the NLP adds ``+ a_c``: the equality
    ``L_c = (1 - a_c) L0_c`` as a strain); then the rigid end-patch rows of
    :class:`~mdsr_opt.mechanics.constraints.MuscleConstraints`, each divided by the norm of its gradient at rest
    (a length). With multipliers ``kappa`` (one per row) the stationarity conditions gain ``J(x)^T kappa``;
    for a rope, ``kappa_c = tau_c L0_c / (E t h)`` (``tau_c`` the tension, :meth:`tension`).

    Numbers (:meth:`values`, :meth:`jacobian`, :meth:`hessian`, :meth:`multipliers`) come from the
    constraints' closed forms in numpy. The NLP's SX functions of the local dofs ``xl`` (sorted, so local
    order is global order) are built on first use and cached with the constraints (one build per mesh,
    muscles and model): ``val(xl, kappa) -> (C, J^T kappa)``; ``jac(xl, kappa) -> (J^T kappa, nz(J),
    nz(H_kappa))`` with ``H_kappa = d^2 (kappa . C) / dxl^2`` (both triangles); ``hess(xl, lam, kappa, omega)
    -> nz(triu H)``, the Hessian over ``(xl, kappa)`` of ``lam . J^T kappa + omega . C`` (the block's part of
    the NLP's Lagrangian; the ``kappa``-``kappa`` block is zero). Sparsities ``J_sp``, ``Hk_sp``, ``H_sp``.
    """

    def __init__(self, prob: "DesignProblem"):
        mc = prob.constraints
        self.mc = mc
        self.rope = prob.muscle_model == "cable"
        self.n_rope = prob.m if self.rope else 0
        self.n_rigid = int(mc.n_rigid)
        self.nc = self.n_rope + self.n_rigid
        self.L0 = prob.L0
        self.scale_t = prob.Et * prob.h  # kappa -> tension: tau = kappa * Et h / L0
        self.dofs = np.asarray(mc.dofs, dtype=np.int64)  # ropes' and anchor groups' coordinates, sorted
        self.d = len(self.dofs)
        #: the constraints' rows the block uses (all but the ropes for the springs model)
        self.rows = np.arange(mc.n_muscles - self.n_rope, mc.n_constraints)
        scale = np.ones(0)
        if self.n_rigid:
            Jr = mc.local_jacobian(prob.X[self.dofs])[mc.n_muscles:]
            norms = np.sqrt(np.asarray(Jr.multiply(Jr).sum(axis=1)).ravel())
            if (norms <= 0).any():
                raise ValueError("a rigid end-patch constraint has a zero gradient at rest (degenerate patch)")
            scale = 1.0 / norms
        self.rigid_scale = scale
        self.row_scale = np.concatenate([1.0 / self.L0[:self.n_rope], scale])
        self.offset = np.concatenate([np.ones(self.n_rope), np.zeros(self.n_rigid)])
        key = ("design-block", self.rope)
        self._sym_cache = mc.__dict__.setdefault("_design_block_sx", {})
        self._sym_key = key

    # ------------------------------------------------------------------ the NLP's SX functions (lazy)
    def _sym(self) -> dict:
        cache, key = self._sym_cache, self._sym_key
        if key not in cache:
            cache[key] = self._build_sym()
        return cache[key]

    def _build_sym(self) -> dict:
        d, nc = self.d, self.nc
        nlf, P, Lin = self.mc.symbolic_parts()
        R = sp.csr_matrix((self.row_scale, (np.arange(nc), self.rows)), shape=(nc, self.mc.n_constraints))
        Pb, Linb = (R @ P).tocsr(), (R @ Lin).tocsr()
        Pd, Ld = to_dm(Pb), to_dm(Linb)
        xl = ca.SX.sym("xl", d)
        kap = ca.SX.sym("kappa", nc)
        lam = ca.SX.sym("lam", d)
        om = ca.SX.sym("omega", nc)
        nl = nlf(xl)
        C = ca.mtimes(Pd, nl) + ca.mtimes(Ld, xl) - ca.DM(self.offset) if nc else ca.SX(0, 1)
        # the linear rows have a constant Jacobian and no curvature: only the nonlinear ones are differentiated
        J = ca.mtimes(Pd, ca.jacobian(nl, xl)) + Ld if nc else ca.SX(0, d)
        kap_nl = ca.mtimes(Pd.T, kap)
        JTk = ca.mtimes(J.T, kap) if nc else ca.SX(d, 1)
        Hk = ca.hessian(ca.dot(kap_nl, nl), xl)[0] if nc else ca.SX(d, d)
        # lam . J^T kappa + omega . C: its linear rows are linear in (xl, kappa) jointly, so drop out of the
        # Hessian over (xl, kappa)
        phi = ca.dot(lam, ca.gradient(ca.dot(kap_nl, nl), xl)) + ca.dot(ca.mtimes(Pd.T, om), nl)
        Hphi = ca.triu(ca.hessian(phi, ca.vertcat(xl, kap))[0])
        return {"J_sp": J.sparsity(), "Hk_sp": Hk.sparsity(), "H_sp": Hphi.sparsity(),
                "val": ca.Function("muscle_con_val", [xl, kap], [C, JTk]),
                "jac": ca.Function("muscle_con_jac", [xl, kap], [JTk, _nonzeros(J), _nonzeros(Hk)]),
                "hess": ca.Function("muscle_con_hess", [xl, lam, kap, om], [_nonzeros(Hphi)])}

    val = property(lambda self: self._sym()["val"])
    jac = property(lambda self: self._sym()["jac"])
    hess = property(lambda self: self._sym()["hess"])
    J_sp = property(lambda self: self._sym()["J_sp"])
    Hk_sp = property(lambda self: self._sym()["Hk_sp"])
    H_sp = property(lambda self: self._sym()["H_sp"])

    # ------------------------------------------------------------------ numbers
    def values(self, xflat) -> np.ndarray:
        """The rows ``C(x)`` (without the NLP's ``+ a``)."""
        return self.mc.values(xflat)[self.rows] * self.row_scale - self.offset

    def jacobian(self, xflat) -> sp.csr_matrix:
        """``dC/dx`` as a scipy matrix ``(nc, 2n)``."""
        return (sp.diags(self.row_scale) @ self.mc.jacobian(xflat)[self.rows]).tocsr()

    def hessian(self, xflat, kappa) -> sp.csr_matrix:
        """``d^2 (kappa . C) / dx^2`` as a scipy matrix ``(2n, 2n)``."""
        lam = np.zeros(self.mc.n_constraints)
        lam[self.rows] = np.asarray(kappa, dtype=float) * self.row_scale
        return self.mc.hessian(xflat, lam).tocsr()

    def multipliers(self, xflat, g_scaled, free=None) -> np.ndarray:
        """Least-squares ``kappa`` with ``g_scaled + J^T kappa = 0`` on the free dofs (``g_scaled`` the
        energy gradient over ``E t h``): the multipliers of an equilibrium, e.g. to warm-start the NLP."""
        if self.nc == 0:
            return np.zeros(0)
        J = self.jacobian(xflat)
        if free is not None:
            J = J[:, np.nonzero(free)[0]]
            g_scaled = np.asarray(g_scaled)[free]
        kap = least_squares_multipliers(J, g_scaled)  # the augmented system, else the normal equations
        if kap is not None:
            return kap
        A = (J @ J.T).tocsc()
        rhs = -(J @ g_scaled)
        try:  # J J' is symmetric positive (semi)definite: diagonal pivots in a minimum-degree order
            kap = spla.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                            options={"SymmetricMode": True}).solve(rhs)
            if np.all(np.isfinite(kap)):
                return kap
        except RuntimeError:
            pass
        return np.asarray(spla.spsolve(A, rhs)).ravel()  # a breakdown: the general solve

    def tension(self, kappa) -> np.ndarray:
        """Rope tensions (force units) from the rope multipliers."""
        return np.asarray(kappa)[:self.n_rope] * self.scale_t / self.L0[:self.n_rope]


#: the first solve of a :class:`ForwardSolver` from a given shape approaches the equilibrium with the energy's
#: Hessian projected to positive semi-definite down to this scaled KKT residual, then finishes with the
#: exact Hessian. From the target, compressed elements made the exact Hessian indefinite and IPOPT
#: regularised it by up to 1e2 x I, crawling (the strip of bench_fine_design: 14 iterations at 8k nodes
#: against 5 projected and 2 exact)
PROJECTED_START_TOL = 1e-2

#: ... and the exact finish goes at least this far (quadratic convergence: a step or two): the design NLP
#: started from a state the projected steps left at the warm start's 1e-4 took up to 3x its iterations
#: (bench_buildable's star 383 against 52, tentacle 121 against 43; 23 and 35 with this finish)
EXACT_FINISH_TOL = 1e-6


class ForwardSolver:
    """Warm-started forward solves (:func:`~mdsr_opt.solve_internal` with the problem's muscle model and
    anchor patches), each from the last accepted state, in the gauge frame (not aligned to rest).

    ``started_from`` says where the first solve started: ``"rest"`` (load stepping with the predictor) or
    ``"target"`` (a shape given to :meth:`solve`)."""

    def __init__(self, prob: DesignProblem, tol: float, max_iter: int):
        self.prob = prob
        self.tol, self.max_iter = tol, max_iter
        self.a = np.zeros(prob.m)
        self.x = prob.X.copy()  # the rest state is the equilibrium at a = 0
        self.n_solves = 0
        self.iterations = 0
        self.build_time = 0.0
        self.started_from = None
        #: contact keywords of every forward solve (``contact``, ``obstacles`` on the unit body, ``contact_gap``)
        self.contact: dict = {}

    def _run(self, a, guess, max_iter, min_step=1.0 / 256, check_stability: bool = True, tol=None):
        prob = self.prob
        res = solve_internal(prob.mesh, prob.material, prob.muscles, np.clip(a, 0.0, 0.999),
                             muscle_model=prob.muscle_model, stiffness=prob.stiffness, anchor_radius=prob.anchor_radius,
                             tol=self.tol if tol is None else tol, max_iter=max_iter, align_to_rest=False, initial_guess=guess,
                             min_step=min_step, check_stability=check_stability, held=prob.held, **self.contact)
        if self.n_solves == 0:
            self.build_time += res.build_time
        self.n_solves += 1
        self.iterations += res.iterations
        return res

    def solve(self, a, start=None, tol: float | None = None) -> tuple[np.ndarray, bool, str]:
        """The equilibrium at contractions ``a``: ``(x flat, success, status)``. The first solve starts
        from ``start`` (an (n, 2) shape in any pose, moved rigidly into the gauge frame) when given, with at
        most :data:`~mdsr_opt.mechanics.loadsteps.STEP_ITER_CAP` iterations (a load step's, so the same IPOPT
        solver serves both) and no load stepping, and from rest when that fails or none is given; later
        ones from the last accepted state. The solve from ``start`` takes any equilibrium
        (``solve_internal(check_stability=False)``: a warm start whose design is verified afterwards), in two
        steps: with the energy's Hessian projected per element
        (:func:`~mdsr_opt.mechanics.ropesolve.projected_energy_hessian`) to :data:`PROJECTED_START_TOL`, then
        with the exact one from there to :data:`EXACT_FINISH_TOL` (or ``tol`` if tighter); the others only a
        stable one.
        ``tol`` replaces the solver's tolerance for this solve (a warm start needs no tight equilibrium); its
        state becomes the last accepted one all the same."""
        a = np.asarray(a, dtype=float).copy()
        res = None
        if self.started_from is None:
            self.started_from = "rest"
            guess = None if start is None else self.prob.in_frame(np.asarray(start, dtype=float))
            if guess is not None:
                cap = min(self.max_iter, STEP_ITER_CAP)
                with projected_energy_hessian():  # far from equilibrium: Newton-like steps to near it
                    near = self._run(a, guess, cap, min_step=1.0, check_stability=False,
                                     tol=max(PROJECTED_START_TOL, self.tol if tol is None else tol))
                res = self._run(a, near.x if near.success else guess, cap, min_step=1.0, check_stability=False,
                                tol=min(EXACT_FINISH_TOL, self.tol if tol is None else tol))
                if res.success:
                    self.started_from = "target"
        if res is None or not res.success:  # from rest (no state accepted yet) or the last accepted state
            res = self._run(a, "predictor" if not np.any(self.a) else self.x.reshape(-1, 2), self.max_iter, tol=tol)
        x = res.x.reshape(-1)
        if res.success:
            self.a, self.x = a, x
        return x, bool(res.success), res.status


# ---------------------------------------------------------------------------------------------- input checks
def check_inputs(mesh, material, muscles, target, a_max, weights, interior_weight, muscle_model, stiffness,
                  initial):
    check_mesh_material(mesh, material)
    if isinstance(muscles, Muscle):
        muscles = [muscles]
    if muscles is None or (hasattr(muscles, "__len__") and len(muscles) == 0):
        raise ValueError("design needs at least one muscle: the muscle list is empty")
    mus = check_muscles(mesh, muscles)
    y = check_target_shape(mesh, target)  # finite, (n, 2), no inverted triangle: every design's door
    if isinstance(a_max, bool) or not isinstance(a_max, numbers.Real):
        raise TypeError(f"a_max must be a real number, got {type(a_max).__name__}")
    a_max = float(a_max)
    if not (0.0 < a_max < 1.0):
        raise ValueError(f"a_max must lie in (0, 1) (a fraction of the rest length), got {a_max}")
    if muscle_model not in ("springs", "cable"):
        raise ValueError(f"muscle_model must be 'springs' or 'cable', got {muscle_model!r}")
    if muscle_model == "cable":
        check_distinct_ropes(mus)
    stiffness = positive_float(stiffness, "stiffness")
    if weights is None:
        w = node_weights(mesh, interior_weight)
    else:
        w = as_float_array(weights, "weights", shape=(mesh.n_nodes,))
        if (w < 0).any() or w.sum() <= 0:
            raise ValueError("weights must be non-negative with a positive sum")
    a0 = None
    if initial is not None:
        a0 = as_float_array(np.atleast_1d(initial), "initial", shape=(len(mus),))
        if (a0 < 0).any() or (a0 > a_max).any():
            raise ValueError(f"initial contractions must lie in [0, a_max = {a_max:g}], got {a0.tolist()}")
    return mus, y, a_max, w, stiffness, a0


def initial_guess_of(mesh, muscles, y, a_max) -> np.ndarray:
    """Each muscle's geometric contraction in the target (``1 - L_target / L_rest``), clipped into the bounds."""
    a = np.array([1.0 - mu.length(y) / mu.rest_length(mesh) for mu in muscles])
    return np.clip(a, 0.0, 0.9 * a_max)
