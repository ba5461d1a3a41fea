"""Which backend and which mesh to use, per library scene: ``mdsr study recommend``.

For every scene named, every case of it (``scene/case`` study problems) is solved by every candidate
backend at every candidate mesh resolution, and each run is measured against a reference solved on a
FINER mesh (Neo-Hookean, IPOPT, tight tolerance; the reference must have more nodes than every candidate
mesh, so no run is compared with its own discrete solution):

- ``error``: the largest node distance to the reference (interpolated at the run's rest nodes) over the
  body's size, the shape tolerance ``tol`` applies to it;
- ``stroke_error`` (cases driven by muscles): the largest difference of a muscle's stroke (rest length
  minus path length) from the reference's, over the largest reference stroke; ``stroke_tol`` applies.

A backend and resolution *meet* the tolerances for a scene when every case of the scene succeeded
(failures are classified as in :data:`~mdsr_opt.studies.spec.FAILURES`: saddle, self-contact, inverted
elements, iteration limit, ...) within them; the recommendation is the one of least cost (build plus
solve time summed over the scene's cases). One recommendation per scene, never pooled over scenes.

Example
-------
>>> from mdsr_opt.studies.recommend import pick_recommendation
>>> rows = [dict(problem="s/a", method=m, resolution=r, nodes=r, success=True, failure="none", error=e,
...              stroke_error=float("nan"), build_time=0.0, solve_time=t)
...         for m, r, e, t in (("ipopt", 100, 0.02, 0.1), ("ipopt", 300, 0.004, 0.5), ("newton", 300, 0.004, 0.3))]
>>> rec = pick_recommendation(rows, "s", 0.01)
>>> rec.met, rec.method, rec.resolution
(True, 'newton', 300)
"""

from __future__ import annotations

import csv
import io
import math
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ..body.io import atomic_path, write_json
from ..core.errors import checking_input
from ..core.results import compact_repr, to_jsonable
from .problems import build_setup, is_scene_path, list_study_problems
from .runs import fill_accuracy, run_all
from .spec import FAILURES, RECOMMEND, Study
from .study import StudyResult, environment_info, output_folder
from ..core.checks import did_you_mean

__all__ = ["Recommendation", "pick_recommendation", "run_recommendation", "recommendation_markdown",
           "RECOMMEND_STUDY", "DEFAULT_SCENES", "DEFAULT_BACKENDS", "DEFAULT_RESOLUTIONS"]

#: the study's name on the command line
RECOMMEND_STUDY = RECOMMEND
DEFAULT_SCENES = ("gripper", "tentacle")
DEFAULT_BACKENDS = ("ipopt", "sqpmethod", "ipopt-lbfgs")
DEFAULT_RESOLUTIONS = (100, 300, 1000)


@dataclass
class Recommendation:
    """The backend and mesh recommended for one scene.

    Attributes
    ----------
    scene : str
    tol, stroke_tol : the shape tolerance (largest node error over the body's size) and the stroke tolerance.
    met : bool
        Some backend and resolution met both on every case. Otherwise the other fields describe the
        candidate that met them on the most cases (then the smallest worst error).
    method, resolution, nodes : the recommendation.
    error, stroke_error : its worst errors over the scene's cases.
    time : its build plus solve time summed over the cases (s).
    cases : number of cases of the scene.
    candidates : number of backend and resolution combinations tried.
    meeting : how many of them met the tolerances.
    failures : failure reasons over all the scene's runs (``reason count, ...``).
    reference : what the errors are measured against.
    """

    scene: str
    tol: float
    stroke_tol: float
    met: bool
    method: str
    resolution: int
    nodes: int
    error: float
    stroke_error: float
    time: float
    cases: int
    candidates: int
    meeting: int
    failures: str
    reference: str = ""

    def __repr__(self) -> str:
        return compact_repr(self, ("scene", "tol", "met", "method", "nodes", "error", "time"))

    def to_dict(self) -> dict:
        return to_jsonable(asdict(self))


def _worst(values) -> float:
    v = [x for x in values if isinstance(x, (int, float)) and math.isfinite(x)]
    return max(v) if v else math.nan


def pick_recommendation(rows: Sequence[dict], scene: str, tol: float, stroke_tol: float = 0.05,
                        reference: str = "") -> Recommendation:
    """The backend and resolution of least summed cost meeting ``tol`` (and ``stroke_tol`` where a stroke
    error was measured) on every case of ``scene`` (rows whose problem is ``scene/<case>``)."""
    for name, v in (("tol", tol), ("stroke_tol", stroke_tol)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be a positive number, got {v!r}")
    rs = [r for r in rows if r["problem"].rsplit("/", 1)[0] == scene]
    if not rs:
        raise ValueError(f"no runs of scene {scene!r}")
    cases = sorted({r["problem"] for r in rs})
    groups: dict = {}
    for r in rs:
        groups.setdefault((r["method"], int(r["resolution"])), []).append(r)

    def within(r) -> bool:
        if not r["success"] or not (math.isfinite(r["error"]) and r["error"] <= tol):
            return False
        s = r.get("stroke_error", math.nan)
        return not math.isfinite(s) or s <= stroke_tol

    scored = []
    for (m, res), g in groups.items():
        n_ok = sum(within(r) for r in g)
        cost = sum(r["build_time"] + r["solve_time"] for r in g)
        err = _worst(r["error"] for r in g)
        scored.append((n_ok == len(cases) and len(g) == len(cases), n_ok, cost, err, m, res, g))
    meeting = [s for s in scored if s[0]]
    if meeting:
        best = min(meeting, key=lambda s: (s[2], s[5]))
    else:  # the most cases met, then the smallest worst error
        best = min(scored, key=lambda s: (-s[1], s[3] if math.isfinite(s[3]) else math.inf, s[2]))
    _, _, cost, err, m, res, g = best
    fails = {f: sum(r["failure"] == f for r in rs) for f in FAILURES[1:]}
    return Recommendation(scene, float(tol), float(stroke_tol), bool(best[0]), m, res,
                          int(max(r["nodes"] for r in g)), float(err),
                          float(_worst(r.get("stroke_error", math.nan) for r in g)), float(cost), len(cases),
                          len(groups), len(meeting), ", ".join(f"{k} {v}" for k, v in fails.items() if v) or "-",
                          reference)


def _strokes(setup, x) -> np.ndarray:
    """Every muscle's stroke (rest length minus path length) in state ``x``."""
    return np.array([m.rest_length(setup.mesh) - m.length(x) for m in setup.muscles])


def _fill_strokes(outcomes, refs: dict) -> None:
    """``stroke_error`` of the internal-driving runs against their reference (NaN elsewhere)."""
    ref_strokes = {}
    for key, ref in refs.items():
        if ref.row["success"] and ref.row["kind"] == "equilibrium":
            s = build_setup(key[0], ref.row["resolution"], key[1])
            if s.mode == "internal" and len(s.muscles):
                ref_strokes[key] = _strokes(s, ref.x)
    for o in outcomes:
        r = o.row
        r["stroke_error"] = math.nan
        key = (r["problem"], r["load"])
        if key not in ref_strokes or o.x is None or not r["success"]:
            continue
        s = build_setup(r["problem"], r["resolution"], r["load"])
        ref = ref_strokes[key]
        if len(s.muscles) != len(ref):
            continue
        r["stroke_error"] = float(np.abs(_strokes(s, o.x) - ref).max() / max(np.abs(ref).max(), 1e-300))


def scene_stem(scene: str) -> str:
    """The name a scene's files take: a library scene's name, a scene file's stem (``scenes/ring.toml`` ->
    ``ring``)."""
    return Path(scene).stem if is_scene_path(scene) else scene


def _scene_problems(scenes: Sequence[str]) -> list[str]:
    from ..scenes.library import get_problem

    known = list_study_problems()
    out = []
    for sc in scenes:
        if not isinstance(sc, str):
            raise TypeError(f"scene names must be strings, got {sc!r}")
        if is_scene_path(sc):  # a user's scene file or problem script, as mdsr run and get_problem take it
            out += [f"{sc}/{c}" for c in get_problem(sc, resolution="coarse").case_names]
            continue
        mine = [p for p in known if p.rsplit("/", 1)[0] == sc and "/" in p]
        if not mine:
            names = sorted({p.rsplit("/", 1)[0] for p in known if "/" in p})
            hint = did_you_mean(sc, names)
            raise ValueError(f"unknown library scene {sc!r}{hint}; valid: {', '.join(names)}, or the path of a "
                             "scene file (.toml/.json) or problem script (.py)")
        out += mine
    stems = [scene_stem(sc) for sc in scenes]
    twice = sorted({s for s in stems if stems.count(s) > 1})
    if twice:
        raise ValueError(f"two scenes named {twice[0]!r}: their charts would share recommend_{twice[0]}.png")
    return out


def run_recommendation(out: str | os.PathLike | None = None, *, scenes: Sequence[str] = DEFAULT_SCENES,
                       tol: float = 0.01, stroke_tol: float = 0.05, backends: Sequence[str] = DEFAULT_BACKENDS,
                       resolutions: Sequence[int] = DEFAULT_RESOLUTIONS, reference_resolution: int | None = None,
                       timeout: float = 60.0, scheduler: Any = None, workers: int | None = None,
                       progress: bool = True, figures: bool = True, log: Callable[[str], Any] | None = None,
                       overwrite: bool = False) -> tuple[list[Recommendation], StudyResult]:
    """Run the recommendation study (module docstring) and with ``out`` write ``recommend.csv`` (one row
    per scene), ``recommend_runs.csv`` (every run, with ``stroke_error``), ``recommend.md``,
    ``recommend.json`` and one chart per scene ``recommend_<scene>.png``. ``out`` follows
    :func:`~mdsr_opt.studies.study.run_study`'s rules. Returns the recommendations and the runs.

    Raises
    ------
    ValueError
        Before any run: an unknown scene or backend, a bad tolerance, a node count out of range, or a
        reference mesh not finer than every candidate mesh of some case.
    """
    with checking_input():
        scenes = tuple(scenes)
        if not scenes:
            raise ValueError("name at least one library scene")
        for name, v in (("tol", tol), ("stroke_tol", stroke_tol)):
            if isinstance(v, bool) or not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number, got {v!r}")
        problems = _scene_problems(scenes)
        resolutions = tuple(resolutions)
        st = Study(RECOMMEND_STUDY, "which backend and mesh reach a shape or stroke tolerance at least cost, "
                   "per library scene", tuple(problems), resolutions, ("neo-hookean",), tuple(backends),
                   reference_resolution=reference_resolution, timeout=float(timeout))
        for p in problems:  # a reference on the same (or a coarser) mesh would measure nothing
            fine = build_setup(p, st.resolutions[-1]).mesh.n_nodes
            ref = build_setup(p, st.reference_resolution).mesh.n_nodes
            if ref <= fine:
                raise ValueError(f"{p}: the reference mesh ({ref} nodes at reference_resolution="
                                 f"{st.reference_resolution}) must be finer than the finest candidate ({fine} nodes)")
        runs, refs, _ = st.plan()
    if log is None or not progress:
        log = print if progress and log is None else (log if progress else None)
    names = [f"recommend{x}" for x in (".csv", "_runs.csv", ".md", ".json")]
    names += [f"recommend_{scene_stem(s)}.png" for s in scenes] if figures else []
    with output_folder(out, overwrite, names) as folder:
        t0 = time.perf_counter()
        outs = run_all(refs + runs, scheduler, workers, log)
        ref_out, run_out = outs[:len(refs)], outs[len(refs):]
        refmap = {(o.row["problem"], o.row["load"]): o for o in ref_out}
        fill_accuracy(run_out, refmap)
        _fill_strokes(run_out, refmap)
        rows = [o.row for o in run_out]
        recs = []
        for sc in scenes:
            bad = [o.row["problem"] for o in ref_out if o.row["problem"].startswith(sc + "/") and not o.row["success"]]
            where = (f"neo-hookean, ipopt (tol 1e-10) at resolution {st.reference_resolution}"
                     + (f"; failed for {', '.join(bad)}" if bad else ""))
            recs.append(pick_recommendation(rows, sc, tol, stroke_tol, where))
        meta = {"study": st.to_dict(), "scenes": list(scenes), "tol": tol, "stroke_tol": stroke_tol,
                "wall_time": time.perf_counter() - t0, "environment": environment_info(),
                "error": "largest node distance to the finer-mesh reference (interpolated at the run's rest "
                         "nodes) over the body's size; internal driving after the best rigid motion",
                "stroke_error": "largest |stroke - reference stroke| over the largest reference stroke",
                "choice": "least build + solve time summed over the scene's cases, among the backend and "
                          "resolution combinations whose every case succeeded within both tolerances"}
        res = StudyResult(st, rows, [o.row for o in ref_out], meta)
        if folder is not None:
            folder.begin(names)
            _write(out, recs, res, meta, scenes, figures, log)
    return recs, res


def _write(out, recs, res, meta, scenes, figures, log) -> None:
    out = os.fspath(out)
    os.makedirs(out, exist_ok=True)
    table = [r.to_dict() for r in recs]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(table[0]), lineterminator="\n")
    w.writeheader()
    for r in table:
        w.writerow({k: ("" if v is None else repr(v) if isinstance(v, float) else v) for k, v in r.items()})
    runs = io.StringIO()
    keys = list(res.rows[0]) if res.rows else []
    wr = csv.DictWriter(runs, fieldnames=keys, lineterminator="\n", extrasaction="ignore")
    wr.writeheader()
    for r in res.rows:
        wr.writerow({k: (repr(v) if isinstance(v, float) else v) for k, v in r.items()})
    for fname, text in (("recommend.csv", buf.getvalue()), ("recommend_runs.csv", runs.getvalue()),
                        ("recommend.md", recommendation_markdown(recs))):
        with atomic_path(os.path.join(out, fname)) as tmp, open(tmp, "w") as fh:
            fh.write(text)
    write_json(os.path.join(out, "recommend.json"), to_jsonable({**meta, "recommendations": table}))
    if figures:
        from ..plot.common import save_figure
        from ..plot.studies import plot_recommendation

        for sc, rec in zip(scenes, table):
            rows = [r for r in res.rows if r["problem"].rsplit("/", 1)[0] == sc]
            save_figure(plot_recommendation(rows, rec), os.path.join(out, f"recommend_{scene_stem(sc)}.png"),
                        close=True)
    if log:
        log(f"wrote recommend.csv, recommend_runs.csv, recommend.md, recommend.json"
            f"{', ' + ', '.join(f'recommend_{s}.png' for s in scenes) if figures else ''} to {out}")


def recommendation_markdown(recs: Sequence[Recommendation]) -> str:
    """The recommendations as a Markdown table (one row per scene)."""
    lines = ["| scene | cases | tol | stroke tol | recommendation | nodes | worst error | worst stroke error | "
             "time s | meeting | failures |", "| --- | ---: | ---: | ---: | --- | ---: | ---: | ---: | ---: | ---: | --- |"]

    def g(v, f):
        return "-" if not math.isfinite(v) else format(v, f)

    for r in recs:
        pick = f"{r.method} at {r.resolution}" if r.met else f"none met (closest: {r.method} at {r.resolution})"
        lines.append(f"| {r.scene} | {r.cases} | {r.tol:g} | {r.stroke_tol:g} | {pick} | {r.nodes} | "
                     f"{g(r.error, '.2g')} | {g(r.stroke_error, '.2g')} | {r.time:.3g} | "
                     f"{r.meeting}/{r.candidates} | {r.failures} |")
    return "\n".join(lines) + "\n"
