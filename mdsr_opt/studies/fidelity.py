"""Fidelity: model no more than a scene needs.

:func:`choose_fidelity` solves a scene with every candidate mesh resolution and material model, measures
each solution against a reference (by default a mesh four times finer than the finest candidate with the
full Neo-Hookean model, or a known fine solution you pass), and picks **the coarsest mesh, and on it the simplest material model**, whose
largest node error stays within a stated tolerance (a fraction of the body's size). It reports the saving in
time and nodes against the finest model (Neo-Hookean on the finest candidate mesh).

Material models are tried simplest first: ``linear`` (small strain, :class:`~mdsr_opt.LinearElastic`), then
``neo-hookean``. Linear elasticity is adequate where strains and rotations stay small; it is not rotation
invariant, so a bend fails it (and it may invert elements, which counts as a failed candidate).

:func:`run_fidelity_study` does this for several scenes and tolerances at once (serially or on Dask) and
writes a table and a chart; it is ``mdsr study fidelity``.

Example
-------
>>> from mdsr_opt.studies.fidelity import choose_fidelity
>>> c = choose_fidelity("strip-stretch", 0.01, load=0.02, resolutions=(30, 100), progress=False)
>>> c.material, c.nodes, c.error <= 0.01
('linear', 27, True)
"""

from __future__ import annotations

import csv
import io
import logging
import math
import os
import time
from dataclasses import asdict, dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from ..body.io import atomic_path, write_json
from ..body.mesh import Mesh
from ..core.errors import checking_input
from ..core.results import compact_repr, to_jsonable
from .problems import MATERIALS, get_study_problem
from .runs import RunOutcome, fill_accuracy, run_all
from .spec import Study
from .study import StudyResult, environment_info, output_folder

_LOG = logging.getLogger(__name__)

__all__ = ["FidelityChoice", "choose_fidelity", "pick_fidelity", "run_fidelity_study", "FIDELITY_CASES",
           "DEFAULT_TOLERANCES"]

#: Scenes of the fidelity study: (problem, load), small and large loads of each kind.
FIDELITY_CASES = (("strip-stretch", 0.02), ("strip-stretch", 1.0), ("strip-bend", 20.0), ("strip-bend", 90.0),
                  ("strip-contract", 0.05), ("strip-contract", 0.3))
#: Tolerances of the fidelity study: largest node error over the body size.
DEFAULT_TOLERANCES = (1e-2, 1e-3)
_RANK = {m: i for i, m in enumerate(MATERIALS)}  # simplest first


@dataclass
class FidelityChoice:
    """The model the helper picked for one scene and tolerance.

    Attributes
    ----------
    problem, load, tol : the scene and the tolerance (largest node error over the body size).
    met : bool
        Some candidate met the tolerance. When none did, the other fields describe the finest model.
    resolution, nodes, material : the choice.
    error : float
        Its largest node error over the body size, against the reference.
    time : float
        Its build plus solve time (s).
    finest : dict
        The finest model (Neo-Hookean on the finest candidate mesh): resolution, nodes, material, time, error.
    time_saving, node_saving : float
        Finest model's time and node count over the choice's.
    reference : str
        What the errors are measured against.
    candidates : list of dict
        Every candidate's study row.
    """

    problem: str
    load: float
    tol: float
    met: bool
    resolution: int
    nodes: int
    material: str
    error: float
    time: float
    finest: dict
    time_saving: float
    node_saving: float
    reference: str
    candidates: list = field(default_factory=list)

    def __repr__(self) -> str:
        return compact_repr(self, ("problem", "load", "tol", "met", "material", "nodes", "error", "time_saving"))

    def to_dict(self) -> dict:
        """Every field, candidates included, as a JSON-ready dict."""
        return to_jsonable(asdict(self))

    def summary(self) -> dict:
        """The scalars, for a table row."""
        d = {k: v for k, v in asdict(self).items() if k not in ("candidates", "finest")}
        d.update({f"finest_{k}": v for k, v in self.finest.items()})
        return d


def pick_fidelity(rows: Sequence[dict], problem: str, load: float, tol: float, reference: str = "") -> FidelityChoice:
    """Pick from candidate rows (study rows of one scene): the coarsest mesh, then the simplest material, whose
    run succeeded with ``error <= tol``."""
    tol = float(tol)
    if not (math.isfinite(tol) and tol > 0):
        raise ValueError(f"tolerance must be a positive number, got {tol}")
    cand = [r for r in rows if r["problem"] == problem and r["load"] == load]
    if not cand:
        raise ValueError(f"no candidate runs for {problem!r} at load {load:g}")
    cand.sort(key=lambda r: (r["nodes"], _RANK.get(r["material"], 99)))
    rich = [r for r in cand if r["material"] == max(MATERIALS, key=lambda m: _RANK[m])] or cand
    fine = max(rich, key=lambda r: r["nodes"])

    def t(r):
        return r["build_time"] + r["solve_time"]

    finest = {"resolution": fine["resolution"], "nodes": fine["nodes"], "material": fine["material"],
              "time": t(fine), "error": fine["error"]}
    ok = [r for r in cand if r["success"] and np.isfinite(r["error"]) and r["error"] <= tol]
    best, met = (ok[0], True) if ok else (fine, False)
    return FidelityChoice(problem, float(load), tol, met, best["resolution"], best["nodes"], best["material"],
                          float(best["error"]), t(best), finest, t(fine) / max(t(best), 1e-12),
                          fine["nodes"] / best["nodes"], reference, list(cand))


def _reference_outcome(reference) -> RunOutcome:
    """A known fine solution ``(mesh, x)`` or ``(points, triangles, x)`` as a reference outcome."""
    if isinstance(reference, (tuple, list)) and len(reference) == 2 and isinstance(reference[0], Mesh):
        pts, tri, x = reference[0].points, reference[0].triangles, reference[1]
    elif isinstance(reference, (tuple, list)) and len(reference) == 3:
        pts, tri, x = reference
    else:
        raise TypeError("reference must be (mesh, x) or (points, triangles, x)")
    pts = np.asarray(pts, dtype=float)
    x = np.asarray(x, dtype=float)
    if x.shape != pts.shape:
        raise ValueError(f"reference state has shape {x.shape}, its mesh has {pts.shape[0]} nodes")
    return RunOutcome(-1, {"success": True, "energy": math.nan}, x, pts, np.asarray(tri, dtype=np.int64))


def choose_fidelity(problem: str, tol: float, *, load: float | None = None,
                    resolutions: Sequence[int] = (30, 100, 300, 1000),
                    materials: Sequence[str] = tuple(MATERIALS), method: str = "ipopt",
                    reference: Any = None, reference_resolution: int | None = None, timeout: float = 120.0,
                    scheduler: Any = None, workers: int | None = None, progress: bool = True) -> FidelityChoice:
    """Pick the coarsest mesh and simplest material model that solve ``problem`` within ``tol``.

    Parameters
    ----------
    problem : str
        A study problem (:func:`mdsr_opt.studies.problems.list_study_problems`).
    tol : float
        Largest node error allowed, as a fraction of the body's size.
    load : float, optional
        The problem's load (default: its own).
    resolutions : sequence of int
        Candidate meshes (approximate node counts).
    materials : sequence of str
        Candidate material models; tried simplest first whatever the order given.
    method : str
        The equilibrium backend for every candidate.
    reference : (mesh, x) or (points, triangles, x), optional
        A known fine solution to measure errors against. By default the reference is the problem solved
        with Neo-Hookean by IPOPT (tight tolerance) at ``reference_resolution`` (default: a mesh
        :data:`~mdsr_opt.studies.spec.REFERENCE_FACTOR` times finer than the finest candidate; a candidate on
        a mesh as fine as the reference is not measured).
    scheduler, workers : as in :func:`mdsr_opt.studies.study.run_study` (the candidates run in parallel on Dask).

    Returns
    -------
    FidelityChoice
    """
    prob = get_study_problem(problem)
    load = prob.default_load if load is None else float(load)
    tol = float(tol)
    if not (math.isfinite(tol) and tol > 0):
        raise ValueError(f"tolerance must be a positive number, got {tol}")
    st = Study(f"fidelity-{problem}", f"fidelity of {problem}", (problem,), tuple(resolutions), tuple(materials),
               (method,), loads={problem: (load,)}, reference_resolution=reference_resolution, timeout=timeout)
    log = _LOG.info if progress else None
    runs, refs, _ = st.plan()
    if reference is not None:
        ref = _reference_outcome(reference)
        outs = run_all(runs, scheduler, workers, log)
        where = "the given fine solution"
    else:
        all_out = run_all(refs + runs, scheduler, workers, log)
        ref, outs = all_out[0], all_out[1:]
        if not ref.row["success"]:
            raise RuntimeError(f"the reference solve of {problem!r} failed: {ref.row['status']}")
        where = f"neo-hookean, {ref.row['nodes']} nodes, ipopt (tol 1e-10)"
    fill_accuracy(outs, {(problem, load): ref})
    return pick_fidelity([o.row for o in outs], problem, load, tol, where)


def run_fidelity_study(out: str | os.PathLike | None = None, *, tolerances: Sequence[float] | None = None,
                       cases: Sequence[tuple[str, float]] = FIDELITY_CASES,
                       resolutions: Sequence[int] = (30, 100, 300, 1000), reference_resolution: int = 4000,
                       method: str = "ipopt", scheduler: Any = None, workers: int | None = None,
                       progress: bool = True, figures: bool = True, log: Callable[[str], Any] | None = None,
                       overwrite: bool = False) -> tuple[list[FidelityChoice], StudyResult]:
    """The fidelity study: :func:`choose_fidelity` for each scene in ``cases`` and each tolerance.

    All candidates of all scenes run as one sweep (Neo-Hookean and linear, every resolution), measured against
    a Neo-Hookean reference at ``reference_resolution`` nodes; then each (scene, tolerance) is picked.
    With ``out`` it writes ``fidelity.csv`` (one row per choice), ``fidelity_runs.csv`` (every candidate),
    ``fidelity.json``, ``fidelity.md`` and ``fidelity.png``; ``out`` follows :func:`run_study`'s rules
    (new or empty, locked while the study runs; ``overwrite`` replaces an earlier mdsr output's listed files).
    Progress messages go to ``log`` (default: this module's logger) unless ``progress`` is False;
    ``fidelity_markdown(choices)`` gives the table.
    """
    with checking_input():  # the scenes and the study's axes: bad input, before any run
        tolerances = tuple(DEFAULT_TOLERANCES if tolerances is None else tolerances)
        for tol in tolerances:
            if isinstance(tol, bool) or not isinstance(tol, (int, float, np.integer, np.floating)) or not (math.isfinite(tol) and tol > 0):
                raise ValueError(f"tolerances must be positive numbers, got {tol!r}")
        loads: dict = {}
        for p, load in cases:
            get_study_problem(p)
            loads.setdefault(p, []).append(float(load))
        st = Study("fidelity", "coarsest mesh and simplest material model within a tolerance, per scene",
                   tuple(loads), tuple(resolutions), tuple(MATERIALS), (method,),
                   loads={k: tuple(v) for k, v in loads.items()}, reference_resolution=reference_resolution,
                   timeout=120.0)
    if log is None or not progress:
        log = _LOG.info if progress else None
    names = [f"fidelity{x}" for x in (".csv", "_runs.csv", ".md", ".json")] + (["fidelity.png"] if figures else [])
    with output_folder(out, overwrite, names) as folder:
        return _run_fidelity(st, out, tolerances, cases, scheduler, workers, figures, log,
                             lambda: folder.begin(names))


def _run_fidelity(st: Study, out, tolerances, cases, scheduler, workers, figures, log, begin):
    """:func:`run_fidelity_study` once its sweep is defined and its folder taken."""
    t0 = time.perf_counter()
    with checking_input():  # the plan checks the axes
        runs, refs, _ = st.plan()
    outs = run_all(refs + runs, scheduler, workers, log)
    ref_out, run_out = outs[:len(refs)], outs[len(refs):]
    fill_accuracy(run_out, {(o.row["problem"], o.row["load"]): o for o in ref_out})
    rows = [o.row for o in run_out]
    choices = []
    for p, load in cases:
        ref = next(o for o in ref_out if o.row["problem"] == p and o.row["load"] == float(load))
        where = f"neo-hookean, {ref.row['nodes']} nodes, ipopt"
        for tol in tolerances:
            choices.append(pick_fidelity(rows, p, float(load), tol, where))
    meta = {"study": st.to_dict(), "tolerances": list(tolerances), "cases": [list(c) for c in cases],
            "wall_time": time.perf_counter() - t0, "environment": environment_info(),
            "error": "largest node distance to the reference (interpolated at the run's rest nodes) over the "
                     "body's size; internal driving after the best rigid motion",
            "choice": "coarsest mesh, then simplest material (linear before neo-hookean), among successful "
                      "runs with error <= tol; saving = finest model (neo-hookean, finest candidate mesh) over "
                      "the choice"}
    res = StudyResult(st, rows, [o.row for o in ref_out], meta)
    if out is not None:
        begin()  # the earlier output's files go only now, when the new ones are ready
        out = os.fspath(out)
        os.makedirs(out, exist_ok=True)
        table = [c.summary() for c in choices]
        keys = list(table[0])

        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=keys, lineterminator="\n")
        w.writeheader()
        for r in table:
            w.writerow({k: (repr(v) if isinstance(v, float) else v) for k, v in r.items()})
        with atomic_path(os.path.join(out, "fidelity.csv")) as tmp, open(tmp, "w") as fh:
            fh.write(buf.getvalue())
        with atomic_path(os.path.join(out, "fidelity_runs.csv")) as tmp, open(tmp, "w") as fh:
            fh.write(res.csv_text())
        with atomic_path(os.path.join(out, "fidelity.md")) as tmp, open(tmp, "w") as fh:
            fh.write(fidelity_markdown(choices))
        write_json(os.path.join(out, "fidelity.json"), {**meta, "choices": table})
        if figures:
            from ..plot.common import save_figure
            from ..plot.studies import plot_fidelity

            save_figure(plot_fidelity(rows, table), os.path.join(out, "fidelity.png"), close=True)
        if log:
            log(f"wrote fidelity.csv, fidelity_runs.csv, fidelity.md, fidelity.json"
                f"{', fidelity.png' if figures else ''} to {out}")
    return choices, res


def fidelity_markdown(choices: Sequence[FidelityChoice]) -> str:
    """A Markdown table of choices."""
    lines = [("| scene | load | tol | choice | nodes | error | time s | finest model time s | time saving | "
              "node saving |"), "| --- | ---: | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for c in choices:
        choice = c.material if c.met else f"none met (finest: {c.material})"
        lines.append(f"| {c.problem} | {c.load:g} | {c.tol:g} | {choice} | {c.nodes} | {c.error:.2g} | "
                     f"{c.time:.3g} | {c.finest['time']:.3g} | {c.time_saving:.1f}x | {c.node_saving:.0f}x |")
    return "\n".join(lines) + "\n"

