"""``mdsr list`` and ``mdsr run``: the problem library from the command line."""

from __future__ import annotations

import argparse
import ast
import inspect
from pathlib import Path
import time

from ..core.errors import InputError, checking_input
from ..core.progress import progress_for_cli
from ..scenes.library import build_from, load_module, problem_files, figure_scripts, get_problem, list_problems, problems_dir
from ..scenes.rundir import RunFolder
from ..scenes.scene import resolve_resolution
from ..scenes.scenereport import case_notes
from ..scenes.runscene import n_units, parse_resolution, parse_seed, parse_size, run_entries, scene_pool, write_scene

__all__ = ['add_cli']


# ---------------------------------------------------------------------------------------------- the command
def _doc_line(path: Path) -> str:
    try:
        doc = ast.get_docstring(ast.parse(path.read_text()))
    except SyntaxError:
        return "(cannot be parsed)"
    return (doc or "").strip().split("\n")[0]


def _cmd_list(a) -> int:
    files = problem_files()
    if not files:
        print("no problem library found (looked in $MDSR_PROBLEMS, the installed package and the source checkout); "
              "run a scene file with `mdsr run PATH`")
        return 1
    print(f"problem library: {problems_dir()}")
    w = max(len(n) for n in files)
    for name, path in files.items():
        line = f"  {name:<{w}}  {_doc_line(path)}"
        if a.cases:
            with checking_input():  # a problem script that does not build: its author's input
                scene = build_from(path, "coarse")
            kinds = ", ".join(f"{c.name} ({c.kind})" for c in scene.cases)
            line += f"\n  {'':<{w}}  cases: {kinds}" + (
                f"; animations: {', '.join(x.name for x in scene.animations)}" if scene.animations else "")
        print(line)
    for name, path in figure_scripts().items():
        print(f"  {name:<{w}}  {_doc_line(path)} (figure)")
    print("run one with: mdsr run NAME --out DIR   (or a scene file: mdsr run PATH.toml --out DIR)")
    return 0


def _cmd_run(a) -> int:
    names = list(a.scenes)
    if names == ["all"]:
        names = list_problems()
        if not names:
            raise InputError("no problem library found: `mdsr run all` needs the problems/ folder")

    t0 = time.perf_counter()
    vector = a.vector_format or ("pdf" if a.vector else None)  # --vector-format alone implies --vector
    if vector is not None and a.no_figures:  # options that contradict each other: said, not one silently ignored
        raise InputError(f"--{'vector-format' if a.vector_format else 'vector'} writes the figures as vector files "
                         "too: it cannot go with --no-figures")
    if a.photo_size is not None and a.no_photos:
        raise InputError("--photo-size sets the size of the synthetic photographs (and of the virtual "
                         "prototype's camera): it cannot go with --no-photos")
    size = {} if a.photo_size is None else {"photo_size": a.photo_size}  # else write_scene's default (the paper's)
    # the folder first (a one-line error for an empty, unwritable, busy or non-empty --out), then every
    # scene (all input errors, inside checking_input), and only then any solving or writing
    figs = figure_scripts()
    if any(n in figs for n in names):  # a figure script runs on its own (e.g. mdsr run figure6)
        if len(names) != 1:
            raise InputError(f"run a figure script ({', '.join(n for n in names if n in figs)}) on its own")
        with checking_input():
            module = load_module(figs[names[0]])
            if a.resolution is not None:
                resolve_resolution(a.resolution)
            extra = {}
            if vector is not None:  # passed on to a figure script that takes it, else said at the door
                if "vector" not in inspect.signature(module.run_figure).parameters:
                    raise InputError(f"{names[0]} writes no vector figures: run it without --vector")
                extra["vector"] = vector
        with RunFolder(a.out, overwrite=a.overwrite, command=getattr(a, "command_line", "")) as folder:
            folder.begin(figure_outputs(getattr(module, "OUTPUTS", ()), vector))
            with progress_for_cli(a, 0, names[0], unit="step") as log:
                code = int(module.run_figure(a.out, resolution=a.resolution or "medium", log=log, **extra))
            folder.finish("complete" if code == 0 else "complete, some designs failed")
        return code
    parallel = getattr(a, "pool", True) and not a.serial and not (a.no_figures and a.no_photos)
    # the folder first (a busy or used --out is refused before any work), then one pool of worker processes
    # for every scene's jobs, shut down before the folder is released
    with RunFolder(a.out, overwrite=a.overwrite, command=getattr(a, "command_line", "")) as folder, \
            scene_pool(None if parallel else 0) as pool:
        with checking_input():  # building the scenes checks them: bad input, before any work
            scenes = [get_problem(n, resolution=a.resolution) for n in names]
            seen = set()
            for s in scenes:
                if s.name in seen:
                    raise ValueError(f"scene {s.name!r} is named twice")
                seen.add(s.name)
            if a.case:
                for s in scenes:
                    for c in a.case:
                        s.case(c)  # an unknown --case names the scene's cases
        folder.begin(run_entries(scenes[0], a.case, vector=vector) if len(scenes) == 1 else [s.name for s in scenes] + ["tables.md"])
        # several scenes beside a pool: each scene's solves run while the jobs of the scenes before it (figures,
        # photographs, the virtual prototype's solves) run in the workers, the scenes with the most cases
        # first (their jobs are the longest); the reports keep the order asked for
        overlap = len(scenes) > 1 and pool is not None
        order = sorted(range(len(scenes)), key=lambda k: -len(scenes[k].cases)) if overlap else range(len(scenes))
        done: dict = {}
        with progress_for_cli(a, sum(n_units(s, a.case, not a.no_animations, photos=not a.no_photos,
                                             figures=not a.no_figures) for s in scenes),
                              "mdsr run", unit="stage") as log:
            for i, k in enumerate(order):
                scene = scenes[k]
                out = Path(a.out) if len(scenes) == 1 else Path(a.out) / scene.name
                if len(scenes) > 1:
                    log(f"=== scene {i + 1}/{len(scenes)}: {scene.name} ===")
                done[k] = write_scene(scene, out, cases=a.case, method=a.method, photos=not a.no_photos,
                                      figures=not a.no_figures, animations=not a.no_animations,
                                      mesh_format=a.format, log=log, **size,
                                      prototype=not a.no_prototype, prototype_seed=a.prototype_seed,
                                      background=pool is not None, pool=pool,
                                      max_difference=a.max_difference, bands=a.bands, vector=vector,
                                      wait=not overlap)
            for k in order:  # each scene's jobs, then its summaries
                if callable(done[k]):
                    done[k] = done[k]()
        reports = [done[k] for k in range(len(scenes))]
        if len(scenes) > 1 and not a.no_photos and not a.no_prototype:
            from ..body.io import atomic_path
            from ..scenes.prototype import validation_tables

            with atomic_path(Path(a.out) / "tables.md") as tmp:
                Path(tmp).write_text(validation_tables(reports))
        folder.finish("complete" if all(r.success for r in reports) else "complete, some cases failed")
    lines = reports[0].table().split("\n")
    for r in reports[1:]:
        lines += r.table().split("\n")[2:]
    ok = all(r.success for r in reports)
    n_cases = sum(len(r.cases) for r in reports)
    n_bad = sum(not c.success for r in reports for c in r.cases)
    print("\n" + "\n".join(lines))
    for r in reports:
        for c in r.cases:
            if not c.success:
                print(f"FAILED {r.scene}/{c.case}: {c.message}")
        for name, an in r.animations.items():
            if not an.get("success", False):
                print(f"FAILED {r.scene}/{name} (animation): {an.get('message') or an.get('failed_frames')}")
    noted = [f"{r.scene}/{c.case}" for r in reports for c in r.cases if case_notes(c)] + [
        f"{r.scene}/gait {name}" for r in reports for name, an in r.animations.items()
        if an.get("kind") == "gait" and an.get("notes")]  # a gait's shared layout: listed as a case's
    if noted:  # the resolutions themselves are long: each scene's summary.md lists them
        where = "summary.md" if len(reports) == 1 else "each scene's summary.md"
        which = ", ".join(noted) if len(noted) <= 4 else f"{len(noted)} case(s)"
        print(f"notes (fixtures shrunk, ropes cut, dropped or moved, idle muscles dropped, layouts that cannot be "
              f"moulded) of {which}: under Notes in {where}")
    print(f"{n_cases - n_bad}/{n_cases} case(s) succeeded in {time.perf_counter() - t0:.1f} s; "
          f"results in {a.out}" + ("" if a.no_photos else "; photographs are SYNTHETIC"))
    return 0 if ok else 1


def figure_outputs(outputs, vector=None) -> list[str]:
    """The files a figure script writes: its ``OUTPUTS``, and with ``vector`` each PNG's vector copy beside
    it (``figure6a.png`` and ``vector="pdf"``: ``figure6a.png``, ``figure6a.pdf``)."""
    from ..plot.style import figure_formats

    out = []
    for name in outputs:
        out.append(name)
        stem, ext = name.rsplit(".", 1) if "." in name else (name, "")
        if ext.lower() == "png":
            out += [f"{stem}.{f}" for f in figure_formats(vector)]
    return out


def _fraction(text: str) -> float:
    """``--max-difference``: a positive fraction of the body's diameter."""
    from ..synthesis.acceptance import check_max_difference

    try:
        return check_max_difference(float(text))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"expected a positive fraction of the size, got {text!r} ({exc})") from None


def add_cli(sub) -> None:
    """Register ``mdsr list`` and ``mdsr run``."""
    p = sub.add_parser("list", help="list the problem library (the paper's robots as scenes)")
    p.add_argument("--cases", action="store_true", help="also build each scene (coarse) and list its cases")
    p.set_defaults(func=_cmd_list)

    q = sub.add_parser("run", help="run scenes through the whole pipeline: target, muscles, contractions, "
                       "forward check, synthetic photograph, contour metrics, validation against a virtual prototype (the "
                       "paper's Tables 2-4 in validation.md, and tables.md for several scenes); figures, meshes, JSON")
    q.add_argument("scenes", nargs="+", metavar="NAME|PATH",
                   help="library names (see mdsr list), 'all', problem scripts (.py) or scene files (.toml/.json)")
    q.add_argument("--out", required=True,
                   help="output folder (one sub-folder per scene when several); it must be new or empty, and "
                   "is locked while the run writes into it: a second run into it stops with an error")
    q.add_argument("--overwrite", action="store_true",
                   help="replace the files of an earlier mdsr run or study in --out: only the files its manifest "
                   "lists are removed, any other file there stays (a folder holding files but no manifest is "
                   "refused). Without it a non-empty --out is refused, so one folder never mixes two runs")
    q.add_argument("--resolution", type=parse_resolution, default=None,
                   help="coarse (~150 nodes), medium (~600), fine (~2400) or a node count (default: the scene's: "
                        "medium for the library's but gripper_hold, coarse; a scene file's own resolution or "
                        "max_area); refused for a scene file whose body is a mesh file")
    q.add_argument("--case", action="append", default=None, help="run only this case (repeatable)")
    q.add_argument("--method", choices=("flattened", "nested", "derivative-free"), default=None,
                   help="design method (default: the scene's, normally flattened)")
    q.add_argument("--format", choices=("vtu", "vtk", "xdmf"), default="vtu", help="mesh files (default vtu)")
    q.add_argument("--no-photos", action="store_true", help="skip the synthetic photographs and contour metrics")
    q.add_argument("--photo-size", type=parse_size, default=None, metavar="WxH",
                   help="size of the synthetic photographs in pixels (default 500x500, as in the paper)")
    q.add_argument("--no-prototype", action="store_true",
                   help="skip the virtual prototype (quadratic elements on a 2x finer mesh, silicone, ropes with "
                   "capstan friction on end fixtures, the synthetic camera) against which the paper's Tables 2-4 are computed (validation.md per scene, "
                   "tables.md for several scenes)")
    q.add_argument("--prototype-seed", type=parse_seed, default=0,
                   help="seed of the virtual prototype's material perturbation and camera (default 0)")
    q.add_argument("--no-figures", action="store_true", help="write only the JSON and Markdown summaries")
    q.add_argument("--no-animations", action="store_true",
                   help="skip the animations (GIFs; a [gait]'s layout, schedule and fabrication files are still written)")
    q.add_argument("--vector", action="store_true",
                   help="also write every figure as a vector file beside its PNG, for papers (PDF unless "
                        "--vector-format svg); GIFs stay GIFs")
    q.add_argument("--vector-format", choices=("pdf", "svg"), default=None,
                   help="the format of the vector files (implies --vector; default pdf)")
    q.add_argument("--serial", action="store_true",
                   help="draw figures, measure photographs and make animations in this process after each "
                        "solve, not in worker processes beside the next solve (the files are the same)")
    q.add_argument("--max-difference", type=_fraction, default=None, metavar="FRACTION",
                   help="a case whose design differs from its target by more than this fraction of the body's "
                   "diameter (largest node-to-node distance) fails (default: the scene's [acceptance] max_difference, else 0.05)")
    q.add_argument("--bands", action=argparse.BooleanOptionalAction, default=None,
                   help="compute every stroke's uncertainty band (fixture size +-25 %%, Poisson's ratio +-0.05, "
                   "the mesh refined once): 4-5 more designs per case (default: the scene's [acceptance] bands, "
                   "else off)")
    q.set_defaults(func=_cmd_run)
