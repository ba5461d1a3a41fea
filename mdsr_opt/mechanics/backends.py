"""Minimisers of a model's energy with some coordinates held fixed: one function per backend.

Every backend takes the same inputs (an :class:`~mdsr_opt.model.EnergyModel`, parameters ``p``, a first
guess, a mask of fixed coordinates and their values) and returns a :class:`MinimizeOutcome`. Building a
CasADi solver happens once per model and backend; later solves reuse it.

Backends
--------
``ipopt``         IPOPT, exact Hessian (scattered element Hessians), MUMPS. The default. Energy, gradient
                  and Hessian are evaluated in vectorised numpy where the model allows it
                  (:attr:`~mdsr_opt.mechanics.model.EnergyModel.is_numeric`), else symbolically.
``ipopt-symbolic`` The same IPOPT problem with the energy's gradient and Hessian always from the symbolic
                  CasADi model (the reference formulation; slower to build and to evaluate).
``ipopt-lbfgs``   IPOPT with a limited-memory quasi-Newton Hessian.
``sqpmethod``     CasADi's SQP method with the exact Hessian and the ``qrqp`` QP solver.
``uno``           The Uno solver shipped with the casadi wheel (exact Hessian derived by CasADi).
``scipy``         ``scipy.optimize.minimize(method="trust-constr")`` on the free coordinates with
                  CasADi-generated gradient and sparse Hessian: the baseline a user might write.
``newton``        A projected Newton method in numpy/scipy (:mod:`mdsr_opt.newton`): vectorised element
                  terms projected to positive semi-definite, one fill-reducing ordering reused by every
                  sparse factorisation, backtracking line search.
"""

from __future__ import annotations

import functools
import time
import warnings
from dataclasses import dataclass
from typing import Mapping

import casadi as ca
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..core.guards import captured_stdout, interruptible, quiet_stdout

__all__ = ["MinimizeOutcome", "BACKENDS", "CONSTRAINED_BACKENDS", "available_backends", "minimize",
           "supports_constraints", "interruptible", "check_options"]


@dataclass
class MinimizeOutcome:
    """What one backend's minimisation returned.

    Attributes
    ----------
    x : (2n,) ndarray
        The flattened coordinates reached.
    success : bool
    status : str
    iterations : int
    solve_time, build_time : float
        Seconds solving and building the solver (0 when reused).
    lam_g : ndarray or None
        Constraint multipliers (constrained models only).
    """

    x: np.ndarray  # (2n,) flattened coordinates
    success: bool
    status: str
    iterations: int
    solve_time: float
    build_time: float
    lam_g: np.ndarray | None = None  # constraint multipliers (constrained models only)

    def __repr__(self) -> str:
        from ..core.results import compact_repr

        return compact_repr(self, ("success", "iterations", "solve_time", "x", "lam_g", "status"))

    def to_dict(self) -> dict:
        """Every field as JSON-ready values (arrays as lists)."""
        from ..core.results import to_jsonable

        return {f: to_jsonable(getattr(self, f)) for f in self.__dataclass_fields__}

    def save(self, path) -> str:
        """Write the outcome as one ``.npz`` file (arrays exactly); :meth:`load` reads it back."""
        from ..core.results import save_fields

        return save_fields(self, path, "minimize")

    @classmethod
    def load(cls, path) -> "MinimizeOutcome":
        """Read an outcome written by :meth:`save` (ValueError naming a damaged or foreign file)."""
        from ..core.results import load_fields

        return load_fields(cls, path, "minimize")


def _casadi_factory(plugin: str, opts: dict, symbolic: bool = False):
    def factory(model):
        o = dict(opts)
        o["show_eval_warnings"] = False  # NaN from log J in a trial step is expected; IPOPT cuts the step
        if plugin == "ipopt" and not symbolic and getattr(model, "is_numeric", False):
            # energy, gradient and Hessian in vectorised numpy through callbacks: no symbolic graph to build
            from .assembly import ipopt_functions

            fns = ipopt_functions(model)
            x, p = ca.MX.sym("x", model.n_dof), ca.MX.sym("p", model.n_params)
            o["grad_f"], o["hess_lag"] = fns["grad_f"], fns["hess_lag"]
            o["no_nlp_grad"] = True  # only for multipliers of bounds and parameters, which are not used
            return ca.nlpsol(f"equilibrium_{plugin.replace('-', '_')}", plugin,
                             {"x": x, "p": p, "f": fns["f"](x, p)}, o)
        nlp = {"x": model.x, "p": model.p, "f": model.f_fn(model.x, model.p)}
        if plugin == "ipopt":
            o["hess_lag"] = model.hess_lag_fn
            o["grad_f"] = model.grad_fn
        elif plugin == "sqpmethod":
            o["hess_lag"] = model.hess_lag_full_fn
        # uno: CasADi derives its own gradient and Hessian from the expanded energy
        return ca.nlpsol(f"equilibrium_{plugin.replace('-', '_')}", plugin, nlp, o)
    return factory


def _constrained_factory(plugin: str, opts: dict, symbolic: bool = False):
    """NLP ``min E(x) s.t. g(x)`` of a :class:`~mdsr_opt.constrained.ConstrainedModel`."""
    def factory(cmodel):
        model = cmodel.model
        # IPOPT takes the energy's value, gradient and Hessian from numpy where the model allows it (the
        # constraints stay symbolic: few nodes); "ipopt-symbolic" and the other plugins use the CasADi graph
        numeric = plugin == "ipopt" and not symbolic and getattr(model, "is_numeric", False)
        if numeric:
            from .assembly import ipopt_functions

            fns = ipopt_functions(model)
            x, p = ca.MX.sym("x", model.n_dof), ca.MX.sym("p", model.n_params)
            f = fns["f"](x, p)
        else:
            x, p = model.x, model.p
            f = model.f_fn(x, p)
        g = cmodel.nlp_constraints_expr(x)
        nlp = {"x": x, "p": p, "f": f, "g": g}
        o = dict(opts)
        o["show_eval_warnings"] = False
        if numeric:  # the callbacks have no derivatives; nlp_grad only serves lam_x/lam_p, which are unused
            o["no_nlp_grad"] = True
            if cmodel.n_rows:  # the constraints' Jacobian from their local SX pieces: no AD of the MX graph
                o["jac_g"] = ca.Function("jac_g_c", [x, p], [g, cmodel.nlp_jacobian_expr(x)], ["x", "p"],
                                         ["g", "jac_g_x"])
        if plugin in ("ipopt", "sqpmethod"):
            lam_f = ca.MX.sym("lam_f")
            lam_g = ca.MX.sym("lam_g", g.size1())
            H = cmodel.hess_lag_upper(x, p, lam_f, lam_g, numeric=numeric)
            if plugin == "sqpmethod":
                H = H + ca.triu(H, False).T
            o["hess_lag"] = ca.Function("hess_lag_c", [x, p, lam_f, lam_g], [H], ["x", "p", "lam_f", "lam_g"],
                                        ["hess"])
            if plugin == "ipopt":
                o["grad_f"] = fns["grad_f"] if numeric else model.grad_fn
        return ca.nlpsol(f"constrained_{plugin}", plugin, nlp, o)
    return factory


#: IPOPT options of a constrained solve whose rows are all equalities, started from given multipliers
#: (the least-squares ones of the start, every row fitted: a rope shorter than its new target still pulls):
#: IPOPT's own estimate factorises a system the size of the unknowns. Measured on 3k nodes with 4 ropes (two
#: load steps of 4 iterations each): 0.292 -> 0.264 s, the same iterations and energy; 24 frames of a 32 x 8
#: strip with 4 ropes, each from the last: 81 iterations, as with IPOPT's estimate (116 when ropes short at
#: the start were fitted as slack). Options the caller gives take precedence.
WARM_MULTIPLIERS = {"ipopt.warm_start_init_point": "yes"}


def rope_forms(cmodel, p, x0) -> tuple[bool, ...]:
    """The forms of the rope rows :func:`_solve_constrained` tries from ``x0``, in order (True: ``L = target``,
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
    taking a short rope as slack cost 51 iterations against 42."""
    if not cmodel.n_targets:
        return (False,)
    slack = cmodel.predicted_slack(x0, p)
    return (False, True) if slack is not None and slack.any() else (True, False)


def _solve_constrained(plugin, opts, cmodel, p, x0, fixed, values, symbolic: bool = False):
    """Solve in the forms :func:`rope_forms` gives, each from ``x0``: an equality-form answer with no rope
    pushing is the answer; so is an inequality-form one, with any rope it left undecided settled by
    :func:`_decide_ropes` when that succeeds (as it is otherwise). A failed inequality form tried first is
    followed by the equality form, whose answer replaces it only when it succeeds with no rope pushing."""
    solvers, build = {}, [0.0]

    def solver_for(multipliers: bool):
        """The NLP's solver; with ``multipliers``, IPOPT's that starts from given constraint multipliers."""
        if multipliers not in solvers:
            o = dict(WARM_MULTIPLIERS, **opts) if multipliers else opts  # the caller's options win
            solvers[multipliers], bt = cmodel.solver(plugin + ("-symbolic" if symbolic else ""), o,
                                                     _constrained_factory(plugin, o, symbolic))
            build[0] += bt
        return solvers[multipliers]

    pe = cmodel.split(p)[0]
    lbx = np.full(cmodel.n_dof, -np.inf)
    ubx = np.full(cmodel.n_dof, np.inf)
    lbx[fixed] = values
    ubx[fixed] = values
    x0 = np.array(x0, dtype=float)
    x0[fixed] = values
    nt = cmodel.n_targets
    push_tol = 1e-9 * cmodel.force_scale(p)  # a rope at its length with no load: a multiplier of round-off size
    clock = {"t": 0.0, "it": 0}

    def run(start, equality, released=None):
        lbg, ubg = cmodel.nlp_bounds(p, equality_ropes=equality, released=released)
        t0 = time.perf_counter()
        kw = {}
        # every row an equality: IPOPT starts from the least-squares multipliers of the start, fitted here
        # (a system the size of the rows) instead of by its own (one the size of the unknowns)
        warm = plugin == "ipopt" and bool(np.all(lbg == ubg))
        if warm:
            kw["lam_g0"] = cmodel.multipliers(start, p, fixed, ropes_only_pull=False)[0] / cmodel.row_scale
        solver = solver_for(warm)
        with interruptible(), quiet_stdout(plugin == "uno"):  # Ctrl-C stops here, not after the re-solve
            sol = solver(x0=start, p=pe, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg, **kw)
        clock["t"] += time.perf_counter() - t0
        st = solver.stats()
        clock["it"] += int(st.get("iter_count", st.get("iterations", {}).get("iter", [0])[-1]
                                  if st.get("iterations") else 0))
        lam = np.asarray(sol["lam_g"]).ravel() * cmodel.row_scale  # physical multipliers
        return sol, str(st.get("return_status", st.get("unified_return_status", "unknown"))), \
            bool(st.get("success", False)), lam

    def pushing(lam, held):
        return np.broadcast_to(held, (nt,)) & (lam[:nt] < -push_tol)

    first = None  # a failed inequality form tried first: it stands unless the equality form does better
    for equality in rope_forms(cmodel, p, x0):
        sol, status, ok, lam = run(x0, equality)
        if equality:
            if ok and not pushing(lam, True).any():
                break
            if first is not None:  # second, and no better (a rope pushes, or it failed)
                sol, status, ok, lam = first
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
                    sol, status, ok, lam = decided
                break
            if status == "Maximum_Iterations_Exceeded":
                break
            first = (sol, status, ok, lam)  # failed: the equality form next, if any
    return MinimizeOutcome(np.asarray(sol["x"]).ravel(), ok, status, clock["it"], clock["t"], build[0], lam)


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
    (:func:`_solve_constrained`)."""
    x = np.asarray(sol["x"]).ravel()
    return cmodel.short_ropes(x, p) & ~cmodel.short_ropes(x, p, UNDECIDED_RTOL)


def _ipopt_opts(tol, max_iter, limited_memory=False, linear_solver="mumps"):
    o = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes", "ipopt.tol": tol,
         "ipopt.max_iter": max_iter, "ipopt.linear_solver": linear_solver, "error_on_fail": False,
         # multipliers of bounds and parameters are not used: skip their extra derivative evaluations
         "calc_lam_p": False, "calc_lam_x": False,
         # fixed coordinates become parameters without bound multipliers: about half the gradient calls,
         # solve 9-10 % faster with the same iterates (measured at 3k and 10k nodes)
         "ipopt.fixed_variable_treatment": "make_parameter_nodual"}
    if limited_memory:
        o["ipopt.hessian_approximation"] = "limited-memory"
    return o


def _solve_casadi(plugin, opts, model, p, x0, fixed, values, symbolic: bool = False):
    solver, build_time = model.solver(plugin + ("-symbolic" if symbolic else ""), opts,
                                      _casadi_factory(plugin, opts, symbolic))
    lbx = np.full(model.n_dof, -np.inf)
    ubx = np.full(model.n_dof, np.inf)
    lbx[fixed] = values
    ubx[fixed] = values
    x0 = np.array(x0, dtype=float)
    x0[fixed] = values
    t0 = time.perf_counter()
    with quiet_stdout(plugin == "uno"):
        sol = solver(x0=x0, p=p, lbx=lbx, ubx=ubx)
    solve_time = time.perf_counter() - t0
    st = solver.stats()
    status = str(st.get("return_status", st.get("unified_return_status", "unknown")))
    iters = int(st.get("iter_count", st.get("iterations", {}).get("iter", [0])[-1] if st.get("iterations") else 0))
    return MinimizeOutcome(np.asarray(sol["x"]).ravel(), bool(st.get("success", False)), status, iters,
                           solve_time, build_time)


def _free_problem(model, p, fixed, values, x0):
    free = ~fixed
    base = np.array(x0, dtype=float)
    base[fixed] = values

    def full(z):
        y = base.copy()
        y[free] = z
        return y

    return free, base, full


def _solve_scipy(model, p, x0, fixed, values, tol, max_iter):
    from scipy.optimize import minimize as sp_minimize

    free, base, full = _free_problem(model, p, fixed, values, x0)

    def fun(z):
        f, g = model.grad_fn(full(z), p)
        f = float(f)
        if not np.isfinite(f):
            return np.inf, np.zeros(free.sum())
        return f, np.asarray(g).ravel()[free]

    def hess(z):
        return model.hessian(full(z), p)[free][:, free]

    t0 = time.perf_counter()
    res = sp_minimize(fun, base[free], jac=True, hess=hess, method="trust-constr",
                      options={"gtol": tol, "xtol": 1e-14, "maxiter": max_iter, "verbose": 0})
    solve_time = time.perf_counter() - t0
    return MinimizeOutcome(full(res.x), bool(res.status in (1, 2)) and bool(np.isfinite(res.fun)),
                           f"status {res.status}: {res.message}", int(res.nit), solve_time, 0.0)


def _solve_newton(model, p, x0, fixed, values, tol, max_iter):
    """Projected Newton in numpy/scipy (:mod:`mdsr_opt.newton`): vectorised assembly, one ordering reused."""
    from .newton import projected_newton

    x, success, status, it, seconds = projected_newton(model, p, x0, fixed, values, tol=tol, max_iter=max_iter)
    return MinimizeOutcome(x, success, status, it, seconds, 0.0)


BACKENDS = {
    "ipopt": "IPOPT, exact Hessian, MUMPS (default)",
    "ipopt-lbfgs": "IPOPT, limited-memory Hessian",
    "ipopt-symbolic": "IPOPT, exact Hessian from the symbolic CasADi model (reference)",
    "sqpmethod": "CasADi sqpmethod (exact Hessian, qrqp)",
    "uno": "Uno through CasADi (exact Hessian)",
    "scipy": "scipy.optimize.minimize trust-constr with CasADi derivatives",
    "newton": "projected Newton in numpy/scipy (baseline)",
}


def available_backends() -> list[str]:
    """Names of the backends usable with this CasADi build."""
    return list(_available())


@functools.lru_cache(maxsize=None)
def _available() -> tuple[str, ...]:
    # asked once per process: CasADi looks for each plugin's library (about 0.5 ms a plugin), and every
    # solve checks its backend (4.5 ms of a 30 ms warm-started solve at 555 nodes)
    out = []
    for name in BACKENDS:
        plugin = {"ipopt-lbfgs": "ipopt", "ipopt-symbolic": "ipopt"}.get(name, name)
        if name in ("scipy", "newton") or ca.has_nlpsol(plugin):
            out.append(name)
    return tuple(out)


def check_backend(backend: str) -> str:
    if not isinstance(backend, str):
        raise TypeError(f"backend must be a string, got {type(backend).__name__}")
    if backend not in available_backends():
        raise ValueError(f"unknown backend {backend!r}; available: {', '.join(available_backends())}")
    return backend


_OPTION_VERDICTS: dict = {}  # (plugin, name, repr(value)) -> None (valid) or the error message


def _casadi_verdict(plugin: str, name: str, value) -> str | None:
    x = ca.SX.sym("x")
    opts = {"ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": False} if plugin == "ipopt" else {}
    opts[name] = value
    printed: list[str] = []
    try:
        with captured_stdout(printed):
            ca.nlpsol("option_probe", plugin, {"x": x, "f": (x - 1) ** 2}, opts)
    except RuntimeError as exc:
        text = str(exc)
        if "No such IPOPT option" in text or "Unknown option" in text:
            hint = " (IPOPT's own options are written 'ipopt.NAME')" if plugin == "ipopt" and \
                not name.startswith("ipopt.") else ""
            return f"unknown {plugin} option {name!r}{hint}"
        said = [ln.strip() for ln in printed[0].splitlines() if ln.strip().startswith("Setting:")] if printed else []
        why = said[0].replace(" Check the option documentation.", "") if said else next(
            (ln.strip() for ln in reversed(text.splitlines()) if ln.strip() and "Error calling" not in ln), text)
        why = why.split(".cpp:", 1)[1].split(": ", 1)[-1] if ".cpp:" in why else why
        return f"invalid value {value!r} for {plugin} option {name!r}: {why}"
    return None


def _scipy_verdict(method: str, name: str, value) -> str | None:
    from scipy.optimize import OptimizeWarning
    from scipy.optimize import minimize as sp_minimize

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", OptimizeWarning)
            sp_minimize(lambda z: float(z @ z), np.ones(2), method=method, bounds=[(-1.0, 2.0)] * 2,
                        options={name: value})
    except OptimizeWarning as exc:
        if "Unknown solver options" in str(exc):
            return f"unknown scipy {method} option {name!r}"
        return None  # a warning about the tiny probe problem, not about the option
    except Exception as exc:  # the value broke the method (wrong type, out of range)
        return f"invalid value {value!r} for scipy {method} option {name!r}: {type(exc).__name__}: {exc}"
    return None


def check_options(backend: str, options: Mapping | None) -> dict:
    """Check solver options against what the backend knows, before any solve.

    Parameters
    ----------
    backend : str
        A name of :data:`BACKENDS` (``options`` as :func:`minimize` takes them: CasADi ``nlpsol`` options,
        IPOPT's own with the ``ipopt.`` prefix), or ``"scipy:METHOD"`` for the options of
        ``scipy.optimize.minimize(method=METHOD)`` (as the nested and derivative-free designs take them).
    options : mapping of str to value, or None

    Returns
    -------
    dict
        A copy of ``options``.

    Raises
    ------
    TypeError
        ``options`` is not a mapping or a name is not a string.
    ValueError
        An unknown option or an invalid value, named (with IPOPT's own reason, e.g. the valid settings),
        instead of a CasADi ``RuntimeError`` when the solver is built; or options for a backend that takes
        none (``scipy``, ``newton``).

    Each option is tried once on a one-variable problem (building the solver, not solving) and the verdict
    cached per process, so repeated calls cost a dictionary lookup.

    Example
    -------
    >>> check_options("ipopt", {"ipopt.tol": 1e-6})
    {'ipopt.tol': 1e-06}
    >>> check_options("ipopt", {"ipopt.tolerance": 1e-6})
    Traceback (most recent call last):
    ...
    ValueError: unknown ipopt option 'ipopt.tolerance'
    """
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise TypeError(f"options must be a dict of option names to values, got {type(options).__name__}")
    for k in options:
        if not isinstance(k, str):
            raise TypeError(f"option names must be strings, got {k!r}")
    if not isinstance(backend, str):
        raise TypeError(f"backend must be a string, got {type(backend).__name__}")
    if backend.startswith("scipy:"):
        plugin, verdict = backend, _scipy_verdict
        method = backend.split(":", 1)[1]
    else:
        check_backend(backend)
        if backend in ("scipy", "newton"):
            if options:
                raise ValueError(f"backend {backend!r} takes no options, got {', '.join(map(repr, options))}")
            return {}
        plugin, verdict = {"ipopt-lbfgs": "ipopt", "ipopt-symbolic": "ipopt"}.get(backend, backend), _casadi_verdict
        method = plugin
    for name, value in options.items():
        key = (plugin, name, repr(value))
        if key not in _OPTION_VERDICTS:
            _OPTION_VERDICTS[key] = verdict(method, name, value)
        if _OPTION_VERDICTS[key] is not None:
            raise ValueError(_OPTION_VERDICTS[key])
    return dict(options)


def minimize(model, p, x0, fixed, values, backend="ipopt", tol=1e-8, max_iter=500,
             options: dict | None = None) -> MinimizeOutcome:
    """Minimise ``model``'s energy over the coordinates not in ``fixed`` (boolean mask over 2n).

    A SIGINT during the solve raises :class:`KeyboardInterrupt` (see :func:`interruptible`); it is never
    reported as a failed solve."""
    check_backend(backend)
    options = check_options(backend, options)  # unknown or invalid options: a ValueError naming them
    with interruptible():  # CasADi swallows SIGINT: re-raise it as KeyboardInterrupt after the call
        return _minimize(model, p, x0, fixed, values, backend, tol, max_iter, options)


def _minimize(model, p, x0, fixed, values, backend, tol, max_iter, options) -> MinimizeOutcome:
    options = dict(options or {})
    if hasattr(model, "constraints"):
        return _minimize_constrained(model, p, x0, fixed, values, backend, tol, max_iter, options)
    if backend in ("ipopt", "ipopt-lbfgs", "ipopt-symbolic"):
        o = _ipopt_opts(tol, max_iter if backend != "ipopt-lbfgs" else max(max_iter, 3000),
                        limited_memory=backend == "ipopt-lbfgs")
        o.update(options)
        return _solve_casadi("ipopt", o, model, p, x0, fixed, values, symbolic=backend == "ipopt-symbolic")
    if backend == "sqpmethod":
        o = {"qpsol": "qrqp", "qpsol_options": {"print_iter": False, "print_header": False,
                                                "error_on_fail": False},
             "print_header": False, "print_iteration": False, "print_status": False, "print_time": False,
             "max_iter": max_iter, "tol_du": tol, "tol_pr": tol, "error_on_fail": False}
        o.update(options)
        return _solve_casadi("sqpmethod", o, model, p, x0, fixed, values)
    if backend == "uno":
        o = {"print_time": False, "error_on_fail": False, "uno.logger": "SILENT"}
        o.update(options)
        return _solve_casadi("uno", o, model, p, x0, fixed, values)
    if backend == "scipy":
        return _solve_scipy(model, p, x0, fixed, values, tol, max_iter)
    return _solve_newton(model, p, x0, fixed, values, tol, max_iter)


#: backends that accept constraints (exact cable, rigid anchor patches; constrained models are symbolic)
CONSTRAINED_BACKENDS = ("ipopt", "ipopt-lbfgs", "ipopt-symbolic", "sqpmethod", "uno")


def supports_constraints(backend: str) -> bool:
    """Can ``backend`` solve with muscle constraints (exact cable ropes, rigid anchor patches)?"""
    return backend in CONSTRAINED_BACKENDS


def _minimize_constrained(model, p, x0, fixed, values, backend, tol, max_iter, options):
    if not supports_constraints(backend):
        raise ValueError(f"backend {backend!r} cannot take constraints (exact cable ropes, rigid anchor "
                         f"patches); use one of {', '.join(CONSTRAINED_BACKENDS)}")
    if backend in ("ipopt", "ipopt-lbfgs", "ipopt-symbolic"):
        o = _ipopt_opts(tol, max_iter if backend != "ipopt-lbfgs" else max(max_iter, 3000),
                        limited_memory=backend == "ipopt-lbfgs")
        o["calc_lam_p"] = False
        # IPOPT relaxes inequality bounds by 1e-8 (relative) by default: a taut rope in the inequality form
        # (another rope slack) then ended up to 1e-8 L0 longer than its target. Unrelaxed, it is never
        # longer, and short by the barrier's 1e-10 to 3e-9 L0; same iterations on the strips measured.
        o["ipopt.bound_relax_factor"] = 0.0
        o.update(options)
        return _solve_constrained("ipopt", o, model, p, x0, fixed, values, symbolic=backend == "ipopt-symbolic")
    if backend == "sqpmethod":
        o = {"qpsol": "qrqp", "qpsol_options": {"print_iter": False, "print_header": False,
                                                "error_on_fail": False},
             "print_header": False, "print_iteration": False, "print_status": False, "print_time": False,
             "max_iter": max_iter, "tol_du": tol, "tol_pr": tol, "error_on_fail": False}
        o.update(options)
        return _solve_constrained("sqpmethod", o, model, p, x0, fixed, values)
    o = {"print_time": False, "error_on_fail": False, "uno.logger": "SILENT"}
    o.update(options)
    return _solve_constrained("uno", o, model, p, x0, fixed, values)
