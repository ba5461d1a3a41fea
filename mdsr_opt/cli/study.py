"""``mdsr study``: solver comparison studies from the command line."""

from __future__ import annotations

import argparse
import math

from ..core.errors import InputError
from ..core.progress import progress_for_cli

__all__ = ['add_cli']


# ============================================================================================== CLI
def _csv_list(text: str | None, cast=str, flag: str = "the list"):
    if text is None:
        return None
    items = [t.strip() for t in text.split(",") if t.strip()]
    if not items:
        raise InputError(f"{flag}: expected a comma-separated list, got {text!r}")
    out = []
    for t in items:
        try:
            out.append(cast(t))
        except ValueError:
            kind = {int: "integers", float: "numbers"}.get(cast, "values")
            raise InputError(f"{flag}: expected comma-separated {kind}, got {t!r}") from None
    return out


def _cli(args) -> int:
    # imported here, not with the parser: only this command needs the studies' definitions
    from ..studies.problems import list_study_problems
    from ..studies.spec import FIDELITY_STUDY, STUDIES
    from ..studies.study import run_study

    if args.list or args.name is None:
        from ..studies.fidelity import FIDELITY_CASES

        for name, st in STUDIES.items():
            runs, _refs, _capped = st.plan()
            print(f"{name:<10} {len(runs):>4} runs  {st.description}")
        print(f"{FIDELITY_STUDY:<10} {len(FIDELITY_CASES):>4} scenes  the coarsest mesh and simplest material "
              "model within a tolerance, per scene")
        from ..studies.recommend import DEFAULT_SCENES, RECOMMEND_STUDY

        print(f"{RECOMMEND_STUDY:<10} {len(DEFAULT_SCENES):>4} scenes  which backend and mesh reach a shape or "
              "stroke tolerance at least cost, per library scene (--scenes)")
        print("\nproblems: " + ", ".join(list_study_problems()))
        return 0
    if args.out is None:
        raise InputError("give --out DIR for the study's table and charts")
    from ..scenes.rundir import check_out_path

    check_out_path(args.out)  # every argument before any work
    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers must be at least 1, got {args.workers}")
    if args.timeout is not None and not (math.isfinite(args.timeout) and args.timeout > 0):
        raise InputError(f"--timeout must be a positive number of seconds, got {args.timeout}")
    from ..body.mesh import MAX_RESOLUTION

    why = f"a solve's memory grows with the nodes: about 3 GB at {MAX_RESOLUTION}"
    if args.reference_resolution is not None and not 20 <= args.reference_resolution <= MAX_RESOLUTION:
        raise InputError(f"--reference-resolution must be a node count from 20 to {MAX_RESOLUTION} ({why}), "
                         f"got {args.reference_resolution}")
    resolutions = _csv_list(args.resolutions, int, "--resolutions")
    for r in resolutions or ():
        if not 4 <= r <= MAX_RESOLUTION:
            raise InputError(f"--resolutions must be node counts from 4 to {MAX_RESOLUTION} ({why}), got {r}")
    scheduler = args.scheduler or ("local" if args.dask else None)
    from ..studies.recommend import RECOMMEND_STUDY

    _refuse_unused_options(args, RECOMMEND_STUDY, FIDELITY_STUDY)

    if args.name == RECOMMEND_STUDY:
        from ..studies.recommend import recommendation_markdown, run_recommendation

        kw = {"scenes": _csv_list(args.scenes, str, "--scenes"), "backends": _csv_list(args.methods, str, "--methods"),
              "resolutions": resolutions, "reference_resolution": args.reference_resolution,
              "timeout": args.timeout}
        tols = _csv_list(args.tol, float, "--tol")
        if tols is not None and len(tols) != 1:
            raise InputError(f"--tol: the recommend study takes one shape tolerance, got {args.tol!r}")
        if tols:
            kw["tol"] = tols[0]
        if args.stroke_tol is not None:
            kw["stroke_tol"] = args.stroke_tol
        with progress_for_cli(args, 0, "mdsr study recommend", stream="stderr", unit="run") as log:
            recs, _ = run_recommendation(args.out, scheduler=scheduler, workers=args.workers,
                                         progress=not args.quiet, log=log, overwrite=args.overwrite,
                                         **{k: v for k, v in kw.items() if v is not None})
        print(recommendation_markdown(recs), flush=True)
        return 0
    if args.name == FIDELITY_STUDY:
        from ..studies.fidelity import fidelity_markdown, run_fidelity_study

        kw = {"resolutions": resolutions, "reference_resolution": args.reference_resolution}
        with progress_for_cli(args, 0, "mdsr study fidelity", stream="stderr", unit="run") as log:
            choices, _ = run_fidelity_study(args.out, tolerances=_csv_list(args.tol, float, "--tol"),
                                            scheduler=scheduler, workers=args.workers, progress=not args.quiet,
                                            log=log, overwrite=args.overwrite,
                                            **{k: v for k, v in kw.items() if v is not None})
        print(fidelity_markdown(choices), flush=True)
        return 0
    with progress_for_cli(args, 0, f"mdsr study {args.name}", stream="stderr", unit="run") as log:
        res = run_study(args.name, out=args.out, overwrite=args.overwrite, resolutions=resolutions,
                        methods=_csv_list(args.methods, str, "--methods"),
                        problems=_csv_list(args.problems, str, "--problems"),
                        materials=_csv_list(args.materials, str, "--materials"),
                        reference_resolution=args.reference_resolution, timeout=args.timeout,
                        scheduler=scheduler, workers=args.workers, progress=not args.quiet, log=log)
    print(res.markdown())
    return 0


#: The options that only some studies take (the others would ignore them): flag -> the studies that take it
_ONLY_FOR = {"--tol": ("fidelity", "recommend"), "--stroke-tol": ("recommend",), "--scenes": ("recommend",),
             "--problems": (None,), "--materials": (None,), "--methods": (None, "recommend"),
             "--timeout": (None, "recommend")}


def _refuse_unused_options(args, recommend: str, fidelity: str) -> None:
    """An option given to a study that does not take it is bad input (it would be ignored silently); ``None``
    in :data:`_ONLY_FOR` stands for the solver comparison studies (quick, speed, stability)."""
    kind = {recommend: "recommend", fidelity: "fidelity"}.get(args.name)
    for flag, takers in _ONLY_FOR.items():
        if getattr(args, flag[2:].replace("-", "_")) is not None and kind not in takers:
            raise InputError(f"{flag} does not apply to the {args.name} study (mdsr study {args.name} --help)")


#: The options of ``mdsr study``: flag -> add_argument keywords
_OPTIONS = {
    "--list": dict(action="store_true", help="list the studies and problems"),
    "--out": dict(help="output folder; it must be new or empty, and is locked while the study runs: a second "
                  "command into it stops with an error"),
    "--overwrite": dict(action="store_true", help="replace the files of an earlier mdsr run or study in --out (only "
                        "the files its manifest lists; a folder holding other files but no manifest is still "
                        "refused)"),
    "--resolutions": dict(help="comma-separated node counts, replacing the study's"),
    "--methods": dict(help="comma-separated backends / design methods, replacing the study's"),
    "--problems": dict(help="comma-separated problems, replacing the study's"),
    "--materials": dict(help="comma-separated material models, replacing the study's"),
    "--reference-resolution": dict(type=int, help="node count of the reference solutions"),
    "--timeout": dict(type=float, help="seconds allowed per run"),
    "--tol": dict(help="fidelity study: comma-separated tolerances (default 0.01,0.001); recommend study: the "
                  "shape tolerance (default 0.01)"),
    "--stroke-tol": dict(type=float, help="recommend study: the stroke tolerance (default 0.05)"),
    "--scenes": dict(help="recommend study: comma-separated library scenes or scene file paths (.toml/.json/.py) "
                     "(default gripper,tentacle)"),
    "--dask": dict(action="store_true", help="run on a local Dask cluster (one worker per core)"),
    "--scheduler": dict(help="address of a running Dask scheduler (implies Dask)"),
    "--workers": dict(type=int, help="workers of the local Dask cluster"),
}

#: The options of ``mdsr study recommend`` (the others of ``mdsr study`` do not apply to it)
_RECOMMEND_OPTIONS = ("--out", "--overwrite", "--scenes", "--methods", "--resolutions", "--reference-resolution",
                      "--tol", "--stroke-tol", "--timeout", "--dask", "--scheduler", "--workers")


def recommend_parser() -> argparse.ArgumentParser:
    """A parser whose help is ``mdsr study recommend --help``: what the study does and writes, and only the
    options of ``mdsr study`` that apply to it."""
    p = argparse.ArgumentParser(
        prog="mdsr study recommend", add_help=False,
        description="Which backend and which mesh reach a shape (--tol) and stroke (--stroke-tol) tolerance at "
                    "least cost, per scene (a library scene or a scene file): every case of each scene is "
                    "solved by every backend (--methods) at every node count (--resolutions) and compared with "
                    "a finer reference. Writes into --out: recommend.csv (one row per scene), "
                    "recommend_runs.csv (every run), recommend.md, recommend.json and a chart "
                    "recommend_<scene>.png per scene; prints the table.")
    for flag in _RECOMMEND_OPTIONS:
        p.add_argument(flag, **_OPTIONS[flag])
    return p


class _StudyHelp(argparse.Action):
    """``-h``/``--help``: the help of the study named before it (``mdsr study recommend --help``), else of
    ``mdsr study``."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        from ..studies.spec import RECOMMEND

        if getattr(namespace, "name", None) == RECOMMEND:
            recommend_parser().print_help()
        else:
            parser.print_help()
        parser.exit()


def add_cli(sub) -> None:
    """Register ``mdsr study``."""
    p = sub.add_parser("study", help="run a solver comparison study (mdsr study --list)", add_help=False,
                       description="Run a solver comparison study: a tidy CSV, metadata and charts in --out. "
                                   "mdsr study recommend --help: that study's own help.")
    p.add_argument("-h", "--help", action=_StudyHelp, help="show this help (after a study's name: its help) and exit")
    p.add_argument("name", nargs="?", help="study name (see --list)")
    for flag, kw in _OPTIONS.items():
        p.add_argument(flag, **kw)
    p.set_defaults(func=_cli)
