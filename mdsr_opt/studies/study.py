"""Running a study into its table, summary and charts (:func:`run_study`)."""

from __future__ import annotations

import contextlib
import csv
import io
import logging
import math
import os
import platform
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence
import casadi
import numpy as np
import scipy

from .. import __version__
from ..core.errors import checking_input
from ..core.guards import interruptible
from ..body.io import atomic_path, write_json
from ..core.results import format_value, to_jsonable
from ..core.stats import fit_slopes
from ..scenes.rundir import RunFolder
from .runs import fill_accuracy, run_all
from .spec import COLUMNS, FAILURES, Study, TIMING_COLUMNS, get_study

__all__ = ['StudyResult', 'run_study', 'output_folder']


_LOG = logging.getLogger(__name__)


@dataclass
class StudyResult:
    """A finished study: its table (one dict per run, :data:`COLUMNS`), references and metadata."""

    study: Study
    rows: list
    references: list
    meta: dict = field(default_factory=dict)

    def __repr__(self) -> str:
        ok = sum(bool(r.get("success")) for r in self.rows)
        methods = list(dict.fromkeys(r.get("method") for r in self.rows))
        wall = self.meta.get("wall_time")
        return (f"StudyResult(study={self.study.name!r}, runs={len(self.rows)}, success={ok}, "
                f"methods={format_value(methods)}, references={len(self.references)}"
                + (f", wall_time={wall:.3g} s)" if isinstance(wall, (int, float)) else ")"))

    def to_dict(self) -> dict:
        """The study's definition, rows, references and metadata as a JSON-ready dict (NaN as None)."""
        return to_jsonable({"study": self.study.to_dict(), "rows": self.rows, "references": self.references,
                            "meta": self.meta})

    def column(self, name: str) -> list:
        if name not in COLUMNS:
            raise ValueError(f"unknown column {name!r}; columns: {', '.join(COLUMNS)}")
        return [r[name] for r in self.rows]

    def comparable(self) -> list[tuple]:
        """The rows without their timing columns: equal for any two runs of the same study. A run stopped by
        its time limit ("time-out") keeps only what identifies it and its outcome: how far it got (its
        iterations, steps and state) depends on the machine's speed at the time."""
        keep = [c for c in COLUMNS if c not in TIMING_COLUMNS]
        outcome = set(keep[:keep.index("nodes") + 1]) | {"success", "failure"}

        def value(r, c):  # NaN (a run that produced no number) compares equal to NaN here, as None
            v = r[c] if r["failure"] != "time-out" or c in outcome else None
            return None if isinstance(v, float) and math.isnan(v) else v

        return [tuple(value(r, c) for c in keep) for r in self.rows]

    def csv_text(self, rows: list | None = None) -> str:
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=list(COLUMNS), lineterminator="\n")
        w.writeheader()
        for r in (self.rows if rows is None else rows):
            w.writerow({k: _fmt(r[k]) for k in COLUMNS})
        return buf.getvalue()

    def summary(self) -> list[dict]:
        """Per method: runs, successes, median time and error of the successes, and the fitted scaling slope."""
        slopes = fit_slopes(self.rows)
        out = []
        for m in dict.fromkeys(r["method"] for r in self.rows):
            rs = [r for r in self.rows if r["method"] == m]
            ok = [r for r in rs if r["success"]]
            t = [r["build_time"] + r["solve_time"] for r in ok]
            e = [r["error"] for r in ok if np.isfinite(r["error"])]
            fails = {f: sum(r["failure"] == f for r in rs) for f in FAILURES[1:]}
            out.append({"method": m, "runs": len(rs), "success": len(ok),
                        "median_time": float(np.median(t)) if t else math.nan,
                        "median_error": float(np.median(e)) if e else math.nan,
                        "slope": slopes.get(m, (math.nan,))[0],
                        "failures": ", ".join(f"{k} {v}" for k, v in fails.items() if v) or "-"})
        return out

    def markdown(self) -> str:
        lines = [f"# Study {self.study.name}", "", self.study.description, "",
                 "| method | runs | success | median time s | median error | time ~ nodes^slope | failures |",
                 "| --- | ---: | ---: | ---: | ---: | ---: | --- |"]
        def num(v, f):
            return "-" if not math.isfinite(v) else format(v, f)

        for s in self.summary():
            lines.append(f"| {s['method']} | {s['runs']} | {s['success']} | {num(s['median_time'], '.3g')} | "
                         f"{num(s['median_error'], '.2g')} | {num(s['slope'], '.2f')} | {s['failures']} |")
        return "\n".join(lines) + "\n"

    def write(self, out: str | os.PathLike, figures: bool = True) -> dict:
        """Write ``<name>.csv``, ``<name>_references.csv``, ``<name>.json`` (metadata), ``<name>.md`` and the
        charts ``<name>_pareto.png``, ``<name>_scaling.png``, ``<name>_success.png`` into ``out``; every file
        through a temporary file. Returns ``{kind: path}``."""
        out = os.fspath(out)
        os.makedirs(out, exist_ok=True)
        name = self.study.name
        paths = {}
        for key, fname, text in (("csv", f"{name}.csv", self.csv_text()),
                                 ("references", f"{name}_references.csv", self.csv_text(self.references)),
                                 ("md", f"{name}.md", self.markdown())):
            p = os.path.join(out, fname)
            with atomic_path(p) as tmp, open(tmp, "w") as fh:
                fh.write(text)
            paths[key] = p
        paths["json"] = write_json(os.path.join(out, f"{name}.json"), _jsonable(self.meta))
        if figures:
            from ..plot.common import save_figure
            from ..plot.studies import plot_study_pareto, plot_study_scaling, plot_study_success

            paths["pareto"] = save_figure(plot_study_pareto(self.rows, title=name),
                                          os.path.join(out, f"{name}_pareto.png"), close=True)
            paths["scaling"] = save_figure(plot_study_scaling(self.rows, fit_slopes(self.rows), title=name),
                                           os.path.join(out, f"{name}_scaling.png"), close=True)
            paths["success"] = save_figure(plot_study_success(self.rows, title=name),
                                           os.path.join(out, f"{name}_success.png"), close=True)
        return paths


def _fmt(v):
    if isinstance(v, (bool, np.bool_)):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    return v


def _jsonable(o):
    if isinstance(o, dict):
        return {str(k): _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    if isinstance(o, float) and not math.isfinite(o):
        return None
    return o


@contextlib.contextmanager
def output_folder(out, overwrite: bool, names: Sequence[str]):
    """``out`` guarded as a run's folder for the block (:class:`~mdsr_opt.scenes.rundir.RunFolder`): locked
    against a second writer at once, and new or empty, or with ``overwrite`` holding an earlier mdsr output
    (checked at once too; ``names`` are the files the study writes). Yields the folder, or None without
    ``out``; call its ``begin(names)`` just before writing: the earlier output's listed files are removed
    then, so a study that fails or is interrupted leaves the folder as it was."""
    if out is None:
        yield None
        return

    with RunFolder(out, overwrite=overwrite, claims=names) as folder:
        yield folder


def environment_info() -> dict:
    return {"mdsr_opt": __version__, "python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__, "casadi": casadi.__version__, "platform": platform.platform(),
            "machine": platform.machine(), "cpus": os.cpu_count()}


@interruptible()
def run_study(study: str | Study, *, out: str | os.PathLike | None = None, resolutions: Sequence[int] | None = None,
              methods: Sequence[str] | None = None, problems: Sequence[str] | None = None,
              materials: Sequence[str] | None = None, reference_resolution: int | None = None,
              timeout: float | None = None, scheduler: Any = None, workers: int | None = None,
              progress: bool = True, figures: bool = True, log: Callable[[str], Any] | None = None,
              overwrite: bool = False) -> StudyResult:
    """Run a study and (with ``out``) write its table, metadata and charts.

    Parameters
    ----------
    study : str or Study
        A name from :func:`list_studies` or a :class:`Study`.
    out : path, optional
        Folder for the outputs (:meth:`StudyResult.write`). It must be new or empty; it is locked while the
        study runs (a second study into it is refused at once).
    overwrite : bool
        Replace an earlier mdsr output in ``out``: only the files its manifest ``.mdsr-run.json`` lists are
        removed, once this study's own files are ready (a study that fails leaves them); a folder holding
        files but no manifest is still refused.
    resolutions, methods, problems, materials, reference_resolution, timeout : optional
        Override the study's axes (e.g. the quick study at its smallest size: ``resolutions=[30]``).
    scheduler : None, "local", "inprocess", an address or a ``distributed.Client``
        ``None`` runs serially here; ``"local"`` starts a Dask LocalCluster (one single-threaded worker
        process per core, or ``workers``); ``"inprocess"`` a thread-based one in this process; an address
        such as ``"tcp://10.0.0.5:8786"`` uses a running cluster (its workers need mdsr_opt installed).
    progress : bool
        Print one line per finished run (to stderr, or through ``log``).

    Returns
    -------
    StudyResult
        ``rows`` are in plan order whatever the order runs finished in.

    Raises
    ------
    ValueError
        An unknown study, problem, backend, material or guess (the message lists the valid ones), a node count
        out of range (an :class:`~mdsr_opt.core.errors.InputError`), or an ``out`` that cannot be used
        (:class:`~mdsr_opt.scenes.rundir.OutputFolderError`: a file, not writable, holding other files, or being
        written by another process).
    """
    with checking_input():  # the study and its overrides: bad input, before any run
        st = get_study(study).with_options(resolutions=resolutions, methods=methods, problems=problems,
                                           materials=materials, reference_resolution=reference_resolution,
                                           timeout=timeout)
        runs, refs, capped = st.plan()
    if log is None:
        log = _LOG.info if progress else None
    elif not progress:
        log = None
    names = [f"{st.name}{x}" for x in (".csv", "_references.csv", ".md", ".json")]
    names += [f"{st.name}_{x}.png" for x in ("pareto", "scaling", "success")] if figures else []
    with output_folder(out, overwrite, names) as folder:
        res = _run_planned(st, runs, refs, capped, scheduler, workers, log)
        if folder is not None:
            folder.begin(names)
            paths = res.write(out, figures=figures)
            if log:
                log(f"wrote {', '.join(sorted(os.path.basename(p) for p in paths.values()))} to {out}")
    return res


def _run_planned(st: Study, runs: list, refs: list, capped: list, scheduler, workers, log) -> StudyResult:
    """:func:`run_study` once its study is planned: the runs, their accuracy and the metadata."""
    t0 = time.perf_counter()
    if log:
        name = scheduler if isinstance(scheduler, str) else "client"
        where = "serially" if scheduler is None else f"on Dask ({name})"
        log(f"study {st.name}: {len(runs)} runs and {len(refs)} reference solves, {where}")
    outcomes = run_all(refs + runs, scheduler, workers, log)
    ref_out, run_out = outcomes[:len(refs)], outcomes[len(refs):]
    refmap = {(o.row["problem"], o.row["load"]): o for o in ref_out}
    for o in ref_out:
        if not o.row["success"] and log:
            log(f"warning: reference {o.row['problem']} load {o.row['load']:g} failed ({o.row['failure']}: "
                f"{o.row['status']}); its runs have no accuracy (error and energy_error are nan)")
    fill_accuracy(run_out, refmap)
    for o in ref_out:
        if o.row["success"]:
            o.row["error"], o.row["energy_error"] = 0.0, 0.0
    rows = [o.row for o in run_out]
    for r in rows:
        for k in COLUMNS:
            r.setdefault(k, math.nan)
        for k in ("load", "build_time", "solve_time", "wall_time", "energy", "energy_error", "error", "min_J",
                  "residual"):
            r[k] = float(r[k])
    meta = {"study": st.to_dict(), "runs": len(runs), "references": len(refs), "capped": capped,
            "scheduler": None if scheduler is None else str(scheduler if isinstance(scheduler, str) else "client"),
            "wall_time": time.perf_counter() - t0, "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "environment": environment_info(), "columns": list(COLUMNS), "timing_columns": list(TIMING_COLUMNS),
            "identical_means": "all columns except the timing columns are equal"}
    return StudyResult(st, rows, [o.row for o in ref_out], meta)
