"""Shared layout: one NLP per pose, or all poses in one flattened NLP? (issue 16)

With the layout fixed the poses share no unknowns, so a joint NLP is block diagonal. This benchmark builds
both variants with the SAME machinery (public API only: the energy model's CasADi gradient, sliding-cable
springs of stiffness ``10 E t size / L0`` on the shared layout, IPOPT with CasADi's exact Hessian) on the
gecko at ~600 nodes, and times them side by side in one process:

- ``per-pose``: one NLP per pose (x_p, a_p, theta_p, t_p), solved one after the other;
- ``joint``: one NLP in all poses' variables, the sum of the objectives.

It prints build and solve seconds, IPOPT iterations and each pose's difference (both variants must agree).
This model is a stand-in for the design module's (which has no public joint builder); the structural
question, how a block-diagonal joint NLP compares with its blocks solved apart, does not depend on it.

Run: ``python tests/benchmarks/bench_poses.py [--resolution medium] [--repeat 3]``
"""

from __future__ import annotations

import argparse
import time

import casadi as ca
import numpy as np

from mdsr_opt.mechanics.align import align, node_weights
from mdsr_opt.mechanics.model import get_model
from mdsr_opt.synthesis.layouts import shared_layout
from mdsr_opt.synthesis.routing import route_muscles
from mdsr_opt.scenes.library import get_problem
from mdsr_opt.scenes.cases import prepare_case


def pose_block(model, mesh, material, muscles, y, w, tag):
    """Variables, bounds, start, objective and constraints of one pose's flattened design NLP."""
    n, m = mesh.n_nodes, len(muscles)
    ne = len(mesh.edges)
    L0 = np.array([mu.rest_length(mesh) for mu in muscles])
    Et = material.E * material.thickness
    h = float(mesh.edge_lengths.mean())
    K = 10.0 * Et * mesh.size / L0
    x = ca.MX.sym(f"x{tag}", 2 * n)
    a = ca.MX.sym(f"a{tag}", m)
    th = ca.MX.sym(f"th{tag}")
    t = ca.MX.sym(f"t{tag}", 2)
    p = ca.vertcat(ca.DM(material.params), ca.DM.zeros(ne), ca.DM.ones(ne), ca.DM(K), (1 - a) * ca.DM(L0))
    g = model.grad_fn(x, p)[1]
    i0 = int(np.argmin(np.linalg.norm(mesh.points - mesh.points.mean(0), axis=1)))
    j0 = int(np.argmax(np.linalg.norm(mesh.points - mesh.points[i0], axis=1)))
    fixed = [2 * i0, 2 * i0 + 1, 2 * j0 + 1]
    free = [k for k in range(2 * n) if k not in fixed]
    X = ca.reshape(x, 2, n)
    R = ca.vertcat(ca.horzcat(ca.cos(th), -ca.sin(th)), ca.horzcat(ca.sin(th), ca.cos(th)))
    diff = ca.mtimes(R, X) + ca.repmat(t, 1, n) - ca.DM(y.T)
    J = ca.sum2(ca.sum1(diff ** 2) * ca.DM(w).T) / (float(w.sum()) * h ** 2)
    lbx = np.concatenate([np.full(2 * n, -np.inf), np.zeros(m), [-np.inf] * 3])
    ubx = np.concatenate([np.full(2 * n, np.inf), np.full(m, 0.6), [np.inf] * 3])
    x0 = mesh.points.reshape(-1).copy()
    lbx[fixed] = ubx[fixed] = x0[fixed]
    a0 = np.clip(1 - np.array([mu.length(y) for mu in muscles]) / L0, 0, 0.54)
    al = align(mesh.points, y, w)
    v0 = np.concatenate([x0, a0, [al.angle], al.t])
    return dict(v=ca.vertcat(x, a, th, t), f=J, g=g[free] / (Et * h), lbx=lbx, ubx=ubx, x0=v0, m=m, n=n)


def solve(blocks, opts):
    t0 = time.perf_counter()
    nlp = {"x": ca.vertcat(*[b["v"] for b in blocks]), "f": sum(b["f"] for b in blocks),
           "g": ca.vertcat(*[b["g"] for b in blocks])}
    S = ca.nlpsol("S", "ipopt", nlp, opts)
    tb = time.perf_counter() - t0
    ng = nlp["g"].shape[0]
    t1 = time.perf_counter()
    sol = S(x0=np.concatenate([b["x0"] for b in blocks]), lbx=np.concatenate([b["lbx"] for b in blocks]),
            ubx=np.concatenate([b["ubx"] for b in blocks]), lbg=np.zeros(ng), ubg=np.zeros(ng))
    ts = time.perf_counter() - t1
    st = S.stats()
    v = np.asarray(sol["x"]).ravel()
    out, k = [], 0
    for b in blocks:
        nv = b["v"].shape[0]
        out.append(v[k:k + nv])
        k += nv
    return tb, ts, st["iter_count"], st["return_status"], out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("--resolution", default="medium", help="coarse, medium, fine or a node count")
    ap.add_argument("--repeat", type=int, default=3, help="timed repetitions (the median is printed)")
    a = ap.parse_args(argv)
    scene = get_problem("gecko", resolution=a.resolution)
    mesh, mat = scene.mesh, scene.material
    ys = {c: prepare_case(scene, c).target for c in ("bend_left", "bend_right")}
    lay = {c: tuple(route_muscles(mesh, y, **scene.routing_options)) for c, y in ys.items()}
    mus, _ = shared_layout(mesh, lay)
    w = node_weights(mesh)
    model = get_model(mesh, mat, cables=[mu.nodes for mu in mus])
    opts = {"ipopt.print_level": 0, "print_time": False, "ipopt.tol": 1e-8, "ipopt.max_iter": 500}
    print(f"gecko, {mesh.n_nodes} nodes, {len(mus)} shared muscles, poses {list(ys)}")
    rows = {"per-pose": [], "joint": []}
    for r in range(a.repeat):
        for variant in ("per-pose", "joint") if r % 2 == 0 else ("joint", "per-pose"):
            blocks = [pose_block(model, mesh, mat, mus, y, w, f"{c}{r}") for c, y in ys.items()]
            if variant == "joint":
                tb, ts, it, status, vs = solve(blocks, opts)
                its, sts = [it], [status]
            else:
                tb = ts = 0.0
                its, sts, vs = [], [], []
                for b in blocks:
                    b_, s_, i_, st_, v_ = solve([b], opts)
                    tb, ts = tb + b_, ts + s_
                    its.append(i_)
                    sts.append(st_)
                    vs += v_
            J = [float(np.sqrt(float(ca.Function("f", [b["v"]], [b["f"]])(v)))) for b, v in zip(blocks, vs)]
            rows[variant].append((tb, ts, its, sts, [round(v, 6) for v in J]))
            print(f"{variant:>9}: build {tb:6.2f} s, solve {ts:6.2f} s, IPOPT iterations {its}, {sts}, "
                  f"sqrt(objective) per pose {J}")
    for k, v in rows.items():
        print(f"median {k:>9}: build {np.median([x[0] for x in v]):.2f} s, solve {np.median([x[1] for x in v]):.2f} s")


if __name__ == "__main__":
    main()
