"""Benchmark (a measurement, not a product path): reduced-space Gauss-Newton steps in the contractions as the
flattened design's warm start (issue 32, item 4, idea 2), side by side with the default design.

The default flattened design solves the forward problem at the geometric contractions ``a0`` from the target,
then IPOPT solves the flattened NLP from that equilibrium. Here, before IPOPT, ``steps`` Gauss-Newton steps
move ``a``: at the current equilibrium ``x(a)`` the sensitivities ``dx/da`` come from one factorisation of
the forward KKT matrix (the Hessian of the Lagrangian with the active rows: anchor patches and taut ropes;
a rope row ``C_i(x) + a_i = 0`` gives ``J dx = -e_i da_i``), the step ``da`` minimises the linearised
aligned difference (the rotation and translation linearised with it), and the forward solver re-solves at
``a + da`` from the linear prediction ``x + (dx/da) da`` (the step halved up to twice when the difference does
not fall). The flattened NLP then starts from the last ``(x, a)`` (``initial_guess``, ``warm_start``), and
IPOPT certifies the KKT point as before.

Per case: the default design's process CPU seconds and IPOPT iterations, then for 1, 2, 3 steps the CPU of
the steps (their forward solves included), the IPOPT iterations after them, the total, and the largest
difference in contractions and in the shape difference to the default design (both designs verified=False:
the verification is the same for both).

Run:  python tests/benchmarks/bench_gn_start.py                         # the strip at 2.4k nodes (nu 0.3, 0.45), L, tentacle
      python tests/benchmarks/bench_gn_start.py --cases s44_0.3 s44_0.45  # the strip at 8k nodes
      (cases: ``s<ny>_<nu>`` the strip of bench_fine_design, or a body of bench_buildable at 700 nodes)
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if __name__ == "__main__":  # the checkout this file is in, not the mdsr_opt installed elsewhere
    sys.path.insert(0, str(ROOT))
    sys.path.insert(0, str(Path(__file__).resolve().parent))

from mdsr_opt import NeoHookean  # noqa: E402
from mdsr_opt.mechanics.align import node_weights  # noqa: E402
from mdsr_opt.mechanics.kkt import kkt_factor  # noqa: E402
from mdsr_opt.mechanics.loadsteps import upright  # noqa: E402
from mdsr_opt.mechanics.units import Units  # noqa: E402
from mdsr_opt.synthesis.contractions import design_contractions  # noqa: E402
from mdsr_opt.synthesis.pipeline import design_pipeline  # noqa: E402
from mdsr_opt.synthesis.problem import DesignProblem, ForwardSolver, initial_guess_of  # noqa: E402

PERP = np.array([[0.0, -1.0], [1.0, 0.0]])  # d R(theta) / d theta = R PERP
A_MAX = 0.6  # design_contractions' default


def sensitivities(prob: DesignProblem, a, x) -> np.ndarray:
    """``dx/da`` (2n, m) at the equilibrium ``x`` (flat, unit body, gauge frame) of contractions ``a``."""
    H, free, A, kap, _res = prob.kkt_data(a, x)
    m, n = prob.m, prob.mesh.n_nodes
    idx = np.flatnonzero(free)
    S = np.zeros((2 * n, m))
    if A is None:  # no rows: the springs model, not measured here
        raise ValueError("the cable model with its rope rows is measured here")
    taut = kap[:m] > 1e-9 * max(1.0, float(np.abs(kap).max()))  # the rope rows kept in A, first and in order
    fac = kkt_factor(H[idx][:, idx], A[:, idx], prob.model.free_ordering(free))
    for r, i in enumerate(np.flatnonzero(taut)):
        rhs = np.zeros(len(idx) + A.shape[0])
        rhs[len(idx) + r] = -1.0
        S[idx, i] = fac.solve(rhs)[:len(idx)]
    return S


def gauss_newton_start(mesh, material, muscles, target, anchor_radius, steps: int):
    """``(a, x (n, 2) in the caller's units, forward iterations)`` after ``steps`` Gauss-Newton steps from the
    default warm start; None when the first forward solve fails."""
    units = Units(mesh, material)
    prob = DesignProblem(units.unit_mesh, units.unit_material, list(muscles), units.state_in(target),
                         node_weights(mesh, 0.5), "cable", 10.0, A_MAX, anchor_radius=units.to_unit(anchor_radius))
    a = initial_guess_of(mesh, list(muscles), target, A_MAX)
    a = np.minimum(a, np.where(prob.a_upper < A_MAX, 0.9 * prob.a_upper, prob.a_upper))
    fwd = ForwardSolver(prob, 1e-10, 200)
    x, ok, _ = fwd.solve(a, start=prob.y, tol=1e-6)
    if not ok:
        return None
    J, al, _ = prob.objective(x.reshape(-1, 2))
    n, m = prob.mesh.n_nodes, prob.m
    sw = np.sqrt(prob.w)[:, None]
    for _ in range(steps):
        S = sensitivities(prob, a, x)
        x2 = x.reshape(-1, 2)
        res = x2 @ al.R.T + al.t - prob.y
        cols = [((S[:, c].reshape(-1, 2) @ al.R.T) * sw).ravel() for c in range(m)]
        cols += [((x2 @ (al.R @ PERP).T) * sw).ravel(), (np.tile([1.0, 0.0], (n, 1)) * sw).ravel(),
                 (np.tile([0.0, 1.0], (n, 1)) * sw).ravel()]
        da = np.linalg.lstsq(np.column_stack(cols), -(res * sw).ravel(), rcond=None)[0][:m]
        accepted = False
        for _half in range(3):
            a1 = np.clip(a + da, 0.0, prob.a_upper)
            guess = x + S @ (a1 - a)
            if upright(prob.mesh, guess):
                fwd.x = guess  # the next solve starts from the linear prediction
            x1, ok, _ = fwd.solve(a1)
            if ok:
                J1, al1, _ = prob.objective(x1.reshape(-1, 2))
                if J1 < J:
                    accepted = True
                    break
            fwd.x = x
            da = da / 2
        if not accepted:
            break
        a, x, J, al = a1, x1, J1, al1
        if np.abs(da).max() < 1e-3:
            break
    return a, x.reshape(-1, 2) * units.length, fwd.iterations


def case(spec: str):
    """``(mesh, material, anchors, drags)`` of ``s<ny>_<nu>`` (bench_fine_design's strip) or a body name of
    bench_buildable (700 nodes, nu 0.45)."""
    if spec.startswith("s") and "_" in spec:
        from bench_fine_design import driving, strip

        ny, nu = spec[1:].split("_")
        mesh = strip(int(ny))
        return (mesh, NeoHookean(1.0, float(nu)), *driving(mesh))
    import bench_buildable

    mesh, anchors, drags, _poly, _d = bench_buildable.make_body(spec, 700)
    return mesh, NeoHookean(1.0, 0.45), anchors, drags


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", nargs="+", default=["s24_0.3", "s24_0.45", "L", "tentacle"],
                    help="bodies: s<ny>_<nu> (the fine-design strip), L, tentacle")
    ap.add_argument("--steps", type=int, nargs="+", default=[1, 2, 3],
                    help="numbers of Gauss-Newton warm-start steps to compare with the default")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    for spec in args.cases:
        mesh, mat, anchors, drags = case(spec)
        first = design_pipeline(mesh, mat, anchors, drags)  # the routed muscles and the target
        mus, rad, y = first.muscles, first.routing.fixture_radius, first.target
        c = time.process_time()
        base = design_contractions(mesh, mat, mus, y, anchor_radius=rad, verify=False)
        tb = time.process_time() - c
        for steps in args.steps:
            c = time.process_time()
            out = gauss_newton_start(mesh, mat, mus, y, rad, steps)
            tg = time.process_time() - c
            if out is None:
                print(f"{spec}: the first forward solve failed")
                continue
            a_k, x_k, f_its = out
            c = time.process_time()
            d = design_contractions(mesh, mat, mus, y, anchor_radius=rad, verify=False, initial_guess=a_k, warm_start=x_k)
            tf = time.process_time() - c
            print(f"{spec:10s} {mesh.n_nodes:6d} nodes: default {tb:.3f} s, {base.iterations} IPOPT it | {steps} GN "
                  f"step(s) {tg:.3f} s ({f_its} forward it) + {tf:.3f} s, {d.iterations} IPOPT it = {tg + tf:.3f} s; "
                  f"success {d.success}; |da| {np.abs(d.contractions - base.contractions).max():.1e}, "
                  f"difference {d.difference - base.difference:+.1e}", flush=True)


if __name__ == "__main__":
    main()
