"""A scene's gait, run and written: the scene runner's hook that lays one muscle layout for a gait's poses,
solves its schedule (:mod:`mdsr_opt.synthesis.gait`) and writes its files into the run's folder."""

from __future__ import annotations

import copy
import os
from pathlib import Path
from typing import Mapping

import numpy as np

from ..core.costs import figure_cost, gif_cost
from ..core.quantities import length_unit
from ..plot.style import muscle_label
from ..synthesis.gait import GaitSchedule, gait_schedule, save_gait_animation

__all__ = ["run_gait"]


def _write_schedule(schedule: GaitSchedule, title: str, path, vector=None) -> str:
    """``schedule.png``: the strokes over time (:func:`~mdsr_opt.plot.design.plot_schedule`); with ``vector`` a
    PDF/SVG beside it."""
    from ..plot.common import save_figure
    from ..plot.design import plot_schedule

    return save_figure(plot_schedule(schedule, title=title), path, close=True, vector=vector)


def _gait_label(name: str) -> str:
    """How the log names a gait: ``gait wave``, and ``gait`` alone for one named "gait" (not "gait gait")."""
    return "gait" if name == "gait" else f"gait {name}"


def run_gait(scene, out, runs: Mapping, *, figures: bool = True, log=None, writer=None,
             vector=None, animation: bool = True) -> dict | None:
    """The scene runner's hook: a scene's :class:`~mdsr_opt.synthesis.gait.Gait` from its designed cases, written to ``out/<gait>/``.

    Lays one muscle layout for the gait's poses (:func:`~mdsr_opt.synthesis.poses.design_poses`, the scene's routing and
    design options, the budget ``gait.max_muscles``; the runner's own per-case routings and designs are the
    separate layouts compared against), solves the schedule (:func:`~mdsr_opt.synthesis.gait.gait_schedule`) and writes
    ``layout.json``, ``schedule.csv``, ``schedule.png`` (with ``figures``), ``<gait>.gif`` (with ``figures``
    and ``animation``) and the fabrication files ``<scene>.svg``, ``<scene>.dxf``, ``<scene>_muscles.csv``
    in ``scene.units``, with the channel, wall and fixtures the layout was routed with (the scene's
    ``[fabrication]``); a failed gait's say ``FAILED DESIGN: <reason>, do not build``.

    Parameters
    ----------
    scene : Scene with a ``gait``.
    out : the run's folder.
    runs : mapping case name -> CaseRun (``.setup.target``, ``.setup.muscles``, ``.design``).
    figures, animation : write the chart; with both, the GIF. ``log``: progress messages.
    vector : with ``figures``, also write the chart as PDF/SVG (:func:`mdsr_opt.plot.common.save_figure`).
    writer : :class:`~mdsr_opt.core.jobs.Jobs`, optional
        Runs the chart, GIF and fabrication jobs (its ``submit``; default: here, in turn); ``<gait>.json``,
        listing the files, is written when the last has reported (a pool's: at the writer's ``wait``).

    Returns
    -------
    dict or None
        JSON-friendly summary with ``success`` (every pose designed, every frame solved, every keyframe's pose
        reached: ``reached``, ``unreached``) and the files; None when a pose of the gait was not run (``--case``).
    """
    from ..synthesis.export import export_fabrication, fabrication_files
    from ..body.io import write_json
    from ..synthesis.poses import design_poses
    from .casefab import fixture_wall
    from .obstacles import case_contact

    gait = scene.gait
    say = log or (lambda s: None)
    if any(c not in runs for c in gait.poses):
        return None
    folder = Path(out) / gait.name
    info: dict = {"kind": "gait", "poses": list(gait.poses), "sequence": list(gait.sequence), "units": scene.units}
    missing = [c for c in gait.poses if runs[c].setup is None or getattr(runs[c].setup, "target", None) is None]
    if missing:
        info.update(success=False, message=f"no target for pose(s) {', '.join(missing)}")
        return info
    targets = {c: runs[c].setup.target for c in gait.poses}
    separate = {c: (tuple(runs[c].setup.muscles), runs[c].design) for c in gait.poses
                if runs[c].design is not None and len(runs[c].setup.muscles)}
    # every design of the gait keeps a rope's two end fixtures the scene's wall apart, as its cases' designs
    dopt, case_radii = {**scene.design_options, "fixture_wall": fixture_wall(scene)}, _case_radii(runs, gait.poses)
    if dopt.get("anchor_radius") is None and len(set(case_radii.values())) == 1 and all(
            c in separate and not _routed(runs[c].setup) for c in gait.poses):
        # the poses' muscles are given (the scene's), not routed: the fixtures the cases were designed with
        dopt["anchor_radius"] = next(iter(case_radii.values()))
    try:
        res = design_poses(scene.mesh, scene.material, targets, max_muscles=gait.max_muscles,
                           routing_options=scene.routing_options, design_options=dopt,
                           separate=separate, units=scene.units,
                           idle_contraction=getattr(scene, "acceptance", {}).get("idle_contraction"))
        sch = gait_schedule(scene.mesh, scene.material, res, list(gait.sequence), frames_per_step=gait.frames_per_step,
                            cyclic=gait.cyclic, step_time=gait.step_time, units=scene.units,
                            max_difference=getattr(scene, "acceptance", {}).get("max_difference"))
    except ValueError as exc:
        info.update(success=False, message=str(exc))
        say(f"[{scene.name}] {_gait_label(gait.name)}: not made ({exc})")
        return info
    radius_note = _radius_note(res.anchor_radius, case_radii, scene.units)
    touching = [c for c in gait.poses if case_contact(scene, scene.case(c))]
    obstacle_note = (f"the gait's layout and schedule are designed without the obstacles of {', '.join(touching)} "
                     "(its designs model none)") if touching else ""
    if obstacle_note:
        say(f"[{scene.name}] {_gait_label(gait.name)}: {obstacle_note}")
    if res.dropped:  # said as a case's idle muscles are (the notes, in summary.json and summary.md, say why)
        say(f"[{scene.name}] {_gait_label(gait.name)}: idle {', '.join(d.name for d in res.dropped)} dropped from "
            f"the shared layout (no pose uses {'it' if len(res.dropped) == 1 else 'them'})")
    # what the layout resolved, then the fixtures and the obstacles left out
    notes = list(res.notes) + [n for n in (radius_note, obstacle_note) if n]
    info.update({"notes": notes} if notes else {})
    info.update({"dropped": [d.to_dict() for d in res.dropped]} if res.dropped else {})
    files = [res.save(folder / "layout.json"), sch.write_csv(folder / "schedule.csv")]
    # the chart, the GIF and the fabrication files are jobs; <gait>.json (beside <gait>.gif, as an animation's
    # <name>.json beside its GIF), which lists their files, is written once every one of them has reported (at
    # the writer's wait when they run in workers): a job that fails leaves none
    jobs = []
    if figures:
        from ..plot.style import figure_paths  # not plot.common: matplotlib is the jobs' import
        chart, gif = folder / "schedule.png", folder / f"{gait.name}.gif"
        jobs.append((_write_schedule, (sch, f"{scene.name} {gait.name}: strokes over time ({sch.n_frames} frames; "
                                            "dotted: achieved)", chart), {"vector": vector}, figure_cost()))
        files += figure_paths(chart, vector)
    if figures and animation:
        jobs.append((save_gait_animation, (scene.mesh, sch, res.muscles, gif),
                     {"title": f"{scene.name} {gait.name}:", "fps": gait.fps}, gif_cost(sch.n_frames)))
        files.append(str(gif))
    ok = res.success and sch.success
    failed = [int(k) for k in np.flatnonzero(~sch.frame_success)]
    why = "; ".join([f"frames {failed} of the schedule failed"] * bool(failed) + [sch.outcome()] * bool(sch.unreached))
    jobs.append((export_fabrication, (scene.mesh, res, folder), {"units": scene.units, "name": scene.name,  # a failed
                 "material": scene.material, "allow_failed": True, "failure": why}, 0.0))  # one's say FAILED
    files += [os.fspath(p) for p in fabrication_files(folder, scene.name).values()]
    info.update(success=ok, n_muscles=res.n_muscles, muscles=[muscle_label(m, i) for i, m in enumerate(res.muscles)],
                fixture_radius=None if res.anchor_radius is None else float(res.anchor_radius), separate_n_muscles=int(res.separate_n_muscles.sum()),
                differences=dict(zip(res.names, map(float, res.differences))),
                separate_differences={n: (float(v) if np.isfinite(v) else None)
                                      for n, v in zip(res.names, res.separate_differences)},
                strokes={n: [float(v) for v in row] for n, row in zip(res.names, res.strokes)},
                frames=sch.n_frames, failed_frames=failed,
                reached=[bool(r) for r in sch.reached], unreached=list(sch.unreached),
                message="" if ok else "; ".join([f"{n}: {s}" for n, s, o in zip(res.names, res.status, res.pose_success)
                                                  if not o] + list(res.problems)
                                                 + ([f"frames {failed} failed"] if failed else [])
                                                 + ([sch.outcome()] if sch.unreached else [])),
                times={k: float(v) for k, v in res.times.items()},
                files=[os.path.relpath(f, folder.parent) for f in files])
    record, waiting = copy.deepcopy(info), [len(jobs)]

    def reported(_value):
        waiting[0] -= 1
        if not waiting[0]:
            write_json(folder / f"{gait.name}.json", record)

    for fn, args, kwargs, cost in jobs:
        if writer is not None:
            writer.submit(fn, *args, on_done=reported, cost=cost, **kwargs)
        else:
            reported(fn(*args, **kwargs))
    say(f"[{scene.name}] {_gait_label(gait.name)}: {res.n_muscles} shared muscle(s) (separate layouts: "
        f"{int(res.separate_n_muscles.sum())}), difference ({length_unit(scene.units)}) " + ", ".join(
            f"{n} {d:.4g} ({_own(s, c)})" for n, d, s, c in zip(res.names, res.differences, res.separate_differences,
                                                            res.separate_n_muscles))
        + ("" if sch.unreached else f"; {sch.outcome()}")  # else in the message
        + (f"; {radius_note}" if radius_note else "") + ("" if ok else " - FAILED: " + info["message"]))
    return info


def _own(difference: float, n_muscles: int) -> str:
    """The words for a pose's difference with its own layout: the number, or why there is none."""
    return f"own {difference:.4g}" if np.isfinite(difference) else \
        "own layout: no muscle routed" if not n_muscles else "own layout not designed"


def _routed(setup) -> bool:
    """Were this case's muscles routed (fitted to their fixtures), rather than given by the scene or case?"""
    routing = getattr(setup, "routing", None)
    return routing is not None and tuple(setup.muscles) == tuple(routing.muscles)


def _case_radii(runs: Mapping, poses) -> dict:
    """Per pose the fixture (anchor patch) radius its case's design was made with, where it has one."""
    designs = {c: runs[c].design for c in poses}
    return {c: float(d.anchor_radius) for c, d in designs.items() if getattr(d, "anchor_radius", None) is not None}


def _radius_note(radius, case_radii: Mapping, units) -> str:
    """The words for a gait whose fixtures differ from those its cases were designed with ("" if the same):
    its strokes and differences are then not the cases' for the same muscle and target."""
    if radius is None or not case_radii or all(abs(r - radius) <= 1e-9 * max(abs(r), 1.0)
                                               for r in case_radii.values()):
        return ""
    unit = f" {units}" if units else ""
    cases = ", ".join(f"{c} {r:.4g}" for c, r in case_radii.items())
    return (f"the gait's end fixtures have radius {radius:.4g}{unit}, the cases' designs {cases}{unit}: one size "
            "at which every shared rope keeps its fixtures, so its strokes and differences differ from the "
            "cases' for the same muscle and target")
