"""Folder evaluation: a folder of photographs against a folder of states, as a table (paper Tables 2-4)."""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence
import cv2
import numpy as np

from ..body.io import FORMATS, atomic_path, read_mesh
from ..core.results import compact_repr
from ..core.errors import InputError, checking_input
from .compare import ContourComparison
from .contours import contour_loops_from_image
from .loops import LoopComparison, compare_loops, simulated_loops
from .images import IMAGE_SUFFIXES, load_image

__all__ = ['CaseResult', 'evaluate_folder', 'evaluation_files', 'write_evaluation', 'write_table']


#: State files are the mesh formats of :mod:`mdsr_opt.body.io` (so a ``case.svg`` figure beside ``case.vtu``
#: is not taken for a second state).
STATE_SUFFIXES = tuple(FORMATS)


def write_together(writers: Sequence[tuple[Path, Callable[[str], None]]]) -> list[Path]:
    """Write several files as one: each ``write(tmp)`` fills a temporary file beside its target
    (:class:`mdsr_opt.body.io.atomic_path`), and only when every write has succeeded are they all renamed onto
    their targets, last writer first. An error in any write leaves no file changed and no temporary file
    behind; only a failing rename (e.g. a target that is a folder) could leave part of the set renamed."""
    paths = [Path(p) for p, _ in writers]
    for p in paths:  # the likeliest rename failure, caught before anything is written
        if p.is_dir():
            raise InputError(f"cannot write {p}: it is a folder")
    if len(set(paths)) != len(paths):
        raise ValueError(f"the same file would be written twice: {sorted(str(p) for p in paths)}")
    with contextlib.ExitStack() as stack:
        for path, write in writers:
            write(stack.enter_context(atomic_path(path)))
    return paths


def bytes_writer(data: bytes) -> Callable[[str], None]:
    def write(tmp: str) -> None:
        with open(tmp, "wb") as fh:
            fh.write(data)

    return write


# ----------------------------------------------------------------------------------------------- batch
@dataclass(frozen=True)
class CaseResult:
    """One row of an evaluation table: an image compared with the state of the same name.

    ``comparison`` is the outer outline's (its registration places the state on the photograph, as the
    overlay draws it); ``loops`` every boundary loop's, the holes matched to the photograph's
    (:func:`~mdsr_opt.photos.loops.compare_loops`): the table's figures. None: made without (by hand).
    """

    case: str
    image: str
    state: str
    synthetic: bool
    comparison: ContourComparison
    loops: LoopComparison | None = None

    def __repr__(self) -> str:
        c = self.comparison
        return compact_repr(self, ("case", "synthetic"), extra={
            "mean_px": c.mean_px, "max_px": c.max_px, "ratio": c.ratio, "image": self.image, "state": self.state})

    def to_dict(self) -> dict:
        """The row with its comparison (arrays as lists) as a JSON-ready dict."""
        return {"case": self.case, "image": self.image, "state": self.state, "synthetic": self.synthetic,
                "comparison": self.comparison.to_dict(),
                "loops": None if self.loops is None else self.loops.summary()}


def list_files(where: str | os.PathLike | Sequence, suffixes: tuple[str, ...], what: str) -> list[Path]:
    if isinstance(where, (str, os.PathLike)):
        p = Path(where)
        if not p.exists():
            raise FileNotFoundError(f"{what} folder does not exist: {p}")
        if p.is_dir():
            files = sorted(f for f in p.iterdir() if f.is_file() and f.suffix.lower() in suffixes)
            if not files:
                raise ValueError(f"no {what} files ({', '.join(suffixes)}) in {p}")
            return files
        return [p]
    files = [Path(f) for f in where]
    for f in files:
        if not f.exists():
            raise FileNotFoundError(f"{what} file does not exist: {f}")
    if not files:
        raise ValueError(f"no {what} files given")
    return files


def _is_synthetic(image_path: Path) -> bool:
    side = image_path.with_suffix(".json")
    if not side.is_file():
        return False
    try:
        return bool(json.loads(side.read_text()).get("synthetic", False))
    except (ValueError, OSError, AttributeError):
        return False


def evaluate_folder(images: str | os.PathLike | Sequence, states: str | os.PathLike | Sequence, *,
                    out: str | os.PathLike | None = None, name: str = "evaluation",
                    extract: dict | None = None, compare: dict | None = None,
                    figures: bool = False) -> list[CaseResult]:
    """Compare every image of a folder with the simulated state of the same name; write a table.

    Every boundary loop is compared, as ``mdsr run``'s validation compares them
    (:func:`~mdsr_opt.photos.loops.compare_loops`): the outline, and each hole of the state against the
    photographed hole it matches. A hole of the body that the photograph does not show (filled in, or another
    body) is measured to the nearest photographed loop, so it is never scored as a match, and the table says
    so below it (its ``Holes body/photo`` column, ``UNMATCHED``); the CSV gives ``holes``, ``photo_holes``,
    ``unmatched_holes`` and the outline's own ``outline_mean_px``.

    Parameters
    ----------
    images : folder or list of image files
        Photographs (``.png``, ``.jpg``, ...). An image ``case.png`` is compared with the state file
        ``case.*`` in ``states``. A ``case.json`` sidecar with ``"synthetic": true`` (written by
        :meth:`SyntheticPhoto.save`) marks the case synthetic in the table.
    states : folder or list of mesh files
        States in a format of :mod:`mdsr_opt.body.io` (``.vtu``, ``.vtk``, ``.xdmf``, ``.msh``; rest mesh plus
        ``displacement``, or points holding the deformed state). Other files in a states folder (a
        ``case.svg`` figure, say) are ignored.
    out : folder, optional
        Where to write ``<name>.csv`` and ``<name>.md`` (and ``<case>_overlay.png`` with ``figures``).
        Everything, figures included, is computed before anything is written; then every file goes to
        a temporary file beside its target and all are renamed together at the end. An error therefore
        leaves the previous files untouched and no partial set (only a failing rename itself, e.g. a
        target that is a folder, could leave part of the set renamed).
    name : str
        Base name of the table files.
    extract, compare : dict, optional
        Keyword arguments of :func:`~mdsr_opt.photos.contours.contour_loops_from_image` (those of
        :func:`contour_from_image`, and ``min_hole_fraction``) and :func:`compare_contours`.
    figures : bool
        Also write an overlay figure per case.

    Returns
    -------
    list of CaseResult, in the order of the image names.

    Raises
    ------
    FileNotFoundError
        A folder or listed file does not exist.
    ValueError
        No images or states, an image without a state (or two states for one case), or any error while
        reading, extracting or comparing a case: the message starts with ``case '<name>':`` and the
        original exception is chained (``__cause__``). An :class:`~mdsr_opt.core.errors.InputError` (bad
        input) except for a ``TypeError`` in a case (a bug).

    Example
    -------
    >>> import tempfile
    >>> from mdsr_opt import Mesh, render_photo
    >>> from mdsr_opt.body.io import write_mesh
    >>> mesh = Mesh.rectangle(3.0, 1.0, 6, 2)
    >>> with tempfile.TemporaryDirectory() as d:
    ...     _ = write_mesh(f"{d}/states/bent.vtu", mesh, x=mesh.points * [1.0, 0.8])
    ...     _ = render_photo(mesh, mesh.points * [1.0, 0.8], image_size=(300, 200)).save(f"{d}/img/bent.png")
    ...     rows = evaluate_folder(f"{d}/img", f"{d}/states", out=f"{d}/out")
    >>> rows[0].case, rows[0].synthetic, bool(rows[0].comparison.mean_px < 1.0)
    ('bent', True, True)
    """
    with checking_input():  # the arguments and the folders: bad input, before any work
        if not isinstance(name, str) or not name or any(c in name for c in "/\\") or name.startswith("."):
            raise ValueError(f"name must be a plain file stem, got {name!r}")
        image_files = list_files(images, IMAGE_SUFFIXES, "image")
        state_files = list_files(states, STATE_SUFFIXES, "state")
        by_stem: dict[str, Path] = {}
        for f in state_files:
            if f.stem in by_stem:
                raise ValueError(f"two state files for case {f.stem!r}: {by_stem[f.stem].name} and {f.name}")
            by_stem[f.stem] = f
        missing = [f.name for f in image_files if f.stem not in by_stem]
        if missing:
            raise ValueError(f"no state file for image(s) {', '.join(missing)} (states are matched by file name "
                             f"without extension; available: {', '.join(sorted(by_stem)) or 'none'})")
    seen: set[str] = set()
    results = []
    for img_path in image_files:
        case = img_path.stem
        if case in seen:
            raise InputError(f"two images for case {case!r}")
        seen.add(case)
        try:
            data = read_mesh(by_stem[case])
            image = load_image(img_path)
            # every loop, as mdsr run's validation measures it: the outline and each hole against its
            # photographed counterpart, so that a photograph without the body's hole is no match
            found = contour_loops_from_image(image, **(extract or {}))
            comp = compare_loops(simulated_loops(data.mesh, data.x), found, **(compare or {}))
        except (ValueError, TypeError, OSError, cv2.error) as exc:
            # one type for every per-case failure (re-raising type(exc) breaks for exceptions whose
            # constructors need more arguments); the original is chained. A case's files that cannot be
            # read, or in which no body is found, are bad input; a TypeError is a bug, named with its case
            kind = ValueError if isinstance(exc, TypeError) else InputError
            raise kind(f"case {case!r}: {exc}") from exc
        results.append(CaseResult(case, str(img_path), str(by_stem[case]), _is_synthetic(img_path), comp.outer,
                                  comp))
    if out is not None:
        write_evaluation(results, out, name=name, figures=figures)
    return results


def evaluation_files(results: Sequence[CaseResult], name: str = "evaluation", figures: bool = False) -> list[str]:
    """The names of the files :func:`write_evaluation` writes for ``results``: the tables, then one
    ``<case>_overlay.png`` per case with ``figures``."""
    return [f"{name}.csv", f"{name}.md"] + ([f"{r.case}_overlay.png" for r in results] if figures else [])


def write_evaluation(results: Sequence[CaseResult], out: str | os.PathLike, *, name: str = "evaluation",
                     figures: bool = False) -> list[Path]:
    """Write the tables of :func:`evaluate_folder`'s ``results`` into the folder ``out`` (and, with
    ``figures``, an overlay figure per case, drawn from the image and state files the results name).

    Everything is rendered before anything is written; then all files are written together
    (:func:`write_together`): an error leaves the previous files untouched. Returns the paths written.
    Files of those names already in ``out`` are replaced, without a warning (``mdsr evaluate`` refuses to
    without ``--overwrite``).
    """
    out = Path(out)
    writers = _table_writers(results, out / f"{name}.csv", out / f"{name}.md")
    if figures:
        from ..plot.common import close_figure, save_figure
        from ..plot.photos import plot_overlay

        # render every figure to PNG bytes now (one figure open at a time), write with the tables
        with tempfile.TemporaryDirectory() as scratch:
            for k, row in enumerate(results):
                data = read_mesh(row.state)
                fig = plot_overlay(load_image(row.image), data.mesh, data.x, row.comparison,
                                   synthetic=row.synthetic, title=row.case)
                try:
                    png = Path(save_figure(fig, Path(scratch, f"{k}.png")))
                finally:
                    close_figure(fig)
                writers.insert(k, (out / f"{row.case}_overlay.png", bytes_writer(png.read_bytes())))
    return write_together(writers)


def _table_rows(results: Sequence[CaseResult]) -> list[dict[str, Any]]:
    """One row per case: the distances over every loop (the outline's alone when ``loops`` is None), the
    outline's own mean, the normalised ones (over every loop: divided by the unit rectangle's side in pixels
    when a hole is measured), the holes of the body and of the photograph and how many have no counterpart."""
    rows = []
    for r in results:
        c, lc = r.comparison, r.loops or _outline_only(r.comparison)
        holes = [row for row in lc.loops if row["kind"] != "outer"]
        norm = (c.mean_norm, c.std_norm) if not holes else (lc.mean_px / c.size_px, lc.std_px / c.size_px)
        rows.append({"case": r.case, "source": "synthetic" if r.synthetic else "photo",
                     "mean_px": lc.mean_px, "std_px": lc.std_px, "max_px": lc.max_px,
                     "mean_norm": norm[0], "std_norm": norm[1], "ratio": lc.ratio, "outline_mean_px": c.mean_px,
                     "holes": sum(row["kind"] == "hole" for row in holes),
                     "photo_holes": sum(row["matched"] is not None for row in holes)
                     + sum(row["kind"] == "photo-only hole" for row in holes),
                     "unmatched_holes": lc.n_unmatched,
                     "bias_px": c.bias_px, "angle_deg": c.angle_deg, "n_nodes": c.n_nodes,
                     "image": r.image, "state": r.state})
    return rows


def _outline_only(c: ContourComparison) -> LoopComparison:
    """A comparison of the outline alone, as :func:`~mdsr_opt.photos.loops.compare_loops` gives it."""
    return LoopComparison(outer=c, loops=[{"kind": "outer", "index": 0, "matched": 0, "n": int(c.n_nodes),
                                           "mean_px": c.mean_px, "std_px": c.std_px, "max_px": c.max_px}],
                          mean_px=c.mean_px, std_px=c.std_px, max_px=c.max_px, ratio=c.ratio, n_unmatched=0)


def unmatched_words(loops: LoopComparison | None) -> str:
    """The words for a comparison whose holes do not all have a counterpart (``""`` when they do): the holes
    the body has that the photograph does not show, and the reverse."""
    if loops is None:
        return ""
    body_only = sum(row["kind"] == "hole" and row["matched"] is None for row in loops.loops)
    photo_only = sum(row["kind"] == "photo-only hole" for row in loops.loops)
    said = []
    if body_only:
        said.append(f"the body has {body_only} hole(s) the photograph does not show (filled in, or another "
                    "body): each is measured to the nearest photographed loop, not scored as a match")
    if photo_only:
        said.append(f"the photograph shows {photo_only} hole(s) the body does not have: each is measured to the "
                    "nearest simulated loop")
    return "; ".join(said)


def write_table(results: Sequence[CaseResult], csv_path: str | os.PathLike,
                md_path: str | os.PathLike | None = None) -> list[Path]:
    """Write the evaluation table as CSV (all fields) and Markdown (like the paper's Tables 2-4).

    Both files are first written to temporary files beside their targets and then renamed together, so
    an error leaves the previous files (if any) untouched and never a partial file or a lone table.

    Example
    -------
    >>> import tempfile, numpy as np
    >>> from mdsr_opt.photos.compare import compare_contours
    >>> sq = np.array([[0, 0], [2, 0], [2, 1], [0, 1]], float)
    >>> r = CaseResult("a", "a.png", "a.vtu", False, compare_contours(sq, sq * [100, -100]))
    >>> with tempfile.TemporaryDirectory() as d:
    ...     paths = write_table([r], f"{d}/t.csv", f"{d}/t.md")
    ...     print(open(paths[0]).readline().strip()[:30])
    case,source,mean_px,std_px,max
    """
    return write_together(_table_writers(results, csv_path, md_path))


def _table_writers(results: Sequence[CaseResult], csv_path: str | os.PathLike,
                   md_path: str | os.PathLike | None) -> list[tuple[Path, Callable[[str], None]]]:
    if not results:
        raise ValueError("no results to write")
    rows = _table_rows(results)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in row.items()})
    writers = [(Path(csv_path), bytes_writer(buf.getvalue().encode()))]
    if md_path is not None:
        holes = any(row["holes"] or row["photo_holes"] for row in rows)  # a column of its own only then

        def hole_cell(row):
            return (f" {row['holes']}/{row['photo_holes']}" + (" UNMATCHED" if row["unmatched_holes"] else "")
                    + " |") if holes else ""

        lines = ["| Case | Source | Average distance d (px) | Standard deviation (px) | Max (px) | "
                 "d normalised | Ratio d/size (%) |" + (" Holes body/photo |" if holes else ""),
                 "| --- | --- | ---: | ---: | ---: | ---: | ---: |" + (" ---: |" if holes else "")]
        for row in rows:
            lines.append(f"| {row['case']} | {row['source']} | {row['mean_px']:.2f} | {row['std_px']:.2f} | "
                         f"{row['max_px']:.2f} | {row['mean_norm']:.4f} | {100 * row['ratio']:.2f} |" + hole_cell(row))
        mean = {k: float(np.mean([row[k] for row in rows])) for k in ("mean_px", "std_px", "max_px",
                                                                        "mean_norm", "ratio")}
        lines.append(f"| **mean** | | {mean['mean_px']:.2f} | {mean['std_px']:.2f} | {mean['max_px']:.2f} | "
                     f"{mean['mean_norm']:.4f} | {100 * mean['ratio']:.2f} |" + (" |" if holes else ""))
        lines.append("")
        lines.append("d: mean distance of the simulated boundary nodes (the outline's and every hole's, each hole "
                     "matched to the photographed hole nearest it: mdsr_opt.photos.loops.compare_loops) to the "
                     "measured contours (cv2.pointPolygonTest); normalised: in the unit rectangle (the simulated "
                     "outline's bounding rectangle at the registered scale, longer side 1); ratio: d over the "
                     "square root of the measured outline's area.")
        for r in results:
            words = unmatched_words(r.loops)
            if words:
                lines += ["", f"**{r.case}**: {words}."]
        if any(row["source"] == "synthetic" for row in rows):
            lines.append("")
            lines.append("**SYNTHETIC**: rows marked synthetic compare with images rendered by the synthetic "
                         "camera (mdsr_opt.photos.camera.render_photo), not with photographs of a prototype.")
        writers.append((Path(md_path), bytes_writer(("\n".join(lines) + "\n").encode())))
    return writers
