"""How good are the routed muscles? A quality table for every case of the problem library.

For each case the target is solved and the muscles routed as the scene says (:func:`~mdsr_opt.scenes.
prepare_case`; for an internal case, the muscles routing would choose on its target), and the table gives

- ``muscles``, ``total_length`` (rest, summed) and ``largest_turn`` (degrees, the largest turn of any
  muscle at any node; the routing's tortuosity rule bounds it by ``max_turn``);
- ``nonuniformity``: the largest relative spread of a muscle's edge contractions,
  ``max_c std(w over c) / mean(w over c)`` (0 = every part contracts alike);
- ``difference``: the design difference reached with the routed muscles (routed as ``mdsr run`` routes them,
  :func:`~mdsr_opt.synthesis.routing.route_for_design`; the scene's design options, with the end-fixture
  radius the routing fitted the ropes to);
- ``edge_bound``: the difference reached when every contracted edge (``w > min_contraction``) is a muscle
  of its own, designed as point-to-point dummy springs (``muscle_model="springs"``, ``anchor_radius=0``).
  For spring muscles this relaxes every routed layout (each segment gets its own contraction), so, up to
  local minima, no layout of spring muscles can do better; a layout designed with the default exact cable
  and finite ends is compared with it as a reference, not a strict bound. ``ratio = difference / edge_bound``.
- ``dropped``: fragments spliced or dropped and muscles cut by ``max_muscles``.

:func:`write_quality_table` writes the rows as CSV and markdown. Solver failures are reported in the rows
(``success``, ``status``), never hidden.

Example
-------
>>> rows = routing_quality([("one_muscle", "a20")], resolution="coarse", bound=False)  # doctest: +SKIP
>>> rows[0].muscles >= 1                                                                # doctest: +SKIP
True
"""

from __future__ import annotations

import csv
import io
import math
import warnings
from dataclasses import asdict, dataclass
from typing import Sequence

import numpy as np

from ..body.io import atomic_path
from ..body.muscles import Muscle
from ..synthesis.fabrication import check_fabrication
from ..synthesis.routing import edge_weights, RoutingWarning, route_for_design

__all__ = ["QualityRow", "routing_quality", "write_quality_table", "edge_muscles"]


@dataclass
class QualityRow:
    """One row of the routing-quality table (see the module docstring for the columns)."""

    scene: str
    case: str
    n_nodes: int
    muscles: int
    total_length: float
    largest_turn: float
    nonuniformity: float
    difference: float
    edge_bound: float
    ratio: float
    edge_muscles: int
    dropped: int
    success: bool
    status: str


def edge_muscles(mesh, target, min_contraction: float = 1e-3) -> list[Muscle]:
    """One two-node muscle per mesh edge that ``target`` contracts by more than ``min_contraction``."""
    _, _, w = edge_weights(mesh, target)
    return [Muscle((int(a), int(b)), name=f"edge {k}") for k, (a, b) in enumerate(mesh.edges.tolist())
            if w[k] > min_contraction]


def _library_cases(cases):
    from ..scenes.library import get_problem, list_problems

    if cases is None:
        out = []
        for name in list_problems():
            scene = get_problem(name, resolution="coarse")
            out += [(name, c) for c in scene.case_names]
        return out
    out = []
    for item in cases:
        if not (isinstance(item, (tuple, list)) and len(item) == 2 and all(isinstance(s, str) for s in item)):
            raise TypeError(f"cases must be (scene, case) name pairs, got {item!r}")
        out.append((item[0], item[1]))
    return out


def routing_quality(cases: Sequence[tuple[str, str]] | None = None, *, resolution="coarse",
                    routing_options: dict | None = None, bound: bool = True, log=None) -> list[QualityRow]:
    """The routing-quality table of library cases.

    Parameters
    ----------
    cases : sequence of (scene, case) names, optional
        Default: every case of every scene of the problem library.
    resolution : str or int, default "coarse"
        Passed to the scenes' factories.
    routing_options : dict, optional
        Override the scenes' routing options (e.g. ``{"max_turn": 30}``).
    bound : bool, default True
        Also design with every contracted edge as its own muscle (``edge_bound``); ``nan`` when False.
    log : callable, optional
        Called with one line per case.

    Returns
    -------
    list of QualityRow
        ``success`` is False (and ``status`` says why) when the target, the routing or a design failed.
    """
    from ..synthesis.contractions import design_contractions
    from ..scenes.library import get_problem
    from ..scenes.cases import prepare_case
    from ..scenes.casefab import fixture_wall
    from ..scenes.fixtures import scene_fixture_radius

    pairs = _library_cases(cases)
    scenes: dict = {}
    for name, _ in pairs:  # every name checked before any work
        if name not in scenes:
            scenes[name] = get_problem(name, resolution=resolution)
    for name, cname in pairs:
        scenes[name].case(cname)
    rows = []
    for name, cname in pairs:
        scene = scenes[name]
        setup = prepare_case(scene, cname)
        nan = float("nan")
        opts = dict(scene.routing_options)
        opts.update(routing_options or {})
        row = QualityRow(name, cname, scene.mesh.n_nodes, 0, 0.0, nan, nan, nan, nan, nan, 0, 0, False, "")
        if not setup.target_result.success:
            row.status = f"target failed: {setup.target_result.status}"
            rows.append(row)
            continue
        y = setup.target
        # routed as mdsr run routes (route_for_design, its fixtures the scene's), and designed with the fixture
        # radius the routing fitted the ropes to
        opts["fabrication"] = check_fabrication(opts.get("fabrication"), scene_fixture_radius(scene))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RoutingWarning)
            rr = route_for_design(scene.mesh, y, **opts)
        row.muscles, row.dropped = len(rr), len(rr.dropped)
        if not len(rr):
            row.status = "routing found no muscle"
            rows.append(row)
            continue
        row.total_length = float(sum(s.rest_length for s in rr.stats))
        row.largest_turn = math.degrees(max(s.max_turn for s in rr.stats))
        row.nonuniformity = float(max(math.sqrt(s.nonuniformity) / s.mean_weight for s in rr.stats))
        dopts = {k: v for k, v in scene.design_options.items() if k != "method"}
        if rr.fixture_radius is not None:
            dopts["anchor_radius"] = float(rr.fixture_radius)
        # the ropes' end fixtures the scene's wall apart, as mdsr run designs them (casefab.fixture_wall)
        res = design_contractions(scene.mesh, scene.material, rr.muscles, y, **dopts, fixture_wall=fixture_wall(scene))
        row.difference = res.difference
        status = [] if res.success else [f"design: {res.status}"]
        if bound:
            em = edge_muscles(scene.mesh, y, opts.get("min_contraction", 1e-3))
            row.edge_muscles = len(em)
            # one muscle per edge, point-to-point (a two-node muscle has no room for end patches), as the
            # paper's dummy springs: hundreds of rope constraints would only slow this reference down
            rb = design_contractions(scene.mesh, scene.material, em, y,
                                     **{**dopts, "muscle_model": "springs", "anchor_radius": 0.0})
            row.edge_bound = rb.difference
            row.ratio = res.difference / rb.difference if rb.difference > 0 else nan
            if not rb.success:
                status.append(f"edge bound: {rb.status}")
        row.success = not status
        row.status = "; ".join(status) or "ok"
        rows.append(row)
        if log:
            log(f"{name}/{cname}: {row.muscles} muscle(s), turn <= {row.largest_turn:.1f} deg, "
                f"D = {row.difference:.4g}, edge bound {row.edge_bound:.4g} ({row.status})")
    return rows


def _fmt(v) -> str:
    if isinstance(v, float):
        return "" if not np.isfinite(v) else f"{v:.4g}"
    return str(v)


def write_quality_table(rows: Sequence[QualityRow], csv_path, md_path=None) -> list[str]:
    """Write the rows as CSV (and markdown when ``md_path`` is given), each file atomically.

    Returns the paths written.
    """
    rows = list(rows)
    if not rows:
        raise ValueError("write_quality_table needs at least one row")
    keys = list(asdict(rows[0]))
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=keys, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow(asdict(r))
    written = []
    with atomic_path(csv_path) as tmp:
        with open(tmp, "w") as fh:
            fh.write(buf.getvalue())
    written.append(str(csv_path))
    if md_path is not None:
        lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
        lines += ["| " + " | ".join(_fmt(v) for v in asdict(r).values()) + " |" for r in rows]
        note = ("\n\nlargest_turn in degrees at a single node; nonuniformity = max over muscles of std(w)/mean(w); "
                "difference = design difference with the routed muscles; edge_bound = the difference with every "
                "contracted edge a muscle of its own (a lower bound for spring muscles, up to local minima); "
                "ratio = difference / edge_bound.\n")
        with atomic_path(md_path) as tmp:
            with open(tmp, "w") as fh:
                fh.write("# Routing quality of the library cases\n\n" + "\n".join(lines) + note)
        written.append(str(md_path))
    return written
