"""Driving-quantity design: the contractions that make the muscle-driven body match a target shape.

Given muscles ``C`` on a mesh and a target configuration ``y`` (typically an external-driving equilibrium),
find contractions ``a`` (one per muscle, ``0 <= a <= a_max``) minimising the difference index

``D(a) = min_{R, t} sum_i e_i |R x*_i(a) + t - y_i|^2``,

where ``x*(a)`` is the internal-driving equilibrium (a minimiser of ``E_e(x) + E_d(x, a)`` with the rigid
gauge pinned) and ``e_i`` are node weights (1 on the boundary, 0.3-0.7 inside). The difference is reported
as a length, ``sqrt(D / sum e)``.

Three methods solve it:

``"flattened"`` (the default, the product's defining choice)
    One NLP in ``(x, a, theta, t, tau, mu)``: minimise ``D`` subject to the lower level's KKT conditions,
    stationarity ``grad E(x, a) + sum_c tau_c grad L_c(x) + sum_k mu_k grad c_k(x) = 0`` on the non-gauge
    coordinates, the exact cable's rope equalities ``L_c(x) = (1 - a_c) L0_c`` with tensions ``tau_c >= 0``
    as bounds (``muscle_model="cable"``, the default; a rope with ``tau_c = 0`` is slack and its ``a_c`` is
    the contraction it reached), the rigid end patches ``c_k(x) = 0`` of both muscle models
    (:mod:`~mdsr_opt.muscle_constraints`; for ``"springs"`` the energy ``E`` includes the dummy springs and
    there are no rope rows), the gauge as fixed variables and ``0 <= a <= a_max``. IPOPT through CasADi with the exact
    Hessian of the Lagrangian, warm-started from a forward solve at the initial contractions. Objective and
    constraints are scaled (see *Scaling* below). The NLP's derivatives (constraint Jacobian, Hessian of the
    Lagrangian with the energy's third derivatives) are assembled term by term from small per-element and
    per-spring SX functions, like the energy model's own, plus one sparse SX block for the muscle
    constraints over the coordinates they touch; ``derivatives="casadi"`` instead builds the NLP in SX and
    lets CasADi differentiate it (the same numbers, much slower to build).
``"nested"``
    The reduced-space rival: an outer L-BFGS-B over ``a``; each evaluation solves the equilibrium (warm
    started from the previous one) and the exact gradient comes from the implicit-function theorem by one
    adjoint solve with the KKT matrix of the equilibrium (Hessian of its Lagrangian and the active muscle
    constraints: anchor patches, taut ropes), ``dD/da = -lambda^T dF/da``.
``"derivative-free"``
    The baseline a user without this toolkit would write: Nelder-Mead (or Powell) over ``a`` with bounds,
    each evaluation a warm-started forward solve.

Every design is verified (:func:`verify_design`): the forward internal-driving problem is solved again from
rest at the found contractions and its state compared with the design's; the design's state must be a strict
minimum of the energy (the free-coordinate Hessian positive definite, checked by the signs of the pivots of
a symmetric factorisation and the smallest eigenvalue). A design whose optimiser failed, whose verification
gap exceeds the tolerance or whose state is a saddle is reported with ``success=False``; a target that no
contractions reach is a success with a positive difference.

Scaling
-------
The flattened NLP divides the objective by ``sum(e) * h**2`` (mean squared distance in mean rest edge
lengths ``h``), and further by its warm-start value when that exceeds 1 (a target out of reach: IPOPT's
absolute tolerance then stays a relative one), and the stationarity constraints by ``E * t * h``
(strain-like); rope rows are strains (``L/L0 - 1 + a``) and rigid-patch rows lengths. Normalising the objective
by the body's size instead (``scaling="size"``) leaves the objective's Hessian orders of magnitude below
the constraint Jacobian on a 1k-node mesh, and IPOPT then regularises the Hessian and needs many more
iterations (see ``tests/benchmarks/bench_design.py``).

Example
-------
>>> import numpy as np
>>> from mdsr_opt import Mesh, Muscle, NeoHookean, solve_internal
>>> from mdsr_opt.design import design_contractions
>>> mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
>>> muscle = Muscle(range(1, 16))                       # along the bottom edge
>>> target = solve_internal(mesh, NeoHookean(1.0, 0.3), [muscle], [0.2]).x
>>> res = design_contractions(mesh, NeoHookean(1.0, 0.3), [muscle], target, initial=[0.05])
>>> res.success, round(float(res.contractions[0]), 6), round(float(res.stroke[0]), 6)  # stroke = a L0
(True, 0.2, 0.7)
"""

from __future__ import annotations

import json
import math
import numbers
import os
import time
from dataclasses import asdict, dataclass, field
from typing import Any, Callable, Sequence

import casadi as ca
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike

from ._checks import as_float_array, positive_float
from .align import align, node_weights
from .equilibrium import _check_mesh_material, _gauge, external_stability, solve_internal
from .mesh import Mesh
from .model import _to_dm, get_model
from .muscle_constraints import (MuscleConstraints, check_anchor_radius, segment_spring_parameters,
                                 spring_segments, spring_stiffness)
from .muscles import Muscle, check_muscles
from .stability import check_stability

__all__ = ["METHODS", "DesignResult", "Verification", "PipelineResult", "design_contractions",
           "verify_design", "check_minimum", "design", "design_pipeline"]

METHODS = ("flattened", "nested", "derivative-free")


# ---------------------------------------------------------------------------------------------- results
@dataclass
class Verification:
    """The independent check of a design.

    Attributes
    ----------
    passed : bool
        The forward re-solve succeeded, its gap to the design's state is within ``gap_tol`` and the design's
        state is a strict minimum.
    gap : float
        Largest node distance between the design's state and the forward re-solve from rest at the same
        contractions, after rigidly aligning the two (a length).
    gap_tol : float
        The tolerance on ``gap`` (a length: ``gap_rtol * mesh.size``).
    forward_success, forward_status : bool, str
        Outcome of the forward re-solve.
    forward_difference : float
        Difference index of the forward re-solve to the target.
    residual : float
        Max-norm of the energy gradient on the free coordinates at the design's state, relative to
        ``E t size``.
    positive_definite : bool
        The free-coordinate Hessian at the design's state is positive definite (every pivot of its
        symmetric factorisation is positive).
    min_eigenvalue : float
        Its smallest eigenvalue, relative to ``E t`` (negative: a saddle); see :func:`check_minimum`. When
        the state is positive definite it is only estimated with ``verify_design(..., lowest=True)`` (an
        eigen-solve, 30-100x the cost of the inertia) and is NaN otherwise; when it is not, the curvature
        along the direction of negative curvature found (an upper bound on the smallest eigenvalue).
    message : str
        Why the check failed (empty when it passed).
    time : float
        Seconds spent verifying.
    target_stable : bool or None
        The target is a stable equilibrium of its external driving (None: anchors and drags not given).
    """

    passed: bool
    gap: float
    gap_tol: float
    forward_success: bool
    forward_status: str
    forward_difference: float
    residual: float
    positive_definite: bool
    min_eigenvalue: float
    message: str = ""
    time: float = 0.0
    target_stable: bool | None = None


@dataclass
class DesignResult:
    """Contractions found for a target, the driven state and how they were found.

    Attributes
    ----------
    method : str
        ``"flattened"``, ``"nested"`` or ``"derivative-free"``.
    contractions : (m,) ndarray
        One contraction per muscle, in ``[0, a_max]``.
    x : (n, 2) ndarray
        The driven equilibrium at ``contractions``, rigidly aligned to the rest shape (as
        :func:`~mdsr_opt.solve_internal` returns it).
    rotation, translation : (2, 2) and (2,) ndarrays
        The best rigid motion taking ``x`` onto the target: ``x @ rotation.T + translation``.
    difference : float
        Weighted RMS node distance to the target after that motion (a length).
    success : bool
        The optimiser converged and the verification passed.
    status : str
        The optimiser's status, with the reason when the design was rejected.
    iterations : int
        Outer iterations (IPOPT iterations for ``"flattened"``).
    n_forward : int
        Forward (equilibrium) solves made, warm start included.
    inner_iterations : int
        Solver iterations summed over those forward solves.
    build_time, solve_time, time : float
        Seconds building models and solvers (0 when cached), optimising (warm start included), and their sum.
    initial_contractions : (m,) ndarray
        The starting point.
    initial_difference : float
        Difference of the warm-start state.
    a_max : float
        Upper bound on the contractions.
    muscle_model : str
        ``"cable"`` (the exact rope) or ``"springs"``.
    stiffness : float
        Spring stiffness relative to ``E t`` (springs only).
    anchor_radius : float
        Radius of the rigid patch at each muscle end (a length; see
        :func:`~mdsr_opt.muscle_constraints.anchor_patches`).
    rest_lengths : (m,) ndarray
        Each muscle's rest length ``L0`` along its node chain.
    achieved : (m,) ndarray
        Achieved contraction ``1 - L / L0`` of every muscle along its node chain in ``x`` (the cable:
        equal to ``contractions`` unless the rope is slack; springs: less, the springs stretch).
    stroke : (m,) ndarray
        The rope length each muscle pulls in, ``achieved * L0`` (a length; what a servo winds).
    tension : (m,) ndarray
        The muscle's pull (force: ``E t`` times a length). The cable: the rope's tension, the multiplier
        of its length constraint (never negative). Springs: the mean force of its segment springs.
    slack : (m,) bool ndarray
        The muscle does not pull (tension about zero, or negative for springs).
    verification : Verification or None
        The independent check (None when ``verify=False``).
    history : list of (float, float)
        ``(seconds since start, difference)`` after each forward solve of the outer loop (nested,
        derivative-free) or at start and end (flattened, whose iterates are not equilibria).
    """

    method: str
    contractions: np.ndarray
    x: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    difference: float
    success: bool
    status: str
    iterations: int
    n_forward: int
    inner_iterations: int
    build_time: float
    solve_time: float
    time: float
    initial_contractions: np.ndarray
    initial_difference: float
    a_max: float
    muscle_model: str = "cable"
    stiffness: float = 10.0
    verification: Verification | None = None
    history: list = field(default_factory=list)
    anchor_radius: float = float("nan")
    rest_lengths: np.ndarray = field(default_factory=lambda: np.zeros(0))
    achieved: np.ndarray = field(default_factory=lambda: np.zeros(0))
    stroke: np.ndarray = field(default_factory=lambda: np.zeros(0))
    tension: np.ndarray = field(default_factory=lambda: np.zeros(0))
    slack: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))

    @property
    def commanded(self) -> np.ndarray:
        """The designed (commanded) contractions, the same as ``contractions``."""
        return self.contractions

    def muscle_table(self) -> str:
        """One line per muscle: commanded and achieved contraction, stroke, tension, slack."""
        lines = [f"{'muscle':>6} {'commanded':>10} {'achieved':>9} {'stroke':>10} {'tension':>10} slack"]
        for i in range(len(self.contractions)):
            def at(v, k=i):
                return float(v[k]) if len(v) > k else float("nan")
            sl = bool(self.slack[i]) if len(self.slack) > i else False
            lines.append(f"{i:>6} {at(self.contractions):>10.4f} {at(self.achieved):>9.4f} "
                         f"{at(self.stroke):>10.4g} {at(self.tension):>10.4g} {'yes' if sl else 'no'}")
        return "\n".join(lines)

    @property
    def x_aligned(self) -> np.ndarray:
        """The driven state moved onto the target: ``x @ rotation.T + translation``."""
        return self.x @ self.rotation.T + self.translation

    @property
    def angle(self) -> float:
        """Rotation angle (radians) of the motion onto the target."""
        return float(math.atan2(self.rotation[1, 0], self.rotation[0, 0]))

    def summary(self) -> dict:
        """Scalars of the result (no arrays except the contractions), for tables and logs."""
        v = self.verification
        return {"method": self.method, "success": self.success, "status": self.status,
                "muscle_model": self.muscle_model,
                "contractions": [float(c) for c in self.contractions],
                "achieved": [float(c) for c in self.achieved], "stroke": [float(c) for c in self.stroke],
                "tension": [float(c) for c in self.tension], "slack": [bool(s) for s in self.slack],
                "anchor_radius": self.anchor_radius, "difference": self.difference,
                "initial_difference": self.initial_difference, "iterations": self.iterations,
                "n_forward": self.n_forward, "inner_iterations": self.inner_iterations,
                "build_time": self.build_time, "solve_time": self.solve_time, "time": self.time,
                "verified": None if v is None else v.passed, "gap": None if v is None else v.gap,
                "min_eigenvalue": None if v is None or not np.isfinite(v.min_eigenvalue) else v.min_eigenvalue}

    def to_dict(self) -> dict:
        """A JSON-ready dict (arrays as nested lists); :meth:`from_dict` inverts it."""
        d = {}
        for k, v in self.__dict__.items():
            if isinstance(v, np.ndarray):
                d[k] = v.tolist()
            elif isinstance(v, Verification):
                d[k] = asdict(v)
            elif k == "history":
                d[k] = [[float(a), float(b)] for a, b in v]
            else:
                d[k] = v
        return _finite_or_none(d)

    @classmethod
    def from_dict(cls, d: dict) -> "DesignResult":
        d = {k: (float("nan") if v is None and k in ("difference", "initial_difference", "anchor_radius") else v)
             for k, v in d.items()}
        for k in ("contractions", "x", "rotation", "translation", "initial_contractions"):
            d[k] = np.asarray(d[k], dtype=float)
        for k in ("rest_lengths", "achieved", "stroke", "tension"):
            if k in d:
                d[k] = np.asarray([np.nan if v is None else v for v in d[k]], dtype=float)
        if "slack" in d:
            d["slack"] = np.asarray(d["slack"], dtype=bool)
        if d.get("verification") is not None:
            v = dict(d["verification"])
            if v.get("min_eigenvalue") is None:  # not estimated (NaN, written as null)
                v["min_eigenvalue"] = np.nan
            d["verification"] = Verification(**v)
        d["history"] = [tuple(h) for h in d.get("history", [])]
        return cls(**d)


def _finite_or_none(o):
    """Replace NaN/inf floats by None (JSON has no NaN), recursively."""
    if isinstance(o, dict):
        return {k: _finite_or_none(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_finite_or_none(v) for v in o]
    if isinstance(o, (float, np.floating)):
        return float(o) if math.isfinite(o) else None
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.bool_):
        return bool(o)
    return o


# ---------------------------------------------------------------------------------------------- the problem
class _Problem:
    """Everything the three methods share: model, affine parameters ``p(a) = p0 + B a``, the muscle
    constraints (rope lengths for the cable, rigid end patches for both models), gauge, weights, scales."""

    def __init__(self, mesh, material, muscles, target, weights, muscle_model, stiffness, a_max,
                 anchor_radius=None):
        self.mesh, self.material, self.muscles = mesh, material, muscles
        self.y = target
        self.w = weights
        self.muscle_model = muscle_model
        self.stiffness = stiffness
        self.a_max = a_max
        self.m = len(muscles)
        n = mesh.n_nodes
        t0 = time.perf_counter()
        # the exact cable is a constraint, not an energy: the energy model is the body's (plus the
        # per-segment springs of the "springs" model, zero for the cable)
        self.model = get_model(mesh, material)
        self.anchor_radius = check_anchor_radius(mesh, anchor_radius)
        self.constraints = MuscleConstraints(mesh, muscles, self.anchor_radius)
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
        self.fixed = np.zeros(2 * n, dtype=bool)
        self.gauge = list(_gauge(mesh))
        self.fixed[self.gauge] = True
        self.free = ~self.fixed
        self.X = mesh.points.reshape(-1).copy()
        self.h = float(mesh.edge_lengths.mean())
        self.Et = material.E * material.thickness
        self.W = float(weights.sum())
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
        al = align(x2, self.y, self.w)
        r = x2 @ al.R.T + al.t - self.y
        J = float((self.w * (r ** 2).sum(1)).sum()) / (self.W * self.h ** 2)
        dJ = (2.0 / (self.W * self.h ** 2)) * (self.w[:, None] * (r @ al.R))  # envelope theorem: R, t optimal
        return J, al, dJ.reshape(-1)

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
        sc = 1.0 / (self.Et * self.h)
        p = self.params(a)
        g = self.model.gradient(xflat, p) * sc
        H = self.model.hessian(xflat, p) * sc
        blk = self.block
        if not blk.nc:
            return H.tocsc(), self.free.copy(), None, np.zeros(0), float(np.abs(g[self.free]).max())
        kap = blk.multipliers(xflat, g, self.free)
        J = blk.jacobian(xflat)
        act = np.ones(blk.nc, dtype=bool)
        if blk.rope:  # a slack rope (no tension) constrains nothing
            act[:self.m] = kap[:self.m] > 1e-9 * max(1.0, float(np.abs(kap).max()))
        res = float(np.abs((g + J.T @ kap)[self.free]).max())
        return (H + blk.hessian(xflat, kap)).tocsc(), self.free.copy(), J[np.nonzero(act)[0]], kap, res

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


def _nonzeros(M: ca.SX) -> ca.SX:
    """The structural nonzeros of ``M`` as a column (column-major order, as its sparsity lists them)."""
    return ca.vec(M.nz[:]) if M.nnz() else ca.SX(0, 1)


class _ConstraintBlock:
    """The muscle constraints of the flattened NLP as one sparse SX block over the dofs they touch.

    Rows: for the cable, one per rope, ``L_c(x) / L0_c - 1`` (the NLP adds ``+ a_c``: the equality
    ``L_c = (1 - a_c) L0_c`` as a strain); then the rigid end-patch rows of
    :class:`~mdsr_opt.muscle_constraints.MuscleConstraints`, each divided by the norm of its gradient at rest
    (a length). With multipliers ``kappa`` (one per row) the stationarity conditions gain ``J(x)^T kappa``;
    for a rope, ``kappa_c = tau_c L0_c / (E t h)`` (``tau_c`` the tension, :meth:`tension`).

    Functions of the local dofs ``xl`` (sorted, so local order is global order):
    ``val(xl, kappa) -> (C, J^T kappa)``; ``jac(xl, kappa) -> (J^T kappa, nz(J), nz(H_kappa))`` with
    ``H_kappa = d^2 (kappa . C) / dxl^2`` (both triangles); ``hess(xl, lam, kappa, omega) -> nz(triu H)``,
    the Hessian over ``(xl, kappa)`` of ``lam . J^T kappa + omega . C`` (the block's part of the NLP's
    Lagrangian; the ``kappa``-``kappa`` block is zero).
    """

    def __init__(self, prob: "_Problem"):
        mc = prob.constraints
        n = prob.mesh.n_nodes
        self.rope = prob.muscle_model == "cable"
        self.n_rope = prob.m if self.rope else 0
        self.n_rigid = int(mc.n_rigid)
        self.nc = self.n_rope + self.n_rigid
        self.L0 = prob.L0
        self.scale_t = prob.Et * prob.h  # kappa -> tension: tau = kappa * Et h / L0
        self.dofs = np.sort(np.asarray(mc.dofs, dtype=np.int64))  # ropes' and anchor groups' coordinates
        d = len(self.dofs)
        self.d = d
        xl = ca.SX.sym("xl", d)
        xf = ca.SX.zeros(2 * n)
        if d:
            xf[self.dofs.tolist()] = xl
        parts = []
        if self.rope:
            parts.append(mc.lengths_expr(xf) / ca.DM(self.L0) - 1.0)
        scale = np.ones(0)
        if self.n_rigid:
            raw = mc.rigid_expr(xf)
            Jr = ca.Function("rigid_jac", [xl], [ca.jacobian(raw, xl)])(prob.X[self.dofs])
            norms = np.sqrt(np.asarray(ca.sum2(Jr * Jr)).ravel())
            if (norms <= 0).any():
                raise ValueError("a rigid end-patch constraint has a zero gradient at rest (degenerate patch)")
            scale = 1.0 / norms
            parts.append(raw * ca.DM(scale))
        self.rigid_scale = scale
        C = ca.vertcat(*parts) if parts else ca.SX(0, 1)
        kap = ca.SX.sym("kappa", self.nc)
        lam = ca.SX.sym("lam", d)
        om = ca.SX.sym("omega", self.nc)
        J = ca.jacobian(C, xl)
        JTk = ca.gradient(ca.dot(kap, C), xl) if self.nc else ca.SX(d, 1)
        Hk = ca.hessian(ca.dot(kap, C), xl)[0] if self.nc else ca.SX(d, d)
        phi = ca.dot(lam, JTk) + ca.dot(om, C)
        Hphi = ca.triu(ca.hessian(phi, ca.vertcat(xl, kap))[0])
        self.J_sp, self.Hk_sp, self.H_sp = J.sparsity(), Hk.sparsity(), Hphi.sparsity()
        self.val = ca.Function("muscle_con_val", [xl, kap], [C, JTk])
        self.jac = ca.Function("muscle_con_jac", [xl, kap], [JTk, _nonzeros(J), _nonzeros(Hk)])
        self.hess = ca.Function("muscle_con_hess", [xl, lam, kap, om], [_nonzeros(Hphi)])
        self.jac_num = ca.Function("muscle_con_J", [xl], [J])
        self.hess_num = ca.Function("muscle_con_Hk", [xl, kap], [Hk])

    def values(self, xflat) -> np.ndarray:
        """The rows ``C(x)`` (without the NLP's ``+ a``)."""
        return np.asarray(self.val(np.asarray(xflat)[self.dofs], np.zeros(self.nc))[0]).ravel()

    def jacobian(self, xflat) -> sp.csr_matrix:
        """``dC/dx`` as a scipy matrix ``(nc, 2n)``."""
        Jl = self.jac_num(np.asarray(xflat)[self.dofs]).sparse()
        Jl = sp.csr_matrix(Jl)
        n2 = len(xflat)
        return sp.csr_matrix((Jl.data, self.dofs[Jl.indices], Jl.indptr), shape=(self.nc, n2))

    def hessian(self, xflat, kappa) -> sp.csr_matrix:
        """``d^2 (kappa . C) / dx^2`` as a scipy matrix ``(2n, 2n)``."""
        Hl = sp.coo_matrix(self.hess_num(np.asarray(xflat)[self.dofs], kappa).sparse())
        n2 = len(xflat)
        return sp.csr_matrix((Hl.data, (self.dofs[Hl.row], self.dofs[Hl.col])), shape=(n2, n2))

    def multipliers(self, xflat, g_scaled, free=None) -> np.ndarray:
        """Least-squares ``kappa`` with ``g_scaled + J^T kappa = 0`` on the free dofs (``g_scaled`` the
        energy gradient over ``E t h``): the multipliers of an equilibrium, e.g. to warm-start the NLP."""
        if self.nc == 0:
            return np.zeros(0)
        J = self.jacobian(xflat)
        if free is not None:
            J = J[:, np.nonzero(free)[0]]
            g_scaled = np.asarray(g_scaled)[free]
        A = (J @ J.T).tocsc()
        return np.asarray(spla.spsolve(A, -(J @ g_scaled))).ravel()

    def tension(self, kappa) -> np.ndarray:
        """Rope tensions (force units) from the rope multipliers."""
        return np.asarray(kappa)[:self.n_rope] * self.scale_t / self.L0[:self.n_rope]


class _Forward:
    """Warm-started forward solves (:func:`~mdsr_opt.solve_internal` with the problem's muscle model and
    anchor patches), each from the last accepted state, in the gauge frame (not aligned to rest)."""

    def __init__(self, prob: _Problem, tol: float, max_iter: int):
        self.prob = prob
        self.tol, self.max_iter = tol, max_iter
        self.a = np.zeros(prob.m)
        self.x = prob.X.copy()  # the rest state is the equilibrium at a = 0
        self.n_solves = 0
        self.iterations = 0
        self.build_time = 0.0

    def solve(self, a) -> tuple[np.ndarray, bool, str]:
        a = np.asarray(a, dtype=float).copy()
        prob = self.prob
        at_rest = self.n_solves == 0 or not np.any(self.a)
        guess = "predictor" if at_rest else self.x.reshape(-1, 2)
        res = solve_internal(prob.mesh, prob.material, prob.muscles, np.clip(a, 0.0, 0.999),
                             model=prob.muscle_model, stiffness=prob.stiffness, anchor_radius=prob.anchor_radius,
                             tol=self.tol, max_iter=self.max_iter, align_to_rest=False, initial_guess=guess)
        if self.n_solves == 0:
            self.build_time += res.build_time
        self.n_solves += 1
        self.iterations += res.iterations
        x = res.x.reshape(-1)
        if res.success:
            self.a, self.x = a, x
        return x, bool(res.success), res.status


# ---------------------------------------------------------------------------------------------- input checks
def _check_inputs(mesh, material, muscles, target, a_max, weights, interior_weight, muscle_model, stiffness,
                  initial):
    _check_mesh_material(mesh, material)
    if isinstance(muscles, Muscle):
        muscles = [muscles]
    if muscles is None or (hasattr(muscles, "__len__") and len(muscles) == 0):
        raise ValueError("design needs at least one muscle: the muscle list is empty")
    mus = check_muscles(mesh, muscles)
    y = as_float_array(target, "target")
    if y.shape != (mesh.n_nodes, 2):
        raise ValueError(f"target must have shape ({mesh.n_nodes}, 2) (one position per mesh node), got {y.shape}")
    if isinstance(a_max, bool) or not isinstance(a_max, numbers.Real):
        raise TypeError(f"a_max must be a real number, got {type(a_max).__name__}")
    a_max = float(a_max)
    if not (0.0 < a_max < 1.0):
        raise ValueError(f"a_max must lie in (0, 1) (a fraction of the rest length), got {a_max}")
    if muscle_model not in ("springs", "cable"):
        raise ValueError(f"muscle_model must be 'springs' or 'cable', got {muscle_model!r}")
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


def _initial_guess(mesh, muscles, y, a_max) -> np.ndarray:
    """Each muscle's geometric contraction in the target (``1 - L_target / L_rest``), clipped into the bounds."""
    a = np.array([1.0 - mu.length(y) / mu.rest_length(mesh) for mu in muscles])
    return np.clip(a, 0.0, 0.9 * a_max)


# ---------------------------------------------------------------------------------------------- assembled derivatives
class _Assembly:
    """A sparse matrix summed from vectors of term values by constant scatter matrices.

    Each part is a column of values and, per scattered value, a target ``(row, col)``, the index of its
    source in the column and an optional weight. The pattern is the union of all targets (CSC order is
    ascending ``col * nrow + row``), and the matrix is ``sum_k S_k v_k`` on that pattern.
    """

    def __init__(self, nrow: int, ncol: int):
        self.shape = (nrow, ncol)
        self.parts: list = []
        self._scatter = None

    def add(self, values, rows, cols, src, weights=None):
        """Scatter ``values[src[k]] * weights[k]`` to ``(rows[k], cols[k])``; targets with a negative row
        or column are dropped."""
        rows, cols, src = (np.asarray(v, dtype=np.int64) for v in (rows, cols, src))
        weights = np.ones(len(rows)) if weights is None else np.asarray(weights, dtype=float)
        keep = (rows >= 0) & (cols >= 0)
        if keep.any():
            self.parts.append((values, rows[keep], cols[keep], src[keep], weights[keep]))

    def build(self, values: list | None = None) -> ca.MX:
        """The assembled matrix; ``values`` (one column per part, the same sizes) replaces the parts' values,
        reusing the scatter (for a second matrix with the same structure)."""
        nrow, ncol = self.shape
        if not self.parts:
            return ca.MX(nrow, ncol)
        if self._scatter is None:  # one scatter matrix from all parts' values, stacked
            offsets = np.cumsum([0] + [p[0].numel() for p in self.parts])
            keys = np.concatenate([p[2] * nrow + p[1] for p in self.parts])
            src = np.concatenate([p[3] + o for p, o in zip(self.parts, offsets)])
            wts = np.concatenate([p[4] for p in self.parts])
            ukeys, nzpos = np.unique(keys, return_inverse=True)
            colind = np.concatenate([[0], np.cumsum(np.bincount(ukeys // nrow, minlength=ncol))])
            spars = ca.Sparsity(nrow, ncol, colind.tolist(), (ukeys % nrow).tolist())
            S = sp.csr_matrix((wts, (nzpos.ravel(), src)), shape=(len(ukeys), offsets[-1]))
            self._scatter = (spars, _to_dm(S))
        spars, S = self._scatter
        vals = ca.vertcat(*([p[0] for p in self.parts] if values is None else values))
        return ca.MX(spars, ca.mtimes(S, vals))


def _block_targets(rmap: np.ndarray, cmap: np.ndarray, upper: bool):
    """Targets of per-instance ``d x d`` blocks (``vec`` order, instance after instance): local entry
    ``(i, j)`` of instance ``e`` goes to ``(rmap[e, i], cmap[e, j])``; entries mapped to -1 are dropped,
    and with ``upper`` those below the diagonal too. Returns ``(rows, cols, src)``."""
    N, d = rmap.shape
    rr = np.broadcast_to(rmap[:, None, :], (N, d, d)).reshape(-1)
    cc = np.broadcast_to(cmap[:, :, None], (N, d, d)).reshape(-1)
    keep = (rr >= 0) & (cc >= 0)
    if upper:
        keep &= rr <= cc
    src = np.nonzero(keep)[0]
    return rr[keep], cc[keep], src


def _param_targets(rmap: np.ndarray, idx: np.ndarray, B: sp.csr_matrix, col0: int):
    """Targets of per-instance ``d x nd`` derivatives with respect to a parameter datum (``vec`` order,
    instance after instance), chained with ``dp/da = B``: local entry ``(i, j)`` of instance ``e`` goes to
    ``(rmap[e, i], col0 + c)`` with weight ``B[idx[j, e], c]`` for every nonzero of that row of ``B``.
    Returns ``(rows, cols, src, weights)``."""
    N, d = rmap.shape
    nd = idx.shape[0]
    e, j, i = (g.ravel() for g in np.meshgrid(np.arange(N), np.arange(nd), np.arange(d), indexing="ij"))
    src = e * nd * d + j * d + i
    q = idx[j, e]
    row = rmap[e, i]
    cnt = np.diff(B.indptr)[q]
    rep = np.repeat(np.arange(len(q)), cnt)
    k = B.indptr[q][rep] + (np.arange(len(rep)) - np.repeat(np.cumsum(cnt) - cnt, cnt))
    rows, cols, srcs, wts = row[rep], col0 + B.indices[k], src[rep], B.data[k]
    keep = rows >= 0
    return rows[keep], cols[keep], srcs[keep], wts[keep]


def _term_functions(fam, sens: list[int], exact: bool = True) -> dict:
    """SX functions of one term family ``W(xl, *data, glob)`` for the flattened NLP.

    ``g``: ``-> grad W``; ``gh``: ``-> (grad W, vec(Hessian W))``; ``lxx``: ``(xl, lam, *data, glob) ->
    vec(d^2 (lam . grad W) / dxl^2)`` (third derivatives of ``W`` contracted with the local multipliers);
    and, for the parameter data inputs ``sens`` (those moved by the contractions), ``dg``: ``->
    [vec(d grad W / d datum)]`` and ``lxp``: ``(xl, lam, ...) -> [vec(d^2 (lam . grad W) / dxl d datum)]``.
    Without ``exact`` (Gauss-Newton Hessian) the third-derivative functions ``lxx`` and ``lxp`` are omitted.
    """
    W = fam.W
    d = W.size1_in(0)
    xl = ca.SX.sym("xl", d)
    lam = ca.SX.sym("lam", d)
    dl = [ca.SX.sym(f"d{i}", W.size1_in(1 + i)) for i in range(W.n_in() - 2)]
    gl = ca.SX.sym("gl", W.size1_in(W.n_in() - 1))
    args, largs = [xl, *dl, gl], [xl, lam, *dl, gl]
    w = W(*args)
    gx = ca.gradient(w, xl)
    lg = ca.gradient(ca.dot(lam, gx), xl)  # = Hessian(W) lam

    def vec(e):
        return ca.vec(ca.densify(e))

    out = {"g": ca.Function(f"{fam.name}_g", args, [gx]),
           "gh": ca.Function(f"{fam.name}_gh", args, [gx, vec(ca.jacobian(gx, xl))])}
    if exact:
        out["lxx"] = ca.Function(f"{fam.name}_lxx", largs, [vec(ca.jacobian(lg, xl))])
    if sens:
        out["dg"] = ca.Function(f"{fam.name}_dg", args, [vec(ca.jacobian(gx, dl[k])) for k in sens])
        if exact:
            out["lxp"] = ca.Function(f"{fam.name}_lxp", largs, [vec(ca.jacobian(lg, dl[k])) for k in sens])
    return out


def _mapped(fn: ca.Function, X, *args) -> list:
    """Outputs (a list) of ``fn`` mapped serially over the columns of ``X`` (and of the per-instance args)."""
    return fn.map(X.shape[1], "serial").call([X, *args])


def _objective_terms(x, y, w, v, so, gauss_newton: bool):
    """The alignment objective ``so sum_i w_i |R(theta) x_i + t - y_i|^2`` and its derivatives, per node, as
    vectorised MX expressions (``x``, ``y``: 2n; ``w``: n; ``v = [theta, t]``).

    Returns ``f``, the gradient parts ``(g_x0, g_x1)`` (per node, 1 x n) and ``(g_theta, g_t0, g_t1)``, and
    the Hessian parts as a dict ``{(a, b): 1 x n values}`` over the local variables ``a, b`` in ``x0, x1,
    th, t0, t1`` (``a <= b``; entries of the ``(theta, t)`` block are per-node summands). With
    ``gauss_newton`` the Hessian is ``2 so w_i J_i^T J_i`` (``J_i`` the residual's Jacobian)."""
    X0, X1 = x[0::2].T, x[1::2].T
    Y0, Y1 = y[0::2].T, y[1::2].T
    W2 = 2 * so * w.T
    c, s = ca.cos(v[0]), ca.sin(v[0])
    rx = c * X0 - s * X1 + v[1] - Y0
    ry = s * X0 + c * X1 + v[2] - Y1
    px, py = -s * X0 - c * X1, c * X0 - s * X1  # dR/dtheta x_i
    f = so * ca.sum2(w.T * (rx ** 2 + ry ** 2))
    gx = (W2 * (c * rx + s * ry), W2 * (-s * rx + c * ry))
    gv = (ca.sum2(W2 * (rx * px + ry * py)), ca.sum2(W2 * rx), ca.sum2(W2 * ry))
    zero = 0 * W2
    h = {("x0", "x0"): W2, ("x1", "x1"): W2,  # R^T R = I
         ("x0", "th"): W2 * -X1, ("x1", "th"): W2 * X0,  # R^T dR/dtheta x_i = (-x_i1, x_i0)
         ("x0", "t0"): W2 * c, ("x0", "t1"): W2 * s, ("x1", "t0"): W2 * -s, ("x1", "t1"): W2 * c,
         ("th", "th"): W2 * (px ** 2 + py ** 2), ("th", "t0"): W2 * px, ("th", "t1"): W2 * py,
         ("t0", "t0"): W2, ("t0", "t1"): zero, ("t1", "t1"): W2}
    if not gauss_newton:  # the residual's curvature: r . d^2 r
        h[("x0", "th")] += W2 * (-s * rx + c * ry)
        h[("x1", "th")] += W2 * (-c * rx - s * ry)
        h[("th", "th")] += W2 * -(rx * (c * X0 - s * X1) + ry * (s * X0 + c * X1))
    return f, gx, gv, h


def _assembled_nlp(prob: _Problem, hessian: str):
    """The flattened NLP with its derivatives assembled term by term.

    Returns ``(nlp, functions)``: the NLP dict (MX) and the ``grad_f``, ``jac_g`` and ``hess_lag``
    Functions for IPOPT, all exact:

    - constraints ``sc grad_x E(x, p0 + B a)`` on the free coordinates: per-term gradients scattered;
    - their Jacobian: in ``x``, the per-term Hessians scattered onto the free rows (both triangles); in
      ``a``, the per-term derivatives of the gradient with respect to the parameter data, chained with
      ``B``, over the terms whose parameters move with ``a`` (the muscles' springs or cables);
    - the objective's gradient and Hessian: closed-form per-node expressions, vectorised;
    - the Hessian of the Lagrangian (upper triangle): the objective's, plus the per-term third derivatives
      of the energy contracted with the multipliers (``x-x``) and their parameter derivatives (``x-a``);
      the ``a-a`` block is zero since the constraints are affine in ``a``.

    Edge springs without a muscle have zero stiffness for every design of these muscles and are left out.
    """
    model, n, m = prob.model, prob.mesh.n_nodes, prob.m
    blk = prob.block
    nc = blk.nc
    nx = 2 * n
    nz = nx + m + 3 + nc
    it = nx + m  # index of theta; t follows
    ik = it + 3  # index of the muscle constraints' multipliers kappa
    npar = model.n_params
    z = ca.MX.sym("z", nz)
    par = ca.MX.sym("par", 3 * n + npar + 2)
    x, a, v, kap = z[:nx], z[nx:nx + m], z[it:ik], z[ik:]
    y, w, p0 = par[:nx], par[nx:nx + n], par[nx + n:nx + n + npar]
    so, sc = par[3 * n + npar], par[3 * n + npar + 1]
    B = sp.csr_matrix(prob.B)
    B.eliminate_zeros()
    p = p0 + ca.mtimes(_to_dm(B), a)
    free = np.nonzero(prob.free)[0]
    nfree = len(free)
    cidx = np.full(nx, -1, dtype=np.int64)  # dof -> constraint row (-1: gauge)
    cidx[free] = np.arange(nfree)
    lam_f = ca.MX.sym("lam_f")
    lam_g = ca.MX.sym("lam_g", nfree + nc)
    P = sp.csr_matrix((np.ones(nfree), (free, np.arange(nfree))), shape=(nx, nfree))
    lam_u = ca.mtimes(_to_dm(P), lam_g[:nfree])  # the stationarity rows' multipliers per dof (0 on the gauge)
    lam_x = sc * lam_u

    # objective
    exact = hessian == "exact"  # else Gauss-Newton: the objective's part only, no third derivatives
    f, gx, gv, ho = _objective_terms(x, y, w, v, so, not exact)
    # dense: with structural zeros (the a-entries) IPOPT through CasADi took wrong steps and failed
    grad_f = ca.densify(ca.vertcat(ca.vec(ca.vertcat(*gx)), ca.MX(m, 1), *gv, ca.MX(nc, 1)))
    hess = _Assembly(nz, nz)
    loc = {"x0": 2 * np.arange(n), "x1": 2 * np.arange(n) + 1, "th": np.full(n, it), "t0": np.full(n, it + 1),
           "t1": np.full(n, it + 2)}
    for (ka, kb), val in ho.items():
        hess.add(lam_f * val.T, loc[ka], loc[kb], np.arange(n))

    # constraints, their Jacobian, and their part of the Lagrangian's Hessian, term by term
    gval, gjac = _Assembly(nfree, 1), []  # the constraints, and their values from jac_g's term functions
    jac = _Assembly(nfree + nc, nz)  # stationarity rows, then the muscle constraints' rows
    ind = np.diff(B.indptr) > 0  # parameters moved by the contractions
    for fam in model.term_families():
        rows = np.arange(fam.dofs.shape[0])
        if fam.name == "spring":  # data (l0, k, r): only springs with stiffness
            rows = np.nonzero(prob.p0[fam.data_index[1][0]] != 0)[0]
        if len(rows) == 0:
            continue
        if len(fam.glob_index) and ind[fam.glob_index].any():  # pragma: no cover - p(a) never moves material
            raise NotImplementedError(f"{fam.name}: the shared parameters depend on the contractions")
        sens = [k for k, idx in enumerate(fam.data_index) if idx is not None and ind[np.asarray(idx)[:, rows]].any()]
        fn = _term_functions(fam, sens, exact)
        dofs = fam.dofs[rows]
        N, d = dofs.shape
        X = ca.reshape(x[dofs.reshape(-1).tolist()], d, N)
        L = ca.reshape(lam_x[dofs.reshape(-1).tolist()], d, N)
        ins = fam.inputs(p, rows)
        gtargets = (cidx[dofs].reshape(-1), np.zeros(N * d), np.arange(N * d))
        gval.add(ca.vec(_mapped(fn["g"], X, *ins)[0]), *gtargets)
        gl, Hl = _mapped(fn["gh"], X, *ins)
        gjac.append(ca.vec(gl))
        jac.add(sc * ca.vec(Hl), *_block_targets(cidx[dofs], dofs, upper=False))
        if exact:
            hess.add(ca.vec(_mapped(fn["lxx"], X, L, *ins)[0]), *_block_targets(dofs, dofs, upper=True))
        if not sens:
            continue
        moving = np.zeros(N, dtype=bool)  # instances whose parameters move with a
        for k in sens:
            moving |= ind[np.asarray(fam.data_index[k])[:, rows]].any(axis=0)
        sub = np.nonzero(moving)[0]
        ds = dofs[sub]
        Xs, Ls = (ca.reshape(u[ds.reshape(-1).tolist()], d, len(sub)) for u in (x, lam_x))
        ins = fam.inputs(p, rows[sub])
        dgv = _mapped(fn["dg"], Xs, *ins)
        lxpv = _mapped(fn["lxp"], Xs, Ls, *ins) if exact else [None] * len(sens)
        for k, dv, lv in zip(sens, dgv, lxpv):
            idx = np.asarray(fam.data_index[k])[:, rows[sub]]
            jac.add(sc * ca.vec(dv), *_param_targets(cidx[ds], idx, B, nx))
            if exact:
                hess.add(ca.vec(lv), *_param_targets(ds, idx, B, nx))
    g_stat = sc * ca.densify(gval.build())
    g_stat_j = sc * ca.densify(gval.build(gjac))
    g, g_j = g_stat, g_stat_j
    if nc:  # the muscle constraints: their rows, and J^T kappa in the stationarity rows
        dl = blk.dofs
        xl = x[dl.tolist()]
        C, JTk = blk.val(xl, kap)
        JTk_j, Jnz, Hknz = blk.jac(xl, kap)
        extra, extra_j = _Assembly(nfree, 1), _Assembly(nfree, 1)
        for asm, val in ((extra, JTk), (extra_j, JTk_j)):
            asm.add(val, cidx[dl], np.zeros(blk.d), np.arange(blk.d))
        arow = ca.vertcat(a, ca.MX(blk.n_rigid, 1)) if blk.rope else ca.MX(nc, 1)
        g = ca.vertcat(g_stat + ca.densify(extra.build()), C + arow)
        g_j = ca.vertcat(g_stat_j + ca.densify(extra_j.build()), C + arow)
        jr, jc = np.asarray(blk.J_sp.row()), np.asarray(blk.J_sp.get_col())
        hr, hc = np.asarray(blk.Hk_sp.row()), np.asarray(blk.Hk_sp.get_col())
        jac.add(Hknz, cidx[dl[hr]], dl[hc], np.arange(len(hr)))  # d(J^T kappa)/dx
        jac.add(Jnz, cidx[dl[jc]], ik + jr, np.arange(len(jr)))  # d(J^T kappa)/dkappa = J^T
        jac.add(Jnz, nfree + jr, dl[jc], np.arange(len(jr)))  # dC/dx
        if blk.rope:  # d(C + a)/da on the rope rows
            jac.add(ca.MX(ca.DM.ones(m)), nfree + np.arange(m), nx + np.arange(m), np.arange(m))
        gmap = np.concatenate([dl, ik + np.arange(nc)])
        Hs = blk.H_sp
        lam_l = lam_u[dl.tolist()]
        if exact:
            hess.add(blk.hess(xl, lam_l, kap, lam_g[nfree:]), gmap[np.asarray(Hs.row())],
                     gmap[np.asarray(Hs.get_col())], np.arange(Hs.nnz()))

    fns = {"grad_f": ca.Function("design_grad_f", [z, par], [f, grad_f], ["x", "p"], ["f", "grad"]),
           "jac_g": ca.Function("design_jac_g", [z, par], [g_j, jac.build()],
                                ["x", "p"], ["g", "jac"]),
           "hess_lag": ca.Function("design_hess_lag", [z, par, lam_f, lam_g], [hess.build()],
                                   ["x", "p", "lam_f", "lam_g"], ["hess"])}
    return {"x": z, "p": par, "f": f, "g": g}, fns


# ---------------------------------------------------------------------------------------------- flattened NLP
def _flattened_solver(prob: _Problem, hessian: str, derivatives: str, opts_key: tuple, ipopt_opts: dict):
    """The flattened NLP's solver, cached on the mesh per muscles, muscle model, Hessian mode, derivatives
    and options.

    Parameters of the NLP: target ``y`` (2n), weights (n), ``p0``, objective scale, constraint scale, so one
    built solver serves any target, weights, material numbers and stiffness.

    ``derivatives="assembled"`` gives IPOPT the derivatives assembled term by term
    (:func:`_assembled_nlp`); ``"casadi"`` builds the NLP in SX and lets CasADi differentiate it.
    """
    mesh = prob.mesh
    key = ("design-flattened", tuple(mu.nodes for mu in prob.muscles), prob.muscle_model, prob.material.kind,
           prob.anchor_radius, hessian, derivatives, opts_key)
    cache = mesh.__dict__.setdefault("_design_cache", {})
    if key in cache:
        return cache[key], 0.0
    t0 = time.perf_counter()
    opts = {"print_time": False, "error_on_fail": False, "show_eval_warnings": False}
    opts.update({f"ipopt.{k}": v for k, v in ipopt_opts.items()})
    if derivatives == "assembled":
        nlp, fns = _assembled_nlp(prob, hessian)
        opts.update(fns)
        opts["calc_lam_p"] = False  # parameter multipliers are not used: skip their derivatives
    else:
        nlp, extra = _symbolic_nlp(prob, hessian)
        opts.update(extra)
    solver = ca.nlpsol("design_flattened", "ipopt", nlp, opts)
    bt = time.perf_counter() - t0
    cache[key] = solver
    return solver, bt


def _symbolic_nlp(prob: _Problem, hessian: str):
    """The flattened NLP in SX; CasADi differentiates it (the energy's gradient expanded symbolically)."""
    mesh, model = prob.mesh, prob.model
    n, m = mesh.n_nodes, prob.m
    x = ca.SX.sym("x", 2 * n)
    a = ca.SX.sym("a", m)
    th = ca.SX.sym("theta")
    tt = ca.SX.sym("t", 2)
    y = ca.SX.sym("y", 2 * n)
    w = ca.SX.sym("w", n)
    p0 = ca.SX.sym("p0", model.n_params)
    so = ca.SX.sym("obj_scale")
    sc = ca.SX.sym("con_scale")
    B = sp.csc_matrix(prob.B)
    Bdm = ca.DM(ca.Sparsity(B.shape[0], B.shape[1], B.indptr.tolist(), B.indices.tolist()), B.data.tolist())
    g = model.grad_fn(x, p0 + ca.mtimes(Bdm, a))[1]
    free = np.nonzero(prob.free)[0].tolist()
    blk = prob.block
    kap = ca.SX.sym("kappa", blk.nc)
    G = sc * g[free]
    if blk.nc:  # the muscle constraints, written from MuscleConstraints directly (not from the block)
        mc = prob.constraints
        parts = []
        if blk.rope:
            parts.append(mc.lengths_expr(x) / ca.DM(prob.L0) - 1.0 + a)
        if blk.n_rigid:
            parts.append(mc.rigid_expr(x) * ca.DM(blk.rigid_scale))
        C = ca.vertcat(*parts)
        Ca = C - (ca.vertcat(a, ca.SX(blk.n_rigid, 1)) if blk.rope else 0)  # the part that depends on x
        G = ca.vertcat(G + ca.gradient(ca.dot(kap, Ca), x)[free], C)
    Xm = ca.reshape(x, 2, n)
    Ym = ca.reshape(y, 2, n)
    c, s = ca.cos(th), ca.sin(th)
    rx = c * Xm[0, :] - s * Xm[1, :] + tt[0] - Ym[0, :]
    ry = s * Xm[0, :] + c * Xm[1, :] + tt[1] - Ym[1, :]
    f = so * ca.dot(w, (rx ** 2 + ry ** 2).T)
    z = ca.vertcat(x, a, th, tt, kap)
    par = ca.vertcat(y, w, p0, so, sc)
    extra = {}
    if hessian == "gauss-newton":
        # Hessian of the objective only (constrained Gauss-Newton): no third derivatives of the energy
        lam_f = ca.SX.sym("lam_f")
        lam_g = ca.SX.sym("lam_g", G.numel())
        r = ca.vertcat(ca.vec(rx * ca.sqrt(w).T), ca.vec(ry * ca.sqrt(w).T))
        Jr = ca.jacobian(r, z)
        Hgn = ca.triu(2 * so * lam_f * ca.mtimes(Jr.T, Jr))
        extra["hess_lag"] = ca.Function("design_hess_gn", [z, par, lam_f, lam_g], [Hgn],
                                        ["x", "p", "lam_f", "lam_g"], ["hess"])
    return {"x": z, "p": par, "f": f, "g": G}, extra


def _run_flattened(prob, a0, fwd: _Forward, tol, max_iter, hessian, scaling, warm_start, ipopt_options, clock,
                   derivatives="assembled"):
    mesh, n, m = prob.mesh, prob.mesh.n_nodes, prob.m
    ipopt_opts = {"print_level": 0, "sb": "yes", "tol": tol, "max_iter": max_iter, "mu_strategy": "monotone"}
    ipopt_opts.update(ipopt_options or {})
    solver, bt = _flattened_solver(prob, hessian, derivatives,
                                   tuple(sorted((k, repr(v)) for k, v in ipopt_opts.items())), ipopt_opts)
    t_start = time.perf_counter()
    if warm_start:
        x0, ok, status = fwd.solve(a0)
        if not ok:
            return None, f"warm start failed: {status}", 0, bt
    else:
        x0 = prob.X.copy()
    J0, al0, _ = prob.objective(x0.reshape(-1, 2))
    history = [(clock(), math.sqrt(J0) * prob.h)]
    if scaling == "auto":
        # a target far from reachable has J0 >> 1 (J grows as 1/h^2 under refinement): dividing by it keeps
        # IPOPT's absolute tolerance a relative one (without it a 4k-node design stopped at "acceptable")
        so, sc = 1.0 / (prob.W * prob.h ** 2) / max(1.0, J0), 1.0 / (prob.Et * prob.h)
    else:  # "size": objective normalised by the body's size (the badly scaled variant, for comparisons)
        so, sc = 1.0 / (prob.W * mesh.size ** 2), 1.0 / (prob.Et * prob.h)
    blk = prob.block
    a_start = np.asarray(a0, dtype=float).copy()
    if warm_start and blk.nc:
        # multipliers of the forward equilibrium (least squares); a rope the forward solve left slack
        # starts at the contraction it reached, at zero tension
        gs = prob.model.gradient(x0, prob.params(a_start)) * sc
        kap0 = blk.multipliers(x0, gs, prob.free)
        if blk.rope:
            ach = prob.achieved(x0.reshape(-1, 2))
            slack = ach < a_start - 1e-9
            a_start[slack] = np.clip(ach[slack], 0.0, prob.a_max)
            kap0[:m] = np.maximum(kap0[:m], 0.0)
    else:
        kap0 = np.zeros(blk.nc)
    z0 = np.concatenate([x0, a_start, [al0.angle], al0.t, kap0])
    lbz = np.full(len(z0), -np.inf)
    ubz = np.full(len(z0), np.inf)
    lbz[prob.gauge] = prob.X[prob.gauge]
    ubz[prob.gauge] = prob.X[prob.gauge]
    lbz[2 * n:2 * n + m] = 0.0
    ubz[2 * n:2 * n + m] = prob.a_max
    if blk.rope:  # a rope only pulls: tension >= 0
        lbz[2 * n + m + 3:2 * n + 2 * m + 3] = 0.0
    par = np.concatenate([prob.y.reshape(-1), prob.w, prob.p0, [so, sc]])
    sol = solver(x0=z0, p=par, lbx=lbz, ubx=ubz, lbg=0.0, ubg=0.0)
    st = solver.stats()
    z = np.asarray(sol["x"]).ravel()
    # "Solved_To_Acceptable_Level" means IPOPT could not reach tol: not a success
    ok = bool(st.get("success")) and st.get("return_status") == "Solve_Succeeded"
    iters = int(st.get("iter_count", 0))
    if ok and blk.rope:
        # A slack rope sits on its bound tau = 0 where the interior point method converges slowly (a
        # degenerate bound: its multiplier is about zero too, e.g. when the target is reachable), leaving
        # tensions of ~1e-7 and contractions off by ~1e-6. Polish: fix the near-zero tensions at 0 (their
        # ropes then only measure a = achieved contraction) and solve again from the solution; kept when
        # it converges and the objective is no worse.
        ik = 2 * n + m + 3
        kr = z[ik:ik + m]
        small = kr < 1e-4 * max(1.0, float(kr.max()))
        if small.any():
            lb2, ub2 = lbz.copy(), ubz.copy()
            lb2[ik + np.nonzero(small)[0]] = 0.0
            ub2[ik + np.nonzero(small)[0]] = 0.0
            z2 = z.copy()
            z2[ik + np.nonzero(small)[0]] = 0.0
            sol2 = solver(x0=z2, p=par, lbx=lb2, ubx=ub2, lbg=0.0, ubg=0.0)
            st2 = solver.stats()
            iters += int(st2.get("iter_count", 0))
            if st2.get("return_status") == "Solve_Succeeded" and \
                    float(sol2["f"]) <= float(sol["f"]) * (1 + 1e-6) + 1e-14:
                z = np.asarray(sol2["x"]).ravel()
    out = {"x": z[:2 * n], "a": np.clip(z[2 * n:2 * n + m], 0.0, prob.a_max), "success": ok,
           "kappa": z[2 * n + m + 3:],
           "status": str(st.get("return_status", "unknown")), "iterations": iters,
           "history": history, "initial_difference": math.sqrt(J0) * prob.h, "t_start": t_start}
    return out, out["status"], out["iterations"], bt


# ---------------------------------------------------------------------------------------------- outer loops
class _Outer:
    """Objective of the reduced problem ``a -> J(x*(a))`` with a record of every evaluation."""

    def __init__(self, prob: _Problem, fwd: _Forward, clock: Callable[[], float], penalty: float = 1e6):
        self.prob, self.fwd, self.clock = prob, fwd, clock
        self.penalty = penalty
        self.history: list[tuple[float, float]] = []
        self.best: tuple[float, np.ndarray, np.ndarray] | None = None
        self.failures: list[str] = []
        self.n_eval = 0

    def _eval(self, a):
        a = np.clip(np.asarray(a, dtype=float), 0.0, self.prob.a_max)
        x, ok, status = self.fwd.solve(a)
        self.n_eval += 1
        if not ok:
            self.failures.append(status)
            return None, a, x, None, None
        J, al, dJ = self.prob.objective(x.reshape(-1, 2))
        if self.best is None or J < self.best[0]:
            self.best = (J, a.copy(), x.copy())
        self.history.append((self.clock(), math.sqrt(self.best[0]) * self.prob.h))
        return J, a, x, al, dJ

    def value(self, a) -> float:
        J, *_ = self._eval(a)
        return self.penalty if J is None else J

    def value_and_grad(self, a):
        J, a, x, _al, dJ = self._eval(a)
        if J is None:
            raise _ForwardFailed(self.failures[-1])
        return J, _reduced_gradient(self.prob, a, x, dJ)


class _ForwardFailed(RuntimeError):
    pass


def _reduced_gradient(prob: _Problem, a, x, dJ) -> np.ndarray:
    """``dJ/da`` at an equilibrium ``x`` of contractions ``a`` by the implicit-function theorem.

    The equilibrium solves ``F(x, kappa; a) = [sc grad E(x, a) + J_C(x)^T kappa ; C(x) + E a] = 0`` on the
    free dofs, with the active muscle constraints (the rigid end patches; the cable's taut ropes; a slack
    rope's row drops out, and so does its contraction's influence). One adjoint solve with the symmetric
    KKT matrix ``K = [[H, A^T], [A, 0]]`` (``H`` the Hessian of the Lagrangian) gives
    ``dJ/da = -lambda^T dF/da`` with ``K lambda = [dJ/dx ; 0]``. Without constraints ``K = H``.
    """
    free = prob.free
    sc = 1.0 / (prob.Et * prob.h)
    p = prob.params(a)
    H = prob.model.hessian(x, p) * sc
    blk = prob.block
    dFa = sc * prob.dg_da(x)[free]
    if blk.nc:
        kap = blk.multipliers(x, prob.model.gradient(x, p) * sc, free)
        act = np.ones(blk.nc, dtype=bool)
        if blk.rope:
            act[:prob.m] = kap[:prob.m] > 1e-9 * max(1.0, float(np.abs(kap).max()))
        H = (H + blk.hessian(x, kap)).tocsr()
        A = blk.jacobian(x)[np.nonzero(act)[0]][:, np.nonzero(free)[0]]
        K = sp.bmat([[H[free][:, free], A.T], [A, None]]).tocsc()
        Ea = np.zeros((blk.nc, prob.m))
        if blk.rope:
            Ea[:prob.m] = np.eye(prob.m)
        dFa = np.vstack([dFa, Ea[act]])
        rhs = np.concatenate([dJ[free], np.zeros(int(act.sum()))])
    else:
        K = H[free][:, free].tocsc()
        rhs = dJ[free]
    lam = spla.spsolve(K, rhs)
    return -(dFa.T @ lam)


def _run_nested(prob, a0, fwd, tol, max_iter, outer_options, clock):
    from scipy.optimize import minimize

    obj = _Outer(prob, fwd, clock)
    opts = {"maxiter": max_iter, "ftol": tol ** 2, "gtol": tol}
    opts.update(outer_options or {})
    try:
        res = minimize(obj.value_and_grad, a0, jac=True, method="L-BFGS-B",
                       bounds=[(0.0, prob.a_max)] * prob.m, options=opts)
    except _ForwardFailed as exc:
        return obj, False, f"forward solve failed: {exc}", obj.n_eval
    return obj, bool(res.success), f"L-BFGS-B: {res.message}", int(res.nit)


def _run_derivative_free(prob, a0, fwd, tol, max_iter, outer, outer_options, clock):
    from scipy.optimize import minimize

    obj = _Outer(prob, fwd, clock)
    bounds = [(0.0, prob.a_max)] * prob.m
    if outer == "nelder-mead":
        opts = {"maxfev": max_iter, "maxiter": max_iter, "xatol": tol, "fatol": tol ** 2, "adaptive": prob.m > 2}
        opts.update(outer_options or {})
        res = minimize(obj.value, a0, method="Nelder-Mead", bounds=bounds, options=opts)
    else:
        opts = {"maxfev": max_iter, "xtol": tol, "ftol": tol ** 2}
        opts.update(outer_options or {})
        res = minimize(obj.value, a0, method="Powell", bounds=bounds, options=opts)
    ok = bool(res.success) and not obj.failures
    status = f"{'Nelder-Mead' if outer == 'nelder-mead' else 'Powell'}: {res.message}"
    if obj.failures:
        status += f"; {len(obj.failures)} forward solve(s) failed ({obj.failures[-1]})"
    return obj, ok, status, int(res.nit)


# ---------------------------------------------------------------------------------------------- public API
def design_contractions(mesh: Mesh, material, muscles: Sequence[Muscle], target: ArrayLike, *,
                        method: str = "flattened", a_max: float = 0.6, initial: ArrayLike | None = None,
                        weights: ArrayLike | None = None, interior_weight: float = 0.5,
                        muscle_model: str = "cable", stiffness: float = 10.0, anchor_radius: float | None = None,
                        tol: float | None = None,
                        max_iter: int | None = None, hessian: str = "exact", scaling: str = "auto",
                        warm_start: bool = True, outer: str = "nelder-mead", options: dict | None = None,
                        inner_tol: float = 1e-10, verify: bool = True, gap_rtol: float = 1e-5,
                        derivatives: str = "assembled") -> DesignResult:
    """Find the contractions that make the muscle-driven body match ``target`` after rigid alignment.

    Parameters
    ----------
    mesh, material : the body.
    muscles : sequence of Muscle (or node lists), at least one, along mesh edges.
    target : (n, 2) array
        Target node positions, in any pose (only the shape matters).
    method : {"flattened", "nested", "derivative-free"}
        See the module docstring.
    a_max : float, default 0.6
        Upper bound on every contraction, in ``(0, 1)``.
    initial : (m,) array, optional
        Starting contractions; default: each muscle's geometric contraction ``1 - L_target / L_rest``
        clipped to ``[0, 0.9 a_max]``.
    weights : (n,) array, optional
        Node weights ``e_i``; default :func:`~mdsr_opt.align.node_weights` with ``interior_weight``.
    interior_weight : float in [0.3, 0.7], default 0.5
    muscle_model : {"cable", "springs"}, default "cable"
        As in :func:`~mdsr_opt.solve_internal`: the exact rope (its path length is ``(1 - a) L0``, its
        tension a multiplier) or the paper's per-segment dummy springs.
    stiffness : float, default 10
        Muscle spring stiffness relative to ``E t`` (springs only).
    anchor_radius : float, optional
        Radius of the rigid patch at each muscle end (a length, >= 0); default
        :func:`~mdsr_opt.muscle_constraints.default_anchor_radius` (a fraction of the body's size).
    tol : float, optional
        Optimiser tolerance: IPOPT's ``tol`` (flattened, default 1e-10), the projected-gradient tolerance
        (nested, default 1e-10), the tolerance on ``a`` (derivative-free, default 1e-7).
    max_iter : int, optional
        IPOPT iterations (default 500), L-BFGS-B iterations (default 500), or function evaluations
        (derivative-free, default ``400 * m``).
    hessian : {"exact", "gauss-newton"}
        Flattened only: the exact Hessian of the Lagrangian, or the objective's Gauss-Newton Hessian.
    scaling : {"auto", "size"}
        Flattened only: objective over ``sum(e) h^2`` and constraints over ``E t h`` (``h`` the mean edge
        length), or the objective normalised by the body's size instead (for comparison studies).
    warm_start : bool
        Flattened only: start from a forward solve at ``initial`` (else from the rest shape).
    derivatives : {"assembled", "casadi"}
        Flattened only: give IPOPT the NLP's exact derivatives assembled term by term from small per-term
        functions (fast to build, linear in the mesh size), or build the NLP in SX and let CasADi
        differentiate it (the reference; slow to build). Both are exact; iterates agree to rounding.
    outer : {"nelder-mead", "powell"}
        Derivative-free only: the scipy method.
    options : dict, optional
        Extra options for IPOPT (flattened, without the ``ipopt.`` prefix) or scipy's ``minimize``.
    inner_tol : float
        IPOPT tolerance of the forward solves.
    verify : bool
        Run :func:`verify_design` (recommended; without it ``success`` reflects the optimiser only).
    gap_rtol : float
        Verification tolerance on the state gap, relative to ``mesh.size``.

    Returns
    -------
    DesignResult

    Raises
    ------
    TypeError, ValueError
        Bad input: target of the wrong shape, muscles not on the mesh, ``a_max`` outside (0, 1), an empty
        muscle list, an unknown method.

    Example
    -------
    >>> import numpy as np
    >>> from mdsr_opt import Mesh, Muscle, NeoHookean
    >>> mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    >>> stretched = mesh.points * 1.1                     # muscles cannot stretch a body
    >>> res = design_contractions(mesh, NeoHookean(1.0, 0.3), [Muscle(range(1, 16))], stretched)
    >>> res.success, res.difference > 0.01
    (True, True)
    """
    clock0 = time.perf_counter()
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(map(repr, METHODS))}, got {method!r}")
    if hessian not in ("exact", "gauss-newton"):
        raise ValueError(f"hessian must be 'exact' or 'gauss-newton', got {hessian!r}")
    if scaling not in ("auto", "size"):
        raise ValueError(f"scaling must be 'auto' or 'size', got {scaling!r}")
    if outer not in ("nelder-mead", "powell"):
        raise ValueError(f"outer must be 'nelder-mead' or 'powell', got {outer!r}")
    if derivatives not in ("assembled", "casadi"):
        raise ValueError(f"derivatives must be 'assembled' or 'casadi', got {derivatives!r}")
    mus, y, a_max, w, stiffness, a0 = _check_inputs(mesh, material, muscles, target, a_max, weights,
                                                    interior_weight, muscle_model, stiffness, initial)
    anchor_radius = check_anchor_radius(mesh, anchor_radius)
    m = len(mus)
    if tol is None:
        tol = {"flattened": 1e-10, "nested": 1e-10, "derivative-free": 1e-7}[method]
    tol = positive_float(tol, "tol")
    if max_iter is None:
        max_iter = 400 * m if method == "derivative-free" else 500
    if isinstance(max_iter, bool) or not isinstance(max_iter, (int, np.integer)) or max_iter < 1:
        raise ValueError(f"max_iter must be a positive integer, got {max_iter!r}")
    inner_tol = positive_float(inner_tol, "inner_tol")
    gap_rtol = positive_float(gap_rtol, "gap_rtol")
    if a0 is None:
        a0 = _initial_guess(mesh, mus, y, a_max)

    prob = _Problem(mesh, material, mus, y, w, muscle_model, stiffness, a_max, anchor_radius)
    fwd = _Forward(prob, inner_tol, 200)
    t_solve0 = time.perf_counter()

    def clock():
        return time.perf_counter() - t_solve0

    build_time = prob.build_time
    bt = 0.0
    if method == "flattened":
        out, status, iters, bt = _run_flattened(prob, a0, fwd, tol, int(max_iter), hessian, scaling, warm_start,
                                                options, clock, derivatives)
        build_time += bt
        kappa = None
        if out is None:
            x, a, ok, hist, d0 = fwd.x, a0, False, [], float("nan")
        else:
            x, a, ok, hist, d0 = out["x"], out["a"], out["success"], out["history"], out["initial_difference"]
            kappa = out["kappa"]
    else:
        if method == "nested":
            obj, ok, status, iters = _run_nested(prob, a0, fwd, tol, int(max_iter), options, clock)
        else:
            obj, ok, status, iters = _run_derivative_free(prob, a0, fwd, tol, int(max_iter), outer, options, clock)
        hist = obj.history
        kappa = None
        d0 = hist[0][1] if hist else float("nan")
        if obj.best is None:
            x, a, ok = fwd.x, a0, False
        else:
            _J, a, x = obj.best
    build_time += fwd.build_time
    x2 = x.reshape(-1, 2)
    al_rest = align(x2, mesh.points)
    x_rest = al_rest.apply(x2)
    al = align(x_rest, y, w)
    t_end = time.perf_counter()
    if method == "flattened":  # seconds of solving: the NLP's build is not part of the trace
        hist = [(t - bt, d) for t, d in hist] + [(t_end - t_solve0 - bt, al.difference)]
    total = t_end - clock0
    res = DesignResult(method=method, contractions=np.asarray(a, dtype=float).copy(), x=x_rest, rotation=al.R,
                       translation=al.t, difference=al.difference, success=bool(ok), status=status,
                       iterations=int(iters), n_forward=fwd.n_solves, inner_iterations=fwd.iterations,
                       build_time=build_time, solve_time=total - build_time, time=total,
                       initial_contractions=np.asarray(a0, dtype=float).copy(), initial_difference=float(d0),
                       a_max=a_max, muscle_model=muscle_model, stiffness=stiffness, history=list(hist),
                       anchor_radius=prob.anchor_radius, rest_lengths=prob.L0.copy())
    _report_muscles(prob, res, x, kappa)
    if not np.all(np.isfinite(res.x)) or mesh.jacobians(res.x).min() <= 0:
        res.success = False
        res.status += "; rejected: the design's state inverts an element"
    if verify:
        v = verify_design(mesh, material, mus, res, y, weights=w, gap_rtol=gap_rtol)
        res.verification = v
        if res.success and not v.passed:
            res.success = False
            res.status += f"; rejected by verification: {v.message}"
    return res


def _report_muscles(prob: _Problem, res: DesignResult, xflat, kappa) -> None:
    """Fill the per-muscle fields of ``res``: achieved contraction, stroke, tension, slack."""
    x2 = np.asarray(xflat, dtype=float).reshape(-1, 2)
    if not np.all(np.isfinite(x2)):
        return
    res.achieved = prob.achieved(x2)
    res.stroke = res.achieved * prob.L0
    try:
        if kappa is not None and prob.muscle_model == "cable":  # the NLP's own multipliers
            res.tension = prob.block.tension(kappa)
        else:
            res.tension = prob.tensions(res.contractions, x2.reshape(-1))
    except (RuntimeError, ValueError):  # pragma: no cover - singular least squares
        res.tension = np.full(prob.m, np.nan)
    tiny = 1e-7 * prob.Et * prob.h
    res.slack = res.tension <= tiny


def check_minimum(mesh: Mesh, material, muscles: Sequence[Muscle], contractions: ArrayLike, x: ArrayLike, *,
                  muscle_model: str = "cable", stiffness: float = 10.0,
                  anchor_radius: float | None = None, lowest: bool = True) -> tuple[bool, float, float]:
    """Is ``x`` a strict minimum of the internal-driving energy (rigid gauge pinned)?

    With muscle constraints (the exact cable's taut ropes, the rigid anchor patches) the test is on the
    Hessian of the Lagrangian restricted to the tangent space of the active constraints.

    Returns ``(positive_definite, min_eigenvalue, residual)``: whether the (reduced) free-coordinate Hessian
    is positive definite, from the inertia of a sparse symmetric factorisation
    (:func:`~mdsr_opt.stability.check_stability`, no eigen-solve of the Hessian); its smallest eigenvalue
    relative to ``E t`` (when positive definite an estimate by LOBPCG preconditioned by the factor; else the
    curvature along the direction of most negative curvature found, an upper bound); and the max-norm of the
    free gradient of the Lagrangian relative to ``E t size``. With ``lowest=False`` the eigenvalue estimate
    is skipped when the state is positive definite (NaN returned; the inertia alone decides, 30-100x cheaper
    at thousands of nodes).

    Example
    -------
    >>> from mdsr_opt import Mesh, NeoHookean, Muscle, solve_internal
    >>> mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
    >>> res = solve_internal(mesh, NeoHookean(1.0, 0.3), [Muscle(range(0, 9))], [0.2])
    >>> pd, lam, r = check_minimum(mesh, NeoHookean(1.0, 0.3), [Muscle(range(0, 9))], [0.2], res.x)
    >>> pd, lam > 0, r < 1e-6
    (True, True, True)
    """
    _check_mesh_material(mesh, material)
    mus = check_muscles(mesh, muscles)
    if not mus:
        raise ValueError("check_minimum needs at least one muscle")
    if muscle_model not in ("springs", "cable"):
        raise ValueError(f"muscle_model must be 'springs' or 'cable', got {muscle_model!r}")
    a = as_float_array(np.atleast_1d(contractions), "contractions", shape=(len(mus),))
    x = mesh._check_state(x)
    prob = _Problem(mesh, material, mus, x, np.ones(mesh.n_nodes), muscle_model, stiffness, 0.99,
                    anchor_radius=anchor_radius)
    return _stability(prob, a, x.reshape(-1), lowest=bool(lowest))


def _stability(prob: _Problem, a, xflat, lowest: bool = True) -> tuple[bool, float, float]:
    """``(positive_definite, min_eigenvalue / (E t), residual)`` at ``xflat`` (see :func:`check_minimum`).

    The gauge coordinates are pinned (the energy is invariant under rigid motion); with muscle constraints
    the Hessian is the Lagrangian's with least-squares multipliers, on the tangent space of the active
    rows (:meth:`_Problem.kkt_data`, in units of ``E t h``)."""
    H, free, A, _kap, res = prob.kkt_data(a, xflat)
    chk = check_stability(H, free, A, lowest=lowest)
    lam = float(chk.curvature) * prob.h if chk.curvature is not None else (0.0 if not chk.stable else np.nan)
    return bool(chk.stable), lam, res * prob.h / prob.mesh.size


def verify_design(mesh: Mesh, material, muscles: Sequence[Muscle], result: DesignResult, target: ArrayLike, *,
                  weights: ArrayLike | None = None, gap_rtol: float = 1e-5, anchors=None,
                  drags=None, lowest: bool = False) -> Verification:
    """Check a design independently of how it was found.

    Solves the forward internal-driving problem from rest at ``result.contractions``
    (:func:`~mdsr_opt.solve_internal`), measures the largest node distance between that state and
    ``result.x`` after rigid alignment, and checks that ``result.x`` is a strict minimum of the energy
    (:func:`check_minimum`). Passes when the forward solve succeeded, the gap is at most
    ``gap_rtol * mesh.size`` and the (reduced) Hessian is positive definite.

    When the target came from external driving, give its ``anchors`` and ``drags`` (as in
    :func:`~mdsr_opt.solve_external`): the target must then also be a stable equilibrium of that driving
    (:func:`~mdsr_opt.equilibrium.external_stability`), since a saddle (e.g. an unbuckled compressed strip)
    is a shape no body holds; ``target_stable`` reports it.

    The minimum test is the inertia of one sparse factorisation; ``lowest=True`` also estimates the smallest
    eigenvalue of a positive definite state (``min_eigenvalue``, NaN otherwise), an eigen-solve that costs
    30-100x the inertia at thousands of nodes.

    Example
    -------
    >>> from mdsr_opt import Mesh, Muscle, NeoHookean, solve_internal
    >>> mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    >>> mat, mus = NeoHookean(1.0, 0.3), [Muscle(range(1, 16))]
    >>> target = solve_internal(mesh, mat, mus, [0.1]).x
    >>> res = design_contractions(mesh, mat, mus, target, verify=False)
    >>> verify_design(mesh, mat, mus, res, target).passed
    True
    """
    t0 = time.perf_counter()
    _check_mesh_material(mesh, material)
    mus = check_muscles(mesh, muscles)
    y = as_float_array(target, "target", shape=(mesh.n_nodes, 2))
    w = node_weights(mesh) if weights is None else as_float_array(weights, "weights", shape=(mesh.n_nodes,))
    if not isinstance(result, DesignResult):
        raise TypeError(f"result must be a DesignResult, got {type(result).__name__}")
    a = np.asarray(result.contractions, dtype=float)
    x = mesh._check_state(result.x)
    radius = getattr(result, "anchor_radius", None)
    radius = None if radius is None or not np.isfinite(radius) else float(radius)
    target_check = None
    if anchors is not None or drags is not None:  # checked first: cheap, and bad anchors/drags fail before any solve
        target_check, target_residual = external_stability(mesh, material, anchors, drags, y)
    prob = _Problem(mesh, material, mus, y, w, result.muscle_model, result.stiffness, 0.99, anchor_radius=radius)
    gap_tol = gap_rtol * mesh.size
    fwd = solve_internal(mesh, material, mus, np.clip(a, 0.0, 0.999), model=result.muscle_model,
                         stiffness=result.stiffness, anchor_radius=radius, tol=1e-10)
    fx = fwd.x
    al = align(x, fx)
    gap = float(np.linalg.norm(al.apply(x) - fx, axis=1).max())
    fdiff = align(fx, y, w).difference
    # the design's own state, expressed in the gauge frame used by the model
    xg = x.reshape(-1)
    pd, lam, residual = _stability(prob, a, xg, lowest=bool(lowest))
    msgs = []
    if not fwd.success:
        msgs.append(f"forward re-solve failed ({fwd.status})")
    if not np.isfinite(gap) or gap > gap_tol:
        msgs.append(f"gap {gap:.3g} between the design's state and the forward re-solve exceeds {gap_tol:.3g}")
    if not pd:
        msgs.append(f"the design's state is not a minimum of the energy (a saddle: curvature {lam:.3g} E t "
                    f"along its direction of negative curvature)")
    if target_check is not None and not target_check.stable:
        msgs.append(f"the target is not a stable equilibrium of its external driving ({target_check.n_negative} "
                    f"direction(s) of negative curvature, {target_check.n_zero} zero)")
    if target_check is not None and target_residual > 1e-5:
        msgs.append(f"the target is not an equilibrium of its external driving (residual {target_residual:.3g})")
    return Verification(passed=not msgs, gap=gap, gap_tol=gap_tol, forward_success=bool(fwd.success),
                        forward_status=fwd.status, forward_difference=float(fdiff), residual=residual,
                        positive_definite=bool(pd), min_eigenvalue=lam, message="; ".join(msgs),
                        time=time.perf_counter() - t0,
                        target_stable=None if target_check is None else bool(target_check.stable))


# ---------------------------------------------------------------------------------------------- the pipeline
@dataclass
class PipelineResult:
    """The whole design pipeline: target by external driving, routed muscles, contractions, verification.

    Attributes
    ----------
    mesh : Mesh
    material : NeoHookean or LinearElastic
    anchors : (k,) int ndarray
    drag_nodes, drag_positions : (d,) int and (d, 2) float ndarrays
    target : (n, 2) ndarray
        The external-driving equilibrium the design aims at.
    external : dict
        Summary of the external-driving solve (:meth:`EquilibriumResult.summary`).
    muscles : tuple of Muscle
    routing : dict or None
        Routing knobs and per-muscle figures (None when muscles were given).
    design : DesignResult
    times : dict
        Seconds per stage (``external``, ``routing``, ``design``, ``total``).
    """

    mesh: Mesh
    material: Any
    anchors: np.ndarray
    drag_nodes: np.ndarray
    drag_positions: np.ndarray
    target: np.ndarray
    external: dict
    muscles: tuple
    routing: dict | None
    design: DesignResult
    times: dict = field(default_factory=dict)

    @property
    def success(self) -> bool:
        """The design succeeded and was verified."""
        return bool(self.design.success)

    @property
    def contractions(self) -> np.ndarray:
        return self.design.contractions

    def save(self, directory) -> str:
        """Write ``design.json`` and the meshes ``target.vtu`` and ``driven.vtu`` (states as displacements)
        into ``directory`` (created if missing), each atomically. Returns the JSON path."""
        from .io import write_json, write_mesh

        directory = os.fspath(directory)
        if not str(directory).strip():
            raise ValueError("directory is empty: give a folder name")
        if os.path.exists(directory) and not os.path.isdir(directory):
            raise ValueError(f"{directory} is an existing file, not a folder")
        os.makedirs(directory, exist_ok=True)
        write_mesh(os.path.join(directory, "target.vtu"), self.mesh, x=self.target, material=self.material)
        write_mesh(os.path.join(directory, "driven.vtu"), self.mesh, x=self.design.x_aligned,
                   material=self.material)
        mat = self.material
        data = {
            "format": "mdsr_opt.design/1",
            "material": {"kind": mat.kind, "E": mat.E, "nu": mat.nu, "thickness": mat.thickness},
            "anchors": self.anchors.tolist(), "drag_nodes": self.drag_nodes.tolist(),
            "drag_positions": self.drag_positions.tolist(), "external": self.external,
            "muscles": [{"nodes": list(mu.nodes), "name": mu.name} for mu in self.muscles],
            "routing": self.routing, "design": self.design.to_dict(), "times": self.times,
            "meshes": {"target": "target.vtu", "driven": "driven.vtu"},
        }
        return write_json(os.path.join(directory, "design.json"), _finite_or_none(data))

    @classmethod
    def load(cls, directory) -> "PipelineResult":
        """Read a result written by :meth:`save`.

        Raises
        ------
        FileNotFoundError
            ``directory``, its ``design.json`` or a mesh file it names does not exist.
        ValueError
            ``directory`` is a file; ``design.json`` is not valid JSON, not a design result, or damaged (a
            field missing or of the wrong kind, named); a mesh file cannot be read or does not match.
        """
        import json

        from .io import read_mesh
        from .material import LinearElastic, NeoHookean

        directory = os.fspath(directory)
        if not os.path.exists(directory):
            raise FileNotFoundError(f"no such design result folder: {directory}")
        if not os.path.isdir(directory):
            raise ValueError(f"{directory} is a file; PipelineResult.load takes the folder written by save()")
        path = os.path.join(directory, "design.json")
        if not os.path.exists(path):
            raise FileNotFoundError(f"no design.json in {directory}")
        try:
            with open(path, encoding="utf-8") as fh:
                data = json.load(fh)
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ValueError(f"{path} is damaged: not valid JSON ({exc})") from None
        if not isinstance(data, dict) or data.get("format") != "mdsr_opt.design/1":
            fmt = data.get("format") if isinstance(data, dict) else None
            raise ValueError(f"{path} is not a mdsr_opt design result (format {fmt!r})")
        field_ = "meshes.target"
        try:
            mpath = os.path.join(directory, data["meshes"]["target"])
            if not os.path.exists(mpath):
                raise FileNotFoundError(f"{path}: the target mesh {mpath} is missing")
            md = read_mesh(mpath)
            field_ = "material"
            m = data["material"]
            kinds = {NeoHookean.kind: NeoHookean, LinearElastic.kind: LinearElastic}
            if m["kind"] not in kinds:
                raise ValueError(f"unknown material kind {m['kind']!r}")
            material = kinds[m["kind"]](m["E"], m["nu"], m["thickness"])
            field_ = "muscles"
            muscles = tuple(Muscle(tuple(mu["nodes"]), name=mu.get("name")) for mu in data["muscles"])
            for mu in muscles:
                mu.check_on(md.mesh)
            field_ = "anchors/drags"
            kw = dict(anchors=np.asarray(data["anchors"], dtype=np.int64),
                      drag_nodes=np.asarray(data["drag_nodes"], dtype=np.int64),
                      drag_positions=np.asarray(data["drag_positions"], dtype=float).reshape(-1, 2))
            field_ = "design"
            design = DesignResult.from_dict(data["design"])
            if design.x.shape != md.x.shape:
                raise ValueError(f"the design's state has shape {design.x.shape}, the mesh {md.x.shape}")
            field_ = "external/routing/times"
            return cls(mesh=md.mesh, material=material, target=md.x, external=data["external"],
                       muscles=muscles, routing=data["routing"], design=design, times=data.get("times", {}), **kw)
        except FileNotFoundError:
            raise
        except KeyError as exc:
            raise ValueError(f"{path} is damaged: field {exc.args[0]!r} is missing (in {field_})") from None
        except (TypeError, ValueError, AttributeError, IndexError) as exc:
            raise ValueError(f"{path} is damaged ({field_}): {exc}") from None


def design(mesh: Mesh, material, anchors, drags, *, muscles: Sequence[Muscle] | None = None,
           routing_options: dict | None = None, method: str = "flattened", external_options: dict | None = None,
           **design_options) -> PipelineResult:
    """The whole pipeline in one call: external driving -> muscle routing -> contractions -> verification.

    Parameters
    ----------
    mesh, material : the body.
    anchors, drags : as in :func:`~mdsr_opt.solve_external`; their equilibrium is the target shape.
    muscles : optional
        Use these muscles instead of routing them.
    routing_options : dict, optional
        Keyword arguments for :func:`~mdsr_opt.routing.route_muscles` (``K_a``, ``K_b``, ``max_muscles``...).
    method : str
        The design method (see :func:`design_contractions`).
    external_options : dict, optional
        Keyword arguments for :func:`~mdsr_opt.solve_external` (``backend``, ``tol``...).
    **design_options
        Passed to :func:`design_contractions` (``a_max``, ``muscle_model`` (default ``"cable"``, the exact
        rope), ``anchor_radius``, ``stiffness``...). ``.design`` reports per muscle the commanded and achieved
        contraction, the stroke (rope length pulled in) and the tension.

    Returns
    -------
    PipelineResult
        ``.design`` holds contractions, driven state, alignment, difference and verification; ``.save(dir)``
        writes JSON plus meshes and :meth:`PipelineResult.load` reads them back.

    Raises
    ------
    SolverFailure
        The external-driving solve (the target) failed.
    ValueError
        Routing found no muscle (e.g. a target that only stretches the body), or bad input.

    Example
    -------
    >>> from mdsr_opt import Mesh, NeoHookean
    >>> mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    >>> left = [i for i, (x, y) in enumerate(mesh.points) if x == 0.0]
    >>> top_right = {i: (x - 0.3, y - 0.4) for i, (x, y) in enumerate(mesh.points) if x == 4.0}
    >>> out = design(mesh, NeoHookean(1.0, 0.3), left, top_right)
    >>> out.success, out.design.difference < 0.05
    (True, True)
    """
    from .equilibrium import _parse_drags, solve_external

    t0 = time.perf_counter()
    _check_mesh_material(mesh, material)
    ext = solve_external(mesh, material, anchors, drags, **(external_options or {}))
    ext.raise_on_failure()
    t1 = time.perf_counter()
    anc = np.asarray([] if anchors is None else anchors, dtype=np.int64).reshape(-1)
    didx, dpos = _parse_drags(drags, mesh.n_nodes)
    routing = None
    if muscles is None:
        from .routing import route_muscles

        rr = route_muscles(mesh, ext.x, **(routing_options or {}))
        mus = tuple(rr.muscles)
        if not mus:
            raise ValueError("routing found no muscle for this target (muscles can only contract: does the "
                             "target shorten any edge?); pass muscles=... or relax routing_options")
        routing = {"params": dict(rr.params), "stats": [asdict(s) for s in rr.stats], "n_units": rr.n_units}
    else:
        mus = tuple(check_muscles(mesh, muscles))
    t2 = time.perf_counter()
    res = design_contractions(mesh, material, mus, ext.x, method=method, **design_options)
    t3 = time.perf_counter()
    return PipelineResult(mesh=mesh, material=material, anchors=anc, drag_nodes=didx, drag_positions=dpos,
                          target=ext.x.copy(), external=ext.summary(), muscles=mus, routing=routing, design=res,
                          times={"external": t1 - t0, "routing": t2 - t1, "design": t3 - t2, "total": t3 - t0})


#: The pipeline under a name that does not clash with the module ``mdsr_opt.design`` at package level.
design_pipeline = design
