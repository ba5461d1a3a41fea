"""The README's main job: mesh a shape, drag it, contract a muscle, write figures and meshes.

Run it as ``mdsr demo --out DIR``. It takes a few seconds and writes into ``DIR``:

- ``external.png``, ``external.vtu``: a finger anchored at its base and bent 90 degrees by dragging its tip;
- ``internal_springs.png``, ``internal_cable.png`` and ``.vtu``: the free finger with a muscle along its
  lower side commanded to contract by 30 %, with the dummy springs (a penalty: the body resists a little)
  and the exact cable (an inextensible rope: it reaches the command); the log and the titles give the
  contraction and stroke each one achieved;
- ``summary.json``: solver status, iterations, energies and timings of each solve.
"""

from __future__ import annotations

import logging
import os
import time

import numpy as np

from ..core.errors import InputError, InputTypeError
from ..core.progress import progress_for_cli

__all__ = ["finger_outline", "run_demo", "check_demo_mesh_size", "add_cli"]


def finger_outline(length: float = 4.0, width: float = 1.0, n_round: int = 12) -> np.ndarray:
    """A strip with a rounded tip: the demo's body (counter-clockwise)."""
    r = width / 2
    arc = np.linspace(-np.pi / 2, np.pi / 2, n_round)
    tip = np.column_stack([length - r + r * np.cos(arc), r + r * np.sin(arc)])
    return np.vstack([[0.0, 0.0], tip, [0.0, width]])


#: the files the demo writes into its folder
DEMO_FILES = ("external.png", "external.vtu", "internal_springs.png", "internal_springs.vtu", "internal_cable.png",
              "internal_cable.vtu", "summary.json")


def run_demo(out: str, max_area: float = 0.01, contraction: float = 0.3, log=None, overwrite: bool = False) -> dict:
    """Run the demo into ``out``; ``log`` takes the progress messages (default: this module's logger).

    ``out`` follows ``mdsr run``'s rules (:class:`~mdsr_opt.scenes.rundir.RunFolder`): a new or empty folder,
    locked while the demo writes; with ``overwrite`` an earlier mdsr output there is replaced (only the files
    its manifest lists), without it a folder that holds anything is refused.
    """
    log = log or logging.getLogger(__name__).info
    from ..scenes.rundir import RunFolder, check_out_path

    # every argument before any work: meshing and solving take seconds
    for name, v in (("max_area", max_area), ("contraction", contraction)):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
            raise InputTypeError(f"{name} must be a number, got {type(v).__name__}")
        if not np.isfinite(v):
            raise InputError(f"{name} must be finite, got {v}")
    if not 0.0 <= contraction < 1.0:
        raise InputError(f"contraction {contraction} is outside [0, 1) (a fraction of the muscle's rest length)")
    if max_area <= 0:
        raise InputError(f"max_area must be > 0, got {max_area}")
    check_demo_mesh_size(max_area)
    check_out_path(out)
    with RunFolder(out, overwrite=overwrite, claims=DEMO_FILES) as folder:
        folder.begin(DEMO_FILES)
        summary = _write_demo(out, max_area, contraction, log)
        folder.finish("complete" if summary["success"] else "complete, some solves failed")
    return summary


def _write_demo(out: str, max_area: float, contraction: float, log) -> dict:
    """The demo's work, into the folder ``out`` (made and guarded by :func:`run_demo`)."""
    from ..body import io
    from ..plot.common import coordinate_axes, legend_below, plot_mesh, plot_muscles, save_figure
    from ..plot.style import commanded_achieved, energy_label, shared_limits
    from ..mechanics.equilibrium import solve_external, solve_internal
    from ..body.material import NeoHookean
    from ..body.mesh import Mesh
    from ..body.muscles import Muscle

    t_all = time.perf_counter()
    log(f"[1/4] meshing a finger (max triangle area {max_area})")
    mesh = Mesh.from_polygon(finger_outline(), max_area=max_area)
    mat = NeoHookean(E=1.0, nu=0.4)
    P = mesh.points
    log(f"      {mesh.n_nodes} nodes, {mesh.n_triangles} triangles, min angle "
        f"{mesh.quality()['min_angle_deg']:.1f} deg")
    summary: dict = {"mesh": mesh.quality(), "material": {"E": mat.E, "nu": mat.nu}}

    log("[2/4] external driving: anchor the base, drag the tip through 90 degrees")
    base = np.nonzero(P[:, 0] < 1e-9)[0]
    tip = int(np.argmax(P[:, 0]))
    # the tip goes where a circular arc of the finger's centre line would put it after 90 degrees
    L = P[tip, 0]
    R = 2 * L / np.pi
    target = np.array([R, 0.5 + R])
    ext = solve_external(mesh, mat, anchors=base, drags={tip: target})
    log(f"      {ext.status}: {ext.iterations} iterations in {len(ext.steps)} load step(s), "
        f"{ext.solve_time:.2f} s")
    summary["external"] = ext.summary()
    energy = energy_label(getattr(mat, "stress_unit", None), None)
    fig = plot_mesh(mesh, ext.x, values=io_energy(mesh, mat, ext.x), colorbar_label=energy,
                    title="external driving: anchored base, dragged tip")
    ax = fig.axes[0]
    plot_mesh(mesh, None, ax=ax, color="none", edgecolor="#bbbbbb", alpha=0.6)
    # the marks said in a legend under the drawing (beside it sits the colour bar)
    ax.plot(ext.x[base, 0], ext.x[base, 1], "s", color="k", ms=3, label="anchored nodes")
    ax.plot(ext.x[tip, 0], ext.x[tip, 1], "o", color="#d62728", ms=5, label="dragged tip")
    ax.plot([], [], "-", color="#bbbbbb", lw=0.8, label="rest shape")
    legend_below(ax, ncol=3)
    coordinate_axes(ax)
    save_figure(fig, os.path.join(out, "external.png"), close=True)
    io.write_mesh(os.path.join(out, "external.vtu"), mesh, x=ext.x, material=mat)

    log(f"[3/4] internal driving: a muscle along the lower side is commanded to contract by {contraction:.0%}")
    lower = sorted((i for i in range(mesh.n_nodes) if P[i, 1] < 1e-9), key=lambda i: P[i, 0])
    muscle = Muscle(lower)  # M1, as every figure and drawing names it
    results = {}
    for model in ("springs", "cable"):
        res = solve_internal(mesh, mat, [muscle], [contraction], muscle_model=model)
        got, stroke, tension = float(res.achieved[0]), float(res.stroke[0]), float(res.tension[0])
        ratio = muscle.length(res.x) / muscle.rest_length(mesh)
        log(f"      {model}: {res.status}, {res.iterations} iterations; achieved contraction {got:.1%} "
            f"(commanded {contraction:.0%}), stroke {stroke:.3f}, tension {tension:.3g}"
            + (", rope slack" if res.slack[0] else ""))
        summary[f"internal_{model}"] = {**res.summary(), "muscle_length_ratio": ratio}
        results[model] = res
    # the two muscle models' panels are compared: one colour scale for both
    energies = {m: io_energy(mesh, mat, r.x) for m, r in results.items()}
    lo, hi = shared_limits(*energies.values())
    for model, res in results.items():
        # the title states the commanded contraction beside the one the muscle reached
        fig = plot_mesh(mesh, res.x, values=energies[model], colorbar_label=energy, vmin=lo, vmax=hi,
                        title=f"{model}: contraction commanded \u2192 achieved "
                              f"{commanded_achieved([contraction], res.achieved)}, "
                              f"stroke {float(res.stroke[0]):.3g} body units")
        plot_muscles(res.x, [muscle], ax=fig.axes[0])
        legend_below(fig.axes[0], ncol=1)
        coordinate_axes(fig.axes[0])
        save_figure(fig, os.path.join(out, f"internal_{model}.png"), close=True)
        io.write_mesh(os.path.join(out, f"internal_{model}.vtu"), mesh, x=res.x, material=mat)

    log("[4/4] writing summary.json")
    summary["total_time_s"] = time.perf_counter() - t_all
    ok = all(summary[k]["success"] for k in ("external", "internal_springs", "internal_cable"))
    summary["success"] = ok
    io.write_json(os.path.join(out, "summary.json"), summary)
    log(f"done in {summary['total_time_s']:.1f} s: {'all solves succeeded' if ok else 'SOME SOLVES FAILED'}; "
        f"results in {out}")
    return summary


def check_demo_mesh_size(max_area: float) -> None:
    """Refuse, before any work, a ``max_area`` that would make more triangles than :meth:`Mesh.from_polygon`
    allows (its ``MAX_TRIANGLES``): the finger has no thin part, so its count is the area bound's."""
    from ..body.mesh import MAX_TRIANGLES
    from ..body.polygons import polygon_area
    from ..body.triangulate import TRIANGLES_PER_AREA

    area = abs(polygon_area(finger_outline()))
    expected = TRIANGLES_PER_AREA * area / float(max_area)
    if expected > MAX_TRIANGLES:
        raise InputError(f"max_area {max_area:g} would make about {expected:.3g} triangles, more than the limit "
                         f"{MAX_TRIANGLES:,}; give --max-area of at least {TRIANGLES_PER_AREA * area / MAX_TRIANGLES:.2g}")


def io_energy(mesh, material, x):
    return material.psi(mesh.deformation_gradients(x))


def add_cli(sub) -> None:
    p = sub.add_parser("demo", help="mesh a finger, drag it, contract a muscle; write figures and meshes")
    p.add_argument("--out", default="demo_out", help="output folder (default: demo_out)")
    p.add_argument("--max-area", type=float, default=0.01, help="largest triangle area (default 0.01)")
    p.add_argument("--contraction", type=float, default=0.3, help="muscle contraction in [0, 1) (default 0.3)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the files of an earlier mdsr command in --out (as mdsr run --overwrite); without "
                   "it a non-empty --out is refused")
    p.set_defaults(func=lambda a: 0 if run_demo(a.out, a.max_area, a.contraction, overwrite=a.overwrite,
                                                log=progress_for_cli(a, 0, "mdsr demo", bar=False))["success"] else 1)
