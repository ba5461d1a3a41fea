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
- ``figure6c.png``: difference against IPOPT iteration for both layouts of each target, each point the
  difference of the equilibrium at that iterate's contractions;
- ``table1.csv`` and ``table1.md``: strokes and contractions per muscle, difference and iterations;
- ``figure6.json``: the same numbers and each design's trace;
- ``findings.txt``: the sentences the README states about Figure 6, computed from the table
  (:func:`findings`).

The iterates of the flattened NLP are not equilibria until it converges (their states violate the
equilibrium constraints), so Figure 6c does not chart them: it takes each iterate's contractions
(:func:`iterate_contractions`) and solves the body forward at them, warm-started from the previous
iterate's equilibrium (:func:`equilibrium_trace`). Every point is the difference of a physical state; such
a trace need not fall monotonically (Table 1's ``equilibrium_rises``).

With ``--vector`` (``run_figure(vector=...)``) each figure is also written as a PDF (or SVG) beside its PNG.
Differences are lengths in each scene's unit (:attr:`~mdsr_opt.scenes.scene.Scene.units`), as the figures say.

Run ``python problems/figure6.py --out out/figure6`` or ``mdsr run figure6 --out out/figure6``.
"""

from __future__ import annotations

import csv
import io
import os
import sys
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


def design_layout(scene, target, muscles):
    """Design the contractions of ``muscles`` for ``target`` (the scene's design options, flattened NLP) and
    chart its convergence in equilibria (:func:`equilibrium_trace`). Returns ``(DesignResult, trace dict)``."""
    from mdsr_opt.synthesis.contractions import design_contractions

    opts = {k: v for k, v in scene.design_options.items() if k != "method"}
    res = design_contractions(scene.mesh, scene.material, muscles, target, method="flattened", **opts)
    return res, equilibrium_trace(scene, target, muscles, res, opts)


def iterate_contractions(scene, target, muscles, res, opts):
    """The contractions of every IPOPT iterate of the flattened design ``res``: iterate 0 is its start,
    iterate k the design stopped after k iterations (``max_iter=k``, the same start and options: IPOPT is
    deterministic, so it is iterate k of the full run), until one converges. The polish of slack ropes
    (a second, short solve) is not an iterate of the main run; the last entry is the design's own
    contractions, at the design's iteration count (the polish's iterations included). Returns ``(iterations, contractions (K+1, m))``."""
    from mdsr_opt.synthesis.contractions import design_contractions

    warm = "rest" if "warm-started from rest after" in str(res.status) else True
    its, A = [0], [np.asarray(res.initial_contractions, dtype=float)]
    for k in range(1, max(int(res.iterations), 1)):
        r = design_contractions(scene.mesh, scene.material, muscles, target, method="flattened",
                                max_iter=k, verify=False, warm_start=warm,
                                **{key: v for key, v in opts.items() if key not in ("verify", "warm_start")})
        if r.success:  # converged within k iterations: the rest is the design's own end point
            break
        its.append(k)
        A.append(np.asarray(r.contractions, dtype=float))
    its.append(max(int(res.iterations), its[-1] + 1))  # the polish's iterations counted, as in Table 1
    A.append(np.asarray(res.contractions, dtype=float))
    return np.array(its), np.array(A)


def equilibrium_trace(scene, target, muscles, res, opts):
    """Figure 6c's trace: at every IPOPT iterate, the difference of the EQUILIBRIUM at that iterate's
    contractions (the flattened NLP's own iterates violate the equilibrium constraints until it converges).

    Each iterate's contractions (:func:`iterate_contractions`) are solved forward
    (:func:`~mdsr_opt.mechanics.equilibrium.solve_internal`, the design's muscle model, stiffness and anchor
    radius), warm-started from the previous iterate's equilibrium, and the result aligned onto the target
    with the design's node weights. Returns a dict of lists: ``iterations``, ``difference`` (NaN where the
    forward solve failed), ``contractions``, ``solved`` and ``status``.
    """
    from mdsr_opt.mechanics.align import align, node_weights
    from mdsr_opt.mechanics.equilibrium import solve_internal

    its, A = iterate_contractions(scene, target, muscles, res, opts)
    w = node_weights(scene.mesh, opts.get("interior_weight", 0.5))
    guess, D, ok, status = "predictor", [], [], []
    for a in A:
        eq = solve_internal(scene.mesh, scene.material, muscles, a, muscle_model=res.muscle_model,
                            stiffness=res.stiffness, anchor_radius=res.anchor_radius, initial_guess=guess)
        ok.append(bool(eq.success))
        status.append(str(eq.status))
        D.append(float(align(eq.x, target, w).difference) if eq.success else float("nan"))
        if eq.success:
            guess = np.asarray(eq.x, dtype=float)
    return {"iterations": its.tolist(), "difference": D, "contractions": A.tolist(), "solved": ok,
            "status": status}


def table_rows(runs):
    """Table 1 rows (dicts) from the runs of :func:`run_figure`; ``relative_difference`` is over the body's
    diameter at rest, as ``mdsr run``'s."""
    from mdsr_opt.mechanics.anchors import body_size

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
            tr = r["traces"][j]
            d = np.asarray(tr["difference"], dtype=float)
            row.update({"difference": res.difference, "relative_difference": res.difference / body_size(r["scene"].mesh),
                        "initial_difference": res.initial_difference, "iterations": res.iterations,
                        "success": bool(res.success), "status": res.status,
                        "equilibrium_start": float(d[0]), "equilibrium_rises": rises(d),
                        "equilibria_solved": bool(all(tr["solved"]))})
            rows.append(row)
    return rows


#: a rise of the equilibrium trace: the difference grows by more than this fraction from one iterate to the next
RISE = 1e-3


def rises(differences) -> int:
    """How many times an equilibrium trace's difference grows by more than :data:`RISE` (relative) from one
    iterate to the next (a failed forward solve, NaN, counts as no rise)."""
    d = np.asarray(differences, dtype=float)
    return int(np.sum(d[1:] > d[:-1] * (1.0 + RISE)))


def _count(k: int, n: int) -> str:
    return f"{k} of {n}"


def findings(rows) -> list[str]:
    """The sentences the README states about Figure 6, computed from Table 1's rows (dicts or a CSV's
    strings): how the muscle counts of the two layouts compare, which layout converges in fewer IPOPT
    iterations and reaches the smaller difference, and how often the equilibrium trace of Figure 6c rises."""
    def num(r, k, cast=float):
        return cast(r[k]) if not isinstance(r[k], str) else cast(float(r[k]))

    pairs = {}
    for r in rows:
        pairs.setdefault(r["target"], {})[r["layout"]] = r
    n = len(pairs)
    fewer, same, more = [], 0, 0
    for p in pairs.values():
        c, d = num(p["C"], "muscles", int), num(p["D"], "muscles", int)
        if c == d:
            same += 1
        else:
            more += c > d
            fewer.append((p["C"], p["D"]) if c < d else (p["D"], p["C"]))
    counts = f"for {_count(len(fewer) - more, n)} targets and as many for {same}"
    counts += f" (more for {more})" if more else ""
    out = [f"The smaller `K_a` gives fewer muscles {counts}."]
    k = len(fewer)
    if k:
        its = [(num(a, "iterations", int), num(b, "iterations", int)) for a, b in fewer]
        lt, eq = sum(x < y for x, y in its), sum(x == y for x, y in its)
        smaller = sum(num(a, "difference") < num(b, "difference") for a, b in fewer)
        out.append(f"Where the counts differ, the layout with fewer muscles converges in fewer IPOPT iterations "
                   f"for {_count(lt, k)}, in as many for {eq} and in more for {k - lt - eq}; it reaches the "
                   f"smaller difference for {_count(smaller, k)}.")
    up = sum(num(r, "equilibrium_rises", int) > 0 for r in rows)
    out.append(f"Figure 6c charts the difference of the equilibrium at each iterate's contractions; it rises "
               f"after an iteration in {_count(up, len(rows))} designs.")
    return out


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
    show = [k for k in keys if k not in ("status", "total_length", "initial_difference", "equilibria_solved")]
    lines = ["| " + " | ".join(show) + " |", "|" + "---|" * len(show)]
    lines += ["| " + " | ".join(_fmt(r[k]) for k in show) + " |" for r in rows]
    note = ("\n\nstrokeN = aN * L0 of muscle lN (rest length, the length the servo pulls); idle = muscles the "
            "design leaves at a < 0.001 (routed, but not worth building for this target); difference = "
            "weighted RMS node distance to the target after rigid alignment (a length), relative = over the "
            "body's diameter; iterations = IPOPT iterations of the flattened design; equilibrium_start = difference of the "
            "equilibrium at the design's starting contractions, equilibrium_rises = iterates after which the "
            "difference of the equilibrium at the iterate's contractions grows (Figure 6c).\n")
    with atomic_path(md_path) as tmp:
        with open(tmp, "w") as fh:
            fh.write("# Table 1: contractions of the Figure 6 layouts\n\n" + "\n".join(lines) + note)


# the files run_figure writes into its folder (an ``mdsr run`` records them in the run folder's manifest)
OUTPUTS = ("figure6a.png", "figure6b.png", "figure6c.png", "table1.csv", "table1.md", "figure6.json", "findings.txt")


def run_figure(out, resolution="medium", log=print, vector=None) -> int:
    """Route, design and draw Figure 6 and Table 1 into folder ``out``.

    Parameters
    ----------
    out : str or path-like
        The folder written.
    resolution : str or int
        The scenes' resolution (``"coarse"``, ``"medium"``, ``"fine"`` or a node count).
    log : callable
        Receives one progress line per design and the findings.
    vector : bool, str or sequence of str, optional
        Every figure also as a vector file beside its PNG (:func:`mdsr_opt.plot.style.figure_formats`:
        ``True`` a PDF, ``"svg"`` an SVG; ``mdsr run figure6 --vector``). A bad format is a ValueError
        before any work.

    Returns
    -------
    int
        0 when all ten designs succeeded, 1 otherwise (the table says which failed and why).
    """
    import matplotlib

    if "matplotlib.pyplot" not in sys.modules:
        matplotlib.use("Agg")
    from mdsr_opt.body.io import atomic_path, write_json
    from mdsr_opt.plot.common import figure_paths, save_figure
    from mdsr_opt.plot.routing import plot_convergence, plot_design_grid, plot_layout_grid
    from mdsr_opt.plot.style import figure_formats

    figure_formats(vector)  # a bad vector format: ValueError before any work
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
             "row_labels": labels(r), "units": r["scene"].units} for r in runs]
    files = []

    def save(fig, name):  # the PNG, and with vector its PDF/SVG beside it: every path listed
        save_figure(fig, os.path.join(out, name), close=True, vector=vector)
        files.extend(figure_paths(os.path.join(out, name), vector))

    save(plot_layout_grid(cols, title="Figure 6a: targets, contraction graphs, layouts at "
                                      "a smaller (C) and a larger (D) K_a"), "figure6a.png")
    dcols = [{"title": c["title"], "mesh": c["mesh"], "target": c["target"], "row_labels": c["row_labels"],
              "units": c["units"],
              "designs": [{"x": d.x_aligned, "muscles": lay.muscles, "difference": d.difference,
                           "success": d.success} for d, lay in zip(r["designs"], r["layouts"])]}
             for c, r in zip(cols, runs)]
    save(plot_design_grid(dcols, title="Figure 6b: driven by the designed contractions (blue) over the target "
                                       "(grey)", row_names=["target", "layout C, driven", "layout D, driven"]), "figure6b.png")
    panels = [{"title": c["title"], "units": c["units"],
               "traces": [(f"{lab}, {len(lay)} m.", t["iterations"], t["difference"])
                          for lab, lay, t in zip(c["row_labels"], r["layouts"], r["traces"])]}
              for c, r in zip(cols, runs)]
    save(plot_convergence(panels, title="Figure 6c: difference of the equilibrium at each IPOPT iterate's "
                                        "contractions (flattened design)"), "figure6c.png")
    rows = table_rows(runs)
    write_table(rows, os.path.join(out, "table1.csv"), os.path.join(out, "table1.md"))
    files += [os.path.join(out, "table1.csv"), os.path.join(out, "table1.md")]
    write_json(os.path.join(out, "figure6.json"), {
        "resolution": resolution, "routing": ROUTING, "rows": rows,
        "layouts": [{"target": f"{r['scene'].name}/{r['case'].name}", "K_a": K_a,
                     "muscles": [list(m.nodes) for m in lay], "dropped": [d.reason for d in lay.dropped],
                     "trace": t} for r in runs for K_a, lay, t in zip(r["K_a"], r["layouts"], r["traces"])]})
    files.append(os.path.join(out, "figure6.json"))
    found = findings(rows)
    with atomic_path(os.path.join(out, "findings.txt")) as tmp:
        with open(tmp, "w") as fh:
            fh.write("\n".join(found) + "\n")
    files.append(os.path.join(out, "findings.txt"))
    for line in found:
        log(line)
    ok = all(row["success"] for row in rows)
    log(f"figure6: {sum(row['success'] for row in rows)}/{len(rows)} designs succeeded in "
        f"{time.perf_counter() - t0:.1f} s; wrote {', '.join(os.path.basename(f) for f in files)} to {out}")
    return 0 if ok else 1


def main(argv=None) -> int:
    from mdsr_opt.scenes.runscene import figure_arguments

    a = figure_arguments("figure6", __doc__.split("\n")[0], argv)
    code = run_figure(a.out, resolution=a.resolution, vector=a.vector)
    with open(os.path.join(a.out, "table1.md")) as fh:
        print(fh.read())
    return code


if __name__ == "__main__":
    raise SystemExit(main())
