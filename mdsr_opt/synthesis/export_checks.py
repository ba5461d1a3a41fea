"""Whether a design's fabrication files may be written as a robot to build, and with which fabrication.

:func:`~mdsr_opt.synthesis.export.export_fabrication` asks two things before it writes anything:

* :func:`design_failure`: why the design is not to be built ("" when it may be): a design that failed (not
  converged, rejected by its verification, a pose of a layout not reached, a layout that cannot be moulded)
  or a stroke no rope can make (:func:`impossible_strokes`: a muscle commanded to shorten whose path in the
  designed state is longer than at rest, so the rope would be stretched). Such files are written only when
  asked for (``allow_failed=True``), and each of them then says :func:`failed_mark`.
* :func:`routed_fabrication`: the channel, wall and fixtures the layout was routed with (a
  :class:`~mdsr_opt.synthesis.pipeline.PipelineResult`'s routing, a
  :class:`~mdsr_opt.synthesis.poses_result.PosesResult`'s ``fabrication``): the files draw it unless told otherwise,
  and :func:`check_same_fabrication` refuses an explicit one that states other sizes.
"""

from __future__ import annotations

import math
from dataclasses import fields
from typing import Mapping

import numpy as np

from ..core.results import one_line

__all__ = ["design_failure", "impossible_strokes", "failed_mark", "not_mouldable", "routed_fabrication",
           "check_same_fabrication"]

#: A commanded contraction and the achieved one may differ by this much before a stretched rope is called
#: impossible (the solvers' tolerance on a taut rope is far below it).
STRETCH_TOLERANCE = 1e-3


def failed_mark(reason: str) -> str:
    """The sentence every file of a failed design carries: ``FAILED DESIGN: <reason>, do not build``."""
    return f"FAILED DESIGN: {reason.strip().rstrip('.;')}, do not build"


def not_mouldable(conflicts, marked: str = "") -> str:
    """The sentence every file of a layout that cannot be moulded carries (the SVG's caption, the CSV's comment
    line): ``NOT MOULDABLE as laid out (<k> place(s)[, <marked>]): <each place's message>``, ``conflicts``
    :class:`~mdsr_opt.synthesis.fabrication.Conflict` s and ``marked`` how the drawing marks them."""
    where = f"{len(conflicts)} place(s)" + (f", {marked}" if marked else "")
    return f"NOT MOULDABLE as laid out ({where}): " + "; ".join(cf.message for cf in conflicts)


def design_failure(design, size: float | None = None) -> str:
    """Why ``design`` (anything :func:`~mdsr_opt.synthesis.export.fabrication_data` reads) is no design to
    build, in one phrase naming the failed pose(s) and their status; "" when it succeeded (or is None: a
    layout alone).

    A :class:`~mdsr_opt.synthesis.pipeline.PipelineResult` that is a success but that the acceptance rule
    rejects (its ``far_from_target``, with an :class:`~mdsr_opt.synthesis.acceptance.AcceptanceWarning`: the
    case ``mdsr run`` fails) is no design to build either: "too far from the target (<its reason>)". A
    :class:`~mdsr_opt.synthesis.poses_result.PosesResult`'s poses that barely move the body are not
    ``pose_success`` already; given the body's ``size`` (a length, its diameter at rest), a designed pose
    whose difference is above :data:`~mdsr_opt.synthesis.acceptance.MAX_DIFFERENCE` of it is named too, "too
    far from its target" (the pose a gait schedule reports not reached). A bare DesignResult records no
    acceptance (its caller's ``failure`` says it)."""
    from .pipeline import PipelineResult
    from .poses_result import PosesResult

    if design is None:
        return ""
    if isinstance(design, PipelineResult):  # failed, or a success the acceptance rule rejects (as mdsr run does)
        why = ([] if design.success else [f"the design failed ({one_line(design.design.status, 300)})"]) + \
            ([f"too far from the target ({one_line(design.far_from_target, 300)})"] if design.far_from_target else [])
        return "; ".join(why)
    if isinstance(design, PosesResult):
        from .acceptance import difference_failure

        why = [f"pose {n}: {one_line(s, 160)}" for n, s, ok in zip(design.names, design.status, design.pose_success)
               if not ok] + [one_line(p, 160) for p in design.problems]
        if size is not None:  # designed, but too far from its target: the 5 % rule of mdsr run and the gait
            why += [f"pose {n}: too far from its target ({far})" for n, d, ok in
                    zip(design.names, design.differences, design.pose_success)
                    if ok and (far := difference_failure(float(d), size, units=design.units))]
        return "" if not why else "the layout's design failed (" + "; ".join(why) + ")"
    items = dict(design) if isinstance(design, Mapping) else {"design": design}
    why = [(f"{k}: " if len(items) > 1 else "") + one_line(getattr(d, "status", "not a success"), 160)
           for k, d in items.items() if not bool(getattr(d, "success", True))]
    return "" if not why else "the design failed (" + "; ".join(why) + ")"


def impossible_strokes(fd) -> list:
    """One sentence per muscle and pose of a :class:`~mdsr_opt.synthesis.export.FabricationData` whose
    commanded contraction is positive but whose path in the designed state is longer than at rest (achieved
    contraction below zero and below the commanded one): the rope would have to stretch, so the row's
    contraction and stroke describe no robot."""
    out = []
    L0 = np.asarray(fd.rest_lengths, dtype=float)
    for k, pose in enumerate(fd.pose_names):
        for i, mu in enumerate(fd.muscles):
            a, s = float(fd.contractions[k, i]), float(fd.strokes[k, i])
            ach = s / L0[i] if L0[i] > 0 else math.nan
            if a > 0 and ach < -STRETCH_TOLERANCE and ach < a - STRETCH_TOLERANCE:
                out.append(f"muscle {mu.name} in {pose}: commanded contraction {a:.4g} but achieved {ach:.4g} "
                           f"(its path {1.0 - ach:.3g}x its rest length, stroke {s:.4g}): a rope cannot stretch")
    return out


def routed_fabrication(design):
    """The :class:`~mdsr_opt.synthesis.fabrication.Fabrication` the design's layout was routed with (every
    field set) or, for muscles given to design_pipeline, given for; None when it records none (a
    DesignResult, a result saved without it)."""
    from .pipeline import PipelineResult
    from .poses_result import PosesResult

    if isinstance(design, PipelineResult):
        routed = None if design.routing is None else design.routing.fabrication
        return design.fabrication if routed is None else routed
    if isinstance(design, PosesResult):
        return design.fabrication
    return None


def check_same_fabrication(given, routed) -> None:
    """ValueError when the fabrication ``given`` to an export states a size (a field not None) other than
    the one the layout was routed with (``routed``, every field set): the ropes were placed for the routed
    channel, wall and fixtures, so files drawn with others would show ropes that are not where that
    workshop's channels can go. ``given`` may be a Fabrication, a dict of its fields, None or False."""
    from .fabrication import check_fabrication

    fab = check_fabrication(given)
    if routed is None or fab is False or fab is None:
        return
    off = [f"{f.name} {getattr(fab, f.name):g} (the layout's: {getattr(routed, f.name):g})"
           for f in fields(fab) if getattr(fab, f.name) is not None and getattr(routed, f.name) is not None
           and not math.isclose(getattr(fab, f.name), getattr(routed, f.name), rel_tol=1e-9, abs_tol=0.0)]
    if off:
        raise ValueError("fabrication differs from the one the layout was routed (or given) with: " + ", ".join(off)
                         + ". The ropes were placed for the layout's channel, wall and fixtures; leave fabrication "
                         "out (the layout's is drawn) or design again with this one")
