"""The face's four expressions from ONE muscle layout, in one figure.

A face robot carries one set of muscles for all its expressions. This figure script lays that set with
:func:`~mdsr_opt.synthesis.poses.design_poses` for the face scene's four expression targets (``face.py``:
smile, frown, wink, pucker; each routed with ``face.EXPRESSION_ROUTING``, the routings merged), designs
every expression's strokes on it and measures each by ``face.motion_recovered`` on ``face.moving_nodes``
(every node the expression moves by more than 10 % of its largest motion, with the whole rim of every hole
such a node is on). The layout is the one the face scene's cases are designed on (checked: the same node
chains), so ``mdsr run face`` designs the same muscles case by case.

This script is a figure, not a scene: ``mdsr run face_expressions --out DIR`` calls its ``run_figure``
(``mdsr run all`` skips it). It writes

- ``expressions.png``: each expression's target (top) and the face driven by its designed strokes over it,
  with the layout's muscles it pulls (bottom);
- ``expressions.json``: the layout (each muscle's name and node chain) and per expression the muscles it
  pulls, their contractions and strokes, the difference, the motion recovered and the nodes measured;
- ``layout.json``: the :class:`~mdsr_opt.synthesis.poses_result.PosesResult`;
- with ``--vector``, ``expressions.pdf`` (or ``.svg``) beside the PNG.

Run ``python problems/face_expressions.py --out out/face_expressions``.
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

#: the share of its target motion every expression must reach on its moving nodes
REQUIRED = 0.70

# the files run_figure writes into its folder (an ``mdsr run`` records them in the run folder's manifest)
OUTPUTS = ("expressions.png", "expressions.json", "layout.json")


def _face_module():
    from mdsr_opt.scenes.library import load_problem_module

    return load_problem_module(os.path.join(os.path.dirname(os.path.abspath(__file__)), "face.py"))


def design_expressions(resolution="medium"):
    """The face scene, its module, the targets and the :class:`PosesResult` of its four expressions on one
    layout. Raises ``RuntimeError`` when that layout is not the one the scene's cases use."""
    from mdsr_opt.scenes.library import get_problem
    from mdsr_opt.synthesis.poses import design_poses

    face = _face_module()
    scene = get_problem("face", resolution=resolution)
    routing = {**scene.routing_options, **face.EXPRESSION_ROUTING}
    layout, targets = face.one_layout(scene.mesh, scene.material, scene.cases, routing,
                                      scene.design_options.get("anchor_radius"))
    res = design_poses(scene.mesh, scene.material, {c: targets[c] for c in scene.case_names},
                       routing_options=routing, design_options=scene.design_options, compare=False,
                       clashes=face.CLASHES)
    if [tuple(m.nodes) for m in res.muscles] != [tuple(m.nodes) for m in layout]:
        raise RuntimeError("face_expressions: design_poses laid another layout than the face scene's cases use")
    return scene, face, targets, res


def expression_rows(scene, face, targets, res) -> list[dict]:
    """Per expression: the muscles it pulls, contractions, strokes, difference and motion recovered."""
    rows = []
    for k, name in enumerate(res.names):
        d = res.designs.get(name)
        on = np.flatnonzero(res.engaged[k])
        moving = face.moving_nodes(scene.mesh, targets[name])
        rec = (face.motion_recovered(scene.mesh.points, targets[name], d.x_aligned, moving)
               if d is not None else float("nan"))
        rows.append({"expression": name, "muscles": [res.muscles[i].name for i in on],
                     "contractions": [float(res.contractions[k, i]) for i in on],
                     "strokes": [float(res.strokes[k, i]) for i in on], "difference": float(res.differences[k]),
                     "motion_recovered": float(rec), "measured_nodes": int(len(moving)),
                     "success": bool(res.pose_success[k]), "status": str(res.status[k])})
    return rows


def run_figure(out, resolution="medium", log=print, vector=None) -> int:
    """Lay the face's one layout, design its four expressions and draw them into folder ``out``.

    Parameters
    ----------
    out : str or path-like
        The folder written.
    resolution : str or int
        The face's resolution (``"coarse"``, ``"medium"``, ``"fine"`` or a node count).
    log : callable
        Receives one line per expression and a summary.
    vector : bool, str or sequence of str, optional
        The figure also as a vector file beside its PNG (:func:`mdsr_opt.plot.style.figure_formats`:
        ``True`` a PDF, ``"svg"`` an SVG; ``mdsr run face_expressions --vector``). A bad format is a
        ValueError before any work.

    Returns
    -------
    int
        0 when every expression's design succeeded and recovered at least :data:`REQUIRED` of its motion.
    """
    import matplotlib

    if "matplotlib.pyplot" not in sys.modules:
        matplotlib.use("Agg")
    from mdsr_opt.body.io import write_json
    from mdsr_opt.plot.common import figure_paths, save_figure
    from mdsr_opt.plot.routing import plot_design_grid
    from mdsr_opt.plot.style import figure_formats

    figure_formats(vector)  # a bad vector format: ValueError before any work
    t0 = time.perf_counter()
    os.makedirs(out, exist_ok=True)
    scene, face, targets, res = design_expressions(resolution)
    rows = expression_rows(scene, face, targets, res)
    cols = []
    for k, r in enumerate(rows):
        d = res.designs.get(r["expression"])
        on = np.flatnonzero(res.engaged[k])
        cols.append({"title": f"{r['expression']}: {100 * r['motion_recovered']:.0f} % of its motion",
                     "mesh": scene.mesh, "target": targets[r["expression"]], "units": scene.units,
                     "row_labels": [f"pulls {', '.join(r['muscles'])}"],
                     "designs": [{"x": d.x_aligned if d is not None else scene.mesh.points,
                                  "muscles": [res.muscles[i] for i in on], "difference": r["difference"],
                                  "success": r["success"]}]})
    names = f"{res.muscles[0].name}..{res.muscles[-1].name}" if res.n_muscles > 1 else res.muscles[0].name
    fig = plot_design_grid(cols, title=f"One face, one layout of {res.n_muscles} muscles ({names}): each expression's "
                                       "target (top) and the face its strokes drive (bottom)",
                           row_names=["target", "driven by its strokes"])
    save_figure(fig, os.path.join(out, "expressions.png"), close=True, vector=vector)
    files = figure_paths(os.path.join(out, "expressions.png"), vector)
    files.append(write_json(os.path.join(out, "expressions.json"), {
        "resolution": resolution, "nodes": scene.mesh.n_nodes, "required": REQUIRED,
        "layout": [{"name": m.name, "nodes": [int(v) for v in m.nodes], "sources": list(s)}
                   for m, s in zip(res.muscles, res.sources)],
        "expressions": rows, "layout_problems": list(res.problems)}))
    files.append(res.save(os.path.join(out, "layout.json")))
    for r in rows:
        log(f"{r['expression']}: pulls {', '.join(r['muscles'])}; {100 * r['motion_recovered']:.1f} % of its "
            f"motion on {r['measured_nodes']} nodes; {'ok' if r['success'] else 'FAILED: ' + r['status']}")
    ok = all(r["success"] and r["motion_recovered"] >= REQUIRED for r in rows)
    log(f"face_expressions: one layout of {res.n_muscles} muscles, {sum(r['success'] for r in rows)}/4 designs "
        f"succeeded in {time.perf_counter() - t0:.1f} s; wrote {', '.join(os.path.basename(f) for f in files)} "
        f"to {out}")
    if res.problems:  # the expressions are reached, but the one layout cannot be cast in one layer
        log(f"face_expressions: the layout is NOT mouldable in one layer ({len(res.problems)} place(s), in "
            "expressions.json's layout_problems): crossing ropes need channels at two depths")
    return 0 if ok else 1


def main(argv=None) -> int:
    from mdsr_opt.scenes.runscene import figure_arguments

    a = figure_arguments("face_expressions", __doc__.split("\n")[0], argv)
    return run_figure(a.out, resolution=a.resolution, vector=a.vector)


if __name__ == "__main__":
    raise SystemExit(main())
