"""A whole scene through the pipeline into a run folder (:func:`run_scene`, the one way to run a scene from
Python), and problem scripts' command line (:func:`run_main`).

:func:`write_scene`, :func:`run_entries` and :func:`scene_pool` are the internals that ``run_scene`` and
``mdsr run`` share (``mdsr run`` guards one folder and one worker pool for several scenes); they are not
part of the public API."""

from __future__ import annotations

import argparse
import contextlib
import functools
import logging
import os
import sys
from concurrent.futures import Executor
from pathlib import Path
import time
from typing import Callable, Sequence

from ..body.material import material_dict
from ..body.muscles import Muscle
from ..core.costs import animation_cost, figure_cost, photo_cost, shapes_cost
from ..core.errors import checking_input, exit_report
from ..core.jobs import Jobs, main_is_plain_script, process_pool
from ..core.progress import advance, progress_for_cli
from .gaitrun import run_gait
from .animate import animate
from .names import RUN_FILES
from .rundir import check_interrupt, RunFolder, noting_interrupts
from .runner import CaseRun, case_files, case_parts, finite, measure_case, measure_prototype, run_case
from .scene import Scene, resolve_resolution
from .scenereport import SceneReport
from .casefab import write_case_fabrication
from .grips import PROTOTYPE_NOTE
from .obstacles import case_contact
from .verdict import prototype_verdict

__all__ = ['run_scene', 'run_main', 'figure_arguments']


_LOG = logging.getLogger(__name__)

#: what the jobs of a run import (figures, meshes, photographs, the prototype's and the animations' solves):
#: the workers of its pool import them as they start (see :func:`~mdsr_opt.core.jobs.process_pool`)
JOB_MODULES = ("numpy", "scipy.sparse.linalg", "scipy.spatial", "casadi", "networkx", "shapely", "cv2", "meshio",
               "matplotlib.pyplot", "mdsr_opt.plot.scenes", "mdsr_opt.plot.design", "mdsr_opt.plot.photos",
               "mdsr_opt.mechanics.equilibrium", "mdsr_opt.synthesis.routing", "mdsr_opt.synthesis.gait",
               "mdsr_opt.synthesis.export", "mdsr_opt.photos.camera", "mdsr_opt.photos.contours",
               "mdsr_opt.photos.loops", "mdsr_opt.scenes.prototype", "mdsr_opt.scenes.animate",
               "mdsr_opt.scenes.runscene")


def scene_pool(workers: int | None = None):
    """:func:`~mdsr_opt.core.jobs.process_pool` for a scene's figure, photograph and animation jobs: its
    workers import :data:`JOB_MODULES` and note the files they complete in this process's run folders (made
    inside a :class:`~mdsr_opt.scenes.rundir.RunFolder`, so ``--overwrite`` and a killed run's clean-up know
    them)."""
    from ..body.io import adopt_noted_folders, noted_folders

    return process_pool(workers, JOB_MODULES, setup=(adopt_noted_folders, (noted_folders(),)))


def run_scene(scene: Scene, out: str | os.PathLike, *, cases: Sequence[str] | None = None,
              method: str | None = None, photos: bool = True, figures: bool = True,
              animations: bool = True, mesh_format: str = "vtu", photo_size: tuple[int, int] = (500, 500),
              log: Callable[[str], None] | None = _LOG.info, overwrite: bool = False,
              prototype: bool = True, prototype_seed: int = 0, background: bool | None = None,
              max_difference: float | None = None, bands: bool | None = None, vector=None) -> SceneReport:
    """Run the whole pipeline on a scene's cases and write everything into ``out``.

    For every case (or those named in ``cases``): target, contraction graph, muscles, contractions,
    forward check, SYNTHETIC photograph and contour metrics (:func:`run_case`), then its figures, meshes
    and photograph into ``out/<case>/`` (:func:`write_case`). Then each animation (forward solves of
    interpolated contractions) as ``out/<animation>.gif`` with ``out/<animation>.json``; the rest mesh
    with its regions as ``out/rest.png``; and last ``out/summary.json`` and ``out/summary.md`` (the table,
    then the notes of what the pipeline resolved on its own:
    :meth:`~mdsr_opt.scenes.scenereport.SceneReport.markdown`).

    Parameters
    ----------
    scene : Scene
    out : folder (created).
    cases : names of the cases to run (default all); animations needing a case not run are skipped.
    method : design method overriding the scene's ``design_options["method"]``.
    photos, figures, animations : turn the photographs, the figures and the animations (GIFs) off; a gait's
        layout, schedule and fabrication files are written all the same.
    mesh_format : ``"vtu"``, ``"vtk"`` or ``"xdmf"`` (through meshio).
    photo_size : (width, height) of the synthetic photographs, in pixels.
    log : progress messages (default: this module's logger at INFO level; ``None`` for silence).
    prototype, prototype_seed : with ``photos``, validate every case against a virtual prototype
        (:class:`~mdsr_opt.scenes.prototype.VirtualPrototype`, drawn from ``prototype_seed``) and write the paper's
        Tables 2-4 as ``out/validation.md``.
    background : bool, optional
        Draw and write each case's figures, meshes and photographs, make each animation (its frames'
        forward solves, GIF and JSON) and write the gait's chart, GIF and fabrication files in worker
        processes while the next solves run (:func:`~mdsr_opt.core.jobs.process_pool`: with two or more
        cores; on one core, and with ``False``, one after the other in this process). The files are the
        same either way. Default: True, except when called from a plain script file
        (:func:`~mdsr_opt.core.jobs.main_is_plain_script`), whose workers would run the script again: pass
        True from a script whose work sits under ``if __name__ == "__main__":``.
    vector : bool, str or sequence of str, optional
        Every figure also as a vector file beside its PNG, for papers: ``True`` a PDF, ``"svg"`` an SVG
        (:func:`mdsr_opt.plot.style.figure_formats`; ``mdsr run --vector``). GIFs stay GIFs.
    overwrite : bool
        ``out`` must be empty or new; with ``overwrite`` the files of an earlier run there are removed first
        (only those it recorded; see :class:`~mdsr_opt.scenes.rundir.RunFolder`, which also locks the folder
        against a second run and removes the temporaries of an interrupted one).
    max_difference : float, optional
        A case whose difference exceeds this fraction of the body's diameter fails (default: the scene's
        ``acceptance``, :data:`~mdsr_opt.synthesis.acceptance.MAX_DIFFERENCE` unless it says otherwise).
    bands : bool, optional
        Compute every stroke's uncertainty band (default: the scene's ``acceptance["bands"]``).

    Returns
    -------
    SceneReport
        ``.success`` is False when a target solve, the routing, a design (refused, not verified, or
        farther from its target than ``max_difference``) or an animation frame failed; the reasons are in
        each case's ``message`` and in ``summary.json``; the other cases still run. Nothing is hidden.

    Raises
    ------
    OutputFolderError (a ValueError)
        ``out`` is a file, cannot be written, holds other files (without ``overwrite``) or is locked by
        another run.
    KeyboardInterrupt
        Passed on at once (never recorded as a failed case); the files already complete stay.
    """
    names = _check_run(scene, cases, mesh_format, photo_size, max_difference)
    if background is None:
        background = not main_is_plain_script()
    with noting_interrupts(), RunFolder(out, overwrite=overwrite,
                                        command=f"run_scene({scene.name!r}, {os.fspath(out)!r})") as folder:
        folder.begin(run_entries(scene, names, vector=vector))
        report = write_scene(scene, out, cases=names, method=method, photos=photos, figures=figures,
                             animations=animations, mesh_format=mesh_format, photo_size=photo_size,
                             log=log, prototype=prototype, prototype_seed=prototype_seed,
                             background=background, max_difference=max_difference, bands=bands, vector=vector)
        folder.finish("complete" if report.success else "complete, some cases failed")
    return report


def _check_run(scene, cases, mesh_format, photo_size=(500, 500), max_difference=None) -> tuple[str, ...]:
    from ..body.io import FORMATS
    from ..photos.size import check_photo_size
    from ..synthesis.acceptance import check_max_difference

    check_photo_size(photo_size, "photo_size")
    if max_difference is not None:
        check_max_difference(max_difference)

    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a Scene, got {type(scene).__name__}")
    if "." + str(mesh_format).lstrip(".") not in FORMATS or mesh_format.lstrip(".") == "msh":
        raise ValueError(f"mesh_format must be 'vtu', 'vtk' or 'xdmf', got {mesh_format!r}")
    if isinstance(cases, str):
        cases = [cases]
    names = scene.case_names if cases is None else tuple(dict.fromkeys(cases))
    for c in names:
        scene.case(c)  # KeyError naming the choices
    return names


def run_entries(scene: Scene, cases: Sequence[str] | None = None, vector=None) -> list[str]:
    """Internal: the names a run of ``scene`` may write directly into its folder: :data:`RUN_FILES` (with
    ``vector``, ``rest.pdf``/``rest.svg`` too), one folder per case run and ``<animation>.gif`` /
    ``<animation>.json`` per animation."""
    from ..plot.style import figure_formats

    names = scene.case_names if cases is None else tuple(cases)
    out = list(RUN_FILES) + [f"rest.{f}" for f in figure_formats(vector)] + list(names)
    for a in scene.animations:
        out += [f"{a.name}.gif", f"{a.name}.json"]
    if scene.gait is not None:
        out.append(scene.gait.name)  # the gait's folder: layout, schedule, animation, fabrication files
    return out


def write_scene(scene: Scene, out: str | os.PathLike, *, cases: Sequence[str] | None = None,
                method: str | None = None, photos: bool = True, figures: bool = True,
                animations: bool = True, mesh_format: str = "vtu", photo_size: tuple[int, int] = (500, 500),
                log: Callable[[str], None] | None = _LOG.info, prototype: bool = True,
                prototype_seed: int = 0, background: bool = True, pool: Executor | None = None,
                max_difference: float | None = None, bands: bool | None = None, vector=None,
                wait: bool = True):
    """Internal: the body of :func:`run_scene` without the folder's guard, for ``run_scene`` and ``mdsr run``
    (call :func:`run_scene` instead). Runs and writes into ``out`` as it stands (the caller holds a
    :class:`~mdsr_opt.scenes.rundir.RunFolder`). Same parameters and result; ``pool`` (with ``background``)
    is the process pool to send the jobs to (``mdsr run`` shares one between its scenes; None: one of this
    call's own). With ``wait=False`` and a ``pool``, it returns once the scene's solves are done and its jobs
    sent: a function without arguments that waits for those jobs, writes the summaries and returns the
    SceneReport (``mdsr run`` solves the next scene meanwhile)."""
    from ..plot.style import figure_formats

    names = _check_run(scene, cases, mesh_format, photo_size, max_difference)
    figure_formats(vector)  # a bad vector format: ValueError before any work
    if pool is not None and not isinstance(pool, Executor):
        raise TypeError(f"pool must be a concurrent.futures.Executor or None, got {type(pool).__name__}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    parallel = background and (figures or photos)
    if not wait and not (parallel and pool is not None):
        raise ValueError("write_scene(wait=False) needs a pool and background=True")
    with contextlib.ExitStack() as stack:
        if parallel and pool is None:
            pool = stack.enter_context(scene_pool())
        bg = Jobs(pool if parallel else None)
        try:
            finish = _start_scene(scene, out, names, bg, method=method, photos=photos, figures=figures,
                                  animations=animations, mesh_format=mesh_format, photo_size=photo_size,
                                  log=log, prototype=prototype, prototype_seed=prototype_seed,
                                  max_difference=max_difference, bands=bands, vector=vector)
        except BaseException as exc:  # Ctrl-C or SIGTERM: the workers are ended, not waited for
            bg.stop(exc)
            raise
        if not wait:
            return finish
        return finish()


def _start_scene(scene: Scene, out: Path, names, bg: Jobs, *, method, photos, figures, animations, mesh_format,
                 photo_size, log, prototype, prototype_seed, max_difference, bands, vector) -> Callable[[], SceneReport]:
    """:func:`write_scene`'s work: the scene's solves, its jobs sent to ``bg``; returns the function that
    waits for those jobs (on an exception or Ctrl-C there: cancels the rest), then writes the scene's
    summaries and returns its report."""
    say = log or (lambda s: None)
    t0 = time.perf_counter()
    say(f"{scene.name}: {scene.title or scene.name} ({scene.mesh.n_nodes} nodes, {len(names)} case(s))")
    proto = None
    if photos and prototype:
        from .prototype import VirtualPrototype

        proto = VirtualPrototype.for_scene(scene, seed=prototype_seed, photo_size=photo_size)
        d = proto.describe()
        say(f"{scene.name}: virtual prototype: {d['nodes']} nodes ({d['design_nodes']} in the design model), "
            f"{d['elements']} elements, silicone nu {d['silicone_nu']:.3f}, E x {d['E_factor']:.3f}, rope friction "
            f"{d['rope_friction']:g}, fixtures of radius {d['fixture_radius']:.3g} (the scene's; a routed layout's "
            f"own, where shrunk, on its Table 4 line), seed {d['seed']}")
    runs: dict[str, CaseRun] = {}
    written: dict[str, list[list[str]]] = {}
    # an animation (its frames' forward solves, GIF and JSON) is one job, the run's longest: it is sent
    # as soon as the last of its cases is designed, ahead of that case's figure and photograph jobs, so
    # that it runs beside them instead of ending the run alone on one core
    anim_out: dict[str, dict] = {}
    waiting = [a for a in scene.animations if all(c in names for c in a.cases)] if animations else []
    for anim in waiting:
        anim_out[anim.name] = {}  # filled in when its job is done (the summary keeps the scene's order)

    def send_animations():  # those whose cases have all run (an animation of the rest shape: at once)
        for anim in [a for a in waiting if all(c in runs for c in a.cases)]:
            waiting.remove(anim)
            designs = {c: (runs[c].setup.muscles, runs[c].design.contractions, runs[c].design.anchor_radius)
                       for c in anim.cases if runs[c].design is not None}
            bg.submit(_animation_job, scene, anim, designs, out, figures,
                      on_done=functools.partial(_animation_done, anim_out, anim.name, say, log),
                      cost=animation_cost((len(anim.keyframes) - 1) * anim.frames_per_step + 1,
                                         scene.mesh.n_nodes, figures))

    send_animations()
    taken: list = []
    # with a pool, the internal cases' photograph jobs (the prototype driven by the scene's muscles at the
    # cases' contractions, e.g. 20, 30, 40, 50 %) are one job, sent once the last of them is designed, that
    # runs them in order of contraction: each prototype solve then steps on from the state below it
    # (VirtualPrototype keeps its solved states) instead of from rest, as a run without a pool does
    chained = [c for c in names if scene.case(c).kind == "internal" and scene.case(c).muscles is None
               and not case_contact(scene, scene.case(c))] \
        if proto is not None and bg.parallel else []
    chain: list = []
    for i, cname in enumerate(names):
        prefix = f"[{scene.name} {i + 1}/{len(names)} {cname}] "
        check_interrupt()
        # the photograph stage (measure_case) and the case's files are background jobs: the report's
        # photo entry, the files and the stage's messages arrive at bg.wait()
        run = runs[cname] = run_case(scene, cname, method=method, photo=False, log=say, prefix=prefix,
                                     max_difference=max_difference, bands=bands, taken=taken)
        if run.setup is not None:  # the next cases' routed muscles are named on from these (one name a rope),
            # the idle ones this case dropped too: a rope dropped here and kept later keeps its name
            dropped = [Muscle(tuple(d["nodes"]), name=d["name"]) for d in run.report.dropped]
            taken += [m for m in (*run.setup.muscles, *dropped) if m not in taken]
        send_animations()
        advance(log)  # the progress bar of `mdsr run` (no-op for a plain callable): the case's solves
        parts = case_parts(scene, run, out / cname, mesh_format, vector=vector) if figures else []
        written[cname] = [[] for _ in range(3)]  # the files of the shapes, the prototype's and the photograph
        cproto = proto
        if proto is not None and photos and run.design is not None and case_contact(scene, scene.case(cname)):
            cproto = None  # the virtual prototype models no contact: said, never run without the obstacles
            run.report.notes.append(PROTOTYPE_NOTE)
            say(prefix + PROTOTYPE_NOTE)
        if photos and run.design is not None and len(chained) > 1 and cname in chained:
            chain.append((run, prefix, parts[1:], written[cname][1]))
        elif photos and run.design is not None:
            # the synthetic photograph and the virtual prototype's two drivings (its Table 2/3 and Table 4
            # solves, the run's longest jobs) are three jobs, which free workers start costliest first; the
            # case's photograph stage is done (one unit of progress) when the last, the design's, reports
            bg.submit(_photo_job, scene, run, photo_size, None, prefix, parts[2:],
                      on_done=functools.partial(_photo_done, run, written[cname][2], say, log if cproto is None
                                                else None), cost=photo_cost())
            for part in (("driving", "design") if cproto is not None else ()):
                bg.submit(_prototype_job, run, cproto, prefix, parts[1:2], part,
                          on_done=functools.partial(_prototype_done, run, written[cname][1], say,
                                                    log if part == "design" else None),
                          cost=_prototype_cost(run, cproto, part))
        elif photos:
            advance(log)  # no design to photograph: the case's photograph stage is done
        if chain and cname == chained[-1]:
            chain.sort(key=lambda item: float(max(item[0].setup.case.contractions, default=0.0)))
            bg.submit(_photo_chain_job, scene, [item[:3] for item in chain], photo_size, proto,
                      on_done=functools.partial(_photo_chain_done, [(item[0], item[3]) for item in chain], say, log),
                      cost=sum(_photo_cost(item[0], proto) for item in chain))
        if parts:
            bg.submit(parts[0], on_done=functools.partial(_files_done, written[cname][0], log), cost=shapes_cost())
        elif figures:
            advance(log)  # no files to draw: the case's figure stage is done
    if scene.gait is not None:  # issue 16: one layout, gait schedule, fabrication files (no GIF: --no-animations)
        gait_info = _run_gait(scene, out, runs, figures=figures, log=say, writer=bg, vector=vector,
                              animation=animations)
        if gait_info is not None:
            anim_out[scene.gait.name] = gait_info
        advance(log)
    if figures:  # sent last: the cheapest job, which a free worker takes last, holds back no job's report
        bg.submit(_write_rest, scene, out / "rest.png", vector, cost=figure_cost())
    return functools.partial(_finish_scene, scene, out, names, bg, t0, runs, written, anim_out, proto, say, figures,
                             photos, max_difference)


def _finish_scene(scene: Scene, out: Path, names, bg: Jobs, t0: float, runs: dict, written: dict, anim_out: dict,
                  proto, say, figures: bool, photos: bool, max_difference) -> SceneReport:
    """The end of :func:`_start_scene`: wait for the scene's jobs, write ``summary.json``, ``summary.md`` and
    ``validation.md``; the report."""
    from ..body.io import atomic_path, write_json

    with bg:
        bg.wait()  # every case's files are known before the summary lists them
    for i, cname in enumerate(names):  # the prototype's validations are in: a case it failed fails
        run = runs[cname]
        if prototype_verdict(run.report):
            say(f"[{scene.name} {i + 1}/{len(names)} {cname}] FAILED: {run.report.message}")
            if figures:  # its fabrication files, drawn while the prototype ran, say so too (the same names)
                write_case_fabrication(scene, run, out / cname)
    if figures:
        for cname, parts in written.items():
            runs[cname].report.files = case_files(parts, out / cname)
    report = SceneReport(scene=scene.name, title=scene.title, n_nodes=scene.mesh.n_nodes,
                         cases=[runs[c].report for c in names], animations=anim_out, out=str(out),
                         time=time.perf_counter() - t0, units=scene.units)
    summary = report.to_dict()
    summary.update({"description": scene.description, "source": portable_source(scene.source, out),
                    "resolution": scene.resolution,
                    "mesh": {k: float(v) for k, v in scene.mesh.quality().items()},
                    "material": material_dict(scene.material),
                    "routing_options": scene.routing_options, "design_options": scene.design_options,
                    "acceptance": dict(scene.acceptance, **({} if max_difference is None else
                                                           {"max_difference": max_difference})),
                    "photographs": "SYNTHETIC (rendered by mdsr_opt.photos.camera.render_photo), not camera images"
                    if photos else None,
                    "expected": scene.expected})
    write_json(out / "summary.json", finite(summary))
    with atomic_path(out / "summary.md") as tmp:
        Path(tmp).write_text(report.markdown())
    if proto is not None:
        from .prototype import validation_tables

        with atomic_path(out / "validation.md") as tmp:
            Path(tmp).write_text(validation_tables([report]))
    say(f"{scene.name}: {'all cases succeeded' if report.success else 'SOME CASES FAILED'} in {report.time:.1f} s; "
        f"results in {out}")
    return report


def portable_source(source: str, out) -> str:
    """The scene's source as ``summary.json`` records it: a path relative to the output folder ``out`` when
    the source lies in it or beside it (at most one ``..``), else only its file name; never an absolute
    path, which would name the machine's folders (a user's home, a virtual environment)."""
    if not source:
        return ""
    src = Path(source)
    if not src.is_absolute():
        src = Path.cwd() / src
    try:
        rel = Path(os.path.relpath(src, Path(out).resolve()))
    except ValueError:  # another drive (Windows)
        return src.name
    return rel.as_posix() if rel.parts[:2] != ("..", "..") else src.name


def figure_arguments(name: str, description: str, argv: Sequence[str] | None = None):
    """The command line of a figure script (``mdsr run figure6`` runs it too): ``[--out DIR] [--resolution R]
    [--vector {pdf,svg}]``, parsed from ``argv``; ``--out`` defaults to ``out/<name>``."""
    import argparse

    p = argparse.ArgumentParser(description=description)
    p.add_argument("--out", default=os.path.join("out", name), help=f"output folder (default out/{name})")
    p.add_argument("--resolution", default="medium", type=lambda s: int(s) if s.isdigit() else s,
                   help="coarse, medium (default), fine or a node count")
    p.add_argument("--vector", choices=("pdf", "svg"), help="also write every figure in this vector format")
    return p.parse_args(argv)


def run_main(build: Callable[..., Scene], argv: Sequence[str] | None = None) -> int:
    """The ``__main__`` of a problem script: ``[--out DIR] [--resolution R] [--case NAME ...]``.

    Returns the process exit code: 0 when every case succeeded, 1 otherwise.
    """
    p = argparse.ArgumentParser(description=(build.__doc__ or "").strip().split("\n")[0])
    p.add_argument("--out", default=None, help="output folder (default: out/<scene>)")
    p.add_argument("--resolution", default=None, type=parse_resolution,
                   help="coarse, medium, fine or a node count (default: the script's, medium for most)")
    p.add_argument("--case", action="append", default=None, help="run only this case (repeatable)")
    p.add_argument("--method", default=None, choices=("flattened", "nested", "derivative-free"),
                   help="design method (default: the scene's, normally flattened)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the files of an earlier run in --out (without it, a non-empty --out is refused)")
    a = p.parse_args(argv)
    try:
        if a.out is not None:
            from .rundir import check_out_path

            check_out_path(a.out)
        with checking_input():  # building the scene checks it: bad input, before any work
            scene = build() if a.resolution is None else build(resolution=a.resolution)
        with progress_for_cli(a, n_units(scene, a.case, True), scene.name, unit="stage") as log:
            rep = run_scene(scene, a.out or os.path.join("out", scene.name), cases=a.case,
                            method=a.method, overwrite=a.overwrite, log=log,
                            background=True)  # a problem script calls run_main under its __main__ guard
    except KeyboardInterrupt:
        print(f"{p.prog}: interrupted; the files already complete are kept", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - bad input: one line, 2; a bug: its traceback, 1
        code, text = exit_report(p.prog, exc)
        print(text, file=sys.stderr)
        return code
    print(rep.table())
    return 0 if rep.success else 1


def parse_resolution(text: str):
    """``--resolution``: a name (checked with the scene) or a node count from 20 to
    :data:`~mdsr_opt.body.mesh.MAX_RESOLUTION`."""
    if not text.isdigit():
        return text
    try:
        return resolve_resolution(int(text))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def parse_seed(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        v = -1
    if v < 0:
        raise argparse.ArgumentTypeError(f"a seed is a non-negative integer, got {text!r}")
    return v


def parse_size(text: str) -> tuple[int, int]:
    """``--photo-size WxH``: each side from 64 to :data:`~mdsr_opt.photos.size.MAX_PHOTO_SIDE` pixels."""
    from ..photos.size import check_photo_size

    parts = text.lower().split("x")
    if len(parts) != 2 or not all(p.isdigit() for p in parts):
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT in pixels, got {text!r}")
    try:
        return check_photo_size((int(parts[0]), int(parts[1])), "the photograph", lo=64)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def n_units(scene: Scene, cases, animations: bool, photos: bool = True, figures: bool = True) -> int:
    """Units of work of ``run_scene`` for the progress bar, one per stage that takes time: per case its
    solves (target, routing, design), with ``photos`` its photograph stage, with ``figures`` its figures and
    meshes; with ``animations`` one per animation made; one for the scene's gait."""
    names = set(scene.case_names if cases is None else cases)
    n = len(names) * (1 + bool(photos) + bool(figures)) + (scene.gait is not None)
    if animations:
        n += sum(set(x.cases) <= names for x in scene.animations)
    return n


def _animation_job(scene: Scene, anim, designs: dict, out: Path, figures: bool) -> dict:
    """An animation of the scene: its frames' forward solves (:func:`~mdsr_opt.scenes.animate.animate`), its
    GIF (with ``figures``) and ``out/<animation>.json``; returns the JSON's data and the message to log."""
    from ..plot.scenes import save_animation
    from ..plot.style import commanded_achieved, muscle_label
    from ..body.io import write_json

    res = animate(scene, anim, designs)
    data = res.to_dict()
    if res.states:
        said = (f"[{scene.name}] animation {anim.name}: {len(res.states)} frames, {len(res.muscles)} muscle(s), "
                + ("all forward solves succeeded" + (f"; {res.message}" if res.message else "") if res.success
                   else f"{res.message} (frames {res.failed_frames})"))
        if figures:
            act = res.contractions / scene.design_options.get("a_max", 0.6)
            # titles state per muscle the contraction commanded and the one reached along its node chain
            reached = [[1.0 - m.length(x) / m.rest_length(scene.mesh) for m in res.muscles] for x in res.states]
            names = [muscle_label(m, i) for i, m in enumerate(res.muscles)]
            titles = [f"{anim.name} {k + 1}/{len(act)}: " + commanded_achieved(res.contractions[k], f, names, ".2f")
                      for k, f in enumerate(reached)]
            save_animation(scene.mesh, res.states, out / f"{anim.name}.gif", muscles=res.muscles,
                           activations=act, titles=titles, fps=anim.fps, units=scene.units)
            data["gif"] = f"{anim.name}.gif"
    else:
        said = f"[{scene.name}] animation {anim.name}: not made ({res.message})"
    write_json(out / f"{anim.name}.json", finite(data))
    return {"data": data, "log": said}


def _animation_done(anim_out: dict, name: str, say, log, got: dict) -> None:
    """Put an :func:`_animation_job`'s answer into the scene's report and say it."""
    anim_out[name] = got["data"]
    say(got["log"])
    advance(log)


def _run_gait(scene: Scene, out, runs, figures: bool, log, writer, vector=None, animation=True):
    return run_gait(scene, out, runs, figures=figures, log=log, writer=writer, vector=vector, animation=animation)


def _photo_cost(run: CaseRun, proto) -> float:
    """The estimated cost of a case's photograph job (:mod:`mdsr_opt.core.costs`)."""
    nodes = proto.describe()["nodes"] if proto is not None else 0
    return photo_cost(nodes, len(run.setup.muscles) if run.setup is not None else 0)


def _photo_job(scene: Scene, run: CaseRun, photo_size, proto, prefix: str, writers=()) -> dict:
    """A case's photograph stage (:func:`~mdsr_opt.scenes.runner.measure_case`, with the virtual prototype
    ``proto`` unless None), then its result-side files (``writers``: :func:`~mdsr_opt.scenes.runner.case_parts`
    parts): what the run's report needs back from a job run in a worker."""
    said: list[str] = []
    measure_case(scene, run, photo_size=photo_size, prototype=proto, log=said.append, prefix=prefix)
    files = [f for write in writers for f in write()]
    return {"photo": run.report.photo, "time": run.report.times["photo"], "files": files, "log": said}


def _prototype_cost(run: CaseRun, proto, part: str) -> float:
    """The estimated cost of a :func:`_prototype_job` of ``part`` ``"driving"`` or ``"design"``: the
    prototype's share of :func:`_photo_cost` (half a muscle for the external driving, as there)."""
    share = _photo_cost(run, proto) - photo_cost()
    muscles = len(run.setup.muscles) if run.setup is not None else 0
    return share * (muscles if part == "design" else 0.5) / (muscles + 0.5)


def _prototype_job(run: CaseRun, proto, prefix: str, writers=(), part: str = "both") -> dict:
    """A case's validation against the virtual prototype ``proto``
    (:func:`~mdsr_opt.scenes.runner.measure_prototype`): its ``part``, ``"driving"`` (Table 2/3),
    ``"design"`` (Table 4) or ``"both"``; then its photographs (``writers``)."""
    said: list[str] = []
    seconds = measure_prototype(run, proto, log=said.append, prefix=prefix, driving=part != "design",
                                design=part != "driving")
    files = [f for write in writers for f in write()]
    return {"prototype": run.report.photo["prototype"], "time": seconds, "files": files, "log": said}


def _prototype_done(run: CaseRun, paths: list, say, log, got: dict) -> None:
    """Put a :func:`_prototype_job`'s answer into the run (after its :func:`_photo_job`'s), beside that of
    the case's other prototype job; with ``log``, the case's photograph stage is done (one unit of its
    progress)."""
    mine = (run.report.photo or {}).get("prototype") or {}
    run.report.photo = dict(run.report.photo or {}, prototype={**mine, **got["prototype"]})
    _photo_done(run, paths, say, log, dict(got, photo=run.report.photo,
                                           time=run.report.times.get("photo", 0.0) + got["time"]), got["time"])


def _photo_chain_job(scene: Scene, items: list, photo_size, proto) -> list[dict]:
    """:func:`_photo_job` of several cases, ``items`` of ``(run, prefix, write_result)``, one after the other in
    one process: the virtual prototype ``proto`` keeps the states it solved, so that each case's prototype
    solve can start from the one before."""
    return [_photo_job(scene, run, photo_size, proto, prefix, write) for run, prefix, write in items]


def _photo_chain_done(targets: list, say, log, got: list) -> None:
    """:func:`_photo_done` for each case of a :func:`_photo_chain_job` (``targets``: its ``(run, paths)``)."""
    for (run, paths), one in zip(targets, got):
        _photo_done(run, paths, say, log, one)


def _photo_done(run: CaseRun, paths: list, say, log, got: dict, added: float | None = None) -> None:
    """Put a :func:`_photo_job`'s answer into the run (its report, its files, its messages); one more unit
    of ``log``'s progress done (``log`` None: the stage goes on in a :func:`_prototype_job`). ``added``: the
    seconds of ``got["time"]`` not yet in the run's total (default all)."""
    run.report.photo = got["photo"]
    run.report.times["photo"] = got["time"]
    run.report.times["total"] = run.report.times.get("total", 0.0) + (got["time"] if added is None else added)
    paths.extend(got["files"])
    for line in got["log"]:
        say(line)
    advance(log)


def _files_done(paths: list, log, got: list) -> None:
    """Note the files a case's figure job wrote; one more unit of ``log``'s progress done."""
    paths.extend(got)
    advance(log)


def _write_rest(scene: Scene, path, vector=None) -> str:
    """``rest.png``: the rest mesh with its regions (with ``vector``, a PDF/SVG beside it)."""
    from ..plot.common import save_figure
    from ..plot.scenes import plot_scene

    fig = plot_scene(scene.mesh, scene.regions, units=scene.units,
                     title=f"{scene.name}: rest mesh ({scene.mesh.n_nodes} nodes) and regions")
    return save_figure(fig, path, close=True, vector=vector)
