"""Figure 6 and Table 1 of the paper: each body target routed at a smaller and a larger K_a, both designed.

The paper routes five targets of its three MDSR bodies twice, with a smaller nonuniformity weight K_a (its
row C: fewer, longer muscles) and a larger one (row D), optimises the contractions of both layouts (its
Figure 6b and Table 1) and charts the difference against the optimiser's iterations (its Figure 6c). It
records the K_a values per target but the text copy lost them, so ours are chosen per target the way the
paper describes: the smaller value splices units into fewer, longer muscles, the larger keeps them
apart (see :data:`TARGETS`). The five targets are the external-driving cases of ``tentacle.py``,
``gripper.py`` and ``humanoid.py``.

This script is a figure, not a scene: it has no ``build`` but a ``run_figure(out, ...)``, which
``mdsr run figure6 --out DIR`` calls (``mdsr run all`` skips it). It writes

- ``figure6a.png``: targets (row A), contraction graphs (B), the layouts at the smaller (C) and larger (D) K_a;
- ``figure6b.png``: the target and the driven state of each layout over it;
- ``figure6c.png``: difference against IPOPT iteration for both layouts of each target;
- ``table1.csv`` and ``table1.md``: strokes and contractions per muscle, difference and iterations;
- ``figure6.json``: the same numbers and each design's trace.

The convergence trace comes from IPOPT's own iteration log (``file_print_level`` 5): the objective at
iterate k, converted to a difference by the final design (``D_k = D * sqrt(f_k / f_end)``, the objective
is ``D**2`` up to a constant factor). The iterates of the flattened NLP are not equilibria until it
converges (the log's ``inf_pr`` is saved beside it), so the early points are not the difference of a
physical state.

Run ``python problems/figure6.py --out out/figure6`` or ``mdsr run figure6 --out out/figure6``.
"""

from __future__ import annotations

import csv
import io
import os
import re
import sys
import tempfile
import time
import warnings

import numpy as np

#: (scene, case, (smaller K_a, larger K_a)). Chosen from a sweep of K_a = 0.5 .. 32 at medium resolution
#: (tests/benchmarks/bench_routing.py prints it): the smaller value is where units splice into fewer,
#: longer muscles, the larger where they stay apart or stop short.
TARGETS = (
    ("tentacle", "curl", (1.0, 8.0)),
    ("tentacle", "s_curve", (1.0, 8.0)),
    ("gripper", "close", (4.0, 16.0)),
    ("humanoid", "raise_arms", (1.0, 4.0)),
    ("humanoid", "lean", (0.5, 4.0)),
)

#: Routing knobs shared by all ten layouts (the paper's 5-10 seeds per region, at most 4 muscles l1..l4); the
#: paper's search on the whole contraction graph (``fabrication=False``: no channel clearance, no fixtures).
ROUTING = {"K_b": 4.0, "K_h": 0.1, "n_seeds": 8, "max_muscles": 4, "max_turn": 45.0, "fabrication": False}

_ITER_LINE = re.compile(r"^\s*(\d+)r?\s+([-+]?\d\.\d+e[-+]\d+)\s+(\d\.\d+e[-+]\d+)\s")


def route_targets(resolution="medium"):
    """Solve the five targets and route each at its two K_a values.

    Returns
    -------
    list of dict
        One per target: ``scene``, ``case``, ``K_a`` (pair), ``target`` (n, 2), ``external`` (the solve) and
        ``layouts`` (two RoutingResults). A failed target solve raises ``RuntimeError`` naming it.
    """
    from mdsr_opt.mechanics.equilibrium import solve_external
    from mdsr_opt.synthesis.routing import RoutingWarning, route_muscles
    from mdsr_opt.scenes.library import get_problem

    out, scenes = [], {}
    for name, cname, kas in TARGETS:
        if name not in scenes:
            scenes[name] = get_problem(name, resolution=resolution)
        scene = scenes[name]
        case = scene.case(cname)
        ext = solve_external(scene.mesh, scene.material, case.anchors, case.drags)
        if not ext.success:
            raise RuntimeError(f"figure6: the target {name}/{cname} did not solve: {ext.status}")
        layouts = []
        for K_a in kas:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RoutingWarning)
                layouts.append(route_muscles(scene.mesh, ext.x, K_a=K_a, **ROUTING))
        out.append({"scene": scene, "case": case, "K_a": kas, "target": ext.x, "external": ext,
                    "layouts": layouts})
    return out


def read_ipopt_log(path):
    """IPOPT's iteration table from an ``output_file`` log: (iterations, objective, inf_pr) arrays.

    A restarted count (several tables) keeps the last run only.
    """
    its, obj, inf = [], [], []
    with open(path) as fh:
        for line in fh:
            m = _ITER_LINE.match(line)
            if m:
                k = int(m.group(1))
                if its and k <= its[-1]:
                    its, obj, inf = [], [], []
                its.append(k)
                obj.append(float(m.group(2)))
                inf.append(float(m.group(3)))
    return np.array(its, dtype=int), np.array(obj), np.array(inf)


def design_layout(scene, target, muscles):
    """Design the contractions of ``muscles`` for ``target`` (the scene's design options, flattened NLP),
    with IPOPT's iteration log turned into a trace. Returns ``(DesignResult, trace dict)``."""
    from mdsr_opt.synthesis.contractions import design_contractions

    opts = {k: v for k, v in scene.design_options.items() if k != "method"}
    with tempfile.TemporaryDirectory() as tmp:
        log = os.path.join(tmp, "ipopt.log")
        res = design_contractions(scene.mesh, scene.material, muscles, target, method="flattened",
                                  options={"output_file": log, "file_print_level": 5}, **opts)
        its, f, inf = read_ipopt_log(log) if os.path.exists(log) else (np.zeros(0, int), np.zeros(0), np.zeros(0))
    if len(f) and f[-1] > 0 and np.isfinite(res.difference):
        d = res.difference * np.sqrt(np.maximum(f, 0.0) / f[-1])
    else:
        d = np.full(len(f), np.nan)
    return res, {"iterations": its.tolist(), "difference": d.tolist(), "inf_pr": inf.tolist()}


def table_rows(runs):
    """Table 1 rows (dicts) from the runs of :func:`run_figure`."""
    rows = []
    for r in runs:
        for j, (K_a, lay, res) in enumerate(zip(r["K_a"], r["layouts"], r["designs"])):
            L0 = [s.rest_length for s in lay.stats]
            row = {"target": f"{r['scene'].name}/{r['case'].name}", "layout": "CD"[j], "K_a": K_a,
                   "muscles": len(lay), "total_length": sum(L0)}
            for i in range(ROUTING["max_muscles"]):
                a = float(res.contractions[i]) if i < len(lay) else None
                row[f"a{i + 1}"] = a
                row[f"stroke{i + 1}"] = None if a is None else a * L0[i]
            row["idle"] = int(sum(float(a) < 1e-3 for a in res.contractions))
            row.update({"difference": res.difference, "relative_difference": res.difference / r["scene"].mesh.size,
                        "initial_difference": res.initial_difference, "iterations": res.iterations,
                        "success": bool(res.success), "status": res.status})
            rows.append(row)
    return rows


def _fmt(v):
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def write_table(rows, csv_path, md_path):
    """Write Table 1 as CSV and as a markdown table (both atomically)."""
    from mdsr_opt.body.io import atomic_path

    keys = list(rows[0])
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=keys, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if r[k] is None else r[k]) for k in keys})
    with atomic_path(csv_path) as tmp:
        with open(tmp, "w") as fh:
            fh.write(buf.getvalue())
    show = [k for k in keys if k not in ("status", "total_length", "initial_difference")]
    lines = ["| " + " | ".join(show) + " |", "|" + "---|" * len(show)]
    lines += ["| " + " | ".join(_fmt(r[k]) for k in show) + " |" for r in rows]
    note = ("\n\nstrokeN = aN * L0 of muscle lN (rest length, the length the servo pulls); idle = muscles the "
            "design leaves at a < 0.001 (routed, but not worth building for this target); difference = "
            "weighted RMS node distance to the target after rigid alignment (a length), relative = over the "
            "body's size; iterations = IPOPT iterations of the flattened design.\n")
    with atomic_path(md_path) as tmp:
        with open(tmp, "w") as fh:
            fh.write("# Table 1: contractions of the Figure 6 layouts\n\n" + "\n".join(lines) + note)


# the files run_figure writes into its folder (an ``mdsr run`` records them in the run folder's manifest)
OUTPUTS = ("figure6a.png", "figure6b.png", "figure6c.png", "table1.csv", "table1.md", "figure6.json")


def run_figure(out, resolution="medium", log=print) -> int:
    """Route, design and draw Figure 6 and Table 1 into folder ``out``.

    Returns
    -------
    int
        0 when all ten designs succeeded, 1 otherwise (the table says which failed and why).
    """
    import matplotlib

    if "matplotlib.pyplot" not in sys.modules:
        matplotlib.use("Agg")
    from mdsr_opt.body.io import write_json
    from mdsr_opt.plot.common import save_figure
    from mdsr_opt.plot.routing import plot_convergence, plot_design_grid, plot_layout_grid

    t0 = time.perf_counter()
    os.makedirs(out, exist_ok=True)
    runs = route_targets(resolution)
    for r in runs:
        r["designs"], r["traces"] = [], []
        for K_a, lay in zip(r["K_a"], r["layouts"]):
            if not len(lay):
                raise RuntimeError(f"figure6: {r['scene'].name}/{r['case'].name} at K_a={K_a} routed no muscle")
            res, trace = design_layout(r["scene"], r["target"], lay.muscles)
            r["designs"].append(res)
            r["traces"].append(trace)
            log(f"{r['scene'].name}/{r['case'].name} K_a={K_a:g}: {len(lay)} muscle(s), D = {res.difference:.4g}, "
                f"{res.iterations} it., {'ok' if res.success else 'FAILED: ' + res.status}")
    labels = lambda r: [f"K_a = {k:g}" for k in r["K_a"]]  # noqa: E731
    cols = [{"title": f"{r['scene'].name}/{r['case'].name}", "mesh": r["scene"].mesh, "target": r["target"],
             "anchors": r["case"].anchors, "drag_nodes": r["case"].drag_nodes, "layouts": r["layouts"],
             "row_labels": labels(r)} for r in runs]
    files = [save_figure(plot_layout_grid(cols, title="Figure 6a: targets, contraction graphs, layouts at "
                                                      "a smaller (C) and a larger (D) K_a"),
                         os.path.join(out, "figure6a.png"))]
    dcols = [{"title": c["title"], "mesh": c["mesh"], "target": c["target"], "row_labels": c["row_labels"],
              "designs": [{"x": d.x_aligned, "muscles": lay.muscles, "difference": d.difference,
                           "success": d.success} for d, lay in zip(r["designs"], r["layouts"])]}
             for c, r in zip(cols, runs)]
    files.append(save_figure(plot_design_grid(dcols, title="Figure 6b: driven by the designed contractions "
                                                           "(blue) over the target (grey)"),
                             os.path.join(out, "figure6b.png")))
    panels = [{"title": c["title"], "traces": [(f"{lab}, {len(lay)} m.", t["iterations"], t["difference"])
                                               for lab, lay, t in zip(c["row_labels"], r["layouts"], r["traces"])]}
              for c, r in zip(cols, runs)]
    files.append(save_figure(plot_convergence(panels, title="Figure 6c: difference against IPOPT iteration "
                                                            "(flattened design)"),
                             os.path.join(out, "figure6c.png")))
    rows = table_rows(runs)
    write_table(rows, os.path.join(out, "table1.csv"), os.path.join(out, "table1.md"))
    files += [os.path.join(out, "table1.csv"), os.path.join(out, "table1.md")]
    write_json(os.path.join(out, "figure6.json"), {
        "resolution": resolution, "routing": ROUTING, "rows": rows,
        "layouts": [{"target": f"{r['scene'].name}/{r['case'].name}", "K_a": K_a,
                     "muscles": [list(m.nodes) for m in lay], "dropped": [d.reason for d in lay.dropped],
                     "trace": t} for r in runs for K_a, lay, t in zip(r["K_a"], r["layouts"], r["traces"])]})
    files.append(os.path.join(out, "figure6.json"))
    ok = all(row["success"] for row in rows)
    log(f"figure6: {sum(row['success'] for row in rows)}/{len(rows)} designs succeeded in "
        f"{time.perf_counter() - t0:.1f} s; wrote {', '.join(os.path.basename(f) for f in files)} to {out}")
    return 0 if ok else 1


def main(argv=None) -> int:
    import argparse

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", default=os.path.join("out", "figure6"), help="output folder (default out/figure6)")
    p.add_argument("--resolution", default="medium",
                   type=lambda s: int(s) if s.isdigit() else s, help="coarse, medium (default), fine or a node count")
    a = p.parse_args(argv)
    code = run_figure(a.out, resolution=a.resolution)
    with open(os.path.join(a.out, "table1.md")) as fh:
        print(fh.read())
    return code


if __name__ == "__main__":
    raise SystemExit(main())
