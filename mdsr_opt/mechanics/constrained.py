"""An energy model whose minimisation carries muscle constraints (exact cable ropes, rigid anchor patches).

:class:`ConstrainedModel` wraps an :class:`~mdsr_opt.mechanics.model.EnergyModel` and a
:class:`~mdsr_opt.mechanics.constraints.MuscleConstraints` with the interface the load-stepping loop of
:mod:`mdsr_opt.mechanics.equilibrium` uses (``energy``, ``gradient``, ``hessian``, ``solver``, ``predict``), so that
:func:`mdsr_opt.mechanics.backends.minimize` solves ``min E(x)`` subject to the constraints. Its parameter vector
carries the rope targets (they move with the load fraction) and multipliers (for the Lagrangian's gradient
and Hessian, e.g. the KKT residual and the stability check of a result).
"""

from __future__ import annotations

import time
import weakref

import casadi as ca
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .anchors import body_size
from .assembly import BufferedFunction, SparseLayout
from .constraints import MuscleConstraints
from .kkt import kkt_factor, least_squares_multipliers
from .loadsteps import min_jacobian
from .model import to_dm
from .ropesolve import projecting

__all__ = ["ConstrainedModel"]


class ConstrainedModel:
    """An :class:`~mdsr_opt.mechanics.model.EnergyModel` whose minimisation carries muscle constraints.

    The objective is the model's energy; the constraints are the rigid anchor rows of ``constraints`` and,
    with ``ropes=True`` (the exact cable), one rope row per muscle, ``L_c(x) <= target_c``. The parameter
    vector is ``p = [energy params, rope targets (n_targets), multipliers (n_rows)]``: the multipliers enter
    :meth:`gradient` and :meth:`hessian`, which are those of the Lagrangian
    ``E(x) + sum_i lam_i g_i(x)`` (with zero multipliers, those of the energy), so a KKT point has zero
    :meth:`gradient` on the free coordinates. :func:`mdsr_opt.mechanics.backends.minimize` recognises this class and
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
        # the NLP sees dimensionless rows (ropes over L0, rigid rows over the body size), so the solver's
        # absolute tolerances mean the same on a body in metres as in millimetres
        scale = np.full(self.n_rows, 1.0 / body_size(model.mesh))
        if self.n_targets:
            scale[:self.n_targets] = 1.0 / mc.rest_lengths
        self.row_scale = scale
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

    def bounds(self, p, equality_ropes=False, released=None) -> tuple[np.ndarray, np.ndarray]:
        """``(lbg, ubg)`` of the NLP's constraint rows: ropes ``<= target`` (``== target`` when
        ``equality_ropes``: True for all, or a bool per rope; unbounded where the bool mask ``released``
        is True), rigid rows ``== 0``."""
        _, targets, _ = self.split(p)
        lb = np.zeros(self.n_rows)
        ub = np.zeros(self.n_rows)
        if self.n_targets:
            ub[:self.n_targets] = targets
            lb[:self.n_targets] = np.where(equality_ropes, targets, -np.inf)
            if released is not None:
                ub[:self.n_targets][released] = np.inf
                lb[:self.n_targets][released] = -np.inf
        return lb, ub

    # ------------------------------------------------------------------ numeric evaluation
    def values(self, x) -> np.ndarray:
        """The NLP's constraint rows at ``x``."""
        v = self.constraints.values(x)
        return v if self.ropes else v[self.rows]

    def short_ropes(self, x, p, rtol: float = 1e-7) -> np.ndarray:
        """Ropes shorter than their targets at ``x`` by more than ``rtol * L0``: (n_targets,) bool.

        Such a rope is slack there, unless the body stretches it back to its target."""
        if not self.n_targets:
            return np.zeros(0, dtype=bool)
        _, targets, _ = self.split(p)
        return self.values(x)[:self.n_targets] < targets - rtol * self.constraints.rest_lengths

    def jacobian(self, x) -> sp.csr_matrix:
        J = self.constraints.jacobian(x)
        return J if self.ropes else J[self.rows]

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
        """The rows (physical units: lengths) as a CasADi column."""
        g = self.constraints.constraints_expr(x)
        return g if self.ropes else g[self.constraints.n_muscles:]

    def nlp_constraints_expr(self, x):
        """The rows as the NLP sees them: multiplied by :attr:`row_scale` (dimensionless)."""
        return self.constraints_expr(x) * ca.DM(self.row_scale)

    def nlp_jacobian_expr(self, x):
        """The Jacobian (n_rows, n_dof) of :meth:`nlp_constraints_expr` as a sparse CasADi expression of ``x``.

        The nonlinear rows are differentiated on the local coordinates (an SX function of a few hundred
        inputs), the linear rows are a constant matrix. Given to IPOPT as ``jac_g`` it spares ``nlpsol`` its
        own differentiation through the MX graph (a quicker build), with the same iterates to rounding."""
        mc = self.constraints
        nl, P, Lin = mc.symbolic_parts()
        R = sp.diags(self.row_scale) @ sp.identity(mc.n_constraints, format="csr")[self.rows]
        xl = ca.SX.sym("xl", mc.n_local)
        Jl = ca.mtimes(to_dm(R @ P), ca.jacobian(nl(xl), xl)) + to_dm(R @ Lin)
        local = ca.Function("muscle_jac_local", [xl], [Jl])
        dofs = np.asarray(mc.dofs, dtype=np.int64)
        S = sp.csc_matrix((np.ones(len(dofs)), (np.arange(len(dofs)), dofs)), shape=(len(dofs), self.n_dof))
        return ca.mtimes(local(x[dofs.tolist()]), to_dm(S))

    def nlp_bounds(self, p, equality_ropes=False, released=None) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`bounds` for :meth:`nlp_constraints_expr`."""
        lb, ub = self.bounds(p, equality_ropes, released)
        return lb * self.row_scale, ub * self.row_scale

    def hess_lag_upper(self, x, p, lam_f, lam_g):
        """Upper triangle of the Lagrangian's Hessian as a CasADi expression (for IPOPT's ``hess_lag``), with
        ``lam_g`` the multipliers of :meth:`nlp_constraints_expr` (physical ones: ``row_scale * lam_g``): the
        symbolic formulation (``"ipopt-symbolic"``, ``sqpmethod``); IPOPT's default takes
        :meth:`numeric_functions`."""
        lam_g = lam_g * ca.DM(self.row_scale)
        lam = lam_g if self.ropes else ca.vertcat(ca.MX(self.constraints.n_muscles, 1), lam_g)
        return self.model.hess_lag_fn(x, p, lam_f, ca.MX(0, 1)) + self.constraints.hessian_expr(x, lam)

    def numeric_functions(self) -> dict:
        """The NLP's pieces in numpy, as CasADi callbacks (:class:`~mdsr_opt.mechanics.assembly.BufferedFunction`),
        made once per model: ``"g"``, ``(x, p) ->`` :meth:`nlp_constraints_expr`'s rows; ``"jac_g"``,
        ``(x, p) -> (rows, Jacobian)``; ``"hess_lag"``, ``(x, p, lam_f, lam_g) ->`` the upper triangle of the
        Lagrangian's Hessian (as :meth:`hess_lag_upper`; the energy's from
        :func:`~mdsr_opt.mechanics.assembly.ipopt_functions`, the constraints' closed forms), ``p`` the
        energy's parameters. Nothing symbolic is built (the constraints' SX pieces give the same iterates to
        rounding, at a longer build)."""
        cached = self.__dict__.get("_numeric_functions")
        if cached is not None:
            return cached

        ref = weakref.ref(self)  # the model keeps these alive; they must not keep the model alive
        mc, n, nr = self.constraints, self.n_dof, self.n_rows
        dofs = np.asarray(mc.dofs, dtype=np.int64)
        x0 = np.asarray(self.mesh.points, dtype=float).reshape(-1)[dofs]
        rowmap = np.full(mc.n_constraints, -1, dtype=np.int64)
        rowmap[self.rows] = np.arange(nr)
        scale_all = np.zeros(mc.n_constraints)
        scale_all[self.rows] = self.row_scale
        Jl = mc.local_jacobian(x0)  # its pattern does not depend on the state
        jrow = np.repeat(np.arange(Jl.shape[0]), np.diff(Jl.indptr))
        jac = SparseLayout(nr, n)
        jac.add(rowmap[jrow], dofs[Jl.indices])
        jac.finish()
        jscale = scale_all[jrow]
        pat = self.model.hessian_pattern
        pcols = np.repeat(np.arange(pat.shape[1]), np.diff(pat.indptr))
        hr, hc, _ = mc.local_hessian_entries(x0, np.zeros(mc.n_constraints))
        hess = SparseLayout(n, n, upper=True)
        hess.add(pat.indices[pat.upper], pcols[pat.upper])
        hess.add(dofs[hr], dofs[hc])
        hess.finish()
        # the energy's upper triangle is written in place (its entries are distinct), the constraints'
        # few entries added: a sum over the whole pattern per call cost more than the SX pieces saved
        epos, cpos = hess.positions(0), hess.positions(1)
        ckeep = cpos >= 0
        cpos = cpos[ckeep]
        energy_is_all = bool(np.array_equal(epos, np.arange(hess.nnz)))  # (upper entries: none dropped)

        def rows(x):
            m = ref()
            return m.values(x) * m.row_scale

        def g(ins, outs):
            if outs[0] is not None:
                outs[0][:] = rows(ins[0])

        def jac_g(ins, outs):
            m = ref()
            if outs[0] is not None:
                outs[0][:] = rows(ins[0])
            if outs[1] is not None:
                outs[1][:] = jac.data([m.constraints.local_jacobian(ins[0][dofs]).data * jscale])

        def hess_lag(ins, outs):
            if outs[0] is None:
                return
            m = ref()
            lam = np.zeros(mc.n_constraints)
            lam[m.rows] = ins[3] * m.row_scale  # the physical multipliers
            out = outs[0]
            energy_hessian = m.model.projected_hessian_data if projecting() else m.model.hessian_data
            eh = energy_hessian(ins[0], ins[1])[pat.upper]
            if energy_is_all:
                np.multiply(eh, ins[2][0], out=out)
            else:
                out[:] = 0.0
                out[epos] = eh * ins[2][0]
            np.add.at(out, cpos, m.constraints.local_hessian_entries(ins[0][dofs], lam)[2][ckeep])

        sx, sp_ = ca.Sparsity.dense(n, 1), ca.Sparsity.dense(self.model.n_params, 1)
        sg = ca.Sparsity.dense(nr, 1)
        fns = {"g": BufferedFunction("constraints_num", [sx, sp_], [sg], g),
               "jac_g": BufferedFunction("constraints_jac_num", [sx, sp_], [sg, jac.sparsity], jac_g),
               "hess_lag": BufferedFunction("constrained_hess_lag_num", [sx, sp_, ca.Sparsity.dense(1, 1), sg],
                                            [hess.sparsity], hess_lag)}
        self.__dict__["_numeric_functions"] = fns
        return fns

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
        and met, ropes whose predicted tension is negative dropped (slack). None if the system is singular
        or the step would leave an element with less than a quarter of the smallest ``det F`` of ``x``
        (load stepping then tries a smaller load step); ``x`` itself (fixed coordinates moved) when the step
        leaves a rope farther from its target than ``x`` is."""
        free = ~fixed
        pe, targets, _ = self.split(p)
        lin = self._linearisation(x, pe, fixed)
        Hff, Hfc, g, J, c_x, lus = lin["Hff"], lin["Hfc"], lin["g"], lin["J"], lin["c"], lin["lu"]
        dfix = values - x[fixed]
        rhs_x = -(g[free] + Hfc @ dfix)
        lb, ub = self.bounds(p)
        c = c_x - ub  # ropes: L - target; rigid: residual
        keep = np.ones(self.n_rows, dtype=bool)
        if self.n_targets:  # a rope shorter than its target at the start is taken as slack
            keep[:self.n_targets] = c[:self.n_targets] > -1e-12 * self.constraints.rest_lengths
        pushing = np.zeros(self.n_targets, dtype=bool)  # dropped for a clearly negative predicted tension
        push_tol = 1e-9 * self.force_scale(p)  # as solve_constrained's: below it, a tension is round-off
        for _ in range(3):
            Jk = J[keep]
            Jf, Jc = Jk[:, free], Jk[:, fixed]
            rhs = np.concatenate([rhs_x, -(c[keep] + Jc @ dfix)])
            kk = keep.tobytes()
            if kk not in lus:  # the same state and active set (e.g. rest, at two load steps): one factorisation
                lus[kk] = kkt_factor(Hff, Jf, self.model.free_ordering(free))
            if lus[kk] is None:
                return None
            sol = lus[kk].solve(rhs)
            if not np.all(np.isfinite(sol)):
                return None
            nk = int(keep[:self.n_targets].sum())
            tau = sol[free.sum():free.sum() + nk]
            if not self.n_targets or np.all(tau >= 0):
                break
            idx = np.nonzero(keep[:self.n_targets])[0]
            keep[idx[tau < 0]] = False
            pushing[idx[tau < -push_tol]] = True  # tau: physical multipliers (J and c unscaled)
        # a linearised step that nearly inverts an element (a large contraction bends the body far) is a
        # poor start: report no prediction, so that load stepping takes a smaller load step instead.
        # Measured on 1k-10k node strips: IPOPT then needs 7-14 iterations in all, against up to 35 from a
        # full or a shortened step.
        y = np.array(x, dtype=float)
        y[free] += sol[:free.sum()]
        y[fixed] = values
        if min_jacobian(self.mesh, y) < 0.25 * lin["j0"]:
            return None
        if self.n_targets:
            # A rope contracted from straight: the linearised step bends the body (rotations to first order)
            # and lengthens what it meant to shorten, the farther the larger the step. Such a step is a worse
            # start than none: the current state (fixed coordinates moved) is returned instead. Measured on
            # one_muscle and two_muscles at medium resolution (541 and 567 nodes), 20-50 % contractions: 11-342
            # IPOPT iterations and up to 3 load steps with the step, 12-55 iterations in one step without,
            # the same equilibria. The ropes found slack are recorded for that state too (predicted_slack):
            # 30 random layouts of 2-4 ropes on a strip took 340 IPOPT iterations in all (26 solved), against
            # 8,208 (21 solved) with the equality form always first (bench_loadsteps.py --strips).
            L0 = self.constraints.rest_lengths
            before = np.abs(c_x[:self.n_targets] - ub[:self.n_targets]) / L0
            after = np.abs(self.values(y)[:self.n_targets] - ub[:self.n_targets]) / L0
            if after.max() > before.max():
                y = np.array(x, dtype=float)
                y[fixed] = values
            self.__dict__["_predicted_slack"] = (y.tobytes(), np.asarray(p, dtype=float).tobytes(),
                                                 pushing | (c[:self.n_targets] < -1e-12 * L0))
        return y

    def predicted_slack(self, x, p) -> np.ndarray | None:
        """The ropes :meth:`predict` left slack in its last prediction (shorter than their targets at its
        start, or pushing: a predicted tension below round-off, ``-1e-9`` x :meth:`force_scale`), when ``x``
        is the state it returned (the step, or the start kept instead of it) for the parameters ``p``; None
        for any other state or parameters (a warm start)."""
        last = self.__dict__.get("_predicted_slack")
        if last is None or last[0] != np.asarray(x, dtype=float).tobytes() or \
                last[1] != np.asarray(p, dtype=float).tobytes():
            return None
        return last[2].copy()

    def _linearisation(self, x, pe, fixed) -> dict:
        """What :meth:`predict` needs at ``x`` besides the targets: the Hessian of the Lagrangian with
        ``x``'s own multipliers (every rope taken as at its length: under load the energy's Hessian alone can
        be indefinite where the ropes hold the body) split into free-free and free-fixed blocks, the energy
        gradient, the constraints' Jacobian and values, and the KKT factorisations made so far (per active
        set), and the smallest ``det F`` at ``x``. The last one is kept: load stepping predicts from the same
        state again after a rejected step. So is the rest state's, per parameters and fixed coordinates: every
        solve from rest starts there (a design's warm start and its verification, at other contractions)."""
        x = np.asarray(x, dtype=float)
        key = (x.tobytes(), np.asarray(pe, dtype=float).tobytes(), fixed.tobytes())
        last = self.__dict__.get("_last_linearisation")
        if last is not None and last[0] == key:
            return last[1]
        at_rest = np.array_equal(x, self.mesh.points.reshape(-1))
        rest = self.__dict__.setdefault("_rest_linearisations", {})
        if at_rest and key in rest:
            self.__dict__["_last_linearisation"] = (key, rest[key])
            return rest[key]
        free = ~fixed
        g = self.model.gradient(x, pe)
        c = self.values(x)
        lam_x, _ = self.multipliers(x, self.params(pe, c[:self.n_targets] if self.n_targets else None), fixed,
                                    gradient=g)
        H = self.hessian(x, self.params(pe, c[:self.n_targets] if self.n_targets else None, lam_x))
        Hf = H[free]
        lin = {"Hff": Hf[:, free], "Hfc": Hf[:, fixed], "g": g, "J": self.jacobian(x), "c": c, "lu": {},
               "j0": min_jacobian(self.mesh, x)}
        self.__dict__["_last_linearisation"] = (key, lin)
        if at_rest:
            if len(rest) >= 2:  # each holds a KKT factor (6 MB at 3k nodes); one per material and gauge is typical
                rest.pop(next(iter(rest)))
            rest[key] = lin
        return lin

    def multipliers(self, x, p, fixed, rtol: float = 1e-7, gradient=None,
                    ropes_only_pull: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Least-squares multipliers at a solution ``x``: ``(lam (n_rows,), taut (n_targets,) bool)``.

        Ropes shorter than their target by more than ``rtol * L0`` are slack (multiplier 0); a taut rope
        whose fitted multiplier is negative is released and the fit repeated, so tensions are never
        compressive. The Lagrangian gradient with these multipliers (:meth:`gradient`) is the KKT residual.
        ``ropes_only_pull=False`` fits every row at once, as an estimate at a state that is no solution
        (e.g. a solve's start, where a rope shorter than its new target still pulls). ``gradient``: the
        energy gradient at ``x`` when the caller has it. The last answer is kept (a solve's stability check
        and its result ask at the same state).
        """
        pe, targets, _ = self.split(p)
        if not ropes_only_pull:
            rtol = np.inf
        active = np.ones(self.n_rows, dtype=bool)
        nt = self.n_targets
        if nt:
            active[:nt] = ~self.short_ropes(x, p, rtol)
        # the fit depends on the targets and rtol only through the ropes taken as taut: a state checked at two
        # tolerances (a solve's residual, then its stability) with the same taut ropes is fitted once
        key = (np.asarray(x, dtype=float).tobytes(), pe.tobytes(), active.tobytes(), np.asarray(fixed).tobytes(),
               bool(ropes_only_pull))
        last = self.__dict__.get("_last_multipliers")
        if last is not None and last[0] == key:
            return last[1].copy(), last[2].copy()
        # the fixed coordinates' columns zeroed rather than sliced out (the same products, 10x cheaper)
        g = np.where(fixed, 0.0, self.model.gradient(x, pe) if gradient is None else gradient)
        J = self.jacobian(x).tocsr(copy=True)
        J.data[fixed[J.indices]] = 0.0
        lam = np.zeros(self.n_rows)
        for _ in range(nt + 1):
            Ja = J[active]
            if Ja.shape[0] == 0:
                break
            la = least_squares_multipliers(Ja, g)  # the augmented system: no dense block per anchor patch
            if la is None:  # it broke down (e.g. dependent rows): the normal equations
                A = (Ja @ Ja.T).tocsc()
                try:  # J J' is symmetric positive (semi)definite: diagonal pivots in a minimum-degree order
                    la = spla.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                                   options={"SymmetricMode": True}).solve(-(Ja @ g))
                except RuntimeError:
                    la = np.linalg.lstsq(Ja.T.toarray(), -g, rcond=None)[0]
            lam[:] = 0.0
            lam[active] = la
            neg = np.nonzero(active[:nt] & (lam[:nt] < 0))[0]
            if len(neg) == 0 or not ropes_only_pull:
                break
            active[neg] = False
        self.__dict__["_last_multipliers"] = (key, lam.copy(), active[:nt].copy())
        return lam, active[:nt]

