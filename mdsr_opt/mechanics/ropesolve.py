"""The constrained solve: a model's energy minimised under its muscle constraints (exact cable ropes at or
below their targets, rigid anchor patches) by a CasADi NLP solver, ropes ending slack included.

:func:`solve_constrained` is what :func:`~mdsr_opt.mechanics.backends.minimize` calls for a
:class:`~mdsr_opt.mechanics.constrained.ConstrainedModel`: it builds the NLP (:func:`_constrained_factory`,
once per model, plugin and options), chooses the rope rows' forms (:func:`rope_forms`: equalities or upper
bounds, in which order) and settles ropes an inequality-form answer leaves undecided (:func:`_decide_ropes`).
"""

from __future__ import annotations

import contextlib
import time
from contextvars import ContextVar

import casadi as ca
import numpy as np

from ..core.guards import interruptible, quiet_stdout
from .assembly import ipopt_functions
from .result import MinimizeOutcome, solver_status
from .stability import STEP_RTOL, ipopt_certifies_minimum
from .stopping import with_stop_callback

__all__ = ["WARM_MULTIPLIERS", "UNDECIDED_RTOL", "pinned_bounds", "projected_energy_hessian", "projecting",
           "rope_forms", "solve_constrained"]


_PROJECTED: ContextVar[bool] = ContextVar("mdsr_projected_energy_hessian", default=False)


@contextlib.contextmanager
def projected_energy_hessian():
    """A scope in which IPOPT's constrained solves (numeric models) take the energy's Hessian projected to
    positive semi-definite per term (each element's tangent and each spring's block, as the ``newton``
    backend projects them) instead of the exact one, and certify no state by IPOPT's inertia test.

    For a start far from equilibrium that needs only a loose tolerance (the design's warm start): where
    compressed elements make the exact Hessian indefinite, IPOPT regularises it by a multiple of the
    identity grown until the inertia is right and shrunk by a third per iteration, and crawls with short,
    gradient-like steps; the projected Hessian keeps Newton-like steps there. Near the answer it converges
    only linearly where a tangent is projected, so tight tolerances keep the exact Hessian (outside this
    scope). The states it returns are equilibria by the same KKT residual as any other."""
    token = _PROJECTED.set(True)
    try:
        yield
    finally:
        _PROJECTED.reset(token)


def projecting() -> bool:
    """Inside :func:`projected_energy_hessian`?"""
    return _PROJECTED.get()


def _constrained_factory(plugin: str, opts: dict, symbolic: bool = False):
    """NLP ``min E(x) s.t. g(x)`` of a :class:`~mdsr_opt.mechanics.constrained.ConstrainedModel`."""
    def factory(cmodel):
        model = cmodel.model
        # IPOPT takes the energy's and the constraints' values and derivatives from numpy where the model
        # allows it (ConstrainedModel.numeric_functions: nothing symbolic to build); "ipopt-symbolic" and
        # the other plugins use the CasADi graph
        numeric = plugin == "ipopt" and not symbolic and getattr(model, "is_numeric", False)
        o = with_stop_callback(opts)  # Ctrl-C stops the solver at its next iteration
        o["show_eval_warnings"] = False
        if numeric:
            fns, cfns = ipopt_functions(model), cmodel.numeric_functions()
            x, p = ca.MX.sym("x", model.n_dof), ca.MX.sym("p", model.n_params)
            g = cfns["g"](x, p) if cmodel.n_rows else ca.MX(0, 1)
            # the callbacks have no derivatives; nlp_grad only serves lam_x/lam_p, which are unused
            o.update(no_nlp_grad=True, grad_f=fns["grad_f"], hess_lag=cfns["hess_lag"])
            if cmodel.n_rows:
                o["jac_g"] = cfns["jac_g"]
            return ca.nlpsol(f"constrained_{plugin}", plugin, {"x": x, "p": p, "f": fns["f"](x, p), "g": g}, o)
        x, p = model.x, model.p
        f = model.f_fn(x, p)
        g = cmodel.nlp_constraints_expr(x)
        nlp = {"x": x, "p": p, "f": f, "g": g}
        if plugin in ("ipopt", "sqpmethod"):
            lam_f = ca.MX.sym("lam_f")
            lam_g = ca.MX.sym("lam_g", g.size1())
            H = cmodel.hess_lag_upper(x, p, lam_f, lam_g)
            if plugin == "sqpmethod":
                H = H + ca.triu(H, False).T
            o["hess_lag"] = ca.Function("hess_lag_c", [x, p, lam_f, lam_g], [H], ["x", "p", "lam_f", "lam_g"],
                                        ["hess"])
            if plugin == "ipopt":
                o["grad_f"] = model.grad_fn
        return ca.nlpsol(f"constrained_{plugin}", plugin, nlp, o)
    return factory


#: IPOPT options of a constrained solve whose rows are all equalities, started from given multipliers
#: (the least-squares ones of the start, every row fitted: a rope shorter than its new target still pulls):
#: IPOPT's own estimate factorises a system the size of the unknowns; these need the same iterations and
#: reach the same energy (24 frames of a 32 x 8 strip with 4 ropes, each from the last: 81 iterations, as
#: with IPOPT's estimate; 116 when ropes short at the start were fitted as slack). Options the caller gives
#: take precedence.
WARM_MULTIPLIERS = {"ipopt.warm_start_init_point": "yes"}


def rope_forms(cmodel, p, x0) -> tuple[bool, ...]:
    """The forms of the rope rows :func:`solve_constrained` tries from ``x0``, in order (True: ``L = target``,
    False: ``L <= target``).

    Ropes as equalities first: if every rope's multiplier (tension) is then >= 0, that is a KKT point of the
    inequality problem too, found without the interior point method's slow approach to a degenerate bound;
    otherwise the inequality form, from the same start. A start made by the KKT predictor that left a rope
    slack (its predicted tension was negative: :meth:`~mdsr_opt.mechanics.constrained.ConstrainedModel.
    predicted_slack`) takes the inequality form first: held at its length, such a rope made the equality
    solve long, and its answer was then discarded. A rope an inequality-form answer leaves undecided is then
    settled by :func:`_decide_ropes`. Measured on 1k and 3k strips
    with 8 muscles, two or three of them ending slack: 30-92 IPOPT iterations (20-84 of them in the
    equality solve) against 8-17, the same equilibria (``bench_loadsteps.py --strips``). Other starts (a warm start from an earlier state,
    where a released rope is short but usually pulls again) keep the equality form first: on gecko's gait
    taking a short rope as slack cost 51 iterations against 42. (Such a start first tries the ropes its
    own state had slack, by their multipliers rather than their lengths: :func:`_warm_active_set`.)"""
    if not cmodel.n_targets:
        return (False,)
    slack = cmodel.predicted_slack(x0, p)
    return (False, True) if slack is not None and slack.any() else (True, False)


def pinned_bounds(n_dof: int, x0, fixed, values) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """IPOPT's bounds for a solve with coordinates ``fixed`` pinned at ``values`` (both bounds equal, the
    others free) and the start ``x0`` with them in place: ``(lbx, ubx, x0)``."""
    lbx = np.full(n_dof, -np.inf)
    ubx = np.full(n_dof, np.inf)
    lbx[fixed] = values
    ubx[fixed] = values
    x0 = np.array(x0, dtype=float)
    x0[fixed] = values
    return lbx, ubx, x0


def solve_constrained(plugin, opts, cmodel, p, x0, fixed, values, symbolic: bool = False):
    """Solve in the forms :func:`rope_forms` gives, each from ``x0``: an equality-form answer with no rope
    pushing is the answer; so is an inequality-form one, with any rope it left undecided settled by
    :func:`_decide_ropes` when that succeeds (as it is otherwise). A failed inequality form tried first is
    followed by the equality form, whose answer replaces it only when it succeeds with no rope pushing.
    Before those, a warm start with slack ropes (IPOPT) tries its own guess of them
    (:func:`_warm_active_set`)."""
    solvers, build = {}, [0.0]

    def options_for(multipliers: bool) -> dict:
        """The options of :func:`solver_for`'s solver (the caller's win over WARM_MULTIPLIERS)."""
        return dict(WARM_MULTIPLIERS, **opts) if multipliers else opts

    def solver_for(multipliers: bool):
        """The NLP's solver; with ``multipliers``, IPOPT's that starts from given constraint multipliers."""
        if multipliers not in solvers:
            o = options_for(multipliers)
            solvers[multipliers], bt = cmodel.solver(plugin + ("-symbolic" if symbolic else ""), o,
                                                     _constrained_factory(plugin, o, symbolic))
            build[0] += bt
        return solvers[multipliers]

    pe = cmodel.split(p)[0]
    lbx, ubx, x0 = pinned_bounds(cmodel.n_dof, x0, fixed, values)
    nt = cmodel.n_targets
    push_tol = 1e-9 * cmodel.force_scale(p)  # a rope at its length with no load: a multiplier of round-off size
    clock = {"t": 0.0, "it": 0}
    step_tol = STEP_RTOL * cmodel.mesh.size

    def run(start, equality, released=None, lam0=None):
        lbg, ubg = cmodel.nlp_bounds(p, equality_ropes=equality, released=released)
        t0 = time.perf_counter()
        kw = {}
        # every row an equality: IPOPT starts from the least-squares multipliers of the start, fitted here
        # (a system the size of the rows) instead of by its own (one the size of the unknowns); ``lam0``: the
        # caller's fit, for rows that are equalities or released (no bound at all)
        warm = plugin == "ipopt" and (bool(np.all(lbg == ubg)) or lam0 is not None)
        if warm:
            lam0 = cmodel.multipliers(start, p, fixed, ropes_only_pull=False)[0] if lam0 is None else lam0
            kw["lam_g0"] = lam0 / cmodel.row_scale
        solver = solver_for(warm)
        with interruptible(), quiet_stdout(plugin == "uno"):  # Ctrl-C stops here, not after the re-solve
            sol = solver(x0=start, p=pe, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg, **kw)
        clock["t"] += time.perf_counter() - t0
        st = solver.stats()
        status, its = solver_status(st)
        clock["it"] += its
        lam = np.asarray(sol["lam_g"]).ravel() * cmodel.row_scale  # physical multipliers
        # every row an equality (no slack variable's barrier in IPOPT's matrix) and every rope pulling (a rope
        # with no tension could also shorten: IPOPT's tangent space would be too small): its inertia test
        # certifies the state a strict minimum or leaves the question to the stability check
        # (not with a projected energy Hessian: IPOPT's inertia is then that of another matrix)
        cert = plugin == "ipopt" and bool(np.all(lbg == ubg)) and bool(np.all(lam[:nt] > push_tol)) and \
            not projecting() and ipopt_certifies_minimum(st, options_for(warm), step_tol)
        return sol, status, bool(st.get("success", False)), lam, cert

    def pushing(lam, held):
        return np.broadcast_to(held, (nt,)) & (lam[:nt] < -push_tol)

    forms = rope_forms(cmodel, p, x0)
    guessed = _warm_active_set(run, cmodel, p, x0, fixed, forms, pushing) if plugin == "ipopt" else None
    if guessed is not None:
        sol, status, ok, lam, cert = guessed
        return MinimizeOutcome(np.asarray(sol["x"]).ravel(), ok, status, clock["it"], clock["t"], build[0], lam,
                               certified=bool(ok and cert))
    first = None  # a failed inequality form tried first: it stands unless the equality form does better
    for equality in forms:
        sol, status, ok, lam, cert = run(x0, equality)
        if equality:
            if ok and not pushing(lam, True).any():
                break
            if first is not None:  # second, and no better (a rope pushes, or it failed)
                sol, status, ok, lam, cert = first
                break
            if status == "Maximum_Iterations_Exceeded":
                # not a rope that would push but a step too long: the inequality form, from the same start,
                # only repeats the failure (a 50 % contraction at 541 nodes: twice 100 iterations and about
                # 3,000 energy evaluations each before load stepping halved the step)
                break
            if ok:
                status, ok = "a rope would push: re-solved with slack allowed", False
        else:
            if ok:
                decided = _decide_ropes(run, cmodel, p, sol, pushing)
                if decided is not None:
                    sol, status, ok, lam, cert = decided
                break
            if status == "Maximum_Iterations_Exceeded":
                break
            first = (sol, status, ok, lam, cert)  # failed: the equality form next, if any
    return MinimizeOutcome(np.asarray(sol["x"]).ravel(), ok, status, clock["it"], clock["t"], build[0], lam,
                           certified=bool(ok and cert))


def _warm_active_set(run, cmodel, p, x0, fixed, forms, pushing):
    """A warm start's own guess of the slack ropes, solved first. From a state that is no prediction (an
    earlier equilibrium, e.g. the previous frame of an animation), the least-squares multipliers of every row
    at ``x0`` are those of the state it solved (its targets do not enter them): a rope they leave without
    tension (at most :data:`SLACK_MULTIPLIER` x the force scale) was slack there and is released (its row
    dropped), the others are held at their new lengths (equalities, started from those multipliers). The
    answer is a KKT point of the inequality problem, returned as the solve's, when it succeeds with no held
    rope pushing and no released rope longer than its target; otherwise None, and :func:`solve_constrained`
    solves the forms of :func:`rope_forms` from ``x0`` as without it. None at once when no rope is released
    (the equality form first is that guess), for a start made by the KKT predictor (which has its own
    guess, :func:`rope_forms`) and inside :func:`projected_energy_hessian`: a start far from equilibrium (the
    design's target shape) is no earlier equilibrium, so its multipliers tell nothing of slack ropes (on
    bench_fine_design's strip the guess released a rope that then pulled, and that solve was thrown away)."""
    nt = cmodel.n_targets
    if not nt or forms[0] is not True or projecting() or cmodel.predicted_slack(x0, p) is not None:
        return None
    lam = cmodel.multipliers(x0, p, fixed, ropes_only_pull=False)[0]
    released = lam[:nt] <= SLACK_MULTIPLIER * cmodel.force_scale(p)
    if not released.any():
        return None
    lam[:nt][released] = 0.0
    out = run(x0, ~released, released, lam)
    if not out[2] or pushing(out[3], ~released).any():
        return None
    x = np.asarray(out[0]["x"]).ravel()
    if np.any(released & ~cmodel.short_ropes(x, p, -1e-9)):  # a released rope longer than its target: it pulls
        return None
    return out


#: a rope whose least-squares multiplier at a warm start is at most this fraction of the force scale (no
#: tension but round-off) was slack in the state the start was solved as (:func:`_warm_active_set`)
SLACK_MULTIPLIER = 1e-6


def _decide_ropes(run, cmodel, p, sol, pushing):
    """Settle the ropes an inequality-form answer left undecided (:func:`_undecided_ropes`); None when it
    left none, or when settling them fails (the answer then stands as it is).

    The interior point method approaches a rope that ends at its length with almost no tension slowly, and
    may stop with it short by 1e-7 to 1e-4 L0 and a spurious tension. From that answer, the ropes not
    clearly slack are held at their lengths (the clearly slack ones keep their ``<=`` rows); a held rope
    that then pushes, if it was an undecided one, is released (its row dropped) and the solve repeated,
    and is accepted only if it ends no longer than its target. Measured: a strip whose second rope ends
    taut with tension 0.0009 against 0.12 (held: met exactly); a 24 x 6 strip with 6 ropes, one of which
    pushes with -3.4e-6 against tensions of 0.04 when held (released: it ends 9e-6 L0 short, at zero
    tension), where the inequality answer had left it 5.9e-5 short with a tension of 4.5e-5 and a
    Lagrangian residual of 1.1e-5 that rejected the state."""
    x = np.asarray(sol["x"]).ravel()
    undecided = _undecided_ropes(cmodel, p, sol)
    if not undecided.any():
        return None
    held = ~cmodel.short_ropes(x, p, UNDECIDED_RTOL)
    released = np.zeros_like(held)
    for _ in range(2):
        out = run(x, held, released)
        if not out[2]:
            return None
        push = pushing(out[3], held)
        if not push.any():
            x = np.asarray(out[0]["x"]).ravel()
            # "shorter than its target by more than -1e-9 L0": no longer than it beyond round-off
            if np.any(released & ~cmodel.short_ropes(x, p, -1e-9)):
                return None  # a released rope ends longer than its target: it was not slack
            return out
        if np.any(push & ~undecided):  # a rope the inequality form found taut would push: no settling it
            return None
        held, released = held & ~push, released | push
        x = np.asarray(out[0]["x"]).ravel()
    return None


#: the band of rope lengths an inequality-form answer leaves undecided (:func:`_undecided_ropes`): shorter
#: than the target by more than the slack tolerance of the multipliers' fit (1e-7 L0), by less than this
UNDECIDED_RTOL = 1e-4


def _undecided_ropes(cmodel, p, sol) -> np.ndarray:
    """Ropes of an inequality-form answer that are neither at their length (within the 1e-7 L0 that
    :meth:`~mdsr_opt.mechanics.constrained.ConstrainedModel.multipliers` allows a taut rope) nor clearly
    slack (short by more than :data:`UNDECIDED_RTOL`): a rope ending at its length with almost no tension,
    which the interior point method approaches slowly. On a strip whose second rope ended so (tension
    0.0009 against 0.12), its answer stopped 9e-7 L0 short; the multipliers' fit took the rope for slack
    and the Lagrangian residual of 2e-4 rejected the state. :func:`_decide_ropes`, holding it, meets it exactly
    (:func:`solve_constrained`)."""
    x = np.asarray(sol["x"]).ravel()
    return cmodel.short_ropes(x, p) & ~cmodel.short_ropes(x, p, UNDECIDED_RTOL)
